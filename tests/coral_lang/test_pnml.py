"""PNML import and export: the MCC conformance models, round trips, and refused inputs."""

from __future__ import annotations

import dataclasses
import re
import time
from pathlib import Path
from typing import Any

import pytest
import yaml
from defusedxml import ElementTree as SafeET
from hypothesis import given, settings
from hypothesis import strategies as st

from coral_lang import ast
from coral_lang.compiler import compile_source
from coral_lang.diagnostics import PnmlError, Span
from coral_lang.net import (
    Assertion,
    AssertKind,
    Command,
    FinalMarking,
    Net,
    Place,
    PlaceKind,
    Transition,
    TransitionKind,
)
from coral_lang.pnml import PNML_NAMESPACE, PTNET_TYPE, parse_pnml, read_pnml, to_pnml, write_pnml
from coral_lang.printer import format_mission
from tests.analysis.strategies import small_nets
from tests.conftest import CONFORMANCE
from tests.coral_lang.strategies import missions

PNML_DIR = CONFORMANCE / "pnml"
ORACLE: list[dict[str, Any]] = yaml.safe_load((CONFORMANCE / "oracle.yaml").read_text())["models"]
MODELS = {m["model"]: m for m in ORACLE}

Structure = tuple[dict[str, int], dict[str, tuple[dict[str, int], dict[str, int]]]]


def structure(net: Net) -> Structure:
    """The P/T part of a net: initial marking per place, weighted arcs per transition."""
    return (
        {p.name: p.initial for p in net.places},
        {t.name: (dict(t.inputs), dict(t.outputs)) for t in net.transitions},
    )


def stats(net: Net) -> dict[str, int]:
    weights = [w for t in net.transitions for _, w in (*t.inputs, *t.outputs)]
    return {
        "places": len(net.places),
        "transitions": len(net.transitions),
        "arcs": len(weights),
        "max_arc_weight": max(weights, default=0),
        "initial_tokens_total": sum(net.initial_marking()),
    }


def pnml(body: str, *, net_type: str = PTNET_TYPE, net_id: str = "n") -> str:
    """A one-page PNML document around ``body`` (the page's content)."""
    return (
        '<?xml version="1.0"?>\n'
        f'<pnml xmlns="{PNML_NAMESPACE}">\n'
        f'<net id="{net_id}" type="{net_type}">\n'
        '<page id="pg">\n'
        f"{body}\n"
        "</page>\n"
        "</net>\n"
        "</pnml>\n"
    )


# -- the MCC conformance models ----------------------------------------------------------


def test_every_conformance_file_has_an_oracle_entry() -> None:
    files = sorted(p.stem for p in PNML_DIR.glob("*.pnml"))
    assert len(files) == 47
    assert files == sorted(MODELS)


@pytest.fixture(scope="module", params=sorted(MODELS))
def model(request: pytest.FixtureRequest) -> tuple[dict[str, Any], Net]:
    entry: dict[str, Any] = MODELS[request.param]
    return entry, read_pnml(CONFORMANCE / entry["pnml"])


@pytest.mark.slow
def test_conformance_model_matches_oracle_net_stats(model: tuple[dict[str, Any], Net]) -> None:
    entry, net = model
    expected = {key: entry["net_stats"][key] for key in stats(net)}
    assert stats(net) == expected
    assert net.name == entry["model"]


@pytest.mark.slow
def test_conformance_model_survives_export_and_import(model: tuple[dict[str, Any], Net]) -> None:
    _, net = model
    again = parse_pnml(to_pnml(net))
    assert structure(again) == structure(net)
    # Nothing mission-specific in an MCC net, so the whole Net is identical, labels too.
    assert again == net


# -- round trips of random and mission nets ----------------------------------------------


@given(small_nets())
def test_random_nets_survive_a_round_trip(net: Net) -> None:
    assert parse_pnml(to_pnml(net)) == net


