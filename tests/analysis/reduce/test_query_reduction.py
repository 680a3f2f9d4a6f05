"""Reachability formulas and UpperBounds answered on the reduced net equal the MCC's
answers (the smaller vendored instances here; all of them in bench/reductions.py)."""

from __future__ import annotations

import gzip
from functools import cache
from typing import Any

import pytest

from analysis.examinations import REDUCED, QueryLimits, QuerySession, _reachability
from analysis.mccxml import MccProperty, PlaceBound, parse_properties
from analysis.reduce.deadlock import replay
from analysis.reduce.query import bound_by_reduction, reach_by_reduction
from coral_lang.net import Net
from tests.analysis.test_mcc_conformance import MCC, _models, _net

MAX_STATES = 1_000
"""Instances up to this many reachable markings run here (about half a second each)."""

EXAMINATIONS = ("ReachabilityCardinality", "ReachabilityFireability", "UpperBounds")


def _props(model: dict[str, Any], net: Net) -> list[tuple[MccProperty, Any]]:
    out = []
    for exam in EXAMINATIONS:
        entry = model["examinations"][exam]
        if entry["queries"] is None:
            continue
        data = gzip.decompress((MCC / entry["queries"]).read_bytes())
        expected = {f["id"]: f["expected"] for f in entry["formulas"]}
        out += [(p, expected[p.id]) for p in parse_properties(data, "q.xml", net)]
    return out


@cache
def _small() -> list[str]:
    return sorted(n for n, m in _models().items() if m["states"] <= MAX_STATES)


@pytest.mark.parametrize("name", _small())
def test_reduced_answers_equal_the_contests(name: str) -> None:
    model = _models()[name]
    net = _net(model)
    checked = 0
    for prop, expected in _props(model, net):
        if isinstance(prop.query, PlaceBound):
            found = bound_by_reduction(net, prop.query.places)
            assert found is not None  # the reduced search completes on these
            value: Any = found.value
            assert found.trace is not None
            reached = replay(net, found.trace)
            assert reached is not None
            assert sum(reached[net.place_index(p)] for p in prop.query.places) == value
        else:
            reach = _reachability(prop.query)
            assert reach is not None
            answer = reach_by_reduction(net, reach.target)
            assert answer is not None
            value = bool(answer.value) != reach.negated
            assert (answer.trace is not None) == bool(answer.value)
        if expected is not None:
            assert value == expected, prop.id
            checked += 1
    assert checked >= 40  # 48 formulas, a few without a consensus


def test_a_query_cut_short_is_answered_on_the_reduced_net() -> None:
    # HouseConstruction-PT-00002: 1,501 markings; a 300-marking search decides few.
    model = _models()["HouseConstruction-PT-00002"]
    net = _net(model)
    props = _props(model, net)
    session = QuerySession(net, QueryLimits(max_states=300, time_limit=60.0))
    answers = session.check([p for p, _ in props])
    expected = {p.id: e for p, e in props}
    reduced = [a for a in answers if a.techniques == REDUCED]
    assert reduced
    for a in answers:
        if a.value is not None and expected[a.id] is not None:
            assert a.value == expected[a.id], a.id


def test_the_reductions_switch_keeps_the_plain_answer() -> None:
    model = _models()["HouseConstruction-PT-00002"]
    net = _net(model)
    props = [p for p, _ in _props(model, net)]
    limits = QueryLimits(max_states=300, time_limit=60.0, reductions=False)
    answers = QuerySession(net, limits).check(props)
    assert all(a.techniques != REDUCED for a in answers)
