"""``coral-run fuzz``: replays, the report files, the gate, bad input, and the CLI frame."""

from __future__ import annotations

import io
import json
from pathlib import Path

import pytest

from coral_lang.cliframe import command_parser, run_main, subcommands
from runtime import fuzz as fuzz_module
from tests.conftest import EXAMPLES, session_signing_key
from tests.runtime.fuzz.common import POOL, RACY, cli
from tests.runtime.test_racy import HOSTILE_RACE_SEED, RACE_MARKINGS


def test_a_failure_replays_exactly_with_its_seed(
    tmp_path: Path, heading_90: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Fuzz finds the race; ``--replay SEED`` and ``--runs 1 --seed SEED`` give the same run."""
    base = ["--unverified", "--link", "hostile", "--vehicle-config", str(heading_90), "-q"]
    code, out, err = cli(
        [
            RACY,
            *base,
            "--runs",
            "4",
            "--seed",
            str(HOSTILE_RACE_SEED - 2),
            "--out",
            str(tmp_path / "a"),
        ],
        capsys,
    )
    assert code == 1, out + err
    assert "WARNING" in err and "NOT verified" in err
    assert f"seed {HOSTILE_RACE_SEED}: deadlock" in out
    assert "a deadlock analysis predicts" in out
    assert f"--replay {HOSTILE_RACE_SEED}" in out
    assert (tmp_path / "a" / "failures" / f"seed-{HOSTILE_RACE_SEED}.sqlite").exists()
    report = json.loads((tmp_path / "a" / "fuzz-report.json").read_text())
    failed = next(r for r in report["runs"] if r["seed"] == HOSTILE_RACE_SEED)
    assert failed["end"] == "deadlock" and failed["marking"] in RACE_MARKINGS

    code, out, _ = cli(
        [RACY, *base, "--replay", str(HOSTILE_RACE_SEED), "--out", str(tmp_path / "b")], capsys
    )
    assert code == 1
    assert failed["events_digest"] in out
    assert "depth_never_acked" in out  # the replay prints the events
    assert (tmp_path / "b" / f"replay-seed-{HOSTILE_RACE_SEED}.sqlite").exists()

    code, out, _ = cli(
        [
            RACY,
            *base,
            "--runs",
            "1",
            "--seed",
            str(HOSTILE_RACE_SEED),
            "--out",
            str(tmp_path / "c"),
        ],
        capsys,
    )
    assert code == 1
    again = json.loads((tmp_path / "c" / "fuzz-report.json").read_text())["runs"][0]
    assert again["events_digest"] == failed["events_digest"]


@pytest.mark.slow
def test_a_verified_mission_that_always_ends_well_exits_0(
    tmp_path: Path, pool_certificate: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, err = cli(
        [
            POOL,
            "--certificate",
            str(pool_certificate),
            "--trusted-keys",
            str(session_signing_key().public),
            "--runs",
            "2",
            "--out",
            str(tmp_path),
        ],
        capsys,
    )
    assert code == 0, out + err
    assert "WARNING" not in err
    assert "reached a declared final marking: 2/2 (100.0 %)" in out
    assert "final { mission_complete }" in out
    assert "mission time (virtual): median" in out and "p90" in out
    assert "schedules/s" in out
    assert (tmp_path / "fuzz-histogram.png").stat().st_size > 1000
    report = json.loads((tmp_path / "fuzz-report.json").read_text())
    assert report["success_rate"] == 1.0 and len(report["runs"]) == 2
    assert not (tmp_path / "failures").exists()
    assert "coverage: exercised" in out
    assert 0 < report["coverage"]["exercised"] < report["coverage"]["transitions"]


def test_an_unverified_mission_needs_unverified(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, _, err = cli([RACY, "--runs", "1", "--out", str(tmp_path)], capsys)
    assert code == 2
    assert "--unverified" in err and "Traceback" not in err
    assert not (tmp_path / "fuzz-report.json").exists()


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["missing.coral", "--unverified"], "file not found"),
        ([RACY, "--unverified", "--link", "hostlie"], "did you mean"),
        ([RACY, "--unverified", "--vehicle-config", "BAD"], "BAD"),
    ],
)
def test_bad_input_exits_2_with_a_message(
    tmp_path: Path, argv: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    code, _, err = cli([*argv, "--out", str(tmp_path)], capsys)
    assert code == 2
    assert message in err and "Traceback" not in err


def test_a_bad_vehicle_file_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("initial:\n  psi_deg: north\n", encoding="utf-8")
    code, _, err = cli([RACY, "--unverified", "--vehicle-config", str(bad)], capsys)
    assert code == 2 and "psi_deg" in err and "Traceback" not in err


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--runs", "0"], "argument --runs: must be at least 1"),
        (["--seed", "-1"], "argument --seed: a seed is 0 .. 2**63-1, got -1"),
        (["--time-limit", "inf"], "argument --time-limit: not a finite number: 'inf'"),
        (["--vary-replies", "1.5"], "argument --vary-replies: must be a probability in [0, 1]"),
    ],
)
def test_bad_numbers_are_usage_errors(
    argv: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert fuzz_module.main([RACY, *argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith("usage: coral-run fuzz") and message in err
    assert "Traceback" not in err


def test_the_arguments_fit_a_subcommand_of_another_parser(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """What ``coral-run`` does: a ``fuzz`` subparser filled by `add_fuzz_arguments`,
    dispatched to `run_fuzz`; abbreviations stay off there too."""
    top = command_parser("coral-run", "run missions")
    sub = subcommands(top).add_parser("fuzz", prog="coral-run fuzz")
    fuzz_module.add_fuzz_arguments(sub)

    def run(argv: list[str]) -> int:
        return run_main(top, argv, lambda args: fuzz_module.run_fuzz(args, stderr=io.StringIO()))

    assert run(["fuzz", RACY, "--vehicle", "10.0.0.1:5000"]) == 2
    assert "unrecognized arguments: --vehicle" in capsys.readouterr().err
    assert run(["fuzz", "--version"]) == 0
    assert capsys.readouterr().out.startswith("coral-run fuzz (coral ")
    argv = ["fuzz", POOL, "--unverified", "--runs", "1", "--link", "lan", "-q", "--no-plot"]
    assert run([*argv, "--out", str(tmp_path)]) == 0
    assert json.loads((tmp_path / "fuzz-report.json").read_text())["success_rate"] == 1.0


def test_version_and_help_exit_0(capsys: pytest.CaptureFixture[str]) -> None:
    assert fuzz_module.main(["--version"]) == 0
    assert capsys.readouterr().out.startswith("coral-run fuzz (coral ")
    assert fuzz_module.main(["--help"]) == 0
    assert "--vary-replies" in capsys.readouterr().out


def test_errors_go_to_the_stream_given(tmp_path: Path) -> None:
    err = io.StringIO()
    code = fuzz_module.main(["missing.coral", "--out", str(tmp_path)], stderr=err)
    assert code == 2
    assert (
        err.getvalue().startswith("coral-run fuzz: error: ") and "file not found" in err.getvalue()
    )


@pytest.mark.slow  # 24 runs of a long survey: 20 to 40 s on 2 shared cores
def test_reply_fuzzing_a_second_vehicle_exercises_more_of_its_net(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """MINNOW by its profile, against the generic vehicle: a healthy vehicle flies the
    main path only; with --vary-replies the abort paths run too, each to a declared
    final marking (the survey mission is verified: any reply is handled)."""
    survey = EXAMPLES / "survey_auv" / "survey.coral"
    minnow = EXAMPLES / "profiles" / "minnow.yaml"
    base = [str(survey), "--profile", str(minnow), "--unverified", "-q", "--no-plot"]
    base += ["--runs", "12", "--link", "lan"]
    healthy_out, varied_out = tmp_path / "healthy", tmp_path / "varied"
    assert cli([*base, "--out", str(healthy_out)], capsys)[0] == 0
    code, out, _ = cli([*base, "--vary-replies", "0.3", "--out", str(varied_out)], capsys)
    assert code == 0, out
    healthy = json.loads((healthy_out / "fuzz-report.json").read_text())
    varied = json.loads((varied_out / "fuzz-report.json").read_text())
    assert {r["end"] for r in varied["runs"]} == {"final"}
    assert {tuple(r["marking"]) for r in healthy["runs"]} == {("survey_complete",)}
    assert len({tuple(r["marking"]) for r in varied["runs"]}) >= 2
    assert varied["coverage"]["exercised"] > healthy["coverage"]["exercised"]
    never = {n["transition"] for n in healthy["coverage"]["never"]}
    assert {"first_fix.timeout", "end_line1.error"} <= never
    assert varied["faults"] == "*=any@0.3" and healthy["faults"] is None
    assert varied["vehicle"] == "MINNOW"


def test_a_fault_rule_that_does_not_fit_the_profile_is_bad_input(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, _, err = cli(
        [RACY, "--unverified", "--fault", "DEPTH=timeout", "--out", str(tmp_path)], capsys
    )
    assert code == 2 and "DEPTH" in err and "Traceback" not in err
    assert not (tmp_path / "fuzz-report.json").exists()


def test_include_path_reaches_the_compile_and_the_replay_command(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    lib = tmp_path / "lib dir"
    lib.mkdir()
    (lib / "step.coral").write_text("transition t wait {a} signal {b}\n")
    mission = tmp_path / "m.coral"
    mission.write_text(
        'mission m\nvehicle ROMEO\nplace a = 1, b\nfinal {b}\ninclude "step.coral"\n'
    )
    argv = [str(mission), "--unverified", "--runs", "2", "--link", "lan", "-q", "--no-plot"]
    argv += ["--out", str(tmp_path / "out")]
    code, _, err = cli(argv, capsys)
    assert code == 2 and "step.coral" in err  # not found without the folder
    code, _, err = cli([*argv, "--include-path", str(lib)], capsys)
    assert code == 0, err
    from runtime.fuzz.cli import _command, build_parser

    replay = _command(build_parser().parse_args([*argv, "--include-path", str(lib)]))
    assert f"--include-path '{lib}'" in replay  # a failure's replay line finds it again
    assert json.loads((tmp_path / "out" / "fuzz-report.json").read_text())["success_rate"] == 1.0
    code, _, err = cli([*argv, "--include-path", str(tmp_path / "nowhere")], capsys)
    assert code == 2 and "argument --include-path:" in err and "no such folder" in err


def test_shared_options_read_as_in_coral_run(capsys: pytest.CaptureFixture[str]) -> None:
    assert fuzz_module.main(["--help"]) == 0
    out = capsys.readouterr().out
    assert "--profile YAML" in out and "--seed N" in out and "--include-path DIR" in out
    assert fuzz_module.main([RACY, "--replay", "-3"]) == 2
    assert "argument --replay: a seed is 0 .. 2**63-1, got -3" in capsys.readouterr().err
