"""Source positions, diagnostics and the error hierarchy shared by every stage.

Every diagnostic knows where it is (file, line, column) and renders the same way:
``pool.coral:14:12: error: unknown place 'dpeth_ok' (did you mean 'depth_ok'?)``
followed by the source line and a caret. One helper renders them all, so the
format never drifts between the parser, the compiler and the checks.
"""

from __future__ import annotations

import difflib
import enum
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import NamedTuple


class Span(NamedTuple):
    """A region of a source file; lines and columns count from 1, ``end_col`` is exclusive.

    A named tuple rather than a dataclass: a large mission has hundreds of thousands of
    them, and tuples are several times cheaper to build.
    """

    file: str
    line: int
    col: int
    end_line: int
    end_col: int

    def __str__(self) -> str:
        return f"{self.file}:{self.line}:{self.col}"

    def to_dict(self) -> dict[str, object]:
        """JSON-friendly form, as reports and the certificate use it."""
        return {
            "file": self.file,
            "line": self.line,
            "col": self.col,
            "end_line": self.end_line,
            "end_col": self.end_col,
        }


class Severity(enum.Enum):
    """How bad a diagnostic is; only errors make a compile fail."""

    ERROR = "error"
    WARNING = "warning"
    NOTE = "note"


@dataclass(frozen=True)
class Diagnostic:
    """One finding about a source file, with a stable rule code."""

    severity: Severity
    code: str
    message: str
    span: Span | None
    notes: tuple[str, ...] = field(default=())

    def render(self, sources: Mapping[str, str] | None = None) -> str:
        """Render as ``file:line:col: severity: message [code]`` plus source line and caret."""
        where = f"{self.span}: " if self.span else ""
        lines = [f"{where}{self.severity.value}: {self.message} [{self.code}]"]
        if self.span and sources and self.span.file in sources:
            lines.extend(_excerpt(sources[self.span.file], self.span))
        lines.extend(f"  note: {note}" for note in self.notes)
        return "\n".join(lines)

    def to_dict(self) -> dict[str, object]:
        """JSON-friendly form."""
        return {
            "severity": self.severity.value,
            "code": self.code,
            "message": self.message,
            "span": self.span.to_dict() if self.span else None,
            "notes": list(self.notes),
        }


def _excerpt(text: str, span: Span) -> list[str]:
    source_lines = text.splitlines()
    if not 1 <= span.line <= len(source_lines):
        return []
    line = source_lines[span.line - 1].expandtabs(1)
    width = len(str(span.line))
    end = span.end_col if span.end_line == span.line else len(line) + 1
    length = max(1, min(end, len(line) + 1) - span.col)
    gutter = " " * width
    return [
        f" {gutter} |",
        f" {span.line} | {line}",
        f" {gutter} | {' ' * (span.col - 1)}^{'~' * (length - 1)}",
    ]


def render_all(diagnostics: Iterable[Diagnostic], sources: Mapping[str, str] | None = None) -> str:
    """Render several diagnostics, separated by blank lines, in source order."""
    return "\n\n".join(d.render(sources) for d in sort_diagnostics(diagnostics))


def sort_diagnostics(diagnostics: Iterable[Diagnostic]) -> list[Diagnostic]:
    """Source order: by file, line, column; diagnostics without a span last."""

    def key(d: Diagnostic) -> tuple[int, str, int, int]:
        if d.span is None:
            return (1, "", 0, 0)
        return (0, d.span.file, d.span.line, d.span.col)

    return sorted(diagnostics, key=key)


def did_you_mean(name: str, candidates: Iterable[str]) -> str:
    """A `` (did you mean 'x'?)`` suffix when a close candidate exists, else ``""``."""
    close = difflib.get_close_matches(name, list(candidates), n=1, cutoff=0.6)
    return f" (did you mean '{close[0]}'?)" if close else ""


class CoralError(Exception):
    """Root of every error coral raises on purpose; catch this to catch them all."""


class CompileError(CoralError, ValueError):
    """A mission did not compile. ``diagnostics`` holds every error found, in source order.

    Usually a typo in a place or command name, a parameter out of the profile's range,
    or a reply kind left unmapped: each diagnostic names the line and says how to fix it.
    """

    def __init__(self, diagnostics: Iterable[Diagnostic], sources: Mapping[str, str] | None = None):
        self.diagnostics = sort_diagnostics(diagnostics)
        self.sources = dict(sources or {})
        super().__init__(render_all(self.diagnostics, self.sources))


class ProfileError(CoralError, ValueError):
    """A vehicle profile is malformed; ``path`` is the YAML path of the offending field.

    Fix the field named in the message (for example ``commands.DEPTH.params[0].max``).
    """

    def __init__(self, file: str, path: str, message: str):
        self.file = file
        self.path = path
        self.detail = message
        super().__init__(f"{file}: {path}: {message}" if path else f"{file}: {message}")


class PnmlError(CoralError, ValueError):
    """A PNML file could not be read as a P/T net.

    Usually the file is not PNML, is a coloured or other non-P/T net type, or is
    truncated; the message names the element and, when known, the line.
    """
