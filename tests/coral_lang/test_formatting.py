"""The formatter: the printer's layout with every comment kept where lint reads it."""

from __future__ import annotations

from itertools import pairwise
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from analysis.lint import LintOptions, lint
from coral_lang import ast
from coral_lang.compiler import compile_source
from coral_lang.diagnostics import CompileError
from coral_lang.formatting import format_source
from coral_lang.lexer import Kind, Token, tokenize
from coral_lang.parser import parse
from coral_lang.printer import format_mission
from tests.conftest import EXAMPLES, REPO
from tests.coral_lang.strategies import missions

MISSION_FILES = sorted([*EXAMPLES.rglob("*.coral"), *(REPO / "tests" / "data").rglob("*.coral")])
HEADER = "mission m\nvehicle ROMEO\n"


def _comments(text: str) -> list[str]:
    found: list[Token] = []
    tokenize(text, "c.coral", found)
    return [t.text for t in found]


def _tree(text: str) -> ast.Mission:
    mission, diagnostics = parse(text, "t.coral")
    assert diagnostics == []
    return mission


def test_there_are_mission_files_to_format() -> None:
    assert len(MISSION_FILES) >= 10


@pytest.mark.parametrize("path", MISSION_FILES, ids=lambda p: str(p.relative_to(REPO)))
def test_every_mission_file_formats_stably_to_the_same_net(path: Path) -> None:
    text = path.read_text()
    formatted = format_source(text, str(path))
    assert format_source(formatted, str(path)) == formatted
    assert _comments(formatted) == _comments(text)
    assert _tree(formatted) == _tree(text)
    before = compile_source(text, str(path), base_dir=path.parent)
    after = compile_source(formatted, str(path), base_dir=path.parent)
    assert [d.code for d in after.diagnostics] == [d.code for d in before.diagnostics]
    if before.net is not None:
        assert after.net is not None and after.net.digest() == before.net.digest()


def test_layout_comments_and_blank_lines() -> None:
    source = (
        "# header comment\n"
        "mission   m\n"
        "vehicle ROMEO\n"
        "\n"
        "\n"
        "\n"
        "const   T =   60 s   # how long\n"
        "const LONG_NAME = 2.50 m # depth\n"
        "# about the places\n"
        "\n"
        "place a = 1,b\n"
        "transition t wait {a}   # coral: allow CORAL207 -- why\n"
        "    # the command\n"
        "    action {ROMEO(DEPTH, z = LONG_NAME) -> {ack: b, error: b}}\n"
        "final {b}\n"
        "# the end\n"
    )
    assert format_source(source, "m.coral") == (
        "# header comment\n"
        "mission m\n"
        "vehicle ROMEO\n"
        "\n"
        "const T         = 60 s   # how long\n"
        "const LONG_NAME = 2.5 m  # depth\n"
        "# about the places\n"
        "\n"
        "place a = 1, b\n"
        "transition t  # coral: allow CORAL207 -- why\n"
        "    wait   { a }\n"
        "    # the command\n"
        "    action { ROMEO(DEPTH, z = LONG_NAME) -> { ack: b, error: b } }\n"
        "final { b }\n"
        "# the end\n"
    )


def test_a_trailing_comment_stays_on_the_first_line_of_its_source_line() -> None:
    # a one-line transition with an action printed on three lines keeps its comment on
    # the header, where a finding about it points
    text = HEADER + (
        "place a = 1, b\ntransition t wait { a } action { ROMEO(DEPTH, z = 1.0 m)"
        " -> { ack: b, error: b } }  # about t\n"
    )
    lines = format_source(text, "m.coral").splitlines()
    assert lines[-3] == "transition t  # about t"


