"""Stubborn sets: partial-order reduction for deadlock and reachability checks.

In a marking ``m`` a *stubborn set* ``S`` of transitions is closed under two rules
(Valmari's, for place/transition nets):

* an enabled ``t`` in ``S`` brings in every transition sharing an input place with
  it, ``(pre t) post``: nothing outside ``S`` can then disable ``t`` or be disabled by
  it, so ``t`` commutes with every sequence of transitions outside ``S``;
* a disabled ``t`` in ``S`` brings in every transition that adds tokens to one
  *scapegoat* input place ``p`` with ``m(p) < W(p, t)`` (the first such place of its
  preset): ``t`` stays disabled until one of them fires.

Firing only the enabled transitions of a stubborn set that contains at least one
enabled transition keeps every reachable deadlock (and every shortest path to it is
replaced by one of equal length or longer, never lost).

For a reachability question about a set of *visible* places, two more conditions:
if ``S`` holds an enabled visible transition (one that changes a visible place), it
holds all visible transitions; and the explorer's cycle proviso (see
`analysis.statespace`) expands a marking fully when a reduced successor was already
known. Together they keep every reachable combination of token counts on the visible
places, so any predicate over them is reachable in the reduced graph exactly when it
is in the full one.

Why vectorised: the closures used to be computed one marking at a time in Python,
which made ``--por`` slower than the full search on every net it did not reduce much
(TokenRing-PT-010: 15 s against 0.3 s). Here all closures of a block of markings grow
together, one numpy step per round of the closure: a *run* is one (marking, seed)
pair, and each round adds, for every run, the transitions its newest members bring
in. A run stops early once it holds every enabled transition of its marking (it can
no longer reduce anything) or more than `MAX_WORK` transitions; the smallest finished
run of each marking wins, the first seed on ties. Giving up on a run only costs
reduction: firing every enabled transition is always allowed.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from analysis.encoding import CompactNet
from analysis.encoding.compact import row_entries

IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

SEEDS = 2
"""Enabled transitions tried as the seed of a stubborn set, per marking."""

MAX_WORK = 256
"""Transitions a closure may take in before it is abandoned. Firing all enabled
transitions is always allowed, so giving up costs reduction, never correctness; it
keeps nets with huge conflict clusters (TokenRing) from spending time on sets that end
up full anyway."""

RAW_WORK = 4 * MAX_WORK
"""Candidates (duplicates included) one round may bring into a run before the run is
abandoned: keeps a round's temporaries small on nets whose conflict sets are large."""

CHOSEN_CELLS = 1 << 22
"""Largest ``transitions x runs`` matrix one batch of closures uses (two of them: a
membership bit and a 4-byte stamp per cell)."""


class _Rows:
    """Compressed rows of transition (or place) indices: ``items[ptr[i]:ptr[i+1]]``."""

    def __init__(self, lists: Sequence[Sequence[int]]) -> None:
        counts = np.array([len(row) for row in lists], dtype=np.int64)
        self.ptr = np.zeros(len(lists) + 1, dtype=np.int64)
        np.cumsum(counts, out=self.ptr[1:])
        self.items = np.array([x for row in lists for x in row], dtype=np.int64)
        self.counts = counts

    def expand(self, rows: IntArray) -> tuple[IntArray, IntArray]:
        """``(owner, item)`` pairs: every item of each of ``rows``, ``owner`` being its
        position in ``rows``."""
        owner, entry = row_entries(self.ptr, self.counts, rows)
        return owner, self.items.take(entry)


