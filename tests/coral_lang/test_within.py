"""``assert within T { places }``: the deadline a mission states for timed analysis.

Parsing, the errors (each message), what the net carries (seconds, whatever the unit),
digest stability for every net without a deadline, the printer's and the formatter's
round trips, and the PNML export.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from analysis.lint import lint
from coral_lang import ast
from coral_lang.compiler import compile_file, compile_source
from coral_lang.diagnostics import PnmlError
from coral_lang.formatting import format_source
from coral_lang.net import Assertion, AssertKind, Net
from coral_lang.parser import parse
from coral_lang.pnml import parse_pnml, to_pnml
from coral_lang.printer import format_mission
from coral_lang.profile import load_profile
from tests.conftest import EXAMPLES, REPO
from tests.coral_lang.strategies import missions

HEADER = "mission m\nvehicle ROMEO\n"
BODY = (
    "const T_MISSION = 10 min\n"
    'const LABEL = "x"\n'
    "const N = 3\n"
    "const NEG = -5 s\n"
    "place a = 1, b, mission_complete\n"
    "transition t wait { a } signal { b }\n"
    "transition u wait { b } signal { mission_complete }\n"
    "final { mission_complete }\n"
)
LINE = 11  # the line the assertion under test is on, after HEADER + BODY
PROFILES = [load_profile(p) for p in sorted((EXAMPLES / "profiles").glob("*.yaml"))]
MISSION_FILES = sorted([*EXAMPLES.rglob("*.coral"), *(REPO / "tests" / "data").rglob("*.coral")])


def _net(assertion: str) -> Net:
    return compile_source(HEADER + BODY + assertion + "\n", "m.coral").raise_for_errors()


def _only(net: Net) -> Assertion:
    (assertion,) = net.assertions
    return assertion


# -- parsing and compiling -------------------------------------------------------------


def test_the_brief_example_parses_to_a_within_declaration() -> None:
    mission, diagnostics = parse(HEADER + "assert within 600 s { mission_complete }\n")
    assert diagnostics == []
    (declaration,) = mission.declarations
    assert declaration == ast.AssertDecl(
        ast.AssertKind.WITHIN,
        (ast.TokenRef("mission_complete"),),
        None,
        deadline=ast.Number(600, "s"),
    )
    assert (declaration.span.line, declaration.span.col) == (3, 1)
    assert (declaration.span.end_line, declaration.span.end_col) == (3, 41)


@pytest.mark.parametrize(
    ("written", "seconds"),
    [
        ("600 s", 600.0),
        ("10 min", 600.0),
        ("1.5 h", 5400.0),
        ("250 ms", 0.25),
        ("T_MISSION", 600.0),
        ("0.001 ms", 1e-6),
    ],
)
def test_the_net_carries_the_deadline_in_seconds(written: str, seconds: float) -> None:
    assertion = _only(_net(f"assert within {written} {{ b, mission_complete*2 }}"))
    assert assertion.kind is AssertKind.WITHIN
    assert assertion.places == (("b", 1), ("mission_complete", 2))
    assert assertion.deadline_s == pytest.approx(seconds, rel=1e-12)
    assert assertion.bound is None and assertion.formula is None and not assertion.temporal
    assert assertion.text == f"assert within {written} {{ b, mission_complete*2 }}"
    assert assertion.span is not None and (assertion.span.line, assertion.span.col) == (LINE, 1)


def test_describe_gives_seconds_whatever_the_unit() -> None:
    assert _only(_net("assert within 10 min { b }")).describe() == "assert within 600 s { b }"
    assert _only(_net("assert within 250 ms { b*2 }")).describe() == (
        "assert within 0.25 s { b*2 }"
    )


def test_a_deadline_takes_its_place_among_the_assertions_in_source_order() -> None:
    net = _net(
        "assert never { a, mission_complete }\n"
        "assert within 1 min { mission_complete }\n"
        "assert always a + b <= 1\n"
        "assert reachable { b }"
    )
    kinds = [a.kind for a in net.assertions]
    assert kinds == [AssertKind.NEVER, AssertKind.WITHIN, AssertKind.LTL, AssertKind.REACHABLE]


@pytest.mark.parametrize(
    "assertion",
    [
        "assert within leadsto done",
        "assert within and a leadsto done",
        "assert within*2 leadsto done",
        "assert within + a >= 1 leadsto done",
        "assert always within",
        "assert never { within }",
    ],
)
def test_a_place_named_within_can_still_be_used(assertion: str) -> None:
    """``within`` is not reserved: missions with a place of that name keep compiling."""
    text = HEADER + "place a = 1, within, done\ntransition t wait { a } signal { within }\n"
    result = compile_source(text + assertion + "\n", "m.coral")
    assert result.errors == [], [d.render() for d in result.errors]
    assert result.net is not None
    assert all(a.kind is not AssertKind.WITHIN for a in result.net.assertions)


# -- errors ------------------------------------------------------------------------------

ERRORS: list[tuple[str, str]] = [
    (
        "assert within { b }",
        "11:15: expected a duration after 'assert within', found '{' [CORAL001]",
    ),
    (
        "assert within",
        "12:1: expected a duration after 'assert within', found end of file [CORAL001]",
    ),
    (
        "assert within 600 m { b }",
        "11:15: the deadline of 'assert within' must be a time (s, ms, min, h), got '600 m' "
        "(length) [CORAL005]",
    ),
    (
        "assert within 90 deg { b }",
        "11:15: the deadline of 'assert within' must be a time (s, ms, min, h), got '90 deg' "
        "(angle) [CORAL005]",
    ),
    (
        "assert within 600 { b }",
        "11:15: the deadline of 'assert within' needs a time unit: write '600 s' "
        "(s, ms, min, h) [CORAL005]",
    ),
    (
        "assert within N { b }",
        "11:15: the deadline of 'assert within' needs a time unit: write '3 s' "
        "(s, ms, min, h) [CORAL005]",
    ),
    (
        "assert within LABEL { b }",
        "11:15: the deadline of 'assert within' must be a time, got text \"x\" [CORAL005]",
    ),
    (
        "assert within -5 s { b }",
        "11:15: the deadline of 'assert within' must be more than 0 s, got -5 s [CORAL005]",
    ),
    (
        "assert within NEG { b }",
        "11:15: the deadline of 'assert within' must be more than 0 s, got -5 s [CORAL005]",
    ),
    (
        "assert within 0 s { b }",
        "11:15: the deadline of 'assert within' must be more than 0 s, got 0 s [CORAL005]",
    ),
    (
        "assert within 0.0 min { b }",
        "11:15: the deadline of 'assert within' must be more than 0 s, got 0.0 min [CORAL005]",
    ),
    (
        "assert within 1e308 h { b }",
        "11:15: the deadline of 'assert within' is out of range, got 1e+308 h [CORAL005]",
    ),
    ("assert within 1e400 s { b }", "11:15: number out of range: 1e400 [CORAL001]"),
    (
        "assert within T_MISION { b }",
        "11:15: unknown constant 'T_MISION' (did you mean 'T_MISSION'?) [CORAL002]",
    ),
    (
        "assert within 600 s { mision_complete }",
        "11:23: unknown place 'mision_complete' (did you mean 'mission_complete'?) [CORAL002]",
    ),
    (
        "assert within 600 s { }",
        "11:1: 'assert within' names no place, so it would hold at the start [CORAL005]",
    ),
    (
        "assert within 600 s b",
        "11:21: expected '{' after the deadline of 'assert within', found 'b' [CORAL001]",
    ),
    (
        "assert within 600 s { b, b }",
        "11:26: place 'b' appears twice in an assertion; write 'b*N' for N tokens [CORAL003]",
    ),
    ("assert within 600 s { b*0 }", "11:25: weight of 'b' must be at least 1, got 0 [CORAL005]"),
    (
        "assert witihn 600 s { b }",
        "11:8: expected 'never', 'reachable', 'bound', 'within', 'always', 'eventually', 'ltl', "
        "'ctl' or 'P leadsto Q' after 'assert', found 'witihn' (did you mean 'within'?) "
        "[CORAL001]",
    ),
]


@pytest.mark.parametrize(("assertion", "expected"), ERRORS, ids=[e[0] for e in ERRORS])
def test_each_mistake_gets_its_message(assertion: str, expected: str) -> None:
    result = compile_source(HEADER + BODY + assertion + "\n", "m.coral")
    assert result.net is None
    first = result.errors[0]
    assert first.span is not None
    assert f"{first.span.line}:{first.span.col}: {first.message} [{first.code}]" == expected


_PIECES = st.sampled_from(
    [
        *("assert ", "within ", "within", "600", " s", " m", "min", "-", "1e308", "0", "T_MISSION"),
        *(" { ", " }", "b", "*", "2", ",", "\n", " leadsto ", "place within", "const T = "),
    ]
)


@pytest.mark.slow
@given(st.lists(_PIECES, max_size=12))
@settings(max_examples=200, deadline=None)
def test_damaged_deadlines_give_diagnostics_not_exceptions(pieces: list[str]) -> None:
    result = compile_source(HEADER + BODY + "".join(pieces) + "\n", "fuzz.coral")
    for diagnostic in result.diagnostics:
        assert diagnostic.span is not None and diagnostic.span.line >= 1
        diagnostic.render(result.sources)
    if result.net is None:
        assert result.errors
    else:
        for assertion in result.net.assertions:
            if assertion.kind is AssertKind.WITHIN:
                deadline = assertion.deadline_s
                assert deadline is not None and math.isfinite(deadline) and deadline > 0


def test_a_bad_deadline_from_a_constant_points_at_the_constant() -> None:
    result = compile_source(HEADER + BODY + "assert within NEG { b }\n", "m.coral")
    assert result.errors[0].notes == ("'NEG' is defined at m.coral:6:1",)


def test_a_missing_duration_says_how_to_write_one() -> None:
    result = compile_source(HEADER + BODY + "assert within { b }\n", "m.coral")
    (error,) = result.errors
    assert error.notes == (
        "write the deadline before the places, e.g. 'assert within 600 s { done }'",
    )


def test_a_bad_deadline_and_a_bad_place_are_both_reported() -> None:
    result = compile_source(HEADER + BODY + "assert within 600 m { zzz }\n", "m.coral")
    assert sorted(d.code for d in result.errors) == ["CORAL002", "CORAL005"]


# -- canonical form and digest ------------------------------------------------------------


def _legacy_digest(net: Net) -> str:
    """The digest as computed before ``within`` existed: assertions as [kind, places,
    bound] (+ formula), ordered by kind, places, bound, formula."""

    def order(a: Assertion) -> tuple[str, list[list[str | int]], int, str]:
        places: list[list[str | int]] = sorted([p, w] for p, w in a.places)
        return a.kind.value, places, -1 if a.bound is None else a.bound, str(a.formula or "")

    def entry(a: Assertion) -> list[object]:
        base: list[object] = [a.kind.value, sorted([p, w] for p, w in a.places), a.bound]
        return base + ([str(a.formula)] if a.formula is not None else [])

    canonical = net.canonical()
    canonical["assertions"] = [entry(a) for a in sorted(net.assertions, key=order)]
    blob = json.dumps(canonical, sort_keys=True, separators=(",", ":"))
    return "sha256:" + hashlib.sha256(blob.encode()).hexdigest()


def _nets_without_a_deadline() -> list[Path]:
    """The mission files that compile alone (not mission parts, not the example that
    must not compile) and state no deadline."""
    out = []
    for path in MISSION_FILES:
        net = compile_file(path, PROFILES).net
        if net is not None and not any(a.kind is AssertKind.WITHIN for a in net.assertions):
            out.append(path)
    return out


@pytest.mark.parametrize("path", _nets_without_a_deadline(), ids=lambda p: str(p.relative_to(REPO)))
def test_nets_without_a_deadline_keep_their_digest(path: Path) -> None:
    net = compile_file(path, PROFILES).net
    assert net is not None
    assert net.digest() == _legacy_digest(net)


@pytest.mark.slow
@given(missions())
@settings(max_examples=15, deadline=None)
def test_generated_nets_without_a_deadline_keep_their_digest(mission: ast.Mission) -> None:
    net = compile_source(format_mission(mission), "gen.coral").raise_for_errors()
    assert net.digest() == _legacy_digest(net)


def test_the_deadline_is_part_of_the_digest_but_its_unit_is_not() -> None:
    plain = compile_source(HEADER + BODY, "m.coral").raise_for_errors().digest()
    in_seconds = _net("assert within 600 s { b }").digest()
    assert in_seconds != plain
    assert _net("assert within 10 min { b }").digest() == in_seconds
    assert _net("assert within T_MISSION { b }").digest() == in_seconds
    assert _net("assert within 601 s { b }").digest() != in_seconds
    assert _net("assert within 600 s { b*2 }").digest() != in_seconds
    assert _net("assert reachable { b }").digest() != in_seconds


def test_a_whole_number_deadline_is_the_same_as_its_float() -> None:
    """Nets built in code (analysis, tests) may pass ``deadline_s=600``: the canonical
    form must not tell it from the compiler's ``600.0``."""
    made = Assertion(AssertKind.WITHIN, (("b", 1),), deadline_s=600)
    assert made.canonical() == ["within", [["b", 1]], None, 600.0]
    assert json.dumps(made.canonical()) == json.dumps(
        _only(_net("assert within 10 min { b }")).canonical()
    )


