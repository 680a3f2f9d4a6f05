"""Timed analysis in verification's outputs, with a hand-made `TimedReport`.

The analyser (`analysis.timed.explore.analyse_timed`) is replaced by a stub returning a
report written here, so these tests pin down what `analysis.verify` makes of it (the
``timed:*`` properties, the ``within`` assertions) and how every output shows it: text,
JSON (against the schema), SARIF, HTML and the certificate. What the analyser itself
finds is tested with it.
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import jsonschema
import pytest

import analysis.timed
from analysis.certificate import make_certificate
from analysis.outcome import to_json_document
from analysis.pipeline import CheckOptions, check_file
from analysis.report import Verdict
from analysis.sarif import to_sarif
from analysis.timed import (
    DeadlineResult,
    FinalTiming,
    QueryAdequacy,
    ScheduledCommand,
    ScheduledFiring,
    TimedOptions,
    TimedReport,
    TimedSchedule,
)
from analysis.verify import NO_PROFILE, UNTIMED_WITHIN, VerifyOptions, run_verification
from coral_lang.compiler import compile_file
from coral_lang.net import Net
from coral_lang.profile import VehicleProfile
from coral_lang.timing import LinkBounds
from tests.conftest import EXAMPLES, REPO

POOL = EXAMPLES / "pool_mission"
LINK = LinkBounds("genoa-lisbon", 0.045, 9.5)
DIGEST = "sha256:" + "0" * 64
WITHIN = "assert within 10 min { mission_complete }"
WITHIN_KEY = "assert:4"  # the pool mission has three assertions before it
SCHEMA_FILE = REPO / "docs" / "schema" / "coral-check.schema.json"
FAST = VerifyOptions(structural=False, timed=TimedOptions(LINK))


# -- a hand-made report ------------------------------------------------------------------


def schedule(kind: str, reason: str, *, timeout: bool = False, final: bool = True) -> TimedSchedule:
    """A short run of the pool mission's first commands (its times are made up)."""
    depth_reply = "timeout" if timeout else "done"
    commands = (
        ScheduledCommand("initialise", 1, "INIT", 0.0, 0.5, "done", 2.0, 0.1, 0.5),
        ScheduledCommand("set_depth", 1, "DEPTH", 3.1, 7.0, "ack", 1.0, 0.1, 0.4),
        ScheduledCommand("check_depth", 1, "DEPTH?", 11.6, 9.5, depth_reply, 30.0, 0.1, 9.5),
    )
    firings = (
        ScheduledFiring(0.0, "initialise"),
        ScheduledFiring(3.1, "initialise.done"),
        ScheduledFiring(3.1, "begin"),
        ScheduledFiring(3.1, "set_depth"),
        ScheduledFiring(11.6, "set_depth.ack"),
        ScheduledFiring(11.6, "check_depth"),
        ScheduledFiring(60.7, f"check_depth.{depth_reply}"),
        ScheduledFiring(60.8, "no_such_transition"),  # skipped in traces, kept in files
    )
    return TimedSchedule(
        mission="pool_mission",
        net_digest=DIGEST,
        kind=kind,
        reason=reason,
        link=LINK,
        duration_s=60.7,
        final={"mission_complete": 1} if final else None,
        commands=commands,
        firings=firings,
    )


def timed_report(
    *,
    complete: bool = True,
    deadline: Verdict = Verdict.PROVEN,
    query: Verdict = Verdict.VIOLATED,
    unbounded: str = "",
) -> TimedReport:
    """What the stub analyser answers: one final, two queries (one adequate, one whose
    verdict is ``query``) and the ``within`` deadline (verdict ``deadline``)."""
    violated_deadline = deadline is Verdict.VIOLATED
    return TimedReport(
        complete=complete,
        reason="" if complete else "symbolic state budget of 10 exhausted",
        link=LINK,
        states=1234,
        seconds=0.5,
        finals=(
            FinalTiming(
                {"mission_complete": 1},
                160.2,
                402.7,
                schedule("best-case", "best case to final { mission_complete }"),
                schedule("worst-case", "worst case to final { mission_complete }"),
            ),
        ),
        queries=(
            QueryAdequacy("check_heading", "HEADING?", 60.0, Verdict.PROVEN, "", margin_s=12.5),
            QueryAdequacy(
                "check_depth",
                "DEPTH?",
                30.0,
                query,
                "DEPTH? can time out" if query is Verdict.VIOLATED else "margin 0.5 s",
                counterexample=schedule("timeout", "check_depth times out", timeout=True)
                if query is Verdict.VIOLATED
                else None,
                margin_s=None if query is Verdict.VIOLATED else 0.5,
            ),
        ),
        deadlines=(
            DeadlineResult(
                4,
                {"mission_complete": 1},
                600.0,
                deadline,
                "missed by a run" if violated_deadline else "met by every run",
                counterexample=schedule("deadline", "deadline of assert:4 missed", final=False)
                if violated_deadline
                else None,
                latest_s=None if violated_deadline else 402.7,
            ),
        ),
        unbounded=unbounded,
    )


