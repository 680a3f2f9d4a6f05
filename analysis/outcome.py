"""What ``coral-check`` found in one file, its exit code, and the JSON document of a run.

A `FileOutcome` gathers everything the output formats show about one file: the compile
and lint diagnostics, the verification report (when the file was verified), the source
texts for excerpts, and the net for drawings. Text, JSON, SARIF and HTML are all
rendered from a list of outcomes, so they never disagree.

Exit codes, per file and for a run:

* 0: no errors, and (when verified) every property proven;
* 1: errors in the mission (compile or lint errors), or a property violated;
* 3: a property inconclusive, nothing violated, no errors;
* 0 also for a *part* of a mission (checked with its whole mission, not verified on
  its own) without errors of its own;
* 2: bad usage or input that cannot be read at all.

With several files the worst one wins, in the order 2 > 1 > 3 > 0: a file that could
not be read means the run checked less than was asked, which CI must not take for a
result; a violation is a definite answer and outranks an inconclusive one.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

from analysis.report import Report

# Re-exported: the CLI modules and tests take every exit code from here.
from coral_lang.cliframe import EXIT_FAILED
from coral_lang.cliframe import EXIT_OK as EXIT_OK
from coral_lang.cliframe import EXIT_USAGE as EXIT_USAGE
from coral_lang.compiler import CompileResult
from coral_lang.diagnostics import Diagnostic, Severity, sort_diagnostics
from coral_lang.net import Net

EXIT_ERRORS = EXIT_FAILED
"""Errors in a mission, or a property violated: the frame's definite negative answer."""
EXIT_INCONCLUSIVE = 3
"""coral-check's own code: a property neither proven nor violated (a budget ran out)."""

_RANK = {EXIT_OK: 0, EXIT_INCONCLUSIVE: 1, EXIT_ERRORS: 2, EXIT_USAGE: 3}

JSON_SCHEMA_NAME = "coral-check"
JSON_SCHEMA_VERSION = 2
"""Version of the document `to_json_document` builds (``docs/json.md``). Within a
version keys are only ever added; 2: ``coral-check verify`` emits it too (command
``verify``), files gained ``part_of`` and status ``part``, properties ``findings``."""
JSON_COMMANDS = ("check", "lint", "verify")


def worst_exit_code(codes: Iterable[int]) -> int:
    """The exit code of a run over several files: 2 > 1 > 3 > 0 (0 for no files)."""
    return max(codes, key=_RANK.__getitem__, default=EXIT_OK)


@dataclass(frozen=True)
class FileOutcome:
    """Everything coral-check found in one file.

    Attributes:
        path: The file as named on the command line.
        diagnostics: Compile and lint diagnostics, in source order.
        report: The verification report; None when the file was not verified (it did
            not compile, could not be read, or only lint was asked for).
        net: The compiled or imported net; None when there is none.
        sources: Text of every source file involved (the mission and its includes),
            for excerpts and the HTML source view.
        input_error: Why the file could not be read at all; None when it could.
        result: The compile (or import) result behind it, for what needs more than
            the net (a certificate records the profile the mission compiled against);
            None when the file could not be read.
        part_of: The whole mission this file is a part of (it was compiled and
            linted within it, and not verified); None for a file checked on its own.
    """

    path: str
    diagnostics: tuple[Diagnostic, ...] = ()
    report: Report | None = None
    net: Net | None = None
    sources: Mapping[str, str] = field(default_factory=dict)
    input_error: str | None = None
    result: CompileResult | None = field(default=None, compare=False, repr=False)
    part_of: str | None = None

    @property
    def errors(self) -> list[Diagnostic]:
        """The diagnostics of severity error."""
        return [d for d in self.diagnostics if d.severity is Severity.ERROR]

    @property
    def warnings(self) -> list[Diagnostic]:
        """The diagnostics of severity warning."""
        return [d for d in self.diagnostics if d.severity is Severity.WARNING]

    def exit_code(self) -> int:
        """This file's exit code (see the module docstring)."""
        if self.input_error is not None:
            return EXIT_USAGE
        if self.errors or self.net is None:
            return EXIT_ERRORS
        return self.report.exit_code() if self.report is not None else EXIT_OK

    def status(self) -> str:
        """One word: ``unreadable``, ``errors``, ``violated``, ``inconclusive``,
        ``proven`` (verified), ``clean`` (linted only, no errors) or ``part`` (a part of
        a mission, no errors in it: its mission is verified when it is checked)."""
        if self.input_error is not None:
            return "unreadable"
        if self.errors or self.net is None:
            return "errors"
        if self.part_of is not None:
            return "part"
        return self.report.verdict.value if self.report is not None else "clean"

    def to_dict(self) -> dict[str, object]:
        """JSON form: one entry of ``files`` (see ``docs/json.md``)."""
        return {
            "file": self.path,
            "status": self.status(),
            "exit_code": self.exit_code(),
            "error": self.input_error,
            "part_of": self.part_of,
            "diagnostics": [diagnostic_to_dict(d, self.path) for d in self.diagnostics],
            "report": self.report.to_dict(self.net) if self.report is not None else None,
        }


def diagnostic_to_dict(diagnostic: Diagnostic, default_file: str) -> dict[str, object]:
    """A diagnostic as a flat JSON object; ``default_file`` names the file when the
    diagnostic has no position (line and column are then null)."""
    span = diagnostic.span
    return {
        "code": diagnostic.code,
        "severity": diagnostic.severity.value,
        "file": span.file if span else default_file,
        "line": span.line if span else None,
        "col": span.col if span else None,
        "end_line": span.end_line if span else None,
        "end_col": span.end_col if span else None,
        "message": diagnostic.message,
        "notes": list(diagnostic.notes),
    }


def make_outcome(
    path: str,
    diagnostics: Iterable[Diagnostic],
    *,
    report: Report | None = None,
    net: Net | None = None,
    sources: Mapping[str, str] | None = None,
    result: CompileResult | None = None,
    part_of: str | None = None,
) -> FileOutcome:
    """A `FileOutcome` with its diagnostics put in source order."""
    return FileOutcome(
        path=path,
        diagnostics=tuple(sort_diagnostics(diagnostics)),
        report=report,
        net=net,
        sources=dict(sources or {}),
        result=result,
        part_of=part_of,
    )


def to_json_document(
    outcomes: Sequence[FileOutcome], command: str, tool_version: str
) -> dict[str, object]:
    """The ``--format json`` document of a run: one object, versioned, one entry per file,
    the same for ``coral-check``, ``coral-check lint`` and ``coral-check verify``
    (``docs/json.md``; its JSON Schema is ``docs/schema/coral-check.schema.json``).

    Args:
        outcomes: The files, in the order they were named.
        command: ``check`` (lint and verify), ``lint`` or ``verify``.
        tool_version: The coral version that made the document.

    Raises:
        ValueError: ``command`` is none of those.
    """
    if command not in JSON_COMMANDS:
        raise ValueError(f"command {command!r}: expected one of {', '.join(JSON_COMMANDS)}")
    return {
        "schema": JSON_SCHEMA_NAME,
        "schema_version": JSON_SCHEMA_VERSION,
        "tool": {"name": "coral-check", "version": tool_version},
        "command": command,
        "exit_code": worst_exit_code(o.exit_code() for o in outcomes),
        "files": [o.to_dict() for o in outcomes],
    }
