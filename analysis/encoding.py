"""Compact, array-based views of a `Net` for fast exploration.

Two things live here:

* `CompactNet`: the net as numpy arrays, built once. Dense ``pre``/``post``/``delta``
  matrices (transitions x places), the sparse presets grouped by preset size so that
  enabling over a whole frontier is a handful of vectorised gathers, and the positive
  effects of every transition (for overflow checks).
* `Layout`: how a marking is packed into a few ``uint64`` words. Every place gets a
  bit field wide enough for the tokens seen so far; packing is injective, so two
  markings are equal exactly when their packed keys are equal (no hash collisions to
  resolve) and a state costs ``8 * words`` bytes. Packing is linear: the key of
  ``m + delta(t)`` is ``key(m) + key_delta(t)`` (mod 2**64 per word) as long as no field
  overflows, which the explorer checks before it trusts a successor key.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from coral_lang.net import Net

IntArray = npt.NDArray[np.int64]
KeyArray = npt.NDArray[np.uint64]

MAX_FIELD_BITS = 60
"""Widest bit field for one place. Token counts at or above ``2**60`` stop exploration
(such a count only arises in unbounded nets, long after any sensible budget)."""


@dataclass(frozen=True)
class PresetGroup:
    """Transitions that share a preset size ``s``: their input places and weights.

    Attributes:
        transitions: indices of the transitions in the group, shape ``(g,)``.
        places: input place of each arc, shape ``(g, s)``.
        weights: arc weight of each arc, shape ``(g, s)``.
    """

    transitions: IntArray
    places: IntArray
    weights: IntArray


@dataclass(frozen=True)
class CompactNet:
    """A `Net` as arrays: everything the vectorised explorer needs, computed once.

    Attributes:
        net: the net this was built from.
        pre: ``pre[t, p]`` = weight of arc ``p -> t`` (0 if none), shape ``(T, P)``.
        post: ``post[t, p]`` = weight of arc ``t -> p``, shape ``(T, P)``.
        delta: ``post - pre``, the effect of firing ``t``.
        initial: initial marking, shape ``(P,)``.
        groups: sparse presets grouped by size (size 0 = always enabled).
        inc_places: for every transition, the places it strictly increases, padded
            with ``-1``; shape ``(T, k)`` with ``k`` the largest such count (>= 1).
        inc_amounts: the matching increases (0 in the padding).
        max_increase: largest increase of each place by any single firing.
    """

    net: Net
    pre: IntArray
    post: IntArray
    delta: IntArray
    initial: IntArray
    groups: tuple[PresetGroup, ...]
    inc_places: IntArray
    inc_amounts: IntArray
    max_increase: IntArray

    @property
    def n_places(self) -> int:
        """Number of places (columns of a marking)."""
        return int(self.pre.shape[1])

    @property
    def n_transitions(self) -> int:
        """Number of transitions."""
        return int(self.pre.shape[0])

    @classmethod
    def from_net(cls, net: Net) -> CompactNet:
        """Build the arrays of ``net``; parallel arcs between one pair add up."""
        n_p, n_t = len(net.places), len(net.transitions)
        pre = np.zeros((n_t, n_p), dtype=np.int64)
        post = np.zeros((n_t, n_p), dtype=np.int64)
        for t, tr in enumerate(net.transitions):
            for name, weight in tr.inputs:
                pre[t, net.place_index(name)] += weight
            for name, weight in tr.outputs:
                post[t, net.place_index(name)] += weight
        delta = post - pre
        initial = np.array([p.initial for p in net.places], dtype=np.int64)

        # Per-transition place lists from the arcs (never a scan of a dense row: a
        # mission can have thousands of places and transitions).
        presets: list[list[int]] = []
        raised: list[list[int]] = []
        for t, tr in enumerate(net.transitions):
            touched = sorted({net.place_index(name) for name, _ in (*tr.inputs, *tr.outputs)})
            presets.append([p for p in touched if pre[t, p] > 0])
            raised.append([p for p in touched if delta[t, p] > 0])
        sizes = np.array([len(ps) for ps in presets], dtype=np.int64)
        groups = []
        for size in sorted(set(sizes.tolist())):
            members = np.flatnonzero(sizes == size)
            places = np.zeros((members.size, size), dtype=np.int64)
            weights = np.zeros((members.size, size), dtype=np.int64)
            for row, t in enumerate(members.tolist()):
                places[row] = presets[t]
                weights[row] = pre[t, presets[t]]
            groups.append(PresetGroup(members.astype(np.int64), places, weights))

        width = max(1, max((len(r) for r in raised), default=0))
        inc_places = np.full((n_t, width), -1, dtype=np.int64)
        inc_amounts = np.zeros((n_t, width), dtype=np.int64)
        for t, cols in enumerate(raised):
            inc_places[t, : len(cols)] = cols
            inc_amounts[t, : len(cols)] = delta[t, cols]
        max_increase = np.maximum(delta, 0).max(axis=0, initial=0)
        return cls(
            net, pre, post, delta, initial, tuple(groups), inc_places, inc_amounts, max_increase
        )


def _bits_for(value: int) -> int:
    return max(1, int(value).bit_length())


@dataclass(frozen=True)
class Layout:
    """Where each place's token count sits inside the packed key of a marking.

    Attributes:
        bits: field width of each place.
        word: which ``uint64`` word holds each place.
        shift: bit offset of each place inside its word.
        n_words: words per marking.
    """

    bits: tuple[int, ...]
    word: IntArray
    shift: npt.NDArray[np.uint64]
    n_words: int

    @classmethod
    def for_bits(cls, bits: list[int] | tuple[int, ...]) -> Layout:
        """Pack fields in place order, starting a new word when one would overflow."""
        word = np.zeros(len(bits), dtype=np.int64)
        shift = np.zeros(len(bits), dtype=np.uint64)
        current, used = 0, 0
        for p, width in enumerate(bits):
            if used + width > 63:  # the top bit stays 0: all-ones marks an empty slot
                current, used = current + 1, 0
            word[p] = current
            shift[p] = used
            used += width
        return cls(tuple(bits), word, shift, current + 1 if bits else 1)

    @classmethod
    def initial_guess(cls, cn: CompactNet) -> Layout:
        """Fields wide enough for the initial marking and one firing's increase."""
        bits = [
            _bits_for(max(int(m), int(inc)))
            for m, inc in zip(cn.initial.tolist(), cn.max_increase.tolist(), strict=True)
        ]
        return cls.for_bits(bits)

    def widened(self, needed: dict[int, int]) -> Layout:
        """A layout where place ``p`` holds at least ``needed[p]`` (the largest count
        about to be reached). Fields at least double, so a place that keeps growing
        is re-packed ``O(log log bound)`` times, not once per extra bit."""
        bits = list(self.bits)
        for p, value in needed.items():
            bits[p] = max(2 * bits[p], _bits_for(value) + 1)
        return Layout.for_bits(bits)

    @property
    def limits(self) -> IntArray:
        """``2**bits`` per place: the first token count that no longer fits."""
        return np.array([1 << b for b in self.bits], dtype=np.int64)

    def pack(self, rows: npt.NDArray[np.integer]) -> KeyArray:
        """Keys of markings ``rows`` (shape ``(n, P)``), shape ``(n, n_words)``."""
        keys = np.zeros((rows.shape[0], self.n_words), dtype=np.uint64)
        values = rows.astype(np.uint64, copy=False) << self.shift
        for w in range(self.n_words):
            cols = self.word == w
            if cols.any():
                keys[:, w] = np.bitwise_or.reduce(values[:, cols], axis=1)
        return keys

    def unpack(self, keys: KeyArray, dtype: npt.DTypeLike = np.int64) -> npt.NDArray[np.integer]:
        """Markings of ``keys`` (shape ``(n, n_words)``) as rows of ``dtype``."""
        masks = np.array([(1 << b) - 1 for b in self.bits], dtype=np.uint64)
        fields = keys[:, self.word] >> self.shift
        return (fields & masks).astype(dtype)

    def key_deltas(self, delta: IntArray) -> KeyArray:
        """Per transition, what firing it adds to each key word (mod ``2**64``)."""
        out = np.zeros((delta.shape[0], self.n_words), dtype=np.uint64)
        mask = (1 << 64) - 1
        for t in range(delta.shape[0]):
            acc = [0] * self.n_words
            for p in np.flatnonzero(delta[t]).tolist():
                acc[int(self.word[p])] += int(delta[t, p]) << int(self.shift[p])
            out[t] = [a & mask for a in acc]
        return out


