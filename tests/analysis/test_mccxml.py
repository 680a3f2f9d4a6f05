"""The MCC property-file reader (`analysis.mccxml`): every element, and every fault
reported with file, line, element and property id, never a traceback."""

from __future__ import annotations

import gzip

import pytest

from analysis.mccxml import MccXmlError, PlaceBound, parse_properties, read_properties
from coral_lang.diagnostics import CoralError
from coral_lang.formula import (
    All,
    And,
    Compare,
    Const,
    Deadlock,
    Exists,
    Finally,
    Fireable,
    Globally,
    IntConst,
    Next,
    Not,
    Or,
    Tokens,
    Until,
)
from tests.analysis.nets import make_net
from tests.conftest import REPO

MCC = REPO / "tests" / "data" / "mcc"

NET = make_net(
    "n",
    {"p": 1, "q": 0, "r": 0},
    {"t": ({"p": 1}, {"q": 1}), "u": ({"q": 1}, {"r": 1})},
)


def doc(*formulas: str, ids: bool = True) -> str:
    """A property set with one property per formula, ids ``F-0``, ``F-1``, ..."""
    props = "".join(
        "<property>"
        + (f"<id>F-{k}</id>" if ids else "")
        + f"<description>x</description><formula>{f}</formula></property>\n"
        for k, f in enumerate(formulas)
    )
    return f'<?xml version="1.0"?>\n<property-set xmlns="http://mcc.lip6.fr/">\n{props}</property-set>\n'


LE = (
    "<integer-le><tokens-count><place>p</place><place>q</place></tokens-count>"
    "<integer-constant>3</integer-constant></integer-le>"
)
FIRE = "<is-fireable><transition>t</transition><transition>u</transition></is-fireable>"
LE_ATOM = Compare(Tokens((("p", 1), ("q", 1))), "<=", IntConst(3))
FIRE_ATOM = Fireable(("t", "u"))


def test_every_element_maps_to_the_formula_tree() -> None:
    text = doc(
        f"<all-paths><globally>{LE}</globally></all-paths>",
        f"<exists-path><finally><negation>{FIRE}</negation></finally></exists-path>",
        f"<all-paths><next><conjunction>{LE}{FIRE}<true/></conjunction></next></all-paths>",
        f"<exists-path><until><before><disjunction>{LE}<false/></disjunction></before>"
        f"<reach><deadlock/></reach></until></exists-path>",
        "<place-bound><place>q</place><place>r</place></place-bound>",
    )
    props = parse_properties(text, "q.xml", NET)
    assert [p.id for p in props] == ["F-0", "F-1", "F-2", "F-3", "F-4"]
    assert [p.line for p in props] == [3, 4, 5, 6, 7]
    assert props[0].query == All(Globally(LE_ATOM))
    assert props[1].query == Exists(Finally(Not(FIRE_ATOM)))
    assert props[2].query == All(Next(And((LE_ATOM, FIRE_ATOM, Const(True)))))
    assert props[3].query == Exists(Until(Or((LE_ATOM, Const(False))), Deadlock()))
    assert props[4].query == PlaceBound(("q", "r"))


def test_older_comparisons_and_repeated_places() -> None:
    text = doc(
        "<integer-ge><tokens-count><place>p</place><place>p</place></tokens-count>"
        "<integer-constant>2</integer-constant></integer-ge>"
    )
    (prop,) = parse_properties(text, "q.xml", NET)
    assert prop.query == Compare(Tokens((("p", 1),)), ">=", IntConst(2))


def test_without_a_net_names_are_not_checked() -> None:
    text = doc("<is-fireable><transition>nope</transition></is-fireable>")
    assert parse_properties(text)[0].query == Fireable(("nope",))


def test_a_vendored_mcc_file_reads_completely() -> None:
    data = gzip.decompress((MCC / "queries" / "Sudoku-PT-AN01.CTLFireability.xml.gz").read_bytes())
    props = parse_properties(data, "Sudoku-PT-AN01.CTLFireability.xml")
    assert len(props) == 16
    assert props[0].id == "Sudoku-PT-AN01-CTLFireability-2025-00"