class Stub:
    """Stands in for `analyse_timed`: answers ``report`` and records its calls."""

    def __init__(self, report: TimedReport) -> None:
        self.report = report
        self.calls: list[tuple[Net, tuple[VehicleProfile, ...], TimedOptions]] = []

    def __call__(
        self, net: Net, profiles: Sequence[VehicleProfile], options: TimedOptions
    ) -> TimedReport:
        self.calls.append((net, tuple(profiles), options))
        return self.report


def install_stub(monkeypatch: pytest.MonkeyPatch, report: TimedReport) -> Stub:
    """Make `analysis.timed.analyse_timed` answer ``report`` (`analysis.verify` looks
    it up on the package each time it runs)."""
    stub = Stub(report)
    monkeypatch.setattr(analysis.timed, "analyse_timed", stub)
    return stub


def pool_with_deadline(folder: Path) -> Path:
    """A copy of the pool mission with ``assert within 10 min { mission_complete }``."""
    target = folder / "pool"
    shutil.copytree(POOL, target)
    mission = target / "pool_mission.coral"
    mission.write_text(mission.read_text(encoding="utf-8") + WITHIN + "\n", encoding="utf-8")
    (target / "pool_mission.certificate.json").unlink(missing_ok=True)
    return mission


def validate_document(document: dict[str, object]) -> dict[str, Any]:
    schema = json.loads(SCHEMA_FILE.read_text(encoding="utf-8"))
    data: dict[str, Any] = json.loads(json.dumps(document))
    errors = list(jsonschema.Draft202012Validator(schema).iter_errors(data))
    assert not errors, [f"{list(e.path)}: {e.message}" for e in errors[:5]]
    return data


# -- verification ------------------------------------------------------------------------


def test_untimed_verification_leaves_a_deadline_inconclusive(tmp_path: Path) -> None:
    net = compile_file(pool_with_deadline(tmp_path)).raise_for_errors()
    report = run_verification(net, VerifyOptions(structural=False)).report
    within = report.property(WITHIN_KEY)
    assert within.verdict is Verdict.INCONCLUSIVE and within.detail == UNTIMED_WITHIN
    assert within.title == "assert within 600 s { mission_complete }"
    assert within.span is not None and within.span.line == 44
    assert report.timed is None and "timed" not in report.to_dict()
    assert not [p for p in report.properties if p.key.startswith("timed:")]
    assert report.exit_code() == 3


