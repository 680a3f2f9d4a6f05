"""SIGTERM and Ctrl-C end a run cleanly and tell the vehicle to make itself safe.

Real processes over localhost sockets: ``coral-vehicle serve`` is MINNOW (the generic
simulated vehicle at 100x), ``coral-run`` the controller. SIGTERM in the middle of the
first survey line: exit 143, one message (signal, mission time, the vehicle's
acknowledgement, the logs, the ``--resume`` command), the vehicle's make-safe in its
log; then ``--resume`` consumes the stopped query's ``timeout`` and ends in the abort
path's declared final marking, no command carried out twice. And in virtual time, a
real SIGINT stops the simulated run the same way.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
from pathlib import Path

import pytest

from runtime.controller import RunEnd
from runtime.eventlog import EventLog
from tests.conftest import EXAMPLES
from tests.runtime.helpers import BIN, sign_file, start_server, write_psk

SURVEY = EXAMPLES / "survey_auv" / "survey.coral"
MINNOW = EXAMPLES / "profiles" / "minnow.yaml"


def _serve(tmp: Path, key: Path) -> tuple[subprocess.Popen[str], str]:
    settings = tmp / "generic.yaml"
    settings.write_text("watchdog_s: 10000\nvariation: 0.1\n")  # outlasts the restart
    return start_server(
        [
            str(BIN / "coral-vehicle"),
            "serve",
            "--profile",
            str(MINNOW),
            "--key-file",
            str(key),
            "--speed",
            "100",
            "--sim-config",
            str(settings),
        ],
    )


def _signal_at(argv: list[str], line: str, sig: signal.Signals) -> tuple[int, str, str]:
    """Run ``argv`` until a stdout line matches ``line``, send ``sig``; exit code, output."""
    process = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert process.stdout is not None
    seen = []
    for text in process.stdout:
        seen.append(text)
        if re.match(line, text):
            process.send_signal(sig)
            break
    out, err = process.communicate(timeout=60)
    return process.returncode, "".join(seen) + out, err


@pytest.mark.slow
def test_sigterm_makes_the_vehicle_safe_and_resume_takes_the_error_path(tmp_path: Path) -> None:
    key = write_psk(tmp_path)
    certificate = tmp_path / "survey.certificate.json"
    out = tmp_path / "run"
    vehicle, address = _serve(tmp_path, key)
    common = ["--profile", str(MINNOW), "--vehicle", address, "--key-file", str(key)]
    common += ["--certificate", str(certificate), "--link", "lan"]
    try:
        # Stop while the vehicle runs the first survey line (#6 LINE_END? pending).
        code, stdout, stderr = _signal_at(
            [str(BIN / "coral-run"), str(SURVEY), "--verify", "--out", str(out), *common],
            r"t=\S+ #6 end_line1",
            signal.SIGTERM,
        )
        assert code == 143, stdout + stderr
        assert "Traceback" not in stderr
        (message,) = [line for line in stderr.splitlines() if "stopped by SIGTERM" in line]
        assert re.search(r"at mission time \d+\.\d s", message), message
        assert "the vehicle acknowledged the make-safe request" in message
        assert f"logs in {out}/" in message
        assert f"coral-run --resume {out / 'controller.sqlite'}" in message
        assert "mission ended: stopped" in stdout
        assert re.search(r"coral-run: wrote \S+", stdout), stdout  # plots, as after a run

        trusted = sign_file(certificate)  # the first run's certificate was unsigned
        second = subprocess.run(
            [
                str(BIN / "coral-run"),
                "--resume",
                str(out / "controller.sqlite"),
                *common,
                "--trusted-keys",
                str(trusted),
                "--no-plots",
            ],
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert second.returncode == 0, second.stdout + second.stderr
        assert re.search(r"#6 replied timeout \(.*make itself safe", second.stdout)
        assert "mission ended: final" in second.stdout
    finally:
        vehicle.send_signal(signal.SIGINT)
        _, vehicle_err = vehicle.communicate(timeout=30)

    assert "asked the vehicle to make itself safe (SIGTERM)" in vehicle_err
    with EventLog.open(out / "controller.sqlite") as log:
        sent = [e.data["command_id"] for e in log.events("command-sent")]
        replies = [e.data["reply_seq"] for e in log.events("reply")]
        ends = [e.data for e in log.events("mission-end")]
        assert log.count("make-safe-acked") == 1
    assert [e["end"] for e in ends] == ["stopped", "final"]
    assert ends[-1]["marking"] == {"aborted_at_surface": 1}
    assert len(sent) == len(set(sent)) and replies == list(range(1, len(replies) + 1))
    stats = re.search(r"(\d+) commands \((\d+) repeats\)", vehicle_err)
    assert stats, vehicle_err
    assert int(stats.group(1)) == len(sent)  # each command carried out once


def test_ctrl_c_stops_a_virtual_time_run_cleanly(tmp_path: Path) -> None:
    """A real SIGINT, sent from inside the run when command #6 goes out, under virtual time."""
    from coral_lang.profile import load_profile
    from runtime.gate import approve_mission
    from runtime.run import RunConfig, run_mission

    profile = load_profile(MINNOW)
    approved = approve_mission(SURVEY, tmp_path / "cert.json", issue=True, profiles=[profile])
    lines: list[str] = []

    def console(line: str) -> None:
        lines.append(line)
        if re.match(r"t=\S+ #6 end_line1", line):
            os.kill(os.getpid(), signal.SIGINT)

    config = RunConfig(out_dir=tmp_path / "run", psk=os.urandom(32), console=console)
    result = run_mission(approved, config)
    assert result.end is RunEnd.STOPPED and result.stopped_by == "SIGINT"
    assert result.made_safe is True
    assert any("stopping (SIGINT)" in line for line in lines)
    assert not any("#7 " in line for line in lines)  # nothing new after the signal
    # The handlers are put back: a Ctrl-C after the run is Python's again.
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    with EventLog.open(tmp_path / "run" / "vehicle.sqlite") as vlog:
        assert vlog.count("make-safe") == 1


def test_the_exit_codes_are_in_the_help() -> None:
    from runtime.cli import EXIT_SIGINT, EXIT_SIGTERM, build_run_parser

    assert (EXIT_SIGINT, EXIT_SIGTERM) == (130, 143)
    epilog = build_run_parser().epilog or ""
    assert "130 stopped by Ctrl-C (SIGINT)" in epilog and "143 stopped by SIGTERM" in epilog


@pytest.mark.parametrize(("sig", "code"), [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_a_signal_outside_the_run_ends_with_its_code_and_a_message(
    sig: signal.Signals,
    code: int,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """While compiling or verifying (no loop yet), SIGTERM too ends with a message."""
    import runtime.cli as cli

    def signalled(options: object) -> int:
        signal.raise_signal(sig)
        raise AssertionError("the signal should have ended the run")

    before = signal.getsignal(signal.SIGTERM)
    monkeypatch.setattr(cli, "_run", signalled)
    assert cli.main([str(SURVEY), "--out", "somewhere"]) == code
    err = capsys.readouterr().err
    assert f"interrupted by {sig.name}" in err and "Traceback" not in err
    assert "coral-run --resume somewhere/controller.sqlite" in err
    assert signal.getsignal(signal.SIGTERM) is before  # put back
