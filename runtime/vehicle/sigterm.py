"""SIGTERM taken as Ctrl-C, for the command-line programs of both ends.

``kill``, systemd and container runtimes stop a program with SIGTERM, whose default
action ends the process at once: no ``finally`` block runs, so a log is left
uncommitted and nothing says why the program stopped. Raised as `Terminated`, a
`KeyboardInterrupt` subclass, SIGTERM goes through the same clean path as Ctrl-C
(``asyncio.run`` lets it through at once as it does Ctrl-C), and the program can still
tell the two apart for its message and exit code. It lives on the vehicle side so that
``coral-vehicle``, ``romeo-sim`` and ``coral-run`` share it (``docs/architecture.md``).
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator
from types import FrameType

__all__ = ["Terminated", "sigterm_raises"]


class Terminated(KeyboardInterrupt):
    """SIGTERM arrived while `sigterm_raises` was in force."""


def _raise_terminated(signum: int, frame: FrameType | None) -> None:
    raise Terminated


@contextlib.contextmanager
def sigterm_raises() -> Iterator[None]:
    """SIGTERM raises `Terminated` inside the block; the handler before is put back after.

    Only the main thread can set signal handlers; elsewhere this does nothing.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGTERM, _raise_terminated)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)
