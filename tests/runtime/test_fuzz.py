"""``coral-run fuzz``: reproducible runs, the report, the gate, and bad input."""

from __future__ import annotations

import dataclasses
import io
import json
from pathlib import Path

import pytest

from runtime import fuzz as fuzz_module
from runtime.cli import main as coral_run
from runtime.controller import RunEnd
from runtime.engine import Policy
from runtime.fuzz import (
    UNVERIFIED,
    FuzzOptions,
    FuzzReport,
    ProgressBar,
    approval_for,
    format_report,
    fuzz,
    run_one,
    run_seed,
)
from runtime.link import BUILTIN_PROFILES
from tests.runtime.helpers import approve
from tests.runtime.test_properties import MISSIONS, mission
from tests.runtime.test_racy import HOSTILE_RACE_SEED, RACE_MARKINGS

RACY = str(MISSIONS["racy"])
POOL = str(MISSIONS["pool"])


@pytest.fixture
def heading_90(tmp_path: Path) -> Path:
    """A vehicle file: the bundled ROMEO, already facing 90 degrees."""
    path = tmp_path / "heading90.yaml"
    path.write_text("initial:\n  psi_deg: 90.0\n", encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def pool_certificate(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("cert")
    approve(mission("pool").net, folder)
    return folder / "pool_mission.certificate.json"


def cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = coral_run(["fuzz", *argv])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


# --------------------------------------------------------------------------- reproducibility


@pytest.mark.parametrize("name", ["racy", "pool"])
def test_the_same_seed_gives_the_same_outcome_and_the_same_events(name: str) -> None:
    m = mission(name)
    options = FuzzOptions(runs=1, seed=7, link=BUILTIN_PROFILES["hostile"])
    first = run_one(m.net, m.approval, 7, options, keep_events=True)
    second = run_one(m.net, m.approval, 7, options, keep_events=True)
    assert (first.end, first.marking, first.duration) == (
        second.end,
        second.marking,
        second.duration,
    )
    assert [(e.time, e.kind, e.data) for e in first.events] == [
        (e.time, e.kind, e.data) for e in second.events
    ]
    assert first.events_digest == second.events_digest
    other = run_one(m.net, m.approval, 8, options)
    assert other.events_digest != first.events_digest  # the seed does matter


def test_run_seeds_follow_the_base_seed() -> None:
    assert [run_seed(40, i) for i in range(3)] == [40, 41, 42]
    assert run_seed(2**63 - 1, 1) == 0


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


# --------------------------------------------------------------------------- the report


def test_a_verified_mission_that_always_ends_well_exits_0(
    tmp_path: Path, pool_certificate: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, err = cli(
        [POOL, "--certificate", str(pool_certificate), "--runs", "2", "--out", str(tmp_path)],
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


def test_the_report_counts_endings_and_names_the_worst_runs() -> None:
    racy = mission("racy")
    options = FuzzOptions(runs=3, seed=5, link=BUILTIN_PROFILES["lan"], policy=Policy.PRIORITY)
    report = fuzz(racy.net, racy.approval, options)
    assert [r.seed for r in report.runs] == [5, 6, 7]
    assert report.success_rate == 1.0
    text = format_report(report, "coral-run fuzz racy.coral")
    assert "3/3 (100.0 %)" in text and "final { aborted }" in text
    assert "longest runs:" in text and "failures" not in text
    stats = report.durations()
    assert stats["median"] <= stats["p90"] <= stats["max"]


def test_the_report_flags_a_dead_marking_analysis_did_not_predict() -> None:
    """Never expected; the report must say so loudly if the runtime ever disagreed."""
    racy = mission("racy")
    options = FuzzOptions(runs=1, seed=0, link=BUILTIN_PROFILES["ideal"])
    run = run_one(racy.net, racy.approval, 0, options)
    odd = dataclasses.replace(run, end=RunEnd.DEADLOCK, marking={"hovering": 1})
    report = FuzzReport("racy_mission", RACY, options, [odd], 1.0, predicted_deadlocks=set())
    assert "NOT among analysis's dead markings" in format_report(report, "coral-run fuzz x")


def test_the_progress_bar_draws_on_a_terminal_only() -> None:
    class Terminal(io.StringIO):
        def isatty(self) -> bool:
            return True

    tty = Terminal()
    bar = ProgressBar(tty, width=10)
    bar(3, 10, 1)
    bar.close()
    assert "[###.......] 3/10 runs, 1 failed" in tty.getvalue()
    assert tty.getvalue().endswith("\n")
    pipe = io.StringIO()
    bar = ProgressBar(pipe)
    bar(3, 10, 1)
    bar.close()
    assert pipe.getvalue() == ""


# --------------------------------------------------------------------------- the gate


def test_an_unverified_mission_needs_unverified(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, _, err = cli([RACY, "--runs", "1", "--out", str(tmp_path)], capsys)
    assert code == 2
    assert "--unverified" in err and "Traceback" not in err
    assert not (tmp_path / "fuzz-report.json").exists()


def test_the_unverified_approval_is_marked_and_only_ever_simulated() -> None:
    racy = mission("racy")
    approval, reason = approval_for(
        racy.net, Path(RACY), Path("/nonexistent.json"), unverified=True
    )
    assert approval.path == UNVERIFIED and reason is not None
    assert approval.net_digest == racy.net.digest()
    # There is no way to point fuzz at a vehicle: no such option, no socket link used.
    with pytest.raises(SystemExit) as exc:
        fuzz_module.build_parser().parse_args([RACY, "--vehicle", "10.0.0.1:5000"])
    assert exc.value.code == 2
    source = Path(fuzz_module.__file__).read_text(encoding="utf-8")
    assert "SocketLink" not in source and "run_mission" not in source


def test_a_verified_mission_keeps_its_certificate(pool_certificate: Path) -> None:
    pool = mission("pool")
    approval, reason = approval_for(pool.net, Path(POOL), pool_certificate, unverified=True)
    assert reason is None and approval.path == str(pool_certificate)


# --------------------------------------------------------------------------- bad input


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


@pytest.mark.parametrize("argv", [["--runs", "0"], ["--seed", "-1"], ["--time-limit", "inf"]])
def test_bad_numbers_are_usage_errors(argv: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        coral_run(["fuzz", RACY, *argv])
    assert exc.value.code == 2
    assert "Traceback" not in capsys.readouterr().err
