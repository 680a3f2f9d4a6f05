"""The controller end to end against the simulated ROMEO: virtual time, emulated links,
resets and outages, hostile bytes, a vehicle that lost the mission."""

from __future__ import annotations

import asyncio
import contextlib
import random
import re
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest

from analysis.certificate import CertificateCheck
from analysis.statespace import explore
from coral_lang.compiler import compile_mission
from coral_lang.net import Net
from romeo_sim.config import default_config
from romeo_sim.server import VehicleServer
from romeo_sim.vehicle import Vehicle
from runtime.controller import Controller, ControllerOptions, RunEnd, RunResult
from runtime.engine import Engine
from runtime.eventlog import EventLog
from runtime.link import BUILTIN_PROFILES, LinkEmulator, MemoryLink
from runtime.protocol import Command, Reply
from runtime.vclock import run_virtual
from tests.runtime.helpers import POOL_MISSION, approve

PSK = bytes(range(32))


@pytest.fixture(scope="module")
def pool(tmp_path_factory: pytest.TempPathFactory) -> tuple[Net, CertificateCheck]:
    net = compile_mission(POOL_MISSION)
    return net, approve(net, tmp_path_factory.mktemp("pool"))


@dataclass
class Run:
    result: RunResult
    server: VehicleServer
    log_path: Path


def simulate(
    net: Net,
    approval: CertificateCheck,
    tmp: Path,
    *,
    profile: str = "genoa-lisbon",
    seed: int = 0,
    wrap: type[MemoryLink] = MemoryLink,
) -> Run:
    """Run the mission against the simulator under virtual time."""
    rng = random.Random(seed)
    log_path = tmp / f"controller-{profile}-{seed}.sqlite"

    async def main() -> tuple[RunResult, VehicleServer]:
        loop = asyncio.get_running_loop()
        server = VehicleServer(
            Vehicle(default_config(), seed=seed),
            PSK,
            clock=loop.time,
            nonces=random.Random(seed + 1).randbytes,
            log=lambda line: None,
        )
        link = wrap(server, LinkEmulator(BUILTIN_PROFILES[profile], seed=seed))
        log = EventLog.create(log_path, role="controller", mission=net.name, meta={})
        try:
            controller = Controller.start_new(
                Engine(net, approval),
                link,
                PSK,
                log,
                mission_id=rng.getrandbits(63),
                now=loop.time(),
                nonces=rng.randbytes,
                console=lambda line: None,
                options=ControllerOptions(time_limit=3600.0),
            )
            result = await controller.run()
        finally:
            log.close()
            await link.aclose()
            await server.stop()
        return result, server

    result, server = run_virtual(main())
    return Run(result, server, log_path)


def check_nothing_lost(run: Run, net: Net) -> None:
    """Every command logged once and carried out once; every reply consumed once."""
    with EventLog.open(run.log_path) as log:
        sent = [e.data["command_id"] for e in log.events("command-sent")]
        replies = [e.data for e in log.events("reply")]
        firings = [str(e.data["transition"]) for e in log.events("fire")]
    assert len(sent) == len(set(sent)) == run.result.commands_sent
    answered = Counter(r["command_id"] for r in replies)
    assert set(answered) == set(sent) and set(answered.values()) == {1}
    seqs = [r["reply_seq"] for r in replies]
    assert seqs == list(range(1, len(seqs) + 1))
    # The vehicle carried out each command id once, however often it was re-sent.
    assert run.server.stats.commands == len(sent)
    # Refinement: replaying the logged firings stays inside the verified state space.
    space = explore(net)
    reachable = {tuple(row) for row in space.markings.tolist()}
    marking = net.initial_marking()
    for name in firings:
        tr = net.transition(name)
        assert net.enabled(marking, tr), name
        marking = net.fire(marking, tr)
        assert marking in reachable
    assert net.marking_dict(marking) == run.result.marking