@pytest.mark.slow
@given(missions())
@settings(max_examples=15, deadline=None)
def test_compiled_missions_survive_a_round_trip_with_their_digest(mission: ast.Mission) -> None:
    """Mission nets exercise every coral block the writer makes (kinds, commands with typed
    parameters, spans, finals, assertions); only temporal assertions stay behind."""
    net = compile_source(format_mission(mission), "gen.coral").raise_for_errors()
    exported = dataclasses.replace(
        net, assertions=tuple(a for a in net.assertions if not a.temporal)
    )
    again = parse_pnml(to_pnml(net))
    assert again == exported
    assert again.digest() == exported.digest()


def test_a_requirement_travels_and_an_unknown_one_is_refused() -> None:
    """``require termination`` changes what a certificate must prove (and the digest):
    losing it on the way through PNML would weaken the check of the net read back."""
    net = dataclasses.replace(mission_net(), requirements=("termination",))
    text = to_pnml(net)
    again = parse_pnml(text)
    assert again.requirements == ("termination",) and again.digest() == net.digest()
    forged = text.replace('<require name="termination"', '<require name="terminaton"')
    with pytest.raises(PnmlError, match=r"unknown requirement 'terminaton'.*did you mean"):
        parse_pnml(forged, "forged.pnml")


def test_the_document_is_laid_out_one_element_a_line() -> None:
    """The writer indents (``ET.indent``): a diff of two exports reads element by element."""
    text = to_pnml(mission_net())
    lines = text.splitlines()
    assert lines[0] == '<?xml version="1.0" encoding="UTF-8"?>'
    assert lines[1] == f'<pnml xmlns="{PNML_NAMESPACE}">'
    assert all(line.startswith("  ") for line in lines[2:-1]) and lines[-1] == "</pnml>"
    assert text.endswith("</pnml>\n")
    assert sum("<toolspecific" in line for line in lines) == 7  # net, 4 places, 2 transitions
    # Every element starts on a line of its own.
    assert all(line.strip().startswith("<") for line in lines)


# Names a mission never has but a Net may: spaces, quotes, markup, leading digits, unicode.
_NAME = st.text(
    st.characters(exclude_categories=("Cs", "Cc", "Cn"), include_characters="\t\n\r"),
    min_size=1,
    max_size=8,
)
_LABEL = st.text(st.characters(exclude_categories=("Cs", "Cc", "Cn")), max_size=8).filter(
    lambda s: s == s.strip()
)


@st.composite
def oddly_named_nets(draw: st.DrawFn) -> Net:
    place_names = draw(st.lists(_NAME, min_size=1, max_size=4, unique=True))
    transition_names = draw(st.lists(_NAME, min_size=1, max_size=4, unique=True))
    places = tuple(Place(n, draw(st.integers(0, 3)), label=draw(_LABEL)) for n in place_names)
    weights = st.dictionaries(st.sampled_from(place_names), st.integers(1, 4), max_size=3)
    transitions = tuple(
        Transition(
            n, tuple(draw(weights).items()), tuple(draw(weights).items()), label=draw(_LABEL)
        )
        for n in transition_names
    )
    return Net(draw(_NAME), places, transitions)


@given(oddly_named_nets())
def test_any_names_survive_a_round_trip_and_give_valid_unique_ids(net: Net) -> None:
    text = to_pnml(net)
    assert parse_pnml(text) == net
    root = SafeET.fromstring(text.encode())
    ids = [e.get("id") for e in root.iter() if e.get("id") is not None]
    assert len(ids) == len(set(ids))
    assert all(re.fullmatch(r"[A-Za-z_][A-Za-z0-9_.\-]*", i) for i in ids)


