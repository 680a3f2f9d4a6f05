"""Fast explicit exploration of the reachable markings of a `Net`.

Breadth first, one layer at a time, vectorised over the frontier with numpy:

1. a block of the frontier (markings as columns of small integers: the field values
   of `analysis.encoding.FieldNet`, one per count or component) is checked against
   every transition's preset at once, giving the enabled transitions of each marking
   as bit sets, one ``uint64`` per 64 transitions ANDed from a few tables indexed by
   field values (`_EnablingBits`), or where those tables do not fit, an enabled
   matrix; their set bits are the edges (all counted, as the MCC counts them); on nets
   with hundreds of transitions that take a component's token, those are looked up by
   the component's value instead (`_EnablingIndex`);
2. *sleep sets* (`SleepSets`) drop the edges whose successor another edge is sure to
   reach in the same layer, typically three quarters of them on concurrent nets: only
   the others are fired (sleep sets and self-loops are masks over the bit sets, or
   applied to the matrix, and only the fired edges are listed); of transitions with
   the same effect enabled in one marking, only the lowest is fired;
3. each fired edge yields its successor's *packed key* by one addition per key word
   (see `analysis.encoding.Layout`; one-hot components make most markings one word),
   never a full row;
4. the keys go through a vectorised open-addressing set (`KeyStore`) that numbers new
   markings as they are first met, so state numbers grow with BFS depth
   (``layer_starts``) and parents always precede their children; on nets with several
   enabled transitions per marking a cheap direct-mapped table drops most repeats of
   a step first (`_Explorer.unrepeated`), keeping every first occurrence in order;
5. new markings get no columns: the next layer is unpacked from the stored keys a
   block at a time (`Layout.fields`; the states of a layer are numbered
   consecutively), and the bounds are recorded then (`_Explorer.frontier`).

Narrow layers (deep state spaces: long missions, counters) are explored several layers
per insertion instead, see `_Explorer.speculate`: numpy's cost per call, not per
marking, is what limits a layer of a hundred markings.

Counts are exact: packed keys are injective on reachable markings, multi-word keys
are compared in full, ``edges`` counts (marking, enabled transition)
pairs, and a count field that some firing would overflow is widened (every stored key
is re-packed) before any successor using it is trusted; past ``2**60`` tokens
exploration stops with a reason. A state keeps neither its parent nor the transition
that found it: `StateSpace.trace_to` finds a parent again among the stored markings of
the layer before (`analysis.parents`), one layer up at a time, so it returns a shortest
firing sequence (sleep sets keep every state at its BFS depth).

Memory per stored state: the bytes of a one-word key its fields reach
(``Layout.word_bytes``: 4 of Referendum-PT-0015's 30 bits, 5 of Peterson-PT-3's 34;
likewise for keys of ``W > 1`` words, see `_stored_bytes`) and 5 to 10 bytes of hash
table (a 3- or 4-byte state number per slot, load 0.4 to 0.6, see `KeyStore`): about 9
to 18 bytes for one-word nets. What else is
resident while the search runs, and what bounds it: the sleep sets of the layer being
expanded and of the next one (in maps of their own that are unmapped as they are read,
only their nonzero words where layers are wide: `analysis.spool`), one step's
temporaries (`BLOCK_TEMPORARY_BYTES`), and what the C heap keeps free, which is given
back before the table grows (`analysis.allocator.release_free_heap`).

Typical use::

    space = explore(net, max_states=1_000_000)
    if space.deadlocks.size:
        print(space.trace_names(int(space.deadlocks[0])))
    hit = space.find(lambda m: (m[:, p] > 0) & (m[:, q] > 0))
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import numpy.typing as npt

from analysis.allocator import heap_free_bytes, settle_allocator
from analysis.budget import (
    Budget,
    BudgetExceeded,
    memory_limit_reason,
    work_limit_reason,
)
from analysis.encoding import (
    MAX_FIELD_BITS,
    NEVER,
    RESERVE_LIMIT,
    Added,
    Arcs,
    CompactNet,
    FieldGroup,
    FieldNet,
    Growable,
    KeyStore,
    KeyView,
    Layout,
    invariant_place_bounds,
    one_hot_components,
    row_dtype,
)
from analysis.inputs import has_inputs, input_edges_at, legal_trace, terminal_rows
from analysis.parents import parent_step
from analysis.progress import ProgressCallback, ProgressInfo
from analysis.spool import RowSpool
from analysis.stubborn import StubbornSets
from coral_lang.net import Net

DEFAULT_MAX_STATES = 5_000_000
"""Default state budget: about 150 MB on typical nets, seconds of work."""

DEFAULT_CHUNK = 1 << 15
"""Frontier rows handled per vectorised step: bounds the temporaries to a few MB."""

EDGES_PER_STEP = 1 << 19
"""Most edges one vectorised step handles (about 40 MB of temporaries at most)."""

STEP_BYTES = 64 << 20
"""Most bytes of successor keys (and, in a narrow round, columns) one vectorised step
builds: `EDGES_PER_STEP` assumes keys of a word or two, while a net of 10,000 places of
2-bit counts has keys of 320 words, where that many edges would take gigabytes."""

BLOCK_TEMPORARY_BYTES = 8 << 20
"""Bytes of temporaries a step is sized for at least (`_Explorer.block_size`, by
`state_bytes` and `edge_bytes`); at most a quarter of the store's bytes beyond the next
layer's sleep sets when that is more. They are freed after the step, but the largest
step sets the heap's high-water mark on top of the store and the sleep sets: on
SharedMemory-PT-000010 (4 words of sleep sets, 3 edges fired per marking, layers whose
sleep sets outweigh the store) blocks of `DEFAULT_CHUNK` markings took 15 MB, 8
resident bytes per stored state, and any budget above 8 MB added 2 to 4 of them; on
Peterson-PT-3 (332 transitions tested a block at a time) small blocks cost time, and
the quarter of the store gives back part of it as the store grows."""

SPARSE_SLEEP_SHARE = 4
"""A layer's successors keep sparse sleep sets (`analysis.spool.RowSpool`) when the
layer's own sleep sets would take at least a quarter of the store's bytes."""

CELLS_PER_STEP = 1 << 23
"""Most (transition, marking) cells of one step's enabled matrix (8 MB of booleans)."""

BLOCK_CELLS = 1 << 22
"""Most (marking, place or field) cells decoded at once (32 MB of ``int64``)."""

Markings = npt.NDArray[np.int64]
Predicate = Callable[[Markings], npt.NDArray[np.bool_]]
StopWhen = Callable[[int, Markings], bool]
"""``stop_when(first_state, markings)``: see `explore`."""

STOPPED_BY_REQUEST = "stopped: stop_when asked to"
"""``stopped_reason`` when `explore`'s ``stop_when`` ended the search."""