@pytest.mark.slow
def test_the_pool_mission_completes_over_the_genoa_lisbon_link(
    pool: tuple[Net, CertificateCheck], tmp_path: Path
) -> None:
    net, approval = pool
    run = simulate(net, approval, tmp_path)
    assert run.result.end is RunEnd.FINAL
    assert run.result.marking == {"mission_complete": 1}
    assert run.result.telemetry > 100
    assert len(run.result.clock_syncs) == run.result.connections
    check_nothing_lost(run, net)


class NoTelemetrySocket(MemoryLink):
    """A link whose telemetry socket cannot be opened (say --telemetry-host was removed
    from the machine after start-up)."""

    async def open_telemetry(self, receive: Callable[[bytes], None]) -> int:
        raise OSError(99, "Cannot assign requested address")


def test_a_telemetry_socket_that_cannot_open_costs_the_telemetry_not_the_mission(
    pool: tuple[Net, CertificateCheck], tmp_path: Path
) -> None:
    net, approval = pool
    run = simulate(net, approval, tmp_path, wrap=NoTelemetrySocket)
    assert run.result.end is RunEnd.FINAL
    assert run.result.telemetry == 0
    with EventLog.open(run.log_path) as log:
        notes = [str(e.data.get("detail")) for e in log.events("note")]
    assert notes == ["no telemetry: cannot open its socket (Cannot assign requested address)"]
    check_nothing_lost(run, net)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_resets_and_outages_lose_and_repeat_nothing(
    pool: tuple[Net, CertificateCheck], tmp_path: Path, seed: int
) -> None:
    net, approval = pool
    run = simulate(net, approval, tmp_path, profile="hostile", seed=seed)
    assert run.result.end is RunEnd.FINAL
    assert run.result.connections > 1  # the hostile link did cut the connection
    check_nothing_lost(run, net)


class _Tampering(MemoryLink):
    """Puts garbage, a forged frame and a replayed frame in front of the vehicle's bytes."""

    async def connect(self):  # type: ignore[no-untyped-def]
        conn = await super().connect()
        original = conn.read
        reads = 0
        recorded = b""

        async def read() -> bytes:
            nonlocal reads, recorded
            data = await original()
            reads += 1
            if not data or reads < 3:
                return data
            if not recorded:
                recorded = data  # replayed later
            junk = b"\xc5\x01garbage" + bytes(40)
            forged = b"\xc5\x01\x11" + bytes(60)  # looks like a Reply frame, bad tag
            replay = recorded if reads % 5 == 0 else b""
            return junk + forged + replay + data

        conn.read = read  # type: ignore[method-assign]
        return conn


def test_hostile_bytes_are_dropped_and_the_mission_goes_on(
    pool: tuple[Net, CertificateCheck], tmp_path: Path
) -> None:
    net, approval = pool
    run = simulate(net, approval, tmp_path, profile="lan", wrap=_Tampering)
    assert run.result.end is RunEnd.FINAL
    assert run.result.rejected_frames > 0
    check_nothing_lost(run, net)


def test_a_vehicle_that_lost_the_mission_ends_the_run(
    pool: tuple[Net, CertificateCheck], tmp_path: Path
) -> None:
    """Resuming against a vehicle that restarted must not assume its state."""
    net, approval = pool
    log_path = tmp_path / "ctl.sqlite"

    async def main() -> RunResult:
        loop = asyncio.get_running_loop()
        server = VehicleServer(Vehicle(default_config(), seed=0), PSK, clock=loop.time)
        link = MemoryLink(server, None)
        log = EventLog.create(log_path, role="controller", mission=net.name, meta={})
        engine = Engine(net, approval)
        engine.start(0.0)
        log.commit(
            {"engine": engine.snapshot(), "mission_id": 42, "consumed": 1, "mission_known": True}
        )
        try:
            controller = Controller.resume(
                lambda s: Engine.restore(net, approval, s),
                link,
                PSK,
                log,
                console=lambda line: None,
            )
            return await controller.run()
        finally:
            log.close()
            await link.aclose()
            await server.stop()

    result = run_virtual(main())
    assert result.end is RunEnd.VEHICLE_LOST_MISSION
    with EventLog.open(log_path) as log:
        assert log.count("mission-lost") == 1


