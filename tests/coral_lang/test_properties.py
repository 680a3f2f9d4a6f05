"""Temporal assertions and requirements: parsing, lowering to the formula tree,
printing, digests, PNML. The errors are rows of ``test_diagnostics_table.py``."""

from __future__ import annotations

from pathlib import Path

import pytest

from coral_lang import ast
from coral_lang import formula as fm
from coral_lang.compiler import compile_file, compile_source
from coral_lang.diagnostics import PnmlError
from coral_lang.net import AssertKind, Net
from coral_lang.parser import parse
from coral_lang.pnml import parse_pnml, to_pnml
from coral_lang.printer import format_expr, format_mission
from tests.conftest import EXAMPLES

HEADER = "mission m\nvehicle ROMEO\n"
MISSION = HEADER + (
    "const N = 2\n"
    "place start = 1, depth_set, depth_ok, abort, buf capacity 2\n"
    "final { depth_ok }\n"
    "final { abort }\n"
    "transition set_depth\n"
    "    wait { start }\n"
    "    action { ROMEO(DEPTH, z = 2.0) -> { ack: depth_set, error: abort } }\n"
    "transition check_depth\n"
    "    wait { depth_set }\n"
    "    action { ROMEO(DEPTH?, z = 2.0, time_out = 60) -> { done: depth_ok, timeout: abort } }\n"
    "transition log wait { abort } signal { abort, buf }\n"
)


def p(name: str, k: int = 1) -> fm.Formula:
    """``name >= k``: what a bare place compiles to."""
    return fm.Compare(fm.Tokens(((name, 1),)), ">=", fm.IntConst(k))


def compiled(*lines: str) -> Net:
    return compile_source(
        MISSION + "".join(line + "\n" for line in lines), "m.coral"
    ).raise_for_errors()


def lowered(line: str) -> fm.Formula:
    (assertion,) = [a for a in compiled(line).assertions if a.temporal]
    assert assertion.formula is not None
    return assertion.formula


FINAL_DEPTH_OK = fm.And(
    (
        fm.Compare(fm.Tokens((("depth_ok", 1),)), "==", fm.IntConst(1)),
        fm.Compare(
            fm.Tokens(
                (
                    ("start", 1),
                    ("depth_set", 1),
                    ("abort", 1),
                    ("buf", 1),
                    ("set_depth.pending", 1),
                    ("check_depth.pending", 1),
                )
            ),
            "==",
            fm.IntConst(0),
        ),
    )
)

LOWERING = [
    ("assert always depth_ok", fm.All(fm.Globally(p("depth_ok")))),
    ("assert eventually abort*2", fm.All(fm.Finally(p("abort", 2)))),
    (
        "assert depth_set leadsto depth_ok or abort",
        fm.All(
            fm.Globally(
                fm.Or((fm.Not(p("depth_set")), fm.Finally(fm.Or((p("depth_ok"), p("abort"))))))
            )
        ),
    ),
    (
        "assert always depth_ok + abort*2 <= N + 1",
        fm.All(
            fm.Globally(
                fm.Compare(fm.Tokens((("depth_ok", 1), ("abort", 2))), "<=", fm.IntConst(3))
            )
        ),
    ),
    (
        "assert always 1 + depth_ok != abort + 1",
        fm.All(
            fm.Globally(fm.Compare(fm.Tokens((("depth_ok", 1),)), "!=", fm.Tokens((("abort", 1),))))
        ),
    ),
    (
        "assert always 3 > abort + abort",
        fm.All(fm.Globally(fm.Compare(fm.IntConst(3), ">", fm.Tokens((("abort", 2),))))),
    ),
    (
        "assert always in_flight(set_depth, check_depth) -> not deadlock",
        fm.All(
            fm.Globally(
                fm.Or(
                    (
                        fm.Not(
                            fm.Compare(
                                fm.Tokens((("set_depth.pending", 1), ("check_depth.pending", 1))),
                                ">=",
                                fm.IntConst(1),
                            )
                        ),
                        fm.Not(fm.Deadlock()),
                    )
                )
            )
        ),
    ),
    (
        "assert always fireable(log, check_depth.done) or true and false",
        fm.All(
            fm.Globally(
                fm.Or(
                    (
                        fm.Fireable(("log", "check_depth.done")),
                        fm.And((fm.Const(True), fm.Const(False))),
                    )
                )
            )
        ),
    ),
    (
        "assert ltl G (fires(check_depth.timeout) -> X abort) and depth_ok U abort",
        fm.All(
            fm.And(
                (
                    fm.Globally(
                        fm.Or((fm.Not(fm.Fires(("check_depth.timeout",))), fm.Next(p("abort"))))
                    ),
                    fm.Until(p("depth_ok"), p("abort")),
                )
            )
        ),
    ),
    (
        "assert ltl F G depth_ok leadsto abort",
        fm.All(
            fm.Globally(
                fm.Or(
                    (
                        fm.Not(fm.Finally(fm.Globally(p("depth_ok")))),
                        fm.Finally(p("abort")),
                    )
                )
            )
        ),
    ),
    (
        "assert ctl AG EF depth_ok and A [ not abort U depth_ok ] or E G abort",
        fm.Or(
            (
                fm.And(
                    (
                        fm.All(fm.Globally(fm.Exists(fm.Finally(p("depth_ok"))))),
                        fm.All(fm.Until(fm.Not(p("abort")), p("depth_ok"))),
                    )
                ),
                fm.Exists(fm.Globally(p("abort"))),
            )
        ),
    ),
    (
        "assert ctl AX EX not AF depth_ok",
        fm.All(fm.Next(fm.Exists(fm.Next(fm.Not(fm.All(fm.Finally(p("depth_ok")))))))),
    ),
]


