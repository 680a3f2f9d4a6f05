"""``coral-run fuzz``: reproducible runs, the report, the gate, and bad input."""

from __future__ import annotations

import dataclasses
import io
import json
from collections import Counter
from pathlib import Path

import pytest

from analysis.signing import TrustStore
from coral_lang.mission import load_mission
from coral_lang.net import TransitionKind
from runtime import fuzz as fuzz_module
from runtime.cli import main as coral_run
from runtime.controller import RunEnd
from runtime.engine import Policy
from runtime.fuzz import (
    NEVER_SHOWN,
    REPORT_JSON,
    UNVERIFIED,
    Coverage,
    FuzzOptions,
    FuzzReport,
    NeverFired,
    ProgressBar,
    approval_for,
    events_digest,
    format_report,
    fuzz,
    run_one,
    run_seed,
)
from runtime.link import BUILTIN_PROFILES
from tests.conftest import EXAMPLES, session_signing_key
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
        load_mission(Path(RACY)), Path("/nonexistent.json"), unverified=True
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
    del pool
    approval, reason = approval_for(
        load_mission(Path(POOL)),
        pool_certificate,
        unverified=True,
        trusted=session_signing_key().trusted,
    )
    assert reason is None and approval.path == str(pool_certificate)
    # Not trusted: refused as a run refuses it, so only --unverified fuzzes it.
    refused, reason = approval_for(
        load_mission(Path(POOL)), pool_certificate, unverified=True, trusted=TrustStore()
    )
    assert refused.path == UNVERIFIED and reason is not None and "not trusted" in reason


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


# --------------------------------------------------------------------------- coverage


@pytest.fixture(scope="module")
def pool_fuzz() -> FuzzReport:
    """Two runs of the pool mission over the LAN: every reply as a healthy vehicle gives."""
    pool = mission("pool")
    return fuzz(pool.net, pool.approval, FuzzOptions(runs=2, seed=0, link=BUILTIN_PROFILES["lan"]))


def test_a_run_counts_the_transitions_its_events_fired() -> None:
    pool = mission("pool")
    options = FuzzOptions(runs=1, seed=4, link=BUILTIN_PROFILES["lan"])
    run = run_one(pool.net, pool.approval, 4, options, keep_events=True)
    fires = Counter(e.data["transition"] for e in run.events if e.kind == "fire")
    assert dict(run.fired) == dict(fires) and fires
    assert run.events_digest == events_digest(run.events)
    lean = run_one(pool.net, pool.approval, 4, options)
    assert lean.events == () and lean.fired == run.fired
    assert lean.events_digest == run.events_digest
    assert lean.to_json()["transitions_fired"] == len(run.fired)


def test_coverage_adds_up(pool_fuzz: FuzzReport) -> None:
    net = mission("pool").net
    coverage = pool_fuzz.coverage()
    assert coverage is not None
    names = [t.name for t in net.transitions]
    assert coverage.transitions == len(names)
    assert 0 < coverage.exercised < coverage.transitions
    assert set(coverage.fired) <= set(names)
    assert [n.transition for n in coverage.never] == [n for n in names if n not in coverage.fired]
    for name, count in coverage.fired.items():
        assert count == sum(run.fired.get(name, 0) for run in pool_fuzz.runs) > 0
    # Reply transitions fire too: the replies the simulator gave, and only those.
    assert {"initialise.done", "check_depth.done", "fix_position.done"} <= set(coverage.fired)
    assert any(net.transition(n).kind is TransitionKind.REPLY for n in coverage.fired)
    assert f"{100.0 * coverage.share:.1f}" == f"{100.0 * coverage.exercised / len(names):.1f}"


def test_never_fired_transitions_name_their_line_command_and_reply(pool_fuzz: FuzzReport) -> None:
    net = mission("pool").net
    coverage = pool_fuzz.coverage()
    assert coverage is not None
    never = {n.transition: n for n in coverage.never}
    span = net.transition("check_depth.timeout").span
    assert span is not None
    assert never["check_depth.timeout"] == NeverFired(
        "check_depth.timeout", f"{span.file}:{span.line}", "DEPTH?", "timeout"
    )
    assert never["depth_branch_failed"].command is None
    assert never["depth_branch_failed"].reply is None
    assert never["depth_branch_failed"].line is not None
    assert never["depth_branch_failed"].line.endswith("go_to_operating_site.coral:46")
    data = json.loads(json.dumps(pool_fuzz.to_json()))["coverage"]
    assert data["transitions"] == coverage.transitions
    assert data["exercised"] == coverage.exercised == len(data["fired"])
    assert data["fired"] == dict(coverage.fired)
    assert [n["transition"] for n in data["never"]] == [n.transition for n in coverage.never]
    assert {"transition", "line", "command", "reply"} == set(data["never"][0])


def test_the_text_report_lists_never_fired_transitions_with_their_lines(
    pool_fuzz: FuzzReport,
) -> None:
    coverage = pool_fuzz.coverage()
    assert coverage is not None
    text = format_report(pool_fuzz, "coverage.coral")
    assert (
        f"coverage: exercised {coverage.exercised} of {coverage.transitions} transitions "
        f"({100.0 * coverage.share:.1f} %)"
    ) in text
    shown = [line.split() for line in text.splitlines() if line.startswith("    ")]
    rows = {words[0]: words for words in shown}
    for never in coverage.never[:NEVER_SHOWN]:
        assert rows[never.transition][1] == never.line
        if never.reply is not None:
            assert rows[never.transition][2:] == [str(never.command), "replied", never.reply]
    for name in coverage.fired:
        assert name not in rows
    assert "reply fuzzing" in text
    hidden = len(coverage.never) - NEVER_SHOWN
    assert (f"... and {hidden} more in {REPORT_JSON}" in text) == (hidden > 0)


def test_the_text_report_caps_the_list_and_json_keeps_it_all() -> None:
    net = mission("pool").net
    options = FuzzOptions(runs=0, seed=0, link=BUILTIN_PROFILES["lan"])
    report = FuzzReport("pool_mission", POOL, options, [], 0.0, net=net)
    text = format_report(report, "x")
    assert f"exercised 0 of {len(net.transitions)} transitions (0.0 %)" in text
    assert f"... and {len(net.transitions) - NEVER_SHOWN} more in {REPORT_JSON}" in text
    assert len(report.to_json()["coverage"]["never"]) == len(net.transitions)  # type: ignore[index]


def test_a_report_without_its_net_has_no_coverage() -> None:
    options = FuzzOptions(runs=0, seed=0, link=BUILTIN_PROFILES["lan"])
    report = FuzzReport("m", "m.coral", options, [], 0.0)
    assert report.coverage() is None and report.to_json()["coverage"] is None
    assert "coverage" not in format_report(report, "x")
    full = Coverage.of(mission("racy").net, [])
    assert full.exercised == 0 and full.share == 0.0


# --------------------------------------------------------------------------- any vehicle


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