@dataclass
class StateSpace:
    """What `explore` learnt about a net.

    Attributes:
        net: the explored net.
        states: reachable markings found (all of them when ``complete``).
        edges: (marking, enabled transition) pairs fired; with ``por`` only the
            reduced ones.
        place_bounds: most tokens each place held in any stored marking whose bounds
            were recorded: the first ``recorded`` states (all of them, unless a time
            limit ran out with states stored but not expanded: those are recorded
            only until `RECORD_GRACE` seconds past the deadline).
        max_tokens_place: ``max(place_bounds)``.
        max_tokens_marking: most tokens in one stored marking.
        deadlocks: numbers of all dead states found (no transition enabled; on a net
            with operator inputs, every *terminal* state: no transition but inputs
            enabled, see `analysis.inputs`), ascending, so ``deadlocks[0]`` has the
            shortest trace; ``int32`` when the state limit keeps state numbers below
            2**30, else ``int64``.
        fired_transitions: ``fired_transitions[t]`` is whether ``t`` is enabled in some
            stored marking. With ``por`` this under-approximates (reduced graph).
        complete: whether every reachable marking was stored.
        stopped_reason: why exploration stopped early (``None`` when complete).
        seconds: wall time of the exploration.
        stored_bytes: bytes of the arrays kept for the states (keys and table).
        depth: BFS layers explored (the deepest state is at ``depth - 1``).
        reduced: whether partial-order reduction was on.
        reduction_note: with ``por``, why the reduction was switched off part-way
            (it pruned almost nothing on a sample of markings), else ``None``.
        recorded: the states counted in ``place_bounds``, ``max_tokens_place`` and
            ``max_tokens_marking`` (see ``place_bounds``; -1: all of them).
    """

    net: Net
    states: int
    edges: int
    place_bounds: npt.NDArray[np.int64]
    max_tokens_place: int
    max_tokens_marking: int
    deadlocks: npt.NDArray[np.signedinteger[Any]]
    fired_transitions: npt.NDArray[np.bool_]
    complete: bool
    stopped_reason: str | None
    seconds: float
    stored_bytes: int
    depth: int
    reduced: bool
    layout: Layout = field(repr=False)
    keys: KeyView = field(repr=False)
    store: KeyStore = field(repr=False)
    compact: CompactNet = field(repr=False)
    layer_starts: npt.NDArray[np.int64] = field(repr=False)
    reduction_note: str | None = None
    recorded: int = -1

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
        return self.layout.unpack(self.keys[:]).astype(np.int64)

    def iter_markings(self, chunk: int = 1 << 16) -> Iterator[tuple[int, Markings]]:
        """``(first_state, markings)`` blocks of at most ``chunk`` states, in order (fewer
        on nets with many places: a block stays within `BLOCK_CELLS` counts)."""
        chunk = max(1, min(chunk, BLOCK_CELLS // max(1, len(self.net.places))))
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
        state ``index`` (shortest in the reduced graph when ``reduced``). On a net with
        operator inputs every input in it fires while the run is on
        (`analysis.inputs.legal_trace`)."""
        path: list[int] = []
        # Neither parent numbers nor arriving transitions (1 or 2 bytes a state) are
        # stored: each parent is found again among the stored markings of the layer
        # before.
        while index > 0:
            index, t = parent_step(self.compact, self.layout, self.store, self.layer_starts, index)
            path.append(t)
        path.reverse()
        if has_inputs(self.net):
            legal = legal_trace(self.net, path)
            assert legal is not None, "a state space with inputs starts from a live marking"
            return legal
        return path

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


Edges = tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]
"""``(transitions, sources)``: one entry per edge; sources are block columns."""

SLEEP_WORDS = 8
"""Sleep sets track at most ``64 * SLEEP_WORDS`` transitions (the first ones); the
others are always fired. Tracking fewer only means less reduction."""

SLEEP_MIN_DEGREE = 1.5
"""Sleep sets are used while the explored markings enable at least this many
transitions on average; below, there is little to save and their bookkeeping costs
more than it saves (deep, narrow state spaces)."""

DEFAULT_RESERVE = 1 << 20
"""States to reserve address space for when there is no state budget."""

DEAD_RESERVE_SHARE = 4
"""The dead markings' array reserves address space for this share of the reserved
states (it grows by copying beyond: few nets have that many dead markings)."""

NARROW_WIDTH = 1024
"""Frontiers up to this many markings are explored several layers at a time (deep,
narrow state spaces: long missions, counters), see `_Explorer.speculate`."""

NARROW_CANDIDATES = 1 << 14
"""Most candidates one narrow round generates before it inserts them."""

NARROW_LEVELS = 512
"""Most layers one narrow round explores."""

REPEATS_MIN = 256
"""A narrow level of at least this many candidates, and half again as many as the
level above, drops its repeated markings before it is expanded (`_Round.drop_repeats`):
on nets with many enabled transitions most candidates of a level are the same few
markings reached in different orders (Dekker: 60 enabled, 16 fired, 1 new per
marking), and each copy would be expanded again."""

KEYED_ARCS = 2
"""Transitions with at most this many input fields, one of them a component, are
enabled by lookup (`_EnablingIndex`)..."""

KEYED_SHARE = 0.75
"""... when they are at least this share of all transitions (otherwise the dense test
of the others dominates, and the lookup only adds a pass and a sort)..."""

KEYED_MIN = 256
"""... and there are at least this many transitions: below, testing every transition in
every marking costs less than the lookup (Referendum, 31 transitions: 40 % slower)."""

INSERT_BYTES = 64
"""Bytes of temporaries per candidate while a batch is inserted (hashes, slots,
positions, probe results), beside its key and its successor's column."""

RECORD_GRACE = 0.1
"""Seconds past a time limit (or from the end of a search stopped before it) that the
bounds of states stored but not expanded are still recorded (`StateSpace.recorded`)."""

RECORD_CELLS = 1 << 18
"""Most (marking, field) cells `_Explorer.record_pending` decodes at once (2 MB of
``int64``): it also runs after a search stopped at its memory limit."""

BLOCK_TEMPORARIES = 64 << 20
"""Bytes of temporaries a block-wise pass over the store (a re-packing) may hold."""

PACK_WIDE_KEYS = True
"""Whether keys of several words are stored byte-granular too (see `_stored_bytes`);
off, they are stored as whole words (tests compare the two)."""

GUARD_MIN_BYTES = 1 << 20
"""Smallest allocation `_Explorer.guard` checks against the memory limit (reading the
process's memory costs about 50 us: DoubleExponent-PT-003's 18,128 narrow levels took
2.3x as long with a limit as without); smaller ones are left to the budget's own
periodic check (`Budget.expired`)."""

REPEAT_FILTER_MIN = 1 << 12
"""Fewest successor keys of a step worth filtering for repeats (`_Explorer.unrepeated`)..."""

REPEAT_FILTER_DEGREE = 2.0
"""... on nets whose markings enable at least this many transitions on average."""

BIT_TABLE_ROWS = 1 << 12
"""Most rows of one table of `_EnablingBits` (32 KiB per word of transitions)..."""

BIT_TABLES_MIN = 4
"""... and enabling goes by such tables when there are at most this many of them, or
one per `BIT_TABLE_TRANSITIONS` transitions; more, and the dense test costs less."""

BIT_TABLE_TRANSITIONS = 16


DENSE_DELTA_CELLS = 1 << 24
"""Largest places x transitions for a dense effect matrix (successor columns by one
gather); larger nets add their sparse effects instead."""


POR_SAMPLE = 4096
"""Markings with a choice (two or more enabled transitions) that partial-order
reduction is judged on: if it pruned almost none of their firings, the rest of the
search expands every marking fully."""

POR_USELESS = 0.95
"""Share of the enabled firings of the sample that the stubborn sets kept, from which
the reduction is judged useless. Expanding fully is always sound (every enabled set is
stubborn), and it costs a fraction of computing stubborn sets that end up full: on
TokenRing-PT-010 and Dekker-PT-015 they kept every firing and cost 30-60x the search."""


class SleepSets:
    """Sleep sets for breadth-first search, which keep every state and its BFS depth.

    Transitions ``t`` and ``s`` are *independent* when neither lowers an input place of
    the other: where both are enabled, firing one leaves the other enabled, and both
    orders reach the same marking. Order transitions by index and layer ``k`` by the
    order the search numbers it in; the *first arrival* of a state of layer ``k + 1`` is
    its smallest edge ``(p, s)`` from layer ``k`` (source number, then transition). The
    explorer fires edges in exactly that order, so a new state's first arrival is the
    edge that found it. Its sleep set is then

        ``sleep(m) = (sleep(p) | {u enabled in p, u < s}) & independent(s)``

    and the transitions in ``sleep(m)`` are not fired from ``m``. Why nothing is lost:
    take, for any reachable ``m'``, its lexicographically smallest shortest path ``w``.
    If its last edge ``(m, t)`` were asleep, the sleep set's origin gives a position
    ``j`` with ``t < w_j``, ``t`` enabled before ``w_j`` and independent of ``w_j ..
    w_n``; moving ``t`` there gives another shortest path to ``m'`` that is smaller,
    a contradiction. So every edge of these paths is fired and every state is found in
    its own layer. Transitions that change nothing are never fired either, nor (with
    enabling as bit sets) a transition with the effect of a lower one enabled in the
    same marking, asleep or not (`_EnablingBits._twin_runs`): firing that one instead
    gives another shortest path that is smaller, so such an edge is on no smallest path.

    Sleep sets only ever drop edges; states, edges counted, deadlocks and bounds are
    those of the full graph. Each frontier state carries ``words`` ``uint64`` of sleep
    bits (the first ``64 * words`` transitions are tracked).
    """

    def __init__(self, cn: CompactNet) -> None:
        n_t = cn.n_transitions
        self.tracked = min(n_t, 64 * SLEEP_WORDS)
        self.words = max(1, -(-self.tracked // 64))
        t = np.arange(n_t, dtype=np.int64)
        inside = t < self.tracked
        self.word = np.where(inside, t // 64, 0)
        self.bit = np.where(inside, np.left_shift(np.uint64(1), (t % 64).astype(np.uint64)), 0)
        self.bit = self.bit.astype(np.uint64)
        self.independent = self._independence(cn)
        # `wake` reads the sleep bits a byte at a time: tracked transition ``t`` is bit
        # ``t % 8`` of byte ``byte[t]`` of its marking's ``8 * words`` bytes.
        tracked = np.arange(self.tracked)
        within = (tracked % 64) // 8
        if sys.byteorder == "big":
            within = 7 - within
        self.byte = (tracked // 64) * 8 + within
        self.byte_bit = np.left_shift(1, tracked % 8).astype(np.uint8)[:, None]
        # below[t]: the tracked transitions before t, as sleep bits
        below = np.zeros((n_t, self.words), dtype=np.uint64)
        low_bits = np.left_shift(np.uint64(1), (t % 64).astype(np.uint64)) - np.uint64(1)
        for k in range(self.words):
            below[:, k] = np.where(t // 64 > k, ~np.uint64(0), np.where(t // 64 == k, low_bits, 0))
        self.below = below & self._everything()

    def _masks(
        self, cn: CompactNet, rows: npt.NDArray[np.int64], places: npt.NDArray[np.int64]
    ) -> npt.NDArray[np.uint64]:
        """Per place, the bits of the tracked transitions among ``rows`` (arcs)."""
        out = np.zeros(cn.n_places * self.words, dtype=np.uint64)
        sel = rows < self.tracked
        np.bitwise_or.at(out, places[sel] * self.words + self.word[rows[sel]], self.bit[rows[sel]])
        return out.reshape(cn.n_places, self.words)

    def _independence(self, cn: CompactNet) -> npt.NDArray[np.uint64]:
        """``(T, words)``: per transition, the tracked transitions independent of it."""
        n_t, w = cn.n_transitions, self.words
        lowers = cn.effects.values < 0
        low_t, low_p = cn.effects.rows[lowers], cn.effects.places[lowers]
        in_t, in_p = cn.inputs.rows, cn.inputs.places
        consumers = self._masks(cn, in_t, in_p)  # tracked transitions reading each place
        lowerers = self._masks(cn, low_t, low_p)  # tracked transitions lowering it
        flat = np.zeros(n_t * w, dtype=np.uint64)
        for k in range(w):
            np.bitwise_or.at(flat, low_t * w + k, consumers[low_p, k])
            np.bitwise_or.at(flat, in_t * w + k, lowerers[in_p, k])
        dependent = flat.reshape(n_t, w)
        own = np.arange(n_t) < self.tracked
        dependent[own, self.word[own]] |= self.bit[own]
        return ~dependent & self._everything()

    def _everything(self) -> npt.NDArray[np.uint64]:
        """The bits of all tracked transitions."""
        everything = np.zeros(self.words, dtype=np.uint64)
        for t in range(self.tracked):
            everything[t // 64] |= np.uint64(1 << (t % 64))
        return everything

    def fired_sets(self, fired: npt.NDArray[np.bool_]) -> npt.NDArray[np.uint64]:
        """``(n, words)``: per column of a block's ``(T, n)`` matrix of fired edges, the
        tracked transitions fired, as sleep bits (8 shifts over bytes)."""
        n = fired.shape[1]
        padded = np.zeros((64 * self.words, n), dtype=np.uint8)
        padded[: self.tracked] = fired[: self.tracked]
        by_bit = padded.reshape(8 * self.words, 8, n)
        packed = by_bit[:, 0].copy()
        for i in range(1, 8):
            packed |= by_bit[:, i] << np.uint8(i)
        little = np.ascontiguousarray(packed.T).view("<u8")
        return little.astype(np.uint64, copy=False)

    def awake(self, sleep: npt.NDArray[np.uint64], edges: Edges) -> npt.NDArray[np.bool_]:
        """Which edges are not asleep; ``sleep`` is ``(n, words)`` for the block."""
        trans, src = edges
        if self.words == 1:
            word = sleep.reshape(-1).take(src)
        else:
            word = sleep.reshape(-1).take(src * self.words + self.word.take(trans))
        word &= self.bit.take(trans)
        awake: npt.NDArray[np.bool_] = word == 0
        return awake

    def wake(self, enabled: npt.NDArray[np.bool_], sleep: npt.NDArray[np.uint64]) -> None:
        """Clear the asleep entries of a block's ``(T, n)`` enabled matrix (``sleep`` is
        ``(n, words)``): `awake` on the matrix, a few passes over bytes instead of a
        gather per edge (Dekker enables 60 transitions per marking and fires 16)."""
        n = sleep.shape[0]
        per_byte = np.ascontiguousarray(sleep).view(np.uint8).reshape(n, 8 * self.words)
        bits = np.ascontiguousarray(per_byte.T).take(self.byte, axis=0)
        bits &= self.byte_bit
        enabled[: self.tracked] &= bits == 0

    def successors(
        self,
        sleep: npt.NDArray[np.uint64] | None,
        edges: Edges,
        first: npt.NDArray[np.int64],
        fired: npt.NDArray[np.uint64] | None = None,
    ) -> npt.NDArray[np.uint64]:
        """Sleep sets ``(len(first), words)`` of the new states found by the fired
        ``edges`` at positions ``first``, which are in (source, transition) order;
        ``fired`` (`fired_sets`), when given, says which transitions each source fired:
        then the work is per new state, not per edge."""
        trans, src = edges
        rep_t, rep_s = trans.take(first), src.take(first)
        if fired is not None:
            out = fired.take(rep_s, axis=0)
            out &= self.below.take(rep_t, axis=0)
            if sleep is not None:
                out |= sleep.take(rep_s, axis=0)
            out &= self.independent.take(rep_t, axis=0)
            return out
        # The fired transitions of the same source before each first arrival are the
        # enabled u < s (asleep ones are in sleep(p)): an exclusive prefix OR of their
        # bits within the source's run, computed as a prefix sum (the bits are distinct).
        runs = np.searchsorted(src, rep_s)
        out = np.empty((first.size, self.words), dtype=np.uint64)
        bits = self.bit.take(trans)
        for k in range(self.words):
            mine = bits if self.words == 1 else np.where(self.word.take(trans) == k, bits, 0)
            total = np.cumsum(mine, dtype=np.uint64)
            total -= mine
            out[:, k] = total.take(first) - total.take(runs)
        if sleep is not None:
            out |= sleep.take(rep_s, axis=0)
        out &= self.independent.take(rep_t, axis=0)
        return out


class _Round:
    """The levels of one narrow round (see `_Explorer.speculate`): per level, the
    candidates' columns and keys, and how many transitions each candidate of the level
    above enables (``counts[0]`` is for the layer the round started from). Which
    transition produced a candidate is not kept: no state keeps it
    (`analysis.parents`)."""

    def __init__(self) -> None:
        self.cols: list[npt.NDArray[np.integer]] = []
        self.keys: list[npt.NDArray[np.uint64]] = []
        self.counts: list[npt.NDArray[np.int64]] = []
        self.ends: list[int] = []  # cumulative candidates after each level
        self.total = 0
        self.cells = 0  # enabled-matrix cells computed so far

    def add(
        self,
        counts: npt.NDArray[np.int64],
        cols: npt.NDArray[np.integer],
        keys: npt.NDArray[np.uint64],
        cells: int,
    ) -> None:
        """One more level (``counts`` is for the level it was expanded from, whose
        enabled matrix had ``cells`` cells)."""
        self.cells += cells
        self.counts.append(counts)
        self.cols.append(cols)
        self.keys.append(keys)
        self.total += keys.shape[0]
        self.ends.append(self.total)

    def drop_repeats(self) -> None:
        """Keep only the first candidate of each marking of the last level, in order.

        Exact: a repeat's successors are its first copy's, which the next level gets
        anyway, at positions before the repeat's; every marking's first candidate, and
        so the states' numbers and edges stay the same."""
        keys = self.keys[-1]
        first = _first_rows(keys)
        if first.size == keys.shape[0]:
            return
        self.keys[-1] = keys.take(first, axis=0)
        self.cols[-1] = self.cols[-1].take(first, axis=1)
        self.total -= keys.shape[0] - first.size
        self.ends[-1] = self.total

    def joined(
        self,
    ) -> tuple[npt.NDArray[np.uint64], npt.NDArray[np.integer], npt.NDArray[np.int64]]:
        """All candidates in level order: keys, columns, and how many
        transitions each enables (``-1`` on the last level, which was not expanded).

        The levels are released as they are joined (but ``counts[0]``, the starting
        layer's): a round's candidates are not held twice while the store inserts them,
        which is when a deep, narrow search peaks (DoubleExponent-PT-003: 16,000
        candidates of 30 fields, 5 MB held twice)."""
        last = self.keys[-1].shape[0]
        keys = np.concatenate(self.keys)
        self.keys = []
        cols = np.concatenate(self.cols, axis=1)
        self.cols = []
        counts = np.concatenate([*self.counts[1:], np.full(last, -1, dtype=np.int64)])
        self.counts = self.counts[:1]
        return keys, cols, counts


def _first_rows(keys: npt.NDArray[np.uint64]) -> npt.NDArray[np.int64]:
    """Positions of the first occurrence of each distinct row of ``keys`` ``(n, W)``,
    ascending (a stable sort, then neighbours compared in full: exact)."""
    if keys.shape[1] == 1:
        order = np.argsort(keys[:, 0], kind="stable")
    else:
        order = np.lexsort(keys.T[::-1])  # stable too
    ordered = keys.take(order, axis=0)
    fresh = np.empty(keys.shape[0], dtype=bool)
    fresh[:1] = True
    np.any(ordered[1:] != ordered[:-1], axis=1, out=fresh[1:])
    return np.sort(order[fresh])


class _EnablingIndex:
    """Which transitions `_Explorer.edges_of` looks up by the value of a field instead
    of testing them in every marking.

    A transition with an input place in a component tests ``field == value`` and can
    only be enabled where that field holds that value. Such transitions are listed per
    field, by value (each keyed on its component input with the most values: fewest
    candidates per lookup); a block's candidates are the lists its field values select,
    and only their other input arcs are tested. A Peterson marking then costs a few
    candidates instead of 332 transition tests. Transitions with count inputs only are
    tested densely (``dense``, presets ``groups`` renumbered from 0).

    Attributes:
        dense: transitions tested densely.
        groups: their presets.
        keyed: per key field, ``(field, start, transitions)``: the transitions keyed on
            value ``v`` are ``transitions[start[v]:start[v + 1]]``.
        rest_width: most other input arcs of a keyed transition.
        rest_fields, rest_low, rest_exact: those arcs, ``(rest_width, T)``, padded with
            the zero row ``n_fields`` tested ``>= 0``.
    """

    def __init__(self, fnet: FieldNet, layout: Layout, n_t: int) -> None:
        n_f = fnet.n_fields
        values = np.zeros(n_f + 1, dtype=np.int64)  # per field, its number of values
        for f, (members, onehot, first) in enumerate(
            zip(layout.members, layout.onehot, layout.first, strict=True)
        ):
            values[f] = len(members) + first if onehot else 0
        width = min(KEYED_ARCS, max((g.fields.shape[1] for g in fnet.groups), default=0))
        fields = np.full((n_t, width), n_f, dtype=np.int64)
        low = np.zeros((n_t, width), dtype=np.int64)
        exact = np.zeros((n_t, width), dtype=bool)
        wide = np.zeros(n_t, dtype=bool)  # more arcs than the index handles
        for g in fnet.groups:
            size = g.fields.shape[1]
            if size > width:
                wide[g.transitions] = True
                continue
            fields[g.transitions, :size] = g.fields
            low[g.transitions, :size] = g.low
            exact[g.transitions, :size] = g.exact
        never = np.zeros(n_t, dtype=bool)
        never[fnet.never] = True
        # A component arc scores its number of values plus one; a count arc less than
        # one, the less the more transitions produce into it (a rarely marked key lets
        # fewer candidates through); padding -1.
        count_arc = (fields < n_f) & ~exact
        raised = fnet.inc_fields[fnet.inc_fields >= 0]
        producers = np.bincount(raised, minlength=n_f + 1).astype(np.float64)
        rarity = 0.5 / (1.0 + producers[fields])
        score = np.where(exact, values[fields] + 1.0, np.where(count_arc, rarity, -1.0))
        key = score.argmax(axis=1) if width else np.zeros(n_t, dtype=np.int64)
        best = score.max(axis=1) if width else np.full(n_t, -1.0)
        has_key = (best >= 0) & ~wide
        if n_t < KEYED_MIN or np.count_nonzero(has_key) < KEYED_SHARE * n_t:
            has_key[:] = False  # the dense test is cheap, or most of the work anyway
        keyed_t = np.flatnonzero(has_key & ~never & (best >= 1))
        # count keys are coded as ``field * (top + 1) + low`` in int64 (see `_CountKeys`)
        huge = low[np.arange(n_t), key] >= (1 << 62) // (n_f + 1) if width else has_key
        counted_t = np.flatnonzero(has_key & ~never & (best < 1) & ~huge)
        has_key[np.flatnonzero(has_key & (best < 1) & huge)] = False
        self.dense = np.flatnonzero(~has_key & ~never)
        self.groups = self._dense_groups(fnet, n_t)
        self.keyed = self._lists(
            keyed_t, fields[keyed_t, key[keyed_t]], low[keyed_t, key[keyed_t]], values
        )
        self._join_lists()
        self.rest_width = max(0, width - 1)
        take = np.zeros((n_t, 0), dtype=np.int64)
        if width:  # every arc column but the key's
            rest = np.ones((n_t, width), dtype=bool)
            rest[np.arange(n_t), key] = False
            take = np.nonzero(rest)[1].reshape(n_t, self.rest_width)
        rows = np.arange(n_t)[:, None]
        self.rest_fields = np.ascontiguousarray(fields[rows, take].T)
        bare = (self.rest_fields == n_f).all(axis=0)  # no arc but the key
        self.count_keys = [
            _CountKeys(t, fields[t, key[t]], low[t, key[t]], tested)
            for tested, t in (
                (False, counted_t[bare[counted_t]]),
                (True, counted_t[~bare[counted_t]]),
            )
            if t.size
        ]
        self.looked_up = bool(self.keyed) or bool(self.count_keys)
        self.rest_low = np.ascontiguousarray(low[rows, take].T)
        self.rest_exact = np.ascontiguousarray(exact[rows, take].T)

    def _dense_groups(self, fnet: FieldNet, n_t: int) -> list[FieldGroup]:
        local = np.full(n_t, -1, dtype=np.int64)
        local[self.dense] = np.arange(self.dense.size)
        groups = []
        for g in fnet.groups:
            sel = np.flatnonzero(local[g.transitions] >= 0)
            if sel.size:
                groups.append(
                    FieldGroup(local[g.transitions[sel]], g.fields[sel], g.low[sel], g.exact[sel])
                )
        return groups

    @staticmethod
    def _lists(
        trans: npt.NDArray[np.int64],
        field: npt.NDArray[np.int64],
        value: npt.NDArray[np.int64],
        values: npt.NDArray[np.int64],
    ) -> list[tuple[int, npt.NDArray[np.int64], npt.NDArray[np.int64]]]:
        keyed = []
        for f in np.unique(field).tolist():
            sel = np.flatnonzero(field == f)
            order = np.lexsort((trans[sel], value[sel]))
            start = np.zeros(int(values[f]) + 1, dtype=np.int64)
            start[1:] = np.cumsum(np.bincount(value[sel], minlength=int(values[f])))
            keyed.append((int(f), start, trans[sel][order]))
        return keyed

    def _join_lists(self) -> None:
        """The lists of `keyed` as one (`candidates` looks every key field up at once):
        field ``keyed[k][0]`` holding ``v`` lists ``listed[start[base[k] + v] :
        start[base[k] + v + 1]]``."""
        self.key_fields = np.array([f for f, _, _ in self.keyed], dtype=np.int64)
        starts: list[npt.NDArray[np.int64]] = []
        lists: list[npt.NDArray[np.int64]] = []
        base: list[int] = []
        offset = 0
        for _, start, listed in self.keyed:
            base.append(sum(part.size for part in starts))
            starts.append(start[:-1] + offset)
            lists.append(listed)
            offset += listed.size
        self.key_base = np.array(base, dtype=np.int64)[:, None]
        self.key_start = np.concatenate([*starts, np.array([offset], dtype=np.int64)])
        self.key_listed = np.concatenate(lists) if lists else np.zeros(0, dtype=np.int64)

    def candidates(self, cols: npt.NDArray[np.integer]) -> Edges:
        """The (transition, column) pairs whose key test passes, by key field, then
        column: one lookup for all key fields (a dozen numpy calls, not a dozen per
        field: TokenRing's narrow levels have 11 key fields and a few markings)."""
        n = cols.shape[1]
        at = cols.take(self.key_fields, axis=0).astype(np.int64)
        at += self.key_base
        at = at.reshape(-1)
        first = self.key_start.take(at)
        count = self.key_start.take(at + 1) - first
        total = int(count.sum())
        offsets = np.cumsum(count) - count - first
        trans = self.key_listed.take(np.arange(total) - np.repeat(offsets, count))
        return trans, np.repeat(np.arange(at.size) % max(1, n), count)


class _CountKeys:
    """Transitions looked up by a count input (their *key*): enabled only where that
    field holds at least ``low`` tokens. Sorted by ``(field, low)`` as codes
    ``field * (top + 1) + low``, the transitions a field holding ``v`` tokens lets
    through (``low <= v``) are a run of the sorted list, found for every marked
    (field, column) pair of a block by one `np.searchsorted`: a marking costs one
    comparison per key field plus what it marks, not the transitions of the net.

    ``tested`` says whether the transitions have other input arcs to test (`edges_of`
    skips the test for lists whose transitions have none)."""

    def __init__(
        self,
        trans: npt.NDArray[np.int64],
        field: npt.NDArray[np.int64],
        low: npt.NDArray[np.int64],
        tested: bool,
    ) -> None:
        self.tested = tested
        self.top = int(low.max(initial=1))
        codes = field * (self.top + 1) + low
        order = np.lexsort((trans, codes))
        self.codes = codes[order]
        self.trans = trans[order]
        self.fields, self.first = np.unique(field[order], return_index=True)
        self.least = low[order][self.first]  # each field's first run is its lowest

    def candidates(self, cols: npt.NDArray[np.integer]) -> Edges:
        """The (transition, column) pairs whose key holds enough tokens."""
        n = cols.shape[1]
        values = cols.take(self.fields, axis=0)
        # a filter only (the runs below are exact): clipped to what the dtype holds
        least = np.minimum(self.least, np.iinfo(values.dtype).max).astype(values.dtype)
        flat = np.flatnonzero(values >= least[:, None])
        row = flat // n
        col = flat - row * n
        value = np.minimum(values.reshape(-1).take(flat).astype(np.int64), self.top)
        first = self.first.take(row)
        code = self.fields.take(row) * (self.top + 1) + value
        count = np.searchsorted(self.codes, code, side="right") - first
        total = int(count.sum())
        offsets = np.cumsum(count) - count - first
        trans = self.trans.take(np.arange(total) - np.repeat(offsets, count))
        return trans, np.repeat(col, count)


_BitTable = tuple[npt.NDArray[np.int64], list[np.int32], list[int], npt.NDArray[np.uint64]]
"""One table of `_EnablingBits`: fields, weights, clipping bounds, rows of words."""


class _EnablingBits:
    """Enabling as bit sets: a marking's enabled transitions are one ``uint64`` per 64
    transitions, the AND of a few table rows, where the ``(T, n)`` boolean matrix of
    `_Explorer.enabled` costs a gather and a test per arc and several passes over
    ``T`` bytes per marking afterwards.

    Each transition's preset tests fields (``field == low`` for a one-hot place,
    ``field >= low`` for a count). Per field, only the values up to its largest ``low``
    plus one "above all" class matter (counts are clipped to it), so the tested fields
    are grouped, in order, into tables of at most `BIT_TABLE_ROWS` combinations of
    their values: row ``sum(value_f * weight_f)`` holds the transitions whose arcs on
    the group's fields all pass. A marking ANDs one row per table. The sleep sets
    (`SleepSets`, same bit layout when every transition is tracked), the self-loops and
    the fired sets are then word operations, and the fired edges come out of the bits
    in (source, transition) order, as the next layer's sleep sets need them.

    Attributes:
        words: ``uint64`` words per marking.
        tables: per group, ``(fields, weights, clip, rows)``: the group's fields, their
            weights in the row number, per field the value larger ones are clipped to
            (``-1``: a one-hot field, whose values all have a row) and the
            ``(combinations, words)`` table.
        feasible: whether the tables were built (see `BIT_TABLES_MIN`).
    """

    def __init__(self, fnet: FieldNet, n_t: int) -> None:
        self.n_t = n_t
        self.words = max(1, -(-n_t // 64))
        top = np.zeros(fnet.n_fields, dtype=np.int64)  # largest ``low`` tested, per field
        tested = np.zeros(fnet.n_fields, dtype=bool)
        for g in fnet.groups:
            if g.fields.size:
                np.maximum.at(top, g.fields.reshape(-1), g.low.reshape(-1))
                tested[g.fields.reshape(-1)] = True
        sizes = top + 2  # values 0 .. top, and "above top"
        # one-hot fields hold fewer values than that often: no clipping needed then
        values = np.diff(np.append(fnet.offsets, fnet.n_seen))
        bounded = fnet.onehot & (values <= sizes)
        sizes[bounded] = values[bounded]
        self.tables: list[_BitTable] = []
        self.clips: list[npt.NDArray[np.integer] | None] = []
        fields = np.flatnonzero(tested)
        groups: list[list[int]] = []
        rows = BIT_TABLE_ROWS + 1
        for f in fields.tolist():
            if rows * int(sizes[f]) > BIT_TABLE_ROWS:
                groups.append([])
                rows = 1
            groups[-1].append(f)
            rows *= int(sizes[f])
        # a table per field of more values than a table holds: not worth it; nor are
        # more tables than a marking's dense test costs (about a pass per transition)
        self.feasible = bool((sizes[tested] <= BIT_TABLE_ROWS).all()) and len(groups) <= max(
            BIT_TABLES_MIN, n_t // BIT_TABLE_TRANSITIONS
        )
        if not self.feasible:
            return
        passes = self._passes(fnet, n_t, sizes)
        for group in groups:
            table = np.ones((1, n_t), dtype=bool)
            weights = []
            for f in group:
                weights.append(table.shape[0])
                table = (passes[f][:, None, :] & table[None, :, :]).reshape(-1, n_t)
            clip = [-1 if bounded[f] else int(sizes[f]) - 1 for f in group]
            self.tables.append(
                (
                    np.asarray(group, dtype=np.int64),
                    [np.int32(w) for w in weights],
                    clip,
                    self.pack(table),
                )
            )
        never = np.ones((1, n_t), dtype=bool)
        never[0, fnet.never] = False
        self.always = self.pack(never)[0]  # transitions that can be enabled at all
        self.twin_groups: list[tuple[npt.NDArray[np.uint64], ...]] = []
        self._twin_runs(fnet.effects)

    def _twin_runs(self, effects: Arcs) -> None:
        """Find the *twins*: transitions with the same effect on the fields as a
        lower-numbered one (Dekker-PT-015: ``withdraw_i_j`` for the 14 ``j``, 195 of
        255 transitions). Twins enabled in one marking reach one successor (the fields
        encode markings one to one), so only the lowest enabled one of each class is
        fired (`twins_below` gives the others). Classes are cut into runs of
        consecutive transitions within a bit word, and each run keeps its own lowest
        bit: one subtraction over the words for all runs, not a pass per class.

        Sets ``twin_groups``: per group of runs no two of which touch, the masks
        ``(members, firsts, guards)``: the runs' bits, their first bits, and the bits
        just above their last ones (empty when there are no twins)."""
        by_effect: dict[tuple[tuple[int, ...], tuple[int, ...]], int] = {}
        runs: list[tuple[int, int]] = []  # (first, last) transitions of each run
        last_of: dict[int, int] = {}  # class -> its last transition seen
        for t in range(self.n_t):
            a, b = int(effects.indptr[t]), int(effects.indptr[t + 1])
            if a == b:  # a self-loop: never fired anyway
                continue
            effect = (tuple(effects.places[a:b].tolist()), tuple(effects.values[a:b].tolist()))
            c = by_effect.setdefault(effect, len(by_effect))
            if last_of.get(c) == t - 1 and (t - 1) // 64 == t // 64:
                # (a run ending at t - 1 is of t - 1's class, c: extend it)
                if runs and runs[-1][1] == t - 1:
                    runs[-1] = (runs[-1][0], t)
                else:
                    runs.append((t - 1, t))
            last_of[c] = t
        # a run goes to the first group whose last run does not touch it (a run that
        # ends a word touches nothing: its borrow leaves the word)
        groups: list[list[tuple[int, int]]] = []
        for run in runs:
            home = next((g for g in groups if g[-1][1] + 1 < run[0] or g[-1][1] % 64 == 63), None)
            if home is None:
                groups.append(home := [])
            home.append(run)
        width = 64 * self.words
        for group in groups:
            masks = np.zeros((3, width), dtype=bool)
            for a, b in group:
                masks[0, a : b + 1] = True
                masks[1, a] = True
                if (b + 1) % 64:  # (past a word's top bit the borrow leaves the word)
                    masks[2, b + 1] = True
            members, firsts, guards = self.pack(masks)
            self.twin_groups.append((members, firsts, guards))

    def twins_below(self, enabled: npt.NDArray[np.uint64]) -> npt.NDArray[np.uint64]:
        """``(n, words)``: the bits of ``enabled`` with an enabled bit below them in
        their run (see `_twin_runs`). Subtracting a run's first bit from its bits
        borrows up to the lowest set one, which it clears, and no further: ``x & (x -
        first)`` is ``x`` without its lowest bit. A guard bit above each run stops the
        borrow of a run with no bit set (so the runs of a group must not touch)."""
        out: npt.NDArray[np.uint64] | None = None
        for members, firsts, guards in self.twin_groups:
            bits = enabled & members
            borrowed = bits | guards
            borrowed -= firsts
            bits &= borrowed
            out = bits if out is None else out | bits
        assert out is not None
        return out

    @staticmethod
    def _passes(
        fnet: FieldNet, n_t: int, sizes: npt.NDArray[np.int64]
    ) -> dict[int, npt.NDArray[np.bool_]]:
        """Per tested field, ``(sizes[f], T)``: which transitions' arcs on it pass at
        each value (those without an arc on it always pass)."""
        passes: dict[int, npt.NDArray[np.bool_]] = {}
        for g in fnet.groups:
            for k in range(g.fields.shape[1]):
                for f in np.unique(g.fields[:, k]).tolist():
                    sel = np.flatnonzero(g.fields[:, k] == f)
                    table = passes.setdefault(f, np.ones((int(sizes[f]), n_t), dtype=bool))
                    v = np.arange(int(sizes[f]))[:, None]
                    low, exact = g.low[sel, k][None, :], g.exact[sel, k][None, :]
                    table[:, g.transitions[sel]] &= np.where(exact, v == low, v >= low)
        return passes

    def pack(self, matrix: npt.NDArray[np.bool_]) -> npt.NDArray[np.uint64]:
        """Rows of booleans per transition as rows of ``words`` little-endian bit words."""
        padded = np.zeros((matrix.shape[0], 64 * self.words), dtype=bool)
        padded[:, : matrix.shape[1]] = matrix
        packed = np.packbits(padded, axis=1, bitorder="little")
        return np.ascontiguousarray(packed).view("<u8").astype(np.uint64)

    def fit(self, dtype: np.dtype[np.integer]) -> None:
        """The clipping bounds in the row dtype (it changes when fields widen)."""
        top = int(np.iinfo(dtype).max)
        self.clips = [
            None
            if all(c < 0 or c >= top for c in clip)
            else np.asarray([top if c < 0 else min(c, top) for c in clip], dtype=dtype)[:, None]
            for _, _, clip, _ in self.tables
        ]

    def enabled(self, cols: npt.NDArray[np.integer]) -> npt.NDArray[np.uint64]:
        """``(n, words)``: the transitions each column enables, as bits."""
        out: npt.NDArray[np.uint64] | None = None
        for (fields, weights, _, table), clip in zip(self.tables, self.clips, strict=True):
            values = cols.take(fields, axis=0)
            if clip is not None:
                np.minimum(values, clip, out=values)
            # (a row per field in 32 bits: 4x faster than a sum over a 64-bit matrix)
            row = values[0].astype(np.int32) * weights[0]
            for k in range(1, len(weights)):
                row += values[k] * weights[k]
            rows = table.take(row, axis=0)
            if out is None:
                out = rows
            else:
                out &= rows
        if out is None:
            return np.repeat(self.always[None, :], cols.shape[1], axis=0)
        out &= self.always
        return out

    def edges(self, bits: npt.NDArray[np.uint64]) -> Edges:
        """The (transition, column) pairs of the set bits, in (column, transition)
        order. Only the non-zero bytes are unpacked (Dekker: 9 of 32 per marking)."""
        flat = bits.astype("<u8", copy=False).view(np.uint8).reshape(-1)
        at = np.flatnonzero(flat != 0)
        set_bits = np.unpackbits(flat.take(at), bitorder="little").view(bool)
        within = np.flatnonzero(set_bits)
        pos = at.take(within >> 3) << 3
        pos |= within & 7  # bit number in the block, column-major
        width = 64 * self.words
        if width & (width - 1) == 0:
            return pos & (width - 1), pos >> (width.bit_length() - 1)
        src = pos // width
        return pos - src * width, src

    def transitions(self, bits: npt.NDArray[np.uint64]) -> npt.NDArray[np.bool_]:
        """Per transition, whether its bit is set in ``bits`` (``words``)."""
        per_byte = bits.astype("<u8", copy=False).view(np.uint8)
        unpacked: npt.NDArray[np.bool_] = np.unpackbits(per_byte, bitorder="little").view(bool)
        return unpacked[: self.n_t]


class SetupStopped(Exception):
    """The budget was spent before the explorer's set-up was done; ``stage`` names the
    part it was about to start."""

    def __init__(self, stage: str) -> None:
        super().__init__(stage)
        self.stage = stage


class _Explorer:
    """The mutable state of one exploration; `explore` is its only user.

    Frontier blocks are column-major, shape ``(fields, n)`` (see
    `analysis.encoding.FieldNet`): gathering the rows of a transition's input fields is
    then a copy of contiguous memory, and enabling for a block is a
    ``(transitions, n)`` boolean matrix.
    """

    def __init__(
        self,
        cn: CompactNet,
        max_states: int | None,
        budget: Budget,
        reducer: StubbornSets | None,
        progress: ProgressCallback | None,
        chunk: int,
        sleep_sets: bool = True,
    ) -> None:
        self.cn = cn
        self.max_states = max_states
        self.budget = budget
        self.reducer = reducer
        self.progress = progress
        self.chunk = chunk
        self.stop_when: StopWhen | None = None
        self.start = budget.clock()
        small = max_states is not None and max_states < np.iinfo(np.int32).max // 2
        self.index_type = np.int32 if small else np.int64
        # The set-up reads the budget between its stages (on a net of 20,000 places
        # and transitions they took 0.1-0.5 s each): once it is spent the search is
        # not started (`SetupStopped`, see `_explore`).
        self.setup_check("finding one-hot components")
        components = one_hot_components(cn, budget)
        covered = sum(int(c.places.size) for c in components)
        # (the bounds only size count fields: none when components take every place)
        bounds = None
        if covered < cn.n_places:
            self.setup_check("bounding places by invariants")
            bounds = invariant_place_bounds(cn, budget)
        self.setup_check("laying out the keys")
        layout = Layout.initial_guess(cn, components, bounds)
        self.fnet = fnet = FieldNet(cn, layout)
        self.setup_check("indexing enabling")
        self.index = _EnablingIndex(fnet, layout, cn.n_transitions)
        self.bits: _EnablingBits | None = None
        self.bit_fired = 0  # edges listed by `bit_edges`, and the markings it expanded
        self.bit_sources = 0
        if not self.index.looked_up and cn.n_transitions <= 64 * SLEEP_WORDS:
            self.setup_check("tabling enabling")
            bits = _EnablingBits(fnet, cn.n_transitions)
            if bits.feasible:
                self.bits = bits
                loops = np.zeros((1, cn.n_transitions), dtype=bool)
                loops[0, cn.self_loops] = True
                self.not_loops = ~bits.pack(loops)[0]
        # transitions tested in every marking of a narrow level (the others by lookup)
        self.tested = max(1, self.index.dense.size) if self.index.looked_up else cn.n_transitions
        inc_t, inc_col = np.nonzero(fnet.inc_fields >= 0)
        self.inc_t = inc_t.astype(np.int64)
        self.inc_f = fnet.inc_fields[inc_t, inc_col]
        self.inc_amount = fnet.inc_amounts[inc_t, inc_col]
        self.dense_delta = fnet.n_fields * cn.n_transitions <= DENSE_DELTA_CELLS
        self.self_loops = np.flatnonzero(cn.self_loops)
        self.count_fields = np.flatnonzero(~fnet.onehot)
        self.onehot_fields = np.flatnonzero(fnet.onehot)
        self.setup_check("computing key deltas")
        self._set_layout(layout)
        self.widenings = np.zeros(cn.n_places, dtype=np.int64)  # per place
        self.reserve = min(max_states or DEFAULT_RESERVE, RESERVE_LIMIT)
        self.store = KeyStore(
            self.layout.n_words,
            wide_index=not small,
            reserve=self.reserve,
            word_bytes=_stored_bytes(self.layout),
        )
        # numbers of the dead markings, in reserved pages of their own: kept as a list of
        # small arrays on the heap, they pinned it between step temporaries, and joining
        # and sorting them at the end came on top of the search's peak (DoubleExponent-PT-
        # 003: 260,000 dead markings, 2.6 resident bytes per state); 4 bytes each while
        # the state limit keeps numbers below 2**30 (0.4 more of DoubleExponent's bytes)
        reserve = max(1, self.reserve // DEAD_RESERVE_SHARE)
        self.dead = Growable((), self.index_type, reserve)
        self.fired = np.zeros(cn.n_transitions, dtype=bool)
        self.field_max = fnet.initial.copy()  # largest value of each count field
        self.seen = np.zeros(fnet.n_seen, dtype=bool)  # (component, value) pairs met
        self.seen[fnet.offsets[self.onehot_fields] + fnet.initial[self.onehot_fields]] = True
        self.partial_fields = np.flatnonzero(fnet.partial)
        sizes = np.diff(np.append(fnet.offsets, fnet.n_seen))
        self.onehot_sizes = sizes[self.onehot_fields]
        self.unseen_fields = self.onehot_fields  # components with values not yet met
        self.tokens_exact = int(np.count_nonzero(fnet.exact))  # one token in each
        self.max_marking = int(cn.initial.sum())
        # States ``0 .. recorded - 1`` are in the bounds (`record`); the others were
        # stored by `insert` and are recorded when unpacked (`frontier`).
        self.recorded = 1
        self.edges = 0
        self.expanded = 0  # states whose edges `edges` counts (see `edges_per_state`)
        self.offered = 0  # candidates offered to the store so far
        self.repeat_table = np.empty(0, dtype=np.int32)  # see `unrepeated`
        self.layer_starts = [0]
        self.layer_end = 1  # end of the layer being expanded (states beyond: the next)
        self.stopped: str | None = None
        wanted = sleep_sets and reducer is None and cn.n_transitions > 1
        if wanted:
            self.setup_check("computing sleep sets")
        self.sleep = SleepSets(cn) if wanted else None
        self.next_sleep: RowSpool | None = None  # while a layer computes the next one's
        self.choice_markings = 0  # POR: markings with a choice seen, firings kept of them
        self.choice_enabled = 0
        self.choice_fired = 0
        self.reduction_note: str | None = None

    def setup_check(self, stage: str) -> None:
        """Raise `SetupStopped` naming ``stage`` (what was about to start) when the
        budget is spent."""
        if self.budget.expired():
            raise SetupStopped(stage)

    def _set_layout(self, layout: Layout) -> None:
        cn, fnet = self.cn, self.fnet
        self.layout = layout
        self.dtype = row_dtype(layout, cn)
        self.key_delta = layout.key_deltas(cn.effects)
        positive = cn.effects.values > 0
        self.key_pos = layout.key_deltas(_masked(cn, positive, 1))
        self.key_neg = layout.key_deltas(_masked(cn, ~positive, -1))
        self.boundary = layout.boundary
        if self.dense_delta:
            dense = fnet.effects.dense(fnet.n_fields)
            self.col_delta = np.ascontiguousarray(dense.T.astype(self.dtype))
        self.tests = [self._tests(g) for g in fnet.groups]
        if self.bits is not None:
            self.bits.fit(self.dtype)
        self.dense_tests = [self._tests(g) for g in self.index.groups]
        top = np.iinfo(self.dtype).max
        self.rest_low = self.index.rest_low.astype(self.dtype)
        span = np.where(self.index.rest_exact, 0, top).astype(self.dtype)
        self.rest_span = span.view(_unsigned(self.dtype))
        limits = np.left_shift(np.int64(1), np.asarray(layout.bits, dtype=np.int64))
        limits[fnet.onehot] = NEVER
        self.limits = limits
        self.inc_threshold = (limits[self.inc_f] - self.inc_amount)[:, None]
        padding = fnet.inc_fields < 0
        padded = np.append(limits, 0)  # index -1 (padding) lands on the extra 0
        self.edge_threshold = np.where(
            padding, np.iinfo(np.int64).max, padded[fnet.inc_fields] - fnet.inc_amounts
        )
        self.at_risk_from = limits - fnet.max_increase  # a value >= this may overflow
        self._pad_presets()

    def _pad_presets(self) -> None:
        """The presets as ``(T, k)`` arrays for `enabled_few`: field ``n_fields`` is an
        extra row of zeros, which the padding tests (``0 - 0 <= top``)."""
        fnet = self.fnet
        n_t = self.cn.n_transitions
        width = max((g.fields.shape[1] for g in fnet.groups), default=0)
        top = np.iinfo(self.dtype).max
        fields = np.full((n_t, width), fnet.n_fields, dtype=np.int64)
        low = np.zeros((n_t, width), dtype=np.int64)
        span = np.full((n_t, width), top, dtype=np.int64)
        for g in fnet.groups:
            size = g.fields.shape[1]
            fields[g.transitions, :size] = g.fields
            low[g.transitions, :size] = g.low
            span[g.transitions, :size] = np.where(g.exact, 0, top)
        if width and fnet.never.size:  # 0 - 1 wraps to the top: never passes a span 0
            low[fnet.never, -1], span[fnet.never, -1] = 1, 0
            fields[fnet.never, -1] = fnet.n_fields
        self.pad_width = width  # arrays below are (width, T) flattened: arc column major
        self.pad_fields = fields.T.reshape(-1)
        self.pad_low = low.T.astype(self.dtype).reshape(-1, 1)
        unsigned = _unsigned(self.dtype)
        self.pad_span = span.T.astype(self.dtype).view(unsigned).reshape(-1, 1)
        self.last_value = np.minimum(self.limits - 1, np.iinfo(self.dtype).max)
        self.last_value = self.last_value.astype(self.dtype)[:, None]

    def _tests(self, group: FieldGroup) -> list[tuple[str, npt.NDArray[np.integer]]]:
        """Per input column of ``group``: how to test it (``>=``, ``==``, or both kinds
        at once as ``0 <= value - low <= span`` in unsigned arithmetic) and the
        operand, in the row dtype."""
        tests: list[tuple[str, npt.NDArray[np.integer]]] = []
        top = np.iinfo(self.dtype).max
        for k in range(group.fields.shape[1]):
            low, exact = group.low[:, k], group.exact[:, k]
            if not exact.any():
                tests.append(("ge", low.astype(self.dtype)[:, None]))
            elif exact.all():
                tests.append(("eq", low.astype(self.dtype)[:, None]))
            else:
                span = np.where(exact, 0, top).astype(self.dtype).view(_unsigned(self.dtype))
                tests.append(("in", np.stack([low.astype(self.dtype), span.view(self.dtype)])))
        return tests

    # -- one step --------------------------------------------------------------------

    def enabled(self, cols: npt.NDArray[np.integer]) -> npt.NDArray[np.bool_]:
        """``(T, n)`` matrix: transition ``t`` enabled in marking column ``i``."""
        out = _group_matrix(cols, self.fnet.groups, self.tests, self.cn.n_transitions)
        if self.fnet.never.size:
            out[self.fnet.never] = False
        return out

    def edges_of(self, cols: npt.NDArray[np.integer]) -> Edges:
        """The enabled (transition, column) pairs of a block, without the ``(T, n)``
        matrix for the transitions that test a component (`_EnablingIndex`): those are
        looked up by the value of one field, then only their other input arcs are
        tested. Transition-major when no transition is looked up, else in no particular
        order (`fired_edges` sorts what it fires)."""
        index = self.index
        parts: list[Edges] = []
        if index.dense.size:
            matrix = _group_matrix(cols, index.groups, self.dense_tests, index.dense.size)
            rows, src = _nonzero(matrix)
            parts.append((index.dense.take(rows), src))
        if not index.looked_up:
            return parts[0] if parts else (np.zeros(0, np.int64), np.zeros(0, np.int64))
        found = [(index.candidates(cols), True)] if index.keyed else []
        found += [(keys.candidates(cols), keys.tested) for keys in index.count_keys]
        flat: npt.NDArray[np.integer] | None = None
        for (trans, src), tested in found:
            if tested and index.rest_width:
                if flat is None:
                    zero = np.zeros((1, cols.shape[1]), dtype=self.dtype)
                    flat = np.concatenate([cols, zero]).reshape(-1)
                trans, src = self.rest_passed(flat, cols.shape[1], trans, src)
            parts.append((trans, src))
        return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])

    def rest_passed(
        self,
        flat: npt.NDArray[np.integer],
        n: int,
        trans: npt.NDArray[np.int64],
        src: npt.NDArray[np.int64],
    ) -> Edges:
        """The candidates (``trans``, ``src``) whose other input arcs pass, in a block
        of ``n`` columns given flat with an extra row of zeros (``flat``)."""
        index = self.index
        ok: npt.NDArray[np.bool_] | None = None
        for k in range(index.rest_width):
            values = flat.take(index.rest_fields[k].take(trans) * n + src)
            values -= self.rest_low[k].take(trans)
            passed = values.view(_unsigned(self.dtype)) <= self.rest_span[k].take(trans)
            ok = passed if ok is None else ok & passed
        assert ok is not None
        keep = np.flatnonzero(ok)
        return trans.take(keep), src.take(keep)

    def overflow(
        self,
        cols: npt.NDArray[np.integer],
        enabled: npt.NDArray[np.bool_],
        edges: Edges,
    ) -> dict[int, int]:
        """Places whose count field some enabled firing would overflow, each with the
        largest count it would reach; empty if none (the usual case).

        Only fields whose value in the block is close to the limit are checked, per
        increasing arc over the block or per edge, whichever touches fewer values.
        """
        risky = cols.max(axis=1, initial=0) >= self.at_risk_from
        if not risky.any():
            return {}
        trans, src = edges
        fnet = self.fnet
        arcs = np.flatnonzero(risky[self.inc_f])
        if arcs.size * cols.shape[1] <= trans.size * fnet.inc_fields.shape[1]:
            hit = cols[self.inc_f[arcs]] >= self.inc_threshold[arcs]
            hit &= enabled[self.inc_t[arcs]]
            if not hit.any():
                return {}
            arc, col = np.nonzero(hit)
            fields = self.inc_f[arcs[arc]]
            amounts = self.inc_amount[arcs[arc]]
        else:
            gathered = fnet.inc_fields[trans]
            values = cols[np.maximum(gathered, 0), src[:, None]]
            hit = values >= self.edge_threshold[trans]
            if not hit.any():
                return {}
            edge, slot = np.nonzero(hit)
            fields = gathered[edge, slot]
            amounts = fnet.inc_amounts[trans[edge], slot]
            col = src[edge]
        reached = cols[fields, col].astype(np.int64) + amounts
        return _largest(fnet.count_place[fields], reached)

    def successor_keys(
        self, cols: npt.NDArray[np.integer], parents: npt.NDArray[np.uint64], edges: Edges
    ) -> tuple[npt.NDArray[np.uint64] | None, dict[int, int]]:
        """Keys of the successors along ``edges``, and the places whose count field some
        firing overflows (as `overflow`); keys are ``None`` when that is not empty.

        When some count in the block is close to its field limit, the keys are
        computed as ``(key - consumed) + produced``: the subtraction never borrows
        across fields (the transition is enabled), so a field overflows exactly when
        the addition carries into the bit above it, which ``sum ^ a ^ b`` shows for
        all fields of all edges at once.
        """
        trans, src = edges
        keys = parents.take(src, axis=0)
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
        fnet = self.fnet
        gathered = fnet.inc_fields[t_bad]
        reached = cols[np.maximum(gathered, 0), s_bad[:, None]].astype(np.int64)
        reached += fnet.inc_amounts[t_bad]
        hit = (gathered >= 0) & (reached >= self.limits[np.maximum(gathered, 0)])
        needed = _largest(fnet.count_place[gathered[hit]], reached[hit])
        if not needed:  # cannot happen (a carry means an overflow); stay exact anyway
            return None, self.overflow(cols, self.enabled(cols), edges)
        return None, needed

    def place_bounds(self) -> npt.NDArray[np.int64]:
        """Most tokens each place held in a stored marking so far."""
        fnet, layout = self.fnet, self.layout
        bounds = np.zeros(self.cn.n_places, dtype=np.int64)
        counts = self.count_fields
        bounds[fnet.count_place[counts]] = self.field_max[counts]
        bounds[fnet.onehot_places] = self.seen[fnet.seen_slot]
        return bounds if layout.n_places else np.zeros(0, dtype=np.int64)

    def widen(self, needed: dict[int, int], blocks: list[npt.NDArray[np.integer]]) -> None:
        """Re-pack every stored key with wider fields for the ``needed`` places and
        convert the frontier ``blocks`` (in place) to the new row dtype. Only the
        packing changes, never a count."""
        # Every widening re-packs the whole store: widen in the same pass the counts
        # that overflowed before and are half full again (they grow, and often in step
        # with this one), and give spare bits to those that overflowed three times.
        self.record_pending()  # (in the old layout: the keys are re-packed below)
        bounds = self.place_bounds()
        half_full = bounds >= self.layout.limits // 2
        again = np.flatnonzero(half_full & (self.widenings > 0))
        needed = {**{p: 2 * int(bounds[p]) for p in again.tolist()}, **needed}
        for p in needed:
            self.widenings[p] += 1
        grown = np.flatnonzero((self.widenings > 2) & half_full)
        growing = grown[np.argsort(-self.widenings[grown], kind="stable")].tolist()
        layout = self.layout.widened(needed, growing, self.field_max)
        if int(layout.count_bits.max(initial=0)) > MAX_FIELD_BITS:
            p = max(needed, key=lambda q: needed[q])
            name = self.cn.net.places[p].name
            self.stopped = (
                f"token count of place '{name}' would pass 2**{MAX_FIELD_BITS}, past what the"
                " explorer counts exactly (the net may be unbounded)"
            )
            raise BudgetExceeded(self.stopped)
        # A block at a time, in place when the rows keep their bytes: never a second
        # copy of the store as words.
        stored = _stored_bytes(layout)
        new_row = sum(stored)
        fresh = 0 if new_row == sum(self.store.word_bytes) else self.store.size * new_row
        self.guard(BLOCK_TEMPORARIES, fresh)
        old = self.layout
        self.store.repack(lambda block: old.repack(block, layout), layout.n_words, stored)
        self._set_layout(layout)
        for i, block in enumerate(blocks):
            blocks[i] = block.astype(self.dtype)

    def enabled_few(self, cols: npt.NDArray[np.integer]) -> npt.NDArray[np.bool_]:
        """`enabled` in a fixed handful of numpy calls, for few markings: every preset
        padded to the largest size (with a test that always passes, or never for the
        transitions that can never be enabled), one gather, one test per arc, and an
        AND over the ``k`` arc columns (outermost axis: contiguous blocks)."""
        n_t, width = self.cn.n_transitions, self.pad_width
        if not width:
            out = np.ones((n_t, cols.shape[1]), dtype=bool)
            out[self.fnet.never] = False
            return out
        extended = np.concatenate([cols, np.zeros((1, cols.shape[1]), dtype=self.dtype)])
        values = extended.take(self.pad_fields, axis=0)
        values -= self.pad_low
        ok = values.view(self.pad_span.dtype) <= self.pad_span
        enabled: npt.NDArray[np.bool_] = np.logical_and.reduce(ok.reshape(width, n_t, -1))
        return enabled

    def successor_cols(
        self,
        cols: npt.NDArray[np.integer],
        src: npt.NDArray[np.int64],
        trans: npt.NDArray[np.int64],
    ) -> npt.NDArray[np.integer]:
        """Field columns of the successors of ``cols[:, src]`` by ``trans``."""
        new = cols.take(src, axis=1)
        if self.dense_delta:
            new += self.col_delta.take(trans, axis=1)
            return new
        effects = self.fnet.effects
        owner, entry = effects.expand(trans)
        fields = effects.places.take(entry)
        new[fields, owner] += effects.values.take(entry).astype(self.dtype)
        return new

    def offer(self, new: npt.NDArray[np.integer], start: int) -> None:
        """Show the new states ``start ...`` (field columns ``new``) to ``stop_when``."""
        if self.stop_when is None or not new.shape[1]:
            return
        if self.stop_when(start, self.fnet.places(new, self.layout).T):
            self.stopped = STOPPED_BY_REQUEST
            raise BudgetExceeded(self.stopped)

    def record(self, new: npt.NDArray[np.integer]) -> None:
        """Update the bounds and the largest marking with new field columns."""
        counts = new.take(self.count_fields, axis=0)
        if counts.size:
            top = counts.max(axis=1)
            self.field_max[self.count_fields] = np.maximum(self.field_max[self.count_fields], top)
            total = int(counts.sum(axis=0, dtype=np.int64).max())
        else:
            total = 0
        # components that may be empty, unless every one held a token in some marking
        # already (and there are no counts): then no marking holds more
        most = self.tokens_exact + self.partial_fields.size
        if self.partial_fields.size and new.shape[1] and (counts.size or self.max_marking < most):
            held = new.take(self.partial_fields, axis=0) != 0
            total = int((counts.sum(axis=0, dtype=np.int64) + held.sum(axis=0)).max())
        self.max_marking = max(self.max_marking, self.tokens_exact + total)
        if self.unseen_fields.size and new.shape[1]:
            values = new.take(self.unseen_fields, axis=0).astype(np.int64)
            values += self.fnet.offsets[self.unseen_fields][:, None]
            self.seen[values.reshape(-1)] = True
            # components whose every value was met need no more looking at (Dekker: all
            # of them after the first layers)
            met = np.add.reduceat(self.seen, self.fnet.offsets[self.onehot_fields])
            self.unseen_fields = self.onehot_fields[met < self.onehot_sizes]

    def insert(
        self,
        cols: npt.NDArray[np.integer],
        base: int,
        edges: Edges,
        keys: npt.NDArray[np.uint64] | None = None,
        want_ids: bool = False,
    ) -> Added:
        """Store the successors along ``edges`` (their ``keys`` if already computed).

        The new states get no columns here: their bounds are recorded when they are
        unpacked as the frontier (`frontier`, `record_pending`), which every stored
        state is once; only ``stop_when`` needs their markings now."""
        trans, src = edges
        self.guard_insert(trans.size)
        if keys is None:
            keys = self.store.keys.take(base + src, axis=0)
            keys += self.key_delta.take(trans, axis=0)
        limit = None if self.max_states is None else self.max_states - self.store.size
        added = self.store.add(keys, limit, want_ids, grow=False)  # (see `settle`)
        first = added.first
        if first.size and self.stop_when is not None:
            new = self.successor_cols(cols, src.take(first), trans.take(first))
            self.offer(new, added.start)
        if added.cut:
            self.stopped = work_limit_reason(self.max_states or 0, "state")
        return added

    def fired_edges(self, edges: Edges, sleep: npt.NDArray[np.uint64] | None, width: int) -> Edges:
        """The edges to fire: not asleep, not a self-loop; in (source, transition)
        order when the next layer gets sleep sets."""
        trans, src = edges
        keep = None
        if sleep is not None and self.sleep is not None:
            keep = self.sleep.awake(sleep, edges)
        if self.self_loops.size:
            loops = self.cn.self_loops.take(trans)
            keep = ~loops if keep is None else keep & ~loops
        if keep is not None:
            chosen = np.flatnonzero(keep)
            trans, src = trans.take(chosen), src.take(chosen)
        if self.sleep_next:
            # (source, transition) order: stable radix sorts on 16 bits, by transition
            # (unless the edges come transition-major already), then by source.
            if self.index.looked_up:
                order = np.argsort(_small(trans, self.cn.n_transitions), kind="stable")
                trans, src = trans.take(order), src.take(order)
            order = np.argsort(_small(src, width), kind="stable")
            trans, src = trans.take(order), src.take(order)
        return trans, src

    def matrix_edges(
        self, cols: npt.NDArray[np.integer], sleep: npt.NDArray[np.uint64] | None
    ) -> tuple[npt.NDArray[np.int64], Edges, npt.NDArray[np.uint64] | None]:
        """How many transitions each column of a block enables, and the edges to fire
        (as `fired_edges`), from the whole ``(T, n)`` enabled matrix: the counts, the
        sleep sets and the self-loops are applied to the matrix, and only the edges
        fired are listed (on Dekker a quarter of the enabled ones). When the next layer
        gets sleep sets, also the transitions each column fired (`SleepSets.fired_sets`)."""
        if self.bits is not None:
            return self.bit_edges(self.bits, cols, sleep)
        matrix = self.enabled(cols)
        self.fired |= matrix.any(axis=1)
        n_t = self.cn.n_transitions
        small = np.uint16 if n_t < 1 << 16 else np.int64  # a bool sum in 16 bits is fast
        counts = matrix.sum(axis=0, dtype=small).astype(np.int64)
        if sleep is not None and self.sleep is not None:
            self.sleep.wake(matrix, sleep)
        if self.self_loops.size:
            matrix[self.self_loops] = False
        trans, src = _nonzero(matrix)
        if self.sleep_next:  # (source, transition) order: a stable radix sort by source
            order = np.argsort(_small(src, cols.shape[1]), kind="stable")
            trans, src = trans.take(order), src.take(order)
        sets = None
        # per new state from the matrix (a few passes over its bytes), or per fired
        # edge (a prefix sum per key word): whichever touches less (Dekker: the matrix,
        # 16 of 255 fired; SharedMemory: the edges, 3 of 210)
        sleep_sets = self.sleep if self.sleep_next else None
        if sleep_sets is not None and 4 * trans.size * sleep_sets.words >= matrix.size:
            sets = sleep_sets.fired_sets(matrix)
        return counts, (trans, src), sets

    def bit_edges(
        self,
        bits: _EnablingBits,
        cols: npt.NDArray[np.integer],
        sleep: npt.NDArray[np.uint64] | None,
    ) -> tuple[npt.NDArray[np.int64], Edges, npt.NDArray[np.uint64] | None]:
        """`matrix_edges` with enabling as bit sets (`_EnablingBits`): the sleep sets
        and self-loops are masks of words, the fired edges come out in (source,
        transition) order without a sort, and the fired sets are the bits not asleep.
        Of twins (`_EnablingBits._twin_runs`), only the lowest enabled one is fired,
        asleep or not (Dekker-PT-015: 0.71 million keys instead of 3.95); the fired
        sets, and so the sleep sets, keep them all."""
        enabled = bits.enabled(cols)
        # (a word at a time: numpy reduces the short rows of ``(n, words)`` 5-9x slower)
        per_word = np.bitwise_count(enabled)
        counts = per_word[:, 0].astype(np.int64)
        for k in range(1, bits.words):
            counts += per_word[:, k]
        some = [np.bitwise_or.reduce(enabled[:, k]) for k in range(bits.words)]
        self.fired |= bits.transitions(np.asarray(some, dtype=np.uint64))
        twins = bits.twins_below(enabled) if bits.twin_groups else None
        if sleep is not None and self.sleep is not None:
            enabled &= ~sleep
        if self.self_loops.size:
            enabled &= self.not_loops
        edges = bits.edges(enabled if twins is None else enabled & ~twins)
        self.bit_fired += edges[0].size
        self.bit_sources += cols.shape[1]
        return counts, edges, enabled if self.sleep_next else None

    def step(
        self,
        cols: npt.NDArray[np.integer],
        sleep: npt.NDArray[np.uint64] | None,
        base: int,
    ) -> npt.NDArray[np.integer]:
        """Expand the frontier block ``cols`` (states ``base ...``, sleep sets
        ``sleep``); returns ``cols`` in the current row dtype (it changes when fields
        widen)."""
        keys = None
        fired: Edges | None = None
        n = cols.shape[1]
        per_state = self.edges_per_state
        self.guard(n * self.tested + int(n * per_state) * self.edge_bytes)
        if self.reducer is not None:
            return self.reduced_step(cols, base)
        while True:
            if self.index.looked_up:
                edges = self.edges_of(cols)
                fired = self.fired_edges(edges, sleep, cols.shape[1])
                counts = np.bincount(edges[1], minlength=cols.shape[1])
                sets = None
            else:
                counts, fired, sets = self.matrix_edges(cols, sleep)
            if n > 1 and fired[0].size * self.edge_bytes > STEP_BYTES:
                fired = None  # (the halves list their own edges: free these first)
                del counts, sets
                if self.index.looked_up:
                    del edges
                return self.split_step(cols, sleep, base)
            parents = self.store.keys[base : base + cols.shape[1]]
            keys, needed = self.successor_keys(cols, parents, fired)
            if not needed:
                break
            blocks = [cols]
            self.widen(needed, blocks)
            cols = blocks[0]
        if self.index.looked_up:
            self.fired[edges[0]] = True
        self.account(counts, base)
        assert keys is not None
        kept = self.unrepeated(keys)
        if kept is None:
            added = self.insert(cols, base, fired, keys)
            first = added.first
        else:
            offered = fired[0].take(kept), fired[1].take(kept)
            added = self.insert(cols, base, offered, keys.take(kept, axis=0))
            first = kept.take(added.first)
        keys = kept = None  # (freed before the sleep sets' temporaries)
        if self.next_sleep is not None and self.sleep is not None and first.size:
            self.next_sleep.append(self.sleep.successors(sleep, fired, first, sets))
        return cols

    def split_step(
        self,
        cols: npt.NDArray[np.integer],
        sleep: npt.NDArray[np.uint64] | None,
        base: int,
    ) -> npt.NDArray[np.integer]:
        """`step` on each half of a block whose edges would pass `STEP_BYTES`: the
        block size follows the edges per state seen so far, and a layer may enable far
        more (the first wide layer of a net with thousands of transitions). The halves
        go in order, so the new states and their sleep sets come in the same order."""
        half = cols.shape[1] // 2
        self.step(cols[:, :half], None if sleep is None else sleep[:half], base)
        if self.stopped:
            return cols.astype(self.dtype, copy=False)
        rest = cols[:, half:].astype(self.dtype, copy=False)  # (the first half may widen)
        self.step(rest, None if sleep is None else sleep[half:], base + half)
        return cols.astype(self.dtype, copy=False)

    def unrepeated(self, keys: npt.NDArray[np.uint64]) -> npt.NDArray[np.int64] | None:
        """Positions of ``keys`` to offer to the store, ascending: all but most repeats
        of an earlier key of the same step, or None for all of them.

        One pass through a direct-mapped table (a slot per hash, the first key that
        hashes there wins): a key equal to its slot's winner is a repeat. Exact, as
        the store sees every key's first occurrence, in order, so it numbers the same
        states the same way; a repeat in another slot's shadow is left to the store.
        Several times cheaper per key than the store's probing, it pays where keys
        repeat: Dekker fires 715,000 keys for 280,000 states and offers 518,000 (4
        million and 710,000 without the twins rule, `_EnablingBits._twin_runs`)."""
        m = keys.shape[0]
        if keys.shape[1] != 1 or not REPEAT_FILTER_MIN <= m <= EDGES_PER_STEP * 4:
            return None  # (the table, 8 to 16 bytes a key, stays a temporary of a step)
        if self.edges < REPEAT_FILTER_DEGREE * self.store.size:
            return None  # (few enabled transitions per marking: few repeats)
        bits = max(10, int(m - 1).bit_length() + 1)  # a table two to four times m
        if self.repeat_table.size < 1 << bits:
            self.repeat_table = np.empty(1 << bits, dtype=np.int32)
        flat = keys.reshape(-1)
        # hashed backwards: the last write to a slot, the first key there, stays (and a
        # contiguous signed index is written three times faster than a uint64 one)
        backwards = flat[::-1] * np.uint64(0x9E3779B97F4A7C15)
        backwards >>= np.uint64(64 - bits)
        slot = backwards.view(np.int64)  # (below 2**bits)
        self.repeat_table[slot] = np.arange(m - 1, -1, -1, dtype=np.int32)
        winner = self.repeat_table.take(slot[::-1])
        # (m < 2**31: a step's edges; ``<``: only an earlier copy makes a repeat)
        repeat = winner < np.arange(m, dtype=np.int32)
        repeat &= flat.take(winner) == flat
        return np.flatnonzero(~repeat)

    def reduced_step(
        self,
        cols: npt.NDArray[np.integer],
        base: int,
    ) -> npt.NDArray[np.integer]:
        """`step` with partial-order reduction: fire a stubborn subset of the enabled
        transitions of each marking (needs the whole enabled matrix)."""
        reducer = self.reducer
        assert reducer is not None
        while True:
            enabled = self.enabled(cols)
            needed = self.overflow(cols, enabled, _nonzero(enabled))
            if not needed:
                break
            blocks = [cols]
            self.widen(needed, blocks)
            cols = blocks[0]
        any_enabled = enabled.any(axis=0)
        self.fired |= enabled.any(axis=1)
        if not any_enabled.all():
            self.dead.append(base + np.flatnonzero(~any_enabled))
        reduced = reducer.reduce(self.fnet.places(cols, self.layout), enabled)
        rtrans, rsrc = _nonzero(reduced)
        self.judge_reduction(enabled, rsrc.size)
        self.edges += rsrc.size
        self.expanded += cols.shape[1]
        added = self.insert(cols, base, (rtrans, rsrc), want_ids=True)
        if not reducer.needs_proviso or self.stopped:
            return cols
        # Cycle proviso: a marking whose reduced successors include one that was known
        # before it was expanded (stored earlier, or found first by another marking of
        # this block) is expanded fully, so every cycle of the reduced graph has a fully
        # expanded marking and no visible change is postponed forever.
        assert added.ids is not None
        ids = added.ids
        stale = ids < added.start
        new = np.flatnonzero(~stale)
        stale[new] = rsrc[added.first[ids[new] - added.start]] != rsrc[new]
        redo = np.zeros(cols.shape[1], dtype=bool)
        redo[rsrc[stale]] = True
        redo &= (reduced != enabled).any(axis=0)
        if redo.any():
            extra = enabled & ~reduced
            extra[:, ~redo] = False
            etrans, esrc = _nonzero(extra)
            self.edges += esrc.size
            self.insert(cols, base, (etrans, esrc))
        return cols

    def judge_reduction(self, enabled: npt.NDArray[np.bool_], fired: int) -> None:
        """Count what the stubborn sets kept of the markings with a choice, and switch
        the reduction off once a sample shows it prunes almost nothing."""
        counts = enabled.sum(axis=0)
        choice = counts > 1
        self.choice_markings += int(np.count_nonzero(choice))
        self.choice_enabled += int(counts[choice].sum())
        self.choice_fired += fired - int(np.count_nonzero(counts == 1))
        if self.choice_markings < POR_SAMPLE or self.reduction_note is not None:
            return
        kept = self.choice_fired / max(1, self.choice_enabled)
        if kept >= POR_USELESS:
            self.reducer = None
            self.reduction_note = (
                f"stubborn sets kept {kept:.0%} of the firings of the first "
                f"{self.choice_markings:,} markings with a choice: the rest of the search "
                "expanded every marking fully"
            )

    # -- the loop --------------------------------------------------------------------

    def run(self) -> None:
        self.store.add(self.layout.pack(self.cn.initial[None, :]))
        self.offer(self.fnet.initial[:, None], 0)
        too_large = _beyond_exact_arithmetic(self.cn.net)
        if too_large is not None:
            self.stopped = too_large
            raise BudgetExceeded(too_large)
        # A layer is the states ``base ...`` up to the store's end (they are numbered in
        # BFS order), unpacked from their keys a block at a time: no layer is kept as
        # columns, which on wide layers cost more than the store's own bytes per state.
        sleeps: RowSpool | None = None
        base = 0
        while base < self.store.size:
            width = self.store.size - base
            if self.narrow(width):
                done = self.narrow_round(self.frontier(base, width), base)
                if done is not None:
                    base = done[1]
                    sleeps = None
                    continue
            # Each block takes its sleep sets off the front of the layer's spool, which
            # unmaps its pages as they are read: a wide layer's sleep sets (8 bytes per
            # tracked 64 transitions per state) are never held twice, they shrink as the
            # next layer's grow, and they never fragment the heap (`analysis.spool`).
            self.next_sleep = None
            if self.sleep is not None and self.edges >= SLEEP_MIN_DEGREE * base:
                # sparse rows cost time (Peterson-PT-3: a tenth of the search); they pay
                # where layers are wide against the store (SharedMemory-PT-000010: a
                # layer's sleep sets up to 1.7 times the store's bytes, Peterson 0.15)
                words = self.sleep.words
                wide = SPARSE_SLEEP_SHARE * width * words * 8 >= self.store.nbytes
                self.next_sleep = RowSpool(words, sparse=None if wide else False)
            sleep_all = sleeps
            sleeps = None
            self.layer_end = base + width
            c = 0
            while c < width:
                size = min(self.block_size(), width - c)
                self.guard(size * self.fnet.n_fields * (self.dtype.itemsize + 8))
                cols = self.frontier(base + c, size)
                part = None if sleep_all is None else sleep_all.take(size)
                self.step(cols, part, base + c)
                if self.stopped:
                    raise BudgetExceeded(self.stopped)
                del cols, part
                self.store.settle()  # (the step's temporaries are freed: see narrow_round)
                c += size
                self.check_time(self.store.size - base - c)
            base += width
            sleeps, self.next_sleep = self.next_sleep, None
            if base < self.store.size:
                self.layer_starts.append(base)

    def close_layers(self) -> None:
        """After a search stopped inside a layer: the states it stored beyond that
        layer start the next one (`StateSpace.depth_of`, and the parents found in the
        layer before, need every stored state's layer)."""
        if self.store.size > self.layer_end > self.layer_starts[-1]:
            self.layer_starts.append(self.layer_end)

    def frontier(self, start: int, n: int) -> npt.NDArray[np.integer]:
        """Field columns of the states ``start .. start + n - 1``, from their keys; the
        ones not yet recorded (`record`) are recorded now."""
        cols = self.layout.fields(self.store.keys[start : start + n], self.dtype)
        if start + n > self.recorded:
            self.record_pending(start)
            self.record(cols[:, self.recorded - start :])
            self.recorded = start + n
        return cols

    def record_pending(self, end: int | None = None, until: float | None = None) -> None:
        """`record` the stored states from ``recorded`` up to ``end`` (default: all),
        unpacked from their keys a block at a time; stop early once the budget's clock
        passes ``until``."""
        end = self.store.size if end is None else end
        # small blocks: this also runs after a search stopped at its memory limit
        step = max(1, RECORD_CELLS // max(1, self.fnet.n_fields))
        while self.recorded < end:
            if until is not None and self.budget.clock() > until:
                return
            n = min(step, end - self.recorded)
            keys = self.store.keys[self.recorded : self.recorded + n]
            self.record(self.layout.fields(keys, self.dtype))
            self.recorded += n

    def narrow(self, width: int) -> bool:
        """Whether a layer of ``width`` markings is explored by a narrow round: few
        markings, and an enabled matrix small enough to compute at once."""
        few = width <= NARROW_WIDTH and width * self.tested <= CELLS_PER_STEP
        per_state = max(1.0, self.edges_per_state)
        small = width * per_state * self.candidate_bytes <= STEP_BYTES
        return few and small and self.reducer is None

    def narrow_edges(self, cols: npt.NDArray[np.integer]) -> tuple[Edges, int]:
        """The enabled (transition, column) pairs of a narrow level and the cells it
        cost. With keyed transitions (`_EnablingIndex`) only the lookups' candidates
        and the densely tested transitions are looked at: a marking of a net with
        thousands of transitions in components costs what it enables, not the width of
        the net (`enabled_few` tests every transition in every marking)."""
        if not self.index.looked_up:
            enabled = self.enabled_few(cols)
            return _nonzero(enabled), enabled.size
        edges = self.edges_of(cols)
        return edges, cols.shape[1] * self.index.dense.size + edges[0].size

    def speculate(self, cols: npt.NDArray[np.integer], base: int) -> _Round | None:
        """Expand the narrow layer ``cols`` (states ``base ...``) and then its successors,
        level after level, without asking the store whether they are new: as long as
        the candidates stay few, a level costs a couple of dozen small numpy calls and
        no hashing. Level ``j`` holds every successor of level ``j - 1`` (known or not),
        so it contains the whole BFS layer ``j`` below ``cols``, and a key's first level
        is its depth. The last level is not expanded. None when the first level alone
        would pass `STEP_BYTES` (`narrow` guessed its width from the edges per state so
        far): the layer is then expanded by blocks."""
        while True:
            spec = _Round()
            current, keys = cols, self.store.keys[base : base + cols.shape[1]]
            # `chunk` bounds work between checks, `STEP_BYTES` the round's memory
            budget = min(NARROW_CANDIDATES, self.chunk, STEP_BYTES // self.candidate_bytes)
            needed: dict[int, int] = {}
            checked = 0  # candidates when the round's memory was last checked
            above = cols.shape[1]  # width of the level above ``current``...
            produced = 0  # ... and the candidates expanding it gave
            while len(spec.keys) < NARROW_LEVELS:
                width = current.shape[1]
                if spec.keys and width >= REPEATS_MIN and 2 * width > 3 * above:
                    spec.drop_repeats()
                    current, keys = spec.cols[-1], spec.keys[-1]
                    width = current.shape[1]
                # too wide to expand in one go, or (lookups make levels cheap) so wide
                # that unchecked duplicates pile up: the next frontier
                wide = width * self.tested > CELLS_PER_STEP
                if spec.keys and (wide or (self.index.looked_up and width > NARROW_WIDTH)):
                    break
                # a level expected to pass the round's budget by itself: the store
                # dedupes it more cheaply than another level would (Dekker's last
                # layers: 15 markings, 508,440 candidates two levels down)
                if spec.keys and spec.total * above + width * produced > budget * above:
                    break
                above = width
                self.guard(width * self.tested)  # the deadline, between levels too
                every, cells = self.narrow_edges(current)
                counts = np.bincount(every[1], minlength=current.shape[1])
                trans, src = self.fired_edges(every, None, current.shape[1])
                if not spec.keys and src.size * self.candidate_bytes > STEP_BYTES:
                    return None  # a first level this wide is a layer for `step`
                level = src.size * (self.fnet.n_fields * self.dtype.itemsize + 24)
                # with a memory limit, each time the round's candidates double (reading
                # the process's memory every level cost more than the levels)
                if spec.keys and self.budget.memory is not None and spec.total >= 2 * checked:
                    checked = spec.total
                    temporaries, grown = self.insert_bytes(spec.total + src.size)
                    if not self.fits(level + temporaries, grown):
                        break  # store the levels so far instead: their candidates are fewer
                self.guard(level)
                new = self.successor_cols(current, src, trans)
                over = new > self.last_value
                if over.any():
                    field, col = np.nonzero(over)
                    reached = new[field, col].astype(np.int64)
                    needed = _largest(self.fnet.count_place[field], reached)
                    break
                self.fired[every[0]] = True
                produced = src.size
                keys = keys.take(src, axis=0)
                keys += self.key_delta.take(trans, axis=0)
                spec.add(counts, new, keys, cells)
                current = new
                if not src.size or spec.total >= budget or spec.cells >= CELLS_PER_STEP:
                    break
            if spec.keys or not needed:
                return spec
            blocks = [cols]
            self.widen(needed, blocks)
            cols = blocks[0]

    def narrow_round(
        self, cols: npt.NDArray[np.integer], base: int
    ) -> tuple[npt.NDArray[np.integer], int] | None:
        """Explore several BFS layers below the narrow layer ``cols`` (states
        ``base ...``) with one insertion into the store (see `speculate`); returns the
        next frontier and its first state number, or None when the layer is to be
        expanded by blocks instead (nothing was stored)."""
        self.next_sleep = None  # (its levels compute no sleep sets)
        spec = self.speculate(cols, base)
        if spec is None:
            return None
        self.guard_insert(spec.total)
        keys, new_cols, counts = spec.joined()
        limit = None if self.max_states is None else self.max_states - self.store.size
        added = self.store.add(keys, limit, grow=False)  # (grown below, see `settle`)
        del keys
        first, start = added.first, added.start
        cut = np.searchsorted(first, spec.ends)  # (the levels' layers, before anything can stop)
        for j in range(len(spec.ends)):
            if cut[j] > (cut[j - 1] if j else 0):
                self.layer_starts.append(start + (int(cut[j - 1]) if j else 0))
        self.account(spec.counts[0], base)
        new = new_cols.take(first, axis=1)
        del new_cols
        self.record_pending(start)
        self.record(new)
        self.recorded = start + first.size
        self.offer(new, start)
        enables = counts.take(first)
        expanded = int(np.count_nonzero(enables >= 0))  # all but the last level's
        self.account(enables[:expanded], start)
        if added.cut:
            self.stopped = work_limit_reason(self.max_states or 0, "state")
            raise BudgetExceeded(self.stopped)
        frontier = np.ascontiguousarray(new[:, expanded:])
        del new, enables, counts
        # The table grows now, if the round filled it, when the round's candidates are
        # freed: its rebuild's temporaries (a chunk of keys, their hashes and slots)
        # no longer add to theirs, which set the heap's high-water mark on deep, narrow
        # searches (DoubleExponent-PT-003: 2.6 MB of each).
        self.store.settle()
        self.check_time(frontier.shape[1])
        return frontier, start + expanded

    def account(self, counts: npt.NDArray[np.int64], start: int) -> None:
        """Edges and dead markings of states ``start ...`` that enable ``counts``
        transitions each."""
        self.edges += int(counts.sum())
        self.expanded += counts.size
        dead = np.flatnonzero(counts == 0)
        if dead.size:
            self.dead.append(start + dead)

    def block_size(self) -> int:
        """Frontier columns for the next step: ``chunk``, fewer on nets with many
        enabled transitions per marking or many transitions, so that one step
        handles at most `EDGES_PER_STEP` edges and `CELLS_PER_STEP` cells of the
        enabled matrix (bounded temporaries, warmer caches)."""
        per_state = self.edges_per_state
        by_edges = int(min(EDGES_PER_STEP, STEP_BYTES // self.edge_bytes) / max(per_state, 1.0))
        tested = self.tested if self.reducer is None else self.cn.n_transitions
        by_matrix = CELLS_PER_STEP // max(1, tested)  # lookups build no (T, n) matrix
        if self.bits is not None and self.reducer is None and self.bit_fired:
            # steps with enabling as bit sets (`bit_edges`) list only the edges they
            # fire: as many of those (Dekker fires 14 of 60 enabled per marking)
            fired = max(self.bit_fired / self.bit_sources, 1.0)
            by_edges = int(by_edges * max(per_state, 1.0) / fired)
        else:
            fired = per_state
        spool = 0 if self.next_sleep is None else self.next_sleep.nbytes
        budget = max(BLOCK_TEMPORARY_BYTES, (self.store.nbytes - spool) // 4)
        by_bytes = budget // (self.state_bytes + int(fired * self.edge_bytes))
        size = max(min(256, self.chunk), min(self.chunk, by_edges, by_matrix, by_bytes))
        if self.reducer is not None and self.choice_markings < POR_SAMPLE:
            # Small steps until the reduction is judged, so it is judged on the sample.
            size = min(size, max(256, POR_SAMPLE - self.choice_markings))
        return size

    @property
    def sleep_next(self) -> bool:
        """Whether the layer being expanded computes the next one's sleep sets (into
        `next_sleep`)."""
        return self.next_sleep is not None

    @property
    def edges_per_state(self) -> float:
        """Edges per expanded state so far: what sizes blocks and guards. Per *stored*
        state it under-estimated wide nets badly: after a first layer of 300 markings
        with 6,000 edges each and 45,000 successors stored, 40, and one step of 7,513
        markings had 45 million edges (8-13 s past a 1 s limit)."""
        return self.edges / max(1, self.expanded)

    @property
    def state_bytes(self) -> int:
        """Bytes of temporaries per marking of a step: its columns, its parent's key,
        and a few rows of sleep words (the part taken from the spool, the enabled or
        fired bits, the new states' sets)."""
        sleep_words = 0 if self.sleep is None else self.sleep.words
        return (
            self.fnet.n_fields * self.dtype.itemsize
            + 8 * self.layout.n_words
            + 24 * sleep_words
            + 32
        )

    @property
    def edge_bytes(self) -> int:
        """Bytes of temporaries per edge of a step: a few copies of its successor's key
        (parent's, delta, sum, carries) and its numbers (source, transition, hash, slot)."""
        return 32 * self.layout.n_words + 64

    @property
    def candidate_bytes(self) -> int:
        """Bytes a narrow round keeps per candidate: its columns, key and edge."""
        return self.fnet.n_fields * self.dtype.itemsize + 8 * self.layout.n_words + 24

    def check_time(self, left: int) -> None:
        """Report progress, and stop (with the budget's reason) past its deadline."""
        if self.progress is not None:
            now = self.budget.clock() - self.start
            self.progress(
                ProgressInfo(self.store.size, self.edges, left, len(self.layer_starts), now)
            )
        self.guard()

    def guard(self, extra_bytes: int = 0, grown_bytes: int = 0) -> None:
        """Stop, with the budget's reason and every state stored so far kept, when the
        deadline has passed, the process is over its memory limit, or what the caller
        is about to allocate would take it over: ``extra_bytes`` of temporaries (from
        the heap, which reuses its free blocks first: `heap_free_bytes`) and
        ``grown_bytes`` of the store's own arrays (fresh pages). Called before every
        step that allocates much or runs long, so a search ends within one bounded
        step of its limits; nothing is changed yet when it raises."""
        budget = self.budget
        if budget.expired():
            self.stopped = budget.time_reason(self.store.size, "state")
            raise BudgetExceeded(self.stopped)
        if budget.memory is not None and extra_bytes + grown_bytes >= GUARD_MIN_BYTES:
            try:
                budget.check_memory(max(0, extra_bytes - heap_free_bytes()) + grown_bytes)
            except BudgetExceeded:
                self.stopped = memory_limit_reason(budget.memory, self.store.size)
                raise BudgetExceeded(self.stopped) from None

    def fits(self, extra_bytes: int, grown_bytes: int) -> bool:
        """Whether the allocations `guard` is told about keep the process within its
        memory limit."""
        if self.budget.memory is None:
            return True
        return self.budget.would_fit(max(0, extra_bytes - heap_free_bytes()) + grown_bytes)

    def insert_bytes(self, candidates: int) -> tuple[int, int]:
        """Bytes that storing up to ``candidates`` successors may allocate: the
        insertion's temporaries, and the growth of the store (keys, table)."""
        grown = self.store.growth_bytes(candidates)
        # The new states' columns (and sleep sets) are kept for the next layer: twice as
        # many as the share of new states among the candidates so far predicts.
        new = min(candidates, 2 * candidates * self.store.size // max(1, self.offered) + 1024)
        sleep_words = 0 if self.sleep is None else self.sleep.words
        grown += new * (self.fnet.n_fields * self.dtype.itemsize + 8 * sleep_words)
        return candidates * (8 * self.layout.n_words + INSERT_BYTES), grown

    def guard_insert(self, candidates: int) -> None:
        """`guard` before storing up to ``candidates`` successors (`insert_bytes`)."""
        self.guard(*self.insert_bytes(candidates))
        self.offered += candidates


def _stored_bytes(layout: Layout) -> tuple[int, ...]:
    """Bytes the store keeps of each key word: only those the fields reach
    (`Layout.word_bytes`), unless `PACK_WIDE_KEYS` is off and the key has several
    words (then whole words). Since the store compares a key a plane at a time, later
    planes only where the first ones are equal (`analysis.encoding.PackedRows.same`),
    planes cost DoubleExponent-PT-003 (8 + 7 bytes) about 3 % more CPU than whole
    words for a byte less per state; before, when every probe gathered every plane,
    they cost 10-20 %."""
    if layout.n_words == 1 or PACK_WIDE_KEYS:
        return layout.word_bytes
    return (8,) * layout.n_words


def _unsigned(dtype: np.dtype[np.integer]) -> np.dtype[np.unsignedinteger]:
    return np.dtype(f"u{dtype.itemsize}")


def _test(
    values: npt.NDArray[np.integer], test: tuple[str, npt.NDArray[np.integer]]
) -> npt.NDArray[np.bool_]:
    """One input column of a group: which (transition, marking) pairs pass."""
    kind, operand = test
    if kind == "ge":
        ge: npt.NDArray[np.bool_] = values >= operand
        return ge
    if kind == "eq":
        eq: npt.NDArray[np.bool_] = values == operand
        return eq
    values -= operand[0][:, None]
    unsigned = _unsigned(values.dtype)
    inside: npt.NDArray[np.bool_] = values.view(unsigned) <= operand[1].view(unsigned)[:, None]
    return inside


def _small(values: npt.NDArray[np.int64], bound: int) -> npt.NDArray[np.integer]:
    """``values`` (all below ``bound``) as ``uint16`` when they fit: numpy sorts 16-bit
    keys stably with a radix sort, several times faster than 64-bit ones."""
    return values.astype(np.uint16) if bound <= 1 << 16 else values


def _group_matrix(
    cols: npt.NDArray[np.integer],
    groups: Sequence[FieldGroup],
    tests: Sequence[list[tuple[str, npt.NDArray[np.integer]]]],
    rows: int,
) -> npt.NDArray[np.bool_]:
    """``(rows, n)`` enabled matrix of the transitions of ``groups`` (numbered by
    ``group.transitions``), one gather and one test per input column of a group."""
    out = np.empty((rows, cols.shape[1]), dtype=bool)
    for group, checks in zip(groups, tests, strict=True):
        if not checks:
            out[group.transitions] = True
            continue
        ok = _test(cols.take(group.fields[:, 0], axis=0), checks[0])
        for k in range(1, len(checks)):
            ok &= _test(cols.take(group.fields[:, k], axis=0), checks[k])
        out[group.transitions] = ok
    return out


def _largest(places: npt.NDArray[np.int64], reached: npt.NDArray[np.int64]) -> dict[int, int]:
    """``{place: largest count reached}`` over parallel arrays."""
    needed: dict[int, int] = {}
    for p, v in zip(places.tolist(), reached.tolist(), strict=True):
        needed[p] = max(needed.get(p, 0), v)
    return needed


def _masked(cn: CompactNet, select: npt.NDArray[np.bool_], sign: int) -> Arcs:
    """The effect arcs ``select``-ed, times ``sign`` (the others zero)."""
    effects = cn.effects
    return Arcs(effects.indptr, effects.places, np.where(select, sign * effects.values, 0))


def _beyond_exact_arithmetic(net: Net) -> str | None:
    """Why ``net``'s numbers are too large to explore exactly, or None.

    Counts are kept below ``2**MAX_FIELD_BITS``; with every initial count and arc weight
    at most that too, a firing's sum stays below ``2**61`` and 64-bit arithmetic never
    wraps. A larger weight could wrap silently (the red team's net gaining ``2**62``
    tokens a firing was reported bounded), so such a net is not explored at all.
    """
    limit = 2**MAX_FIELD_BITS
    for place in net.places:
        if place.initial > limit:
            return (
                f"place '{place.name}' starts with {place.initial} tokens, over 2**"
                f"{MAX_FIELD_BITS}: too large to count exactly"
            )
    for transition in net.transitions:
        for place_name, weight in (*transition.inputs, *transition.outputs):
            if weight > limit:
                return (
                    f"transition '{transition.name}' moves {weight} tokens of '{place_name}', "
                    f"over 2**{MAX_FIELD_BITS}: too large to count exactly"
                )
    return None


def explore(
    net: Net | CompactNet,
    *,
    max_states: int | None = DEFAULT_MAX_STATES,
    budget: Budget | None = None,
    por: bool = False,
    visible: Sequence[str] | None = None,
    progress: ProgressCallback | None = None,
    chunk: int = DEFAULT_CHUNK,
    stop_when: StopWhen | None = None,
) -> StateSpace:
    """Explore the reachable markings of ``net`` breadth first.

    Args:
        net: the net, or its `CompactNet` when exploring one net several times.
        max_states: stop after storing this many markings (``None``: no limit; an
            unbounded net then runs until its token counts pass ``2**60``).
        budget: its clock times the search and its deadline stops it (checked after
            every chunk, and between the parts of the set-up: spent there, the space
            is the initial marking alone; ``None``: no time limit, on the real clock);
            its work cap, if any, is a state cap too (the smaller of it and
            ``max_states`` applies).
        por: explore a stubborn-set reduced graph instead (`analysis.stubborn`): all
            deadlocks are kept; ``states``/``edges`` then count the reduced graph.
        visible: with ``por``, places a reachability question is about; the reduced
            graph then also keeps every reachable value of these places (visibility
            and cycle provisos), so `StateSpace.find` over them answers as the full
            graph would.
        progress: called after every chunk with a `ProgressInfo`
            (see `analysis.progress.ProgressPrinter`).
        chunk: frontier rows per vectorised step (and most candidates of a narrow
            round), i.e. the work between two deadline/`progress` checks.
        stop_when: called as ``stop_when(first, markings)`` with every batch of newly
            stored states, numbered ``first, first + 1, ...`` (BFS order), their
            markings as rows ``(n, places)``; returning true ends the search there
            (``stopped_reason`` is `STOPPED_BY_REQUEST`). A search for a marking
            uses it to stop at the first (hence shallowest) hit.

    Returns:
        The `StateSpace`; ``complete`` is false, with ``stopped_reason``, when a budget
        or ``stop_when`` stopped it.

    A net with operator inputs (`analysis.inputs`) is explored without partial-order
    reduction (``por`` is ignored, and sleep sets are off too): the reductions preserve
    P/T deadlocks, while its dead states are the terminal ones, found by a pass over
    every stored marking after the search. When its initial marking is itself terminal
    the run never starts: the space is that one marking.
    """
    cn = net if isinstance(net, CompactNet) else CompactNet.from_net(net)
    budget = budget or Budget()
    if budget.work is not None:
        max_states = budget.work if max_states is None else min(max_states, budget.work)
    if has_inputs(cn.net):
        return _explore_with_inputs(
            cn,
            max_states=max_states,
            budget=budget,
            progress=progress,
            chunk=chunk,
            stop_when=stop_when,
        )
    return _explore(
        cn,
        max_states=max_states,
        budget=budget,
        por=por,
        visible=visible,
        progress=progress,
        chunk=chunk,
        stop_when=stop_when,
    )


def _unexpanded(
    cn: CompactNet, budget: Budget, stage: str, start: float, reduced: bool
) -> StateSpace:
    """The state space of a search whose budget ran out in the explorer's set-up: the
    initial marking alone, stored but not expanded, in one count field per place;
    the reason names the limit in the one shape of every stopped search (``time limit
    of 1 s reached after 1 state``). ``stage``: what the set-up was about to start."""
    del stage  # (kept by `SetupStopped` for tests and debugging; not part of the reason)
    initial = cn.initial.astype(np.int64)
    layout = Layout.for_bits([max(1, int(v).bit_length()) for v in initial.tolist()])
    store = KeyStore(layout.n_words, reserve=1, word_bytes=_stored_bytes(layout))
    store.add(layout.pack(initial[None, :]))
    return StateSpace(
        net=cn.net,
        states=1,
        edges=0,
        place_bounds=initial.copy(),
        max_tokens_place=int(initial.max(initial=0)),
        max_tokens_marking=int(initial.sum()),
        deadlocks=np.zeros(0, dtype=np.int64),
        fired_transitions=np.zeros(cn.n_transitions, dtype=bool),
        complete=False,
        stopped_reason=budget.time_reason(1),
        seconds=budget.clock() - start,
        stored_bytes=store.nbytes,
        depth=1,
        reduced=reduced,
        layout=layout,
        keys=store.keys,
        store=store,
        compact=cn,
        layer_starts=np.zeros(1, dtype=np.int64),
    )


def _explore_with_inputs(
    cn: CompactNet,
    *,
    max_states: int | None,
    budget: Budget,
    progress: ProgressCallback | None,
    chunk: int,
    stop_when: StopWhen | None,
) -> StateSpace:
    """`explore` for a net with operator inputs: unreduced P/T search, then the dead
    states recomputed as the terminal ones and the input edges out of them uncounted."""
    net = cn.net
    initial = net.initial_marking()
    if not net.runs_on(initial):
        # Only the initial marking is reachable: stop the search at its first successor.
        space = _explore(cn, max_states=1, budget=budget, sleep_sets=False)
        return replace(
            space,
            states=1,
            edges=0,
            place_bounds=np.asarray(initial, dtype=np.int64),
            max_tokens_place=max(initial, default=0),
            max_tokens_marking=sum(initial),
            deadlocks=np.zeros(1, dtype=np.int64),
            fired_transitions=np.zeros(len(net.transitions), dtype=np.bool_),
            complete=True,
            stopped_reason=None,
            depth=1,
            keys=space.keys,
            layer_starts=np.zeros(1, dtype=np.int64),
        )
    space = _explore(
        cn,
        max_states=max_states,
        budget=budget,
        progress=progress,
        chunk=chunk,
        stop_when=stop_when,
        sleep_sets=False,
    )
    dead: list[npt.NDArray[np.int64]] = []
    removed = 0
    for start, block in space.iter_markings():
        terminal = terminal_rows(net, block)
        removed += input_edges_at(net, block, terminal)
        dead.append(start + np.flatnonzero(terminal).astype(np.int64))
    deadlocks = np.concatenate(dead) if dead else np.zeros(0, dtype=np.int64)
    # An incomplete search did not expand its last states: their edges were never
    # counted, so only a complete one has the removed edges to take back.
    edges = space.edges - removed if space.complete else space.edges
    return replace(space, deadlocks=deadlocks, edges=edges)


def _explore(
    cn: CompactNet,
    *,
    max_states: int | None = DEFAULT_MAX_STATES,
    budget: Budget,
    por: bool = False,
    visible: Sequence[str] | None = None,
    progress: ProgressCallback | None = None,
    chunk: int = DEFAULT_CHUNK,
    stop_when: StopWhen | None = None,
    sleep_sets: bool = True,
) -> StateSpace:
    """`explore` proper: the P/T search (see there)."""
    reducer = None
    if por:
        vis = None if visible is None else [cn.net.place_index(p) for p in visible]
        reducer = StubbornSets(cn, vis)
    settle_allocator()
    start = budget.clock()
    try:
        explorer = _Explorer(
            cn, max_states, budget, reducer, progress, chunk, sleep_sets=sleep_sets
        )
    except SetupStopped as stop:
        return _unexpanded(cn, budget, stop.stage, start, por)
    explorer.stop_when = stop_when
    try:
        explorer.run()
    except BudgetExceeded:  # a budget ran out; the reason is recorded
        pass
    except MemoryError:  # an allocation failed (memory limit or ceiling): say so, keep the rest
        explorer.stopped = memory_limit_reason(budget.memory, explorer.store.size)
    explorer.close_layers()
    # The bounds of the states stored but not expanded: on a net of 20,000 places the
    # last step of a search stopped by its time limit can store 100,000 of them, 17 s
    # of decoding (rings(2000, 10)); within the limit, or briefly past it.
    deadline = budget.deadline
    until = None if deadline is None else max(deadline, budget.clock()) + RECORD_GRACE
    try:
        explorer.record_pending(until=until)
    except MemoryError:  # (a few MB at most, after a search that ran out of memory)
        explorer.stopped = memory_limit_reason(budget.memory, explorer.store.size)
    seconds = budget.clock() - explorer.start
    store = explorer.store
    dead = explorer.dead.view
    dead.sort()  # in place (no copy on top of the store)
    bounds = explorer.place_bounds()
    return StateSpace(
        net=cn.net,
        states=store.size,
        edges=explorer.edges,
        place_bounds=bounds,
        max_tokens_place=int(bounds.max(initial=0)),
        max_tokens_marking=explorer.max_marking,
        deadlocks=dead,
        fired_transitions=explorer.fired,
        complete=explorer.stopped is None,
        stopped_reason=explorer.stopped,
        seconds=seconds,
        stored_bytes=store.nbytes,
        depth=len(explorer.layer_starts),
        reduced=por,
        layout=explorer.layout,
        keys=store.keys,
        store=store,
        compact=cn,
        layer_starts=np.asarray(explorer.layer_starts, dtype=np.int64),
        reduction_note=explorer.reduction_note,
        recorded=-1 if explorer.recorded >= store.size else explorer.recorded,
    )
