"""Minimal P- and T-invariants: known nets, random nets against the reference, limits."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import z3
from hypothesis import given, settings

from analysis.budget import Budget
from analysis.invariants import (
    invariant_bounds,
    invariant_report,
    p_invariants,
    semiflows,
    t_invariants,
)
from analysis.structural import incidence
from coral_lang.net import Net
from tests.analysis.nets import Arcs, make_net, mutex
from tests.analysis.reference import explore_reference
from tests.analysis.strategies import small_nets


def producer_consumer(capacity: int = 2) -> Net:
    """A producer and a consumer around a buffer of ``capacity`` slots (``free`` counts them)."""
    return make_net(
        "prodcons",
        {"ready": 1, "made": 0, "buffer": 0, "free": capacity, "want": 1, "got": 0},
        {
            "produce": ({"ready": 1}, {"made": 1}),
            "deposit": ({"made": 1, "free": 1}, {"ready": 1, "buffer": 1}),
            "take": ({"buffer": 1, "want": 1}, {"free": 1, "got": 1}),
            "consume": ({"got": 1}, {"want": 1}),
        },
    )


def pump() -> Net:
    return make_net("pump", {"a": 1, "b": 0}, {"t": ({"a": 1}, {"a": 1, "b": 1})})


def _supports(net: Net, kind: str) -> set[tuple[str, ...]]:
    basis = p_invariants(net) if kind == "P" else t_invariants(net)
    return {inv.support_names() for inv in basis.invariants}


def test_mutex_invariants() -> None:
    net = mutex()
    p = p_invariants(net)
    assert p.complete and p.covered() is True
    assert {inv.describe() for inv in p.invariants} == {
        "idle1 + cs1",
        "idle2 + cs2",
        "cs1 + cs2 + lock",
    }
    assert _supports(net, "T") == {("enter1", "exit1"), ("enter2", "exit2")}
    assert invariant_bounds(net, p) == {p.name: 1 for p in net.places}


def test_producer_consumer_bounds_the_buffer_by_its_capacity() -> None:
    net = producer_consumer(capacity=3)
    report = invariant_report(net)
    assert {inv.describe() for inv in report.p.invariants} == {
        "ready + made",
        "buffer + free",
        "want + got",
    }
    assert report.bounds["buffer"] == 3 and report.bounds["made"] == 1
    assert report.covered_by_p is True and report.consistent is True
    assert report.conservative  # every transition moves as many tokens as it takes
    assert _supports(net, "T") == {("produce", "deposit", "take", "consume")}


def test_weights_and_gcd_normalisation() -> None:
    # Two tokens of a make one of b: 1*a + 2*b is invariant; the row is gcd-normalised.
    net = make_net("w", {"a": 4, "b": 0}, {"t": ({"a": 2}, {"b": 1}), "u": ({"b": 1}, {"a": 2})})
    p = p_invariants(net)
    assert [inv.weights for inv in p.invariants] == [(1, 2)]
    assert invariant_bounds(net, p) == {"a": 4, "b": 2}
    assert [inv.weights for inv in t_invariants(net).invariants] == [(1, 1)]


def test_pump_has_no_p_invariant_on_the_pumped_place() -> None:
    report = invariant_report(pump())
    assert report.p.uncovered() == ("b",) and report.covered_by_p is False
    assert "b" not in report.bounds and report.bounds == {"a": 1}
    assert report.consistent is False


def test_several_minimal_supports_per_column() -> None:
    # Three ways from s to e: each path is its own minimal P-invariant support.
    net = make_net(
        "diamond",
        {"s": 1, "x": 0, "y": 0, "z": 0, "e": 0},
        {
            "a": ({"s": 1}, {"x": 1}),
            "b": ({"s": 1}, {"y": 1}),
            "c": ({"x": 1}, {"z": 1}),
            "d": ({"y": 1}, {"z": 1}),
            "f": ({"z": 1}, {"e": 1}),
        },
    )
    assert _supports(net, "P") == {("s", "x", "y", "z", "e")}
    assert _supports(net, "T") == set()


def test_row_limit_says_incomplete_and_keeps_only_genuine_invariants() -> None:
    # k disjoint two-place cycles plus one place that every transition touches.
    k = 6
    places = {f"a{i}": 1 for i in range(k)} | {f"b{i}": 0 for i in range(k)} | {"hub": 1}
    transitions: dict[str, tuple[Arcs, Arcs]] = {}
    for i in range(k):
        transitions[f"go{i}"] = ({f"a{i}": 1, "hub": 1}, {f"b{i}": 1})
        transitions[f"back{i}"] = ({f"b{i}": 1}, {f"a{i}": 1, "hub": 1})
    net = make_net("hub", places, transitions)
    full = p_invariants(net)
    assert full.complete
    limited = p_invariants(net, max_rows=3)
    assert not limited.complete and limited.reason == "intermediate row budget of 3 reached"
    assert {inv.weights for inv in limited.invariants} <= {inv.weights for inv in full.invariants}
    assert "incomplete" in limited.explain()


def test_time_limit_with_an_injected_clock() -> None:
    ticks = itertools.count()
    budget = Budget(0.5, clock=lambda: float(next(ticks)))
    result = p_invariants(mutex(), budget=budget)
    assert not result.complete and result.reason == "time limit of 0.5 s reached"


def test_semiflows_of_an_empty_matrix() -> None:
    assert semiflows([]) == ([], True, "")
    assert semiflows([[0, 0], [0, 0]]) == ([(0, 1), (1, 0)], True, "")


# -- random nets ------------------------------------------------------------------------


def _is_strict_superset(a: frozenset[int], b: frozenset[int]) -> bool:
    return b < a


@pytest.mark.slow
@settings(max_examples=200)
@given(small_nets())
def test_p_invariants_hold_on_every_reachable_marking(net: Net) -> None:
    basis = p_invariants(net)
    assert basis.complete
    reference = explore_reference(net, max_states=3_000)
    m0 = net.initial_marking()
    for inv in basis.invariants:
        assert all(w >= 0 for w in inv.weights) and any(inv.weights)
        total = inv.value(m0)
        for marking in reference.states:  # sound on explored markings even if incomplete
            assert inv.value(marking) == total
    bounds = invariant_bounds(net, basis)
    for i, place in enumerate(net.places):
        if place.name in bounds:
            assert max(m[i] for m in reference.states) <= bounds[place.name]


@pytest.mark.slow
@settings(max_examples=200)
@given(small_nets())
def test_t_invariants_are_flows_and_all_invariants_minimal(net: Net) -> None:
    matrix = incidence(net).matrix
    for basis in (p_invariants(net), t_invariants(net)):
        supports = [inv.support for inv in basis.invariants]
        assert len(set(supports)) == len(supports)
        for a, b in itertools.permutations(supports, 2):
            assert not _is_strict_superset(a, b)
        for inv in basis.invariants:
            vector = np.array(inv.weights, dtype=np.int64)
            product = vector @ matrix if basis.kind == "P" else matrix @ vector
            assert not product.any()
            assert np.gcd.reduce(vector) == 1


def _has_semiflow_within(matrix: np.ndarray, support: tuple[int, ...], kind: str) -> bool:
    """Is there a non-zero y >= 0 with support inside ``support`` and y^T C = 0 (or C x = 0)?"""
    rows = matrix if kind == "P" else matrix.T
    y = [z3.Real(f"y{i}") for i in support]
    solver = z3.Solver()
    solver.set("timeout", 5_000)
    solver.add(*[v >= 0 for v in y], z3.Sum(y) == 1)
    for column in range(rows.shape[1]):
        terms = [
            int(rows[i, column]) * v for i, v in zip(support, y, strict=True) if rows[i, column]
        ]
        if terms:
            solver.add(z3.Sum(terms) == 0)
    return bool(solver.check() == z3.sat)


@pytest.mark.slow
@settings(max_examples=60)
@given(small_nets(max_places=4, max_transitions=4))
def test_every_minimal_support_is_found(net: Net) -> None:
    """Brute force: the minimal supports of semiflows are exactly the supports listed."""
    matrix = incidence(net).matrix
    for kind, basis in (("P", p_invariants(net)), ("T", t_invariants(net))):
        n = len(basis.names)
        feasible = [
            frozenset(s)
            for size in range(1, n + 1)
            for s in itertools.combinations(range(n), size)
            if _has_semiflow_within(matrix, s, kind)
        ]
        minimal = {s for s in feasible if not any(o < s for o in feasible)}
        assert minimal == {inv.support for inv in basis.invariants}


def _plain_farkas(rows: list[list[int]]) -> set[tuple[int, ...]]:
    """The textbook elimination, dense and in column order, with no heuristic and no
    limit: the reference the sparse elimination must agree with once complete."""
    from math import gcd

    n = len(rows)
    work = [([int(i == j) for j in range(n)], list(row)) for i, row in enumerate(rows)]
    for c in range(len(rows[0]) if rows else 0):
        zero = [r for r in work if r[1][c] == 0]
        pos = [r for r in work if r[1][c] > 0]
        neg = [r for r in work if r[1][c] < 0]
        for a, b in itertools.product(pos, neg):
            fa, fb = -b[1][c], a[1][c]
            full = [fa * x + fb * y for x, y in zip(a[0] + a[1], b[0] + b[1], strict=True)]
            g = 0
            for v in full:
                g = gcd(g, v)
            zero.append(([v // g for v in full[:n]], [v // g for v in full[n:]]))
        supports = [frozenset(i for i, w in enumerate(r[0]) if w) for r in zero]
        work, seen = [], set()
        for r, s in zip(zero, supports, strict=True):
            if s not in seen and not any(o < s for o in supports):
                seen.add(s)
                work.append(r)
    return {tuple(r[0]) for r in work}


@pytest.mark.parametrize(
    "name", ["Angiogenesis-PT-01", "DrinkVendingMachine-PT-02", "FMS-PT-00002"]
)
def test_sparse_invariants_of_conformance_nets_equal_the_plain_elimination(name: str) -> None:
    from coral_lang.pnml import read_pnml
    from tests.conftest import CONFORMANCE

    net = read_pnml(CONFORMANCE / "pnml" / f"{name}.pnml")
    rows = incidence(net).rows()
    p_basis, t_basis = p_invariants(net), t_invariants(net)
    assert p_basis.complete and t_basis.complete
    assert {inv.weights for inv in p_basis.invariants} == _plain_farkas(rows)
    columns = [list(c) for c in zip(*rows, strict=True)]
    assert {inv.weights for inv in t_basis.invariants} == _plain_farkas(columns)
