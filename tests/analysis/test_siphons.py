"""Siphons, traps and the siphon-trap property: hand nets, brute force, reference."""

from __future__ import annotations

import itertools
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import given, settings

from analysis.budget import Budget
from analysis.siphons import (
    is_siphon,
    is_trap,
    maximal_siphon,
    maximal_trap,
    minimal_siphons,
    siphon_trap_check,
)
from coral_lang.net import Net
from coral_lang.pnml import read_pnml
from tests.analysis.nets import Arcs, make_net, mutex
from tests.analysis.reference import explore_reference
from tests.analysis.strategies import small_nets
from tests.conftest import CONFORMANCE


def two_locks() -> Net:
    """Two processes take two locks in opposite orders: the classic deadlock."""
    return make_net(
        "two_locks",
        {"i1": 1, "h1": 0, "i2": 1, "h2": 0, "a": 1, "b": 1},
        {
            "take_a1": ({"i1": 1, "a": 1}, {"h1": 1}),
            "take_b1": ({"h1": 1, "b": 1}, {"i1": 1, "a": 1, "b": 1}),
            "take_b2": ({"i2": 1, "b": 1}, {"h2": 1}),
            "take_a2": ({"h2": 1, "a": 1}, {"i2": 1, "a": 1, "b": 1}),
        },
    )


def test_siphon_and_trap_predicates() -> None:
    net = mutex()
    assert is_siphon(net, ["idle1", "cs1"]) and is_trap(net, ["idle1", "cs1"])
    assert is_siphon(net, ["lock", "cs1", "cs2"]) and is_trap(net, ["lock", "cs1", "cs2"])
    assert not is_siphon(net, ["lock"]) and not is_trap(net, ["cs1"])
    assert is_siphon(net, []) and is_trap(net, [])


def test_maximal_trap_and_siphon_fixpoints() -> None:
    net = mutex()
    assert maximal_trap(net, ["idle1", "cs1", "lock"]) == {"idle1", "cs1"}
    assert maximal_trap(net, ["lock", "cs2"]) == frozenset()
    assert maximal_siphon(net, ["idle1", "cs1", "cs2"]) == {"idle1", "cs1"}


def test_mutex_siphons_all_contain_marked_traps() -> None:
    net = mutex()
    enumeration = minimal_siphons(net)
    assert enumeration.complete
    assert set(enumeration.siphons) == {
        ("cs1", "idle1"),
        ("cs2", "idle2"),
        ("cs1", "cs2", "lock"),
    }
    check = siphon_trap_check(net)
    assert check.holds is True and check.proves_deadlock_free and not check.proves_live
    assert "deadlock-free" in check.explain()


def test_two_locks_fails_the_property_on_the_deadlock_siphon() -> None:
    check = siphon_trap_check(two_locks())
    assert check.holds is False and not check.proves_deadlock_free
    assert check.failing is not None
    # The dead marking (h1, h2 marked) empties the failing siphon.
    dead = explore_reference(two_locks()).dead
    assert dead
    net = two_locks()
    assert any(all(m[net.place_index(p)] == 0 for p in check.failing) for m in dead)
    assert "no conclusion" in check.scope


def test_free_choice_cycle_is_proven_live() -> None:
    net = make_net(
        "cycle", {"a": 1, "b": 0}, {"t": ({"a": 1}, {"b": 1}), "u": ({"b": 1}, {"a": 1})}
    )
    check = siphon_trap_check(net)
    assert check.holds and check.proves_live and check.proves_deadlock_free
    assert "Commoner" in check.scope


def test_weighted_net_is_only_a_partial_argument() -> None:
    # {a} is a siphon and a marked trap, yet t needs two tokens and is dead at once.
    net = make_net("weighted", {"a": 1}, {"t": ({"a": 2}, {"a": 2})})
    check = siphon_trap_check(net)
    assert check.holds is True
    assert not check.proves_deadlock_free and "partial argument" in check.scope
    assert explore_reference(net).dead == [(1,)]


