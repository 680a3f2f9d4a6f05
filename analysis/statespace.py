"""Fast explicit exploration of the reachable markings of a `Net`.

Breadth first, one layer at a time, vectorised over the frontier with numpy:

1. a block of the frontier (markings as columns of small integers) is checked against
   every transition's sparse preset at once, giving an enabled matrix; its non-zeros
   are the edges;
2. each edge (marking, enabled transition) yields its successor's *packed key* by one
   addition per key word (see `analysis.encoding.Layout`), never a full row;
3. the keys go through a vectorised open-addressing set (`KeyStore`) that numbers new
   markings as they are first met, so state numbers grow with BFS depth
   (``layer_starts``) and parents always precede their children;
4. only new markings get a column (``parent column + delta``) for the next layer.

Counts are exact: packed keys are injective (no hash collisions to resolve),
``edges`` counts (marking, enabled transition) pairs as the MCC does, and a bit field
that some firing would overflow is widened (every stored key is re-packed) before any
successor using it is trusted; past ``2**60`` tokens exploration stops with a reason.
Each state keeps its parent and the transition that found it (``int32`` + ``int16``
for usual budgets), so `StateSpace.trace_to` returns a shortest firing sequence.

Memory per stored state: ``8 * W`` bytes of key (``W`` = words per marking, 1 for up
to ~63 one-bit places), ``16 * W`` to ``32 * W`` bytes of hash table (load <= 0.5),
6 bytes of parent pointer: about 30 to 55 bytes for one-word nets.

Typical use::

    space = explore(net, max_states=1_000_000)
    if space.deadlocks.size:
        print(space.trace_names(int(space.deadlocks[0])))
    hit = space.find(lambda m: (m[:, p] > 0) & (m[:, q] > 0))
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from analysis.encoding import MAX_FIELD_BITS, Added, CompactNet, KeyStore, Layout, row_dtype
from analysis.progress import ProgressCallback, ProgressInfo
from analysis.stubborn import StubbornSets
from coral_lang.net import Net

DEFAULT_MAX_STATES = 5_000_000
"""Default state budget: about 150 MB on typical nets, seconds of work."""

DEFAULT_CHUNK = 1 << 15
"""Frontier rows handled per vectorised step: bounds the temporaries to a few MB."""

EDGES_PER_STEP = 1 << 19
"""Most edges one vectorised step handles (about 40 MB of temporaries at most)."""

CELLS_PER_STEP = 1 << 23
"""Most (transition, marking) cells of one step's enabled matrix (8 MB of booleans)."""

Markings = npt.NDArray[np.int64]
Predicate = Callable[[Markings], npt.NDArray[np.bool_]]
Clock = Callable[[], float]


