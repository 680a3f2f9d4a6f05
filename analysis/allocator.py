"""The C allocator, seen from a search that must stay within a memory budget: how
much the heap holds free (`heap_free_bytes`), and two nudges to glibc's defaults
(`settle_allocator`, `release_free_heap`). Elsewhere than glibc these do nothing.

Why a search cares: its steps allocate and free tens of MB of temporaries each, next
to a store that only grows. glibc serves them from its heap and keeps what is freed,
which is what makes repeated steps cheap, but it means the resident memory of a
process is its store plus the high-water mark of its heap, not plus what is in use.
"""

from __future__ import annotations

import ctypes
from collections.abc import Callable
from typing import cast

import numpy as np


class _MallInfo2(ctypes.Structure):
    """glibc's ``struct mallinfo2`` (all fields ``size_t``)."""

    _fields_ = [
        (name, ctypes.c_size_t)
        for name in [
            "arena",
            "ordblks",
            "smblks",
            "hblks",
            "hblkhd",
            "usmblks",
            "fsmblks",
            "uordblks",
            "fordblks",
            "keepcost",
        ]
    ]


def _mallinfo2() -> Callable[[], _MallInfo2] | None:
    """glibc's ``mallinfo2`` (2.33 and later), or None elsewhere."""
    try:
        function = ctypes.CDLL(None).mallinfo2
    except (AttributeError, OSError):
        return None
    function.restype = _MallInfo2
    function.argtypes = []
    return cast(Callable[[], _MallInfo2], function)


_MALLINFO2 = _mallinfo2()


def heap_free_bytes() -> int:
    """Bytes the C allocator holds free (glibc: ``mallinfo2().fordblks``; 0 elsewhere).

    glibc keeps freed blocks (see `settle_allocator`), so after the first large step
    much of the resident memory is free heap that the next step's temporaries reuse
    without growing the process: a memory check counts an allocation only beyond it,
    or it would stop a search long before its limit (by a factor of 5 on 2^21
    toggles with 40 MiB to spare)."""
    if _MALLINFO2 is None:
        return 0
    return int(_MALLINFO2().fordblks)


def _malloc_trim() -> Callable[[int], int] | None:
    """glibc's ``malloc_trim``, or None elsewhere."""
    try:
        function = ctypes.CDLL(None).malloc_trim
    except (AttributeError, OSError):
        return None
    function.restype = ctypes.c_int
    function.argtypes = [ctypes.c_size_t]
    return cast(Callable[[int], int], function)


_MALLOC_TRIM = _malloc_trim()


def release_free_heap() -> None:
    """Give the C heap's free pages back to the kernel (glibc: ``malloc_trim(0)``).

    After `settle_allocator` glibc's trim threshold is twice its raised mmap threshold
    (60 MB), so it never shrinks the heap by itself: the largest step's temporaries
    would stay resident to the end of the search, on top of the store that keeps
    growing. The key store calls it before its table grows (its largest allocation,
    near the search's peak): the price, a page fault per page the next steps touch
    again, is small against the work between growths. Calling it after every layer of
    65,536 states or more cost Peterson-PT-3 a tenth of its search (130 layers) once
    steps were bounded in bytes, for 0.2 resident bytes per state."""
    if _MALLOC_TRIM is not None:
        _MALLOC_TRIM(0)


def settle_allocator() -> None:
    """Allocate and free one 30 MB block, once per exploration.

    glibc serves blocks above its *mmap threshold* (128 KB at start) with fresh pages
    from the kernel and returns them on free; it raises the threshold (up to 32 MB) only
    after such a block is freed. Until then every temporary of a vectorised step costs
    page faults on every use, which on the reference machine is the price of writing
    the memory many times over. Freeing one large block moves glibc to the steady state
    it reaches by itself later (elsewhere this is just an allocation)."""
    np.empty(30 << 20, dtype=np.uint8)
