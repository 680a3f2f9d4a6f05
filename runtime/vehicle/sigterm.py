"""SIGTERM taken as Ctrl-C, for the command-line programs of both ends.

``kill``, systemd and container runtimes stop a program with SIGTERM, whose default
action ends the process at once: no ``finally`` block runs, so a log is left
uncommitted and nothing says why the program stopped. Under `sigterm_raises` SIGTERM
ends the block with `Terminated`, a `KeyboardInterrupt` subclass, so it goes through the
same clean path as Ctrl-C, and the program can still tell the two apart for its message
and exit code. It lives on the vehicle side so that ``coral-vehicle``, ``romeo-sim`` and
``coral-run`` share it (``docs/architecture.md``).

How, and why not simply raise from the signal handler: an exception raised by a handler
lands between any two bytecodes, for instance between an event log's ``COMMIT`` and its
note of what it committed, and the log's close then writes the same rows again (``UNIQUE
constraint failed``). So while an asyncio loop runs (``asyncio.run``, where servers and
runs spend their time) the handler only asks the loop to cancel its tasks, as
``asyncio.run`` does for Ctrl-C: every task ends at an ``await``, its ``finally`` blocks
run whole, and `Terminated` is raised when the block is left. With no loop running the
handler raises at once, as Ctrl-C does. A second SIGTERM while the first is being
handled raises at once: the operator insists.
"""

from __future__ import annotations

import asyncio
import contextlib
import signal
import threading
from collections.abc import Iterator
from types import FrameType

__all__ = ["Terminated", "sigterm_raises"]


class Terminated(KeyboardInterrupt):
    """SIGTERM arrived while `sigterm_raises` was in force."""


class _Handler:
    """The SIGTERM handler of one `sigterm_raises` block; ``received`` once it fired."""

    def __init__(self) -> None:
        self.received = False

    def __call__(self, signum: int, frame: FrameType | None) -> None:
        try:
            loop: asyncio.AbstractEventLoop | None = asyncio.get_running_loop()
        except RuntimeError:
            loop = None
        if loop is None or self.received or loop.is_closed():
            self.received = True
            raise Terminated
        self.received = True
        loop.call_soon_threadsafe(_cancel_tasks, loop)


def _cancel_tasks(loop: asyncio.AbstractEventLoop) -> None:
    """Cancel every task of ``loop``: each ends at its next ``await``."""
    for task in asyncio.all_tasks(loop):
        task.cancel()


@contextlib.contextmanager
def sigterm_raises() -> Iterator[None]:
    """SIGTERM ends the block with `Terminated`; the handler before is put back after.

    Inside a running asyncio loop the loop's tasks are cancelled first (see the module's
    docstring); the ``CancelledError`` that ends ``asyncio.run`` then becomes
    `Terminated`, and so does a block that ends normally after the signal. Only the main
    thread can set signal handlers; elsewhere this does nothing.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    handler = _Handler()
    previous = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    except asyncio.CancelledError:
        if handler.received:
            raise Terminated from None
        raise
    finally:
        signal.signal(signal.SIGTERM, previous)
    if handler.received:
        raise Terminated
