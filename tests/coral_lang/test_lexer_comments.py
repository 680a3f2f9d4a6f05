"""The lexer hands comments to the formatter on request, and to nobody else."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from coral_lang.lexer import Kind, Token, tokenize

TEXT = (
    "# first line   \n"
    'const NAME = "a # b"  # after a string\r\n'
    "place p = 1 # no space before\n"
    "  ## indented, doubled\n"
)


def test_comments_come_back_with_their_place_and_without_trailing_space() -> None:
    comments: list[Token] = []
    tokenize(TEXT, "c.coral", comments)
    assert [(c.kind, c.text, c.line, c.col, c.end_col) for c in comments] == [
        (Kind.COMMENT, "# first line", 1, 1, 13),
        (Kind.COMMENT, "# after a string", 2, 23, 39),
        (Kind.COMMENT, "# no space before", 3, 13, 30),
        (Kind.COMMENT, "## indented, doubled", 4, 3, 23),
    ]


def test_a_hash_inside_a_string_is_part_of_the_string() -> None:
    tokens, diagnostics = tokenize(TEXT, "c.coral")
    assert diagnostics == []
    assert [t.text for t in tokens if t.kind is Kind.STRING] == ["a # b"]


@given(st.text(alphabet='ab1 #"\n{}=', max_size=80))
@settings(max_examples=200)
def test_asking_for_comments_changes_no_token(text: str) -> None:
    comments: list[Token] = []
    assert tokenize(text, "c.coral", comments) == tokenize(text, "c.coral")
    assert all(c.kind is Kind.COMMENT and c.text.startswith("#") for c in comments)
    assert all(t.kind is not Kind.COMMENT for t in tokenize(text, "c.coral")[0])
