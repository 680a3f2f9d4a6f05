"""Text output: colour only where it belongs, and one summary line per file."""

from __future__ import annotations

import io

import pytest

from analysis.outcome import FileOutcome, make_outcome
from analysis.pipeline import CheckOptions, check_file
from analysis.report import Verdict
from analysis.terminal import (
    render_diagnostic,
    render_report,
    render_run,
    summary_line,
    use_color,
)
from analysis.verify import VerifyOptions, verify
from coral_lang import compile_file
from coral_lang.diagnostics import Diagnostic, Severity, Span
from tests.conftest import EXAMPLES


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


@pytest.mark.parametrize(
    ("mode", "tty", "environ", "expected"),
    [
        ("auto", True, {}, True),
        ("auto", False, {}, False),
        ("auto", True, {"NO_COLOR": "1"}, False),
        ("auto", True, {"NO_COLOR": ""}, True),  # no-color.org: only a non-empty value
        ("auto", True, {"TERM": "dumb"}, False),
        ("always", False, {"NO_COLOR": "1"}, True),  # an explicit flag wins
        ("never", True, {}, False),
    ],
)
def test_use_color(mode: str, tty: bool, environ: dict[str, str], expected: bool) -> None:
    stream = _Tty() if tty else io.StringIO()
    assert use_color(mode, stream, environ) is expected  # type: ignore[arg-type]


def test_diagnostics_keep_their_text_and_colour_only_the_severity() -> None:
    span = Span("m.coral", 3, 5, 3, 9)
    d = Diagnostic(Severity.WARNING, "CORAL203", "place 'x' is declared but unused", span)
    sources = {"m.coral": "a\nb\nplace x, y\n"}
    plain = render_diagnostic(d, sources)
    assert plain == d.render(sources)
    painted = render_diagnostic(d, sources, color=True)
    assert painted.startswith("\033[1mm.coral:3:5:\033[0m \033[1;33mwarning:\033[0m place 'x'")
    assert painted.split("\n")[1:] == plain.split("\n")[1:]


def _verified(name: str) -> FileOutcome:
    path = str(EXAMPLES / "faulty" / name)
    result = compile_file(path)
    assert result.net is not None
    report = verify(result.net, VerifyOptions(structural=False))
    return make_outcome(path, [], report=report, net=result.net, sources=result.sources)


def test_summary_lines_and_the_footer() -> None:
    deadlock = _verified("deadlock.coral")
    assert deadlock.report is not None and deadlock.report.verdict is Verdict.VIOLATED
    assert summary_line(deadlock, lint_only=False).endswith("deadlock.coral: violated, 0 warnings")
    unread = FileOutcome("gone.coral", input_error="no such file")
    assert summary_line(unread, lint_only=False) == "gone.coral: not checked: no such file"
    text = render_run([deadlock, unread], lint_only=False)
    assert text.endswith("\n\n2 files: 1 violated, 1 unreadable\n")
    # the deadlock line, final_always_reachable's line and the report's last line
    assert text.count("VIOLATED") == 3


def test_quiet_keeps_only_problems() -> None:
    deadlock = _verified("deadlock.coral")
    path = str(EXAMPLES / "pool_mission" / "pool_mission.coral")
    result = compile_file(path)
    assert result.net is not None
    pool = make_outcome(
        path, [], report=verify(result.net, VerifyOptions(structural=False)), net=result.net
    )
    quiet = render_run([pool, deadlock], lint_only=False, quiet=True)
    assert "pool_mission" not in quiet and "faulty_deadlock" in quiet and "files:" not in quiet
    assert render_run([pool], lint_only=False, quiet=True) == ""


def test_a_part_says_which_mission_it_was_checked_with() -> None:
    part = EXAMPLES / "pool_mission" / "abort.coral"
    outcome = check_file(part, CheckOptions())
    assert outcome.status() == "part"
    line = summary_line(outcome, lint_only=True)
    assert line.startswith(f"{part}: ok as a part of ") and "pool_mission.coral" in line
    assert "verified when it is checked" in line
    assert render_run([outcome], lint_only=False).endswith(line + "\n")


def test_the_report_in_a_run_locates_its_findings() -> None:
    path = EXAMPLES / "faulty" / "dead_transition.coral"
    outcome = check_file(path, CheckOptions(verify=VerifyOptions(structural=False)))
    assert outcome.net is not None
    span = outcome.net.transition("record_dock").span
    assert f"{span}: transition 'record_dock' can never fire" in render_report(outcome)
    assert render_report(outcome) in render_run([outcome], lint_only=False)
    assert render_report(FileOutcome("x", input_error="gone")) == ""
