"""Telemetry from a vehicle on another address reaches ``coral-run`` (``--telemetry-host``).

The vehicle sends its telemetry to the address its controller connects from. The
controller used to bind its telemetry socket to 127.0.0.1 whatever the vehicle's network,
so a vehicle elsewhere was never heard. Here ``coral-vehicle serve`` listens on 127.0.0.2
(Linux routes all of 127/8 to the loopback interface) with its own ``--log``, and a real
``coral-run --vehicle 127.0.0.2:PORT`` runs a short dive against it; the controller's log
must hold telemetry samples, and the vehicle's log must pair with it by mission id.
"""

from __future__ import annotations

import re
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from runtime.eventlog import EventLog, log_key
from runtime.keys import write_key_file

BIN = Path(sys.executable).parent
DIVE = """\
mission dive
vehicle ROMEO
place start = 1, diving, down, aborted
final { down }
final { aborted }
transition dive wait { start } action { ROMEO(DEPTH, z = 1.0 m) -> { ack: diving, error: aborted } }
transition check wait { diving }
    action { ROMEO(DEPTH?, z = 1.0 m, time_out = 60 s) -> { done: down, timeout: aborted } }
"""


def _can_bind(host: str) -> bool:
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            probe.bind((host, 0))
    except OSError:
        return False
    return True


pytestmark = pytest.mark.skipif(
    not (_can_bind("127.0.0.2") and _can_bind("127.0.0.3")),
    reason="needs 127.0.0.2 and 127.0.0.3 on the loopback interface (Linux)",
)


@pytest.mark.slow
@pytest.mark.parametrize("telemetry_host", [None, "127.0.0.3"], ids=["default", "given"])
def test_coral_run_hears_a_vehicle_served_on_another_address(
    tmp_path: Path, telemetry_host: str | None
) -> None:
    key = tmp_path / "psk.hex"
    psk = bytes(range(7, 39))
    write_key_file(key, psk)
    mission = tmp_path / "dive.coral"
    mission.write_text(DIVE)
    vehicle_log = tmp_path / "vehicle.sqlite"
    vehicle = subprocess.Popen(
        [
            *(str(BIN / "coral-vehicle"), "serve", "--vehicle", "ROMEO", "--host", "127.0.0.2"),
            *("--key-file", str(key), "--speed", "20", "--log", str(vehicle_log)),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert vehicle.stdout is not None
        line = vehicle.stdout.readline()
        match = re.match(r"listening on (127\.0\.0\.2:\d+)", line)
        assert match, line
        extra = [] if telemetry_host is None else ["--telemetry-host", telemetry_host]
        run = subprocess.run(
            [
                *(str(BIN / "coral-run"), str(mission), "--verify", "--vehicle", match.group(1)),
                *("--key-file", str(key), "--out", str(tmp_path / "run"), "--no-plots"),
                *extra,
            ],
            capture_output=True,
            text=True,
            timeout=60,
        )
    finally:
        vehicle.send_signal(signal.SIGINT)
        _, vehicle_err = vehicle.communicate(timeout=15)
    assert run.returncode == 0, run.stdout + run.stderr
    with EventLog.open(tmp_path / "run" / "controller.sqlite") as log:
        samples = list(log.samples())
        (start,) = [event.data for event in log.events(["mission-start"])]
    assert len(samples) >= 3, (run.stdout, vehicle_err)
    with EventLog.open(vehicle_log, mac_key=log_key(psk)) as log:
        assert log.mission == str(start["mission_id"])
        (adopt,) = [event.data for event in log.events(["adopt"])]
    if telemetry_host is not None:  # the control connection leaves from it too
        assert str(adopt["peer"]).startswith(f"{telemetry_host}:"), adopt


@pytest.mark.parametrize(
    ("address", "message"),
    [
        ("vehicle-lan", "expected an IP address, got 'vehicle-lan'"),
        ("203.0.113.254", "203.0.113.254 is not an address of this machine"),  # TEST-NET-3
    ],
)
def test_a_telemetry_host_this_machine_cannot_bind_is_a_usage_error(
    capsys: pytest.CaptureFixture[str], address: str, message: str
) -> None:
    from runtime.cli import main

    assert main(["dive.coral", "--vehicle", "127.0.0.2:1", "--telemetry-host", address]) == 2
    assert message in capsys.readouterr().err
