"""The siphon-trap check proves deadlock-freedom only of nets that have no dead marking."""

from __future__ import annotations

from hypothesis import assume, given, settings

from analysis.reduce.siphon_trap import siphons_prove_deadlock_free
from analysis.statespace import explore
from coral_lang.net import Net, Place, Transition
from tests.analysis.strategies import small_nets


@given(small_nets(max_places=5, max_transitions=6, max_weight=1))
@settings(max_examples=60)
def test_a_proof_means_no_reachable_dead_marking(net: Net) -> None:
    if not siphons_prove_deadlock_free(net):
        return
    space = explore(net, max_states=300)
    assume(space.complete)
    assert not space.has_deadlock


def _mutex(lock: int) -> Net:
    """Two processes around a lock: idle -> (take the lock) -> busy -> (give it) -> idle."""
    places = [Place("lock", lock)]
    transitions = []
    for i in range(2):
        places += [Place(f"idle{i}", 1), Place(f"busy{i}")]
        transitions.append(
            Transition(f"enter{i}", ((f"idle{i}", 1), ("lock", 1)), ((f"busy{i}", 1),))
        )
        transitions.append(
            Transition(f"leave{i}", ((f"busy{i}", 1),), ((f"idle{i}", 1), ("lock", 1)))
        )
    return Net("mutex", tuple(places), tuple(transitions))


def test_a_mutex_with_its_lock_is_proved_and_without_it_is_not() -> None:
    assert siphons_prove_deadlock_free(_mutex(1))
    assert not siphons_prove_deadlock_free(_mutex(0))  # {lock, busy0, busy1} stays empty
    assert explore(_mutex(0)).has_deadlock


def test_weighted_nets_are_not_judged() -> None:
    """With weights a dead transition may have tokens on every input: no proof."""
    net = Net(
        "weighted",
        (Place("a", 1),),
        (Transition("t", (("a", 2),), (("a", 2),)),),
    )
    assert not siphons_prove_deadlock_free(net)
    assert explore(net).has_deadlock
