"""Random walks find dead markings that exist and invent none."""

from __future__ import annotations

from hypothesis import given, settings

from analysis.reduce.deadlock import is_dead, replay
from analysis.reduce.walk import walk_to_deadlock
from analysis.statespace import explore
from coral_lang.net import Net, Place, Transition
from tests.analysis.strategies import small_nets


@given(small_nets(max_places=5, max_transitions=6))
@settings(max_examples=60)
def test_a_walk_ends_in_a_reachable_dead_marking_or_finds_nothing(net: Net) -> None:
    trace = walk_to_deadlock(net, steps=200)
    if trace is None:
        return
    reached = replay(net, trace)
    assert reached is not None and is_dead(net, reached)


def test_a_walk_finds_the_blocking_of_two_philosophers() -> None:
    """Each philosopher takes the left fork then the right: both holding the left one
    is the dead marking, reached by a walk in a few steps."""
    places = [Place(f"fork{i}", 1) for i in range(2)]
    places += [Place(f"think{i}", 1) for i in range(2)] + [Place(f"hold{i}") for i in range(2)]
    transitions = []
    for i in range(2):
        left, right = f"fork{i}", f"fork{(i + 1) % 2}"
        transitions.append(
            Transition(f"take{i}", ((f"think{i}", 1), (left, 1)), ((f"hold{i}", 1),))
        )
        transitions.append(
            Transition(
                f"eat{i}",
                ((f"hold{i}", 1), (right, 1)),
                ((f"think{i}", 1), (left, 1), (right, 1)),
            )
        )
    net = Net("philosophers", tuple(places), tuple(transitions))
    assert explore(net).has_deadlock
    trace = walk_to_deadlock(net)
    assert trace is not None
    reached = replay(net, trace)
    assert reached is not None and is_dead(net, reached)


def test_a_live_net_gives_no_walk() -> None:
    net = Net(
        "cycle",
        (Place("a", 1), Place("b")),
        (Transition("ab", (("a", 1),), (("b", 1),)), Transition("ba", (("b", 1),), (("a", 1),))),
    )
    assert walk_to_deadlock(net) is None