def row_dtype(layout: Layout, cn: CompactNet) -> np.dtype[np.signedinteger]:
    """Smallest signed integer type for frontier rows: holds every packed count, every
    arc weight and every effect, so comparisons and ``row + delta`` never wrap."""
    largest = max(
        (1 << max(layout.bits, default=1)) - 1,
        int(np.abs(cn.delta).max(initial=0)),
        int(cn.pre.max(initial=0)),
    )
    for candidate in (np.int8, np.int16, np.int32):
        if largest <= np.iinfo(candidate).max:
            return np.dtype(candidate)
    return np.dtype(np.int64)


_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
EMPTY = np.uint64(0xFFFF_FFFF_FFFF_FFFF)
"""Marks a free slot; no packed key has its top bit set (see `Layout.for_bits`)."""

MAX_LOAD = 0.5
"""Largest fill of the index before it doubles (linear probing stays ~1.5 probes)."""


_S27, _S29, _S30, _S31 = (np.uint64(k) for k in (27, 29, 30, 31))


WIDE_KEYS = 8
"""From this many words per key, hash and compare with whole-array operations: one
numpy call per word costs more than the 2-D work once keys are wide (missions with
thousands of places pack into dozens of words)."""

_WORD_MULTIPLIERS = np.random.default_rng(0x5EED).integers(
    1, np.iinfo(np.int64).max, size=4096, dtype=np.int64
).astype(np.uint64) | np.uint64(1)


