"""A second vehicle end to end, over real localhost sockets: MINNOW, by its profile alone.

``coral-vehicle serve --profile minnow.yaml`` is the vehicle (the generic simulated one,
served by the vehicle-side library), ``coral-run --profile minnow.yaml --vehicle
HOST:PORT`` the controller: verify, certificate, run to the final marking; a profile
edited after certification is refused; ``kill -9`` and ``--resume`` lose and repeat
nothing, as against ROMEO.
"""

from __future__ import annotations

import re
import signal
import subprocess
from collections import Counter
from collections.abc import Iterator
from pathlib import Path

import pytest

from runtime.eventlog import EventLog
from tests.conftest import EXAMPLES
from tests.runtime.helpers import BIN, kill_9_at, sign_file, start_server, write_psk

SURVEY = EXAMPLES / "survey_auv" / "survey.coral"
MINNOW = EXAMPLES / "profiles" / "minnow.yaml"
SPEED = 100.0
"""Vehicle seconds per wall second: the 20-minute survey in about 12 s."""


def _serve(tmp: Path, key: Path, *extra: str) -> tuple[subprocess.Popen[str], str]:
    settings = tmp / "generic.yaml"
    # A long watchdog (100 wall seconds at this speed) outlasts a controller's restart;
    # a small spread keeps each survey line inside its time-out.
    settings.write_text("watchdog_s: 10000\nvariation: 0.1\n")
    return start_server(
        [
            str(BIN / "coral-vehicle"),
            "serve",
            "--profile",
            str(MINNOW),
            "--key-file",
            str(key),
            "--speed",
            str(SPEED),
            "--sim-config",
            str(settings),
            "--log",
            str(tmp / "vehicle.sqlite"),
            *extra,
        ],
        listening=r"127\.0\.0\.1:\d+",
    )


def _stop(vehicle: subprocess.Popen[str]) -> str:
    vehicle.send_signal(signal.SIGINT)
    _, err = vehicle.communicate(timeout=30)
    return err


@pytest.fixture
def key(tmp_path: Path) -> Path:
    return write_psk(tmp_path)  # mode 0600: a key file others can read is refused


@pytest.fixture
def served(tmp_path: Path, key: Path) -> Iterator[tuple[str, list[str]]]:
    """A served MINNOW and the coral-run options that reach it; the vehicle's stderr is
    appended to the list when it stops."""
    vehicle, address = _serve(tmp_path, key)
    stderr: list[str] = []
    try:
        yield address, stderr
    finally:
        stderr.append(_stop(vehicle))


def _coral_run(*argv: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [str(BIN / "coral-run"), *argv], capture_output=True, text=True, timeout=timeout
    )