def mission_net() -> Net:
    span = Span("pool.coral", 3, 5, 3, 20)
    depth = Command(
        "ROMEO",
        "DEPTH",
        (("z", 2.5), ("n", 3), ("mode", 'say "hi" <now>'), ("strict", True)),
        resources=("depth",),
        replies=("ok", "timeout"),
    )
    places = (
        Place("start", 1, span=span, label="start"),
        Place("done", 0, capacity=2, resources=("depth",)),
        Place("done.free", 2, PlaceKind.COMPLEMENT, complement_of="done"),
        Place("go.pending", 0, PlaceKind.PENDING, label="DEPTH pending", pending_of="go"),
    )
    transitions = (
        Transition(
            "go",
            (("start", 1),),
            (("go.pending", 1),),
            TransitionKind.COMMAND,
            priority=2,
            label="go",
            span=span,
            command=depth,
            pending="go.pending",
        ),
        Transition(
            "go.ok",
            (("go.pending", 1), ("done.free", 1)),
            (("done", 1),),
            TransitionKind.REPLY,
            label="DEPTH",
            reply_to="go",
            reply="ok",
        ),
    )
    return Net(
        "pool mission",
        places,
        transitions,
        finals=(FinalMarking((("done", 1),), span),),
        assertions=(
            Assertion(AssertKind.NEVER, (("start", 1), ("done", 1)), span=span),
            Assertion(AssertKind.BOUND, (("done", 1),), bound=2),
        ),
        vehicle="ROMEO",
        sources=("pool.coral", "lib/common.coral"),
    )


def test_mission_extras_survive_in_the_coral_toolspecific_block(tmp_path: Path) -> None:
    net = mission_net()
    path = tmp_path / "mission.pnml"
    write_pnml(net, path)
    again = read_pnml(path)
    assert again == net
    assert again.digest() == net.digest()


def test_other_tools_see_a_plain_ptnet() -> None:
    text = to_pnml(mission_net())
    stripped = re.sub(r"<toolspecific.*?</toolspecific>", "", text, flags=re.DOTALL)
    plain = parse_pnml(stripped)
    assert structure(plain) == structure(
        Net(
            "x",
            tuple(Place(p.name, p.initial) for p in mission_net().places),
            tuple(Transition(t.name, t.inputs, t.outputs) for t in mission_net().transitions),
        )
    )
    assert plain.name == "pool_mission"  # the sanitised id: the real name was in the block
    assert {p.kind for p in plain.places} == {PlaceKind.MISSION}


def test_line_breaks_and_tabs_in_labels_survive() -> None:
    net = Net("n", (Place("p", label="two\r\nlines\tand a tab"),), ())
    assert parse_pnml(to_pnml(net)).place("p").label == "two\r\nlines\tand a tab"


def test_place_and_transition_with_one_name_get_distinct_ids() -> None:
    net = Net("n", (Place("a", 1),), (Transition("a", (("a", 1),), (("a", 2),)),))
    text = to_pnml(net)
    assert 'id="a"' in text and 'id="a_2"' in text
    assert parse_pnml(text) == net


def test_export_is_standard_ptnet_pnml() -> None:
    net = Net(
        "n",
        (Place("p", 3, label="P"), Place("q")),
        (Transition("t", (("p", 2),), (("q", 1),)),),
    )
    root = SafeET.fromstring(to_pnml(net).encode())
    ns = {"pnml": PNML_NAMESPACE}
    assert root.tag == f"{{{PNML_NAMESPACE}}}pnml"
    net_element = root.find("pnml:net", ns)
    assert net_element is not None and net_element.get("type") == PTNET_TYPE
    assert len(root.findall("pnml:net/pnml:page", ns)) == 1
    marking = root.find(".//pnml:place[@id='p']/pnml:initialMarking/pnml:text", ns)
    assert marking is not None and marking.text == "3"
    inscriptions = [e.text for e in root.iterfind(".//pnml:arc/pnml:inscription/pnml:text", ns)]
    assert inscriptions == ["2"]  # weight 1 is left implicit
    assert root.find(".//pnml:toolspecific", ns) is None  # nothing mission-specific to keep