@dataclass
class StateSpace:
    """What `explore` learnt about a net.

    Attributes:
        net: the explored net.
        states: reachable markings found (all of them when ``complete``).
        edges: (marking, enabled transition) pairs fired; with ``por`` only the
            reduced ones.
        place_bounds: most tokens each place held in any stored marking.
        max_tokens_place: ``max(place_bounds)``.
        max_tokens_marking: most tokens in one stored marking.
        deadlocks: numbers of all dead states found (no transition enabled), ascending,
            so ``deadlocks[0]`` has the shortest trace.
        fired_transitions: ``fired_transitions[t]`` is whether ``t`` is enabled in some
            stored marking. With ``por`` this under-approximates (reduced graph).
        complete: whether every reachable marking was stored.
        stopped_reason: why exploration stopped early (``None`` when complete).
        seconds: wall time of the exploration.
        stored_bytes: bytes of the arrays kept for the states (keys, index, parents).
        depth: BFS layers explored (the deepest state is at ``depth - 1``).
        reduced: whether partial-order reduction was on.
    """

    net: Net
    states: int
    edges: int
    place_bounds: npt.NDArray[np.int64]
    max_tokens_place: int
    max_tokens_marking: int
    deadlocks: npt.NDArray[np.int64]
    fired_transitions: npt.NDArray[np.bool_]
    complete: bool
    stopped_reason: str | None
    seconds: float
    stored_bytes: int
    depth: int
    reduced: bool
    layout: Layout = field(repr=False)
    keys: npt.NDArray[np.uint64] = field(repr=False)
    parents: npt.NDArray[np.integer] = field(repr=False)
    via: npt.NDArray[np.integer] = field(repr=False)
    layer_starts: npt.NDArray[np.int64] = field(repr=False)

    @property
    def bytes_per_state(self) -> float:
        """``stored_bytes / states``."""
        return self.stored_bytes / max(1, self.states)

    @property
    def states_per_second(self) -> float:
        """Exploration rate."""
        return self.states / self.seconds if self.seconds > 0 else float("inf")

    @property
    def has_deadlock(self) -> bool:
        """Whether some stored marking enables nothing."""
        return bool(self.deadlocks.size)

    @property
    def dead_transitions(self) -> npt.NDArray[np.int64]:
        """Transitions never enabled in a stored marking (dead if ``complete``)."""
        return np.flatnonzero(~self.fired_transitions)

    @property
    def ever_marked(self) -> npt.NDArray[np.bool_]:
        """Per place, whether some stored marking puts a token on it."""
        return self.place_bounds > 0

    def marking(self, index: int) -> tuple[int, ...]:
        """Marking of state ``index`` as a tuple aligned with ``net.places``."""
        row = self.layout.unpack(self.keys[index : index + 1])[0]
        return tuple(int(v) for v in row)

    @property
    def markings(self) -> Markings:
        """Every stored marking, shape ``(states, places)``, in state order.

        Decodes all keys at once (``8 * places`` bytes per state); use
        `iter_markings` or `find` on big state spaces.
        """
        return self.layout.unpack(self.keys).astype(np.int64)

    def iter_markings(self, chunk: int = 1 << 16) -> Iterator[tuple[int, Markings]]:
        """``(first_state, markings)`` blocks of at most ``chunk`` states, in order."""
        for start in range(0, self.states, chunk):
            yield start, self.layout.unpack(self.keys[start : start + chunk]).astype(np.int64)

    def find(self, predicate: Predicate) -> int | None:
        """The first (hence shallowest) state whose marking satisfies ``predicate``.

        Args:
            predicate: maps a block of markings ``(n, places)`` to ``n`` booleans,
                e.g. ``lambda m: m[:, p] + m[:, q] > 3``.

        Returns:
            The state number, or ``None`` if no stored marking satisfies it; pair it
            with `trace_to` for a shortest witness.
        """
        for start, block in self.iter_markings():
            hits = np.flatnonzero(predicate(block))
            if hits.size:
                return start + int(hits[0])
        return None

    def max_sum(self, places: Sequence[int]) -> int:
        """Most tokens the ``places`` held together in one stored marking."""
        cols = np.asarray(places, dtype=np.int64)
        best = 0
        for _, block in self.iter_markings():
            best = max(best, int(block[:, cols].sum(axis=1).max(initial=0)))
        return best

    def depth_of(self, index: int) -> int:
        """BFS layer of state ``index`` = length of its shortest trace."""
        return int(np.searchsorted(self.layer_starts, index, side="right")) - 1

    def trace_to(self, index: int) -> list[int]:
        """Transition indices of a shortest firing sequence from the initial marking to
        state ``index`` (shortest in the reduced graph when ``reduced``)."""
        path: list[int] = []
        while index > 0:
            path.append(int(self.via[index]))
            index = int(self.parents[index])
        return path[::-1]

    def trace_names(self, index: int) -> list[str]:
        """`trace_to` as transition names."""
        return [self.net.transitions[t].name for t in self.trace_to(index)]

    def summary(self) -> str:
        """One line: counts, completeness, rate."""
        status = "complete" if self.complete else f"incomplete ({self.stopped_reason})"
        return (
            f"{self.states} states, {self.edges} edges, {self.deadlocks.size} dead, "
            f"{status}, {self.seconds:.2f} s, {self.bytes_per_state:.1f} B/state"
        )


def _nonzero(matrix: npt.NDArray[np.bool_]) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """``np.nonzero`` of a C-contiguous 2-D matrix (same order), via the much faster
    1-D path: rows and columns come from the flat positions."""
    flat = np.flatnonzero(matrix)
    rows = flat // matrix.shape[1]
    return rows, flat - rows * matrix.shape[1]


class _Stop(Exception):
    """Raised inside the loop to end exploration early with a reason."""


