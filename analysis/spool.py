"""A first-in first-out queue of rows of ``uint64`` words (`RowSpool`), for data written
once and read once, in order, a whole search layer later: the explorer's sleep sets.

Two things keep it small. Its memory is anonymous maps of its own (`SEGMENT_BYTES`),
each unmapped as soon as its last value is read: the explorer used to keep the next
layer's sleep sets as many heap blocks of mixed sizes, interleaved with the step
temporaries, which fragmented glibc's heap so that its high-water mark stayed resident
to the end of the search. And rows of several words keep only their nonzero words,
behind a byte that says which: a sleep set is a subset of the few transitions enabled
in its marking, so most of its words are zero on nets of hundreds of transitions
(Peterson-PT-3: 2.2 nonzero of 6 words; SharedMemory-PT-000010: 2.8 of 4).
"""

from __future__ import annotations

import mmap
from collections import deque

import numpy as np
import numpy.typing as npt

SEGMENT_BYTES = 1 << 18
"""Bytes of one memory map: small enough that what is read goes back to the kernel
soon, large enough that mapping costs nothing measurable."""

SPARSE_MAX_WORDS = 8
"""Widest rows kept sparse (the byte that marks a row's nonzero words has 8 bits)."""

SPARSE_SHARE = 0.75
"""Rows are kept sparse when fewer than this share of the words of the first rows
appended are nonzero: below, the mark byte and the masked copies (about a tenth of
a search's time on Peterson-PT-3) buy memory; above, they would buy little (Dekker-PT-015
fills 3.85 of 4 words)."""


class _Stream:
    """Values of one dtype, appended at the back and taken at the front, in maps of
    `SEGMENT_BYTES`."""

    def __init__(self, dtype: npt.DTypeLike) -> None:
        self.dtype = np.dtype(dtype)
        self._segment_items = max(1, SEGMENT_BYTES // self.dtype.itemsize)
        self._segments: deque[npt.NDArray[np.generic]] = deque()
        self._read = 0  # items of the front segment already taken
        self._written = 0  # items of the back segment already written
        self.size = 0  # items appended and not yet taken

    def _new_segment(self) -> npt.NDArray[np.generic]:
        items = self._segment_items
        flat = np.frombuffer(mmap.mmap(-1, items * self.dtype.itemsize), dtype=self.dtype)
        return flat

    def append(self, values: npt.NDArray[np.generic]) -> None:
        start, n = 0, values.size
        while start < n:
            if not self._segments or self._written == self._segment_items:
                self._segments.append(self._new_segment())
                self._written = 0
            k = min(n - start, self._segment_items - self._written)
            self._segments[-1][self._written : self._written + k] = values[start : start + k]
            self._written += k
            start += k
        self.size += n

    def take(self, n: int) -> npt.NDArray[np.generic]:
        out = np.empty(n, dtype=self.dtype)
        done = 0
        while done < n:
            front = self._segments[0]
            filled = self._written if len(self._segments) == 1 else self._segment_items
            k = min(n - done, filled - self._read)
            out[done : done + k] = front[self._read : self._read + k]
            self._read += k
            done += k
            if self._read == self._segment_items:
                self._segments.popleft()  # the last reference: the map is unmapped
                self._read = 0
        self.size -= n
        return out

    @property
    def mapped_bytes(self) -> int:
        return len(self._segments) * self._segment_items * self.dtype.itemsize


class RowSpool:
    """Rows of ``width`` ``uint64`` words, appended at the back and taken at the front
    (`take` returns new arrays: nothing read keeps a map alive). ``sparse`` says whether
    only nonzero words are kept: False never, True always (rows of 2 to 8 words), None
    until the first rows, which decide it (`SPARSE_SHARE`)."""

    def __init__(self, width: int, sparse: bool | None = None) -> None:
        if width < 1:
            raise ValueError(f"rows need at least one word, not {width}")
        self.width = width
        self.sparse: bool | None = sparse if 2 <= width <= SPARSE_MAX_WORDS else False
        self._words = _Stream(np.uint64)
        self._marks = _Stream(np.uint8)  # sparse rows: bit k set when word k is nonzero
        self.size = 0  # rows appended and not yet taken

    def append(self, rows: npt.NDArray[np.uint64]) -> None:
        """Add ``rows`` (shape ``(n, width)``) at the back; they are copied."""
        if rows.ndim != 2 or rows.shape[1] != self.width:
            raise ValueError(f"rows of width {self.width} expected, got shape {rows.shape}")
        if self.sparse is None and rows.size:  # decided by the first rows
            self.sparse = bool(np.count_nonzero(rows) < SPARSE_SHARE * rows.size)
        if self.sparse:
            nonzero = rows != 0
            self._marks.append(np.packbits(nonzero, axis=1, bitorder="little").reshape(-1))
            self._words.append(rows[nonzero])
        else:
            self._words.append(rows.reshape(-1))
        self.size += rows.shape[0]

    def take(self, n: int) -> npt.NDArray[np.uint64]:
        """The next ``n`` rows, shape ``(n, width)``."""
        if not 0 <= n <= self.size:
            raise ValueError(f"cannot take {n} rows of {self.size}")
        self.size -= n
        if not self.sparse:
            return self._words.take(n * self.width).reshape(n, self.width)  # type: ignore[return-value]
        marks = self._marks.take(n).astype(np.uint8, copy=False)
        nonzero = np.unpackbits(marks[:, None], axis=1, count=self.width, bitorder="little")
        where = nonzero.view(bool)
        out = np.zeros((n, self.width), dtype=np.uint64)
        out[where] = self._words.take(int(np.count_nonzero(where)))
        return out

    @property
    def nbytes(self) -> int:
        """Bytes of the values held (written and not yet taken)."""
        return self._words.size * 8 + self._marks.size

    @property
    def mapped_bytes(self) -> int:
        """Bytes of the maps held: whole segments, their pages resident once written."""
        return self._words.mapped_bytes + self._marks.mapped_bytes
