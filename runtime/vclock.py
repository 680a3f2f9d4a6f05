"""Virtual time for asyncio: the same code, run deterministically and instantly.

The controller, the vehicle server and the in-memory link are ordinary asyncio code that
reads the time from ``loop.time()`` and waits with ``asyncio.sleep``, ``wait_for``,
``call_later``. Under `VirtualTimeLoop` those waits take no real time: whenever no
callback is ready, the loop moves its clock straight to the next timer instead of
sleeping. A 40-minute mission over an emulated Internet link then runs in seconds of
CPU, and two runs with the same seeds produce the same events at the same times.

Rules of the virtual world:

* Time moves only when every task is waiting. Computation takes no virtual time.
* Work handed to threads (``run_in_executor``, ``asyncio.to_thread``, ``getaddrinfo``)
  takes no virtual time either: while such a job runs and nothing else is ready, the loop
  waits for it in real time with its clock stopped.
* Real sockets are polled (without waiting) on every iteration, but nothing ties them to
  the virtual clock; use in-memory transports (`runtime.memorylink`) instead.
* If every task waits for something that can never happen (no timer, no ready callback,
  no thread job), the loop raises `VirtualDeadlock` rather than hang.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import selectors
from collections.abc import Callable, Coroutine, Mapping
from concurrent.futures import Executor
from typing import TYPE_CHECKING, Any, TypeVar, TypeVarTuple

if TYPE_CHECKING:
    from _typeshed import FileDescriptorLike

__all__ = ["VirtualDeadlock", "VirtualTimeLoop", "run_virtual"]

T = TypeVar("T")
Ts = TypeVarTuple("Ts")


class VirtualDeadlock(RuntimeError):
    """Every task waits, and nothing scheduled could ever wake one: the run cannot go on.

    Usually a coroutine awaits a future or an event that nobody will set (a read on a
    connection whose other end is gone without closing, a queue nobody fills). Under a
    real clock the program would hang; under virtual time it fails at once.
    """


class _VirtualSelector(selectors.BaseSelector):
    """A selector that polls the real one, then advances the virtual clock instead of waiting.

    The event loop asks it to wait ``timeout`` seconds (until the next timer) or forever
    (``None``, no timer). It never waits in real time, except for thread jobs in flight.
    """

    def __init__(self, start: float) -> None:
        self._real = selectors.DefaultSelector()
        self.now = float(start)
        self.thread_jobs = 0
        self.wake_fds: frozenset[int] = frozenset()
        """Descriptors that only wake a waiting loop (the loop's self-pipe): while no
        other is registered and no signal handler is set, `select` need not poll."""
        self.signal_handlers = False
        self.poll = True
        """Whether `select` polls the real selector (a system call) before moving time."""

    def register(
        self, fileobj: FileDescriptorLike, events: int, data: Any = None
    ) -> selectors.SelectorKey:
        key = self._real.register(fileobj, events, data)
        self.update_poll()
        return key

    def unregister(self, fileobj: FileDescriptorLike) -> selectors.SelectorKey:
        key = self._real.unregister(fileobj)
        self.update_poll()
        return key

    def update_poll(self) -> None:
        """Poll unless only wake-up descriptors are registered and no signal handler is set.

        The self-pipe matters to a loop that waits for it; this one never waits (but for
        thread jobs, when it does poll). Callbacks from other threads are queued directly
        and run at the next iteration whatever the pipe says; a signal handler is only run
        by reading the pipe, and a socket only by polling, so either keeps the polls on.
        """
        self.poll = self.signal_handlers or any(
            key.fd not in self.wake_fds for key in self._real.get_map().values()
        )

    def modify(
        self, fileobj: FileDescriptorLike, events: int, data: Any = None
    ) -> selectors.SelectorKey:
        return self._real.modify(fileobj, events, data)

    def get_map(self) -> Mapping[FileDescriptorLike, selectors.SelectorKey]:
        return self._real.get_map()

    def close(self) -> None:
        self._real.close()

    def select(self, timeout: float | None = None) -> list[tuple[selectors.SelectorKey, int]]:
        if self.poll or self.thread_jobs:
            events = self._real.select(0)
            if events:
                return events
        if timeout == 0:
            return []
        if self.thread_jobs:
            # A thread job will wake the loop (call_soon_threadsafe); its work is free.
            return self._real.select(None)
        if timeout is None:
            raise VirtualDeadlock(
                f"at virtual time {self.now:.6f} s every task is waiting and nothing is "
                "scheduled (no timer, no ready callback, no thread job): the run can never "
                "go on; look for a future, event or read that nobody will complete"
            )
        self.now += timeout
        return []


class VirtualTimeLoop(asyncio.SelectorEventLoop):
    """An asyncio event loop whose clock is virtual and jumps to the next timer.

    ``time()`` starts at ``start`` and only moves forward when every task is waiting, by
    exactly the time to the next scheduled callback. Everything else is the standard
    selector event loop, so code written for asyncio runs unchanged. Prefer `run_virtual`,
    which also cleans up the way ``asyncio.run`` does.

    Args:
        start: the clock's reading when the loop is created (seconds).
    """

    def __init__(self, start: float = 0.0) -> None:
        self._virtual = _VirtualSelector(start)
        super().__init__(self._virtual)
        wake = getattr(self, "_ssock", None)
        if wake is not None:
            self._virtual.wake_fds = frozenset({wake.fileno()})
            self._virtual.update_poll()

    def add_signal_handler(self, sig: int, callback: Callable[[*Ts], object], *args: *Ts) -> None:
        """As for any loop; while a handler is set, real descriptors are polled each turn."""
        super().add_signal_handler(sig, callback, *args)
        self._note_signal_handlers()

    def remove_signal_handler(self, sig: int) -> bool:
        """As for any loop."""
        removed = super().remove_signal_handler(sig)
        self._note_signal_handlers()
        return removed

    def _note_signal_handlers(self) -> None:
        self._virtual.signal_handlers = bool(getattr(self, "_signal_handlers", True))
        self._virtual.update_poll()

    def time(self) -> float:
        """The virtual clock, in seconds."""
        return self._virtual.now

    # The loop runs every timer due before ``time() + _clock_resolution``. asyncio sets
    # that to the monotonic clock's resolution (1 ns), which is below half a float step
    # once the clock reads more than about 1.7e7 s: a timer due exactly now would then
    # never run. Two float steps at the current reading keep "due now" due at any reading.
    @property
    def _clock_resolution(self) -> float:
        return max(1e-9, 2.0 * math.ulp(self._virtual.now))

    @_clock_resolution.setter
    def _clock_resolution(self, _: float) -> None:
        pass  # asyncio's own value does not suit a clock that may read 1.7e9

    def quiet_until(self) -> float | None:
        """How long nothing but the caller can run: the time of the earliest timer.

        None when something else may run sooner: a callback is ready (it runs at the
        present time, before any timer) or a thread job is in flight. ``math.inf`` when
        no timer is scheduled. Called from a callback (e.g. a task's step), this tells
        the caller that until that time no other code of the program will run and the
        clock will not move except to reach a timer the caller sets, so work the caller
        would have done at its own timers before then can be done at once, with the
        times it would have had (`runtime.vehicle.server.VehicleServer` steps a vehicle
        ahead so). Cancelled timers are not counted: they never run.
        """
        if self._virtual.thread_jobs or getattr(self, "_ready", None):
            return None
        scheduled: list[asyncio.TimerHandle] = getattr(self, "_scheduled", [])
        if not scheduled:
            return math.inf
        first = scheduled[0]  # a heap: the earliest of all, cancelled or not
        if not first.cancelled():
            return first.when()
        return min((h.when() for h in scheduled if not h.cancelled()), default=math.inf)

    def run_in_executor(
        self, executor: Executor | None, func: Callable[[*Ts], T], *args: *Ts
    ) -> asyncio.Future[T]:
        """As for any loop; the job takes no virtual time (the clock waits for it)."""
        future = super().run_in_executor(executor, func, *args)
        self._virtual.thread_jobs += 1
        future.add_done_callback(self._thread_job_done)
        return future

    def _thread_job_done(self, _: asyncio.Future[Any]) -> None:
        self._virtual.thread_jobs -= 1


def run_virtual(
    main: Coroutine[Any, Any, T], *, start: float = 0.0, timeout: float | None = None
) -> T:
    """Run ``main`` to completion on a fresh `VirtualTimeLoop`; return its result.

    Like ``asyncio.run``: the loop is the current event loop while ``main`` runs; tasks
    still pending at the end are cancelled, async generators closed and the default
    executor shut down; then the loop is closed.

    Args:
        main: the coroutine to run.
        start: the virtual clock's reading at the start (seconds).
        timeout: give up after this many *virtual* seconds; None: no limit.

    Raises:
        TimeoutError: ``main`` was still running ``timeout`` virtual seconds after the start.
        VirtualDeadlock: every task waited for something that could never happen.
        RuntimeError: called while an event loop is running in this thread.
        ValueError: a start that is not finite, a negative timeout.
    """
    try:
        asyncio.get_running_loop()
    except RuntimeError:
        pass  # no loop running: good
    else:
        main.close()
        raise RuntimeError("run_virtual() cannot be called from a running event loop")
    if not math.isfinite(start) or (timeout is not None and not timeout >= 0.0):
        main.close()
        raise ValueError(
            f"start must be finite and timeout a number >= 0, got {start!r} and {timeout!r}"
        )
    loop = VirtualTimeLoop(start)
    try:
        asyncio.set_event_loop(loop)
        if timeout is None:
            return loop.run_until_complete(main)
        return loop.run_until_complete(_bounded(main, timeout))
    finally:
        try:
            _cancel_pending(loop)
            loop.run_until_complete(loop.shutdown_asyncgens())
            executor = getattr(loop, "_default_executor", None)
            if executor is not None:
                executor.shutdown(wait=True)
        finally:
            asyncio.set_event_loop(None)
            loop.close()


async def _bounded(main: Coroutine[Any, Any, T], timeout: float) -> T:
    loop = asyncio.get_running_loop()
    start = loop.time()
    scope = asyncio.timeout(timeout)
    try:
        async with scope:
            return await main
    except TimeoutError:
        if not scope.expired():
            raise  # main's own time-out, not ours
        raise TimeoutError(
            f"still running after {timeout} virtual seconds (from t={start} to t={loop.time()})"
        ) from None


def _cancel_pending(loop: asyncio.AbstractEventLoop) -> None:
    """Cancel what is left and let it finish, as ``asyncio.run`` does."""
    pending = [task for task in asyncio.all_tasks(loop) if not task.done()]
    if not pending:
        return
    for task in pending:
        task.cancel()
    with contextlib.suppress(VirtualDeadlock):
        loop.run_until_complete(asyncio.gather(*pending, return_exceptions=True))
    for task in pending:
        if task.done() and not task.cancelled() and task.exception() is not None:
            loop.call_exception_handler(
                {
                    "message": "unhandled exception during run_virtual() shutdown",
                    "exception": task.exception(),
                    "task": task,
                }
            )