def test_the_digest_does_not_depend_on_the_order_of_deadlines() -> None:
    one = _net("assert within 600 s { b }\nassert within 1 min { b }\nassert never { a, b }")
    two = _net("assert never { a, b }\nassert within 1 min { b }\nassert within 600 s { b }")
    assert one.digest() == two.digest()
    assert one.canonical()["assertions"] == [
        ["never", [["a", 1], ["b", 1]], None],
        ["within", [["b", 1]], None, 60.0],
        ["within", [["b", 1]], None, 600.0],
    ]


# -- printer and formatter -----------------------------------------------------------------

_TIME_UNITS = ("s", "ms", "min", "h")


@st.composite
def deadlines(draw: st.DrawFn) -> ast.Number:
    """A positive time as a mission writes it: a whole or decimal number and a unit."""
    value: int | float = draw(
        st.one_of(
            st.integers(1, 10**9),
            st.floats(1e-3, 1e9, allow_nan=False, allow_infinity=False),
        )
    )
    return ast.Number(value, draw(st.sampled_from(_TIME_UNITS)))


@st.composite
def missions_with_deadlines(draw: st.DrawFn) -> ast.Mission:
    """A generated valid mission with one to three ``within`` assertions added, on the
    places it declares (with weights), some through a time constant."""
    mission = draw(missions())
    places = [p.name for d in mission.declarations if isinstance(d, ast.Places) for p in d.places]
    added: list[ast.Declaration] = []
    for number in range(draw(st.integers(1, 3))):
        chosen = draw(st.lists(st.sampled_from(places), min_size=1, max_size=3, unique=True))
        tokens = tuple(
            ast.TokenRef(p, draw(st.one_of(st.none(), st.integers(1, 3).map(ast.Number))))
            for p in chosen
        )
        deadline: ast.Number | ast.Name = draw(deadlines())
        if draw(st.booleans()):
            name = f"T_DEADLINE_{number}"
            assert isinstance(deadline, ast.Number)
            added.append(ast.Const(name, deadline))
            deadline = ast.Name(name)
        added.append(ast.AssertDecl(ast.AssertKind.WITHIN, tokens, None, deadline=deadline))
    return dataclasses.replace(mission, declarations=(*mission.declarations, *added))