def test_command_and_reply_frames_fit_the_paper_link(pool: tuple[Net, CertificateCheck]) -> None:
    """Every command the pool mission sends fits in well under one 9600 bps second."""
    from runtime.protocol import frame_size

    net, _ = pool
    for tr in net.transitions:
        if tr.command is not None:
            size = frame_size(Command(1, tr.command.name, 0.0, dict(tr.command.params)))
            assert size < 120, (tr.name, size)
    assert frame_size(Reply(1, 1, "timeout", 0.0)) < 60


@pytest.mark.parametrize(
    ("second_limit", "says"),
    [(80.0, "the vehicle sent reply #19 "), (60.0, "re-sent none after #8")],
    ids=["a-reply-skips-numbers", "nothing-left-to-resend"],
)
def test_a_log_that_lost_its_last_commits_ends_the_run_instead_of_hanging(
    pool: tuple[Net, CertificateCheck], tmp_path: Path, second_limit: float, says: str
) -> None:
    """The red team's truncated write-ahead log: the vehicle had acknowledgements the
    log no longer holds. The resumed controller must stop, saying so, not wait forever."""
    import shutil

    net, approval = pool
    log_path = tmp_path / "ctl.sqlite"
    backup = tmp_path / "early.sqlite"

    async def main() -> tuple[RunResult, RunResult, RunResult]:
        loop = asyncio.get_running_loop()
        server = VehicleServer(Vehicle(default_config(), seed=0), PSK, clock=loop.time)
        link = MemoryLink(server, None)

        def quiet(line: str) -> None:
            del line

        def resumed(limit: float) -> Controller:
            return Controller.resume(
                lambda s: Engine.restore(net, approval, s),
                link,
                PSK,
                EventLog.open(log_path, writable=True),
                options=ControllerOptions(time_limit=limit),
                console=quiet,
            )

        try:
            log = EventLog.create(log_path, role="controller", mission=net.name, meta={})
            first = Controller.start_new(
                Engine(net, approval),
                link,
                PSK,
                log,
                mission_id=7,
                now=loop.time(),
                options=ControllerOptions(time_limit=40.0),
                console=quiet,
            )
            one = await first.run()
            log.close()
            shutil.copy(log_path, backup)  # what a truncated log will hold
            second = resumed(second_limit)
            two = await second.run()
            second.log.close()
            shutil.copy(backup, log_path)  # the commits of the second run are lost
            third = resumed(3600.0)
            three = await third.run()
            third.log.close()
            return one, two, three
        finally:
            await link.aclose()
            await server.stop()

    one, two, three = run_virtual(main())
    assert one.end is RunEnd.TIME_LIMIT and two.end is RunEnd.TIME_LIMIT
    assert two.replies > 0  # the vehicle got acknowledgements the backup does not have
    assert three.end is RunEnd.LOG_BEHIND
    assert "lost its last commits" in three.detail and says in three.detail
    # Within a heartbeat of the handshake, not whenever the vehicle's next reply comes:
    # with nothing left to re-send, the resumed run used to wait for replies it had lost.
    assert three.ended_at - three.started_at < 5.0, three.detail
    with EventLog.open(log_path) as log:
        assert log.count("log-behind") == 1


def test_a_flood_of_junk_telemetry_is_counted_not_logged_datagram_by_datagram(
    pool: tuple[Net, CertificateCheck], tmp_path: Path
) -> None:
    """2.88M random datagrams once grew a log from 80 KB to 61 MB: now the first few are
    logged, then one summary event every few seconds with their count."""
    from runtime.controller import REJECTION_SUMMARY_S, REJECTIONS_LOGGED
    from runtime.protocol import DatagramReceiver

    net, approval = pool
    rng = random.Random(5)
    datagrams = 20_000
    seconds = 60.0

    async def main() -> RunResult:
        loop = asyncio.get_running_loop()
        log = EventLog.create(tmp_path / "ctl.sqlite", role="controller", mission=net.name, meta={})
        controller = Controller.start_new(
            Engine(net, approval),
            MemoryLink(VehicleServer(Vehicle(default_config()), PSK, clock=loop.time), None),
            PSK,
            log,
            mission_id=1,
            now=loop.time(),
            console=lambda line: None,
        )
        controller._result = result = RunResult(RunEnd.FINAL, {}, 0.0, 0.0)
        controller._telemetry = DatagramReceiver(bytes(32))
        for i in range(datagrams):
            await asyncio.sleep(seconds / datagrams)
            controller._on_datagram(rng.randbytes(rng.randrange(1, 80)) if i % 2 else b"\x00")
        log.close()
        return result

    result = run_virtual(main())
    assert result.telemetry_rejected == datagrams
    with EventLog.open(tmp_path / "ctl.sqlite") as log:
        events = list(log.events("telemetry-rejected"))
    summaries = [e for e in events if "count" in e.data]
    assert len(events) - len(summaries) == REJECTIONS_LOGGED
    assert len(summaries) <= seconds / REJECTION_SUMMARY_S + 1
    assert sum(int(str(e.data["count"])) for e in summaries) <= datagrams - REJECTIONS_LOGGED