@pytest.mark.slow
def test_minnow_verify_certify_run_over_localhost_sockets(
    tmp_path: Path, key: Path, served: tuple[str, list[str]]
) -> None:
    address, _ = served
    certificate = tmp_path / "survey.certificate.json"
    out = tmp_path / "run"
    done = _coral_run(
        str(SURVEY),
        "--profile",
        str(MINNOW),
        "--verify",
        "--certificate",
        str(certificate),
        "--vehicle",
        address,
        "--key-file",
        str(key),
        "--link",
        "lan",
        "--no-plots",
        "--out",
        str(out),
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert "verified; certificate written" in done.stdout
    assert "mission ended: final" in done.stdout
    with EventLog.open(out / "controller.sqlite") as log:
        end = list(log.events("mission-end"))[-1].data
        sent = [e.data["name"] for e in log.events("command-sent")]
    assert end["marking"] == {"survey_complete": 1}
    assert sent == [
        "INIT",
        "GPS_FIX?",
        "DIVE",
        "DEPTH?",
        "SURVEY_LINE",
        "LINE_END?",
        "SURVEY_LINE",
        "LINE_END?",
        "SURFACE",
        "SURFACE?",
        "GPS_FIX?",
    ]

    # The profile edited after certification: refused before anything is sent, naming
    # what changed.
    edited = tmp_path / "minnow-edited.yaml"
    edited.write_text(
        MINNOW.read_text().replace("duration_s: 500.0", "duration_s: 900.0"), encoding="utf-8"
    )
    refused = _coral_run(
        str(SURVEY),
        "--trusted-keys",
        str(sign_file(certificate)),
        "--profile",
        str(edited),
        "--certificate",
        str(certificate),
        "--vehicle",
        address,
        "--key-file",
        str(key),
        "--out",
        str(tmp_path / "refused"),
    )
    assert refused.returncode == 2, refused.stdout + refused.stderr
    assert "LINE_END?.duration_s 500 -> 900" in refused.stderr
    assert not (tmp_path / "refused" / "controller.sqlite").exists()


@pytest.mark.slow
def test_kill_9_then_resume_against_the_generic_served_vehicle(tmp_path: Path, key: Path) -> None:
    vehicle, address = _serve(tmp_path, key)
    certificate = tmp_path / "survey.certificate.json"
    out = tmp_path / "run"
    common = [
        "--profile",
        str(MINNOW),
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
        # Kill it during the first survey line, while the vehicle works on LINE_END? (#6).
        seen = kill_9_at(
            [str(BIN / "coral-run"), str(SURVEY), "--verify", "--out", str(out), *common],
            r"t=\S+ #6 ",
            settle=0.3,
        )
        assert any(re.match(r"t=\S+ #6 end_line1", line) for line in seen), "".join(seen)

        # No --profile now: the log recorded the profile file the run was compiled with.
        trusted = sign_file(certificate)  # the first run wrote it unsigned (--verify)
        second = _coral_run(
            "--resume",
            str(out / "controller.sqlite"),
            *common[2:],
            "--trusted-keys",
            str(trusted),
            timeout=180,
        )
        assert second.returncode == 0, second.stdout + second.stderr
        assert "mission ended: final" in second.stdout
    finally:
        vehicle_err = _stop(vehicle)

    with EventLog.open(out / "controller.sqlite") as log:
        sent = [e.data["command_id"] for e in log.events("command-sent")]
        replies = [e.data for e in log.events("reply")]
        assert log.count("resume") == 1
        end = list(log.events("mission-end"))[-1].data
    assert end["marking"] == {"survey_complete": 1}
    assert len(sent) == len(set(sent)) == 11
    assert Counter(r["command_id"] for r in replies) == Counter({i: 1 for i in sent})
    assert [r["reply_seq"] for r in replies] == list(range(1, 12))
    # The vehicle carried out 11 commands, each once; the re-sent one was answered.
    stats = re.search(r"(\d+) commands \((\d+) repeats\)", vehicle_err)
    assert stats, vehicle_err
    assert int(stats.group(1)) == 11
    assert int(stats.group(2)) >= 1  # LINE_END? #6, in flight at the kill, was re-sent


@pytest.mark.slow
def test_coral_vehicle_refuses_bad_input_without_a_traceback(tmp_path: Path, key: Path) -> None:
    base = [str(BIN / "coral-vehicle"), "serve", "--key-file", str(key)]
    cases = {
        "unknown command": (
            [*base, "--profile", str(MINNOW), "--fault", "DIVER=error"],
            "did you mean 'DIVE'",
        ),
        "kind not a reply": (
            [*base, "--profile", str(MINNOW), "--fault", "DIVE=timeout"],
            "DIVE",
        ),
        "bad syntax": ([*base, "--profile", str(MINNOW), "--fault", "DIVE"], "--fault 'DIVE'"),
        "no simulator": (
            [*base, "--profile", str(MINNOW), "--simulator", "romoe"],
            "did you mean 'romeo'",
        ),
        "romeo cannot fly minnow": (
            [*base, "--profile", str(MINNOW), "--simulator", "romeo"],
            "simulator 'romeo'",
        ),
        "no key": (
            [str(BIN / "coral-vehicle"), "serve", "--profile", str(MINNOW)],
            "pre-shared key",
        ),
        "missing profile": ([*base, "--profile", str(tmp_path / "none.yaml")], "none.yaml"),
    }
    for what, (argv, expected) in cases.items():
        done = subprocess.run(argv, capture_output=True, text=True, timeout=60)
        assert done.returncode == 2, (what, done.stderr)
        assert expected in done.stderr, (what, done.stderr)
        assert "Traceback" not in done.stderr, what
    listed = subprocess.run(
        [str(BIN / "coral-vehicle"), "list"], capture_output=True, text=True, timeout=60
    )
    assert listed.returncode == 0
    assert re.search(r"(?m)^generic\s", listed.stdout) and re.search(r"(?m)^romeo\s", listed.stdout)