@pytest.mark.slow
@given(missions_with_deadlines())
@settings(max_examples=30, deadline=None)
def test_printed_deadlines_parse_back_and_compile_to_the_same_net(mission: ast.Mission) -> None:
    text = format_mission(mission)
    parsed, diagnostics = parse(text, "gen.coral")
    assert diagnostics == []
    assert parsed == mission
    net = compile_source(text, "gen.coral").raise_for_errors()
    within = [a for a in net.assertions if a.kind is AssertKind.WITHIN]
    assert within and all(
        a.deadline_s is not None and math.isfinite(a.deadline_s) and a.deadline_s > 0
        for a in within
    )
    again = compile_source(format_mission(parsed), "again.coral").raise_for_errors()
    assert again.digest() == net.digest()


@pytest.mark.parametrize(
    ("written", "printed"),
    [
        ("assert within 600 s { mission_complete }", "assert within 600 s { mission_complete }"),
        (
            "assert   within 600s{b,mission_complete*2}",
            "assert within 600 s { b, mission_complete*2 }",
        ),
        ("assert within 1.50 min {b}", "assert within 1.5 min { b }"),
        ("assert within\n    T_MISSION\n    { b }", "assert within T_MISSION { b }"),
        ("assert within 1e3 ms { b }", "assert within 1000.0 ms { b }"),
    ],
)
def test_the_printer_writes_the_canonical_form(written: str, printed: str) -> None:
    mission, diagnostics = parse(HEADER + BODY + written + "\n")
    assert diagnostics == []
    assert format_mission(mission).endswith("\n" + printed + "\n")


