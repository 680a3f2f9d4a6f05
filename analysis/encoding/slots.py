"""The slots of the key store's hash table (`SlotTable`): three bytes each while the
table is small enough, whole words beyond.

Part of `analysis.encoding`; see its docstring for how the pieces fit.

A slot holds 0 (free), a state number plus one, or, while a batch is placed, minus one
minus a candidate's position: a signed value smaller in magnitude than the number of
slots. Below `THREE_BYTE_SLOTS` slots (up to about five million states at the store's
load) that fits in 24 bits, kept as two aligned planes (the low 16 bits unsigned, the
high 8 signed): a quarter less than an ``int32`` slot, about 2 of the 7-10 bytes a
stored state pays for the table. A gather costs two ``take`` calls instead of one
(2.5 ns instead of 1.2 per slot on the reference machine), small against the key
comparison each probe makes anyway. Past the limit the table is rebuilt in ``int32``
words (``int64`` with ``wide``); the store rebuilds its table whenever it grows, so the
change of width costs nothing of its own.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt

from analysis.encoding.compact import IntArray
from analysis.encoding.reserved import reserved

THREE_BYTE_SLOTS = 1 << 23
"""Tables of at most this many slots keep them in three bytes (every value is smaller
in magnitude than the slot count, so it fits a signed 24-bit number)."""

SlotArray = npt.NDArray[np.signedinteger[Any]]


class SlotTable:
    """``slots`` signed slots, zero when free, over memory reserved for ``reserve``
    slots (address space until touched, see `analysis.encoding.reserved`)."""

    def __init__(self, reserve: int, wide: bool = False) -> None:
        self._reserve = max(16, reserve)
        # whole-word slots past the three-byte limit, and what `take` returns either way
        self._whole_type: type[np.signedinteger[Any]] = np.int64 if wide else np.int32
        self._lo: npt.NDArray[np.uint16] | None = None
        self._hi: npt.NDArray[np.int8] | None = None
        self._whole: SlotArray | None = None
        self.slots = 0
        self._allocate(min(self._reserve, THREE_BYTE_SLOTS))

    def _allocate(self, slots: int) -> None:
        """Fresh zeroed buffers for at least ``slots`` slots: planes while three bytes
        do, a whole-word buffer (for the reservation, or ``slots`` past it) beyond."""
        self._lo = self._hi = self._whole = None  # freed before the next is allocated
        if slots <= THREE_BYTE_SLOTS:
            self._lo = reserved((slots,), np.uint16)
            self._hi = reserved((slots,), np.int8)
        else:
            self._whole = reserved((max(slots, self._reserve),), self._whole_type)

    @property
    def capacity(self) -> int:
        """Slots the current buffers hold."""
        if self._whole is not None:
            return int(self._whole.size)
        assert self._lo is not None and self._hi is not None
        return int(min(self._lo.size, self._hi.size))

    @property
    def slot_bytes(self) -> int:
        """Bytes of one slot (3, 4 or 8)."""
        return 3 if self._whole is None else int(self._whole.itemsize)

    @property
    def nbytes(self) -> int:
        """Bytes of the slots in use."""
        return self.slots * self.slot_bytes

    def growth_bytes(self, slots: int) -> int:
        """Bytes that using ``slots`` slots would newly touch or allocate."""
        if slots <= self.slots:
            return 0
        if self._fits(slots):
            return (slots - self.slots) * self.slot_bytes
        item = 3 if slots <= THREE_BYTE_SLOTS else np.dtype(self._whole_type).itemsize
        return slots * item

    def _fits(self, slots: int) -> bool:
        """Whether ``slots`` slots fit the current buffers at their width."""
        if slots > self.capacity:
            return False
        return self._whole is not None or slots <= THREE_BYTE_SLOTS

    def use(self, slots: int) -> None:
        """Make the table the first ``slots`` slots (new buffers, all free, when they do
        not fit the current ones; the caller then refills them). Slots beyond the old
        table are free: the caller clears the old ones first (`clear`)."""
        if not self._fits(slots):
            self._allocate(slots)
        self.slots = slots

    def clear(self) -> None:
        """Free every slot in use (their pages are touched already; the rest of a
        buffer is still zero)."""
        if self._whole is not None:
            self._whole[: self.slots] = 0
            return
        assert self._lo is not None and self._hi is not None
        self._lo[: self.slots] = 0
        self._hi[: self.slots] = 0

    def take(self, at: IntArray) -> SlotArray:
        """The values of slots ``at`` (any shape), as ``int32`` (``int64`` if wide)."""
        if self._whole is not None:
            whole: SlotArray = self._whole.take(at)
            return whole
        assert self._lo is not None and self._hi is not None
        out: SlotArray = self._hi.take(at).astype(self._whole_type)
        out <<= 16
        out |= self._lo.take(at)
        return out

    def put(self, at: IntArray, values: npt.NDArray[np.integer[Any]]) -> None:
        """Write ``values`` into slots ``at``. Where ``at`` repeats a slot, which value
        it keeps is numpy's choice (see `KeyStore._claim_free`, which checks)."""
        if self._whole is not None:
            self._whole[at] = values
            return
        assert self._lo is not None and self._hi is not None
        self._lo[at] = values.astype(np.uint16)  # (wraps: the low 16 bits)
        self._hi[at] = (values >> 16).astype(np.int8)

    def claim(self, at: IntArray, positions: IntArray) -> IntArray:
        """Let candidates at batch ``positions`` (distinct, non-negative) claim the free
        slots ``at``: each slot gets ``-1 - p`` for the least position ``p`` among its
        claimants. Returns, per claimant, the position that won its slot.

        Written in reverse so that the least position normally writes last and wins;
        numpy does not promise an order for repeated indices, so the result is checked,
        never assumed (in planes, also that both planes kept the same claimant's
        bytes), and redone by sorting where the check fails."""
        refs = -1 - positions
        self.put(at[::-1], refs[::-1])
        won = -1 - self.take(at).astype(np.int64)
        fine = not (won > positions).any()
        if fine and self._whole is None and at.size:
            # each winner must be a claimant of the very slot it won
            bound = int(positions.max()) + 1
            owner = np.full(bound, -1, dtype=np.int32)  # (slots are below 2^23 here)
            owner[positions] = at
            inside = (won >= 0) & (won < bound)
            fine = bool(inside.all()) and bool((owner.take(won) == at).all())
        if fine:
            return won
        order = np.lexsort((positions, at))
        ordered = at.take(order)
        first = np.ones(ordered.size, dtype=bool)
        np.not_equal(ordered[1:], ordered[:-1], out=first[1:])
        self.put(ordered.compress(first), refs.take(order).compress(first))
        return -1 - self.take(at).astype(np.int64)
