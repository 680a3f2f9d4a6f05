"""Stubborn-set reduction gives the same verdicts as the full search."""

from __future__ import annotations

from functools import cache
from typing import Any
from unittest import mock

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from analysis import statespace
from analysis.encoding import CompactNet
from analysis.statespace import StateSpace, explore
from analysis.stubborn import StubbornSets
from coral_lang.net import Net, Place, Transition
from coral_lang.pnml import read_pnml
from tests.analysis.strategies import small_nets
from tests.analysis.test_conformance import MODELS
from tests.conftest import CONFORMANCE

BUDGET = 400
POR_MODELS = [name for name, m in MODELS.items() if m["states"] <= 100_000]
VISIBLE_MODELS = [name for name, m in MODELS.items() if m["states"] <= 30_000]


def _dead(space: StateSpace) -> set[tuple[int, ...]]:
    return {space.marking(i) for i in space.deadlocks.tolist()}


def _independent(n: int) -> Net:
    places = tuple(Place(f"p{i}", 1) for i in range(n))
    transitions = tuple(Transition(f"t{i}", ((f"p{i}", 1),), ()) for i in range(n))
    return Net("independent", places, transitions)


def test_independent_transitions_reduce_to_one_interleaving() -> None:
    full = explore(_independent(10))
    reduced = explore(_independent(10), por=True)
    assert (full.states, reduced.states) == (1024, 11)
    assert _dead(full) == _dead(reduced) == {(0,) * 10}
    assert reduced.reduced and len(reduced.trace_to(int(reduced.deadlocks[0]))) == 10


def test_visible_places_keep_their_interleavings() -> None:
    reduced = explore(_independent(4), por=True, visible=["p0", "p1"])
    assert {(m[0], m[1]) for m in reduced.markings.tolist()} == {(0, 0), (0, 1), (1, 0), (1, 1)}


@pytest.mark.slow
@settings(max_examples=300)
@given(small_nets())
def test_reduction_keeps_every_deadlock(net: Net) -> None:
    full = explore(net, max_states=BUDGET)
    if not full.complete:
        return
    reduced = explore(net, max_states=BUDGET, por=True)
    assert reduced.complete and reduced.states <= full.states
    assert _dead(reduced) == _dead(full)
    for index in reduced.deadlocks.tolist():
        marking = net.initial_marking()
        for t in reduced.trace_to(index):
            assert net.enabled(marking, net.transitions[t])
            marking = net.fire(marking, net.transitions[t])
        assert marking == reduced.marking(index)


@st.composite
def _predicates(draw: st.DrawFn, n_places: int) -> tuple[list[int], list[int]]:
    places = draw(st.lists(st.integers(0, n_places - 1), min_size=1, max_size=2, unique=True))
    levels = [draw(st.integers(1, 3)) for _ in places]
    return places, levels


def _holds(places: list[int], levels: list[int]) -> Any:
    def predicate(m: np.ndarray[Any, Any]) -> Any:
        ok = np.ones(m.shape[0], dtype=bool)
        for p, k in zip(places, levels, strict=True):
            ok &= m[:, p] >= k
        return ok

    return predicate


@pytest.mark.slow
@settings(max_examples=300)
@given(small_nets(), st.data())
def test_reduction_keeps_reachability_of_visible_predicates(net: Net, data: st.DataObject) -> None:
    full = explore(net, max_states=BUDGET)
    if not full.complete:
        return
    places, levels = data.draw(_predicates(len(net.places)))
    names = [net.places[p].name for p in places]
    reduced = explore(net, max_states=BUDGET, por=True, visible=names)
    assert reduced.complete
    predicate = _holds(places, levels)
    assert (reduced.find(predicate) is None) == (full.find(predicate) is None)
    assert reduced.max_sum(places) == full.max_sum(places)
    full_values = {tuple(m) for m in full.markings[:, places].tolist()}
    assert {tuple(m) for m in reduced.markings[:, places].tolist()} == full_values


