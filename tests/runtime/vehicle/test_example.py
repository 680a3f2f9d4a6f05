"""The integrator's example: MINNOW on fake hardware runs the survey mission end to end.

``examples/vehicles/minnow_vehicle.py`` is served by the real `VehicleServer`; the real
controller and engine run ``examples/survey_auv/survey.coral`` (verified) against it,
once over localhost sockets (a faster-than-life fake, a few wall seconds) and once under
virtual time (life-size, about a second of CPU). ``docs/vehicles.md`` shows the
example's code, which must be the file's.
"""

from __future__ import annotations

import asyncio
import importlib.util
import os
import random
import re
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from types import ModuleType

import pytest

from analysis.certificate import CertificateCheck
from coral_lang.compiler import compile_mission
from coral_lang.net import Net
from coral_lang.profile import load_profile
from runtime.controller import Controller, ControllerOptions, RunEnd, RunResult
from runtime.engine import Engine
from runtime.eventlog import EventLog
from runtime.link import Link, MemoryLink, SocketLink
from runtime.vclock import run_virtual
from runtime.vehicle import HandlerVehicle, Reply, VehicleServer
from tests.conftest import EXAMPLES, REPO
from tests.runtime.helpers import approve

PSK = bytes(range(32))
EXAMPLE = EXAMPLES / "vehicles" / "minnow_vehicle.py"
DOC = REPO / "docs" / "vehicles.md"


@pytest.fixture(scope="module")
def example() -> ModuleType:
    spec = importlib.util.spec_from_file_location("minnow_vehicle", EXAMPLE)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def survey(tmp_path_factory: pytest.TempPathFactory) -> tuple[Net, CertificateCheck]:
    minnow = load_profile(EXAMPLES / "profiles" / "minnow.yaml")
    net = compile_mission(EXAMPLES / "survey_auv" / "survey.coral", [minnow])
    return net, approve(net, tmp_path_factory.mktemp("survey"), minnow)


def build(example: ModuleType, warp: float = 1.0) -> HandlerVehicle:
    factory: Callable[[float], HandlerVehicle] = example.build_vehicle
    return factory(warp)


# ---------------------------------------------------------------------- the doc


def test_the_doc_shows_the_example_verbatim() -> None:
    blocks = re.findall(r"```python\n(.*?)```", DOC.read_text(), re.S)
    assert EXAMPLE.read_text() in blocks


def test_the_docs_unit_test_snippet_runs(example: ModuleType) -> None:
    blocks = re.findall(r"```python\n(.*?)```", DOC.read_text(), re.S)
    (snippet,) = [b for b in blocks if b.startswith("vehicle = build_vehicle()")]
    exec(snippet, {"build_vehicle": example.build_vehicle})


# ---------------------------------------------------------------------- the mission


async def _fly(
    net: Net,
    approval: CertificateCheck,
    link: Link,
    log_path: Path,
    *,
    time_limit: float,
) -> RunResult:
    loop = asyncio.get_running_loop()
    rng = random.Random(3)
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
            options=ControllerOptions(time_limit=time_limit),
        )
        return await controller.run()
    finally:
        log.close()
        await link.aclose()


def _commands(log_path: Path) -> list[tuple[str, str]]:
    """(command name, reply kind) in the order the controller consumed the replies."""
    with EventLog.open(log_path) as log:
        names = {e.data["command_id"]: e.data["name"] for e in log.events(["command-sent"])}
        return [
            (str(names[e.data["command_id"]]), str(e.data["kind"])) for e in log.events(["reply"])
        ]


SURVEY = [
    ("INIT", "done"),
    ("GPS_FIX?", "done"),
    ("DIVE", "ack"),
    ("DEPTH?", "done"),
    ("SURVEY_LINE", "ack"),
    ("LINE_END?", "done"),
    ("SURVEY_LINE", "ack"),
    ("LINE_END?", "done"),
    ("SURFACE", "ack"),
    ("SURFACE?", "done"),
    ("GPS_FIX?", "done"),
]