def test_names_xml_cannot_carry_are_refused_on_export() -> None:
    with pytest.raises(PnmlError, match="not allowed in XML"):
        to_pnml(Net("n", (Place("bad\x00name"),), ()))


# -- what import accepts -------------------------------------------------------------------


def test_nested_pages_references_graphics_and_parallel_arcs() -> None:
    net = parse_pnml(
        pnml(
            """
            <place id="p">
              <name><graphics><offset x="0" y="0"/></graphics><text>  Start  </text></name>
              <initialMarking>
                <graphics><offset x="1" y="1"/></graphics><text>2</text>
              </initialMarking>
              <toolspecific tool="nupn" version="1.1"><size places="9"/></toolspecific>
            </place>
            <page id="inner">
              <page id="deeper">
                <transition id="t"><name><text>fire</text></name></transition>
                <referencePlace id="rp" ref="rp2"/>
              </page>
              <referencePlace id="rp2" ref="p"/>
              <referenceTransition id="rt" ref="t"/>
              <place id="q"/>
            </page>
            <arc id="a1" source="p" target="t"/>
            <arc id="a2" source="rp" target="rt">
              <inscription><graphics/><text>3</text></inscription>
            </arc>
            <arc id="a3" source="rt" target="q" type="normal"/>
            <toolspecific tool="nupn" version="1.1"><structure units="1"/></toolspecific>
            """
        )
    )
    assert [(p.name, p.initial, p.label) for p in net.places] == [
        ("p", 2, "Start"),
        ("q", 0, ""),
    ]
    assert net.transitions == (Transition("t", (("p", 4),), (("q", 1),), label="fire"),)


def test_files_without_a_namespace_are_read() -> None:
    text = pnml('<place id="p"><initialMarking><text>1</text></initialMarking></place>')
    net = parse_pnml(text.replace(f' xmlns="{PNML_NAMESPACE}"', ""))
    assert net.initial_marking() == (1,)


def test_prefixed_namespace_is_read() -> None:
    text = (
        f'<p:pnml xmlns:p="{PNML_NAMESPACE}"><p:net id="n" type="{PTNET_TYPE}">'
        '<p:page id="pg"><p:place id="x"/></p:page></p:net></p:pnml>'
    )
    assert parse_pnml(text).place_names == ("x",)


def test_bytes_use_the_declared_encoding() -> None:
    text = pnml('<place id="p"><name><text>Vérifié</text></name></place>')
    data = text.replace('<?xml version="1.0"?>', '<?xml version="1.0" encoding="ISO-8859-1"?>')
    assert parse_pnml(data.encode("latin-1")).place("p").label == "Vérifié"


TWO_NETS = (
    f'<pnml xmlns="{PNML_NAMESPACE}">'
    f'<net id="first" type="{PTNET_TYPE}"><page id="a"><place id="x"/></page></net>'
    f'<net id="second" type="{PTNET_TYPE}"><page id="b"><place id="y"/></page></net>'
    "</pnml>"
)


def test_net_id_picks_one_of_several_nets() -> None:
    assert parse_pnml(TWO_NETS, net_id="second").place_names == ("y",)
    with pytest.raises(PnmlError, match="holds 2 nets \\('first', 'second'\\); pass net_id"):
        parse_pnml(TWO_NETS)
    with pytest.raises(PnmlError, match="no <net> with id 'secnd' \\(did you mean 'second'\\?\\)"):
        parse_pnml(TWO_NETS, net_id="secnd")


def test_missing_file_is_a_pnml_error(tmp_path: Path) -> None:
    with pytest.raises(PnmlError, match=r"missing\.pnml: cannot read"):
        read_pnml(tmp_path / "missing.pnml")


# -- what import refuses, and what it says ------------------------------------------------

