"""Packing markings into ``uint64`` words (`Layout`) and seeing the net through those
fields (`FieldNet`).

Part of `analysis.encoding`; see its docstring for how the pieces fit."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import numpy.typing as npt

from analysis.encoding.compact import (
    FIELD_LOOP,
    MAX_FIELD_BITS,
    NEVER,
    Arcs,
    BoolArray,
    CompactNet,
    IntArray,
    KeyArray,
)
from analysis.encoding.components import Component

# -- packing -----------------------------------------------------------------------------


def _bits_for(value: int) -> int:
    return int(value).bit_length()


def _count_bits(value: int) -> int:
    return max(1, _bits_for(value))


SMALL_FIELD_BITS = 4
"""Widest a count field starts at when a proven bound caps it (below, the cap itself)."""


@dataclass(frozen=True)
class Layout:
    """Where each place's token count sits inside the packed key of a marking.

    A key is a row of ``n_words`` ``uint64`` words; each word holds fields side by side
    with its top bit always 0 (so a key plus one, the table's tag, never wraps). A field
    is a place's count (``onehot`` false) or, for a `Component`, which of its places
    holds the token: ``first[f] + i`` for its ``i``-th place, 0 for none when
    ``first[f]`` is 1.

    Attributes:
        bits: width of each field.
        members: places of each field.
        onehot: whether each field is a component.
        word: which word holds each field.
        shift: bit offset of each field inside its word.
        n_words: words per marking.
        n_places: places of the net.
        first: per field, the value of its first place (0 for counts and components
            that always hold a token, 1 for the others); empty means all 0.
        caps: per field, the most bits its values can ever need (a place bound proven
            by an invariant, see `analysis.encoding.bounds`): no widening goes past it.
            Empty means `MAX_FIELD_BITS` for all.
    """

    bits: tuple[int, ...]
    members: tuple[tuple[int, ...], ...]
    onehot: tuple[bool, ...]
    word: IntArray
    shift: npt.NDArray[np.uint64]
    n_words: int
    n_places: int
    first: tuple[int, ...] = ()
    caps: tuple[int, ...] = ()

    @classmethod
    def build(
        cls,
        bits: Sequence[int],
        members: Sequence[Sequence[int]],
        onehot: Sequence[bool],
        n_places: int,
        first: Sequence[int] = (),
        caps: Sequence[int] = (),
    ) -> Layout:
        """Pack the fields first-fit, widest first (fewest words), never past bit 62."""
        word = np.zeros(len(bits), dtype=np.int64)
        shift = np.zeros(len(bits), dtype=np.uint64)
        used: list[int] = []
        # The first word with room for a width: words before it stay too full for that
        # width (they only fill up), so the scan resumes there, once per width, and
        # costs the words once per width instead of once per field (2,000 fields in
        # 134 words: 0.1 s).
        first_free: dict[int, int] = {}
        for f in sorted(range(len(bits)), key=lambda f: -bits[f]):
            w = first_free.get(bits[f], 0)
            while w < len(used) and used[w] + bits[f] > 63:
                w += 1
            first_free[bits[f]] = w
            if w == len(used):
                used.append(0)
            word[f], shift[f] = w, used[w]
            used[w] += bits[f]
        return cls(
            tuple(int(b) for b in bits),
            tuple(tuple(int(p) for p in m) for m in members),
            tuple(bool(o) for o in onehot),
            word,
            shift,
            max(1, len(used)),
            n_places,
            tuple(int(v) for v in first) or (0,) * len(bits),
            tuple(int(c) for c in caps) or (MAX_FIELD_BITS,) * len(bits),
        )

    @classmethod
    def for_bits(cls, bits: Sequence[int]) -> Layout:
        """One count field per place, of the given widths."""
        return cls.build(bits, [(p,) for p in range(len(bits))], [False] * len(bits), len(bits))

    @classmethod
    def initial_guess(
        cls,
        cn: CompactNet,
        components: Sequence[Component] | None = None,
        bounds: IntArray | None = None,
    ) -> Layout:
        """One field per component, and count fields wide enough for the initial
        marking and one firing's increase for the other places, capped by their proven
        ``bounds`` (per place, negative where unknown). A bounded field starts at its
        cap when that is at most `SMALL_FIELD_BITS` (no widening ever re-packs for it);
        a wider cap is reached by widening only if the counts get there."""
        components = list(components or [])
        covered = np.zeros(cn.n_places, dtype=bool)
        for c in components:
            covered[c.places] = True
        bits = [_bits_for(c.values - 1) for c in components]
        caps = list(bits)
        members: list[Sequence[int]] = [c.places.tolist() for c in components]
        onehot = [True] * len(components)
        first = [0 if c.exact else 1 for c in components]
        for p in np.flatnonzero(~covered).tolist():
            guess = _count_bits(max(int(cn.initial[p]), int(cn.max_increase[p])))
            cap = MAX_FIELD_BITS
            if bounds is not None and int(bounds[p]) >= 0:
                cap = min(cap, _count_bits(int(bounds[p])))
                guess = cap if cap <= SMALL_FIELD_BITS else min(guess, cap)
            bits.append(guess)
            caps.append(cap)
            members.append((p,))
            onehot.append(False)
            first.append(0)
        return cls.build(bits, members, onehot, cn.n_places, first, caps)

    def widened(
        self,
        needed: dict[int, int],
        growing: Sequence[int] = (),
        reached: IntArray | None = None,
    ) -> Layout:
        """A layout where place ``p`` holds at least ``needed[p]`` (the largest count
        about to be reached; never a one-hot place).

        Every re-packing costs a pass over all stored keys, and every extra word slows
        every later step, so: a needed field gets one bit of headroom; then the spare
        bits of the words that are needed anyway go to the ``growing`` places (counts
        close to their limit, widened three times already), each at most doubling. A
        place that keeps growing is thus re-packed about ``log log bound`` times, and
        a bounded net keeps the fewest words its bounds allow.

        Spare bits given earlier may be what a new word would be for: when ``reached``
        (per field, the largest value stored so far) is given and the widths that
        values need (one bit of headroom below the cap) take fewer words, those are
        used instead, narrower fields included (DoubleExponent-PT-003: 2 words where
        the generous widths took 3). No width is ever past its `caps` entry.
        """
        bits = self._needed_bits(list(self.bits), needed)
        words = self._rebuilt(bits).n_words
        if reached is not None and words > self.n_words:
            tight = self._needed_bits(self._tight_bits(reached), needed)
            if self._rebuilt(tight).n_words < words:
                bits, words = tight, self._rebuilt(tight).n_words
        for p in growing:
            f = int(self.field_of[p])
            trial = list(bits)
            trial[f] = min(2 * bits[f], self.caps[f])
            fits = trial[f] > bits[f] and sum(trial) <= 63 * words
            if fits and self._rebuilt(trial).n_words == words:
                bits = trial
        return self._rebuilt(bits)

    def _needed_bits(self, bits: list[int], needed: dict[int, int]) -> list[int]:
        """``bits`` with the fields of ``needed`` places widened (one bit of headroom,
        within the cap; never narrower)."""
        for p, value in needed.items():
            f = int(self.field_of[p])
            wider = max(bits[f] + 1, _count_bits(value) + 1)
            if _count_bits(value) <= self.caps[f]:  # always, the cap being proven
                wider = min(wider, self.caps[f])
            bits[f] = max(bits[f], wider)
        return bits

    def _tight_bits(self, reached: IntArray) -> list[int]:
        """Per field, the bits its largest value so far needs plus one of headroom
        (none at the cap); one-hot fields as they are."""
        out = list(self.bits)
        for f, onehot in enumerate(self.onehot):
            if not onehot:
                need = _count_bits(int(reached[f]))
                out[f] = need + 1 if need < self.caps[f] else need
        return out

    def _rebuilt(self, bits: Sequence[int]) -> Layout:
        """This layout with other field widths."""
        return Layout.build(bits, self.members, self.onehot, self.n_places, self.first, self.caps)

    def repack(self, keys: KeyArray, other: Layout, out: KeyArray | None = None) -> KeyArray:
        """``keys`` (packed with this layout) packed with ``other``, which has the same
        fields, possibly wider: field by field, never through full markings, in blocks
        of rows (a widening re-packs the whole store). ``out`` receives them when given,
        which may be ``keys`` itself when ``other`` has as many words (each block is read
        whole before it is written): a widening then needs no second copy of the store."""
        if out is None:
            out = np.empty((keys.shape[0], other.n_words), dtype=np.uint64)
        assert out.shape == (keys.shape[0], other.n_words), "repack: wrong output shape"
        fields = len(self.bits)
        step = 1 << 16 if fields <= FIELD_LOOP else max(1, (1 << 22) // fields)
        for start in range(0, keys.shape[0], step):
            block = keys[start : start + step]
            if fields <= FIELD_LOOP:
                out[start : start + step] = self._repack_by_field(block, other)
            else:
                out[start : start + step] = self._repack_at_once(block, other)
        return out

    def _masks(self) -> KeyArray:
        return (np.uint64(1) << np.asarray(self.bits, dtype=np.uint64)) - np.uint64(1)

    def _repack_by_field(self, keys: KeyArray, other: Layout) -> KeyArray:
        """Few fields: one pass per field over contiguous word rows."""
        words = np.ascontiguousarray(keys.T)
        out = np.zeros((other.n_words, keys.shape[0]), dtype=np.uint64)
        masks = self._masks()
        for f in range(len(self.bits)):
            value = words[self.word[f]] >> self.shift[f]
            value &= masks[f]
            value <<= other.shift[f]
            out[other.word[f]] |= value
        return out.T

    def _repack_at_once(self, keys: KeyArray, other: Layout) -> KeyArray:
        """Many fields: 2-D passes (a per-field loop would cost a numpy call each)."""
        fields = (keys[:, self.word] >> self.shift) & self._masks()
        fields <<= other.shift
        out = np.zeros((keys.shape[0], other.n_words), dtype=np.uint64)
        for w in range(other.n_words):
            cols = other.word == w
            if cols.any():
                out[:, w] = fields[:, cols].sum(axis=1, dtype=np.uint64)
        return out

    # -- per place views ------------------------------------------------------------

    @cached_property
    def field_of(self) -> IntArray:
        """The field of each place."""
        out = np.zeros(self.n_places, dtype=np.int64)
        for f, places in enumerate(self.members):
            out[list(places)] = f
        return out

    @cached_property
    def place_onehot(self) -> BoolArray:
        """Whether each place belongs to a one-hot component."""
        return (
            np.asarray(self.onehot, dtype=bool)[self.field_of]
            if self.n_places
            else np.zeros(0, bool)
        )

    @cached_property
    def coefficient(self) -> KeyArray:
        """What one token on each place adds to its field: 1 for a count, the place's
        value in its component (``first`` plus its index) for a component's place."""
        out = np.ones(self.n_places, dtype=np.uint64)
        for places, onehot, first in zip(self.members, self.onehot, self.first, strict=True):
            if onehot:
                out[list(places)] = np.arange(len(places), dtype=np.uint64) + np.uint64(first)
        return out

    @cached_property
    def multiplier(self) -> KeyArray:
        """What one token on each place adds to its word of the key."""
        if not self.n_places:
            return np.zeros(0, dtype=np.uint64)
        return self.coefficient << self.shift[self.field_of]

    @cached_property
    def place_word(self) -> IntArray:
        """The word holding each place's field."""
        return self.word[self.field_of] if self.n_places else np.zeros(0, np.int64)

    @property
    def limits(self) -> IntArray:
        """Per place, the first token count that no longer fits (`NEVER` for one-hot
        places, which hold at most one token)."""
        widths = np.asarray(self.bits, dtype=np.int64)[self.field_of]
        out = np.left_shift(np.int64(1), widths)
        out[self.place_onehot] = NEVER
        return out

    @property
    def count_bits(self) -> IntArray:
        """Per place, the width of its count field (0 for one-hot places)."""
        widths = np.asarray(self.bits, dtype=np.int64)[self.field_of]
        widths[self.place_onehot] = 0
        return widths

    @cached_property
    def word_bytes(self) -> tuple[int, ...]:
        """Per word, the bytes its fields reach (at least 1): the store keeps only
        those (`analysis.encoding.PackedRows`), since the bits above the top field
        of a stored key are always 0 (an overflow is widened before it is stored)."""
        used = [0] * self.n_words
        for f, width in enumerate(self.bits):
            w = int(self.word[f])
            used[w] = max(used[w], int(self.shift[f]) + width)
        return tuple(max(1, -(-u // 8)) for u in used)

    @property
    def boundary(self) -> KeyArray:
        """Per word, the bit just above every count field: an addition that overflows a
        field carries into it."""
        out = np.zeros(self.n_words, dtype=np.uint64)
        for f, width in enumerate(self.bits):
            if not self.onehot[f]:
                out[self.word[f]] |= np.uint64(1 << (int(self.shift[f]) + width))
        return out

    # -- packing ---------------------------------------------------------------------

    def pack(self, rows: npt.NDArray[np.integer]) -> KeyArray:
        """Keys of reachable markings ``rows`` (shape ``(n, P)``), shape
        ``(n, n_words)``."""
        keys = np.zeros((rows.shape[0], self.n_words), dtype=np.uint64)
        if not self.n_places:
            return keys
        values = rows.astype(np.uint64) * self.multiplier
        for w in range(self.n_words):
            cols = self.place_word == w
            if cols.any():
                keys[:, w] = values[:, cols].sum(axis=1, dtype=np.uint64)
        return keys

    def unpack(self, keys: KeyArray, dtype: npt.DTypeLike = np.int64) -> npt.NDArray[np.integer]:
        """Markings of ``keys`` (shape ``(n, n_words)``) as rows of ``dtype``."""
        if not self.n_places:
            return np.zeros((keys.shape[0], 0), dtype=dtype)
        widths = np.asarray(self.bits, dtype=np.uint64)[self.field_of]
        masks = (np.uint64(1) << widths) - np.uint64(1)
        fields = (keys[:, self.place_word] >> self.shift[self.field_of]) & masks
        onehot = self.place_onehot
        if onehot.any():
            fields[:, onehot] = fields[:, onehot] == self.coefficient[onehot]
        return fields.astype(dtype)

    def fields(self, keys: KeyArray, dtype: npt.DTypeLike) -> npt.NDArray[np.integer]:
        """Field values of ``keys`` as columns ``(fields, n)`` of ``dtype`` (what
        `FieldNet.values` gives from markings), read straight from the key bits: a
        frontier kept as state numbers is unpacked a block at a time."""
        n_fields = len(self.bits)
        out = np.empty((n_fields, keys.shape[0]), dtype=dtype)
        if not n_fields:
            return out
        words = np.ascontiguousarray(keys.T)
        masks = self._masks()
        for w in range(self.n_words):
            mine = np.flatnonzero(self.word == w)
            if not mine.size:
                continue
            value = np.right_shift(words[w], self.shift[mine][:, None])
            value &= masks[mine][:, None]
            out[mine] = value
        return out

    def key_deltas(self, arcs: Arcs) -> KeyArray:
        """Per transition, what adding its ``arcs`` (e.g. its effect) adds to each key
        word (mod ``2**64``)."""
        n_t = arcs.counts.size
        out = np.zeros(n_t * self.n_words, dtype=np.uint64)
        if arcs.places.size:
            amounts = arcs.values.astype(np.int64).view(np.uint64)
            with np.errstate(over="ignore"):
                contribution = amounts * self.multiplier[arcs.places]
            slot = arcs.rows * self.n_words + self.place_word[arcs.places]
            # the sums per slot (mod 2**64) by sorting, not `np.add.at`: that took 45 ms
            # per call on the 40,000 arcs of 2,000 rings
            order = np.argsort(slot, kind="stable")
            slot = slot[order]
            starts = np.flatnonzero(np.diff(slot, prepend=-1))
            out[slot[starts]] = np.add.reduceat(contribution[order], starts)
        return out.reshape(n_t, self.n_words)


@dataclass(frozen=True)
class FieldGroup:
    """Transitions with the same number of input fields, as `PresetGroup` but per
    field: a transition is enabled when, for every column ``k``, its input field
    ``fields[:, k]`` holds at least ``low[:, k]`` (a count) or exactly ``low[:, k]``
    (``exact``: the index of a one-hot place)."""

    transitions: IntArray
    fields: IntArray
    low: IntArray
    exact: BoolArray


class FieldNet:
    """The net seen through the fields of a `Layout`: enabling, effects and overflow
    checks on field values, so a frontier marking is ``fields`` small integers instead
    of ``places`` (a 56-place process is one field holding the index of its marked
    place). Widening changes field widths, never the fields, so this is built once per
    exploration.

    Attributes:
        n_fields: fields per marking.
        initial: field values of the initial marking.
        groups: presets by size, per field.
        never: transitions that can never be enabled (two tokens asked of a
            component).
        effects: per transition, the change of each field it changes.
        inc_fields: per transition, the count fields it increases, padded with ``-1``.
        inc_amounts: the matching increases.
        max_increase: per field, the largest increase of one firing (0 for one-hot).
        onehot: per field, whether it is a one-hot component.
        count_place: per field, its place if it is a count field, else ``-1``.
        offsets: per component field, where its values start in a flat array of
            (field, value) flags; ``seen_slot`` is that flag for each component place.
        exact: per field, whether it is a component that always holds a token;
            ``partial`` the other components.
    """

    def __init__(self, cn: CompactNet, layout: Layout) -> None:
        field_of, coefficient = layout.field_of, layout.coefficient.astype(np.int64)
        onehot_place = layout.place_onehot
        self.n_fields = len(layout.bits)
        self.onehot = np.asarray(layout.onehot, dtype=bool)
        self.count_place = np.array(
            [m[0] if not o else -1 for m, o in zip(layout.members, layout.onehot, strict=True)],
            dtype=np.int64,
        )
        kinds = list(zip(layout.members, layout.onehot, layout.first, strict=True))
        sizes = np.array([len(m) + first if o else 0 for m, o, first in kinds], dtype=np.int64)
        self.offsets = np.cumsum(sizes) - sizes
        self.n_seen = int(sizes.sum())
        self.onehot_places = np.array([p for m, o, _ in kinds if o for p in m], dtype=np.int64)
        self.seen_slot = (self.offsets[field_of] + coefficient)[self.onehot_places]
        self.exact = self.onehot & (np.asarray(layout.first, dtype=np.int64) == 0)
        self.partial = self.onehot & ~self.exact
        self.initial = self.values(cn.initial[None, :], layout)[0]
        groups, never = [], []
        for g in cn.groups:
            exact = onehot_place[g.places]
            low = np.where(exact, coefficient[g.places], g.weights)
            never.append(g.transitions[(exact & (g.weights > 1)).any(axis=1)])
            groups.append(FieldGroup(g.transitions, field_of[g.places], low, exact))
        self.groups = tuple(groups)
        self.never = np.concatenate(never) if never else np.zeros(0, dtype=np.int64)
        self.effects = self._field_effects(cn, field_of, coefficient)
        eff = self.effects
        raise_ = (eff.values > 0) & ~self.onehot[eff.places]
        rows, fields, amounts = eff.rows[raise_], eff.places[raise_], eff.values[raise_]
        counts = np.bincount(rows, minlength=cn.n_transitions)
        width = max(1, int(counts.max(initial=0)))
        self.inc_fields = np.full((cn.n_transitions, width), -1, dtype=np.int64)
        self.inc_amounts = np.zeros((cn.n_transitions, width), dtype=np.int64)
        slot = np.arange(rows.size) - (np.cumsum(counts) - counts)[rows]
        self.inc_fields[rows, slot] = fields
        self.inc_amounts[rows, slot] = amounts
        self.max_increase = np.zeros(self.n_fields, dtype=np.int64)
        np.maximum.at(self.max_increase, fields, amounts)

    @staticmethod
    def _field_effects(cn: CompactNet, field_of: IntArray, coefficient: IntArray) -> Arcs:
        """Per transition, the net change of each field (a move inside a one-hot
        component changes its field by the difference of the two indices)."""
        eff = cn.effects
        n_f = int(field_of.max(initial=-1)) + 1
        key = eff.rows * n_f + field_of[eff.places]
        unique, inverse = np.unique(key, return_inverse=True)
        total = np.bincount(inverse, weights=eff.values * coefficient[eff.places])
        total = np.rint(total).astype(np.int64)
        keep = total != 0
        rows, fields = unique[keep] // max(1, n_f), unique[keep] % max(1, n_f)
        indptr = np.zeros(cn.n_transitions + 1, dtype=np.int64)
        indptr[1:] = np.cumsum(np.bincount(rows, minlength=cn.n_transitions))
        return Arcs(indptr, fields, total[keep])

    @staticmethod
    def values(rows: npt.NDArray[np.integer], layout: Layout) -> IntArray:
        """Field values of markings ``rows`` (shape ``(n, P)``), shape ``(n, fields)``."""
        out = np.zeros((rows.shape[0], len(layout.bits)), dtype=np.int64)
        if layout.n_places:
            weighted = rows.astype(np.int64) * layout.coefficient.astype(np.int64)
            np.add.at(out.T, layout.field_of, weighted.T)
        return out

    def places(self, cols: npt.NDArray[np.integer], layout: Layout) -> IntArray:
        """Place counts ``(P, n)`` of markings given as field columns ``(fields, n)``."""
        out = cols.take(layout.field_of, axis=0).astype(np.int64)
        onehot = layout.place_onehot
        if onehot.any():
            coefficient = layout.coefficient.astype(np.int64)[onehot]
            out[onehot] = out[onehot] == coefficient[:, None]
        return out


def row_dtype(layout: Layout, cn: CompactNet) -> np.dtype[np.signedinteger]:
    """Smallest signed integer type for frontier rows (field values): holds every field
    value plus one firing's effect, and every arc weight, so comparisons and
    ``row + delta`` never wrap (a value past its field's limit shows as such)."""
    effect = int(np.abs(cn.effects.values).max(initial=0))
    largest = max(
        (1 << max(layout.bits, default=1)) - 1 + effect,
        int(cn.inputs.values.max(initial=0)),
    )
    for candidate in (np.int8, np.int16, np.int32):
        if largest <= np.iinfo(candidate).max:
            return np.dtype(candidate)
    return np.dtype(np.int64)
