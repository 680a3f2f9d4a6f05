"""Many fuzz runs: what they add up to, the text report, coverage, the progress bar."""

from __future__ import annotations

import dataclasses
import io
import json

import pytest

from coral_lang.net import TransitionKind
from runtime.controller import RunEnd
from runtime.engine import Policy
from runtime.fuzz import (
    NEVER_SHOWN,
    REPORT_JSON,
    Coverage,
    FuzzOptions,
    FuzzReport,
    NeverFired,
    ProgressBar,
    format_report,
    fuzz,
    run_one,
)
from runtime.link import BUILTIN_PROFILES
from tests.runtime.fuzz.common import POOL, RACY
from tests.runtime.test_properties import mission


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


def test_worker_processes_give_the_same_report_as_one_process() -> None:
    # A run depends on its seed alone: two spawned workers must give the very runs one
    # process gives, in the same order (only wall times differ).
    pool = mission("pool")
    options = FuzzOptions(runs=6, seed=40, link=BUILTIN_PROFILES["genoa-lisbon"])
    serial = fuzz(pool.net, pool.approval, options)
    parallel = fuzz(pool.net, pool.approval, options, workers=2)

    def key(report: FuzzReport) -> list[tuple[object, ...]]:
        return [
            (r.index, r.seed, r.end, r.marking, r.duration, r.events_digest, dict(r.fired))
            for r in report.runs
        ]

    assert key(parallel) == key(serial)
    assert [r.seed for r in parallel.runs] == list(range(40, 46))


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


@pytest.fixture(scope="module")
def pool_fuzz() -> FuzzReport:
    """Two runs of the pool mission over the LAN: every reply as a healthy vehicle gives."""
    pool = mission("pool")
    return fuzz(pool.net, pool.approval, FuzzOptions(runs=2, seed=0, link=BUILTIN_PROFILES["lan"]))


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
    assert never["depth_branch_failed"].line.endswith("go_to_operating_site.coral:47")
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