@pytest.mark.parametrize(("line", "expected"), LOWERING, ids=[row[0] for row in LOWERING])
def test_each_form_lowers_to_the_formula_tree(line: str, expected: fm.Formula) -> None:
    assert lowered(line) == expected


def test_final_is_one_of_the_declared_final_markings_exactly() -> None:
    rest = ("start", "depth_set", "depth_ok", "buf", "set_depth.pending", "check_depth.pending")
    abort = fm.And(
        (
            fm.Compare(fm.Tokens((("abort", 1),)), "==", fm.IntConst(1)),
            fm.Compare(fm.Tokens(tuple((q, 1) for q in rest)), "==", fm.IntConst(0)),
        )
    )
    formula = lowered("assert eventually final")
    assert formula == fm.All(fm.Finally(fm.Or((FINAL_DEPTH_OK, abort))))
    assert "buf.free" not in fm.places_of(formula)  # complement places follow their place


def test_ltl_forms_are_ltl_and_ctl_is_ctl() -> None:
    net = compiled(
        "assert always depth_ok",
        "assert eventually depth_ok",
        "assert depth_ok leadsto abort",
        "assert ltl X depth_ok",
        "assert ctl EF depth_ok",
    )
    temporal = [a for a in net.assertions if a.temporal]
    assert [a.kind for a in temporal] == [AssertKind.LTL] * 4 + [AssertKind.CTL]
    for assertion in temporal[:4]:
        assert assertion.formula is not None and fm.ltl_body(assertion.formula) is not None
    assert temporal[4].formula is not None and fm.is_ctl(temporal[4].formula)
    assert temporal[2].describe() == "assert depth_ok leadsto abort"
    assert temporal[2].span is not None and temporal[2].span.line == MISSION.count("\n") + 3


@pytest.mark.parametrize(
    ("written", "reads"),
    [
        ("a or b and c", "a or (b and c)"),
        ("not a and F b", "(not a) and (F b)"),
        ("a -> b -> c", "a -> (b -> c)"),
        ("a -> b or c", "a -> (b or c)"),
        ("a U b U c", "a U (b U c)"),
        ("a and b U c", "a and (b U c)"),
        ("F a U b", "(F a) U b"),
        ("a leadsto b -> c", "a leadsto (b -> c)"),
        ("A G a", "AG a"),
        ("E [ a and b U c ]", "E [ (a and b) U c ]"),
        ("E [ a U b U c ]", "E [ a U (b U c) ]"),
        ("a + b*2 <= 3 and c", "(a + b*2 <= 3) and c"),
        ("not not a", "not (not a)"),
    ],
)
def test_precedence(written: str, reads: str) -> None:
    def tree(text: str) -> ast.Declaration:
        mission, diagnostics = parse(f"assert ltl {text}\n")
        assert diagnostics == []
        return mission.declarations[0]

    assert tree(written) == tree(reads)


FORMS = [
    "assert always depth_ok + abort*2 <= N",
    "assert always not (in_flight(set_depth) and in_flight(check_depth))",
    "assert eventually final or deadlock",
    "assert in_flight(check_depth) leadsto depth_ok or abort",
    "assert (depth_set leadsto depth_ok) leadsto abort",
    "assert ltl G (fires(check_depth.timeout) -> X abort)",
    "assert ltl ((a U b) U (c U d)) and not (a U b)",
    "assert ltl ((a -> b) -> c) and (a or b) and c",
    "assert ctl AG EF final",
    "assert ctl A [ (a U b) U c ] and E [ a -> b U true ]",
    "assert ctl not fireable(log) and 1 < abort",
    "require termination",
]


