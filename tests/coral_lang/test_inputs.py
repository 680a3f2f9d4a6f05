"""Operator inputs in the language: ``input NAME, ...`` parses, prints, compiles to an
armed place and an INPUT transition, and is refused where only the operator may mark
it; PNML and DOT carry the new kinds."""

from __future__ import annotations

from pathlib import Path

import pytest

from coral_lang import ast
from coral_lang.compiler import compile_file, compile_source
from coral_lang.diagnostics import PnmlError
from coral_lang.dot import OPERATOR_COLOR, to_dot
from coral_lang.net import MAX_INPUTS, Net, Place, PlaceKind, TransitionKind
from coral_lang.parser import parse
from coral_lang.pnml import parse_pnml, to_pnml
from coral_lang.printer import format_mission
from tests.conftest import EXAMPLES

HEADER = "mission m\nvehicle ROMEO\n"
BODY = (
    "place start = 1, done, aborted\n"
    "final { done }\nfinal { aborted }\n"
    "transition go wait { start } signal { done }\n"
    "transition stop_now wait { start, abort_requested } signal { aborted }\n"
)


def _compile(text: str) -> object:
    result = compile_source(text, "m.coral")
    assert result.errors == [], [d.render() for d in result.errors]
    return result.net


def test_an_input_compiles_to_an_armed_place_and_an_operator_transition() -> None:
    result = compile_source(HEADER + "input abort_requested\n" + BODY, "m.coral")
    assert result.errors == []
    net = result.net
    assert net is not None
    place = net.place("abort_requested")
    assert place.kind is PlaceKind.MISSION and place.initial == 0 and place.capacity is None
    armed = net.place("abort_requested.armed")
    assert armed.kind is PlaceKind.ARMED and armed.initial == 1
    assert armed.armed_of == "abort_requested"
    assert armed.span is not None and (armed.span.line, armed.span.col) == (3, 7)
    operator = net.input_transition("abort_requested")
    assert operator.name == "abort_requested.operator"
    assert operator.kind is TransitionKind.INPUT
    assert operator.inputs == (("abort_requested.armed", 1),)
    assert operator.outputs == (("abort_requested", 1),)
    assert operator.span == armed.span
    assert operator.describe() == "the operator gives input abort_requested"
    assert net.inputs == ("abort_requested",)


def test_several_inputs_on_one_line_and_the_same_input_twice_are_one_each() -> None:
    text = HEADER + "input abort_requested, surface_now\ninput abort_requested\n" + BODY
    text += "transition up wait { done, surface_now } signal { done }\n"
    net = _compile(text)
    assert net.inputs == ("abort_requested", "surface_now")  # type: ignore[attr-defined]


def test_an_input_may_also_be_declared_as_a_plain_place() -> None:
    net = _compile(HEADER + "place abort_requested\ninput abort_requested\n" + BODY)
    assert net.inputs == ("abort_requested",)  # type: ignore[attr-defined]


def test_an_input_declared_in_two_included_files_is_one_input(tmp_path: Path) -> None:
    (tmp_path / "part.coral").write_text(
        "vehicle ROMEO\ninput abort_requested\nplace start\n"
        "transition late wait { done, abort_requested } signal { done }\n"
    )
    (tmp_path / "main.coral").write_text(
        HEADER + 'include "part.coral"\ninput abort_requested\n' + BODY
    )
    result = compile_file(tmp_path / "main.coral")
    assert result.errors == [], [d.render() for d in result.errors]
    assert result.net is not None
    assert result.net.inputs == ("abort_requested",)
    assert sum(p.kind is PlaceKind.ARMED for p in result.net.places) == 1


