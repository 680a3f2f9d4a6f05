"""An engine spin: a cycle of engine transitions that never waits for the vehicle.

The engine gives up after ``max_firings_per_step`` firings and names the cycle (with the
source line of each transition); the controller ends the run as ``spin`` (logged, plots
drawn, ``coral-run`` exits 1), and fuzz counts it as a failed run with its seed. Nothing
more is sent to the vehicle: its watchdog surfaces it.

Every approval here is built in-process (`CertificateCheck` for the net's digest), so
these tests do not depend on whether verification accepts a spinning mission.
"""

from __future__ import annotations

import asyncio
import functools
import json
import random
from collections.abc import Sequence
from pathlib import Path

import pytest

from analysis.certificate import CertificateCheck
from coral_lang.mission import load_mission
from coral_lang.net import Net
from coral_lang.profile import VehicleProfile
from romeo_sim.config import default_config
from romeo_sim.server import VehicleServer
from romeo_sim.vehicle import Vehicle
from runtime import fuzz as fuzz_module
from runtime import gate
from runtime.cli import main
from runtime.controller import Controller, ControllerOptions, RunEnd, RunResult
from runtime.engine import Engine, EngineError, EngineSpin, Outcome, Policy, find_cycle
from runtime.eventlog import EventLog
from runtime.fuzz import FuzzOptions, format_report, fuzz
from runtime.fuzz import one_run as fuzz_one_run
from runtime.link import BUILTIN_PROFILES, Connection, LinkEmulator, MemoryLink
from runtime.vclock import run_virtual
from tests.runtime.helpers import compile_text

PSK = bytes(range(32))

# The DEPTH is below the pool's reachable bottom: the vehicle replies 'error', and the
# error leads into two plain transitions that hand one token back and forth.
SPINNING = """\
# A mission that spins once its DEPTH is refused.
mission spinning
vehicle ROMEO

place start = 1
place done, ping_side, pong_side

final { done }

transition dive
    wait   { start }
    action { ROMEO(DEPTH, z = 10.0 m) -> { ack: done, error: ping_side } }

transition ping
    wait   { ping_side }
    signal { pong_side }

transition pong
    wait   { pong_side }
    signal { ping_side }
"""

# Three plain transitions lead from the start into a cycle of three.
PREFIX_THEN_CYCLE_OF_3 = """\
mission prefix_then_cycle
vehicle ROMEO
place start = 1
place a, b, c, d, e, done
final { done }
transition go
    wait { start }
    signal { a }
transition one
    wait { a }
    signal { b }
transition two
    wait { b }
    signal { c }
transition x
    wait { c }
    signal { d }
transition y
    wait { d }
    signal { e }
transition z
    wait { e }
    signal { c }
"""

# The vehicle is diving (DEPTH acknowledged) when the engine starts to spin.
SPIN_WHILE_DIVING = """\
mission spin_while_diving
vehicle ROMEO
place start = 1
place done, ping_side, pong_side
final { done }
transition dive
    wait   { start }
    action { ROMEO(DEPTH, z = 2.0 m) -> { ack: ping_side, error: done } }
transition ping
    wait   { ping_side }
    signal { pong_side }
transition pong
    wait   { pong_side }
    signal { ping_side }
"""


def line_of(text: str, needle: str) -> int:
    """The 1-based line of ``text`` that holds ``needle``."""
    return next(i for i, line in enumerate(text.splitlines(), 1) if needle in line)


def hand_approval(net: Net) -> CertificateCheck:
    """An approval for ``net`` made here, whatever verification says of it."""
    return CertificateCheck("hand-made (test)", net.digest(), "", "")


# --------------------------------------------------------------------------- the engine