_PT = '<place id="p"/><transition id="t"/>'
BILLION_LAUGHS = (
    '<?xml version="1.0"?>\n<!DOCTYPE lolz [\n <!ENTITY lol "lol">\n'
    ' <!ENTITY lol1 "&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;">\n'
    ' <!ENTITY lol2 "&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;&lol1;">\n'
    "]>\n<pnml>&lol2;</pnml>\n"
)
EXTERNAL_ENTITY = (
    '<?xml version="1.0"?>\n<!DOCTYPE pnml [<!ENTITY xxe SYSTEM "file:///etc/passwd">]>\n'
    "<pnml>&xxe;</pnml>\n"
)
BAD_INPUTS = [
    ("not-xml", "this is not XML", "bad.pnml:1:1: not well-formed XML"),
    ("truncated", pnml(_PT)[:120], "not well-formed XML"),
    ("billion-laughs", BILLION_LAUGHS, "bad.pnml:2: refused a <!DOCTYPE lolz> declaration"),
    ("external-entity", EXTERNAL_ENTITY, "refused a <!DOCTYPE pnml> declaration"),
    ("not-pnml", "<svg/>", "root element is <svg>, expected <pnml>"),
    ("no-net", f'<pnml xmlns="{PNML_NAMESPACE}"/>', "no <net> element in <pnml>"),
    (
        "coloured-net",
        pnml(_PT, net_type="http://www.pnml.org/version-2009/grammar/symmetricnet"),
        "<net> 'n' has type 'http://www.pnml.org/version-2009/grammar/symmetricnet'"
        " (a symmetric (coloured) net); coral reads only P/T nets",
    ),
    (
        "high-level-net",
        pnml(_PT, net_type="http://www.pnml.org/version-2009/grammar/highlevelnet"),
        "(a high-level (coloured) net)",
    ),
    ("untyped-net", pnml(_PT).replace(f' type="{PTNET_TYPE}"', ""), "<net> 'n' has no type"),
    (
        "declaration-in-ptnet",
        pnml("<declaration><structure/></declaration>" + _PT),
        "<declaration> in <page> 'pg' belongs to high-level (coloured) nets",
    ),
    (
        "sort-on-place",
        pnml('<place id="p"><type><structure/></type></place>'),
        "<type> in <place> 'p' belongs to high-level (coloured) nets",
    ),
    (
        "arc-to-unknown-id",
        pnml(_PT + '<arc id="a" source="p" target="tt"/>'),
        "bad.pnml:5:36: <arc> 'a' has target 'tt', an unknown id (did you mean 't'?)",
    ),
    (
        "place-to-place",
        pnml(_PT + '<place id="q"/><arc id="a" source="p" target="q"/>'),
        "<arc> 'a' joins place 'p' to place 'q'; an arc must join a place and a transition",
    ),
    (
        "transition-to-transition",
        pnml(_PT + '<transition id="u"/><arc id="a" source="t" target="u"/>'),
        "joins transition 't' to transition 'u'",
    ),
    (
        "negative-marking",
        pnml('<place id="p"><initialMarking><text>-2</text></initialMarking></place>'),
        "initial marking of <place> 'p' is -2: it must not be negative",
    ),
    (
        "fractional-marking",
        pnml('<place id="p"><initialMarking><text>1.5</text></initialMarking></place>'),
        "initial marking of <place> 'p' is '1.5', not an integer",
    ),
    (
        "marking-without-text",
        pnml('<place id="p"><initialMarking><value>1</value></initialMarking></place>'),
        "initial marking of <place> 'p' has no <text>",
    ),
    (
        "weight-zero",
        pnml(
            _PT
            + '<arc id="a" source="p" target="t"><inscription><text>0</text></inscription></arc>'
        ),
        "weight of <arc> 'a' is 0: it must be at least 1",
    ),
    (
        "inhibitor-arc-attribute",
        pnml(_PT + '<arc id="a" source="p" target="t" type="inhibitor"/>'),
        "<arc> 'a' is of type 'inhibitor'; coral reads only normal arcs",
    ),
    (
        "inhibitor-arc-element",
        pnml(_PT + '<arc id="a" source="p" target="t"><type value="inhibitor"/></arc>'),
        "<arc> 'a' is of type 'inhibitor'",
    ),
    (
        "reset-arc",
        pnml(_PT + '<arc id="a" source="p" target="t" type="reset"/>'),
        "is of type 'reset'",
    ),
    (
        "duplicate-id",
        pnml('<place id="p"/>\n<transition id="p"/>'),
        "bad.pnml:6:1: duplicate id 'p' on <transition>; first used by <place> on line 5",
    ),
    ("place-without-id", pnml("<place/>"), "<place> has no id"),
    (
        "arc-without-source",
        pnml(_PT + '<arc id="a" target="t"/>'),
        "<arc> 'a' has no source",
    ),
    (
        "reference-to-unknown",
        pnml(_PT + '<referencePlace id="r" ref="pp"/>'),
        "<referencePlace> 'r' refers to unknown node 'pp' (did you mean 'p'?)",
    ),
    (
        "reference-to-wrong-kind",
        pnml(_PT + '<referencePlace id="r" ref="t"/>'),
        "<referencePlace> 'r' refers to transition 't'; it must refer to a place",
    ),
    (
        "reference-cycle",
        pnml('<referencePlace id="r1" ref="r2"/><referencePlace id="r2" ref="r1"/>'),
        "reference cycle r1 -> r2 -> r1",
    ),
]


