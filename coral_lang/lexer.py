"""Tokens of the CORAL mission language.

The language is free-form: line breaks are white space, statements start with a
keyword. ``#`` starts a comment to the end of the line. A command name may end in
``?`` (``DEPTH?``); the parser decides where such a name is allowed.

One compiled regular expression does the scanning: a mission of 10,000 transitions
is a quarter of a million tokens, and a per-character Python loop was the slowest
part of compiling it.
"""

from __future__ import annotations

import enum
import re
from typing import NamedTuple

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
    LT = "'<'"
    GE = "'>='"
    GT = "'>'"
    EQEQ = "'=='"
    NE = "'!='"
    PLUS = "'+'"
    LBRACKET = "'['"
    RBRACKET = "']'"
    DOT = "'.'"
    SLASH = "'/'"
    MINUS = "'-'"
    ERROR = "bad character"  # already reported by the lexer; the parser stays quiet on it
    COMMENT = "comment"  # only in the list tokenize(comments=...) fills; never parsed
    EOF = "end of file"


KEYWORDS = frozenset(
    {
        "mission", "vehicle", "const", "place", "capacity", "final", "transition", "priority",
        "wait", "action", "signal", "include", "assert", "never", "reachable", "bound", "ignore",
        "always", "eventually", "leadsto", "ltl", "ctl", "require", "input",
        "not", "and", "or", "true", "false", "deadlock",
    }
)  # fmt: skip

# Words that start a top-level statement: the parser resynchronises on them after an error.
STATEMENT_KEYWORDS = frozenset(
    {
        "mission",
        "vehicle",
        "const",
        "place",
        "final",
        "transition",
        "include",
        "assert",
        "require",
        "input",
    }
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
    "-": Kind.MINUS,
    "->": Kind.ARROW,
    "<=": Kind.LE,
    "<": Kind.LT,
    ">=": Kind.GE,
    ">": Kind.GT,
    "==": Kind.EQEQ,
    "!=": Kind.NE,
    "+": Kind.PLUS,
    "[": Kind.LBRACKET,
    "]": Kind.RBRACKET,
    ".": Kind.DOT,
}

# One match per token: the white space before it (possessive, so it is never given
# back), then the token. Every character of a line is matched, so matches are
# contiguous and columns follow from lengths. findall returns plain tuples: cheaper
# per token than match objects on a mission of a quarter of a million tokens.
_LINE_TOKENS = re.compile(
    r"""
    ([ \t\r\f\v]*+)
    (?:
      ([^\W\d]\w*\??)                                  # identifier
    | ((?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?)          # number
    | ("(?:[^"\\\n]|\\.)*"?)                           # string (maybe unterminated)
    | (->|<=|>=|==|!=|[{}(),=*:/<>+.\[\]-])             # punctuation
    | (\#.*)                                           # comment, to the end of the line
    | ([^\w\s"\#{}(),=*:/<>+.\[\]!-]+|.)                # anything else: an error (a run
                                                       # of them is one error, not many)
    )
    """,
    re.VERBOSE,
)
MAX_LEXER_ERRORS = 50
"""Bad-character errors after which the lexer stops reading a file: by then it is not
a mission (a binary, a stray YAML file), and a million errors would only cost memory."""

MAX_NUMBER_DIGITS = 40
"""Longest number literal (in characters) the lexer accepts. Every number in a mission
is a count, a weight or a parameter; 40 characters is far beyond any, and refusing
longer ones here keeps Python's int() from failing (or taking long) on 5,000 digits."""

_ESCAPE = re.compile(r"\\(.)")
_ESCAPES = {'"': '"', "\\": "\\", "n": "\n", "t": "\t"}


class Token(NamedTuple):
    """A token with its text and where it is (the same position fields as `Span`)."""

    kind: Kind
    text: str
    file: str
    line: int
    col: int
    end_line: int
    end_col: int

    @property
    def span(self) -> Span:
        """Where the token is, as a `Span` (built on demand: most tokens never need one)."""
        return Span(self.file, self.line, self.col, self.end_line, self.end_col)

    def describe(self) -> str:
        """How an error message names this token."""
        if self.kind is Kind.EOF:
            return "end of file"
        if self.kind is Kind.IDENT and self.text in KEYWORDS:
            return f"keyword '{self.text}'"
        return f"'{self.text}'"