def test_the_spin_names_the_cycle_entered_from_a_reply() -> None:
    net = compile_text(SPINNING)
    engine = Engine(net, hand_approval(net), max_firings_per_step=1000)
    (dive,) = engine.start(0.0).commands
    with pytest.raises(EngineSpin) as caught:
        engine.on_reply(dive.command_id, "error", 1.0)
    spin = caught.value
    assert isinstance(spin, EngineError)  # whoever caught the old error still does
    assert spin.cycle == ("ping", "pong")
    ping, pong = line_of(SPINNING, "transition ping"), line_of(SPINNING, "transition pong")
    assert spin.sources == (f"test.coral:{ping}", f"test.coral:{pong}")
    assert [f.transition for f in spin.prefix] == ["dive.error"]
    assert spin.prefix[0].command_id == dive.command_id
    assert not spin.irregular and spin.limit == 1000
    assert spin.marking == {"ping_side": 1}  # 1000 firings: 500 laps
    assert str(spin) == (
        "engine spin: more than 1000 firings without waiting for the vehicle; cycle "
        f"ping (test.coral:{ping}) -> pong (test.coral:{pong}) -> ping"
    )
    assert spin.to_json()["cycle"] == ["ping", "pong"]


@pytest.mark.parametrize("limit", [9, 10, 11, 1000, 4096 + 50])
def test_a_cycle_of_three_entered_after_a_prefix(limit: int) -> None:
    """Two laps after the prefix or more: the cycle starts where the step entered it."""
    net = compile_text(PREFIX_THEN_CYCLE_OF_3)
    engine = Engine(net, hand_approval(net), max_firings_per_step=limit)
    with pytest.raises(EngineSpin, match=f"more than {limit} firings") as caught:
        engine.start(0.0)
    spin = caught.value
    assert spin.cycle == ("x", "y", "z")
    assert [f.transition for f in spin.prefix] == ["go", "one", "two"]
    lines = [line_of(PREFIX_THEN_CYCLE_OF_3, f"transition {n}") for n in ("x", "y", "z")]
    assert spin.sources == tuple(f"test.coral:{n}" for n in lines)
    assert str(spin).endswith(
        f"cycle x (test.coral:{lines[0]}) -> y (test.coral:{lines[1]}) -> "
        f"z (test.coral:{lines[2]}) -> x"
    )


def test_a_random_policy_spin_is_still_named() -> None:
    net = compile_text(PREFIX_THEN_CYCLE_OF_3)
    engine = Engine(net, hand_approval(net), policy=Policy.RANDOM, seed=3, max_firings_per_step=50)
    with pytest.raises(EngineSpin) as caught:
        engine.start(0.0)
    assert caught.value.cycle == ("x", "y", "z")


def test_find_cycle() -> None:
    assert find_cycle(list("abcabcab")) == (0, 3, False)
    assert find_cycle(list("pqrstxyzxyzxyzxyz")) == (5, 3, False)
    assert find_cycle(list("pqxyxy")) == (2, 2, False)
    assert find_cycle(list("aaaa")) == (0, 1, False)
    # A long periodic run: the start is followed back beyond the window.
    fired = ["p", "q", *("uvw" * 5000)]
    assert find_cycle(fired, window=64) == (2, 3, False)
    # Not periodic: the stretch since the last name's previous firing, flagged irregular.
    assert find_cycle(list("abcdbe" + "cdaecb")) == (4, 7, True)  # "b" ... "b"
    assert find_cycle(list("abcdef")) == (6, 0, True)  # nothing repeats
    assert find_cycle(["a"]) == (1, 0, True)
    # A cycle longer than half the window: irregular, but still a real stretch.
    long_cycle = [f"t{i}" for i in range(40)] * 3
    start, length, irregular = find_cycle(long_cycle, window=64)
    assert (length, irregular) == (40, True)
    assert long_cycle[start] == long_cycle[-1]


def test_a_long_cycle_is_cut_in_the_message() -> None:
    spin = EngineSpin(
        cycle=tuple(f"t{i}" for i in range(30)),
        sources=("",) * 30,
        prefix=(),
        marking={},
        limit=10,
    )
    text = str(spin)
    assert "t0 -> t1" in text and "t10 -> ... (19 more) -> t0" in text
    assert "t29" not in text


# --------------------------------------------------------------------------- the controller


