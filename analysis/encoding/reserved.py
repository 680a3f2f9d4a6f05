"""Zeroed memory reserved up front for arrays that grow (`reserved`): address space
only until rows are written.

Part of `analysis.encoding`; see its docstring for how the pieces fit."""

from __future__ import annotations

import mmap
from typing import Any

import numpy as np
import numpy.typing as npt

RESERVE_BYTES = 1 << 30
"""Most bytes of address space one reserved array takes (wide keys reserve fewer
rows), so a reservation never approaches what the kernel would refuse."""


MAPPED_BYTES = 1 << 20
"""Reservations from this size on are anonymous memory maps of their own."""


def reserved(shape: tuple[int, ...], dtype: npt.DTypeLike) -> npt.NDArray[Any]:
    """Zeroed memory for up to ``shape[0]`` rows, fewer past `RESERVE_BYTES` or when the
    address space is refused (callers grow past it anyway)."""
    row = max(1, int(np.prod(shape[1:], dtype=np.int64)) * np.dtype(dtype).itemsize)
    rows = max(1, min(shape[0], RESERVE_BYTES // row))
    if rows * row >= MAPPED_BYTES:
        try:
            # Pages of its own, returned to the kernel when the array is freed: a block
            # from the C heap (glibc serves blocks below its mmap threshold, up to 32 MB,
            # from there) would be zeroed by writing it when it reuses freed memory,
            # making the whole reservation resident at once.
            mapped = mmap.mmap(-1, rows * row)
            flat = np.frombuffer(mapped, dtype=np.uint8)
            return flat.view(dtype).reshape((rows, *shape[1:]))
        except (OSError, ValueError, MemoryError):
            pass
    try:
        return np.zeros((rows, *shape[1:]), dtype=dtype)
    except MemoryError:
        return np.zeros((min(rows, 1 << 12), *shape[1:]), dtype=dtype)
