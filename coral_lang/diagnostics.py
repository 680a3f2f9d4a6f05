"""Source positions, diagnostics and the error hierarchy shared by every stage.

Every diagnostic knows where it is (file, line, column) and renders the same way:
``pool.coral:14:12: error: unknown place 'dpeth_ok' (did you mean 'depth_ok'?)``
followed by the source line and a caret. One helper renders them all, so the
format never drifts between the parser, the compiler and the checks.
"""

from __future__ import annotations

import difflib
import enum
import functools
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


EXCERPT_WIDTH = 120
"""Most characters of a source line an excerpt shows; a longer line is cut to a window
around the column, marked with ``...``, so a 40 KB line costs 120 characters per error."""

MAX_RENDERED_PER_FILE = 100
"""Most diagnostics `render_all` writes out per file; the rest are counted in one line.
A garbage file can hold a million errors, and nobody reads past the first screens."""

_LINE_STARTS_CACHE = 8  # sources whose line offsets are kept (one compile has a few)


@functools.lru_cache(maxsize=_LINE_STARTS_CACHE)
def _line_starts(text: str) -> tuple[int, ...]:
    """Offsets where each line of ``text`` starts, split only at ``\\n`` as the lexer does.

    Computed once per source (a str caches its hash, so the lookup is cheap): rendering
    each diagnostic used to re-split the whole file, quadratic on big garbage inputs.
    Other line breaks (``\\u2028``, ``\\x0c``...) are not line ends for the lexer, so
    they are not here either, or the excerpt would show another line than the error's.
    """
    starts = [0]
    find = text.find
    position = find("\n")
    while position != -1:
        starts.append(position + 1)
        position = find("\n", position + 1)
    return tuple(starts)


def source_line(text: str, line: int) -> str | None:
    """Line ``line`` (from 1) of ``text`` as the lexer counts lines; None past the end."""
    starts = _line_starts(text)
    if not 1 <= line <= len(starts):
        return None
    start = starts[line - 1]
    end = starts[line] - 1 if line < len(starts) else len(text)
    return text[start:end].removesuffix("\r")


def _printable(text: str) -> str:
    """``text`` with tabs as one space and other unprintable characters as ``?``.

    One character out per character in, so the caret stays under the column; and no
    control or escape sequence from a hostile file reaches the terminal.
    """
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else " " if c == "\t" else "?" for c in text)


def _excerpt(text: str, span: Span) -> list[str]:
    line = source_line(text, span.line)
    if line is None:
        return []
    end = span.end_col if span.end_line == span.line else len(line) + 1
    col = min(max(span.col, 1), len(line) + 1)
    length = max(1, min(end, len(line) + 1) - col)
    prefix = suffix = ""
    if len(line) > EXCERPT_WIDTH:
        start = min(max(0, col - 1 - EXCERPT_WIDTH // 3), len(line) - EXCERPT_WIDTH)
        stop = start + EXCERPT_WIDTH
        prefix = "..." if start > 0 else ""
        suffix = "..." if stop < len(line) else ""
        line = line[start:stop]
        col -= start  # now within the window
        length = max(1, min(length, len(line) + 1 - col))
        col += len(prefix)
    shown = prefix + _printable(line) + suffix
    width = len(str(span.line))
    gutter = " " * width
    return [
        f" {gutter} |",
        f" {span.line} | {shown}",
        f" {gutter} | {' ' * (col - 1)}^{'~' * (length - 1)}",
    ]


def render_all(
    diagnostics: Iterable[Diagnostic],
    sources: Mapping[str, str] | None = None,
    limit: int = MAX_RENDERED_PER_FILE,
) -> str:
    """Render several diagnostics, separated by blank lines, in source order.

    At most ``limit`` per file are written out, then one line counts the others: the
    output stays readable, and bounded, however broken the input.
    """
    blocks: list[str] = []
    shown: dict[str, int] = {}
    hidden: dict[str, int] = {}
    for d in sort_diagnostics(diagnostics):
        file = d.span.file if d.span else ""
        if shown.get(file, 0) >= limit:
            hidden[file] = hidden.get(file, 0) + 1
            continue
        shown[file] = shown.get(file, 0) + 1
        blocks.append(d.render(sources))
    for file, count in hidden.items():
        where = f" in {file}" if file else ""
        blocks.append(f"... and {count} more diagnostic{'s' if count != 1 else ''}{where}")
    return "\n\n".join(blocks)


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


MAX_PROFILE_ERRORS_SHOWN = 50
"""Most errors a `ProfileError`'s message lists (all are in its ``errors``): a garbage
profile can hold thousands, and nobody reads past the first screen."""


class ProfileError(CoralError, ValueError):
    """A vehicle profile is malformed; ``path`` is the YAML path of the offending field.

    Fix the field named in the message (for example ``commands.DEPTH.params[0].max``).
    A profile with several mistakes gives one error carrying all of them (`errors`,
    in document order), and its message lists them, one per line: fixing a profile
    should not take one run per mistake. ``file``, ``path`` and ``detail`` are the
    first one's.
    """

    def __init__(
        self, file: str, path: str, message: str, more: Iterable[ProfileError] = ()
    ) -> None:
        self.file = file
        self.path = path
        self.detail = message
        self.more = tuple(m for error in more for m in error.errors)
        lines = [error.line() for error in self.errors[:MAX_PROFILE_ERRORS_SHOWN]]
        hidden = len(self.more) + 1 - len(lines)
        if hidden > 0:
            lines.append(f"... and {hidden} more error{'s' if hidden != 1 else ''}")
        super().__init__("\n".join(lines))

    @classmethod
    def collected(cls, errors: Iterable[ProfileError]) -> ProfileError:
        """One error carrying every one of ``errors`` (at least one)."""
        first, *rest = errors
        return cls(first.file, first.path, first.detail, (*first.more, *rest))

    @property
    def errors(self) -> tuple[ProfileError, ...]:
        """This error and every other one found with it, each alone."""
        if not self.more:
            return (self,)
        return (ProfileError(self.file, self.path, self.detail), *self.more)

    def line(self) -> str:
        """The first error alone: ``file:line:col: field.path: message``."""
        return (
            f"{self.file}: {self.path}: {self.detail}"
            if self.path
            else f"{self.file}: {self.detail}"
        )


class PnmlError(CoralError, ValueError):
    """A PNML file could not be read as a P/T net.

    Usually the file is not PNML, is a coloured or other non-P/T net type, or is
    truncated; the message names the element and, when known, the line.
    """