def _simulate(
    net: Net, log_path: Path, *, limit: int, linger: float = 0.0
) -> tuple[RunResult, VehicleServer]:
    """Run ``net`` against the simulator in virtual time; keep the vehicle running for
    ``linger`` more seconds after the controller is done."""

    async def go() -> tuple[RunResult, VehicleServer]:
        loop = asyncio.get_running_loop()
        server = VehicleServer(
            Vehicle(default_config(), seed=0),
            PSK,
            clock=loop.time,
            nonces=random.Random(1).randbytes,
            log=lambda line: None,
        )
        link = MemoryLink(server, LinkEmulator(BUILTIN_PROFILES["lan"], seed=0))
        log = EventLog.create(log_path, role="controller", mission=net.name, meta={})
        try:
            controller = Controller.start_new(
                Engine(net, hand_approval(net), max_firings_per_step=limit),
                link,
                PSK,
                log,
                mission_id=7,
                now=loop.time(),
                nonces=random.Random(2).randbytes,
                console=lambda line: None,
                options=ControllerOptions(time_limit=3600.0),
            )
            result = await controller.run()
            await link.aclose()
            await asyncio.sleep(linger)
        finally:
            log.close()
            await link.aclose()
            await server.stop()
        return result, server

    return run_virtual(go())


def test_the_controller_ends_a_spin_logs_it_and_leaves_the_vehicle_to_its_watchdog(
    tmp_path: Path,
) -> None:
    net = compile_text(SPIN_WHILE_DIVING)
    log_path = tmp_path / "controller.sqlite"
    watchdog = default_config().watchdog_s
    result, server = _simulate(net, log_path, limit=1000, linger=watchdog + 60.0)
    assert result.end is RunEnd.SPIN and not result.ok
    assert result.commands_sent == 1 and result.replies == 1
    assert "cycle ping (test.coral:" in result.detail
    assert result.detail in result.summary()
    with EventLog.open(log_path) as log:
        kinds = [e.kind for e in log.events() if e.kind not in ("handshake",)]
        spin = next(log.events("engine-spin")).data
        end = next(log.events("mission-end")).data
        reply = next(log.events("reply")).data
        checkpoint = log.checkpoint()
    assert kinds[-4:] == ["reply", "fire", "engine-spin", "mission-end"]
    assert reply["transition"] == "dive.ack"
    assert spin["cycle"] == ["ping", "pong"] and spin["limit"] == 1000
    assert end == {"end": "spin", "final": False, "marking": {"ping_side": 1}}
    # The engine stopped mid-step: the checkpoint is the one before the reply.
    assert checkpoint is not None and checkpoint["consumed"] == 0
    # Nothing more was sent: the vehicle's watchdog stopped the dive and surfaced it.
    assert server.stats.commands == 1
    events = [e.text for e in server.vehicle.events]
    assert any(text.startswith("watchdog: no word from the controller") for text in events)
    assert server.vehicle.telemetry().z < 0.5


class _Unreachable:
    """A link the controller must not use."""

    async def connect(self) -> Connection:
        raise AssertionError("a mission that spun at its start must not reach the vehicle")

    async def open_telemetry(self, receive: object) -> int:
        raise AssertionError("no telemetry either")

    async def aclose(self) -> None:
        return None


def test_a_spin_at_the_start_ends_the_run_before_anything_is_sent(tmp_path: Path) -> None:
    net = compile_text(PREFIX_THEN_CYCLE_OF_3)
    log_path = tmp_path / "controller.sqlite"
    engine = Engine(net, hand_approval(net), max_firings_per_step=100)

    async def go() -> RunResult:
        log = EventLog.create(log_path, role="controller", mission=net.name, meta={})
        try:
            controller = Controller.start_new(
                engine,
                _Unreachable(),
                PSK,
                log,
                mission_id=1,
                now=asyncio.get_running_loop().time(),
                console=lambda line: None,
            )
            return await controller.run()
        finally:
            log.close()

    result = run_virtual(go())
    assert result.end is RunEnd.SPIN and result.connections == 0
    z = line_of(PREFIX_THEN_CYCLE_OF_3, "transition z")
    assert result.detail.endswith(f"-> z (test.coral:{z}) -> x")
    with EventLog.open(log_path) as log:
        kinds = [e.kind for e in log.events()]
    assert kinds == ["mission-start", "fire", "fire", "fire", "engine-spin", "mission-end"]
    assert engine.outcome() is Outcome.RUNNING  # the engine itself never ends a spin


# --------------------------------------------------------------------------- coral-run