@pytest.mark.parametrize("line", FORMS)
def test_every_form_prints_back_as_written_and_parses_to_the_same_tree(line: str) -> None:
    mission, diagnostics = parse(HEADER + line + "\n")
    assert diagnostics == []
    text = format_mission(mission)
    assert text.splitlines()[-1] == line
    again, diagnostics = parse(text)
    assert diagnostics == [] and again == mission


def test_printer_adds_only_the_parentheses_the_tree_needs() -> None:
    mission, _ = parse("assert ltl ((a)) and ((b or (c)))\n")
    declaration = mission.declarations[0]
    assert isinstance(declaration, ast.TemporalAssert)
    assert format_expr(declaration.formula) == "a and (b or c)"


def test_digests_without_temporal_assertions_are_unchanged() -> None:
    # Pinned before temporal assertions existed: their canonical form must not move.
    pool = compile_file(EXAMPLES / "pool_mission" / "pool_mission.coral").raise_for_errors()
    assert pool.digest() == (
        "sha256:0b0557d2829974e40fcf11d72c735370b8749960eab7192ac78063ae33f90c19"
    )
    ordered = compile_source(
        "mission order\nvehicle ROMEO\n"
        "place a = 1, b, c\n"
        "transition t wait { a } signal { b }\n"
        "transition u wait { b } signal { c }\n"
        "final { c }\n"
        "assert never { a, b }\n"
        "assert never { a }\n"
        "assert bound { a, b } <= 2\n"
        "assert bound a <= 1\n"
        "assert reachable { c }\n"
        "assert reachable { b, c }\n",
        "order.coral",
    ).raise_for_errors()
    assert ordered.digest() == (
        "sha256:339e02584c6cf5cf314dfb16acd5bbc9f88f68cbc0cf832e667dc43782a9fd9c"
    )


def test_digest_covers_the_formula_not_its_layout() -> None:
    base = compiled().digest()
    always = compiled("assert always depth_ok or abort").digest()
    assert always != base
    assert compiled("assert   always (depth_ok)\n  or ((abort))").digest() == always
    # the same formula written two ways is the same property
    assert compiled("assert ltl G (depth_ok or abort)").digest() == always
    assert compiled("assert always abort or depth_ok").digest() != always
    assert compiled("assert eventually depth_ok or abort").digest() != always
    assert compiled("assert ctl AG (depth_ok or abort)").digest() != always  # CTL, not LTL
    # order of assertions does not matter
    two = compiled("assert always depth_ok", "assert eventually abort").digest()
    assert compiled("assert eventually abort", "assert always depth_ok").digest() == two


def test_require_termination_reaches_the_net_once() -> None:
    net = compiled("require termination", "require termination")
    assert net.requirements == ("termination",)
    assert net.digest() != compiled().digest()
    assert compiled().requirements == ()


def test_all_errors_of_a_property_are_reported_together() -> None:
    result = compile_source(MISSION + "assert always dd and ee or fires(nope)\n", "m.coral")
    assert [d.message.split(" (")[0] for d in result.errors] == [
        "unknown place 'dd'",
        "unknown place 'ee'",
        "unknown transition 'nope'",
    ]


def test_temporal_and_plain_assertions_mix_in_source_order() -> None:
    net = compiled(
        "assert never { depth_ok, abort }", "assert always depth_ok", "assert reachable { abort }"
    )
    assert [a.kind for a in net.assertions] == [
        AssertKind.NEVER,
        AssertKind.LTL,
        AssertKind.REACHABLE,
    ]


def test_pnml_export_leaves_temporal_assertions_out() -> None:
    net = compiled("assert never { depth_ok, abort }", "assert always depth_ok")
    again = parse_pnml(to_pnml(net))
    assert [a.kind for a in again.assertions] == [AssertKind.NEVER]
    forged = to_pnml(net).replace('kind="never"', 'kind="ltl"')
    with pytest.raises(PnmlError, match="temporal assertions are not carried in PNML"):
        parse_pnml(forged)


def test_pool_mission_with_temporal_assertions_compiles() -> None:
    data = Path(__file__).resolve().parents[1] / "analysis" / "data" / "pool_temporal"
    # Its includes reach back into examples/: allowed only with an explicit include root.
    root = data.parents[3]
    net = compile_file(data / "pool_mission.coral", include_root=root).raise_for_errors()
    assert net.requirements == ("termination",)
    assert sum(a.temporal for a in net.assertions) == 8