def tokenize(
    text: str, file: str, comments: list[Token] | None = None
) -> tuple[list[Token], list[Diagnostic]]:
    """Split ``text`` into tokens; bad characters become diagnostics, never exceptions.

    Comments are not tokens: the parser never sees them. The formatter needs them back,
    so given a ``comments`` list the lexer appends each one to it (kind `Kind.COMMENT`,
    text without trailing white space). Compiling passes none and pays nothing for it.
    """
    tokens: list[Token] = []
    diagnostics: list[Diagnostic] = []
    append = tokens.append
    # Hot loop: names bound locally and tokens built with tuple.__new__ (a named
    # tuple's own constructor is a Python function: twice the cost per token).
    new, token_cls, ident_kind, punctuation = tuple.__new__, Token, Kind.IDENT, _PUNCTUATION
    findall = _LINE_TOKENS.findall
    line = errors = 0
    # Line by line: strings and comments never span lines.
    for line, text_line in enumerate(text.split("\n"), start=1):
        offset = 0
        for space, ident, number, string, punct, comment, error in findall(text_line):
            col = offset + len(space) + 1
            if ident:
                offset = col - 1 + len(ident)
                append(new(token_cls, (ident_kind, ident, file, line, col, line, offset + 1)))
            elif punct:
                offset = col - 1 + len(punct)
                kind = punctuation[punct]
                append(new(token_cls, (kind, punct, file, line, col, line, offset + 1)))
            elif number:
                offset = col - 1 + len(number)
                kind = Kind.INT if number.isdigit() else Kind.FLOAT
                if not number.isascii():
                    # \d matches every Unicode digit (U+0663, U+FF13) and int()/float()
                    # read them as 0-9: a mission would say 3 where its reader sees
                    # another script. Numbers are ASCII digits only.
                    span = Span(file, line, col, line, offset + 1)
                    odd = next(c for c in number if not c.isascii())
                    diagnostics.append(
                        Diagnostic(
                            Severity.ERROR,
                            "CORAL001",
                            f"number {number!r} uses the non-ASCII digit {odd!r}"
                            f" (U+{ord(odd):04X}); write numbers with the digits 0-9",
                            span,
                        )
                    )
                    kind = Kind.ERROR  # the parser stays quiet on it: reported here
                elif len(number) > MAX_NUMBER_DIGITS:
                    span = Span(file, line, col, line, offset + 1)
                    diagnostics.append(
                        Diagnostic(
                            Severity.ERROR,
                            "CORAL001",
                            f"number too long ({len(number)} characters; at most"
                            f" {MAX_NUMBER_DIGITS})",
                            span,
                        )
                    )
                    kind = Kind.ERROR  # the parser stays quiet on it: reported here
                append(new(token_cls, (kind, number, file, line, col, line, offset + 1)))
            elif comment:
                if comments is not None:
                    body = comment.rstrip()
                    end = col + len(body)
                    comments.append(Token(Kind.COMMENT, body, file, line, col, line, end))
                break
            elif string:
                offset = col - 1 + len(string)
                span = Span(file, line, col, line, offset + 1)
                closed = (
                    len(string) >= 2 and string.endswith('"') and not _escaped_quote_at_end(string)
                )
                body = string[1:-1] if closed else string[1:]
                value = _ESCAPE.sub(lambda m: _ESCAPES.get(m.group(1), m.group(0)), body)
                if not closed:
                    diagnostics.append(
                        Diagnostic(Severity.ERROR, "CORAL001", "unterminated string", span)
                    )
                append(Token(Kind.STRING, value, *span))
            else:
                offset = col - 1 + len(error)
                span = Span(file, line, col, line, offset + 1)
                shown = error if len(error) <= 20 else error[:20] + "..."
                shown = f"'{shown}'" if shown.isprintable() else repr(shown)
                plural = "s" if len(error) > 1 else ""
                diagnostics.append(
                    Diagnostic(
                        Severity.ERROR, "CORAL001", f"unexpected character{plural} {shown}", span
                    )
                )
                append(Token(Kind.ERROR, error, *span))
                errors += 1
                if errors >= MAX_LEXER_ERRORS:
                    diagnostics.append(
                        Diagnostic(
                            Severity.ERROR,
                            "CORAL001",
                            f"{errors} bad characters: stopped reading the file here"
                            " (is it a CORAL mission?)",
                            span,
                        )
                    )
                    append(Token(Kind.EOF, "", file, line, offset + 1, line, offset + 2))
                    return tokens, diagnostics
    last = text.rsplit("\n", 1)[-1]
    col = len(last) + 1
    append(Token(Kind.EOF, "", file, max(line, 1), col, max(line, 1), col + 1))
    return tokens, diagnostics


def _escaped_quote_at_end(lexeme: str) -> bool:
    """Whether the final quote of ``lexeme`` is escaped (so the string is unterminated)."""
    backslashes = len(lexeme) - 1 - len(lexeme[:-1].rstrip("\\"))
    return backslashes % 2 == 1