def _multipliers(words: int) -> KeyArray:
    if words <= _WORD_MULTIPLIERS.size:
        return _WORD_MULTIPLIERS[:words]
    reps = -(-words // _WORD_MULTIPLIERS.size)
    return np.tile(_WORD_MULTIPLIERS, reps)[:words] * np.uint64(0x9E37)


def _hash(keys: KeyArray) -> KeyArray:
    """A well-mixed 64-bit hash of each key row (splitmix64 finaliser).

    The hash only chooses slots and sort order; keys are always compared in full, so
    its quality affects speed, never exactness.
    """
    if keys.shape[1] >= WIDE_KEYS:
        with np.errstate(over="ignore"):
            mixed: KeyArray = (keys * _multipliers(keys.shape[1])).sum(axis=1, dtype=np.uint64)
            mixed ^= mixed >> _S30
            mixed *= _MIX1
            mixed ^= mixed >> _S27
            mixed *= _MIX2
            mixed ^= mixed >> _S31
        return mixed
    h = keys[:, 0] ^ (keys[:, 0] >> _S30)
    for w in range(1, keys.shape[1]):
        h = (h ^ (h >> _S29)) * _GOLDEN + keys[:, w]
        h ^= h >> _S30
    h *= _MIX1
    h ^= h >> _S27
    h *= _MIX2
    h ^= h >> _S31
    return h


def _rows_differ(a: KeyArray, b: KeyArray) -> npt.NDArray[np.bool_]:
    """Row-wise ``a != b`` over all words, one word at a time (no 2-D reduction)
    unless the keys are wide."""
    if a.shape[1] >= WIDE_KEYS:
        wide: npt.NDArray[np.bool_] = (a != b).any(axis=1)
        return wide
    out: npt.NDArray[np.bool_] = a[:, 0] != b[:, 0]
    for w in range(1, a.shape[1]):
        out |= a[:, w] != b[:, w]
    return out


def first_occurrences(keys: KeyArray) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Distinct rows of ``keys`` by first occurrence.

    Returns:
        ``(first, leader)``: ascending positions of the first occurrence of each
        distinct row, and for every row the position of its first occurrence.
    """
    m = keys.shape[0]
    if m == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    if keys.shape[1] == 1:
        order = np.argsort(keys[:, 0], kind="stable")
        ordered = keys[order, 0]
        starts = np.empty(m, dtype=bool)
        starts[0] = True
        np.not_equal(ordered[1:], ordered[:-1], out=starts[1:])
    else:
        # Sort by a 64-bit hash (cheaper than a lexicographic sort of W words); equal
        # rows are adjacent. A hash collision between different rows (vanishingly
        # rare) would make them adjacent too: then fall back to the exact sort.
        order = np.argsort(_hash(keys), kind="stable")
        ordered2 = keys[order]
        differs = _rows_differ(ordered2[1:], ordered2[:-1])
        hashes = _hash(ordered2)
        if (differs & (hashes[1:] == hashes[:-1])).any():
            order = np.lexsort(keys.T[::-1])  # stable: equal rows keep batch order
            ordered2 = keys[order]
            differs = _rows_differ(ordered2[1:], ordered2[:-1])
        starts = np.empty(m, dtype=bool)
        starts[0] = True
        starts[1:] = differs
    group_first = order[starts]
    leader = np.empty(m, dtype=np.int64)
    leader[order] = group_first[np.cumsum(starts) - 1]
    return np.sort(group_first), leader


_NO_OWNER = np.iinfo(np.int32).max

PROBE_WINDOW_BELOW = 8192
"""Probe batches up to this size look at `_WINDOW` consecutive slots per round."""

_WINDOW = np.arange(8, dtype=np.int64)


def _arange(n: int) -> npt.NDArray[np.int64]:
    return np.arange(n, dtype=np.int64)


class KeyStore:
    """Packed markings in discovery order plus an open-addressing set of them.

    ``keys[i]`` is the packed marking of state ``i``. The set is a table of keys
    (``EMPTY`` = free), probed linearly from a hash: one random memory access per
    lookup, and since keys are injective, key equality *is* marking equality.
    Lookups and inserts are vectorised over whole batches.
    """

    def __init__(self, n_words: int, capacity: int = 1 << 12) -> None:
        self.n_words = n_words
        self.size = 0
        self._keys = np.zeros((capacity, n_words), dtype=np.uint64)
        self._log = max(4, (int(capacity / MAX_LOAD) - 1).bit_length())
        self._table = np.full((1 << self._log, n_words), EMPTY, dtype=np.uint64)
        self._owner = np.zeros(0, dtype=np.int32)  # scratch for `add`, table-sized
        self._empty = self._rows(np.full((1, n_words), EMPTY, dtype=np.uint64))[0]

    @classmethod
    def of(cls, keys: KeyArray) -> KeyStore:
        """A store holding ``keys`` (pairwise distinct) as states ``0 .. len-1``."""
        store = cls(keys.shape[1], max(1 << 12, keys.shape[0]))
        store._append(keys)
        return store

    @property
    def keys(self) -> KeyArray:
        """Keys of all stored states, shape ``(size, n_words)`` (a view)."""
        return self._keys[: self.size]

    @property
    def nbytes(self) -> int:
        """Bytes held by the key array and the table (allocated, not just used)."""
        return int(self._keys.nbytes + self._table.nbytes)

    def _slots(self, keys: KeyArray, hashes: KeyArray | None = None) -> npt.NDArray[np.int64]:
        if hashes is None:
            hashes = _hash(keys)
        return (hashes >> np.uint64(64 - self._log)).astype(np.int64)

    def _rows(self, keys: KeyArray) -> npt.NDArray[np.generic]:
        """``keys`` (C-contiguous) as a 1-D array with one item per row: ``uint64``
        for one word, else a ``void`` of the row's bytes (compared in one call)."""
        if self.n_words == 1:
            return keys.reshape(-1)
        return keys.view(np.dtype((np.void, 8 * self.n_words))).reshape(-1)

    def contains(self, cand: KeyArray, hashes: KeyArray | None = None) -> npt.NDArray[np.bool_]:
        """Which candidate keys are stored (``hashes``: their `_hash`, if known)."""
        mask = (1 << self._log) - 1
        table = self._rows(self._table)
        empty = self._empty
        rows = self._rows(np.ascontiguousarray(cand))
        slots = self._slots(cand, hashes)
        found = np.zeros(cand.shape[0], dtype=bool)
        active = np.arange(cand.shape[0], dtype=np.int64)
        one = self.n_words == 1
        while active.size:
            s = slots[active]
            # ``take`` is several times faster than fancy indexing of rows. Small
            # batches look at a window of slots per round: fewer numpy calls.
            if active.size > PROBE_WINDOW_BELOW:
                if one:
                    content = table.take(s)
                    equal = content == rows.take(active)
                    stop = equal | (content == empty)
                else:
                    content2 = self._table.take(s, axis=0)
                    equal = ~_rows_differ(content2, cand.take(active, axis=0))
                    stop = equal | (content2[:, 0] == EMPTY)
                step = 1
            else:
                window = (s[:, None] + _WINDOW) & mask
                content = table.take(window)
                hits = content == rows.take(active)[:, None]
                ends = hits | (content == empty)
                stop = ends.any(axis=1)
                equal = hits[_arange(stop.size), ends.argmax(axis=1)] & stop
                step = _WINDOW.size
            found[active[equal]] = True
            more = ~stop
            active = active[more]
            slots[active] = (s[more] + step) & mask
        return found

    def _place(self, keys: KeyArray) -> None:
        """Write pairwise distinct keys that are not in the table yet into it."""
        mask = (1 << self._log) - 1
        table = self._table
        slots = self._slots(keys)
        active = np.arange(keys.shape[0], dtype=np.int64)
        while active.size:
            s = slots[active]
            free = table.take(s, axis=0)[:, 0] == EMPTY
            sf, af = s[free], active[free]
            # Several claims on one free slot: the last write wins, the others probe on.
            table[sf] = keys.take(af, axis=0)
            won = np.zeros(active.size, dtype=bool)
            won[free] = ~_rows_differ(table.take(sf, axis=0), keys.take(af, axis=0))
            active = active[~won]
            slots[active] = (s[~won] + 1) & mask

    def _grow_keys(self, need: int) -> None:
        if need > self._keys.shape[0]:
            grown = np.zeros((max(need, 2 * self._keys.shape[0]), self.n_words), np.uint64)
            grown[: self.size] = self._keys[: self.size]
            self._keys = grown

    def _rebuild(self, load: float, need: int) -> None:
        """Grow the table (re-placing the stored keys) until ``need`` keys fit at
        most ``load`` full; nothing happens if they already do."""
        if need <= load * (1 << self._log):
            return
        while need > load * (1 << self._log):
            self._log += 1
        self._table = np.full((1 << self._log, self.n_words), EMPTY, dtype=np.uint64)
        self._owner = np.zeros(0, dtype=np.int32)
        self._place(self._keys[: self.size])

    def _append(self, keys: KeyArray) -> None:
        need = self.size + keys.shape[0]
        self._grow_keys(need)
        self._rebuild(MAX_LOAD, need)
        self._place(keys)
        self._keys[self.size : need] = keys
        self.size = need

    def _claim(self, keys: KeyArray, hashes: KeyArray) -> npt.NDArray[np.int64]:
        """Place keys that are not in the table before the call, repeats allowed,
        and return each key's slot (equal keys share one)."""
        mask = (1 << self._log) - 1
        table = self._table
        one = self.n_words == 1
        flat_table = table.reshape(-1)
        flat_keys = keys.reshape(-1)
        slots = self._slots(keys, hashes)
        active = np.arange(keys.shape[0], dtype=np.int64)
        while active.size:
            s = slots[active]
            if one:
                mine = flat_keys.take(active)
                free = flat_table.take(s) == EMPTY
                # Several claims on one free slot: the last write wins, equal keys
                # find their copy, the others probe on.
                flat_table[s[free]] = mine[free]
                done = flat_table.take(s) == mine
            else:
                mine2 = keys.take(active, axis=0)
                free = table.take(s, axis=0)[:, 0] == EMPTY
                table[s[free]] = mine2[free]
                done = ~_rows_differ(table.take(s, axis=0), mine2)
            more = ~done
            active = active[more]
            slots[active] = (s[more] + 1) & mask
        return slots

    def add(self, cand: KeyArray, limit: int | None = None) -> Added:
        """Store the candidate keys not seen before; the batch may repeat keys.

        Args:
            cand: candidate keys, shape ``(m, n_words)``.
            limit: store at most this many new states (the budget left).

        Returns:
            An `Added` record; the new states are numbered ``size_before, ...`` in
            the order of their first occurrence in ``cand``.
        """
        hashes = _hash(cand)
        known = self.contains(cand, hashes)
        unknown = np.flatnonzero(~known)
        start = self.size
        if (limit is not None and unknown.size > limit) or unknown.size >= _NO_OWNER:
            first, leader = first_occurrences(cand[unknown])
            first = unknown[first]
            cut = limit is not None and first.size > limit
            if limit is not None and cut:
                first = first[:limit]
            self._append(cand[first])
            return Added(known, unknown, unknown[leader], first, start, cut)
        # No budget cut possible: the table itself removes repeats. Every unknown key
        # is placed (the table may fill to 3/4 for a moment), then the first
        # occurrence of each slot is its smallest batch position.
        self._rebuild(0.75, self.size + unknown.size)
        slot = self._claim(cand.take(unknown, axis=0), hashes.take(unknown))
        if self._owner.size != 1 << self._log:
            self._owner = np.full(1 << self._log, _NO_OWNER, dtype=np.int32)
        owner = self._owner
        local = np.arange(unknown.size, dtype=np.int32)
        np.minimum.at(owner, slot, local)
        lead = owner.take(slot).astype(np.int64)
        owner[slot] = _NO_OWNER
        first_local = np.flatnonzero(lead == local)
        first = unknown[first_local]
        need = self.size + first.size
        self._grow_keys(need)
        self._keys[self.size : need] = cand.take(first, axis=0)
        self.size = need
        self._rebuild(MAX_LOAD, need)
        return Added(known, unknown, unknown[lead], first, start, False)


@dataclass(frozen=True)
class Added:
    """What `KeyStore.add` did with a batch of candidate keys.

    Attributes:
        known: per candidate, whether it was stored before the batch.
        unknown: positions of the other candidates.
        leader: for each of ``unknown``, the position of the first candidate in the
            batch with the same key.
        first: positions of the candidates stored as new states, ascending.
        start: the state number given to ``first[0]``.
        cut: whether the state limit turned new states away.
    """

    known: npt.NDArray[np.bool_]
    unknown: npt.NDArray[np.int64]
    leader: npt.NDArray[np.int64]
    first: npt.NDArray[np.int64]
    start: int
    cut: bool