def test_one_line_transitions_without_an_action_stay_one_line_as_a_table() -> None:
    text = HEADER + (
        "place a = 1, b, c\n"
        "transition t priority 1 wait {a} signal {b}\n"
        "transition long_name wait { b }   signal { c }  # the second\n"
        "transition u\n    wait { c }\n"
    )
    assert format_source(text, "m.coral").splitlines()[3:] == [
        "transition t         priority 1 wait { a } signal { b }",
        "transition long_name            wait { b } signal { c }  # the second",
        "transition u",
        "    wait   { c }",
    ]


def test_comments_meeting_on_one_line_stay_in_order_and_unmerged() -> None:
    text = HEADER + "place a = 1, b\ntransition t wait {\n a  # first\n } signal { b } # last\n"
    assert format_source(text, "m.coral").splitlines()[-4:] == [
        "transition t",
        "    # first",
        "    wait   { a }  # last",
        "    signal { b }",
    ]
    assert _comments(format_source(text, "m.coral")) == ["# first", "# last"]


def test_a_list_written_over_several_lines_keeps_its_breaks_and_comments() -> None:
    text = HEADER + (
        "place a = 1,b,   # the first two\n"
        "  # about c\n"
        "    c capacity 2,\n"
        "\n"
        "  d  # the last\n"
        "input   stop,\n  go\n"
    )
    assert format_source(text, "m.coral").splitlines()[2:] == [
        "place a = 1, b,  # the first two",
        "      # about c",
        "      c capacity 2,",
        "      d  # the last",
        "input stop,",
        "      go",
    ]


def test_a_comment_on_a_part_the_printer_drops_keeps_its_place_in_order() -> None:
    text = HEADER + (
        "place a = 1, b\n"
        "transition t\n"
        "    # on the empty wait\n"
        "    wait { }  # also on it\n"
        "    action { ROMEO(DEPTH, z = 1.0 m) -> { ack: b, error: b } }\n"
    )
    formatted = format_source(text, "m.coral")
    assert _comments(formatted) == ["# on the empty wait", "# also on it"]
    assert format_source(formatted, "m.coral") == formatted
    assert _tree(formatted) == _tree(text)


def test_hash_in_a_string_is_no_comment() -> None:
    text = HEADER + 'include "a#b.coral"  # the real one\n'
    assert format_source(text, "m.coral").endswith('include "a#b.coral"  # the real one\n')


def test_long_actions_wrap_before_the_reply_map() -> None:
    text = HEADER + (
        "place a = 1, b, c\n"
        "transition t wait { a } action { ROMEO(XYPSI?, x = 1.0 m, y = 2.0 m, psi = 3.0 deg,"
        " time_out = 60 s) -> { done: b, timeout: c } }\n"
    )
    formatted = format_source(text, "m.coral")
    assert formatted.splitlines()[-2:] == [
        "    action { ROMEO(XYPSI?, x = 1.0 m, y = 2.0 m, psi = 3.0 deg, time_out = 60 s)",
        "             -> { done: b, timeout: c } }",
    ]
    assert max(len(line) for line in formatted.splitlines()) <= 100


def test_comment_only_and_empty_files() -> None:
    assert format_source("", "e.coral") == ""
    assert format_source("  # one\n\n\n# two  \n", "e.coral") == "# one\n\n# two\n"


def test_text_that_does_not_parse_raises_with_the_parse_errors() -> None:
    with pytest.raises(CompileError) as raised:
        format_source(HEADER + "place start = 1 done\n", "bad.coral")
    [error] = raised.value.diagnostics
    assert error.code == "CORAL001" and error.span is not None
    assert (error.span.file, error.span.line, error.span.col) == ("bad.coral", 3, 17)


_WORDS = st.text(alphabet="abc XYZ#{}\"'*,0123456789:-", max_size=12)