def test_the_formatter_lays_out_a_deadline_and_keeps_its_comments() -> None:
    text = (
        HEADER
        + BODY
        + "# the whole mission, in time\n"
        + "assert   within 10 min{ mission_complete }  # from the operator's brief\n"
        + "assert within T_MISSION {b}\n"
    )
    formatted = format_source(text, "m.coral")
    assert formatted.endswith(
        "# the whole mission, in time\n"
        "assert within 10 min { mission_complete }  # from the operator's brief\n"
        "assert within T_MISSION { b }\n"
    )
    assert format_source(formatted, "m.coral") == formatted
    before = compile_source(text, "m.coral").raise_for_errors()
    after = compile_source(formatted, "m.coral").raise_for_errors()
    assert after.digest() == before.digest()


def test_a_constant_used_only_as_a_deadline_is_not_reported_unused() -> None:
    text = HEADER + BODY.replace('const LABEL = "x"\n', "") + "assert within T_MISSION { b }\n"
    result = compile_source(text, "m.coral")
    findings = [d.message for d in lint(result) if d.code == "CORAL202"]
    assert sorted(findings) == ["constant 'N' is never used", "constant 'NEG' is never used"]


# -- PNML ----------------------------------------------------------------------------------


def test_a_deadline_travels_through_pnml_with_the_digest() -> None:
    net = _net("assert within 0.1 s { b }\nassert within 10 min { mission_complete*2 }")
    text = to_pnml(net)
    assert 'deadline-s="0.1"' in text and 'deadline-s="600.0"' in text
    again = parse_pnml(text)
    assert [a.deadline_s for a in again.assertions] == [0.1, 600.0]
    assert again.digest() == net.digest()
    assert again.assertions[1].describe() == "assert within 600 s { mission_complete*2 }"


def test_other_assertions_are_written_without_a_deadline() -> None:
    text = to_pnml(_net("assert never { a, b }"))
    assert "deadline-s" not in text


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ('deadline-s="600.0"', "", "kind 'within' has no deadline-s"),
        ('deadline-s="600.0"', 'deadline-s="0"', "deadline-s '0' is not a number of seconds"),
        ('deadline-s="600.0"', 'deadline-s="-1"', "deadline-s '-1' is not a number"),
        ('deadline-s="600.0"', 'deadline-s="nan"', "deadline-s 'nan' is not a number"),
        ('deadline-s="600.0"', 'deadline-s="inf"', "deadline-s 'inf' is not a number"),
        ('deadline-s="600.0"', 'deadline-s="soon"', "deadline-s 'soon' is not a number"),
        ('kind="never"', 'kind="never" deadline-s="5"', "kind 'never' has a deadline-s"),
    ],
)
def test_pnml_refuses_a_missing_or_bad_deadline(old: str, new: str, message: str) -> None:
    text = to_pnml(_net("assert within 600 s { b }\nassert never { a, b }"))
    assert old in text
    with pytest.raises(PnmlError, match=message):
        parse_pnml(text.replace(old, new), "forged.pnml")
