"""The packed keys of the stored markings and an open-addressing hash table over them
(`KeyStore`), with batch insertion vectorised over whole frontiers.

Part of `analysis.encoding`; see its docstring for how the pieces fit."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from analysis.allocator import release_free_heap
from analysis.encoding.compact import BoolArray, IntArray, KeyArray
from analysis.encoding.reserved import reserved
from analysis.encoding.slots import SlotTable

# -- hashing -----------------------------------------------------------------------------

_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
EMPTY = 0
"""Marks a free slot: a slot holds a state number plus one (or, while a batch is being
placed, minus one minus a candidate's position), never 0, so a table is born free from
zeroed memory."""

MAX_LOAD = 0.6
"""Largest fill of the table after a batch (linear probing stays ~1.75 probes per hit)."""

BATCH_LOAD = 0.75
"""Largest fill while a batch is placed (batches are cut to stay below it)."""

GROWTH = 1.5
"""Factor by which a full table grows: with slots of 4 bytes and the load kept between
``MAX_LOAD / GROWTH`` and ``MAX_LOAD``, the table costs 6.7-10 bytes per state (doubling
would cost up to 13.3); 5-7.5 with the 3-byte slots of tables up to 2^23 slots."""

_S1, _S27, _S29, _S30, _S31, _S32 = (np.uint64(k) for k in (1, 27, 29, 30, 31, 32))

FILL_CHUNK = 1 << 15
"""Keys placed per step when a table is rebuilt (bounds its temporaries). The last
rebuild comes when the store is near its largest, so its temporaries add to the peak:
2^18 keys took 12-16 MB of them (FMS-PT-00005: 26.7 resident bytes per state against
24.4 with 2^16, at the same speed; 2^14 was slower)."""

TRIM_GROWTH_BYTES = 1 << 22
"""A table growth touching this many new bytes first gives the C heap's free pages back
(`analysis.allocator.release_free_heap`): growths come when the store is near its
largest, so what the heap keeps free then adds to the search's peak (DoubleExponent-PT-003:
10 MB, 4 resident bytes per state)."""

PROBE_WINDOW_BELOW = 4096
"""Probe batches up to this size look at `_WINDOW` consecutive slots per round."""

_WINDOW = np.arange(8, dtype=np.int64)


WIDE_KEYS = 8
"""From this many words per key, hash and compare with whole-array operations: one
numpy call per word costs more than the 2-D work once keys are wide (missions with
thousands of places pack into dozens of words)."""

_WORD_MULTIPLIERS = np.random.default_rng(0x5EED).integers(
    1, np.iinfo(np.int64).max, size=4096, dtype=np.int64
).astype(np.uint64) | np.uint64(1)


def word_multipliers(words: int) -> KeyArray:
    """Odd per-word multipliers (fixed seed) that fold a row of ``words`` words into one
    hash word; the component search uses them to deduplicate its rows too."""
    if words <= _WORD_MULTIPLIERS.size:
        return _WORD_MULTIPLIERS[:words]
    reps = -(-words // _WORD_MULTIPLIERS.size)
    return np.tile(_WORD_MULTIPLIERS, reps)[:words] * np.uint64(0x9E37)


def _mix(h: KeyArray) -> KeyArray:
    """Finaliser of splitmix64, in place: every input bit affects every output bit."""
    h ^= h >> _S30
    h *= _MIX1
    h ^= h >> _S27
    h *= _MIX2
    h ^= h >> _S31
    return h


def _hash(keys: KeyArray) -> KeyArray:
    """A well-mixed 64-bit hash of each key row.

    The hash only chooses slots (and, for keys of several words, the tag kept in the
    table); keys are always compared in full, so its quality affects speed, never
    exactness.
    """
    if keys.shape[1] == 1:
        h = keys[:, 0] * _GOLDEN
        h ^= h >> _S32
        h *= _MIX1
        return h
    with np.errstate(over="ignore"):
        if keys.shape[1] >= WIDE_KEYS:
            mixed: KeyArray = (keys * word_multipliers(keys.shape[1])).sum(axis=1, dtype=np.uint64)
            return _mix(mixed)
        h = keys[:, 0] ^ (keys[:, 0] >> _S30)
        for w in range(1, keys.shape[1]):
            h = (h ^ (h >> _S29)) * _GOLDEN + keys[:, w]
            h ^= h >> _S30
        return _mix(h)


def _rows_differ(a: KeyArray, b: KeyArray) -> BoolArray:
    """Row-wise ``a != b`` over all words, one word at a time (no 2-D reduction)
    unless the keys are wide."""
    if a.shape[1] >= WIDE_KEYS:
        wide: BoolArray = (a != b).any(axis=1)
        return wide
    out: BoolArray = a[:, 0] != b[:, 0]
    for w in range(1, a.shape[1]):
        out |= a[:, w] != b[:, w]
    return out


def first_occurrences(keys: KeyArray) -> tuple[IntArray, IntArray]:
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


@dataclass(frozen=True)
class Added:
    """What `KeyStore.add` did with a batch of candidate keys.

    Attributes:
        first: positions of the candidates stored as new states, ascending; the new
            states are numbered ``start, start + 1, ...`` in this order, and each is
            the first candidate with its key.
        start: the state number given to ``first[0]``.
        cut: whether the state limit turned new states away.
        ids: when asked for, the state number of every candidate (``-1`` for one the
            limit turned away).
    """

    first: IntArray
    start: int
    cut: bool
    ids: IntArray | None = None

    @property
    def known(self) -> BoolArray:
        """Per candidate, whether its key was stored before the batch (needs ``ids``)."""
        assert self.ids is not None, "add(..., want_ids=True) gives ids"
        return (self.ids >= 0) & (self.ids < self.start)


class Growable:
    """An array that grows along its first axis. Its capacity is reserved up front as
    zeroed memory, which costs only address space until rows are written (the kernel
    hands out pages as they are touched, and here touching a fresh page costs far more
    than writing it), so growing within the reservation never copies or re-touches."""

    def __init__(self, tail: tuple[int, ...], dtype: npt.DTypeLike, reserve: int) -> None:
        self._data: npt.NDArray[Any] = reserved((reserve, *tail), dtype)
        self.size = 0

    @property
    def view(self) -> npt.NDArray[Any]:
        """The rows written so far (a view)."""
        return self._data[: self.size]

    @property
    def capacity(self) -> int:
        """Rows that fit without copying."""
        return int(self._data.shape[0])

    @property
    def row_bytes(self) -> int:
        """Bytes of one row."""
        return int(self._data.itemsize * np.prod(self._data.shape[1:], dtype=np.int64))

    def _grown_rows(self, rows: int) -> int:
        """The capacity after growing to hold ``rows`` rows (`GROWTH` steps: a copy
        past the reservation briefly holds old and new arrays, 2.5x rather than 3x)."""
        return max(rows, int(self._data.shape[0] * GROWTH) + 1)

    def growth_bytes(self, rows: int) -> int:
        """Bytes of memory that making room for ``rows`` more rows would newly touch
        or allocate: the rows' own pages within the reservation, a whole new array
        past it. What a search asks its memory budget about before it grows."""
        end = self.size + rows
        if end <= self._data.shape[0]:
            return rows * self.row_bytes
        return self._grown_rows(end) * self.row_bytes

    def ensure(self, rows: int) -> None:
        """Room for ``rows`` rows (copies only past the reservation, by `GROWTH`)."""
        if rows > self._data.shape[0]:
            shape = (self._grown_rows(rows), *self._data.shape[1:])
            grown = np.zeros(shape, dtype=self._data.dtype)
            grown[: self.size] = self._data[: self.size]
            self._data = grown

    def append(self, rows: npt.NDArray[Any]) -> None:
        """Add ``rows`` at the end."""
        end = self.size + rows.shape[0]
        self.ensure(end)
        self._data[self.size : end] = rows
        self.size = end


RESERVE_LIMIT = 1 << 26
"""Most states a store reserves address space for up front (beyond, it doubles)."""

_PLANES: dict[int, tuple[int, ...]] = {
    1: (1,),
    2: (2,),
    3: (2, 1),
    4: (4,),
    5: (4, 1),
    6: (4, 2),
    7: (4, 2, 1),
    8: (8,),
}
"""How a word's used bytes are split into aligned planes of 1, 2, 4 or 8 bytes."""


