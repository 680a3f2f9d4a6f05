"""Twins (transitions with the same effect as a lower-numbered one) are fired only when
no lower twin is enabled in the same marking (`_EnablingBits._twin_runs`): the space,
its numbering, edges and traces stay those of the search that fires them all."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import analysis.statespace as statespace
from analysis.budget import Budget
from analysis.encoding import CompactNet
from analysis.statespace import StateSpace, explore
from coral_lang.net import Net, Place, Transition
from tests.analysis.explored import counting_fired, fingerprint
from tests.analysis.nets import replay
from tests.analysis.reference import explore_reference
from tests.analysis.strategies import small_nets

WIDE = {"NARROW_WIDTH": 0, "SLEEP_MIN_DEGREE": 0.0}  # layer by layer, sleep sets on


@pytest.fixture
def wide(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    for name, value in WIDE.items():
        monkeypatch.setattr(statespace, name, value)
    yield


@st.composite
def nets_with_twins(draw: st.DrawFn) -> Net:
    """A random net plus copies of some of its transitions, each with the same effect
    and a read arc more (so twins differ in when they are enabled)."""
    net = draw(small_nets(max_places=5, max_transitions=5))
    places = [p.name for p in net.places]
    extra = []
    for k, t in enumerate(net.transitions):
        for j in range(draw(st.integers(0, 3))):
            read = draw(st.sampled_from(places))
            weight = draw(st.integers(1, 2))
            inputs = dict(t.inputs)
            outputs = dict(t.outputs)
            inputs[read] = inputs.get(read, 0) + weight
            outputs[read] = outputs.get(read, 0) + weight
            extra.append(
                Transition(
                    f"c{k}_{j}", tuple(sorted(inputs.items())), tuple(sorted(outputs.items()))
                )
            )
    order = draw(st.permutations([*net.transitions, *extra]))
    return Net("twins", net.places, tuple(order))


def _without_twins(net: Net) -> StateSpace:
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(statespace._EnablingBits, "_twin_runs", lambda self, effects: None)
        return explore(net, max_states=400)


@settings(max_examples=80, deadline=None)
@given(nets_with_twins())
def test_firing_one_twin_finds_the_same_space_in_the_same_order(net: Net) -> None:
    with pytest.MonkeyPatch.context() as patch:
        for name, value in WIDE.items():
            patch.setattr(statespace, name, value)
        space = explore(net, max_states=400)
        every = _without_twins(net)
    assert space.complete == every.complete
    if not space.complete:
        assert space.states == every.states
        return
    assert fingerprint(space) == fingerprint(every)
    ref = explore_reference(net, max_states=400)
    assert space.states == len(ref.states) and space.edges == ref.edges
    for index in space.deadlocks.tolist():
        trace = space.trace_to(index)
        assert replay(net, trace) == space.marking(index)
        assert len(trace) == len(ref.trace_to(space.marking(index)))


def _withdraw(k: int) -> Net:
    """A process in ``wait`` withdraws when any of ``k`` flags is up (all up): ``k``
    twins, plus a toggle of each flag (dependent on every twin: it lowers their read)."""
    places = [Place("wait", 1), Place("idle")]
    places += [Place(f"f{j}", 1) for j in range(k)] + [Place(f"g{j}") for j in range(k)]
    ts = [
        Transition(f"w{j}", (("f" + str(j), 1), ("wait", 1)), (("f" + str(j), 1), ("idle", 1)))
        for j in range(k)
    ]
    ts += [Transition(f"down{j}", ((f"f{j}", 1),), ((f"g{j}", 1),)) for j in range(k)]
    return Net("withdraw", tuple(places), tuple(ts))


def _fired(net: Net, twins: bool) -> tuple[StateSpace, int]:
    with pytest.MonkeyPatch.context() as patch, counting_fired() as fired:
        if not twins:
            patch.setattr(statespace._EnablingBits, "_twin_runs", lambda self, effects: None)
        space = explore(net)
    return space, fired[0]


@pytest.mark.usefixtures("wide")
def test_only_the_lowest_enabled_twin_is_fired() -> None:
    net = _withdraw(6)  # every setting of the 6 flags, waiting or not
    full, every = _fired(net, twins=False)
    one, fired = _fired(net, twins=True)
    ref = explore_reference(net)
    assert (one.states, one.edges) == (full.states, full.edges) == (len(ref.states), ref.edges)
    assert one.states == 128 and len(one.deadlocks) == 2
    assert one.keys.tolist() == full.keys.tolist()
    assert one.layer_starts.tolist() == full.layer_starts.tolist()
    # one key per new state, where sleep sets alone fired some twins beside each other
    # (Dekker-PT-015: 715,000 keys instead of 3,950,000)
    assert fired == one.states - 1 < every


def test_runs_stop_at_word_ends_and_at_other_classes() -> None:
    # t0..t69 share one effect except t3 (another one) and t4 (a self-loop): the runs
    # are t0-t2, t5-t63 and t64-t69 (bit words end at 64).
    places = (Place("a", 1), Place("b"), Place("c"))
    move = ((("a", 1),), (("b", 1),))
    ts = [Transition(f"t{i}", *move) for i in range(70)]
    ts[3] = Transition("t3", (("a", 1),), (("c", 1),))
    ts[4] = Transition("t4", (("a", 1),), (("a", 1),))
    cn = CompactNet.from_net(Net("runs", places, tuple(ts)))
    explorer = statespace._Explorer(cn, None, Budget(), None, None, 1 << 15)
    bits = explorer.bits
    assert bits is not None and len(bits.twin_groups) == 1  # (no two runs touch)
    everything = np.full((1, 2), ~np.uint64(0), dtype=np.uint64)
    below = bits.transitions(bits.twins_below(everything)[0])
    assert np.flatnonzero(~below).tolist() == [0, 3, 4, 5, 64]
    # with only t2, t7, t9 and t65 enabled: t2, t7 and t65 are the lowest of their runs
    some = np.zeros((1, 2), dtype=np.uint64)
    some[0] = [(1 << 2) | (1 << 7) | (1 << 9), 1 << 1]
    assert np.flatnonzero(bits.transitions(bits.twins_below(some)[0])).tolist() == [9]


def test_touching_runs_of_two_classes_keep_a_lowest_bit_each() -> None:
    # t0..t3 move a to b, t4..t6 move a to c: two runs that touch, in two groups; an
    # empty run must not borrow from the run above it
    places = (Place("a", 1), Place("b"), Place("c"))
    ts = [Transition(f"t{i}", (("a", 1),), (("b" if i < 4 else "c", 1),)) for i in range(7)]
    cn = CompactNet.from_net(Net("touching", places, tuple(ts)))
    bits = statespace._Explorer(cn, None, Budget(), None, None, 1 << 15).bits
    assert bits is not None and len(bits.twin_groups) == 2
    for enabled in range(1 << 7):
        row = np.array([[enabled]], dtype=np.uint64)
        dropped = np.flatnonzero(bits.transitions(bits.twins_below(row)[0])).tolist()
        on = [i for i in range(7) if enabled >> i & 1]
        keep = [
            min((i for i in on if i < 4), default=-1),
            min((i for i in on if i >= 4), default=-1),
        ]
        assert dropped == [i for i in on if i not in keep]