@st.composite
def commented(draw: st.DrawFn) -> tuple[str, list[str], ast.Mission]:
    """A generated mission's text, lines joined at random (the language is free-form),
    with comments and blank lines sprinkled in; and the comments, in order."""
    mission = draw(missions())
    lines: list[str] = []
    for line in format_mission(mission).split("\n")[:-1]:
        if lines and lines[-1].strip() and line.strip() and draw(st.integers(0, 3)) == 0:
            lines[-1] += " " + line.strip()
        else:
            lines.append(line)
    out: list[str] = []
    texts: list[str] = []
    for line in lines:
        choice = draw(st.integers(0, 5))
        if choice == 0:
            texts.append(f"# c{len(texts)} {draw(_WORDS)}".rstrip())
            out.append(" " * draw(st.integers(0, 6)) + texts[-1])
        elif choice == 1:
            out.append("")
        if choice == 2 and line.strip():
            texts.append(f"#c{len(texts)}{draw(_WORDS)}".rstrip())
            out.append(line + " " * draw(st.integers(1, 3)) + texts[-1])
        else:
            out.append(line)
    return "\n".join(out) + "\n", texts, mission


@pytest.mark.slow
@given(commented())
@settings(max_examples=30)
def test_formatting_keeps_comments_tree_and_is_idempotent(
    case: tuple[str, list[str], ast.Mission],
) -> None:
    text, texts, mission = case
    formatted = format_source(text, "gen.coral")
    assert _comments(formatted) == texts
    assert format_source(formatted, "gen.coral") == formatted
    assert _tree(formatted) == mission
    assert "\n\n\n" not in formatted and not formatted.startswith("\n")


@st.composite
def interrupted(draw: st.DrawFn) -> tuple[str, list[str], ast.Mission]:
    """A generated mission broken between any two tokens (except a number and its unit,
    which share a line) by comments, line breaks and blank lines."""
    mission = draw(missions())
    text = format_mission(mission)
    starts = [0]
    for line in text.split("\n"):
        starts.append(starts[-1] + len(line) + 1)
    tokens, _ = tokenize(text, "gen.coral")
    pieces: list[str] = []
    texts: list[str] = []
    at = 0
    for token, following in pairwise(tokens):
        end = starts[token.end_line - 1] + token.end_col - 1
        pieces.append(text[at:end])
        at = end
        if token.kind in (Kind.INT, Kind.FLOAT) and following.kind is Kind.IDENT:
            continue
        choice = draw(st.integers(0, 7))
        if choice == 0:
            texts.append(f"# t{len(texts)}")
            pieces.append("  " + texts[-1] + "\n")
        elif choice == 1:
            texts.append(f"# f{len(texts)}")
            pieces.append("\n" + texts[-1] + "\n")
        elif choice == 2:
            pieces.append("\n\n")
    pieces.append(text[at:])
    return "".join(pieces), texts, mission


@pytest.mark.slow
@given(interrupted())
@settings(max_examples=30)
def test_comments_between_any_tokens_survive_in_order(
    case: tuple[str, list[str], ast.Mission],
) -> None:
    text, texts, mission = case
    formatted = format_source(text, "gen.coral")
    assert _comments(formatted) == texts
    assert format_source(formatted, "gen.coral") == formatted
    assert _tree(formatted) == mission


_SMALL = LintOptions(max_states=500, time_limit=60.0)
"""A small state budget for the race rule: generated missions can have large state
spaces, and the same budget before and after formatting is all the test needs."""


def _findings(text: str, path: Path | None = None) -> list[tuple[str, str]]:
    """Lint's findings (code and message, which names the element) of ``text``, after
    its suppressions: one silenced differently changes the list."""
    result = compile_source(text, str(path or "m.coral"), base_dir=path.parent if path else None)
    return sorted((d.code, d.message) for d in lint(result, _SMALL))


@pytest.mark.parametrize("path", MISSION_FILES, ids=lambda p: str(p.relative_to(REPO)))
def test_formatting_a_mission_file_never_changes_lint(path: Path) -> None:
    text = path.read_text()
    assert _findings(format_source(text, str(path)), path) == _findings(text, path)


ALLOW_RACE = HEADER + "place s = 1, a, b\nfinal { a }\nfinal { b }\n"


