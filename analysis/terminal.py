"""``coral-check``'s text output: diagnostics, verdicts and a summary, for a terminal.

Colour (ANSI) is for people at a terminal only: `use_color` says yes when asked
(``--color always``), or, with ``--color auto``, when the stream is a TTY, ``NO_COLOR`` is
unset or empty (https://no-color.org) and ``TERM`` is not ``dumb``. A pipe, a file or
CI log therefore gets plain text.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Literal, TextIO

from analysis.outcome import FileOutcome
from coral_lang.diagnostics import Diagnostic, Severity

ColorMode = Literal["auto", "always", "never"]
COLOR_MODES: tuple[ColorMode, ...] = ("auto", "always", "never")

_SEVERITY_COLOURS = {Severity.ERROR: "1;31", Severity.WARNING: "1;33", Severity.NOTE: "1;36"}
_STATUS_COLOURS = {
    "proven": "32",
    "clean": "32",
    "part": "32",
    "violated": "31",
    "errors": "31",
    "unreadable": "31",
    "inconclusive": "33",
}


def use_color(mode: ColorMode, stream: TextIO, environ: Mapping[str, str]) -> bool:
    """Whether to write ANSI colours to ``stream`` (see the module docstring)."""
    if mode == "always":
        return True
    if mode == "never":
        return False
    if environ.get("NO_COLOR", "") != "" or environ.get("TERM") == "dumb":
        return False
    isatty = getattr(stream, "isatty", None)
    return bool(isatty and isatty())


def _paint(text: str, code: str, color: bool) -> str:
    return f"\033[{code}m{text}\033[0m" if color else text


def render_diagnostic(
    diagnostic: Diagnostic, sources: Mapping[str, str], color: bool = False
) -> str:
    """One diagnostic as `Diagnostic.render` writes it, its severity word in colour."""
    text = diagnostic.render(sources)
    if not color:
        return text
    where = f"{diagnostic.span}: " if diagnostic.span else ""
    word = diagnostic.severity.value
    prefix = f"{where}{word}:"
    if not text.startswith(prefix):
        return text
    painted = _paint(where.rstrip(), "1", color) + " " if where else ""
    return (
        painted
        + _paint(word + ":", _SEVERITY_COLOURS[diagnostic.severity], color)
        + (text[len(prefix) :])
    )


def _count(n: int, word: str) -> str:
    return f"{n} {word}{'' if n == 1 else 's'}"


def summary_line(outcome: FileOutcome, lint_only: bool, color: bool = False) -> str:
    """The last line about a file, e.g. ``pool_mission.coral: proven, 0 warnings``."""
    status = outcome.status()
    if outcome.input_error is not None:
        return f"{outcome.path}: {_paint('not checked', '31', color)}: {outcome.input_error}"
    errors, warnings = len(outcome.errors), len(outcome.warnings)
    if status == "errors":
        tail = "" if lint_only else "; not verified"
        return f"{outcome.path}: {_paint(_count(errors, 'error'), '31', color)}{tail}"
    assert outcome.net is not None
    if status == "part":
        warned = f", {_count(warnings, 'warning')}" if warnings else ""
        return (
            f"{outcome.path}: {_paint('ok', '32', color)} as a part of {outcome.part_of}"
            f"{warned} (compiled and linted with it; verified when it is checked)"
        )
    if lint_only:
        warned = f", {_count(warnings, 'warning')}" if warnings else ""
        return (
            f"{outcome.path}: {_paint('ok', '32', color)}{warned}, {outcome.net.summary()}, "
            f"digest {outcome.net.digest()}"
        )
    # A property that failed but is not required must not hide behind "proven".
    flagged = sum(1 for p in outcome.report.properties if p.warning) if outcome.report else 0
    tail = ""
    if flagged and status != "violated":
        tail = f", {_paint(_count(flagged, 'property warning'), '33', color)}"
    return (
        f"{outcome.path}: {_paint(status, _STATUS_COLOURS[status], color)}, "
        + _count(warnings, "warning")
        + tail
    )


def render_outcome(
    outcome: FileOutcome, *, lint_only: bool, color: bool = False, quiet: bool = False
) -> str:
    """Everything about one file: diagnostics, the verification report, the summary.

    ``quiet`` keeps only problems: the diagnostics, and the report when some property
    is not proven.
    """
    parts = [render_diagnostic(d, outcome.sources, color) for d in outcome.diagnostics]
    report = render_report(outcome, color)
    if report and not (quiet and outcome.status() == "proven"):
        parts.append(report)
    if not quiet:
        parts.append(summary_line(outcome, lint_only, color))
    return "\n\n".join(parts)


def render_report(outcome: FileOutcome, color: bool = False) -> str:
    """The verification report of a file (empty when it was not verified): verdicts,
    each finding located as ``file:line:col: message``, every trace step by step."""
    if outcome.report is None:
        return ""
    return outcome.report.render_text(color=color, net=outcome.net)


def render_footer(outcomes: Sequence[FileOutcome], quiet: bool = False) -> str:
    """A count of files by status, e.g. ``3 files: 1 proven, 2 violated``; empty for one
    file or when ``quiet``."""
    if len(outcomes) < 2 or quiet:
        return ""
    counts: dict[str, int] = {}
    for outcome in outcomes:
        counts[outcome.status()] = counts.get(outcome.status(), 0) + 1
    shown = ", ".join(f"{n} {status}" for status, n in counts.items())
    return f"{len(outcomes)} files: {shown}"


def render_run(
    outcomes: Sequence[FileOutcome],
    *,
    lint_only: bool,
    color: bool = False,
    quiet: bool = False,
) -> str:
    """The text output of a run: each file in turn, blank lines between, then
    `render_footer`.

    Returns:
        The text, ending with a newline (empty when ``quiet`` and nothing to say).
    """
    blocks = [render_outcome(o, lint_only=lint_only, color=color, quiet=quiet) for o in outcomes]
    blocks.append(render_footer(outcomes, quiet))
    text = "\n\n".join(b for b in blocks if b)
    return text + "\n" if text else ""