# --- stopping: SIGINT/SIGTERM end a run cleanly (Controller.request_stop) ----------------


@dataclass
class Stopped:
    stopped: RunResult
    resumed: RunResult
    console: list[str]
    server: VehicleServer


def stop_then_resume(
    net: Net,
    approval: CertificateCheck,
    tmp: Path,
    *,
    stop_at: float,
    second_stop_after: float | None = None,
    profile: str = "lan",
    start: float = 1682.6,
    cut_after_stop: float | None = None,
) -> Stopped:
    """Run the pool mission in virtual time, stop it ``stop_at`` seconds in (as a signal
    would), then resume it from the log against the same vehicle."""
    log_path = tmp / "controller.sqlite"
    console: list[str] = []

    async def main() -> tuple[RunResult, RunResult, VehicleServer]:
        loop = asyncio.get_running_loop()
        vehicle_log = EventLog.create(
            tmp / "vehicle.sqlite", role="vehicle", mission=net.name, meta={}
        )
        server = VehicleServer(
            Vehicle(default_config(), seed=0),
            PSK,
            clock=loop.time,
            nonces=random.Random(1).randbytes,
            log=lambda line: None,
            event_log=vehicle_log,
        )
        link = MemoryLink(server, LinkEmulator(BUILTIN_PROFILES[profile], seed=0))
        rng = random.Random(2)
        try:
            log = EventLog.create(log_path, role="controller", mission=net.name, meta={})
            first = Controller.start_new(
                Engine(net, approval),
                link,
                PSK,
                log,
                mission_id=7,
                now=loop.time(),
                nonces=rng.randbytes,
                console=console.append,
            )
            loop.call_later(stop_at, first.request_stop, "SIGTERM")
            if second_stop_after is not None:
                loop.call_later(stop_at + second_stop_after, first.request_stop, "SIGTERM")
            if cut_after_stop is not None:  # a reset, with the make-safe request in flight

                def cut() -> None:
                    for conn in list(link._live):
                        conn._cut()

                loop.call_later(stop_at + cut_after_stop, cut)
            stopped = await first.run()
            log.close()
            second = Controller.resume(
                lambda s: Engine.restore(net, approval, s),
                link,
                PSK,
                EventLog.open(log_path, writable=True),
                nonces=rng.randbytes,
                console=lambda line: None,
                options=ControllerOptions(time_limit=3600.0),
            )
            resumed = await second.run()
            second.log.close()
            return stopped, resumed, server
        finally:
            await link.aclose()
            await server.stop()
            vehicle_log.close()

    stopped, resumed, server = run_virtual(main(), start=start)
    return Stopped(stopped, resumed, console, server)


