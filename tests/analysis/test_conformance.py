"""The fast explorer against the MCC oracles in ``shared/conformance`` (exact numbers).

Every model of ``oracle.yaml`` with at most `MAX_TEST_STATES` reachable markings is
explored completely; its state and edge counts, token maxima, deadlock verdict and every
UpperBounds query must equal the oracle. ``null`` oracle values skip just that field.
The 7 large models (1.8 M to 14.3 M markings) are for ``bench/statespace.py``.
"""

from __future__ import annotations

from functools import cache
from typing import Any

import numpy as np
import pytest
import yaml

from analysis.statespace import StateSpace, explore
from coral_lang.pnml import read_pnml
from tests.analysis.test_statespace import MODES
from tests.analysis.test_statespace import _mode as explorer_mode
from tests.conftest import CONFORMANCE

MAX_TEST_STATES = 300_000
SLOW_STATES = 50_000  # models above this are marked slow (still run in CI)


def _oracle() -> list[dict[str, Any]]:
    path = CONFORMANCE / "oracle.yaml"
    if not path.exists():
        return []
    with path.open() as handle:
        models: list[dict[str, Any]] = yaml.safe_load(handle)["models"]
    return models


MODELS = {m["model"]: m for m in _oracle() if (m["states"] or 0) <= MAX_TEST_STATES}


def _param(name: str) -> Any:
    marks = [pytest.mark.slow] if MODELS[name]["states"] > SLOW_STATES else []
    return pytest.param(name, marks=marks, id=name)


@cache
def _explored(name: str) -> StateSpace:
    net = read_pnml(CONFORMANCE / MODELS[name]["pnml"])
    return explore(net, max_states=2 * MAX_TEST_STATES)


def test_the_oracle_has_the_documented_small_models() -> None:
    assert MODELS, "the vendored conformance data (tests/data/mcc) is missing"
    assert len(MODELS) == 40


@pytest.mark.parametrize("name", [_param(n) for n in MODELS])
def test_state_space_numbers_match_the_oracle(name: str) -> None:
    oracle = MODELS[name]
    space = _explored(name)
    assert space.complete, space.stopped_reason
    found = {
        "states": space.states,
        "edges": space.edges,
        "max_tokens_place": space.max_tokens_place,
        "max_tokens_marking": space.max_tokens_marking,
        "deadlock": space.has_deadlock,
    }
    expected = {key: oracle[key] for key in found if oracle.get(key) is not None}
    assert {key: found[key] for key in expected} == expected


def _bound_queries(name: str) -> list[dict[str, Any]]:
    return [q for q in MODELS[name].get("upper_bounds") or [] if q.get("bound") is not None]


@pytest.mark.parametrize("name", [_param(n) for n in MODELS if _bound_queries(n)])
def test_upper_bounds_match_the_oracle(name: str) -> None:
    queries = _bound_queries(name)
    space = _explored(name)
    net = space.net
    found = {q["id"]: space.max_sum([net.place_index(p) for p in q["places"]]) for q in queries}
    assert found == {q["id"]: q["bound"] for q in queries}


@pytest.mark.parametrize("name", [_param(n) for n in MODELS if MODELS[n]["deadlock"]])
def test_dead_markings_have_shortest_traces_that_replay(name: str) -> None:
    space = _explored(name)
    assert space.has_deadlock
    net = space.net
    for index in space.deadlocks[:5].tolist():
        marking = net.initial_marking()
        trace = space.trace_to(index)
        for t in trace:
            assert net.enabled(marking, net.transitions[t])
            marking = net.fire(marking, net.transitions[t])
        assert marking == space.marking(index)
        assert len(trace) == space.depth_of(index)
        assert not any(net.enabled(marking, tr) for tr in net.transitions)


# Models whose places form components (most transitions then enabled by lookup in the
# "indexed" mode), small enough to explore in every mode of the explorer.
MODE_MODELS = [
    "Peterson-PT-2",
    "TokenRing-PT-010",
    "Dekker-PT-010",
    "SharedMemory-PT-000005",
    "Philosophers-PT-000010",
    "DoubleExponent-PT-002",
    "Referendum-PT-0010",
    "Anderson-PT-04",
]


@pytest.mark.parametrize("mode", sorted(MODES))
@pytest.mark.parametrize("name", [_param(n) for n in MODE_MODELS if n in MODELS])
def test_every_mode_matches_the_oracle(name: str, mode: str) -> None:
    oracle = MODELS[name]
    net = read_pnml(CONFORMANCE / oracle["pnml"])
    with explorer_mode(mode):
        space = explore(net, max_states=2 * MAX_TEST_STATES, chunk=4096)
    found = {
        "states": space.states,
        "edges": space.edges,
        "max_tokens_place": space.max_tokens_place,
        "max_tokens_marking": space.max_tokens_marking,
        "deadlock": space.has_deadlock,
    }
    expected = {key: oracle[key] for key in found if oracle.get(key) is not None}
    assert {key: found[key] for key in expected} == expected
    default = _explored(name)
    assert space.place_bounds.tolist() == default.place_bounds.tolist()
    assert space.fired_transitions.tolist() == default.fired_transitions.tolist()
    assert np.array_equal(np.diff(space.layer_starts), np.diff(default.layer_starts))
