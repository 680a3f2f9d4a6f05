"""Reduced nets answer as the original: checked by exploring both on random small nets."""

from __future__ import annotations

import numpy as np
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from analysis.reduce import Goal, decide_deadlock, reduce_net
from analysis.reduce.deadlock import is_dead, replay
from analysis.statespace import StateSpace, explore
from coral_lang.net import Net, Place, Transition
from tests.analysis.strategies import small_nets

MAX_STATES = 200


def _complete(net: Net) -> StateSpace:
    space = explore(net, max_states=MAX_STATES)
    assume(space.complete)
    return space


def _observed(space: StateSpace, places: list[str], transitions: list[str]) -> set[tuple[int, ...]]:
    """Every reachable (values of ``places``, enabledness of ``transitions``) pair."""
    net = space.net
    m = space.markings
    cols = [m[:, net.place_index(p)] for p in places]
    for name in transitions:
        t = net.transition(name)
        ok = np.ones(space.states, dtype=bool)
        for p, w in t.inputs:
            ok &= m[:, net.place_index(p)] >= w
        cols.append(ok.astype(np.int64))
    rows = np.stack(cols, axis=1) if cols else np.zeros((space.states, 0), dtype=np.int64)
    return {tuple(int(v) for v in row) for row in rows}


def assert_same_observations(net: Net, places: list[str], transitions: list[str]) -> StateSpace:
    """The net reduced for reachability of ``places`` and ``transitions`` reaches the same
    (observed values, observed enabledness) as the original; returns the original's
    complete space."""
    original = _complete(net)
    reduced = explore(reduce_net(net, Goal.reachability(places, transitions)).net, max_states=None)
    assert reduced.complete
    assert _observed(reduced, places, transitions) == _observed(original, places, transitions)
    return original


@st.composite
def series_nets(draw: st.DrawFn) -> Net:
    """A random net with some arcs split by a new place and transition in series, the
    shapes the agglomeration and fusion rules look for (plain random nets rarely have
    them)."""
    net = draw(small_nets(max_places=5, max_transitions=5))
    places = list(net.places)
    transitions = []
    for t in net.transitions:
        inputs, outputs = list(t.inputs), list(t.outputs)
        extra: list[Transition] = []
        split_out: bool = draw(st.booleans())
        split_in: bool = draw(st.booleans())
        if outputs and split_out:
            p, w = outputs.pop(0)
            q = f"{t.name}_out"
            places.append(Place(q))
            outputs.append((q, w))
            extra.append(Transition(f"{t.name}_fwd", inputs=((q, w),), outputs=((p, w),)))
        if inputs and split_in:
            p, w = inputs.pop(0)
            q = f"{t.name}_in"
            places.append(Place(q))
            inputs.append((q, 1))
            extra.append(Transition(f"{t.name}_take", inputs=((p, w),), outputs=((q, 1),)))
        transitions.append(Transition(t.name, inputs=tuple(inputs), outputs=tuple(outputs)))
        transitions.extend(extra)
    return Net(name="series", places=tuple(places), transitions=tuple(transitions))


any_nets = st.one_of(small_nets(max_places=6, max_transitions=7), series_nets())


@given(any_nets)
@settings(max_examples=60)
def test_deadlock_verdict_and_witness_survive_reduction(net: Net) -> None:
    assert_deadlock_preserved(net)


def assert_deadlock_preserved(net: Net) -> None:
    """The reduced net's deadlock verdict is the full search's, and its witness replays
    on ``net`` to a dead marking."""
    original = _complete(net)
    answer = decide_deadlock(net, max_states=MAX_STATES)
    assert answer.deadlock == original.has_deadlock
    if answer.deadlock:
        assert answer.trace is not None
        reached = replay(net, answer.trace)
        assert reached is not None and is_dead(net, reached)


@st.composite
def nets_and_observed(draw: st.DrawFn) -> tuple[Net, list[str], list[str]]:
    net = draw(any_nets)
    names = [p.name for p in net.places]
    places = draw(st.lists(st.sampled_from(names), unique=True, max_size=3))
    trans = [t.name for t in net.transitions]
    transitions = draw(st.lists(st.sampled_from(trans), unique=True, max_size=2))
    return net, places, transitions


@given(nets_and_observed())
@settings(max_examples=60)
def test_reachable_observations_are_the_same(case: tuple[Net, list[str], list[str]]) -> None:
    """Equal sets of observed values: every predicate over them is reachable in both or
    neither (EF/AG questions), and every bound over them is the same."""
    assert_same_observations(*case)


@given(nets_and_observed())
@settings(max_examples=60)
def test_bounds_are_the_same(case: tuple[Net, list[str], list[str]]) -> None:
    net, places, _ = case
    assume(places)
    original = _complete(net)
    red = reduce_net(net, Goal.bounds(places))
    reduced = explore(red.net, max_states=None)
    for k in range(1, len(places) + 1):
        group = places[:k]
        want = original.max_sum([net.place_index(p) for p in group])
        assert reduced.max_sum([red.net.place_index(p) for p in group]) == want


def _chain(length: int) -> Net:
    """A pipeline p0 -> t0 -> p1 -> ... ending in a dead marking, plus a mutex place."""
    places = [Place(f"p{i}", initial=1 if i == 0 else 0) for i in range(length + 1)]
    places.append(Place("lock", initial=1))
    transitions = [
        Transition(
            f"t{i}", inputs=((f"p{i}", 1), ("lock", 1)), outputs=((f"p{i + 1}", 1), ("lock", 1))
        )
        for i in range(length)
    ]
    return Net(name="chain", places=tuple(places), transitions=tuple(transitions))


def test_a_chain_reduces_to_nothing_and_its_witness_is_the_whole_chain() -> None:
    net = _chain(6)
    answer = decide_deadlock(net)
    assert answer.deadlock is True
    assert answer.trace == [f"t{i}" for i in range(6)]
    assert len(answer.reduction.net.transitions) < len(net.transitions)
    assert answer.states <= 2


def test_observed_places_are_kept() -> None:
    net = _chain(4)
    red = reduce_net(net, Goal.bounds(["p2"]))
    assert "p2" in [p.name for p in red.net.places]
    assert explore(red.net).max_sum([red.net.place_index("p2")]) == 1
