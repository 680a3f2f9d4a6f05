"""``coral-run``: help, the gate, exit codes, a whole run with its logs and plots."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from runtime.cli import build_run_parser, main
from runtime.eventlog import EventLog
from tests.runtime.helpers import POOL_MISSION

FAULTY = POOL_MISSION.parent.parent / "faulty" / "deadlock.coral"


def test_help_names_the_modes_and_exit_codes(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--help"]) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "exit codes: 0" in out and "'coral-run MISSION' is short for 'coral-run run" in out
    assert main(["run", "--help"]) == 0
    out = capsys.readouterr().out
    for word in ("--vehicle", "--sim", "--realtime", "--link", "--resume", "--verify"):
        assert word in out
    assert "exit codes: 0" in out
    assert build_run_parser().prog == "coral-run run"


def test_no_mission_is_a_usage_error(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--out", "x"]) == 2
    assert "coral-run run: error: give a MISSION to run, or --resume LOG" in (
        capsys.readouterr().err
    )
    assert main([]) == 2  # nothing at all: the usage line, which lists the commands
    assert "usage: coral-run [-h] [--version] {run,fuzz,watch,timeline,operate}" in (
        capsys.readouterr().err
    )


def test_bad_vehicle_address_is_a_usage_error(capsys: pytest.CaptureFixture[str]) -> None:
    assert main([str(POOL_MISSION), "--vehicle", "nowhere"]) == 2
    assert "expected HOST:PORT, got 'nowhere'" in capsys.readouterr().err


def test_a_mission_without_certificate_does_not_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code = main(
        [
            str(POOL_MISSION),
            "--certificate",
            str(tmp_path / "none.json"),
            "--out",
            str(tmp_path / "run"),
        ]
    )
    assert code == 2
    err = capsys.readouterr().err
    assert "no certificate" in err and "coral-check verify" in err
    assert not (tmp_path / "run" / "controller.sqlite").exists()


def test_a_mission_that_fails_verification_gets_no_certificate(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cert = tmp_path / "deadlock.json"
    code = main([str(FAULTY), "--verify", "--certificate", str(cert), "--out", str(tmp_path)])
    assert code == 2
    assert "deadlock violated" in capsys.readouterr().err
    assert not cert.exists()


def test_a_mission_that_does_not_compile_is_an_input_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bad = tmp_path / "bad.coral"
    bad.write_text("mission m\nvehicle ROMEO\nplace a = 1\ntransition t wait { b }\n")
    assert main([str(bad), "--verify", "--out", str(tmp_path / "run")]) == 2
    assert "bad.coral:4:" in capsys.readouterr().err


@pytest.mark.slow
def test_a_verified_run_completes_logs_and_plots(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cert = tmp_path / "pool.json"
    out = tmp_path / "run"
    code = main(
        [
            str(POOL_MISSION),
            "--verify",
            "--certificate",
            str(cert),
            "--out",
            str(out),
            "--link",
            "genoa-lisbon",
            "-q",
        ]
    )
    assert code == 0, capsys.readouterr()
    assert cert.exists()
    with EventLog.open(out / "controller.sqlite") as log:
        assert log.count("command-sent") == 23
        assert log.role == "controller"
    with EventLog.open(out / "vehicle.sqlite") as log:
        assert log.count("command-received") == 23
        assert sum(1 for _ in log.samples()) > 300
    for png in ("events.png", "telemetry.png"):
        assert (out / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # The certificate written is unsigned: without --verify a later run refuses it.
    assert "unsigned" in capsys.readouterr().out
    refused = main([str(POOL_MISSION), "--certificate", str(cert), "--out", str(tmp_path / "b")])
    assert refused == 2 and "is not signed" in capsys.readouterr().err
    assert not (tmp_path / "b" / "controller.sqlite").exists()
    # A second run into the same folder would mix two missions' logs: refused.
    again = [str(POOL_MISSION), "--verify", "--certificate", str(cert), "--out", str(out), "-q"]
    assert main(again) == 2
    assert "earlier run" in capsys.readouterr().err
    # The timeline subcommand reads the two logs back.
    assert (
        main(
            [
                "timeline",
                str(out / "controller.sqlite"),
                str(out / "vehicle.sqlite"),
                "--out",
                str(tmp_path / "plots"),
            ]
        )
        == 0
    )
    assert (tmp_path / "plots" / "events.png").exists()


def test_a_time_limit_ends_the_run_with_exit_1(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cert = tmp_path / "pool.json"
    code = main(
        [
            str(POOL_MISSION),
            "--verify",
            "--certificate",
            str(cert),
            "--out",
            str(tmp_path / "run"),
            "--time-limit",
            "20",
            "--no-plots",
            "-q",
        ]
    )
    assert code == 1
    assert "time-limit" in capsys.readouterr().out


def test_timeline_of_a_missing_log_is_an_input_error(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["timeline", str(tmp_path / "nope.sqlite")]) == 2
    assert "nope.sqlite" in capsys.readouterr().err


@pytest.mark.slow
def test_realtime_simulator_over_localhost_sockets(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cert = tmp_path / "pool.json"
    out = tmp_path / "run"
    code = main(
        [
            str(POOL_MISSION),
            "--verify",
            "--certificate",
            str(cert),
            "--out",
            str(out),
            "--sim",
            "--realtime",
            "--speed",
            "40",
            "--link",
            "lan",
            "--no-plots",
            "-q",
        ]
    )
    assert code == 0, capsys.readouterr()
    with EventLog.open(out / "controller.sqlite") as log:
        assert log.count("command-sent") == 23
        assert log.meta["realtime"] is True
        assert sum(1 for _ in log.samples()) > 50  # telemetry over real UDP


# -- --profile ----------------------------------------------------------------------------

SURVEY = POOL_MISSION.parent.parent / "survey_auv" / "survey.coral"
MINNOW = POOL_MISSION.parent.parent / "profiles" / "minnow.yaml"


def test_help_lists_the_profile_option(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["run", "--help"]) == 0
    assert "--profile YAML" in capsys.readouterr().out
    assert build_run_parser().parse_args(["m", "--profile", "a", "--profile", "b"]).profile == [
        Path("a"),
        Path("b"),
    ]


@pytest.mark.slow
def test_a_mission_for_a_vehicle_given_by_profile_runs_against_the_generic_vehicle(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cert = tmp_path / "survey.json"
    argv = [str(SURVEY), "--verify", "--certificate", str(cert), "--out", str(tmp_path / "run")]
    assert main([*argv, "--no-plots", "-q"]) == 2  # without its profile: does not compile
    assert "no vehicle profile for 'MINNOW'" in capsys.readouterr().err
    assert not cert.exists()
    assert main([*argv, "--no-plots", "-q", "--profile", str(MINNOW)]) == 0
    captured = capsys.readouterr()
    assert "no vehicle profile" not in captured.err
    assert "mission ended: final" in captured.out and "survey_complete" in captured.out
    assert f"certificate written to {cert}" in captured.out
    section = json.loads(cert.read_text())["profile"]
    assert section["vehicle"] == "MINNOW" and section["file"] == str(MINNOW)
    assert {"DEPTH?", "GPS_FIX?", "SURVEY_LINE"} <= set(section["commands"])


@pytest.mark.parametrize("resume", [False, True], ids=["run", "resume"])
def test_a_bad_profile_file_is_an_input_error_naming_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], resume: bool
) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("vehicle: X\ncommands:\n  A: {kind: task, replies: [ack], duration_s: -1}\n")
    where = ["--resume", str(tmp_path / "none.sqlite")] if resume else [str(POOL_MISSION)]
    code = main([*where, "--profile", str(bad), "--out", str(tmp_path / "run")])
    assert code == 2
    err = capsys.readouterr().err
    assert f"{bad}:3:" in err and "duration must be >= 0" in err
    assert "Traceback" not in err
    missing = tmp_path / "missing.yaml"
    assert main([str(POOL_MISSION), "--profile", str(missing), "--out", str(tmp_path)]) == 2
    assert f"{missing}: cannot read profile" in capsys.readouterr().err


@pytest.mark.slow
def test_include_path_lets_a_run_find_includes_elsewhere_and_is_recorded_for_resume(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The pool mission with its abort phase moved to a library folder: without
    --include-path it does not compile (exit 2); with it, it runs, and the log records
    the folder so that --resume compiles it the same way."""
    import shutil

    mission_dir, library = tmp_path / "mission", tmp_path / "library"
    mission_dir.mkdir()
    library.mkdir()
    for source in POOL_MISSION.parent.glob("*.coral"):
        shutil.copy(source, (library if source.name == "abort.coral" else mission_dir))
    mission = mission_dir / POOL_MISSION.name
    cert = tmp_path / "cert.json"
    common = [str(mission), "--verify", "--certificate", str(cert), "--no-plots", "-q"]
    assert main([*common, "--out", str(tmp_path / "without")]) == 2
    assert "abort.coral" in capsys.readouterr().err
    out = tmp_path / "run"
    assert main([*common, "--include-path", str(library), "--out", str(out)]) == 0
    with EventLog.open(out / "controller.sqlite") as log:
        assert log.meta["include_path"] == [str(library.resolve())]
    missing = tmp_path / "nowhere"
    assert main([*common, "--include-path", str(missing), "--out", str(tmp_path / "x")]) == 2
    assert f"{missing}: no such folder" in capsys.readouterr().err