@pytest.mark.parametrize(
    ("text", "message"), [(t, m) for _, t, m in BAD_INPUTS], ids=[i for i, _, _ in BAD_INPUTS]
)
def test_bad_input_is_refused_with_a_clear_message(text: str, message: str) -> None:
    with pytest.raises(PnmlError) as caught:
        parse_pnml(text, "bad.pnml")
    assert message in str(caught.value)
    assert str(caught.value).startswith("bad.pnml:")


def test_errors_from_a_file_name_the_path(tmp_path: Path) -> None:
    path = tmp_path / "broken.pnml"
    path.write_text(pnml(_PT + '<arc id="a" source="p" target="nowhere"/>'))
    with pytest.raises(PnmlError, match=re.escape(f"{path}:5:")):
        read_pnml(path)


def test_pnml_error_is_a_value_error() -> None:
    with pytest.raises(ValueError):
        parse_pnml("<")


def _reference_chain(length: int, *, cycle: bool = False) -> str:
    """``r0 -> r1 -> ... -> p``: each reference names the next; ``cycle`` closes it."""
    refs = (
        "".join(f'<referencePlace id="r{k}" ref="r{k + 1}"/>' for k in range(length - 1))
        + f'<referencePlace id="r{length - 1}" ref="{"r0" if cycle else "p"}"/>'
    )
    arcs = '<arc id="a" source="r0" target="t"/>'
    return pnml(
        '<place id="p"><initialMarking><text>1</text></initialMarking></place>'
        + '<transition id="t"/>'
        + refs
        + arcs
    )


@pytest.mark.slow
def test_a_long_reference_chain_resolves_in_one_pass() -> None:
    text = _reference_chain(20_000)
    start = time.perf_counter()
    net = parse_pnml(text, "chain.pnml")
    assert time.perf_counter() - start < 5.0  # walking each chain from its start: minutes
    assert dict(net.transitions[0].inputs) == {"p": 1}


@pytest.mark.slow
def test_a_long_reference_cycle_is_refused_naming_the_node() -> None:
    with pytest.raises(PnmlError) as caught:
        parse_pnml(_reference_chain(20_000, cycle=True), "cycle.pnml")
    message = str(caught.value)
    assert "<referencePlace> 'r0' is part of a reference cycle r0 -> r1" in message
    assert "-> r19999 -> r0 (20000 references)" in message
