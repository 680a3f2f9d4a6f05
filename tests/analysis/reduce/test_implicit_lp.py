"""The linear-programming implicit-place rule leaves the reachability graph isomorphic:
checked on random nets and on random nets with a sum-of-places place inserted."""

from __future__ import annotations

from hypothesis import assume, given, settings
from hypothesis import strategies as st

from analysis.reduce.driver import reduce_net
from analysis.reduce.goal import Goal
from analysis.reduce.implicit_lp import remove_lp_implicit_places
from analysis.reduce.work import WorkNet
from analysis.statespace import explore
from coral_lang.net import Net, Place, Transition
from tests.analysis.strategies import small_nets

MAX_STATES = 300


@st.composite
def with_sum_place(draw: st.DrawFn) -> Net:
    """A random net plus a place holding ``M(q1) + M(q2) + extra``: implicit, but only
    with both places together as the witness (beyond the one-witness cheap rule)."""
    net = draw(small_nets(max_places=5, max_transitions=6))
    assume(len(net.places) >= 2)
    q1, q2 = draw(st.lists(st.sampled_from(net.places), min_size=2, max_size=2, unique=True))
    extra = draw(st.integers(0, 2))
    transitions = []
    for t in net.transitions:
        take = sum(k for q, k in t.inputs if q in (q1.name, q2.name))
        give = sum(k for q, k in t.outputs if q in (q1.name, q2.name))
        inputs = t.inputs + ((("sum", take),) if take else ())
        outputs = t.outputs + ((("sum", give),) if give else ())
        transitions.append(Transition(t.name, inputs=inputs, outputs=outputs))
    total = Place("sum", initial=q1.initial + q2.initial + extra)
    return Net(name="sum", places=(*net.places, total), transitions=tuple(transitions))


def _lp_reduced(net: Net) -> tuple[Net, int]:
    w = WorkNet(net, Goal.deadlock())
    while remove_lp_implicit_places(w):
        w.lp_tried.clear()
    return w.to_net(), w.applied["implicit-place-lp"]


@given(st.one_of(small_nets(max_places=6, max_transitions=7), with_sum_place()))
@settings(max_examples=40, deadline=None)
def test_removing_lp_implicit_places_keeps_the_reachability_graph(net: Net) -> None:
    original = explore(net, max_states=MAX_STATES)
    assume(original.complete)
    reduced_net, _ = _lp_reduced(net)
    reduced = explore(reduced_net, max_states=MAX_STATES)
    assert reduced.complete
    assert reduced.states == original.states
    assert reduced.edges == original.edges
    assert reduced.deadlocks.size == original.deadlocks.size
    for i, place in enumerate(reduced_net.places):  # bounds of the places kept
        assert reduced.place_bounds[i] == original.place_bounds[net.place_index(place.name)]


def test_a_sum_place_is_found_implicit() -> None:
    places = (Place("a", initial=1), Place("b"), Place("c"), Place("sum", initial=1))
    transitions = (
        Transition("ab", inputs=(("a", 1), ("sum", 1)), outputs=(("b", 1), ("sum", 1))),
        Transition("bc", inputs=(("b", 1), ("sum", 1)), outputs=(("c", 1),)),
        Transition("ca", inputs=(("c", 1),), outputs=(("a", 1), ("sum", 1))),
    )
    reduced, removed = _lp_reduced(Net(name="n", places=places, transitions=transitions))
    assert removed >= 1 and "sum" not in {p.name for p in reduced.places}


def test_a_place_that_restricts_is_kept() -> None:
    # "gate" has no token: it disables "go", so it is not implicit; "a" always holds one
    # token more than "gate", so "a" is (one witness, weight 1).
    places = (Place("a", initial=1), Place("gate"), Place("b"))
    transitions = (Transition("go", inputs=(("a", 1), ("gate", 1)), outputs=(("b", 1),)),)
    reduced, removed = _lp_reduced(Net(name="n", places=places, transitions=transitions))
    assert removed == 1 and {p.name for p in reduced.places} == {"gate", "b"}


def test_the_driver_runs_the_lp_rule_only_when_asked() -> None:
    places = (Place("a", initial=1), Place("b"), Place("c"), Place("sum", initial=1))
    transitions = (
        Transition("ab", inputs=(("a", 1), ("sum", 1)), outputs=(("b", 1), ("sum", 1))),
        Transition("bc", inputs=(("b", 1), ("sum", 1)), outputs=(("c", 1),)),
        Transition("ca", inputs=(("c", 1),), outputs=(("a", 1), ("sum", 1))),
    )  # sum = a + b: no single place witnesses it, the one-witness rule cannot
    net = Net(name="n", places=places, transitions=transitions)
    goal = Goal.bounds(["a", "b", "c"])
    assert "implicit-place-lp" not in reduce_net(net, goal).applied
    assert reduce_net(net, goal, lp_seconds=1.0).applied.get("implicit-place-lp") == 1