_LE_WORD = np.dtype("<u8")
"""Words as the store reads their bytes: a plane of ``size`` bytes at byte ``offset``
of word ``w`` is element ``(8 * w + offset) // size`` of a row viewed as ``<u{size}``
(the same on every machine; on a little-endian one the views cost nothing)."""


class _Plane:
    """One aligned plane of a word: ``size`` bytes from byte ``offset`` of word ``word``,
    kept in ``rows``; in a word row viewed as ``le`` (little-endian, ``size`` bytes),
    element ``column``."""

    def __init__(self, word: int, offset: int, size: int, reserve: int) -> None:
        self.size = size
        self.rows = Growable((), np.dtype(f"u{size}"), reserve)
        self.le: np.dtype[Any] = np.dtype(f"<u{size}")
        self.column = (8 * word + offset) // size


def _le_words(words: KeyArray) -> npt.NDArray[Any]:
    """``words`` as contiguous little-endian words (no copy on a little-endian machine
    when they are contiguous already)."""
    return np.ascontiguousarray(words, dtype=_LE_WORD)


KeyParts = list[npt.NDArray[Any]]
"""Candidate keys cut as a `PackedRows` compares them (`PackedRows.split`)."""


class PackedRows:
    """Keys of ``len(word_bytes)`` words, each stored in only its low ``word_bytes[w]``
    bytes (the bytes its fields use; the others are always zero).

    A one-word key of 37 bits takes 5 bytes instead of 8: a ``uint32`` plane for its
    low 4 bytes and a ``uint8`` plane for the fifth. Every plane is a contiguous,
    aligned array, so a gather is one ``take`` per plane (numpy's ``take`` would first
    copy a whole unaligned strided view, and its fancy indexing of one runs at a third
    of the speed) and a range of rows a slice per plane; a word is its planes written
    into the bytes of a zeroed word. With whole words the rows are one ``(rows,
    words)`` array, as before. Planes are reserved like `Growable`'s (zeroed memory,
    address space until written) and grow by `GROWTH` past the reservation.

    Candidates are compared with stored rows a plane at a time (`split`, `same`): most
    comparisons of a search are with another key met on the probe path, which the
    first plane tells apart, so the other planes are gathered only for the few rows
    still equal. Each plane is a random access of its own, so gathering all of a key's
    planes costs several times one gather of whole words; comparing the first plane
    only costs less than that one gather. Whole words below `WIDE_KEYS` are compared
    the same way, a word at a time.
    """

    def __init__(self, word_bytes: Sequence[int], reserve: int) -> None:
        self.word_bytes = tuple(int(b) for b in word_bytes)
        if not self.word_bytes or not all(1 <= b <= 8 for b in self.word_bytes):
            raise ValueError(f"PackedRows: word bytes must be 1..8, got {self.word_bytes}")
        self.n_words = len(self.word_bytes)
        self.row_bytes = sum(self.word_bytes)
        self.whole = self.row_bytes == 8 * self.n_words
        self.masks = [np.uint64((1 << (8 * b)) - 1) for b in self.word_bytes]
        self.size = 0
        reserve = max(1, reserve)
        self._planes: list[_Plane] = []
        if self.whole:
            self._whole = Growable((self.n_words,), np.uint64, reserve)
            return
        for w, b in enumerate(self.word_bytes):
            offset = 0
            for size in _PLANES[b]:
                self._planes.append(_Plane(w, offset, size, reserve))
                offset += size
        # compared widest first (a whole word tells most keys apart), then in order
        self._compared = sorted(self._planes, key=lambda p: -p.size)

    @property
    def capacity(self) -> int:
        """Rows that fit without copying."""
        if self.whole:
            return self._whole.capacity
        return min(p.rows.capacity for p in self._planes)

    @property
    def nbytes(self) -> int:
        """Bytes of the rows written."""
        return self.size * self.row_bytes

    def growth_bytes(self, rows: int) -> int:
        """As `Growable.growth_bytes`, over all planes."""
        if self.whole:
            return self._whole.growth_bytes(rows)
        return sum(p.rows.growth_bytes(rows) for p in self._planes)

    def _overflow(self, words: KeyArray) -> int | None:
        """A word of ``words`` that some key uses beyond its bytes, or ``None``."""
        for w, b in enumerate(self.word_bytes):
            if b < 8 and words.shape[0] and words[:, w].max() > self.masks[w]:
                return w
        return None

    def put(self, start: int, words: KeyArray) -> None:
        """Write ``words`` (shape ``(m, n_words)``) as rows ``start ...`` (within
        ``size`` or right after it). Raises ``ValueError`` if a word uses a byte
        beyond its ``word_bytes`` (the layout promised they are zero)."""
        m = words.shape[0]
        end = start + m
        if self.whole:
            self._whole.ensure(end)
            self._whole.size = max(self._whole.size, end)
            self._whole.view[start:end] = words
            self.size = max(self.size, end)
            return
        w = self._overflow(words)
        if w is not None:
            raise ValueError(
                f"PackedRows: a key uses more than {self.word_bytes[w]} bytes of word {w}"
            )
        le = _le_words(words)
        for p in self._planes:
            p.rows.ensure(end)
            p.rows.size = max(p.rows.size, end)
            np.copyto(p.rows.view[start:end], le.view(p.le)[:, p.column])
        self.size = max(self.size, end)

    def append(self, words: KeyArray) -> None:
        """Add ``words`` as the next rows."""
        self.put(self.size, words)

    def _assembled(self, values: list[npt.NDArray[Any]]) -> KeyArray:
        """Words from the values of every plane (in `_planes` order): each written into
        its bytes of a zeroed word row."""
        le = np.zeros((values[0].shape[0], self.n_words), dtype=_LE_WORD)
        for p, value in zip(self._planes, values, strict=True):
            le.view(p.le)[:, p.column] = value
        words: KeyArray = le.astype(np.uint64, copy=False)
        return words

    def words(self, start: int, stop: int) -> KeyArray:
        """Rows ``start .. stop - 1`` as words ``(m, n_words)`` (a view with whole
        words: do not write to it)."""
        stop = min(max(start, stop), self.size)
        if self.whole:
            view: KeyArray = self._whole.view[start:stop]
            return view
        return self._assembled([p.rows.view[start:stop] for p in self._planes])

    def take(self, ids: IntArray) -> KeyArray:
        """Rows ``ids`` as words ``(len(ids), n_words)``."""
        if self.whole:
            rows: KeyArray = self._whole.view.take(ids, axis=0)
            return rows
        return self._assembled([p.rows.view.take(ids) for p in self._planes])

    def take_flat(self, ids: IntArray) -> KeyArray:
        """`take` of one-word rows as a 1-D array."""
        if self.whole:
            flat: KeyArray = self._whole.view[:, 0].take(ids)
            return flat
        return np.ascontiguousarray(self.take(ids)[:, 0])

    # -- comparing candidates with stored rows -----------------------------------------

    def split(self, words: KeyArray) -> tuple[KeyParts, BoolArray | None]:
        """Candidate keys ``words`` cut for `same`: per compared plane, the candidates'
        values in it (contiguous); and which candidates a row can hold at all (``None``
        when all can): one that uses a byte beyond its word's ``word_bytes`` equals no
        stored row, yet its planes alone might."""
        if self.whole:
            if self.n_words >= WIDE_KEYS:
                return [np.ascontiguousarray(words)], None
            return [np.ascontiguousarray(words[:, w]) for w in range(self.n_words)], None
        le = _le_words(words)
        parts = [
            np.ascontiguousarray(le.view(p.le)[:, p.column], p.rows.view.dtype)
            for p in self._compared
        ]
        fits: BoolArray | None = None
        if self._overflow(words) is not None:
            fits = np.ones(words.shape[0], dtype=bool)
            for w, mask in enumerate(self.masks):
                fits &= words[:, w] <= mask
        return parts, fits

    def same(self, ids: IntArray, parts: KeyParts, at: IntArray) -> BoolArray:
        """Whether stored rows ``ids`` equal the candidates at positions ``at`` of
        ``parts`` (`split`): the first compared plane for all, the next ones only
        for the rows equal so far (all rows while most are)."""
        if self.whole and self.n_words >= WIDE_KEYS:
            rows = self._whole.view.take(ids, axis=0)
            same_rows: BoolArray = ~_rows_differ(rows, parts[0].take(at, axis=0))
            return same_rows
        gather = self._gatherer()
        out: BoolArray = gather(0, ids) == parts[0].take(at)
        for k in range(1, len(parts)):
            equal = int(np.count_nonzero(out))
            if not equal:
                break
            if 2 * equal >= out.size:
                out &= gather(k, ids) == parts[k].take(at)
            else:
                live = np.flatnonzero(out)
                out[live] = gather(k, ids.take(live)) == parts[k].take(at.take(live))
        return out

    def _gatherer(self) -> Callable[[int, IntArray], npt.NDArray[Any]]:
        """``gather(k, rows)``: compared plane ``k`` of stored ``rows``."""
        if not self.whole:
            compared = self._compared
            return lambda k, rows: compared[k].rows.view.take(rows)
        n_words, flat = self.n_words, self._whole.view.reshape(-1)
        if n_words == 1:
            return lambda k, rows: flat.take(rows)
        return lambda k, rows: flat.take(rows * n_words + k)


