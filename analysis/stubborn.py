"""Stubborn sets: partial-order reduction for deadlock and reachability checks.

In a marking ``m`` a *stubborn set* ``S`` of transitions is closed under two rules
(Valmari's, for place/transition nets):

* an enabled ``t`` in ``S`` brings in every transition sharing an input place with
  it, ``(pre t) post``: nothing outside ``S`` can then disable ``t`` or be disabled by
  it, so ``t`` commutes with every sequence of transitions outside ``S``;
* a disabled ``t`` in ``S`` brings in every transition that adds tokens to one
  *scapegoat* input place ``p`` with ``m(p) < W(p, t)``: ``t`` stays disabled until
  one of them fires.

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

The sets are computed per marking in Python from precomputed neighbour lists; a few
seeds are tried and the set with fewest enabled transitions wins.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from analysis.encoding import CompactNet

SEEDS = 4
"""Enabled transitions tried as the seed of a stubborn set, per marking."""

MAX_WORK = 256
"""Transitions a closure may take in before it is abandoned. Firing all enabled
transitions is always allowed, so giving up costs reduction, never correctness; it
keeps nets with huge conflict clusters (TokenRing) from spending milliseconds per
marking on sets that end up full anyway."""


class StubbornSets:
    """Computes reduced enabled sets for blocks of markings.

    Args:
        cn: the net.
        visible: places a reachability question is about (``None``: deadlocks only).
    """

    def __init__(self, cn: CompactNet, visible: Sequence[int] | None = None) -> None:
        n_t, n_p = cn.n_transitions, cn.n_places
        self.needs_proviso = visible is not None
        inputs, effects = cn.inputs, cn.effects
        # From the sparse arcs only: a mission can be too large for dense matrices.
        self.preset: list[list[tuple[int, int]]] = [
            list(zip(inputs.places[a:b].tolist(), inputs.values[a:b].tolist(), strict=True))
            for a, b in zip(inputs.indptr[:-1].tolist(), inputs.indptr[1:].tolist(), strict=True)
        ]
        consumers: list[list[int]] = [[] for _ in range(n_p)]
        for t, p in zip(inputs.rows.tolist(), inputs.places.tolist(), strict=True):
            consumers[p].append(t)
        self.conflicts: list[list[int]] = [
            sorted({u for p, _ in self.preset[t] for u in consumers[p]}) for t in range(n_t)
        ]
        self.producers: list[list[int]] = [[] for _ in range(n_p)]
        raised = effects.values > 0
        for t, p in zip(
            effects.rows[raised].tolist(), effects.places[raised].tolist(), strict=True
        ):
            self.producers[p].append(t)
        if visible is None:
            self.visible: set[int] = set()
        else:
            watched = np.zeros(n_p, dtype=bool)
            watched[np.asarray(list(visible), dtype=np.int64)] = True
            self.visible = set(np.unique(effects.rows[watched[effects.places]]).tolist())

    def _closure(
        self, seeds: Sequence[int], marking: list[int], enabled: set[int], give_up: int
    ) -> set[int] | None:
        """The stubborn closure of ``seeds``, or ``None`` as soon as it holds
        ``give_up`` enabled transitions (no better than a set already found) or grows
        past `MAX_WORK` transitions."""
        chosen = set(seeds)
        stack = list(seeds)
        count = len(chosen & enabled)
        while stack:
            t = stack.pop()
            if t in enabled:
                more = self.conflicts[t]
            else:
                more = []
                for p, w in self.preset[t]:
                    if marking[p] < w:
                        more = self.producers[p]
                        break
            for u in more:
                if u not in chosen:
                    chosen.add(u)
                    stack.append(u)
                    if len(chosen) > MAX_WORK:
                        return None
                    if u in enabled:
                        count += 1
                        if count >= give_up:
                            return None
        return chosen

    def stubborn(self, marking: list[int], enabled: list[int]) -> list[int]:
        """The enabled transitions of a small stubborn set of ``marking``."""
        enabled_set = set(enabled)
        best: list[int] = enabled
        for seed in enabled[:SEEDS]:
            chosen = self._closure([seed], marking, enabled_set, len(best))
            if chosen is not None and not self.visible.isdisjoint(chosen & enabled_set):
                seeds = [seed, *sorted(self.visible)]
                chosen = self._closure(seeds, marking, enabled_set, len(best))
            if chosen is None:
                continue
            best = [t for t in enabled if t in chosen]
            if len(best) == 1:
                break
        return best

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
        markings = cols[:, busy].T.tolist()
        sub = enabled[:, busy]
        for k, column in enumerate(busy.tolist()):
            fire = self.stubborn(markings[k], np.flatnonzero(sub[:, k]).tolist())
            if len(fire) < counts[column]:
                reduced[:, column] = False
                reduced[fire, column] = True
        return reduced
