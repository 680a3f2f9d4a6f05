"""runtime.vclock: asyncio code under a virtual clock, instantly and deterministically."""

from __future__ import annotations

import asyncio
import math
import os
import random
import signal
import socket
import threading
import time

import pytest
from hypothesis import given
from hypothesis import strategies as st

from runtime.vclock import VirtualDeadlock, VirtualTimeLoop, run_virtual


def test_an_hour_of_sleep_takes_no_real_time() -> None:
    async def main() -> tuple[float, float]:
        loop = asyncio.get_running_loop()
        before = loop.time()
        await asyncio.sleep(3600)
        return before, loop.time()

    started = time.perf_counter()
    before, after = run_virtual(main())
    assert after - before == 3600.0
    assert time.perf_counter() - started < 1.0


def test_the_clock_starts_where_asked_and_the_loop_is_current() -> None:
    async def main() -> tuple[float, bool]:
        loop = asyncio.get_running_loop()
        return loop.time(), isinstance(loop, VirtualTimeLoop)

    assert run_virtual(main(), start=1.7e9) == (1.7e9, True)


def test_timers_fire_at_large_clock_readings() -> None:
    """At 1.7e9 s one float step is 2.4e-7 s, more than asyncio's 1 ns resolution."""

    async def main() -> list[float]:
        loop = asyncio.get_running_loop()
        fired: list[float] = []
        loop.call_later(0.0, lambda: fired.append(loop.time()))
        await asyncio.sleep(1e-3)
        await asyncio.sleep(86400 * 3 + 0.5)
        fired.append(loop.time())
        return fired

    fired = run_virtual(main(), start=1.7e9, timeout=1e6)
    assert fired == [1.7e9, pytest.approx(1.7e9 + 86400 * 3 + 0.501, abs=1e-6)]


def test_call_later_callbacks_run_in_time_order_at_their_times() -> None:
    async def main() -> list[tuple[str, float]]:
        loop = asyncio.get_running_loop()
        seen: list[tuple[str, float]] = []
        done: asyncio.Future[None] = loop.create_future()

        def note(name: str) -> None:
            seen.append((name, loop.time()))

        for name, delay in [("c", 3.0), ("a", 1.0), ("d", 10.0), ("b", 2.5)]:
            loop.call_later(delay, note, name)
        loop.call_later(11.0, done.set_result, None)
        await done
        return seen

    assert run_virtual(main()) == [("a", 1.0), ("b", 2.5), ("c", 3.0), ("d", 10.0)]


def test_wait_for_times_out_in_virtual_time() -> None:
    async def main() -> float:
        loop = asyncio.get_running_loop()
        with pytest.raises(TimeoutError):
            await asyncio.wait_for(asyncio.sleep(100), 7.0)
        return loop.time()

    assert run_virtual(main()) == 7.0


def test_run_virtual_gives_up_after_its_timeout_in_virtual_seconds() -> None:
    async def forever() -> None:
        while True:
            await asyncio.sleep(1.0)

    started = time.perf_counter()
    with pytest.raises(TimeoutError, match="after 600 virtual seconds"):
        run_virtual(forever(), timeout=600)
    assert time.perf_counter() - started < 1.0


def test_a_time_out_inside_main_is_not_mistaken_for_run_virtuals() -> None:
    async def main() -> None:
        await asyncio.wait_for(asyncio.sleep(10), 1.0)

    with pytest.raises(TimeoutError) as info:
        run_virtual(main(), timeout=100)
    assert "virtual seconds" not in str(info.value)


def test_waiting_for_what_never_comes_is_a_deadlock_not_a_hang() -> None:
    async def main() -> None:
        await asyncio.Event().wait()

    with pytest.raises(VirtualDeadlock, match="nothing is scheduled"):
        run_virtual(main())


def test_thread_jobs_take_no_virtual_time() -> None:
    async def main() -> tuple[int, float]:
        loop = asyncio.get_running_loop()

        def work() -> int:
            time.sleep(0.05)
            return 42

        result = await asyncio.to_thread(work)
        return result, loop.time()

    assert run_virtual(main()) == (42, 0.0)


def test_run_virtual_refuses_to_nest() -> None:
    async def inner() -> None:
        pass

    async def outer() -> None:
        with pytest.raises(RuntimeError, match="running event loop"):
            run_virtual(inner())

    run_virtual(outer())


def test_pending_tasks_are_cancelled_at_the_end() -> None:
    cancelled = threading.Event()

    async def background() -> None:
        try:
            await asyncio.sleep(1e6)
        except asyncio.CancelledError:
            cancelled.set()
            raise

    async def main() -> None:
        asyncio.get_running_loop().create_task(background())
        await asyncio.sleep(1)

    run_virtual(main())
    assert cancelled.is_set()