def same_parts(parts: KeyParts, a: IntArray, b: IntArray) -> BoolArray:
    """Whether the candidates at positions ``a`` and ``b`` of ``parts`` (one batch's
    `PackedRows.split`) are equal, plane by plane."""
    first = parts[0]
    if first.ndim == 2:
        wide: BoolArray = ~_rows_differ(first.take(a, axis=0), first.take(b, axis=0))
        return wide
    out: BoolArray = first.take(a) == first.take(b)
    for part in parts[1:]:
        out &= part.take(a) == part.take(b)
    return out


class KeyView:
    """The stored keys as words, read from a `PackedRows` only where they are
    indexed: ``view[a:b]`` and ``view.take(ids, axis=0)`` build just those rows, so a
    block of the frontier or a trace step never materialises the whole store. Any
    other index, ``len``, ``shape`` and numpy conversion see the whole array."""

    def __init__(self, rows: PackedRows) -> None:
        self._rows = rows

    @property
    def shape(self) -> tuple[int, int]:
        return (self._rows.size, self._rows.n_words)

    @property
    def nbytes(self) -> int:
        """Bytes the rows take in the store."""
        return self._rows.nbytes

    def __len__(self) -> int:
        return self._rows.size

    def __getitem__(self, index: Any) -> KeyArray:
        if isinstance(index, slice) and index.step in (None, 1):
            start, stop, _ = index.indices(self._rows.size)
            return self._rows.words(start, stop)
        if isinstance(index, np.ndarray) and index.ndim == 1 and index.dtype.kind in "iu":
            ids = np.where(index < 0, index + self._rows.size, index).astype(np.int64)
            return self._rows.take(ids)
        whole: KeyArray = self._rows.words(0, self._rows.size)[index]
        return whole

    def take(self, ids: IntArray, axis: int = 0) -> KeyArray:
        """Rows ``ids`` (``axis`` must be 0)."""
        assert axis == 0, "KeyView.take reads rows"
        return self._rows.take(np.asarray(ids, dtype=np.int64))

    def __array__(self, dtype: Any = None, copy: Any = None) -> KeyArray:
        whole = self._rows.words(0, self._rows.size)
        return whole if dtype is None else whole.astype(dtype)

    def tolist(self) -> list[list[int]]:
        rows: list[list[int]] = self._rows.words(0, self._rows.size).tolist()
        return rows