def test_statements_one_suppression_covers_together_are_kept_as_written() -> None:
    line = "transition ta wait {s} signal {a} transition tb wait { s } signal { b }"
    text = ALLOW_RACE + line + "  # coral: allow CORAL207 -- either\nfinal   {a}\n"
    assert format_source(text, "m.coral").splitlines()[-2:] == [
        line + "  # coral: allow CORAL207 -- either",
        "final { a }",
    ]


@pytest.mark.parametrize(
    "text",
    [
        pytest.param(  # an allow after a one-line transition, another one below it
            ALLOW_RACE
            + "transition go_north wait { s } signal { a }  # coral: allow CORAL207 -- why\n"
            "transition go_south wait { s } signal { b }\n",
            id="after-a-one-line-transition",
        ),
        pytest.param(
            ALLOW_RACE + "transition go_north wait { s } signal { a }\n"
            "transition go_south wait { s } signal { b }  # coral: allow CORAL207 -- why\n",
            id="on-the-finding-line",
        ),
        pytest.param(  # the reviewer's case B: a commented place list
            HEADER + "place start = 1,\n"
            "      spare,   # coral: allow CORAL203 -- reserved\n"
            "      done,    # where it ends\n"
            "      other    # the other end\n"
            "final { done }\nfinal { other }\n"
            "transition t wait { start } signal { done }\n"
            "transition u priority 1 wait { start } signal { other }\n",
            id="a-commented-place-list",
        ),
        pytest.param(  # two statements on one line, the allow covering both
            HEADER + "place s = 1, a, b, c\nfinal { a }\nfinal { b }\n"
            "transition ta wait { s } signal { a } transition tb wait { s } signal { b }"
            "  # coral: allow CORAL207 -- either\n",
            id="statements-sharing-a-line",
        ),
        pytest.param(  # the second review's case A: the list's first place on the next line
            HEADER + "place s = 1, a\nfinal { a }\ntransition t wait { s } signal { a }\n"
            "place   # coral: allow CORAL203 -- reserved\nspare\n",
            id="allow-after-a-bare-place-keyword",
        ),
        pytest.param(  # the same for an operator input
            HEADER + "place s = 1, a\nfinal { a }\ntransition t wait { s } signal { a }\n"
            "input   # coral: allow CORAL209 -- not wired yet\nstop\n",
            id="allow-after-a-bare-input-keyword",
        ),
        pytest.param(  # an allow alone on a line above a place joined to the list
            HEADER + "place s = 1, a, b,\n# coral: allow CORAL203 -- later\nc\n"
            "final { a }\ntransition t wait { s } signal { a }\n",
            id="own-line-allow-inside-a-list",
        ),
    ],
)
def test_formatting_never_changes_what_a_suppression_silences(text: str) -> None:
    formatted = format_source(text, "m.coral")
    assert _findings(formatted) == _findings(text)
    assert format_source(formatted, "m.coral") == formatted


def _compile_codes(text: str) -> list[str]:
    return [d.code for d in compile_source(text, "m.coral").diagnostics]


REVIEW_C = HEADER + (  # the second review's case C: a trailing comment that reads like a header
    "place s = 1, a\nfinal { a }\ntransition t wait {\n"
    " s  # coral: part of the retry fix (#12)\n } signal { a } # last\n"
)
REAL_HEADER = "# coral: part of whole.coral\n\nplace   a,b\n"
PART_CASES = [
    pytest.param(REVIEW_C, id="trailing-would-become-own-line"),
    pytest.param(  # the reverse: a misplaced header after a trailing comment
        HEADER + "place s = 1, a\nfinal { a }\ntransition t wait {\n"
        " s  # first\n# coral: part of whole.coral\n } signal { a }\n",
        id="own-line-would-become-trailing",
    ),
    pytest.param(  # a misplaced header the list's comma would lift above the first declaration
        "place a\n# coral: part of whole.coral\n, b\n",
        id="own-line-would-move-above-the-first-declaration",
    ),
    pytest.param(  # a form feed before it: no header as written, one if re-indented
        "\f# coral: part of whole.coral\nplace a, b\n",
        id="form-feed-indented",
    ),
    pytest.param(REAL_HEADER, id="a-real-header"),
]