async def _workers(seed: int) -> list[tuple[float, str]]:
    """Several tasks sleeping random times, talking through a queue and a lock."""
    rng = random.Random(seed)
    loop = asyncio.get_running_loop()
    events: list[tuple[float, str]] = []
    queue: asyncio.Queue[int] = asyncio.Queue()
    lock = asyncio.Lock()

    async def producer(name: str) -> None:
        for i in range(20):
            await asyncio.sleep(rng.expovariate(2.0))
            await queue.put(i)
            events.append((loop.time(), f"{name} put {i}"))

    async def consumer(name: str) -> None:
        while True:
            item = await queue.get()
            async with lock:
                await asyncio.sleep(rng.uniform(0.0, 0.3))
                events.append((loop.time(), f"{name} got {item}"))

    consumers = [asyncio.create_task(consumer(f"c{i}")) for i in range(3)]
    await asyncio.gather(*(producer(f"p{i}") for i in range(3)))
    while not queue.empty():
        await asyncio.sleep(0.1)
    await asyncio.sleep(1.0)
    for task in consumers:
        task.cancel()
    return events


@given(st.integers(min_value=0, max_value=2**32))
def test_two_runs_with_the_same_seed_see_the_same_events(seed: int) -> None:
    first = run_virtual(_workers(seed))
    assert run_virtual(_workers(seed)) == first
    assert len(first) == 120


def test_a_bad_start_or_timeout_is_refused() -> None:
    with pytest.raises(ValueError, match="start must be finite"):
        run_virtual(asyncio.sleep(1), start=float("nan"))
    with pytest.raises(ValueError, match="timeout a number >= 0"):
        run_virtual(asyncio.sleep(1), timeout=-1.0)


def test_quiet_until_tells_the_earliest_timer_that_will_run() -> None:
    async def main() -> list[float | None]:
        loop = asyncio.get_running_loop()
        assert isinstance(loop, VirtualTimeLoop)
        seen: list[float | None] = [loop.quiet_until()]  # nothing scheduled
        late = loop.call_at(50.0, lambda: None)
        early = loop.call_at(20.0, lambda: None)
        seen.append(loop.quiet_until())
        early.cancel()  # a cancelled timer never runs: not counted
        seen.append(loop.quiet_until())
        loop.call_soon(lambda: None)  # a ready callback runs now, before any timer
        seen.append(loop.quiet_until())
        await asyncio.sleep(0)
        seen.append(loop.quiet_until())
        late.cancel()
        return seen

    assert run_virtual(main(), start=10.0) == [math.inf, 20.0, 50.0, None, 50.0]


def test_quiet_until_is_none_while_a_thread_job_runs() -> None:
    release = threading.Event()

    async def main() -> tuple[float | None, float | None]:
        loop = asyncio.get_running_loop()
        assert isinstance(loop, VirtualTimeLoop)
        job = loop.run_in_executor(None, release.wait, 5.0)
        during = loop.quiet_until()
        release.set()
        await job
        return during, loop.quiet_until()

    assert run_virtual(main()) == (None, math.inf)


def test_real_descriptors_are_polled_only_when_something_can_come_from_them() -> None:
    async def main() -> list[bool]:
        loop = asyncio.get_running_loop()
        assert isinstance(loop, VirtualTimeLoop)
        seen = [loop._virtual.poll]  # only the loop's own wake-up pipe: no poll
        first, second = socket.socketpair()
        loop.add_reader(first, lambda: None)
        seen.append(loop._virtual.poll)  # a socket: polled
        loop.remove_reader(first)
        seen.append(loop._virtual.poll)
        loop.add_signal_handler(signal.SIGUSR1, lambda: None)
        seen.append(loop._virtual.poll)  # a signal handler runs only through the pipe
        loop.remove_signal_handler(signal.SIGUSR1)
        seen.append(loop._virtual.poll)
        first.close()
        second.close()
        return seen

    assert run_virtual(main()) == [False, True, False, True, False]


def test_a_signal_still_reaches_its_handler_under_virtual_time() -> None:
    async def main() -> float:
        loop = asyncio.get_running_loop()
        got = loop.create_future()
        loop.add_signal_handler(signal.SIGUSR1, lambda: got.set_result(loop.time()))
        loop.call_later(5.0, os.kill, os.getpid(), signal.SIGUSR1)
        try:
            return await asyncio.wait_for(got, 60.0)
        finally:
            loop.remove_signal_handler(signal.SIGUSR1)

    assert run_virtual(main()) == 5.0
