"""The reference explorer itself, on nets whose answers are known by hand."""

from __future__ import annotations

from coral_lang.net import Net, Place, Transition
from tests.analysis.reference import explore_reference


def _cycle(n: int) -> Net:
    places = tuple(Place(f"p{i}", initial=1 if i == 0 else 0) for i in range(n))
    transitions = tuple(
        Transition(f"t{i}", inputs=((f"p{i}", 1),), outputs=((f"p{(i + 1) % n}", 1),))
        for i in range(n)
    )
    return Net("cycle", places, transitions)


def test_token_on_a_cycle_has_n_states_and_no_deadlock() -> None:
    result = explore_reference(_cycle(4))
    assert len(result.states) == 4 and result.edges == 4 and result.dead == [] and result.complete


def test_two_transitions_to_one_successor_count_as_two_edges() -> None:
    net = Net(
        "fork",
        (Place("a", 1), Place("b")),
        (Transition("t1", (("a", 1),), (("b", 1),)), Transition("t2", (("a", 1),), (("b", 1),))),
    )
    result = explore_reference(net)
    assert len(result.states) == 2 and result.edges == 2 and result.dead == [(0, 1)]
    assert result.trace_to((0, 1)) == [0]


def test_unbounded_net_stops_at_the_budget() -> None:
    net = Net(
        "pump", (Place("a", 1), Place("b")), (Transition("t", (("a", 1),), (("a", 1), ("b", 1))),)
    )
    result = explore_reference(net, max_states=50)
    assert not result.complete and len(result.states) == 50
