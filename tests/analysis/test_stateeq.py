"""The z3 state equation: proofs on hand nets, never contradicting search, MCC deadlocks."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from analysis.budget import Budget
from analysis.invariants import p_invariants, t_invariants
from analysis.stateeq import (
    METHOD,
    METHOD_TRAPS,
    BadMarkings,
    Candidate,
    Op,
    PlaceConstraint,
    Proven,
    Unknown,
    above_bound,
    check_unreachable,
    deadlocks,
    never_together,
    realise,
    unexpected_deadlocks,
)
from analysis.structural import incidence
from coral_lang.net import FinalMarking, Net
from coral_lang.pnml import read_pnml
from tests.analysis.nets import make_net, mutex
from tests.analysis.reference import explore_reference
from tests.analysis.strategies import small_nets
from tests.conftest import CONFORMANCE


def trapmake_net() -> Net:
    """{p, q} is a trap marked initially; the equation alone lets it empty (x = (2, 1))."""
    return make_net(
        "trap", {"p": 1, "q": 0}, {"t": ({"p": 1}, {"q": 1}), "u": ({"q": 2}, {"p": 1})}
    )


def test_mutual_exclusion_is_proven_by_the_state_equation() -> None:
    result = check_unreachable(mutex(), never_together(["cs1", "cs2"]))
    assert isinstance(result, Proven) and result.method == METHOD
    assert "cs1, cs2 marked together" in result.explain()


def test_mutex_never_deadlocks_and_never_exceeds_one_token() -> None:
    net = mutex()
    assert isinstance(check_unreachable(net, deadlocks()), Proven)
    assert isinstance(check_unreachable(net, above_bound(["lock"], 1)), Proven)
    # lock can hold 1 token, so "more than 0" is not provable: a confirmable candidate.
    result = check_unreachable(net, above_bound(["lock"], 0))
    assert isinstance(result, Candidate) and result.marking[net.place_index("lock")] >= 1


def test_invariants_may_be_added_and_must_be_p_invariants() -> None:
    net = mutex()
    result = check_unreachable(net, never_together(["cs1", "cs2"]), invariants=p_invariants(net))
    assert isinstance(result, Proven)
    with pytest.raises(ValueError, match="P-invariants"):
        check_unreachable(net, deadlocks(), invariants=t_invariants(net))


def test_trap_constraint_removes_a_spurious_solution() -> None:
    net = trapmake_net()
    empty = BadMarkings(constraints=(PlaceConstraint((("p", 1), ("q", 1)), "<=", 0),))
    plain = check_unreachable(net, empty, use_traps=False)
    assert isinstance(plain, Candidate)
    assert plain.marking == (0, 0) and plain.firing_counts == (2, 1)
    assert realise(net, plain) is None  # t, then u needs two tokens in q: stuck
    proven = check_unreachable(net, empty)
    assert isinstance(proven, Proven) and proven.method == METHOD_TRAPS
    assert proven.traps == (("p", "q"),)


def test_a_candidate_is_not_a_counterexample() -> None:
    # t needs a token in p to fire and p is never marked: b stays empty, but the state
    # equation (which ignores firability) says b = x_t is fine.
    net = make_net("stuck", {"p": 0, "b": 0}, {"t": ({"p": 1}, {"p": 1, "b": 1})})
    result = check_unreachable(net, above_bound(["b"], 0))
    assert isinstance(result, Candidate) and not result.is_counterexample
    assert result.marking_dict()["b"] >= 1 and result.counts_dict()["t"] >= 1
    assert "not a counterexample" in result.explain()
    assert explore_reference(net).states == [(0, 0)]
    assert realise(net, result) is None


def test_deadlock_except_the_declared_final_marking() -> None:
    finals = (FinalMarking((("c", 1),)),)
    net = make_net(
        "line",
        {"a": 1, "b": 0, "c": 0},
        {"t": ({"a": 1}, {"b": 1}), "u": ({"b": 1}, {"c": 1})},
        finals,
    )
    any_dead = check_unreachable(net, deadlocks())
    assert isinstance(any_dead, Candidate) and any_dead.marking == (0, 0, 1)
    assert realise(net, any_dead) == (0, 1)  # a genuine counterexample: t, then u
    assert isinstance(check_unreachable(net, unexpected_deadlocks(net)), Proven)


def test_weighted_arcs_count_in_the_deadlock_constraint() -> None:
    # One token in a, t needs two: dead at once, although a is marked.
    net = make_net("w", {"a": 1}, {"t": ({"a": 2}, {"a": 2})})
    result = check_unreachable(net, deadlocks())
    assert isinstance(result, Candidate) and result.marking == (1,)


def test_a_transition_without_inputs_rules_out_deadlock() -> None:
    net = make_net("source", {"a": 0}, {"t": ({}, {"a": 1})})
    assert isinstance(check_unreachable(net, deadlocks()), Proven)


def test_timeout_gives_unknown() -> None:
    # An Unknown needs z3 to really run out of time: a 1 ms limit on a query that takes
    # it seconds (DoubleExponent-PT-003 deadlock), so the outcome does not depend on load.
    path = CONFORMANCE / "pnml" / "DoubleExponent-PT-003.pnml"
    assert path.exists(), "the vendored conformance data (tests/data/mcc) is missing"
    net: Net = read_pnml(path)
    result = check_unreachable(net, deadlocks(), query_seconds=0.001, use_traps=False)
    assert isinstance(result, Unknown) and "z3" in result.reason
    assert "inconclusive" in result.explain()


# -- random nets: the state equation never contradicts search ----------------------------


@st.composite
def nets_and_bad_sets(draw: st.DrawFn) -> tuple[Net, BadMarkings]:
    net = draw(small_nets())
    names = net.place_names
    kind = draw(st.sampled_from(["together", "bound", "dead", "dead_except", "linear"]))
    if kind == "together":
        chosen = draw(st.lists(st.sampled_from(names), min_size=1, max_size=2, unique=True))
        return net, never_together(chosen)
    if kind == "bound":
        return net, above_bound([draw(st.sampled_from(names))], draw(st.integers(0, 3)))
    if kind == "dead":
        return net, deadlocks()
    if kind == "dead_except":
        return net, deadlocks([net.initial_marking()])
    terms = tuple(
        (p, draw(st.integers(-2, 2)))
        for p in draw(st.lists(st.sampled_from(names), min_size=1, max_size=3, unique=True))
    )
    ops: list[Op] = [">=", "<=", "=="]
    op = draw(st.sampled_from(ops))
    return net, BadMarkings(constraints=(PlaceConstraint(terms, op, draw(st.integers(-1, 3))),))


@pytest.mark.slow
@settings(max_examples=300)
@given(nets_and_bad_sets())
def test_state_equation_never_contradicts_the_reference(case: tuple[Net, BadMarkings]) -> None:
    net, bad = case
    result = check_unreachable(net, bad, query_seconds=5.0)
    reference = explore_reference(net, max_states=3_000)
    found = [m for m in reference.states if bad.matches(net, m)]
    if isinstance(result, Proven):
        assert not found, (result.explain(), found)
    if found:
        assert not isinstance(result, Proven)
    if isinstance(result, Candidate):
        # A candidate is in the bad set and solves the equation, whatever its reachability.
        assert bad.matches(net, result.marking)
        m0 = np.array(net.initial_marking(), dtype=np.int64)
        x = np.array(result.firing_counts, dtype=np.int64)
        assert (m0 + incidence(net).matrix @ x).tolist() == list(result.marking)
        assert all(v >= 0 for v in result.firing_counts)
        order = realise(net, result, max_nodes=20_000)
        if order is not None:  # a realised candidate is a real bad marking
            marking = net.initial_marking()
            for t in order:
                assert net.enabled(marking, net.transitions[t])
                marking = net.fire(marking, net.transitions[t])
            assert marking == result.marking and bad.matches(net, marking)
            if reference.complete:
                assert marking in found


# -- conformance: deadlock proofs on the MCC models ------------------------------------------

_SLOW = {"DoubleExponent-PT-003", "LamportFastMutEx-PT-2"}


def _oracle_models() -> list[dict[str, Any]]:
    path = CONFORMANCE / "oracle.yaml"
    if not path.exists():
        return []
    models: list[dict[str, Any]] = yaml.safe_load(path.read_text())["models"]
    return models


def _param(model: dict[str, Any]) -> Any:
    marks = [pytest.mark.slow] if model["model"] in _SLOW else []
    return pytest.param(model, id=str(model["model"]), marks=marks)


@pytest.mark.slow
@pytest.mark.parametrize(
    "model", [_param(m) for m in _oracle_models() if m.get("deadlock") is not None]
)
def test_deadlock_proofs_never_contradict_the_mcc_oracle(model: dict[str, Any]) -> None:
    net: Net = read_pnml(Path(CONFORMANCE) / model["pnml"])
    result = check_unreachable(net, deadlocks(), query_seconds=3.0, budget=Budget(10.0))
    if model["deadlock"]:
        assert not isinstance(result, Proven), result.explain()


@pytest.mark.slow
@pytest.mark.parametrize(
    ("name", "method"),
    [
        ("Kanban-PT-00005", METHOD),
        ("Dekker-PT-010", METHOD),
        ("Peterson-PT-2", METHOD),
        ("SimpleLoadBal-PT-02", METHOD_TRAPS),
    ],
)
def test_deadlock_freedom_is_proven_on_known_deadlock_free_models(name: str, method: str) -> None:
    """Regression: these proofs hold today; losing one means the encoding got weaker."""
    model = next((m for m in _oracle_models() if m["model"] == name), None)
    assert model is not None, "the vendored conformance data (tests/data/mcc) is missing"
    assert model["deadlock"] is False
    net: Net = read_pnml(Path(CONFORMANCE) / model["pnml"])
    result = check_unreachable(net, deadlocks(), query_seconds=10.0, budget=Budget(30.0))
    assert isinstance(result, Proven) and result.method == method


def test_the_equation_is_built_from_the_arcs_not_a_dense_matrix(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Past tens of millions of places x transitions cells the dense incidence matrix
    does not fit in memory; the equation needs one term per arc only."""
    import analysis.stateeq
    import analysis.structural
    from analysis.stateeq import _sparse_rows
    from tests.analysis.test_structural import wide_net

    for model in _oracle_models()[:12]:
        net: Net = read_pnml(Path(CONFORMANCE) / model["pnml"])
        dense = analysis.structural.incidence(net).rows()
        rows = _sparse_rows(net)
        assert [[row.get(t, 0) for t in range(len(net.transitions))] for row in rows] == dense

    def refuse(*_: object, **__: object) -> None:
        raise AssertionError("the dense incidence matrix was built")

    monkeypatch.setattr(analysis.structural, "incidence", refuse)
    monkeypatch.setattr(analysis.stateeq, "incidence", refuse, raising=False)
    result = check_unreachable(wide_net(places=20, transitions=19), deadlocks())
    assert isinstance(result, Candidate) and result.marking[-1] == 1