def test_at_most_max_inputs() -> None:
    names = [f"i{k}" for k in range(MAX_INPUTS)]
    assert _compile(
        HEADER + "input " + ", ".join(names) + "\n" + BODY.replace("abort_requested", "i0")
    )
    result = compile_source(
        HEADER
        + "input "
        + ", ".join([*names, "extra"])
        + "\n"
        + BODY.replace("abort_requested", "i0"),
        "m.coral",
    )
    assert [d.code for d in result.errors] == ["CORAL010"]
    assert "'extra' would be number 9" in result.errors[0].message


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        (HEADER + "input\n", "expected an operator input name"),
        (HEADER + "input a b\n", "expected a declaration"),
        (HEADER + "input final\n", "found keyword 'final'"),
        (HEADER + "transition input wait { a } signal { b }\n", "found keyword 'input'"),
        (HEADER + "place a = 1\ntransition t wait { a } signal { input }\n", "keyword 'input'"),
    ],
)
def test_keyword_misuse_is_a_syntax_error(text: str, fragment: str) -> None:
    result = compile_source(text, "m.coral")
    assert result.errors and result.errors[0].code == "CORAL001"
    assert fragment in result.errors[0].message


def test_signalling_an_input_names_the_transition_and_its_signal_clause() -> None:
    text = HEADER + "input abort_requested\n" + BODY
    text += "transition fake wait { done } signal { abort_requested }\n"
    result = compile_source(text, "m.coral")
    assert [d.code for d in result.errors] == ["CORAL010"]
    error = result.errors[0]
    assert "transition 'fake' signals operator input 'abort_requested'" in error.message
    assert error.span is not None and (error.span.line, error.span.col) == (9, 40)
    assert any("declared an input at m.coral:3:7" in n for n in error.notes)


def test_the_printer_prints_inputs_and_they_parse_back() -> None:
    text = HEADER + "input abort_requested, surface_now\n" + BODY
    mission, diagnostics = parse(text, "m.coral")
    assert diagnostics == []
    inputs = [d for d in mission.declarations if isinstance(d, ast.Inputs)]
    assert [n.name for n in inputs[0].names] == ["abort_requested", "surface_now"]
    printed = format_mission(mission)
    assert "input abort_requested, surface_now\n" in printed
    assert parse(printed, "again.coral")[0] == mission


def test_inputs_change_the_digest_and_survive_reprinting() -> None:
    with_input = _compile(HEADER + "input abort_requested\n" + BODY)
    without = _compile(HEADER + "place abort_requested\n" + BODY)
    assert with_input.digest() != without.digest()  # type: ignore[attr-defined]
    mission, _ = parse(HEADER + "input abort_requested\n" + BODY, "m.coral")
    again = _compile(format_mission(mission))
    assert again.digest() == with_input.digest()  # type: ignore[attr-defined]


def test_pnml_round_trip_keeps_inputs_and_the_digest() -> None:
    net = compile_file(EXAMPLES / "faulty" / "unhandled_abort.coral").raise_for_errors()
    back = parse_pnml(to_pnml(net), "x.pnml")
    assert back.digest() == net.digest()
    assert back.inputs == ("abort_requested",)
    assert back.place("abort_requested.armed").kind is PlaceKind.ARMED


def test_a_plain_pnml_net_has_no_inputs() -> None:
    net = compile_file(EXAMPLES / "faulty" / "deadlock.coral").raise_for_errors()
    back = parse_pnml(to_pnml(net), "x.pnml")
    assert back.inputs == ()
    assert "operator-input" not in to_pnml(net) and "armed" not in to_pnml(net)


def test_pnml_with_too_many_armed_places_is_refused() -> None:
    armed = tuple(
        Place(f"i{k}.armed", 1, PlaceKind.ARMED, armed_of=f"i{k}") for k in range(MAX_INPUTS + 1)
    )
    net = Net("many", armed, ())
    with pytest.raises(PnmlError, match=f"{MAX_INPUTS + 1} armed places .* at most {MAX_INPUTS}"):
        parse_pnml(to_pnml(net), "x.pnml")


def test_dot_fills_inputs_and_armed_places_in_the_operator_colour() -> None:
    net = compile_file(EXAMPLES / "faulty" / "unhandled_abort.coral").raise_for_errors()
    text = to_dot(net)
    lines = [line for line in text.splitlines() if OPERATOR_COLOR in line]
    assert len(lines) == 2
    assert any("the operator gives input abort_requested" in line for line in lines)
    assert any("abort_requested.armed" in line for line in lines)
