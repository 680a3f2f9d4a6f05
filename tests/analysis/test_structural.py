"""Incidence matrices, net classes and LP boundedness: hand nets, random nets, MCC."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from hypothesis import given, settings

from analysis.budget import Budget
from analysis.coverability import coverability
from analysis.structural import classify, incidence, structural_boundedness
from coral_lang.net import Net
from coral_lang.pnml import read_pnml
from tests.analysis.nets import make_net, mutex
from tests.analysis.reference import explore_reference
from tests.analysis.strategies import small_nets
from tests.conftest import CONFORMANCE


def cycle(n: int) -> Net:
    return make_net(
        "cycle",
        {f"p{i}": 1 if i == 0 else 0 for i in range(n)},
        {f"t{i}": ({f"p{i}": 1}, {f"p{(i + 1) % n}": 1}) for i in range(n)},
    )


def pump() -> Net:
    return make_net("pump", {"a": 1, "b": 0}, {"t": ({"a": 1}, {"a": 1, "b": 1})})


def test_incidence_is_post_minus_pre_with_weights() -> None:
    net = make_net("w", {"a": 2, "b": 0}, {"t": ({"a": 2}, {"b": 3}), "u": ({"b": 1}, {"a": 1})})
    inc = incidence(net)
    assert inc.places == ("a", "b") and inc.transitions == ("t", "u")
    assert inc.pre.dtype == np.int64 and inc.post.dtype == np.int64
    assert inc.pre.tolist() == [[2, 0], [0, 1]]
    assert inc.post.tolist() == [[0, 1], [3, 0]]
    assert inc.matrix.tolist() == [[-2, 1], [3, -1]]
    # Firing adds the transition's column.
    m = net.fire(net.initial_marking(), net.transitions[0])
    assert list(m) == (np.array(net.initial_marking()) + inc.matrix[:, 0]).tolist()


def test_a_self_loop_cancels_in_the_incidence_but_not_in_pre_and_post() -> None:
    inc = incidence(pump())
    assert inc.pre[0, 0] == 1 and inc.post[0, 0] == 1 and inc.matrix[0, 0] == 0


def test_cycle_is_state_machine_and_marked_graph() -> None:
    kind = classify(cycle(3))
    assert kind.state_machine and kind.marked_graph and kind.free_choice
    assert kind.extended_free_choice and kind.conservative and kind.ordinary
    assert "STATE_MACHINE" in kind.names() and "MARKED_GRAPH" in kind.names()


def test_mutex_is_not_free_choice() -> None:
    kind = classify(mutex())
    # lock feeds enter1 and enter2, whose presets differ: not even extended free choice.
    assert not kind.free_choice and not kind.extended_free_choice
    assert not kind.state_machine and not kind.marked_graph
    assert not kind.conservative and kind.ordinary


def test_extended_free_choice_but_not_free_choice() -> None:
    net = make_net(
        "efc",
        {"a": 1, "b": 1, "c": 0, "d": 0},
        {"t": ({"a": 1, "b": 1}, {"c": 1}), "u": ({"a": 1, "b": 1}, {"d": 1})},
    )
    kind = classify(net)
    assert kind.extended_free_choice and not kind.free_choice


def test_weighted_net_is_in_no_graph_class_but_can_be_conservative() -> None:
    net = make_net("w", {"a": 2, "b": 0}, {"t": ({"a": 2}, {"b": 2}), "u": ({"b": 2}, {"a": 2})})
    kind = classify(net)
    assert not kind.ordinary and not kind.state_machine and not kind.marked_graph
    assert kind.conservative and kind.subconservative


def test_mutex_is_structurally_bounded_with_tight_bounds() -> None:
    result = structural_boundedness(mutex())
    assert result.structurally_bounded is True and result.weights is not None
    assert all(w >= 1 for w in result.weights.values())
    assert result.bounds == {"idle1": 1, "cs1": 1, "idle2": 1, "cs2": 1, "lock": 1}
    assert result.unproven == ()
    assert "structurally bounded" in result.explain()


def test_pump_is_not_structurally_bounded_but_its_generator_is() -> None:
    result = structural_boundedness(pump())
    assert result.structurally_bounded is False
    assert result.bounds == {"a": 1} and result.unproven == ("b",)


def _max_per_place(net: Net, states: list[tuple[int, ...]]) -> dict[str, int]:
    return {p.name: max(m[i] for m in states) for i, p in enumerate(net.places)}


@pytest.mark.slow
@settings(max_examples=150)
@given(small_nets())
def test_lp_bounds_are_sound_and_structural_boundedness_implies_bounded(net: Net) -> None:
    result = structural_boundedness(net, query_seconds=5.0)
    if result.structurally_bounded:
        km = coverability(net, max_nodes=50_000, budget=Budget(20.0))
        assert km.bounded is not False
    reference = explore_reference(net, max_states=5_000)
    seen = _max_per_place(net, reference.states)
    for name, bound in result.bounds.items():
        assert seen[name] <= bound, (name, bound, seen)


# -- conformance: classification against the MCC family verdicts -------------------------

_FLAGS = {
    "ORDINARY": "ordinary",
    "STATE_MACHINE": "state_machine",
    "MARKED_GRAPH": "marked_graph",
    "SIMPLE_FREE_CHOICE": "free_choice",
    "EXTENDED_FREE_CHOICE": "extended_free_choice",
    "CONSERVATIVE": "conservative",
    "SUBCONSERVATIVE": "subconservative",
}


def _oracle_models() -> list[dict[str, Any]]:
    path = CONFORMANCE / "oracle.yaml"
    if not path.exists():
        return []
    models: list[dict[str, Any]] = yaml.safe_load(path.read_text())["models"]
    return models


def _read(model: dict[str, Any]) -> Net:
    net: Net = read_pnml(Path(CONFORMANCE) / model["pnml"])
    return net


@pytest.mark.parametrize(
    "model",
    [m for m in _oracle_models() if m.get("mcc_family_structural_properties")],
    ids=lambda m: str(m["model"]),
)
def test_classification_matches_mcc_structural_properties(model: dict[str, Any]) -> None:
    kind = classify(_read(model))
    expected = model["mcc_family_structural_properties"]
    for key, attribute in _FLAGS.items():
        if key in expected:
            assert getattr(kind, attribute) == expected[key], key


def test_per_place_time_limit_keeps_the_global_bounds() -> None:
    ticks = iter(range(1_000))
    # The clock reads 0 (the budget), 1 (the function's slice of it), 2 (building the
    # global LP), 3 (its time-out: 2.5 s left), 4 (before the first place: in time),
    # 5 (building its LP), 6 (its time-out), 7 (before the second place: past the
    # deadline).
    budget = Budget(5.5, clock=lambda: float(next(ticks)))
    result = structural_boundedness(mutex(), budget=budget)
    assert result.structurally_bounded is True
    assert "per-place bounds stopped: time limit of 5.5 s reached after 1 place" in result.reason
    # The global weighting still bounds every place, just less tightly.
    assert set(result.bounds) == set(mutex().place_names)


def test_public_surface_of_the_structural_modules() -> None:
    """Pin what the verify layer may import; a change here is an API change."""
    import importlib

    expected = {
        "analysis.structural": {
            "DEFAULT_QUERY_SECONDS",
            "MAX_DENSE_CELLS",
            "Incidence",
            "NetClass",
            "StructuralBoundedness",
            "TooLargeForStructure",
            "classify",
            "incidence_columns",
            "incidence_rows",
            "incidence",
            "structural_boundedness",
        },
        "analysis.invariants": {
            "DEFAULT_MAX_ROWS",
            "DEFAULT_TIME_LIMIT",
            "Invariant",
            "InvariantBasis",
            "InvariantReport",
            "invariant_bounds",
            "invariant_report",
            "p_invariants",
            "semiflows",
            "sparse_semiflows",
            "t_invariants",
        },
        "analysis.siphons": {
            "SiphonEnumeration",
            "SiphonTrapCheck",
            "is_siphon",
            "is_trap",
            "maximal_siphon",
            "maximal_trap",
            "minimal_siphons",
            "siphon_trap_check",
        },
        "analysis.stateeq": {
            "METHOD",
            "METHOD_TRAPS",
            "BadMarkings",
            "Candidate",
            "Op",
            "PlaceConstraint",
            "Proven",
            "StateEquationResult",
            "Unknown",
            "above_bound",
            "check_unreachable",
            "deadlocks",
            "never_together",
            "realise",
            "unexpected_deadlocks",
        },
        "analysis.coverability": {
            "DEFAULT_MAX_NODES",
            "DEFAULT_TIME_LIMIT",
            "MAX_EXACT_TOKENS",
            "CoverabilityResult",
            "PumpingTrace",
            "coverability",
            "node_cap",
            "replay_pump",
        },
    }
    for name, names in expected.items():
        module = importlib.import_module(name)
        assert set(module.__all__) == names, name
        assert all(hasattr(module, n) for n in names), name


# -- size guard -------------------------------------------------------------------------


def wide_net(places: int = 100_000, transitions: int = 300) -> Net:
    """``places`` places and ``transitions`` one-arc transitions: its dense matrices
    would hold places x transitions cells (3e7 here, 720 MB as three int64 matrices),
    but the net itself is a few megabytes of small objects."""
    return make_net(
        "wide",
        {f"p{i}": 1 if i == 0 else 0 for i in range(places)},
        {f"t{i}": ({f"p{i}": 1}, {f"p{i + 1}": 1}) for i in range(transitions)},
    )


def test_incidence_refuses_a_net_past_the_dense_limit_before_allocating() -> None:
    import tracemalloc

    from analysis.structural import MAX_DENSE_CELLS, TooLargeForStructure

    net = wide_net()
    assert len(net.places) * len(net.transitions) > MAX_DENSE_CELLS
    tracemalloc.start()
    try:
        with pytest.raises(TooLargeForStructure) as refused:
            incidence(net)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 1_000_000  # nothing near the 720 MB the matrices would take
    message = str(refused.value)
    assert message.startswith("too large for the structural method")
    assert "100,000 places x 300 transitions" in message
    # The limit is a parameter: the same net within a raised limit is built as usual,
    # and a small net past a lowered one is refused the same way.
    assert incidence(wide_net(1_000, 30), max_cells=30_000).matrix.shape == (1_000, 30)
    with pytest.raises(TooLargeForStructure):
        incidence(wide_net(1_000, 30), max_cells=29_999)


def test_invariants_past_the_dense_limit_come_from_the_sparse_arcs() -> None:
    """3e7 cells as a dense matrix: the eliminations work on the arcs instead, within
    their limits, and what they list is genuine."""
    from analysis.invariants import p_invariants, t_invariants

    net = wide_net()
    t_basis = t_invariants(net)  # a chain: no firing sequence returns to its start
    assert t_basis.complete and t_basis.invariants == ()
    p_basis = p_invariants(net)  # 99,700 untouched places: one trivial invariant each
    assert not p_basis.complete and "99,700 invariants found, 2 listed" in p_basis.reason
    small = wide_net(400, 300)  # 99 untouched places, and the chain p0 ... p300
    basis = p_invariants(small)
    assert basis.complete and len(basis.invariants) == 100
    chain = [inv for inv in basis.invariants if len(inv.support) > 1]
    assert [sorted(inv.support) for inv in chain] == [list(range(301))]


def _pairwise_free_choice(net: Net) -> tuple[bool, bool]:
    """The textbook definitions, pair by pair (quadratic: the reference that
    `classify`, grouped per place, must agree with): simple and extended free choice."""
    pre = [frozenset(p for p, _ in t.inputs) for t in net.transitions]
    ordinary = all(w == 1 for t in net.transitions for _, w in (*t.inputs, *t.outputs))
    free = extended = ordinary
    for i, a in enumerate(pre):
        for b in pre[i + 1 :]:
            if a & b:
                extended = extended and a == b
                free = free and a == b and len(a) == 1
    return free, extended


@settings(max_examples=300, deadline=None, derandomize=True)
@given(small_nets(max_places=4, max_transitions=7, max_weight=1))
def test_classify_agrees_with_the_pairwise_free_choice_definitions(net: Net) -> None:
    kind = classify(net)
    assert (kind.free_choice, kind.extended_free_choice) == _pairwise_free_choice(net)


def test_classify_is_linear_in_the_arcs_on_18000_transitions() -> None:
    """18,490 transitions sharing one place (3.4e8 pairs): grouped per place, the
    classes take a fraction of a second (measured 0.15 s)."""
    import time

    from coral_lang.net import Place, Transition

    n = 18_490
    places = (Place("s", 1), *(Place(f"p{i}", 1) for i in range(n)))
    transitions = tuple(
        Transition(f"t{i}", (("s", 1), (f"p{i}", 1)), (("s", 1),)) for i in range(n)
    )
    net = Net("shared", places, transitions)
    started = time.perf_counter()
    kind = classify(net)
    assert time.perf_counter() - started < 3.0
    assert not kind.free_choice and not kind.extended_free_choice and kind.subconservative


def test_a_net_that_makes_no_tokens_is_bounded_without_an_lp(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """No transition puts out more than it takes: y = 1 is the weighting, found from the
    arcs alone (z3 is never asked), and the bounds follow from it."""
    import z3

    from analysis.structural import structural_boundedness
    from tests.analysis.wide_nets import rings

    def no_solver(*args: object, **kwargs: object) -> object:
        raise AssertionError("the LP was built")

    monkeypatch.setattr(z3, "Solver", no_solver)
    net = rings(30, 4, idle=50)  # idle transitions take two tokens and give one
    result = structural_boundedness(net, per_place=False)
    assert result.structurally_bounded is True
    assert result.weights is not None and set(result.weights.values()) == {1}
    assert result.bounds["r0p0"] == 30  # every token of the net could gather there


def test_building_the_lp_stops_at_the_deadline_with_its_reason() -> None:
    from analysis.budget import Budget
    from analysis.structural import structural_boundedness
    from tests.analysis.nets import make_net

    # 'split' makes a token: the unit weighting does not do, so the LP is built.
    net = make_net("grow", {"a": 1, "b": 0}, {"split": ({"a": 1}, {"a": 1, "b": 1})})
    result = structural_boundedness(net, per_place=False, budget=Budget(0.0))
    assert result.structurally_bounded is None
    assert result.reason == "global LP: time limit of 0 s reached"
    assert structural_boundedness(net, per_place=False).structurally_bounded is False
