"""A missing ',' after a number or a constant's name is one error at the name that
follows, with no knock-on."""

from __future__ import annotations

import pytest

from coral_lang import ast
from coral_lang.compiler import compile_source
from coral_lang.parser import parse

HEADER = "mission m\nvehicle ROMEO\n"
UNIT_HINT = " (or a unit after the number: s, min, ...)"


def _errors(body: str) -> list[str]:
    """Every error of compiling ``body`` (parse and compile), as ``line:col: message``."""
    result = compile_source(HEADER + body, "m.coral")
    return [f"{d.span.line}:{d.span.col}: {d.message}" for d in result.errors if d.span]


def test_the_issue_example_is_one_error_at_the_name() -> None:
    body = "place start = 1 done\nfinal { done }\ntransition t wait { start } signal { done }\n"
    result = compile_source(HEADER + body, "m.coral")
    [error] = result.errors
    assert error.code == "CORAL001"
    assert error.render({"m.coral": HEADER + body}).splitlines()[0] == (
        f"m.coral:3:17: error: expected ',' between places{UNIT_HINT} [CORAL001]"
    )


def test_the_places_after_the_missing_comma_are_still_declared() -> None:
    mission, diagnostics = parse(HEADER + "place start = 1 done capacity 3, x = 2 y\n", "m.coral")
    assert len(diagnostics) == 2
    [places] = mission.declarations
    assert isinstance(places, ast.Places)
    assert [p.name for p in places.places] == ["start", "done", "x", "y"]


@pytest.mark.parametrize(
    ("body", "expected"),
    [
        (
            "place a capacity 2 b = 1\nfinal { b }\ntransition t wait { a } signal { b }\n",
            f"3:20: expected ',' between places{UNIT_HINT}",
        ),
        (
            "place a = 2, b, c\nfinal { c }\ntransition t wait { a*2 b } signal { c }\n",
            "5:25: expected ',' between places",  # a weight never takes a unit: no hint
        ),
        (
            "place a = 1, b\nfinal { b }\ntransition t wait { a }\n"
            "    action { ROMEO(GOTO, x = 1 y = 2 m, psi = 0 deg) -> { ack: b, error: b } }\n",
            f"6:32: expected ',' between arguments{UNIT_HINT}",
        ),
        (
            "place a = 1, b\nfinal { b }\ntransition t wait { a }\n"
            "    action { ROMEO(GOTO, x = 1 m y = 2 m, psi = 0 deg) -> { ack: b, error: b } }\n",
            "6:34: expected ',' between arguments",
        ),
        (
            "place a = 1, b\nfinal { b }\ntransition t wait { a }\n"
            "    action { ROMEO(GOTO, x = 1 m, y = 2 m, psi = 0 deg) -> { ack: b*1 error: b } }\n",
            "6:71: expected ',' between replies",
        ),
    ],
)
def test_each_list_reports_one_error_and_goes_on(body: str, expected: str) -> None:
    assert _errors(body) == [expected]


@pytest.mark.parametrize(
    ("body", "expected"),
    [
        ("const T = 60 sec\n", "3:14: unknown unit 'sec'"),  # not in a list: a unit
        (  # an argument's name is followed by '=': 'metres' is a misspelt unit
            "place a = 1, b\nfinal { b }\ntransition t wait { a }\n"
            "    action { ROMEO(DEPTH, z = 2 metres) -> { ack: b, error: b } }\n",
            "6:33: unknown unit 'metres'",
        ),
    ],
)
def test_a_name_that_cannot_start_the_next_item_is_still_an_unknown_unit(
    body: str, expected: str
) -> None:
    assert _errors(body)[:1] == [expected]


@pytest.mark.parametrize(
    ("body", "expected"),
    [
        (  # the reviewer's case: a constant as the count, then a missing ','
            "const N = 2\nplace start = N done\nfinal { done }\n"
            "transition t wait { start } signal { done }\n",
            "4:17: expected ',' between places",
        ),
        (
            "const N = 2\nplace a = 1 capacity N b\nfinal { b }\n"
            "transition t wait { a } signal { b }\n",
            "4:24: expected ',' between places",
        ),
        (
            "const N = 2\nplace a = 2, b, c\nfinal { c }\n"
            "transition t wait { a*N b } signal { c }\n",
            "6:25: expected ',' between places",
        ),
        (  # the issue's token-set case: a weight takes no unit, so no unit hint
            "place start = 1, done\nfinal { done }\n"
            "transition t wait { start*2 done } signal { done }\n",
            "5:29: expected ',' between places",
        ),
    ],
)
def test_a_constant_count_or_a_weight_is_one_error_without_a_unit_hint(
    body: str, expected: str
) -> None:
    assert _errors(body) == [expected]


def test_the_places_after_a_constant_count_are_still_declared() -> None:
    mission, diagnostics = parse(HEADER + "place start = N done, x\n", "m.coral")
    assert [d.message for d in diagnostics] == ["expected ',' between places"]
    [places] = mission.declarations
    assert isinstance(places, ast.Places)
    assert [p.name for p in places.places] == ["start", "done", "x"]


def test_a_name_on_the_next_line_is_no_missing_comma() -> None:
    _, diagnostics = parse(HEADER + "place a = 1\nb\n", "m.coral")
    assert [d.message.split(" (")[0] for d in diagnostics] == ["expected a declaration"]