@pytest.mark.parametrize("text", PART_CASES)
def test_formatting_never_changes_what_a_part_header_comment_means(text: str) -> None:
    formatted = format_source(text, "m.coral")
    assert _compile_codes(formatted) == _compile_codes(text)
    assert _comments(formatted) == _comments(text)
    assert format_source(formatted, "m.coral") == formatted


def test_only_the_statements_around_a_header_like_comment_keep_their_layout() -> None:
    formatted = format_source(REVIEW_C.replace("place s = 1, a", "place   s=1,a"), "m.coral")
    assert formatted.splitlines()[2] == "place s = 1, a"
    assert formatted.splitlines()[-3:] == REVIEW_C.splitlines()[-3:]
    # a real header stays where it is; the rest is laid out as usual
    assert format_source(REAL_HEADER, "m.coral") == "# coral: part of whole.coral\n\nplace a, b\n"


_PART_COMMENTS = [
    "# coral: part of whole.coral",  # a header where the compiler accepts one
    "# coral: part of the retry fix (#12)",  # a malformed one
    "#coral:part of other.coral",
    "# plain",
]


@st.composite
def with_part_comments(draw: st.DrawFn) -> str:
    """A generated mission broken between any two tokens by comments that read like a
    part's header (well formed or not), after code or alone on their line, and maybe
    one before the first statement."""
    text = format_mission(draw(missions()))
    starts = [0]
    for line in text.split("\n"):
        starts.append(starts[-1] + len(line) + 1)
    tokens, _ = tokenize(text, "gen.coral")
    pieces = [draw(st.sampled_from(["", "", *(c + "\n" for c in _PART_COMMENTS)]))]
    at = 0
    for token, following in pairwise(tokens):
        end = starts[token.end_line - 1] + token.end_col - 1
        pieces.append(text[at:end])
        at = end
        if token.kind in (Kind.INT, Kind.FLOAT) and following.kind is Kind.IDENT:
            continue
        comment = draw(st.sampled_from(_PART_COMMENTS))
        choice = draw(st.integers(0, 6))
        pieces.append(
            ["  " + comment + "\n", "\n" + comment + "\n", "\n", "\n" + comment + "\n\n"][choice]
            if choice < 4
            else text[at : starts[following.line - 1] + following.col - 1]
        )
        at = starts[following.line - 1] + following.col - 1
    pieces.append(text[at:])
    return "".join(pieces)


@pytest.mark.slow
@given(with_part_comments())
@settings(max_examples=60, deadline=None)
def test_formatting_keeps_the_compile_diagnostics_of_part_header_comments(text: str) -> None:
    formatted = format_source(text, "gen.coral")
    assert _compile_codes(formatted) == _compile_codes(text)
    assert _comments(formatted) == _comments(text)
    assert format_source(formatted, "gen.coral") == formatted


_CODES = ["CORAL201", "CORAL202", "CORAL203", "CORAL204", "CORAL205", "CORAL207", "CORAL209"]


