"""SIGTERM under `sigterm_raises`: `Terminated` out of the block, never in the middle of
synchronous code while an asyncio loop runs (an event log's commit), handler restored.

The signal is sent to this process with ``os.kill`` from the code under test, so where it
lands is known: Python runs the handler at once, in the main thread.
"""

from __future__ import annotations

import asyncio
import os
import signal
import threading

import pytest

from runtime.vehicle.sigterm import Terminated, sigterm_raises

pytestmark = [
    pytest.mark.skipif(os.name != "posix", reason="POSIX signals"),
    pytest.mark.skipif(
        threading.current_thread() is not threading.main_thread(),
        reason="signal handlers are set in the main thread only",
    ),
]


def _terminate() -> None:
    os.kill(os.getpid(), signal.SIGTERM)


def test_without_a_loop_sigterm_raises_at_once() -> None:
    done: list[str] = []
    before = signal.getsignal(signal.SIGTERM)
    with pytest.raises(Terminated), sigterm_raises():
        _terminate()
        done.append("after the signal")
    assert done == []
    assert signal.getsignal(signal.SIGTERM) is before  # put back


def test_in_a_loop_synchronous_code_runs_whole_then_the_tasks_are_cancelled() -> None:
    """The signal lands inside a 'commit' (synchronous code in a task): the commit
    finishes, the task's ``finally`` runs at its next await, and the block ends with
    `Terminated`: what the old handler, raising in place, broke."""
    steps: list[str] = []

    async def serve() -> None:
        try:
            steps.append("commit begins")
            _terminate()  # mid-commit
            steps.append("commit ends")
            await asyncio.sleep(30)
            steps.append("slept")  # never: cancelled
        finally:
            steps.append("cleanup")
            await asyncio.sleep(0)  # a finally may still await
            steps.append("cleanup done")

    with pytest.raises(Terminated), sigterm_raises():
        asyncio.run(serve())
    assert steps == ["commit begins", "commit ends", "cleanup", "cleanup done"]


def test_a_block_that_ends_normally_after_the_signal_still_raises() -> None:
    async def swallow() -> str:
        try:
            _terminate()
            await asyncio.sleep(30)
        except asyncio.CancelledError:
            return "swallowed"
        return "slept"

    results: list[str] = []
    with pytest.raises(Terminated), sigterm_raises():
        results.append(asyncio.run(swallow()))
    assert results == ["swallowed"]


def test_a_second_sigterm_raises_at_once() -> None:
    steps: list[str] = []

    async def insist() -> None:
        _terminate()
        steps.append("first handled")
        _terminate()
        steps.append("never")

    with pytest.raises(Terminated), sigterm_raises():
        asyncio.run(insist())
    assert steps == ["first handled"]


def test_a_cancellation_without_the_signal_is_left_alone() -> None:
    async def cancelled() -> None:
        task = asyncio.current_task()
        assert task is not None
        task.cancel()
        await asyncio.sleep(1)

    with pytest.raises(asyncio.CancelledError), sigterm_raises():
        asyncio.run(cancelled())
