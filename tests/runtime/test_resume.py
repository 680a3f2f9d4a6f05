"""kill -9 the controller mid-mission, ``coral-run --resume``: no command lost or repeated.

Real processes, real localhost sockets: ``romeo-sim serve`` is the vehicle, ``coral-run``
the controller. The vehicle's watchdog is set long enough for the restart.
"""

from __future__ import annotations

import re
import signal
import subprocess
from collections import Counter
from pathlib import Path

import pytest

from runtime.eventlog import EventLog
from tests.conftest import REPO
from tests.runtime.helpers import BIN, POOL_MISSION, kill_9_at, sign_file, start_server, write_psk


def _start_vehicle(tmp: Path, key: Path) -> tuple[subprocess.Popen[str], str]:
    source = (REPO / "romeo_sim" / "romeo_vehicle.yaml").read_text()
    config = tmp / "vehicle.yaml"
    config.write_text(re.sub(r"(?m)^watchdog_s:.*$", "watchdog_s: 600.0", source))
    return start_server(
        [
            str(BIN / "romeo-sim"),
            "serve",
            "--key-file",
            str(key),
            "--port",
            "0",
            "--speed",
            "8",
            "--vehicle",
            str(config),
        ],
    )


@pytest.mark.slow
def test_kill_9_then_resume_loses_and_repeats_nothing(tmp_path: Path) -> None:
    key = write_psk(tmp_path)  # mode 0600: a key file others can read is refused
    certificate = tmp_path / "pool.certificate.json"
    out = tmp_path / "run"
    vehicle, address = _start_vehicle(tmp_path, key)
    common = [
        "--vehicle",
        address,
        "--key-file",
        str(key),
        "--certificate",
        str(certificate),
        "--no-plots",
        "--link",
        "lan",
    ]
    try:
        # Kill it in the way-point phase, while the vehicle works on query #13 (XY?).
        seen = kill_9_at(
            [str(BIN / "coral-run"), str(POOL_MISSION), "--verify", "--out", str(out), *common],
            r"t=\S+ #13 ",
            settle=0.5,
        )
        assert any(re.match(r"t=\S+ #13 reach_wp", line) for line in seen), "".join(seen)

        # The first run trusted its own verification and wrote the certificate unsigned;
        # resuming takes a signed one, as at sea.
        trusted = sign_file(certificate)
        second = subprocess.run(
            [
                str(BIN / "coral-run"),
                "--resume",
                str(out / "controller.sqlite"),
                *common,
                "--trusted-keys",
                str(trusted),
            ],
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert second.returncode == 0, second.stdout + second.stderr
        assert "resumed mission" not in second.stdout  # that is the vehicle's line
        assert "mission ended: final" in second.stdout
    finally:
        vehicle.send_signal(signal.SIGINT)
        _, vehicle_err = vehicle.communicate(timeout=30)

    with EventLog.open(out / "controller.sqlite") as log:
        sent = [e.data["command_id"] for e in log.events("command-sent")]
        replies = [e.data for e in log.events("reply")]
        assert log.count("resume") == 1
        end = list(log.events("mission-end"))[-1].data
    assert end["marking"] == {"mission_complete": 1}
    assert len(sent) == len(set(sent)) == 23
    assert Counter(r["command_id"] for r in replies) == Counter({i: 1 for i in sent})
    assert [r["reply_seq"] for r in replies] == list(range(1, 24))
    # The vehicle carried out 23 commands, each once; repeats were answered, not re-run.
    stats = re.search(r"(\d+) commands \((\d+) repeats\)", vehicle_err)
    assert stats, vehicle_err
    assert int(stats.group(1)) == 23
    assert int(stats.group(2)) >= 1  # query #13, in flight at the kill, was re-sent