def test_a_stop_makes_the_vehicle_safe_and_resume_follows_the_error_path(
    pool: tuple[Net, CertificateCheck], tmp_path: Path
) -> None:
    net, approval = pool
    run = stop_then_resume(net, approval, tmp_path, stop_at=120.0)
    stopped = run.stopped
    assert stopped.end is RunEnd.STOPPED and not stopped.ok
    assert stopped.stopped_by == "SIGTERM" and stopped.made_safe is True
    assert stopped.mission_time == pytest.approx(120.0, abs=1.0)
    # The vehicle made itself safe once, logged it, and its stopped query's reply waited
    # in the ledger for the resumed controller.
    with EventLog.open(tmp_path / "vehicle.sqlite") as vlog:
        asks = [e.data for e in vlog.events("make-safe")]
    assert [a["repeat"] for a in asks] == [False] and asks[0]["reason"] == "SIGTERM"
    with EventLog.open(tmp_path / "controller.sqlite") as log:
        replies = [e.data for e in log.events("reply")]
        sent = [e.data["command_id"] for e in log.events("command-sent")]
        ends = [e.data for e in log.events("mission-end")]
        assert log.count("make-safe-sent") == log.count("make-safe-acked") == 1
    assert ends[0]["end"] == "stopped" and ends[0]["made_safe"] is True
    stopped_replies = [r for r in replies if "make itself safe" in str(r["detail"])]
    assert stopped_replies and {r["kind"] for r in stopped_replies} <= {"timeout", "error"}
    # Resumed: consumed in order, each command carried out once, a declared final marking.
    assert run.resumed.end is RunEnd.FINAL
    assert run.resumed.marking in ({"aborted_at_surface": 1}, {"operator_alert": 1})
    assert [r["reply_seq"] for r in replies] == list(range(1, len(replies) + 1))
    assert len(sent) == len(set(sent)) == run.server.stats.commands


def test_console_times_are_mission_times_not_the_raw_clock(
    pool: tuple[Net, CertificateCheck], tmp_path: Path
) -> None:
    net, approval = pool
    run = stop_then_resume(net, approval, tmp_path, stop_at=30.0, start=1682.6)
    times = [float(m.group(1)) for line in run.console if (m := re.match(r"t=(\S+) ", line))]
    assert times and times[0] == 0.0 and max(times) < 31.0  # not 1682.6 and up
    connected = next(line for line in run.console if "connected" in line)
    # The vehicle's clock (ROMEO starts at 0) at the moment of the handshake, not the
    # difference between two unrelated clocks (-1682.6 s).
    match = re.search(r"vehicle clock at (\S+) s", connected)
    assert match and 0.0 <= float(match.group(1)) < 5.0, connected


def test_a_second_stop_gives_up_waiting_for_the_vehicle(
    pool: tuple[Net, CertificateCheck], tmp_path: Path
) -> None:
    """Over the Genoa-Lisbon link the acknowledgement takes seconds; the second signal
    a moment later ends the run at once, without it."""
    net, approval = pool
    run = stop_then_resume(
        net, approval, tmp_path, stop_at=120.0, second_stop_after=0.01, profile="genoa-lisbon"
    )
    assert run.stopped.end is RunEnd.STOPPED and run.stopped.made_safe is False
    assert run.stopped.stop_requests == 2
    assert run.stopped.mission_time < 120.5
    assert run.resumed.end is RunEnd.FINAL


def test_a_connection_lost_during_make_safe_is_replaced_within_the_same_budget(
    pool: tuple[Net, CertificateCheck], tmp_path: Path
) -> None:
    """The review found that a reset with the request in flight gave up at once, leaving
    the vehicle to its watchdog; now the request goes again on a new connection."""
    net, approval = pool
    run = stop_then_resume(net, approval, tmp_path, stop_at=120.0, cut_after_stop=1e-4)
    assert run.stopped.end is RunEnd.STOPPED and run.stopped.made_safe is True
    assert run.stopped.mission_time < 120.0 + ControllerOptions().make_safe_timeout
    with EventLog.open(tmp_path / "controller.sqlite") as log:
        kinds = [e.kind for e in log.events() if e.kind.startswith("make-safe")]
    assert kinds == ["make-safe-sent", "make-safe-failed", "make-safe-sent", "make-safe-acked"]
    with EventLog.open(tmp_path / "vehicle.sqlite") as vlog:
        assert [e.data["repeat"] for e in vlog.events("make-safe")] == [False]
    assert run.resumed.end is RunEnd.FINAL