@st.composite
def suppressed(draw: st.DrawFn) -> str:
    """A generated mission re-spaced at random between any two tokens (statements
    joined on one line, lists broken, blank lines) with ``# coral: allow`` comments,
    after code or alone on their line, for codes lint may report."""
    text = format_mission(draw(missions()))
    starts = [0]
    for line in text.split("\n"):
        starts.append(starts[-1] + len(line) + 1)

    def offset(line: int, col: int) -> int:
        return starts[line - 1] + col - 1

    tokens, _ = tokenize(text, "gen.coral")
    pieces: list[str] = []
    for token, following in pairwise(tokens):
        end = offset(token.end_line, token.end_col)
        pieces.append(text[offset(token.line, token.col) : end])
        if token.kind in (Kind.INT, Kind.FLOAT) and following.kind is Kind.IDENT:
            pieces.append(" ")  # a number and its unit share a line
            continue
        allow = f"# coral: allow {draw(st.sampled_from(_CODES))}" + draw(
            st.sampled_from([" -- why", " -- why", ""])  # no reason: CORAL208
        )
        spacing = [" ", "\n", "\n\n", f"  {allow}\n", f"\n{allow}\n", f"\n{allow}\n\n"]
        choice = draw(st.integers(0, 2 * len(spacing) - 1))
        # half the time the printer's own spacing, so statements keep their shape
        pieces.append(
            spacing[choice]
            if choice < len(spacing)
            else text[end : offset(following.line, following.col)]
        )
    return "".join(pieces) + "\n"


@pytest.mark.slow
@given(suppressed())
@settings(max_examples=60, deadline=None)
def test_formatting_never_changes_lint_findings(text: str) -> None:
    formatted = format_source(text, "gen.coral")
    assert _findings(formatted) == _findings(text)
    assert format_source(formatted, "gen.coral") == formatted


def test_suppressions_silence_the_same_findings_after_formatting() -> None:
    text = HEADER + (
        "const UNUSED = 3  # coral: allow CORAL202 -- kept for the next version\n"
        "place a = 1, b, c\n"
        "final { b } final { c }\n"
        "# coral: allow CORAL207 -- either order is fine here\n"
        "transition t wait { a } signal { b }\n"
        "transition u wait { a } signal { c }  # coral: allow CORAL207 -- the same race\n"
    )
    bare = "\n".join(line.split("#")[0] for line in text.split("\n"))

    def findings(source: str) -> list[str]:
        return [d.code for d in lint(compile_source(source, "m.coral"))]

    assert findings(bare) == ["CORAL202", "CORAL207"]
    assert findings(text) == []
    assert findings(format_source(text, "m.coral")) == []


KITCHEN_SINK = HEADER + (
    'const LABEL = "say \\"hi\\"\\tthen # not a comment"  # a string\n'
    "const SPEED = 0.5 m/s\n"
    "const DOWN = -2.0 m\n"
    "input stop  # the operator's\n"
    "place a = 1 capacity 2, b, c, d\n"
    'include "other.coral"\n'
    "transition t priority 2 wait { a*2, stop } action { ROMEO(DEPTH?, z = DOWN,"
    " time_out = 60 s) -> { done: { b, c }, timeout: ignore } }\n"
    "transition u wait { b } signal { d*1 }\n"
    "final { d }\n"
    "assert never { a, d }\n"
    "assert reachable { d }\n"
    "assert bound { a, b } <= 3\n"
    "assert always a + b*2 <= 3  # a sum\n"
    "assert eventually final or deadlock\n"
    "assert a leadsto (b or c)\n"
    "assert ltl G (fires(t.done) -> F d)\n"
    "assert ctl AG E [ not d U (d and not in_flight(t)) ]\n"
    "require termination\n"
)


def test_every_construct_survives_formatting() -> None:
    formatted = format_source(KITCHEN_SINK, "k.coral")
    assert _tree(formatted) == _tree(KITCHEN_SINK)
    assert format_source(formatted, "k.coral") == formatted
    assert _comments(formatted) == ["# a string", "# the operator's", "# a sum"]


@given(st.text(alphabet='ab1 #"\n{}=,*', max_size=60).map(lambda s: HEADER + "place " + s))
@settings(max_examples=200)
def test_any_text_formats_or_raises_compile_error(text: str) -> None:
    try:
        formatted = format_source(text, "any.coral")
    except CompileError as error:
        assert error.diagnostics
        return
    assert _comments(formatted) == _comments(text)
    assert format_source(formatted, "any.coral") == formatted