class _Explorer:
    """The mutable state of one exploration; `explore` is its only user.

    Frontier blocks are column-major, shape ``(places, n)``: gathering the rows of a
    transition's input places is then a copy of contiguous memory, and enabling for a
    block is a ``(transitions, n)`` boolean matrix.
    """

    def __init__(
        self,
        cn: CompactNet,
        max_states: int | None,
        time_limit: float | None,
        reducer: StubbornSets | None,
        progress: ProgressCallback | None,
        chunk: int,
        clock: Clock,
    ) -> None:
        self.cn = cn
        self.max_states = max_states
        self.time_limit = time_limit
        self.reducer = reducer
        self.progress = progress
        self.chunk = chunk
        self.clock = clock
        self.start = clock()
        self.index_type = (
            np.int32 if max_states is not None and max_states < np.iinfo(np.int32).max else np.int64
        )
        self.via_type = np.int16 if cn.n_transitions < np.iinfo(np.int16).max else np.int32
        inc_t, inc_col = np.nonzero(cn.inc_places >= 0)
        self.inc_t = inc_t.astype(np.int64)
        self.inc_p = cn.inc_places[inc_t, inc_col]
        self.inc_amount = cn.inc_amounts[inc_t, inc_col]
        self._set_layout(Layout.initial_guess(cn))
        self.widenings = np.zeros(cn.n_places, dtype=np.int64)  # per place
        self.store = KeyStore(self.layout.n_words)
        self.parents: list[npt.NDArray[np.integer]] = [np.zeros(1, dtype=self.index_type)]
        self.via: list[npt.NDArray[np.integer]] = [np.zeros(1, dtype=self.via_type)]
        self.dead: list[npt.NDArray[np.int64]] = []
        self.fired = np.zeros(cn.n_transitions, dtype=bool)
        self.bounds = cn.initial.copy()
        self.max_marking = int(cn.initial.sum())
        self.edges = 0
        self.layer_starts = [0]
        self.stopped: str | None = None

    def _set_layout(self, layout: Layout) -> None:
        cn = self.cn
        self.layout = layout
        self.dtype = row_dtype(layout, cn)
        self.key_delta = layout.key_deltas(cn.delta)
        self.key_pos = layout.key_deltas(np.maximum(cn.delta, 0))
        self.key_neg = layout.key_deltas(np.maximum(-cn.delta, 0))
        boundary = np.zeros(layout.n_words, dtype=np.uint64)
        for p, width in enumerate(layout.bits):
            boundary[layout.word[p]] |= np.uint64(1 << (int(layout.shift[p]) + width))
        self.boundary = boundary
        self.col_delta = np.ascontiguousarray(cn.delta.T.astype(self.dtype))
        self.weights = [self._fit(g.weights)[:, :, None] for g in cn.groups]
        limits = layout.limits
        self.inc_threshold = (limits[self.inc_p] - self.inc_amount)[:, None]
        padding = cn.inc_places < 0
        padded = np.append(limits, 0)  # index -1 (padding) lands on the extra 0
        self.edge_threshold = np.where(
            padding, np.iinfo(np.int64).max, padded[cn.inc_places] - cn.inc_amounts
        )
        self.at_risk_from = limits - cn.max_increase  # a count >= this may overflow

    def _fit(self, values: npt.NDArray[np.int64]) -> npt.NDArray[np.integer]:
        """``values`` in the row dtype when they fit (fast compares), else as is."""
        info = np.iinfo(self.dtype)
        if values.size == 0 or (values.max() <= info.max and values.min() >= info.min):
            return values.astype(self.dtype)
        return values

    # -- one step --------------------------------------------------------------------

    def enabled(self, cols: npt.NDArray[np.integer]) -> npt.NDArray[np.bool_]:
        """``(T, n)`` matrix: transition ``t`` enabled in marking column ``i``."""
        out = np.empty((self.cn.n_transitions, cols.shape[1]), dtype=bool)
        for group, weights in zip(self.cn.groups, self.weights, strict=True):
            size = group.places.shape[1]
            if size == 0:
                out[group.transitions] = True
                continue
            ok = cols[group.places[:, 0]] >= weights[:, 0]
            for k in range(1, size):
                ok &= cols[group.places[:, k]] >= weights[:, k]
            out[group.transitions] = ok
        return out

    def overflow(
        self,
        cols: npt.NDArray[np.integer],
        enabled: npt.NDArray[np.bool_],
        edges: tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]],
    ) -> dict[int, int]:
        """Places whose bit field some enabled firing would overflow, each with the
        largest count it would reach; empty if none (the usual case).

        Only places whose count in the block is close to the field limit are checked,
        per increasing arc over the block or per edge, whichever touches fewer values.
        """
        risky = cols.max(axis=1, initial=0) >= self.at_risk_from
        if not risky.any():
            return {}
        trans, src = edges
        arcs = np.flatnonzero(risky[self.inc_p])
        if arcs.size * cols.shape[1] <= trans.size * self.cn.inc_places.shape[1]:
            hit = cols[self.inc_p[arcs]] >= self.inc_threshold[arcs]
            hit &= enabled[self.inc_t[arcs]]
            if not hit.any():
                return {}
            arc, col = np.nonzero(hit)
            places = self.inc_p[arcs[arc]]
            amounts = self.inc_amount[arcs[arc]]
        else:
            gathered = self.cn.inc_places[trans]
            values = cols[np.maximum(gathered, 0), src[:, None]]
            hit = values >= self.edge_threshold[trans]
            if not hit.any():
                return {}
            edge, slot = np.nonzero(hit)
            places = gathered[edge, slot]
            amounts = self.cn.inc_amounts[trans[edge], slot]
            col = src[edge]
        reached = cols[places, col].astype(np.int64) + amounts
        needed: dict[int, int] = {}
        for p, v in zip(places.tolist(), reached.tolist(), strict=True):
            needed[p] = max(needed.get(p, 0), v)
        return needed

    def successor_keys(
        self,
        cols: npt.NDArray[np.integer],
        base: int,
        edges: tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]],
    ) -> tuple[npt.NDArray[np.uint64] | None, dict[int, int]]:
        """Keys of the successors along ``edges``, and the places whose bit field some
        firing overflows (as `overflow`); keys are ``None`` when that is not empty.

        When some count in the block is close to its field limit, the keys are
        computed as ``(key - consumed) + produced``: the subtraction never borrows
        across fields (the transition is enabled), so a field overflows exactly when
        the addition carries into the bit above it, which ``sum ^ a ^ b`` shows for
        all fields of all edges at once.
        """
        trans, src = edges
        keys = self.store.keys.take(base + src, axis=0)
        risky = cols.max(axis=1, initial=0) >= self.at_risk_from
        if not risky.any():
            keys += self.key_delta.take(trans, axis=0)
            return keys, {}
        keys -= self.key_neg.take(trans, axis=0)
        produced = self.key_pos.take(trans, axis=0)
        carries = keys + produced
        keys, carries = carries, carries ^ keys
        carries ^= produced
        carries &= self.boundary
        if not np.count_nonzero(carries):
            return keys, {}
        bad = np.flatnonzero(carries.any(axis=1))
        t_bad, s_bad = trans[bad], src[bad]
        gathered = self.cn.inc_places[t_bad]
        reached = cols[np.maximum(gathered, 0), s_bad[:, None]].astype(np.int64)
        reached += self.cn.inc_amounts[t_bad]
        hit = (gathered >= 0) & (reached >= self.layout.limits[np.maximum(gathered, 0)])
        needed: dict[int, int] = {}
        for p, v in zip(gathered[hit].tolist(), reached[hit].tolist(), strict=True):
            needed[p] = max(needed.get(p, 0), v)
        if not needed:  # cannot happen (a carry means an overflow); stay exact anyway
            return None, self.overflow(cols, self.enabled(cols), edges)
        return None, needed

    def widen(self, needed: dict[int, int], blocks: list[npt.NDArray[np.integer]]) -> None:
        """Re-pack every stored key with wider fields for the ``needed`` places and
        convert the frontier ``blocks`` (in place) to the new row dtype."""
        layout = self.layout.widened(needed)
        # Re-packing costs a pass over every stored key: widen, in the same pass, the
        # other fields that were widened twice already and are half full again (counts
        # that keep growing), if that costs at most one more key word. Only the packing
        # changes, never a count.
        for p in needed:
            self.widenings[p] += 1
        growing = (self.widenings >= 2) & (self.bounds >= self.layout.limits // 2)
        growing &= 2 * np.asarray(self.layout.bits, dtype=np.int64) <= MAX_FIELD_BITS
        extra = {p: int(self.bounds[p]) for p in np.flatnonzero(growing).tolist()}
        if extra:
            ahead = self.layout.widened({**extra, **needed})
            if ahead.n_words <= layout.n_words + 1:
                layout = ahead
        if max(layout.bits) > MAX_FIELD_BITS:
            p = max(needed, key=lambda q: needed[q])
            name = self.cn.net.places[p].name
            self.stopped = (
                f"token count of place '{name}' reached {needed[p]} (over 2**{MAX_FIELD_BITS});"
                " the net is unbounded"
            )
            raise _Stop
        old, keys = self.layout, self.store.keys
        packed = np.empty((keys.shape[0], layout.n_words), dtype=np.uint64)
        step = 1 << 16
        for s in range(0, keys.shape[0], step):
            packed[s : s + step] = layout.pack(old.unpack(keys[s : s + step]))
        self._set_layout(layout)
        self.store = KeyStore.of(packed)
        for i, block in enumerate(blocks):
            blocks[i] = block.astype(self.dtype)

    def insert(
        self,
        cols: npt.NDArray[np.integer],
        base: int,
        src: npt.NDArray[np.int64],
        trans: npt.NDArray[np.int64],
        out: list[npt.NDArray[np.integer]],
        keys: npt.NDArray[np.uint64] | None = None,
    ) -> Added:
        """Store the successors of edges ``(src, trans)`` (their ``keys`` if already
        computed); new columns go to ``out``."""
        if keys is None:
            keys = self.store.keys.take(base + src, axis=0)
            keys += self.key_delta.take(trans, axis=0)
        limit = None if self.max_states is None else self.max_states - self.store.size
        added = self.store.add(keys, limit)
        first = added.first
        if first.size:
            self.parents.append((base + src[first]).astype(self.index_type))
            self.via.append(trans[first].astype(self.via_type))
            new = cols.take(src[first], axis=1)
            new += self.col_delta.take(trans[first], axis=1)
            out.append(new)
            self.bounds = np.maximum(self.bounds, new.max(axis=1))
            self.max_marking = max(self.max_marking, int(new.sum(axis=0, dtype=np.int64).max()))
        if added.cut:
            self.stopped = f"state budget reached (max_states={self.max_states})"
        return added

    def step(
        self, cols: npt.NDArray[np.integer], base: int, out: list[npt.NDArray[np.integer]]
    ) -> npt.NDArray[np.integer]:
        """Expand the frontier block ``cols`` (states ``base ...``); returns ``cols`` in
        the current row dtype (it changes when fields widen)."""
        keys = None
        while True:
            enabled = self.enabled(cols)
            edges = _nonzero(enabled)
            if self.reducer is None:
                keys, needed = self.successor_keys(cols, base, edges)
            else:
                needed = self.overflow(cols, enabled, edges)
            if not needed:
                break
            blocks = [cols, *out]
            self.widen(needed, blocks)
            cols, out[:] = blocks[0], blocks[1:]
        any_enabled = enabled.any(axis=0)
        self.fired |= enabled.any(axis=1)
        if not any_enabled.all():
            self.dead.append(base + np.flatnonzero(~any_enabled))
        if self.reducer is None:
            trans, src = edges
            self.edges += src.size
            self.insert(cols, base, src, trans, out, keys)
            return cols
        reduced = self.reducer.reduce(cols, enabled)
        rtrans, rsrc = _nonzero(reduced)
        self.edges += rsrc.size
        added = self.insert(cols, base, rsrc, rtrans, out)
        if not self.reducer.needs_proviso or self.stopped:
            return cols
        # Cycle proviso: a marking whose reduced successors include one that was known
        # before it was expanded (stored earlier, or found first by another marking of
        # this block) is expanded fully, so every cycle of the reduced graph has a fully
        # expanded marking and no visible change is postponed forever.
        stale = added.known.copy()
        stale[added.unknown] = rsrc[added.leader] != rsrc[added.unknown]
        redo = np.zeros(cols.shape[1], dtype=bool)
        redo[rsrc[stale]] = True
        redo &= (reduced != enabled).any(axis=0)
        if redo.any():
            extra = enabled & ~reduced
            extra[:, ~redo] = False
            etrans, esrc = _nonzero(extra)
            self.edges += esrc.size
            self.insert(cols, base, esrc, etrans, out)
        return cols

    # -- the loop --------------------------------------------------------------------

    def run(self) -> None:
        cn = self.cn
        self.store.add(self.layout.pack(cn.initial[None, :]))
        frontier = cn.initial[:, None].astype(self.dtype)
        base = 0
        while frontier.shape[1]:
            out: list[npt.NDArray[np.integer]] = []
            width, c = frontier.shape[1], 0
            while c < width:
                size = self.block_size()
                cols = self.step(frontier[:, c : c + size], base + c, out)
                frontier = frontier.astype(self.dtype, copy=False)
                if self.stopped:
                    raise _Stop
                c += cols.shape[1]
                self.check_time(width - c, out)
            base += width
            if not out:
                break
            frontier = np.concatenate([b.astype(self.dtype, copy=False) for b in out], axis=1)
            self.layer_starts.append(base)

    def block_size(self) -> int:
        """Frontier columns for the next step: ``chunk``, fewer on nets with many
        enabled transitions per marking or many transitions, so that one step
        handles at most `EDGES_PER_STEP` edges and `CELLS_PER_STEP` cells of the
        enabled matrix (bounded temporaries, warmer caches)."""
        per_state = self.edges / max(1, self.store.size)
        by_edges = int(EDGES_PER_STEP / max(per_state, 1.0))
        by_matrix = CELLS_PER_STEP // max(1, self.cn.n_transitions)
        return max(min(256, self.chunk), min(self.chunk, by_edges, by_matrix))

    def check_time(self, left: int, out: list[npt.NDArray[np.integer]]) -> None:
        now = self.clock() - self.start
        if self.progress is not None:
            queued = left + sum(block.shape[1] for block in out)
            self.progress(
                ProgressInfo(self.store.size, self.edges, queued, len(self.layer_starts), now)
            )
        if self.time_limit is not None and now > self.time_limit:
            self.stopped = f"time limit reached ({self.time_limit:g} s)"
            raise _Stop


def explore(
    net: Net | CompactNet,
    *,
    max_states: int | None = DEFAULT_MAX_STATES,
    time_limit: float | None = None,
    por: bool = False,
    visible: Sequence[str] | None = None,
    progress: ProgressCallback | None = None,
    chunk: int = DEFAULT_CHUNK,
    clock: Clock = time.perf_counter,
) -> StateSpace:
    """Explore the reachable markings of ``net`` breadth first.

    Args:
        net: the net, or its `CompactNet` when exploring one net several times.
        max_states: stop after storing this many markings (``None``: no limit; an
            unbounded net then runs until its token counts pass ``2**60``).
        time_limit: stop after this many seconds (checked after every chunk).
        por: explore a stubborn-set reduced graph instead (`analysis.stubborn`): all
            deadlocks are kept; ``states``/``edges`` then count the reduced graph.
        visible: with ``por``, places a reachability question is about; the reduced
            graph then also keeps every reachable value of these places (visibility
            and cycle provisos), so `StateSpace.find` over them answers as the full
            graph would.
        progress: called after every chunk with a `ProgressInfo`
            (see `analysis.progress.ProgressPrinter`).
        chunk: frontier rows per vectorised step.
        clock: seconds counter; tests pass a fake one.

    Returns:
        The `StateSpace`; ``complete`` is false, with ``stopped_reason``, when a budget
        stopped it.
    """
    cn = net if isinstance(net, CompactNet) else CompactNet.from_net(net)
    reducer = None
    if por:
        vis = None if visible is None else [cn.net.place_index(p) for p in visible]
        reducer = StubbornSets(cn, vis)
    explorer = _Explorer(cn, max_states, time_limit, reducer, progress, chunk, clock)
    with contextlib.suppress(_Stop):  # a budget ran out; the reason is recorded
        explorer.run()
    seconds = clock() - explorer.start
    store = explorer.store
    parents = np.concatenate(explorer.parents)[: store.size]
    via = np.concatenate(explorer.via)[: store.size]
    dead = np.concatenate(explorer.dead) if explorer.dead else np.zeros(0, dtype=np.int64)
    return StateSpace(
        net=cn.net,
        states=store.size,
        edges=explorer.edges,
        place_bounds=explorer.bounds,
        max_tokens_place=int(explorer.bounds.max(initial=0)),
        max_tokens_marking=explorer.max_marking,
        deadlocks=np.sort(dead),
        fired_transitions=explorer.fired,
        complete=explorer.stopped is None,
        stopped_reason=explorer.stopped,
        seconds=seconds,
        stored_bytes=store.nbytes + parents.nbytes + via.nbytes,
        depth=len(explorer.layer_starts),
        reduced=por,
        layout=explorer.layout,
        keys=store.keys,
        parents=parents,
        via=via,
        layer_starts=np.asarray(explorer.layer_starts, dtype=np.int64),
    )
