"""Tokens of the CORAL mission language.

The language is free-form: line breaks are white space, statements start with a
keyword. ``#`` starts a comment to the end of the line. A command name may end in
``?`` (``DEPTH?``); the parser decides where such a name is allowed.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from coral_lang.diagnostics import Diagnostic, Severity, Span


class Kind(enum.Enum):
    """Token kinds."""

    IDENT = "name"
    INT = "whole number"
    FLOAT = "number"
    STRING = "string"
    LBRACE = "'{'"
    RBRACE = "'}'"
    LPAREN = "'('"
    RPAREN = "')'"
    COMMA = "','"
    EQUALS = "'='"
    STAR = "'*'"
    COLON = "':'"
    ARROW = "'->'"
    LE = "'<='"
    SLASH = "'/'"
    MINUS = "'-'"
    ERROR = "bad character"  # already reported by the lexer; the parser stays quiet on it
    EOF = "end of file"


KEYWORDS = frozenset(
    {
        "mission", "vehicle", "const", "place", "capacity", "final", "transition", "priority",
        "wait", "action", "signal", "include", "assert", "never", "reachable", "bound", "ignore",
    }
)  # fmt: skip

# Words that start a top-level statement: the parser resynchronises on them after an error.
STATEMENT_KEYWORDS = frozenset(
    {"mission", "vehicle", "const", "place", "final", "transition", "include", "assert"}
)

_PUNCTUATION = {
    "{": Kind.LBRACE,
    "}": Kind.RBRACE,
    "(": Kind.LPAREN,
    ")": Kind.RPAREN,
    ",": Kind.COMMA,
    "=": Kind.EQUALS,
    "*": Kind.STAR,
    ":": Kind.COLON,
    "/": Kind.SLASH,
}


@dataclass(frozen=True)
class Token:
    """A token with its text and where it is."""

    kind: Kind
    text: str
    span: Span

    def describe(self) -> str:
        """How an error message names this token."""
        if self.kind is Kind.EOF:
            return "end of file"
        if self.kind is Kind.IDENT and self.text in KEYWORDS:
            return f"keyword '{self.text}'"
        return f"'{self.text}'"


def tokenize(text: str, file: str) -> tuple[list[Token], list[Diagnostic]]:
    """Split ``text`` into tokens; bad characters become diagnostics, never exceptions."""
    tokens: list[Token] = []
    diagnostics: list[Diagnostic] = []
    line, col, i, n = 1, 1, 0, len(text)

    def span(start_line: int, start_col: int, length: int) -> Span:
        return Span(file, start_line, start_col, start_line, start_col + length)

    while i < n:
        ch = text[i]
        if ch == "\n":
            line, col, i = line + 1, 1, i + 1
            continue
        if ch in " \t\r\f\v":
            i, col = i + 1, col + 1
            continue
        if ch == "#":
            while i < n and text[i] != "\n":
                i += 1
            continue
        start = i
        if ch.isalpha() or ch == "_":
            while i < n and (text[i].isalnum() or text[i] == "_"):
                i += 1
            if i < n and text[i] == "?":
                i += 1
            word = text[start:i]
            tokens.append(Token(Kind.IDENT, word, span(line, col, i - start)))
            col += i - start
            continue
        if ch.isdigit() or (ch == "." and i + 1 < n and text[i + 1].isdigit()):
            kind, i = _number(text, i)
            tokens.append(Token(kind, text[start:i], span(line, col, i - start)))
            col += i - start
            continue
        if ch == '"':
            value, i, closed = _string(text, i)
            length = i - start
            if not closed:
                diagnostics.append(
                    Diagnostic(
                        Severity.ERROR, "CORAL001", "unterminated string", span(line, col, length)
                    )
                )
            tokens.append(Token(Kind.STRING, value, span(line, col, length)))
            col += length
            continue
        if text.startswith("->", i):
            tokens.append(Token(Kind.ARROW, "->", span(line, col, 2)))
            i, col = i + 2, col + 2
            continue
        if text.startswith("<=", i):
            tokens.append(Token(Kind.LE, "<=", span(line, col, 2)))
            i, col = i + 2, col + 2
            continue
        if ch == "-":
            tokens.append(Token(Kind.MINUS, "-", span(line, col, 1)))
            i, col = i + 1, col + 1
            continue
        if ch in _PUNCTUATION:
            tokens.append(Token(_PUNCTUATION[ch], ch, span(line, col, 1)))
            i, col = i + 1, col + 1
            continue
        shown = ch if ch.isprintable() else repr(ch)
        diagnostics.append(
            Diagnostic(
                Severity.ERROR, "CORAL001", f"unexpected character '{shown}'", span(line, col, 1)
            )
        )
        tokens.append(Token(Kind.ERROR, ch, span(line, col, 1)))
        i, col = i + 1, col + 1
    tokens.append(Token(Kind.EOF, "", span(line, col, 1)))
    return tokens, diagnostics


def _number(text: str, i: int) -> tuple[Kind, int]:
    n = len(text)
    kind = Kind.INT
    while i < n and text[i].isdigit():
        i += 1
    if i < n and text[i] == "." and i + 1 < n and text[i + 1].isdigit():
        kind = Kind.FLOAT
        i += 1
        while i < n and text[i].isdigit():
            i += 1
    elif i < n and text[i] == "." and not (i + 1 < n and text[i + 1].isalpha()):
        kind = Kind.FLOAT  # "2." is a float
        i += 1
    if i < n and text[i] in "eE":
        j = i + 1
        if j < n and text[j] in "+-":
            j += 1
        if j < n and text[j].isdigit():
            kind = Kind.FLOAT
            i = j
            while i < n and text[i].isdigit():
                i += 1
    return kind, i


_ESCAPES = {'"': '"', "\\": "\\", "n": "\n", "t": "\t"}


def _string(text: str, i: int) -> tuple[str, int, bool]:
    """Read a string starting at the opening quote; returns (value, end, closed)."""
    out: list[str] = []
    i += 1
    n = len(text)
    while i < n and text[i] != "\n":
        ch = text[i]
        if ch == '"':
            return "".join(out), i + 1, True
        if ch == "\\" and i + 1 < n and text[i + 1] in _ESCAPES:
            out.append(_ESCAPES[text[i + 1]])
            i += 2
            continue
        out.append(ch)
        i += 1
    return "".join(out), i, False
