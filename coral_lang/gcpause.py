"""Pausing Python's cyclic garbage collector around work that builds big acyclic data."""

from __future__ import annotations

import contextlib
import gc
from collections.abc import Iterator


@contextlib.contextmanager
def cyclic_gc_paused() -> Iterator[None]:
    """Pause the cyclic garbage collector for the duration of the block.

    A large mission is hundreds of thousands of tokens and tree nodes; each collection
    walks all of them, which was 40% of compile time. They form no reference cycles, so
    reference counting frees them as usual and pausing loses nothing. Nested use is
    fine: the collector is re-enabled only if it was enabled on entry.
    """
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was_enabled:
            gc.enable()