class StubbornSets:
    """Computes reduced enabled sets for blocks of markings.

    Args:
        cn: the net.
        visible: places a reachability question is about (``None``: deadlocks only).
    """

    def __init__(self, cn: CompactNet, visible: Sequence[int] | None = None) -> None:
        n_t, n_p = cn.n_transitions, cn.n_places
        self.n_transitions = n_t
        self.needs_proviso = visible is not None
        inputs, effects = cn.inputs, cn.effects
        # From the sparse arcs only: a mission can be too large for dense matrices.
        self.inputs = inputs
        consumers: list[list[int]] = [[] for _ in range(n_p)]
        for t, p in zip(inputs.rows.tolist(), inputs.places.tolist(), strict=True):
            consumers[p].append(t)
        presets = [
            inputs.places[a:b].tolist()
            for a, b in zip(inputs.indptr[:-1].tolist(), inputs.indptr[1:].tolist(), strict=True)
        ]
        self.conflicts = _Rows(
            [sorted({u for p in presets[t] for u in consumers[p]}) for t in range(n_t)]
        )
        producers: list[list[int]] = [[] for _ in range(n_p)]
        raised = effects.values > 0
        for t, p in zip(
            effects.rows[raised].tolist(), effects.places[raised].tolist(), strict=True
        ):
            producers[p].append(t)
        self.producers = _Rows(producers)
        # Seeds are tried in this order: fewest conflicts first, then by index.
        self._seed_order = np.lexsort((np.arange(n_t), self.conflicts.counts)).astype(np.int64)
        # Most producers a disabled transition can bring in (its largest scapegoat's).
        self._scapegoat_bound = np.zeros(n_t, dtype=np.int64)
        if inputs.places.size:
            np.maximum.at(
                self._scapegoat_bound, inputs.rows, self.producers.counts.take(inputs.places)
            )
        self.visible = np.zeros(0, dtype=np.int64)
        if visible is not None:
            watched = np.zeros(n_p, dtype=bool)
            watched[np.asarray(list(visible), dtype=np.int64)] = True
            self.visible = np.unique(effects.rows[watched[effects.places]]).astype(np.int64)

    def stubborn(self, marking: list[int], enabled: list[int]) -> list[int]:
        """The enabled transitions of a small stubborn set of one ``marking``."""
        cols = np.asarray(marking, dtype=np.int64)[:, None]
        mask = np.zeros((self.n_transitions, 1), dtype=bool)
        mask[np.asarray(enabled, dtype=np.int64), 0] = True
        return np.flatnonzero(self.reduce(cols, mask)[:, 0]).tolist()

    def reduce(
        self, cols: npt.NDArray[np.integer], enabled: npt.NDArray[np.bool_]
    ) -> npt.NDArray[np.bool_]:
        """Reduced enabled matrix for a block of markings.

        Args:
            cols: markings as columns, shape ``(places, n)``.
            enabled: ``(transitions, n)`` enabled matrix of those markings.

        Returns:
            A sub-matrix of ``enabled``: per marking, the enabled transitions of a
            stubborn set (all of them when no smaller set exists; none when dead).
        """
        reduced = enabled.copy()
        counts = enabled.sum(axis=0)
        busy = np.flatnonzero(counts > 1)
        if busy.size == 0:
            return reduced
        per_batch = max(1, CHOSEN_CELLS // (max(1, self.n_transitions) * SEEDS))
        for start in range(0, busy.size, per_batch):
            part = busy[start : start + per_batch]
            reduced[:, part] = self._reduce_columns(
                np.asarray(cols[:, part], dtype=np.int64), enabled[:, part], counts[part]
            )
        return reduced

    def _reduce_columns(self, cols: IntArray, enabled: BoolArray, counts: IntArray) -> BoolArray:
        """`reduce` for markings that each enable at least two transitions."""
        # Runs: the `SEEDS` enabled transitions of each marking with the fewest
        # conflicts (the likeliest small closures), one run each.
        ranked = enabled[self._seed_order]
        rank = np.cumsum(ranked, axis=0, dtype=np.int32)
        seed_rank, seed_c = np.nonzero(ranked & (rank <= SEEDS))
        order = np.lexsort((seed_rank, seed_c))  # by marking, then by seed preference
        seed_t, column = self._seed_order.take(seed_rank[order]), seed_c[order]
        runs = column.size
        n_t = enabled.shape[0]
        chosen = np.zeros((n_t, runs), dtype=bool)
        stamp = np.empty((n_t, runs), dtype=np.int32)  # deduplicates a round's pairs
        size = np.zeros(runs, dtype=np.int64)  # transitions taken in
        taken = np.zeros(runs, dtype=np.int64)  # enabled transitions taken in
        alive = np.ones(runs, dtype=bool)
        widened = np.zeros(runs, dtype=bool)  # visible transitions added already
        new_t, new_r = seed_t, np.arange(runs, dtype=np.int64)
        full = counts.take(column)
        while new_t.size:
            chosen[new_t, new_r] = True
            size += np.bincount(new_r, minlength=runs)
            is_enabled = enabled[new_t, column.take(new_r)]
            taken += np.bincount(new_r[is_enabled], minlength=runs)
            alive &= (taken < full) & (size <= MAX_WORK)
            keep = alive.take(new_r)
            new_t, new_r, is_enabled = new_t[keep], new_r[keep], is_enabled[keep]
            raw = np.where(
                is_enabled, self.conflicts.counts.take(new_t), self._scapegoat_bound.take(new_t)
            )
            alive &= np.bincount(new_r, weights=raw, minlength=runs) <= RAW_WORK
            keep = alive.take(new_r)
            new_t, new_r, is_enabled = new_t[keep], new_r[keep], is_enabled[keep]
            conf_t, conf_r = self._conflicts_of(new_t[is_enabled], new_r[is_enabled])
            scape_t, scape_r, stuck = self._producers_of(
                new_t[~is_enabled], new_r[~is_enabled], cols, column
            )
            alive[stuck] = False
            more_t, more_r = [conf_t, scape_t], [conf_r, scape_r]
            if self.visible.size:
                hit = np.unique(new_r[is_enabled & np.isin(new_t, self.visible)])
                hit = hit[~widened.take(hit)]
                widened[hit] = True
                more_t.append(np.tile(self.visible, hit.size))
                more_r.append(np.repeat(hit, self.visible.size))
            cand_t, cand_r = np.concatenate(more_t), np.concatenate(more_r)
            fresh = alive.take(cand_r) & ~chosen[cand_t, cand_r]
            cand_t, cand_r = cand_t[fresh], cand_r[fresh]
            order = np.arange(cand_t.size, dtype=np.int32)
            stamp[cand_t, cand_r] = order  # the last write of each pair wins
            first = stamp[cand_t, cand_r] == order
            new_t, new_r = cand_t[first], cand_r[first]
        # Per marking: the finished run with fewest enabled members (first seed on ties).
        score = np.where(alive, taken, np.iinfo(np.int64).max)
        best = np.lexsort((np.arange(runs), score, column))
        first = np.ones(runs, dtype=bool)
        first[1:] = column[best[1:]] != column[best[:-1]]
        winner = best[first]  # one run per marking that has runs, by marking
        out = enabled.copy()
        good = alive.take(winner)
        cols_won, runs_won = column.take(winner)[good], winner[good]
        out[:, cols_won] &= chosen[:, runs_won]
        return out

    def _conflicts_of(self, ts: IntArray, rs: IntArray) -> tuple[IntArray, IntArray]:
        """Rule 1: enabled ``ts`` (of runs ``rs``) bring in every transition sharing
        an input place with them."""
        owner, items = self.conflicts.expand(ts)
        return items, rs.take(owner)

    def _producers_of(
        self, ts: IntArray, rs: IntArray, cols: IntArray, column: IntArray
    ) -> tuple[IntArray, IntArray, IntArray]:
        """Rule 2: disabled ``ts`` (of runs ``rs``) bring in the producers of their
        first insufficient input place. Returns the new pairs and the runs whose
        transition is disabled for no reason the arcs show (never enabled by the
        explorer's bounds): those runs give up."""
        owner, arc = self.inputs.expand(ts)
        places = self.inputs.places.take(arc)
        short = cols[places, column.take(rs.take(owner))] < self.inputs.values.take(arc)
        hits = np.flatnonzero(short)
        # `owner` ascends, so the first hit of each owner is its first short arc.
        owners, first = np.unique(owner.take(hits), return_index=True)
        scapegoat = places.take(hits.take(first))
        lacking = np.ones(ts.size, dtype=bool)
        lacking[owners] = False
        p_owner, items = self.producers.expand(scapegoat)
        return items, rs.take(owners).take(p_owner), rs[lacking]
