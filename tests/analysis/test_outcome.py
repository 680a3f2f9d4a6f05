"""One file's outcome: its status, its exit code, its JSON form."""

from __future__ import annotations

from analysis.outcome import (
    EXIT_ERRORS,
    EXIT_INCONCLUSIVE,
    EXIT_OK,
    EXIT_USAGE,
    FileOutcome,
    diagnostic_to_dict,
    make_outcome,
    to_json_document,
)
from analysis.report import PropertyResult, Report, StateSpaceFigures, Verdict
from coral_lang.diagnostics import Diagnostic, Severity, Span
from tests.analysis.nets import mutex

NET = mutex()


def _report(*verdicts: Verdict) -> Report:
    figures = StateSpaceFigures(1, 0, 1, 1, {}, True, None, False, 0.0, 0.0)
    properties = [
        PropertyResult(key, "t", Verdict.PROVEN, "m", "d") for key in ("bounded", "deadlock")
    ]
    properties += [PropertyResult(f"assert:{i}", "t", v, "m", "d") for i, v in enumerate(verdicts)]
    return Report("n", "sha256:x", (), figures, properties)


def _diag(severity: Severity, line: int = 1) -> Diagnostic:
    return Diagnostic(severity, "CORAL202", "m", Span("a.coral", line, 2, line, 3))


def test_status_and_exit_code_of_each_kind_of_outcome() -> None:
    cases = [
        (FileOutcome("a", input_error="no such file"), "unreadable", EXIT_USAGE),
        (FileOutcome("a", (_diag(Severity.ERROR),)), "errors", EXIT_ERRORS),
        (FileOutcome("a"), "errors", EXIT_ERRORS),  # no net and no report
        (FileOutcome("a", (_diag(Severity.WARNING),), net=NET), "clean", EXIT_OK),
        (FileOutcome("a", net=NET, report=_report(Verdict.PROVEN)), "proven", EXIT_OK),
        (
            FileOutcome("a", net=NET, report=_report(Verdict.PROVEN, Verdict.INCONCLUSIVE)),
            "inconclusive",
            EXIT_INCONCLUSIVE,
        ),
        (
            FileOutcome("a", net=NET, report=_report(Verdict.INCONCLUSIVE, Verdict.VIOLATED)),
            "violated",
            EXIT_ERRORS,
        ),
        (
            FileOutcome("a", (_diag(Severity.ERROR),), net=NET, report=_report(Verdict.PROVEN)),
            "errors",
            EXIT_ERRORS,
        ),
    ]
    for outcome, status, code in cases:
        assert (outcome.status(), outcome.exit_code()) == (status, code), outcome


def test_diagnostics_are_sorted_and_flattened() -> None:
    outcome = make_outcome("a.coral", [_diag(Severity.WARNING, 9), _diag(Severity.NOTE, 2)])
    assert [d.span.line for d in outcome.diagnostics if d.span] == [2, 9]
    positionless = Diagnostic(Severity.ERROR, "CORAL004", "cannot read", None)
    assert diagnostic_to_dict(positionless, "a.coral") == {
        "code": "CORAL004",
        "severity": "error",
        "file": "a.coral",
        "line": None,
        "col": None,
        "end_line": None,
        "end_col": None,
        "message": "cannot read",
        "notes": [],
    }


def test_json_document_takes_the_worst_exit_code() -> None:
    outcomes = [
        FileOutcome("a", net=NET, report=_report(Verdict.INCONCLUSIVE)),
        FileOutcome("b", net=NET, report=_report(Verdict.PROVEN)),
    ]
    document = to_json_document(outcomes, "check", "1.2.3")
    assert document["exit_code"] == EXIT_INCONCLUSIVE
    assert document["tool"] == {"name": "coral-check", "version": "1.2.3"}
    files = document["files"]
    assert isinstance(files, list) and [f["status"] for f in files] == ["inconclusive", "proven"]
