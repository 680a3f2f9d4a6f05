"""Parents found again from the stored markings (`analysis.parents`): every stored state
gets a parent of the layer before, the trace it gives is a shortest firing sequence, and
a key that decodes to another marking is never taken for a parent."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings

import analysis.parents as parents
from analysis.encoding import CompactNet, KeyStore, Layout
from analysis.parents import parent_step
from analysis.statespace import explore
from coral_lang.net import Net, Place, Transition
from tests.analysis.nets import replay
from tests.analysis.reference import explore_reference
from tests.analysis.strategies import small_nets


def _check_every_state(net: Net, *, por: bool = False, states: int = 300) -> None:
    space = explore(net, max_states=states, por=por)
    for index in range(1, space.states):
        parent, t = parent_step(space.compact, space.layout, space.store, space.layer_starts, index)
        assert space.depth_of(parent) == space.depth_of(index) - 1
        assert net.enabled(space.marking(parent), net.transitions[t])
        assert net.fire(space.marking(parent), net.transitions[t]) == space.marking(index)
    for index in range(space.states - 1, 0, -max(1, space.states // 5)):  # a few traces
        trace = space.trace_to(index)
        assert len(trace) == space.depth_of(index)
        assert replay(net, trace) == space.marking(index)


@settings(max_examples=60, deadline=None)
@given(small_nets())
def test_every_stored_state_has_a_parent_one_layer_up(net: Net) -> None:
    _check_every_state(net)


@settings(max_examples=30, deadline=None)
@given(small_nets(max_places=6, max_transitions=7))
def test_parents_under_partial_order_reduction(net: Net) -> None:
    _check_every_state(net, por=True)


@settings(max_examples=40, deadline=None)
@given(small_nets())
def test_traces_are_shortest(net: Net) -> None:
    space = explore(net, max_states=300)
    if not space.complete:
        return
    ref = explore_reference(net)
    for index in range(space.states):
        assert len(space.trace_to(index)) == len(ref.trace_to(space.marking(index)))


def _counter_ring(n: int) -> Net:
    """A token goes round a ring of ``n`` places (a one-hot component) and every full
    turn adds a token to a counter that only grows (its field is widened)."""
    places = [Place(f"r{i}", 1 if i == 0 else 0) for i in range(n)] + [Place("count", 0)]
    moves = [Transition(f"m{i}", ((f"r{i}", 1),), ((f"r{i + 1}", 1),)) for i in range(n - 1)]
    lap = Transition("lap", ((f"r{n - 1}", 1),), (("r0", 1), ("count", 1)))
    return Net("ring", tuple(places), (*moves, lap))


def test_parents_through_components_and_widened_counts() -> None:
    net = _counter_ring(5)
    space = explore(net, max_states=200)
    assert space.states == 200
    _check_every_state(net, states=200)
    assert space.trace_to(199) == [0, 1, 2, 3, 4] * 39 + [0, 1, 2, 3]


def test_candidates_looked_up_in_blocks_give_the_same_parents(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # Every transition of the last one adds a token to p: all of them are candidates.
    places = (Place("p", 0), *(Place(f"q{i}", 1) for i in range(8)))
    transitions = tuple(Transition(f"t{i}", ((f"q{i}", 1),), (("p", 1),)) for i in range(8))
    net = Net("fan", places, transitions)
    space = explore(net)
    whole = [space.trace_to(i) for i in range(space.states)]
    monkeypatch.setattr(parents, "CANDIDATE_CELLS", len(places))  # one candidate a block
    assert [space.trace_to(i) for i in range(space.states)] == whole
    # the smallest transition wins at every step back: the trace fires it last
    assert space.trace_to(space.states - 1) == list(range(7, -1, -1))


def test_a_key_that_decodes_to_another_marking_is_no_parent() -> None:
    # Two count fields of 2 bits. Un-firing t (4 a -> b) from (0, 1) asks for (4, 0),
    # which does not fit its field and packs to the key of the stored (0, 1) itself.
    layout = Layout.for_bits([2, 2])
    net = Net(
        "decoy",
        (Place("a", 0), Place("b", 1)),
        (Transition("t", (("a", 4),), (("b", 1),)),),
    )
    cn = CompactNet.from_net(net)
    stored = np.array([[0, 1]], dtype=np.int64)
    decoy = np.array([[4, 0]], dtype=np.int64)
    assert layout.pack(decoy).tolist() == layout.pack(stored).tolist()
    store = KeyStore(1)
    store.add(layout.pack(stored))
    found = parents._stored_parents(cn, layout, store, stored[0], np.array([0]))
    assert found.tolist() == [-1]
    assert store.find(layout.pack(decoy)).tolist() == [0]  # (what the check caught)


def test_the_initial_state_and_unknown_states_have_no_parent() -> None:
    space = explore(_counter_ring(3), max_states=10)
    for index in (0, space.states, -1):
        with pytest.raises(ValueError, match="has no parent"):
            parent_step(space.compact, space.layout, space.store, space.layer_starts, index)


def test_a_state_whose_parent_is_not_stored_is_an_error() -> None:
    space = explore(_counter_ring(3), max_states=10)  # a chain: state i has parent i - 1
    starts = np.array([0, 1, 2], dtype=np.int64)  # state 5 said to be of layer 2
    with pytest.raises(ValueError, match="no stored parent"):
        parent_step(space.compact, space.layout, space.store, starts, 5)


def test_a_search_stopped_inside_a_layer_still_knows_the_layers_it_stored() -> None:
    # p1 pumps p0 forever; stubborn sets take layer-by-layer steps (no narrow rounds),
    # and the state limit cuts a step that stored the first state of a new layer.
    net = Net(
        "pump",
        (Place("p0", 0), Place("p1", 1)),
        (
            Transition("t0", (("p1", 1),), ()),
            Transition("t1", (("p0", 1),), ()),
            Transition("t2", (("p1", 1),), (("p0", 1), ("p1", 1))),
            Transition("t3", (("p0", 1),), ()),
        ),
    )
    full = explore(net, max_states=300)
    reduced = explore(net, max_states=300, por=True)
    assert not reduced.complete and reduced.states == 300
    assert reduced.layer_starts.tolist() == full.layer_starts.tolist()
    assert reduced.depth_of(299) == full.depth_of(299) == 150
    assert replay(net, reduced.trace_to(299)) == reduced.marking(299)