def test_siphon_budget_says_incomplete() -> None:
    n = 8
    places = {f"p{i}": 1 for i in range(n)}
    transitions: dict[str, tuple[Arcs, Arcs]] = {
        f"t{i}{j}": ({f"p{i}": 1, f"p{j}": 1}, {f"p{(i + 1) % n}": 1, f"p{(j + 1) % n}": 1})
        for i, j in itertools.combinations(range(n), 2)
    }
    result = minimal_siphons(make_net("dense", places, transitions), max_branches=5)
    assert not result.complete and result.reason == "partial set budget of 5 reached"
    assert "incomplete" in result.explain()


# -- random nets ------------------------------------------------------------------------


def _brute_minimal_siphons(net: Net) -> set[tuple[str, ...]]:
    names = net.place_names
    siphons = [
        frozenset(s)
        for size in range(1, len(names) + 1)
        for s in itertools.combinations(names, size)
        if is_siphon(net, s)
    ]
    minimal = [s for s in siphons if not any(o < s for o in siphons)]
    return {tuple(sorted(s)) for s in minimal}


@pytest.mark.slow
@settings(max_examples=200)
@given(small_nets())
def test_minimal_siphons_match_brute_force(net: Net) -> None:
    enumeration = minimal_siphons(net)
    assert enumeration.complete
    assert set(enumeration.siphons) == _brute_minimal_siphons(net)
    for siphon in enumeration.siphons:
        assert is_siphon(net, siphon)


@pytest.mark.slow
@settings(max_examples=200)
@given(small_nets())
def test_maximal_trap_is_the_union_of_traps_inside(net: Net) -> None:
    names = net.place_names
    for size in range(len(names) + 1):
        for subset in itertools.combinations(names, size):
            trap = maximal_trap(net, subset)
            assert is_trap(net, trap) and trap <= set(subset)
    traps = [
        frozenset(s)
        for size in range(len(names) + 1)
        for s in itertools.combinations(names, size)
        if is_trap(net, s)
    ]
    union = frozenset().union(*traps)
    assert maximal_trap(net, names) == union


@pytest.mark.slow
@settings(max_examples=300)
@given(small_nets(max_weight=1))
def test_deadlock_freedom_claims_hold_on_ordinary_nets(net: Net) -> None:
    check = siphon_trap_check(net)
    if check.proves_deadlock_free:
        reference = explore_reference(net, max_states=3_000)
        assert reference.dead == []


# -- conformance: MCC models ------------------------------------------------------------------


def _oracle_models() -> list[dict[str, Any]]:
    path = CONFORMANCE / "oracle.yaml"
    if not path.exists():
        return []
    models: list[dict[str, Any]] = yaml.safe_load(path.read_text())["models"]
    return models


_BIG = {"TokenRing-PT-010", "Peterson-PT-3", "Anderson-PT-04", "TokenRing-PT-005"}


@pytest.mark.parametrize(
    "model",
    [
        pytest.param(m, id=str(m["model"]), marks=[pytest.mark.slow] if m["model"] in _BIG else [])
        for m in _oracle_models()
        if m.get("deadlock") is not None
    ],
)
def test_siphon_trap_claims_never_contradict_the_mcc_oracle(model: dict[str, Any]) -> None:
    net: Net = read_pnml(Path(CONFORMANCE) / model["pnml"])
    check = siphon_trap_check(net, max_branches=20_000, budget=Budget(2.0))
    if model["deadlock"]:
        assert not check.proves_deadlock_free, check.explain()
    if model["live"] is False:
        assert not check.proves_live, check.explain()


@pytest.mark.slow
def test_weighted_mcc_model_with_the_property_still_deadlocks() -> None:
    """PGCD is weighted: every minimal siphon holds a marked trap, yet it deadlocks."""
    model = next((m for m in _oracle_models() if m["model"] == "PGCD-PT-D02N005"), None)
    assert model is not None, "the vendored conformance data (tests/data/mcc) is missing"
    check = siphon_trap_check(read_pnml(Path(CONFORMANCE) / model["pnml"]))
    assert model["deadlock"] is True
    assert check.holds is True and not check.proves_deadlock_free
    assert "partial argument" in check.scope