@pytest.fixture
def spinning(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """The spinning mission on disk, approved in-process by `coral-run`'s gate."""
    path = tmp_path / "spinning.coral"
    path.write_text(SPINNING, encoding="utf-8")

    def approve(
        mission: str | Path,
        certificate: str | Path | None = None,
        *,
        issue: bool = False,
        profiles: Sequence[VehicleProfile] = (),
        trusted: object = None,
        include_path: Sequence[str | Path] = (),
    ) -> gate.ApprovedMission:
        loaded = load_mission(Path(mission), profiles, include_path=include_path)
        return gate.ApprovedMission(loaded, hand_approval(loaded.net), False)

    monkeypatch.setattr(gate, "approve_mission", approve)
    return path


@pytest.mark.slow
def test_coral_run_ends_a_spin_as_a_failed_mission_with_plots(
    spinning: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The engine's real limit, the simulator in virtual time: exit 1, not 2."""
    out = tmp_path / "run"
    code = main([str(spinning), "--sim", "--out", str(out), "-q"])
    captured = capsys.readouterr()
    assert code == 1, captured
    ping, pong = line_of(SPINNING, "transition ping"), line_of(SPINNING, "transition pong")
    cycle = f"cycle ping ({spinning}:{ping}) -> pong ({spinning}:{pong}) -> ping"
    assert "mission ended: spin" in captured.out
    assert cycle in captured.out and cycle in captured.err
    assert "engine spin: more than 1000000 firings without waiting for the vehicle" in captured.err
    for png in ("events.png", "telemetry.png"):
        assert (out / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with EventLog.open(out / "controller.sqlite") as log:
        assert next(log.events("mission-end")).data["end"] == "spin"
        assert next(log.events("engine-spin")).data["cycle"] == ["ping", "pong"]
    assert (out / "vehicle.sqlite").exists()


# --------------------------------------------------------------------------- fuzz


@pytest.fixture
def quick_spin(monkeypatch: pytest.MonkeyPatch) -> None:
    """Fuzz's engines give up after 1,000 firings (the default million is slow to spin)."""
    monkeypatch.setattr(
        fuzz_one_run, "Engine", functools.partial(Engine, max_firings_per_step=1000)
    )


@pytest.mark.usefixtures("quick_spin")
def test_fuzz_counts_a_spin_as_a_failed_run_with_its_seed() -> None:
    net = compile_text(SPINNING)
    options = FuzzOptions(runs=3, seed=40, link=BUILTIN_PROFILES["lan"])
    report = fuzz(net, hand_approval(net), options)
    assert [r.seed for r in report.failures] == [40, 41, 42]
    assert {r.end for r in report.runs} == {RunEnd.SPIN}
    assert report.success_rate == 0.0
    text = format_report(report, "coral-run fuzz spinning.coral")
    assert "reached a declared final marking: 0/3" in text
    assert "seed 41: spin { ping_side } after" in text
    assert "cycle ping (test.coral:" in text
    assert "--replay 42" in text
    assert report.runs[0].to_json()["end"] == "spin"


@pytest.mark.usefixtures("quick_spin")
def test_coral_run_fuzz_reports_a_spin_and_goes_on(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    mission = tmp_path / "spinning.coral"
    mission.write_text(SPINNING, encoding="utf-8")
    out = tmp_path / "fuzz"
    argv = [str(mission), "--unverified", "--runs", "2", "--seed", "5", "-q"]
    code = fuzz_module.main([*argv, "--link", "lan", "--out", str(out), "--no-plot"])
    captured = capsys.readouterr()
    assert code == 1, captured
    assert "seed 5: spin" in captured.out and "seed 6: spin" in captured.out
    report = json.loads((out / "fuzz-report.json").read_text())
    assert [(r["seed"], r["end"], r["final"]) for r in report["runs"]] == [
        (5, "spin", False),
        (6, "spin", False),
    ]
    assert all("cycle ping" in r["detail"] for r in report["runs"])
    assert (out / "failures" / "seed-5.sqlite").exists()
    # The replay of a spinning run prints its events and the cycle.
    code = fuzz_module.main([str(mission), "--unverified", "--replay", "6", "--out", str(out)])
    assert code == 1
    replay = capsys.readouterr().out
    assert "engine-spin" in replay and "ended: spin" in replay and "cycle ping" in replay