def test_timed_verification_adds_the_stubs_verdicts(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    stub = install_stub(monkeypatch, timed_report())
    result = compile_file(pool_with_deadline(tmp_path))
    net = result.raise_for_errors()
    assert result.profile is not None
    report = run_verification(net, FAST, profiles=(result.profile,)).report
    (call,) = stub.calls
    assert call[0] is net and call[1] == (result.profile,) and call[2].link == LINK
    bounds = report.property("timed:bounds")
    assert bounds.verdict is Verdict.PROVEN and bounds.required
    assert bounds.title == "Mission time is bounded"
    assert bounds.detail == "final { mission_complete }: 160.2 s to 402.7 s"
    adequate = report.property("timed:timeout:check_heading")
    assert adequate.verdict is Verdict.PROVEN and not adequate.required
    assert adequate.title == "Time-out of check_heading (HEADING?, 60 s) is adequate"
    assert adequate.detail == "margin 12.5 s"
    late = report.property("timed:timeout:check_depth")
    assert late.verdict is Verdict.VIOLATED and late.warning
    assert late.span == net.transition("check_depth").span
    assert late.evidence is not None
    steps = late.evidence.trace
    assert [s.transition for s in steps][-2:] == ["check_depth", "check_depth.timeout"]
    assert [s.number for s in steps] == list(range(1, 8))  # the unknown firing is skipped
    assert steps[-1].description.startswith("at 60.7 s: ")
    assert "DEPTH? (check_depth #1) sent at 11.6 s: up 9.5 s" in late.evidence.note
    assert "replied timeout" in late.evidence.note
    within = report.property(WITHIN_KEY)
    assert within.verdict is Verdict.PROVEN and within.detail == "met by every run"
    assert report.timed is stub.report
    # A time-out that can happen is a warning: the verdict is the untimed one.
    assert report.verdict is Verdict.PROVEN and report.exit_code() == 0


def test_a_missed_deadline_fails_the_verification(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    install_stub(monkeypatch, timed_report(deadline=Verdict.VIOLATED))
    result = compile_file(pool_with_deadline(tmp_path))
    assert result.profile is not None
    report = run_verification(result.raise_for_errors(), FAST, profiles=(result.profile,)).report
    within = report.property(WITHIN_KEY)
    assert within.verdict is Verdict.VIOLATED and within.required
    assert within.evidence is not None and within.evidence.marking is None
    assert within.evidence.note.startswith("deadline of assert:4 missed: 3 command(s)")
    assert report.exit_code() == 1


@pytest.mark.parametrize(
    ("report", "reason"),
    [
        (timed_report(complete=False), "symbolic state budget of 10 exhausted"),
        (timed_report(unbounded="a cycle of set_depth"), "a cycle of set_depth"),
    ],
)
def test_an_incomplete_or_unbounded_exploration_proves_no_bound(
    monkeypatch: pytest.MonkeyPatch, report: TimedReport, reason: str
) -> None:
    install_stub(monkeypatch, report)
    result = compile_file(POOL / "pool_mission.coral")
    assert result.profile is not None
    verified = run_verification(result.raise_for_errors(), FAST, profiles=(result.profile,))
    bounds = verified.report.property("timed:bounds")
    assert bounds.verdict is Verdict.INCONCLUSIVE and bounds.detail == reason
    assert verified.report.exit_code() == 3


def test_without_a_profile_timed_analysis_is_inconclusive_and_not_run(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    stub = install_stub(monkeypatch, timed_report())
    net = compile_file(pool_with_deadline(tmp_path)).raise_for_errors()
    report = run_verification(net, FAST).report  # a PNML net: no profile behind it
    assert not stub.calls and report.timed is None
    for key in ("timed:bounds", WITHIN_KEY):
        assert report.property(key).verdict is Verdict.INCONCLUSIVE
        assert report.property(key).detail == NO_PROFILE
    assert not [p for p in report.properties if p.key.startswith("timed:timeout")]


def test_the_pipeline_hands_the_missions_profile_to_the_analyser(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    stub = install_stub(monkeypatch, timed_report())
    outcome = check_file(POOL / "pool_mission.coral", CheckOptions(verify=FAST))
    (call,) = stub.calls
    assert [p.name for p in call[1]] == ["ROMEO"]
    assert outcome.report is not None and outcome.report.timed is stub.report


# -- outputs -----------------------------------------------------------------------------


def _outcome(monkeypatch: pytest.MonkeyPatch, folder: Path, **kwargs: Any) -> Any:
    install_stub(monkeypatch, timed_report(**kwargs))
    return check_file(pool_with_deadline(folder), CheckOptions(verify=FAST))


def test_text_report_has_a_timing_section(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    outcome = _outcome(monkeypatch, tmp_path, deadline=Verdict.VIOLATED)
    text = outcome.report.render_text(net=outcome.net)
    timing = text[text.index("Timing (timed analysis):") :]
    assert "link 'genoa-lisbon': one-way delay 0.045 s to 9.5 s; 1234 symbolic states" in timing
    assert "final { mission_complete }: 160.2 s to 402.7 s" in timing
    assert "time-out of check_heading (HEADING?, 60 s): adequate, margin 12.5 s" in timing
    assert "time-out of check_depth (DEPTH?, 30 s): can time out" in timing
    assert "DEPTH? (check_depth #1) sent at 11.6 s: up 9.5 s, work 30.0 s" in timing
    assert "assert:4 within 600 s { mission_complete }: missed" in timing
    assert "WARNING       Time-out of check_depth (DEPTH?, 30 s) is adequate" in text
    assert text.splitlines()[-1].startswith("VIOLATED")


def test_json_report_carries_the_timed_report_and_validates(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    outcome = _outcome(monkeypatch, tmp_path)
    data = validate_document(to_json_document([outcome], "verify", "1"))
    report = data["files"][0]["report"]
    assert report["timed"] == json.loads(json.dumps(timed_report().to_json()))
    assert report["timed"]["worst_s"] == 402.7
    keys = [p["key"] for p in report["properties"]]
    assert keys[-3:] == ["timed:bounds", "timed:timeout:check_heading", "timed:timeout:check_depth"]


def test_sarif_locates_the_violated_timed_properties(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    outcome = _outcome(monkeypatch, tmp_path, deadline=Verdict.VIOLATED)
    sarif = to_sarif([outcome], tool_version="1")
    results = sarif["runs"][0]["results"]  # type: ignore[index]
    by_key = {r["properties"]["property"]: r for r in results if "property" in r["properties"]}
    late = by_key["timed:timeout:check_depth"]
    assert late["ruleId"] == "CORAL-V-timed" and late["level"] == "warning"
    region = late["locations"][0]["physicalLocation"]["region"]
    assert region["startLine"] == outcome.net.transition("check_depth").span.line
    assert late["codeFlows"][0]["threadFlows"][0]["locations"][-1]["location"]["message"][
        "text"
    ].startswith("7. at 60.7 s: ")
    deadline = by_key[WITHIN_KEY]
    assert deadline["level"] == "error"
    assert deadline["locations"][0]["physicalLocation"]["region"]["startLine"] == 44
    assert "timed:timeout:check_heading" not in by_key  # proven: no result


def test_html_report_has_a_timing_section(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from analysis.html_report import render_html

    outcome = _outcome(monkeypatch, tmp_path)
    page = render_html([outcome], layout="builtin", tool_version="1")
    section = page[page.index("<h3>Timing</h3>") : page.index("<h3>State space</h3>")]
    assert "genoa-lisbon: one-way delay 0.045 s to 9.5 s" in section
    assert "final { mission_complete }: 160.2 s to 402.7 s" in section
    assert "can time out: check_depth times out: DEPTH? (check_depth #1)" in section
    assert "met, latest at 402.7 s" in section


# -- certificate -------------------------------------------------------------------------


def test_a_timed_certificate_records_what_was_proven_and_assumed(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    outcome = _outcome(monkeypatch, tmp_path)
    profile = outcome.result.profile
    certificate: dict[str, Any] = make_certificate(outcome.report, FAST, profiles=(profile,))
    timed = certificate["timed"]
    assert timed["link"] == LINK.to_json()
    assert timed["profiles"] == [{"vehicle": "ROMEO", "tolerance": 0.2, "reply_latency_s": 0.1}]
    assert (timed["best_s"], timed["worst_s"]) == (160.2, 402.7)
    assert timed["finals"] == [
        {"final": {"mission_complete": 1}, "best_s": 160.2, "worst_s": 402.7}
    ]
    assert [q["verdict"] for q in timed["queries"]] == ["proven", "violated"]
    assert [q["margin_s"] for q in timed["queries"]] == [12.5, None]
    assert timed["deadlines"] == [
        {"index": 4, "deadline_s": 600.0, "verdict": "proven", "latest_s": 402.7}
    ]
    assert certificate["options"]["timed"]["link"] == LINK.to_json()
    # A time-out that can happen is listed, not required: the certificate passes.
    assert certificate["verdict"] == "proven"
    json.dumps(certificate)


def test_an_incomplete_timed_certificate_promises_no_time(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    outcome = _outcome(monkeypatch, tmp_path, complete=False)
    certificate: dict[str, Any] = make_certificate(outcome.report, FAST, profiles=())
    timed = certificate["timed"]
    assert timed["best_s"] is None and timed["worst_s"] is None and timed["finals"] == []
    assert certificate["verdict"] == "inconclusive"


def test_an_untimed_certificate_says_nothing_about_time() -> None:
    net = compile_file(POOL / "pool_mission.coral").raise_for_errors()
    report = run_verification(net, VerifyOptions(structural=False)).report
    certificate: dict[str, Any] = make_certificate(report, VerifyOptions(structural=False))
    assert "timed" not in certificate and "timed" not in certificate["options"]
    assert not [p for p in certificate["properties"] if p["key"].startswith("timed")]