def test_deep_nesting_needs_no_recursion() -> None:
    depth = 20_000
    text = doc("<negation>" * depth + "<true/>" + "</negation>" * depth)
    (prop,) = parse_properties(text)
    node = prop.query
    for _ in range(depth):
        assert isinstance(node, Not)
        node = node.arg
    assert node == Const(True)


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("not xml at all", r"^q\.xml:1: not well-formed XML"),
        (doc("<true/>") + "<extra/>", r"^q\.xml:\d+: not well-formed XML: junk after document"),
        (
            '<?xml version="1.0"?>\n<!DOCTYPE x [<!ENTITY a "b">]>\n<property-set/>',
            r"^q\.xml:\d+: refused unsafe XML",
        ),
        ("<pnml/>", r"^q\.xml:1: root element is <pnml>, expected <property-set>"),
        (doc("<true/>", ids=False), r"^q\.xml:3: <property> has no <id>$"),
        (
            doc("<all-paths><eventually><true/></eventually></all-paths>"),
            r"^q\.xml:3: unknown element <eventually> \(property 'F-0'\)$",
        ),
        (
            doc(
                "<exists-path><finally><is-fireable><transition>tt</transition>"
                "</is-fireable></finally></exists-path>"
            ),
            r"^q\.xml:3: unknown transition 'tt' in <is-fireable> \(did you mean 't'\?\)"
            r" \(property 'F-0'\)$",
        ),
        (
            doc("<place-bound><place>s</place></place-bound>"),
            r"^q\.xml:3: unknown place 's' in <place-bound>",
        ),
        (
            doc("<negation><true/><false/></negation>"),
            r"<negation> must hold exactly one element, not 2 \(property 'F-0'\)",
        ),
        (
            doc("<exists-path><until><before><true/></before></until></exists-path>"),
            r"<until> needs one <before> and one <reach>",
        ),
        (
            doc("<integer-le><true/><integer-constant>1</integer-constant></integer-le>"),
            r"<true> is a formula, not an integer",
        ),
        (
            doc("<negation><integer-constant>1</integer-constant></negation>"),
            r"<integer-constant> is an integer, not a formula",
        ),
        (
            doc(
                "<integer-le><integer-constant>x1</integer-constant>"
                "<integer-constant>1</integer-constant></integer-le>"
            ),
            r"<integer-constant> 'x1' is not an integer",
        ),
        (
            doc("<tokens-count><place>p</place></tokens-count>"),
            r"<tokens-count> is an integer, not a formula",
        ),
        (
            doc("<integer-le><tokens-count/><integer-constant>1</integer-constant></integer-le>"),
            r"<tokens-count> lists no <place>",
        ),
        (
            doc("<negation><place-bound><place>p</place></place-bound></negation>"),
            r"<place-bound> must be the whole formula",
        ),
        (
            '<property-set xmlns="http://mcc.lip6.fr/"><property><id>A</id></property>'
            "</property-set>",
            r"^q\.xml:1: <property> has no <formula> \(property 'A'\)$",
        ),
        (
            '<property-set xmlns="http://example.org/"/>',
            r"namespace 'http://example.org/', expected 'http://mcc.lip6.fr/'",
        ),
        (
            "<property-set><property><id>A</id><formula><true/></formula></property>"
            "<property><id>A</id><formula><true/></formula></property></property-set>",
            r"duplicate property id 'A' \(first on line 1\)",
        ),
    ],
)
def test_bad_input_names_file_line_and_element(text: str, expected: str) -> None:
    with pytest.raises(MccXmlError, match=expected) as info:
        parse_properties(text, "q.xml", NET)
    assert isinstance(info.value, CoralError)


def test_a_missing_file_is_an_mcc_error() -> None:
    with pytest.raises(MccXmlError, match="cannot read: No such file"):
        read_properties("/nonexistent/ReachabilityCardinality.xml")
