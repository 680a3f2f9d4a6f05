"""`LiveFeed`: a run's state fed by its event log's listener equals a re-read of the same
log, and waking the server costs the engine one signal per burst, not one per row."""

from __future__ import annotations

import asyncio
import json
import random
from pathlib import Path

import pytest

from analysis.certificate import CertificateCheck
from coral_lang.compiler import compile_mission
from coral_lang.net import Net
from romeo_sim.config import default_config
from romeo_sim.server import VehicleServer
from romeo_sim.vehicle import Vehicle
from runtime.controller import Controller, ControllerOptions, RunEnd
from runtime.engine import Engine
from runtime.eventlog import EventLog
from runtime.link import BUILTIN_PROFILES, LinkEmulator, MemoryLink
from runtime.vclock import run_virtual
from runtime.watch.feed import LiveFeed
from runtime.watch.live import LiveWatch
from runtime.watch.server import Watch
from runtime.watch.source import LogReader
from tests.runtime.helpers import POOL_MISSION, approve

PSK = bytes(range(32))


@pytest.fixture(scope="module")
def pool(tmp_path_factory: pytest.TempPathFactory) -> tuple[Net, CertificateCheck]:
    net = compile_mission(POOL_MISSION)
    return net, approve(net, tmp_path_factory.mktemp("pool"))


@pytest.mark.slow
def test_the_listener_feed_equals_a_reread_of_the_log(
    pool: tuple[Net, CertificateCheck], tmp_path: Path
) -> None:
    net, approval = pool
    path = tmp_path / "controller.sqlite"
    net_json = json.dumps(net.canonical(), sort_keys=True)
    wakes: list[tuple[int, bool]] = []

    async def main() -> tuple[RunEnd, LiveFeed]:
        loop = asyncio.get_running_loop()
        server = VehicleServer(Vehicle(default_config(), seed=3), PSK, clock=loop.time)
        link = MemoryLink(server, LinkEmulator(BUILTIN_PROFILES["genoa-lisbon"], seed=3))
        log = EventLog.create(path, role="controller", mission=net.name, meta={}, net_json=net_json)
        feed = LiveFeed(log, net_json)

        async def waiter() -> None:  # the server's side: how often is it woken?
            version = 0
            while True:
                version = await feed.changed(version)
                wakes.append((version, feed.snapshot().end is not None))
                if feed.ended:
                    return
                await asyncio.sleep(feed.interval)

        watching = asyncio.create_task(waiter())
        try:
            controller = Controller.start_new(
                Engine(net, approval),
                link,
                PSK,
                log,
                mission_id=random.Random(3).getrandbits(63),
                now=loop.time(),
                nonces=random.Random(4).randbytes,
                console=lambda line: None,
                options=ControllerOptions(time_limit=3600.0),
            )
            result = await controller.run()
            await asyncio.wait_for(watching, 5)
        finally:
            feed.close()
            log.close()
            await link.aclose()
            await server.stop()
        return result.end, feed

    end, feed = run_virtual(main())
    assert end is RunEnd.FINAL
    reader = LogReader(path)
    try:
        reread = Watch(reader)
        reread.poll()
        assert feed.snapshot().to_json() == reread.state.snapshot().to_json()
        assert feed.span() == reread.span()
        assert feed.state.seq == len(reread.events) and len(reread.samples) > 100
        # The state at a past time is read from the log: the same as a log's server says.
        live = LiveWatch(feed)
        t = feed.span()[1] / 2
        assert live.document(t) == reread.document(t)
        live.close()
    finally:
        reader.close()
    # Throttled: at most one wake per interval of (virtual) time, and the last one saw
    # the mission-end (rows may follow it: the link's goodbye).
    rows = len(reread.events) + len(reread.samples)
    assert feed.version == rows
    assert [ended for _, ended in wakes] == [False] * (len(wakes) - 1) + [True]
    assert len(wakes) <= feed.span()[1] / feed.interval + 2


def test_a_burst_wakes_the_waiter_once(tmp_path: Path) -> None:
    async def main() -> None:
        log = EventLog.create(tmp_path / "l.sqlite", role="controller", mission="m", meta={})
        feed = LiveFeed(log, None)
        signals = 0
        original = feed._signal

        def counting() -> None:
            nonlocal signals
            signals += 1
            original()

        feed._signal = counting  # type: ignore[method-assign]
        try:
            assert await asyncio.wait_for(feed.changed(-1), 1) == 0  # nothing yet: at once
            waiting = asyncio.create_task(feed.changed(0))
            await asyncio.sleep(0)
            for n in range(1000):
                log.event(float(n), "tick")
            assert await asyncio.wait_for(waiting, 1) == 1000
            assert signals == 1
            assert feed.state.seq == 1000 and feed.state.time == 999.0
            feed.close()
            assert await asyncio.wait_for(feed.changed(1000), 1) == 1000  # closed: no wait
            log.event(1000.0, "tick")  # after close: no longer listened to
            assert feed.version == 1000
        finally:
            log.close()

    asyncio.run(main())


def test_rows_logged_from_another_thread_wake_the_loop(tmp_path: Path) -> None:
    async def main() -> None:
        log = EventLog.create(tmp_path / "l.sqlite", role="controller", mission="m", meta={})
        feed = LiveFeed(log, None)
        try:
            waiting = asyncio.create_task(feed.changed(0))
            await asyncio.sleep(0)
            await asyncio.to_thread(log.event, 1.0, "tick")
            assert await asyncio.wait_for(waiting, 1) == 1
        finally:
            feed.close()
            log.close()

    asyncio.run(main())


@pytest.mark.slow
def test_a_dropped_listener_marks_the_feed_broken_and_publishes_once(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The log drops a listener that raises: the feed must say it no longer hears the run
    (a last document with ``broken``, not live) instead of freezing while showing LIVE."""

    async def main() -> None:
        log = EventLog.create(tmp_path / "l.sqlite", role="controller", mission="m", meta={})
        feed = LiveFeed(log, None)
        live = LiveWatch(feed)
        published: list[dict[str, object]] = []
        try:
            log.event(0.0, "tick")
            following = asyncio.create_task(
                live.follow(lambda: published.append(live.document()), lambda line: None)
            )
            await asyncio.sleep(0)
            assert await asyncio.wait_for(feed.changed(-1), 1) == 1

            def failing(*args: object, **kwargs: object) -> None:
                raise RuntimeError("state bug")

            feed.state.advance = failing  # type: ignore[method-assign]
            log.event(1.0, "tick")
            assert feed.broken is not None and "state bug" in feed.broken
            assert feed.ended
            await asyncio.wait_for(following, 1)  # published the broken state, then stopped
            last = published[-1]
            assert last["live"] is False and "RuntimeError: state bug" in str(last["broken"])
            assert all("broken" not in doc for doc in published[:-1])
            log.event(2.0, "tick")  # no longer listened to; logging goes on
            assert log.pending == 3
        finally:
            feed.close()
            log.close()

    asyncio.run(main())
    assert capsys.readouterr().err.count("state bug") == 1