@pytest.mark.slow
def test_minnow_flies_the_survey_over_localhost_sockets(
    example: ModuleType, survey: tuple[Net, CertificateCheck], tmp_path: Path
) -> None:
    net, approval = survey

    async def scenario() -> tuple[RunResult, VehicleServer]:
        # 20x faster-than-life hardware at 50x: about 75 vehicle s in 1.5 wall s.
        server = VehicleServer(
            build(example, warp=20.0), PSK, speed=50.0, tick=0.01, log=lambda _: None
        )
        host, port = await server.start()
        try:
            result = await _fly(
                net, approval, SocketLink(host, port), tmp_path / "c.sqlite", time_limit=20.0
            )
        finally:
            await server.stop()
        return result, server

    started = time.perf_counter()
    result, server = asyncio.run(asyncio.wait_for(scenario(), 30.0))
    assert time.perf_counter() - started < 5.0
    assert result.end is RunEnd.FINAL, result.summary()
    assert result.marking == {"survey_complete": 1}
    assert _commands(tmp_path / "c.sqlite") == SURVEY
    assert server.stats.commands == 11 and server.stats.rejected == 0
    assert result.telemetry > 20


@pytest.mark.slow
def test_minnow_flies_the_survey_life_size_under_virtual_time(
    example: ModuleType, survey: tuple[Net, CertificateCheck], tmp_path: Path
) -> None:
    net, approval = survey
    vehicle = build(example)

    async def scenario() -> RunResult:
        loop = asyncio.get_running_loop()
        server = VehicleServer(
            vehicle,
            PSK,
            clock=loop.time,
            speed=20.0,
            nonces=random.Random(1).randbytes,
            log=lambda _: None,
        )
        try:
            return await _fly(
                net, approval, MemoryLink(server), tmp_path / "c.sqlite", time_limit=3600.0
            )
        finally:
            await server.stop()

    result = run_virtual(scenario(), timeout=600)
    assert result.end is RunEnd.FINAL and result.marking == {"survey_complete": 1}
    assert _commands(tmp_path / "c.sqlite") == SURVEY
    # Life-size: two lines of 566 m and 401 m at 1 m/s, a 15-m dive and climb at 0.5 m/s.
    assert 1000.0 < vehicle.time < 1100.0
    assert [e.text for e in vehicle.events] == [
        "SURVEY_LINE stopped: replaced by SURVEY_LINE",
        "DIVE stopped: replaced by SURFACE",
        "SURVEY_LINE stopped: replaced by SURFACE",
    ]
    pose = vehicle.telemetry()
    assert pose is not None and (pose.x, pose.y, pose.z) == pytest.approx((430.0, 0.0, 0.0))


# ---------------------------------------------------------------------- the fake's refusals


def test_the_fake_refuses_what_the_real_vehicle_would(example: ModuleType) -> None:
    vehicle = build(example)
    line = {"x0": 0.0, "y0": 0.0, "x1": 0.0, "y1": 100.0, "speed": 1.0}
    assert vehicle.command(1, "SURVEY_LINE", line) == [
        Reply(1, "SURVEY_LINE", "error", 0.0, "no position estimate: get a GPS fix first")
    ]
    vehicle.command(2, "DIVE", {"z": 5.0})
    vehicle.advance_to(2.0)
    vehicle.command(3, "GPS_FIX?", {"max_hdop": 2.0, "time_out": 60.0})
    assert vehicle.advance_to(2.1) == [
        Reply(3, "GPS_FIX?", "error", 2.1, "the antenna is under water")
    ]


def test_the_watchdog_surfaces_the_fake(example: ModuleType) -> None:
    vehicle = build(example)
    vehicle.command(1, "DIVE", {"z": 10.0})
    vehicle.advance_to(29.0)
    pose = vehicle.telemetry()
    assert pose is not None and pose.z == pytest.approx(10.0)
    vehicle.advance_to(60.0)  # silence since 0 s: the watchdog trips at 30 s
    pose = vehicle.telemetry()
    assert pose is not None and pose.z == pytest.approx(0.0)


# ---------------------------------------------------------------------- main


def test_main_without_a_key_says_how_to_make_one(
    example: ModuleType, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.delenv("CORAL_KEY_FILE", raising=False)
    assert example.main([]) == 2
    err = capsys.readouterr().err
    assert err.startswith("minnow_vehicle: MINNOW needs a pre-shared key")
    assert "Traceback" not in err


def test_main_serves_until_interrupted(tmp_path: Path) -> None:
    key = tmp_path / "psk.hex"
    key.write_text(PSK.hex())
    key.chmod(0o600)  # a key file others can read is refused
    env = {**os.environ, "CORAL_KEY_FILE": str(key), "PYTHONPATH": str(REPO)}
    proc = subprocess.Popen(
        [sys.executable, str(EXAMPLE), "--speed", "10"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        cwd=tmp_path,
    )
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        assert re.fullmatch(r"listening on 127\.0\.0\.1:\d+\n", line), line
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=5.0)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, err
    assert "stopped (Ctrl-C)" in err and "Traceback" not in err