def test_a_stop_before_any_connection_makes_safe_on_a_new_one(
    pool: tuple[Net, CertificateCheck], tmp_path: Path
) -> None:
    net, approval = pool
    log_path = tmp_path / "ctl.sqlite"

    async def main() -> tuple[RunResult, VehicleServer]:
        loop = asyncio.get_running_loop()
        server = VehicleServer(Vehicle(default_config(), seed=0), PSK, clock=loop.time)
        link = MemoryLink(server, None)
        log = EventLog.create(log_path, role="controller", mission=net.name, meta={})
        try:
            controller = Controller.start_new(
                Engine(net, approval),
                link,
                PSK,
                log,
                mission_id=9,
                now=loop.time(),
                console=lambda line: None,
            )
            controller.request_stop("SIGINT")  # before run(): no connection yet
            return await controller.run(), server
        finally:
            log.close()
            await link.aclose()
            await server.stop()

    result, server = run_virtual(main())
    assert result.end is RunEnd.STOPPED and result.made_safe is True
    assert result.commands_sent == 0 and server.stats.commands == 0
    with EventLog.open(log_path) as log:
        assert log.count("make-safe-acked") == 1
        assert log.checkpoint() is not None  # committed: --resume can continue it


def test_a_controller_killed_before_hearing_back_resumes_without_rerunning_init(
    pool: tuple[Net, CertificateCheck], tmp_path: Path
) -> None:
    """bench/kill9.py found INIT carried out twice: killed after INIT reached the vehicle
    but before any reply or heartbeat came back, the log said the vehicle had not taken
    the mission, and the resumed controller's Hello started it afresh (a new reply
    ledger). Now every Hello after the first asks to resume."""
    import shutil

    net, approval = pool
    log_path = tmp_path / "ctl.sqlite"
    dead = tmp_path / "dead"  # the log as the killed controller left it on disk
    dead.mkdir()

    async def main() -> tuple[RunResult, VehicleServer, dict[str, object]]:
        loop = asyncio.get_running_loop()
        server = VehicleServer(Vehicle(default_config(), seed=0), PSK, clock=loop.time)
        link = MemoryLink(server, LinkEmulator(BUILTIN_PROFILES["lan"], seed=0))
        try:
            log = EventLog.create(log_path, role="controller", mission=net.name, meta={})
            first = Controller.start_new(
                Engine(net, approval),
                link,
                PSK,
                log,
                mission_id=11,
                now=loop.time(),
                console=lambda line: None,
            )
            task = asyncio.ensure_future(first.run())
            while server.stats.commands == 0:  # INIT has reached the vehicle: kill -9
                await asyncio.sleep(0.0005)
            for suffix in ("", "-wal"):
                source = Path(f"{log_path}{suffix}")
                if source.exists():
                    shutil.copy(source, dead / f"ctl.sqlite{suffix}")
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task
            log.close()
            for suffix in ("", "-wal", "-shm"):
                Path(f"{log_path}{suffix}").unlink(missing_ok=True)
                if (dead / f"ctl.sqlite{suffix}").exists():
                    shutil.copy(dead / f"ctl.sqlite{suffix}", f"{log_path}{suffix}")
            resumed_log = EventLog.open(log_path, writable=True)
            state = resumed_log.checkpoint()
            assert state is not None
            second = Controller.resume(
                lambda s: Engine.restore(net, approval, s),
                link,
                PSK,
                resumed_log,
                options=ControllerOptions(time_limit=3600.0),
                console=lambda line: None,
            )
            result = await second.run()
            resumed_log.close()
            return result, server, state
        finally:
            await link.aclose()
            await server.stop()

    result, server, state = run_virtual(main())
    # The situation of the bug: the vehicle had INIT, the log had heard nothing back.
    assert state["mission_known"] is False and state["consumed"] == 0
    assert result.end is RunEnd.FINAL and result.marking == {"mission_complete": 1}
    with EventLog.open(log_path) as log:
        sent = {e.data["command_id"] for e in log.events("command-sent")}
        handshakes = [e.data for e in log.events("handshake")]
    assert server.stats.commands == len(sent)  # INIT (and every other id) carried out once
    assert handshakes[-1]["asked_resume"] is True and handshakes[-1]["resumed"] is True