def _word_bytes(n_words: int, word_bytes: Sequence[int] | None) -> tuple[int, ...]:
    """Bytes stored of each of ``n_words`` words: all 8 unless told."""
    if word_bytes is None:
        return (8,) * n_words
    if len(word_bytes) != n_words:
        raise ValueError(f"KeyStore: {len(word_bytes)} word byte counts for {n_words} words")
    return tuple(int(b) for b in word_bytes)


class KeyStore:
    """Packed markings in discovery order plus an open-addressing set of them.

    ``keys[i]`` is the packed marking of state ``i``. The table holds nothing but state
    numbers: one slot (`SlotTable`: 3 bytes up to 2^23 slots, then 4, 8 with
    ``wide_index``) is ``EMPTY`` or a state number plus one, and a probe compares the
    candidate with the stored key it points to. This costs one more memory access per
    probe than keeping a copy of the key (or a tag) in the slot, but a quarter of the
    memory of the 12-byte tag-and-number slots it replaced,
    and the table needs no copy of the keys at all: it is rebuilt from ``keys`` when it
    grows. Slots are probed linearly from a hash of the key (mapped onto a table of
    any size by multiply-shift, so it grows by `GROWTH`, not 2); inserts are vectorised
    over whole batches, equal keys in one batch resolved in the table (their slots hold
    minus one minus the candidate's position until the batch is numbered). The table
    lives in a prefix of buffers reserved for ``reserve`` states and grows in place
    (see `Growable` for why).
    """

    def __init__(
        self,
        n_words: int,
        capacity: int = 1 << 12,
        wide_index: bool = False,
        reserve: int | None = None,
        word_bytes: Sequence[int] | None = None,
    ) -> None:
        self.n_words = n_words
        reserve = min(max(capacity, reserve or 0), RESERVE_LIMIT)
        self._keys = PackedRows(_word_bytes(n_words, word_bytes), reserve)
        self._table = SlotTable(int(reserve / MAX_LOAD) + 16, wide_index)
        self._use_table(max(16, int(capacity / MAX_LOAD) + 1))

    @classmethod
    def of(cls, keys: KeyArray, wide_index: bool = False, reserve: int = 0) -> KeyStore:
        """A store holding ``keys`` (pairwise distinct) as states ``0 .. len-1``."""
        store = cls(keys.shape[1], max(1 << 12, keys.shape[0]), wide_index, reserve)
        store._insert_distinct(np.ascontiguousarray(keys))
        return store

    @property
    def size(self) -> int:
        """Number of stored states."""
        return self._keys.size

    @property
    def keys(self) -> KeyView:
        """Keys of all stored states, shape ``(size, n_words)``, read as words where
        indexed (`KeyView`)."""
        return KeyView(self._keys)

    @property
    def word_bytes(self) -> tuple[int, ...]:
        """Bytes stored of each key word."""
        return self._keys.word_bytes

    @property
    def nbytes(self) -> int:
        """Bytes of the stored keys and of the table in use."""
        return int(self._keys.nbytes + self._table.nbytes)

    def rekey(self, keys: KeyArray, word_bytes: Sequence[int] | None = None) -> None:
        """Replace every stored key by ``keys`` (same states, same order, a new packing,
        pairwise distinct) and rebuild the table in place: a widening re-packs the
        store without allocating (and touching) a new table."""
        self.repack(lambda block: block, keys.shape[1], word_bytes, source=keys)

    def repack(
        self,
        convert: Callable[[KeyArray], KeyArray],
        n_words: int,
        word_bytes: Sequence[int] | None = None,
        source: KeyArray | None = None,
    ) -> None:
        """Replace every stored key by ``convert`` of it (a new packing: same states,
        same order, pairwise distinct keys of ``n_words`` words that use
        ``word_bytes``), a block of `FILL_CHUNK` keys at a time, then rebuild the
        table in place. With the same bytes per row the keys are rewritten in place;
        otherwise the new rows are written to a new buffer (the old one is freed
        after): no whole copy of the store as words is ever made."""
        new_bytes = _word_bytes(n_words, word_bytes)
        old = self._keys
        read = (lambda a, b: source[a:b]) if source is not None else old.words
        if new_bytes == old.word_bytes:
            target = old
        else:
            target = PackedRows(new_bytes, max(old.capacity, old.size))
        for start in range(0, old.size, FILL_CHUNK):
            stop = min(start + FILL_CHUNK, old.size)
            target.put(start, np.ascontiguousarray(convert(read(start, stop))))
        self._keys = target
        self.n_words = n_words
        self._resize(self._slots)

    def growth_bytes(self, more: int) -> int:
        """Bytes of memory that storing ``more`` new states (at most) would newly touch
        or allocate: their keys, and the table grown to hold them at `MAX_LOAD` (the
        slots beyond the current table within the buffer, a new buffer past it)."""
        total = self._keys.growth_bytes(more)
        slots = self._slots
        while self.size + more > MAX_LOAD * slots:
            slots = self._grown(slots)
        return total + self._table.growth_bytes(slots)

    # -- slots -----------------------------------------------------------------------

    def _home(self, keys: KeyArray) -> IntArray:
        """Home slot of each key: the top 32 bits of its hash scaled to the table."""
        h = _hash(keys)
        h >>= _S32
        h *= np.uint64(self._slots)
        h >>= _S32
        return h.view(np.int64)

    def _wrap(self, slots: IntArray) -> IntArray:
        """``slots`` taken modulo the table size (they are below twice of it), in place."""
        np.subtract(slots, self._slots, out=slots, where=slots >= self._slots)
        return slots

    def _matches(
        self,
        content: npt.NDArray[np.integer],
        which: IntArray,
        parts: KeyParts,
    ) -> BoolArray:
        """Whether the slots with ``content`` hold the key of candidates ``which``
        (``parts`` of the batch; a positive content refers to a stored key, a negative
        one to a candidate)."""
        out = np.zeros(content.size, dtype=bool)
        full = np.flatnonzero(content)
        ref = content.take(full).astype(np.int64)
        if ref.size and int(ref.min()) > 0:  # the usual case: stored states only
            ref -= 1
            out[full] = self._keys.same(ref, parts, which.take(full))
            return out
        old = ref > 0
        if old.any():
            at = full.compress(old)
            ref_old = ref.compress(old) - 1
            out[at] = self._keys.same(ref_old, parts, which.take(at))
        if not old.all():
            at = full.compress(~old)
            ref_new = -1 - ref.compress(~old)
            out[at] = same_parts(parts, ref_new, which.take(at))
        return out

    def _resize(self, slots: int) -> None:
        """A table of ``slots`` slots, rebuilt from the stored keys a chunk at a time
        (bounded temporaries; the old table's pages are reused, not copied)."""
        self._table.clear()
        self._use_table(slots)
        for start in range(0, self.size, FILL_CHUNK):
            part = self._keys.words(start, start + FILL_CHUNK)
            ids = np.arange(start, start + part.shape[0], dtype=np.int64)
            self._place(self._home(part), ids)

    def _use_table(self, slots: int) -> None:
        """Make the table the first ``slots`` slots of its buffers (new ones if they are
        too small or too narrow, see `SlotTable`)."""
        self._table.use(slots)
        self._slots = slots

    def _fill(self, slots: IntArray, ids: IntArray) -> None:
        """Place distinct keys into an empty table at once: in home-slot order, linear
        probing puts the ``i``-th key at ``max(slot_i, position_{i-1} + 1)``, a running
        maximum, computed a chunk at a time (small temporaries); the few keys that run
        past the end wrap around through `_place`."""
        order = np.argsort(slots, kind="stable")
        last, size, chunk = -1, self._slots, FILL_CHUNK
        for start in range(0, order.size, chunk):
            part = order[start : start + chunk]
            steps = np.arange(part.size, dtype=np.int64)
            position = slots.take(part) - steps
            position[0] = max(int(position[0]), last + 1)
            np.maximum.accumulate(position, out=position)
            position += steps
            last = int(position[-1])
            inside = position < size
            rest = part[~inside]
            part, position = part[inside], position[inside]
            self._table.put(position, ids.take(part) + 1)
            if rest.size:  # after the others: they wrap around to the first free slots
                self._place(slots.take(rest), ids.take(rest))

    def _grown(self, slots: int) -> int:
        """The table size after one growth step from ``slots``."""
        return int(slots * GROWTH) + 1

    def _reserve(self, need: int, load: float) -> None:
        """Grow the table until ``need`` keys fill it at most ``load``."""
        slots = self._slots
        while need > load * slots:
            slots = self._grown(slots)
        if slots != self._slots:
            if self._table.growth_bytes(slots) >= TRIM_GROWTH_BYTES:
                release_free_heap()  # (the table's new pages come on top of the heap's)
            self._resize(slots)

    def _place(self, slots: IntArray, ids: IntArray) -> None:
        """Write pairwise distinct keys (by home slot) that are not in the table yet, as
        states ``ids``."""
        table = self._table
        values = ids + 1
        slots = slots.copy()
        while slots.size:
            free = np.flatnonzero(table.take(slots) == EMPTY)
            fs, fv = slots.take(free), values.take(free)
            table.put(fs, fv)
            placed = np.zeros(slots.size, dtype=bool)
            placed[free] = table.take(fs) == fv
            more = np.flatnonzero(~placed)
            slots = slots.take(more)
            slots += 1
            self._wrap(slots)
            values = values.take(more)

    def _insert_distinct(self, keys: KeyArray) -> None:
        """Store pairwise distinct new keys as the next states."""
        need = self.size + keys.shape[0]
        self._reserve(need, MAX_LOAD)
        slots = self._home(keys)
        ids = np.arange(self.size, need, dtype=np.int64)
        if self.size:
            self._place(slots, ids)
        else:
            self._fill(slots, ids)
        self._keys.append(keys)

    # -- queries and inserts ------------------------------------------------------------

    def _probe(
        self,
        slots: IntArray,
        which: IntArray,
        parts: KeyParts,
    ) -> tuple[BoolArray, BoolArray, IntArray]:
        """One probing round from ``slots`` for candidates ``which``: per candidate,
        whether it found its key, whether it found a free slot (never both), and that
        slot (the last one looked at when neither). Small batches look at `_WINDOW`
        consecutive slots at once (fewer rounds, fewer numpy calls); large ones at one
        (less work per candidate)."""
        if slots.size > PROBE_WINDOW_BELOW:
            content = self._table.take(slots)
            return self._matches(content, which, parts), content == EMPTY, slots
        window = slots[:, None] + _WINDOW
        self._wrap(window)
        contents = self._table.take(window)
        wide = np.repeat(which, _WINDOW.size)
        hits = self._matches(contents.reshape(-1), wide, parts).reshape(contents.shape)
        stops = contents == EMPTY
        stops |= hits
        first = stops.argmax(axis=1)
        rows = np.arange(slots.size)
        hit = hits[rows, first]
        free = stops[rows, first] & ~hit
        return hit, free, window[rows, first]

    def _onward(self, at: IntArray, stopped: BoolArray, more: IntArray) -> IntArray:
        """Where the candidates ``more`` probe next: after the slot they stopped at (a
        claim lost to another key), or after the window when they found neither their
        key nor a free slot (``at`` is then its first slot)."""
        onward = at.take(more)
        if stopped.size > PROBE_WINDOW_BELOW:
            onward += 1
        else:
            onward += np.where(stopped.take(more), 1, _WINDOW.size)
        return self._wrap(onward)

    def find(self, cand: KeyArray) -> IntArray:
        """State number of each candidate key, ``-1`` if it is not stored."""
        cand = np.ascontiguousarray(cand)
        parts, fits = self._keys.split(cand)
        slots = self._home(cand)
        out = np.full(cand.shape[0], -1, dtype=np.int64)
        pos = np.arange(cand.shape[0], dtype=np.int64)
        if fits is not None:  # keys no row can hold are not stored
            pos = np.flatnonzero(fits)
            slots = slots.take(pos)
        while pos.size:
            hit, free, at = self._probe(slots, pos, parts)
            where = np.flatnonzero(hit)
            out[pos.take(where)] = self._table.take(at.take(where)).astype(np.int64) - 1
            stopped = hit | free
            more = np.flatnonzero(~stopped)
            slots = self._onward(at, stopped, more)
            pos = pos.take(more)
        return out

    def contains(self, cand: KeyArray) -> BoolArray:
        """Which candidate keys are stored."""
        found: BoolArray = self.find(cand) >= 0
        return found

    def add(
        self,
        cand: KeyArray,
        limit: int | None = None,
        want_ids: bool = False,
        grow: bool = True,
    ) -> Added:
        """Store the candidate keys not seen before; the batch may repeat keys.

        Args:
            cand: candidate keys, shape ``(m, n_words)``.
            limit: store at most this many new states (the budget left).
            want_ids: also return every candidate's state number.
            grow: grow the table after the batch if it is past `MAX_LOAD`; false
                leaves that to `settle`, which the caller calls once the batch's
                other arrays are freed (a growth's temporaries then do not come on
                top of them). Until then the table stays below `BATCH_LOAD`.

        Returns:
            An `Added` record; the new states are numbered ``size_before, ...`` in
            the order of their first occurrence in ``cand``.
        """
        cand = np.ascontiguousarray(cand)
        m, start = cand.shape[0], self.size
        parts, fits = self._keys.split(cand)
        if fits is not None:  # (before the table changes)
            raise ValueError("KeyStore: a key uses more bytes of a word than the store keeps")
        if limit is not None and m > limit:
            return self._add_capped(cand, limit)
        firsts: list[IntArray] = []
        ids: list[IntArray] = []
        done = 0
        while done < m:
            room = int(BATCH_LOAD * self._slots) - self.size
            if room < min(m - done, self._slots >> 3):
                self._resize(self._grown(self._slots))
                continue
            piece = slice(done, done + room)
            first, piece_ids = self._claim(cand[piece], [p[piece] for p in parts], want_ids)
            firsts.append(first + done)
            if piece_ids is not None:
                ids.append(piece_ids)
            done += min(room, m - done)
            if grow or done < m:
                self._reserve(self.size, MAX_LOAD)
        first = np.concatenate(firsts) if firsts else np.zeros(0, dtype=np.int64)
        all_ids = np.concatenate(ids) if want_ids and ids else None
        if want_ids and all_ids is None:
            all_ids = np.zeros(0, dtype=np.int64)
        return Added(first, start, False, all_ids)

    def settle(self) -> None:
        """Grow the table if a batch added with ``grow=False`` left it past
        `MAX_LOAD`."""
        self._reserve(self.size, MAX_LOAD)

    def _claim(
        self, cand: KeyArray, parts: KeyParts, want_ids: bool
    ) -> tuple[IntArray, IntArray | None]:
        """Insert a batch (``parts`` its `PackedRows.split`) that fits in the table
        below `BATCH_LOAD`: the first occurrence of every new key becomes a new state.
        Returns the positions of those first occurrences (ascending) and, if asked,
        every candidate's state number."""
        m = cand.shape[0]
        slots = self._home(cand)
        table = self._table
        final = np.empty(m, dtype=np.int64) if want_ids else None
        pos = np.arange(m, dtype=np.int64)
        claimed: list[IntArray] = []
        while True:
            done, empty, at = self._probe(slots, pos, parts)
            stopped = done | empty
            free = np.flatnonzero(empty)
            if free.size:
                done[free] = self._claim_free(parts, pos.take(free), at.take(free))
                claimed.append(self._reps)
            if final is not None:
                settled = np.flatnonzero(done)
                final[pos.take(settled)] = at.take(settled)
            more = np.flatnonzero(~done)
            if not more.size:
                break
            slots = self._onward(at, stopped, more)
            pos = pos.take(more)
        new_slots = np.concatenate(claimed) if claimed else np.zeros(0, dtype=np.int64)
        reps = -1 - table.take(new_slots).astype(np.int64)
        is_first = np.zeros(m, dtype=bool)
        is_first[reps] = True
        first = np.flatnonzero(is_first)
        slot_of = np.empty(m, dtype=np.int64)
        slot_of[reps] = new_slots
        need = self.size + first.size
        table.put(slot_of.take(first), np.arange(self.size + 1, need + 1, dtype=np.int64))
        self._keys.append(cand.take(first, axis=0))
        if final is None:
            return first, None
        return first, table.take(final).astype(np.int64) - 1

    def _claim_free(self, parts: KeyParts, fp: IntArray, fs: IntArray) -> BoolArray:
        """Candidates ``fp`` (batch positions) found free slots ``fs``: each slot gets
        the first (smallest position) of its claimants as the new key's representative,
        and the claimants with the representative's key are its repeats. Returns which
        candidates are settled (representative or repeat); sets ``self._reps`` to the
        slots that got a representative."""
        rep = self._table.claim(fs, fp)  # (several candidates may claim one slot)
        won: BoolArray = rep == fp
        settled = won.copy()
        lost = np.flatnonzero(~won)  # (few: most claimants win their slot alone)
        if lost.size:
            settled[lost] = same_parts(parts, fp.take(lost), rep.take(lost))
        self._reps = fs.compress(won)
        return settled

    def _add_capped(self, cand: KeyArray, limit: int) -> Added:
        """`add` when the budget may turn new keys away: look up first, keep the first
        ``limit`` new keys by first occurrence, place only those."""
        start = self.size
        ids = self.find(cand)
        unknown = np.flatnonzero(ids < 0)
        first_u, leader_u = first_occurrences(cand.take(unknown, axis=0))
        cut = first_u.size > limit
        kept = first_u[:limit]
        self._insert_distinct(cand.take(unknown.take(kept), axis=0))
        rank = np.searchsorted(first_u, leader_u)
        ids[unknown] = np.where(rank < limit, start + rank, -1)
        return Added(unknown.take(kept), start, cut, ids)
