"""``coral-check query`` against the Model Checking Contest's answers (vendored data).

Every formula of every instance in ``tests/data/mcc`` (copied from the MCC 2025
archives, see its README.md) is run through one `QuerySession` per instance, under the
test budgets below, and compared by formula id with ``answers.yaml``: the seven query
examinations and the five global ones. No answer may be wrong. CANNOT_COMPUTE is
allowed only where a budget documented here runs out, and each instance's count of
answered formulas is asserted, so coverage cannot drop silently.

Budgets: at most `MAX_STATES` markings, a reachability graph of at most `MAX_EDGES`
edges, `TIME_LIMIT` seconds per instance. Only Dekker-PT-015 (278,528 markings,
16.8 million edges) goes beyond them: its graph is refused, so its CTL, LTL and
Liveness formulas are CANNOT_COMPUTE while its reachability, bounds and other global
examinations are answered (`BEYOND_BUDGET`).
"""

from __future__ import annotations

import gzip
import hashlib
from functools import cache
from typing import Any

import pytest
import yaml

from analysis.examinations import GLOBAL_EXAMINATIONS, QUERY_EXAMINATIONS, QueryLimits, QuerySession
from analysis.mccxml import MccProperty, parse_properties
from coral_lang.net import Net
from coral_lang.pnml import parse_pnml
from tests.conftest import REPO

MCC = REPO / "tests" / "data" / "mcc"
MAX_STATES = 400_000
MAX_EDGES = 5_000_000
TIME_LIMIT = 120.0
SLOW_STATES = 10_000  # instances above this many markings are marked slow

BEYOND_BUDGET = {"Dekker-PT-015": 16 * 3 + 4}
"""Instances with formulas the budgets leave undecided -> formulas answered: its
Reachability (32) and UpperBounds (16) formulas, and 4 of the 5 global examinations."""

INSTANCES = 40
FORMULAS = 39 * (7 * 16 + 5) + (16 + 5)
"""39 instances with all seven query files, TokenRing-PT-010 with UpperBounds only."""


@cache
def _models() -> dict[str, dict[str, Any]]:
    with (MCC / "answers.yaml").open() as handle:
        models: list[dict[str, Any]] = yaml.safe_load(handle)["models"]
    return {m["model"]: m for m in models}


def _net(model: dict[str, Any]) -> Net:
    data = gzip.decompress((MCC / model["pnml"]).read_bytes())
    assert hashlib.sha256(data).hexdigest() == model["pnml_sha256"]
    return parse_pnml(data, model["pnml"].removesuffix(".gz"))


def _properties(model: dict[str, Any], net: Net) -> list[tuple[MccProperty, Any]]:
    """Every vendored formula with its expected answer."""
    out = []
    for exam in QUERY_EXAMINATIONS:
        entry = model["examinations"][exam]
        if entry["queries"] is None:
            continue
        data = gzip.decompress((MCC / entry["queries"]).read_bytes())
        props = parse_properties(data, entry["queries"].removesuffix(".gz"), net)
        expected = {f["id"]: f["expected"] for f in entry["formulas"]}
        assert sorted(p.id for p in props) == sorted(expected)
        out += [(p, expected[p.id]) for p in props]
    return out


def _count(model: dict[str, Any]) -> int:
    files = sum(e["queries"] is not None for e in model["examinations"].values())
    return 16 * files + len(GLOBAL_EXAMINATIONS)


def _param(name: str) -> Any:
    marks = [pytest.mark.slow] if _models()[name]["states"] > SLOW_STATES else []
    return pytest.param(name, marks=marks, id=name)


def test_the_vendored_data_is_all_there() -> None:
    models = _models()
    assert len(models) == INSTANCES
    assert sum(_count(m) for m in models.values()) == FORMULAS
    for model in models.values():
        assert (MCC / model["pnml"]).is_file()


@pytest.mark.slow
@pytest.mark.parametrize("name", [_param(n) for n in _models()])
def test_every_answer_matches_the_contest(name: str) -> None:
    model = _models()[name]
    net = _net(model)
    session = QuerySession(
        net, QueryLimits(max_states=MAX_STATES, time_limit=TIME_LIMIT, max_edges=MAX_EDGES)
    )
    props = _properties(model, net)
    answers = session.check([p for p, _ in props])
    found = {a.id: a for a in answers}
    expected = {p.id: e for p, e in props}
    for exam in GLOBAL_EXAMINATIONS:
        found[exam] = session.check_global(exam)
        expected[exam] = model["global_properties"][exam]["expected"]
    wrong = {
        ident: (a.value, expected[ident])
        for ident, a in found.items()
        if a.value is not None and a.value != expected[ident]
    }
    assert not wrong
    undecided = {ident: a.reason for ident, a in found.items() if a.value is None}
    answered = len(found) - len(undecided)
    assert answered == BEYOND_BUDGET.get(name, _count(model)), undecided
    for reason in undecided.values():
        assert reason is not None and "budget" in reason