def test_stubborn_sets_fall_back_to_everything_when_nothing_is_smaller() -> None:
    net = Net(
        "choice",
        (Place("a", 1), Place("b"), Place("c")),
        (Transition("x", (("a", 1),), (("b", 1),)), Transition("y", (("a", 1),), (("c", 1),))),
    )
    sets = StubbornSets(CompactNet.from_net(net))
    assert sets.stubborn([1, 0, 0], [0, 1]) == [0, 1]


@cache
def _full(name: str) -> StateSpace:
    return explore(read_pnml(CONFORMANCE / MODELS[name]["pnml"]))


def _slow(name: str) -> Any:
    marks = [pytest.mark.slow] if MODELS[name]["states"] > 20_000 else []
    return pytest.param(name, marks=marks, id=name)


@pytest.mark.slow
@pytest.mark.parametrize("name", [_slow(n) for n in POR_MODELS])
def test_deadlock_verdicts_match_the_oracle_on_conformance_models(name: str) -> None:
    net = read_pnml(CONFORMANCE / MODELS[name]["pnml"])
    reduced = explore(net, por=True)
    assert reduced.complete
    assert reduced.states <= MODELS[name]["states"]
    assert reduced.has_deadlock == MODELS[name]["deadlock"]


@pytest.mark.slow
@pytest.mark.parametrize("name", [_slow(n) for n in VISIBLE_MODELS])
def test_place_predicates_match_the_full_search_on_conformance_models(name: str) -> None:
    full = _full(name)
    net = full.net
    rng = np.random.default_rng(sum(name.encode()))  # seeded per model: deterministic
    for _ in range(3):
        places = sorted(rng.choice(len(net.places), size=min(2, len(net.places)), replace=False))
        places = [int(p) for p in places]
        bounds = [int(full.place_bounds[p]) for p in places]
        reduced = explore(net, por=True, visible=[net.places[p].name for p in places])
        assert reduced.complete
        for levels in ([max(1, b) for b in bounds], [1] * len(places)):
            predicate = _holds(places, levels)
            assert (reduced.find(predicate) is None) == (full.find(predicate) is None)
        assert reduced.max_sum(places) == full.max_sum(places)


def _shared_switches(n: int) -> Net:
    """``n`` on/off switches that all read one shared place (take its token and put it
    back): every transition shares an input place with every other, so no stubborn set
    is smaller than all enabled transitions, and there are ``2 ** n`` markings."""
    offs = [Place(f"off{i}", 1) for i in range(n)]
    places = (Place("g", 1), *offs, *(Place(f"on{i}") for i in range(n)))
    transitions = tuple(
        Transition(f"up{i}", ((f"off{i}", 1), ("g", 1)), ((f"on{i}", 1), ("g", 1)))
        for i in range(n)
    ) + tuple(
        Transition(f"down{i}", ((f"on{i}", 1), ("g", 1)), ((f"off{i}", 1), ("g", 1)))
        for i in range(n)
    )
    return Net("switches", places, transitions)


def test_a_reduction_that_prunes_nothing_is_switched_off_and_says_so() -> None:
    net = _shared_switches(13)
    full = explore(net)
    reduced = explore(net, por=True)
    assert full.complete and reduced.complete
    assert reduced.states == full.states > statespace.POR_SAMPLE
    assert (
        reduced.reduction_note is not None
        and "expanded every marking fully" in reduced.reduction_note
    )
    assert _dead(reduced) == _dead(full)


def test_a_reduction_that_prunes_is_kept() -> None:
    reduced = explore(_independent(14), por=True)
    assert reduced.reduction_note is None and reduced.states == 15


@pytest.mark.slow
@settings(max_examples=200)
@given(small_nets(), st.integers(1, 40))
def test_switching_the_reduction_off_part_way_keeps_every_deadlock(net: Net, sample: int) -> None:
    """Markings expanded with stubborn sets before the switch and fully after it: a
    mixed graph still keeps every deadlock (a full expansion is a stubborn set)."""
    full = explore(net, max_states=BUDGET)
    if not full.complete:
        return
    with (
        mock.patch.object(statespace, "POR_SAMPLE", sample),
        mock.patch.object(statespace, "POR_USELESS", 0.0),
    ):
        reduced = explore(net, max_states=BUDGET, por=True, chunk=4)
    assert reduced.complete and reduced.states <= full.states
    assert _dead(reduced) == _dead(full)
