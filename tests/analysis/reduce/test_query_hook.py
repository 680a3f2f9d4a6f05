"""`coral-check query`'s ReachabilityDeadlock goes through the reductions first."""

from __future__ import annotations

from analysis.examinations import QueryLimits, QuerySession
from analysis.reduce.deadlock import is_dead, replay
from coral_lang.net import Net, Place, Transition
from coral_lang.pnml import read_pnml
from tests.conftest import CONFORMANCE


def _pipeline(stages: int, loop: bool) -> Net:
    """Stages in series; with ``loop`` the last one feeds the first (no deadlock)."""
    places = tuple(Place(f"p{i}", initial=1 if i == 0 else 0) for i in range(stages + 1))
    transitions = [
        Transition(f"t{i}", inputs=((f"p{i}", 1),), outputs=((f"p{i + 1}", 1),))
        for i in range(stages)
    ]
    if loop:
        transitions.append(Transition("back", inputs=((f"p{stages}", 1),), outputs=(("p0", 1),)))
    return Net(name="pipeline", places=places, transitions=tuple(transitions))


def test_deadlock_is_decided_on_the_reduced_net_with_a_replayable_trace() -> None:
    net = _pipeline(5, loop=False)
    session = QuerySession(net)
    answer = session.check_global("ReachabilityDeadlock")
    assert answer.value is True
    assert "STRUCTURAL_REDUCTION" in answer.techniques
    assert answer.trace is not None
    reached = replay(net, answer.trace)
    assert reached is not None and is_dead(net, reached)
    assert session.space is None  # the full search was not needed


def test_no_deadlock_is_decided_too() -> None:
    answer = QuerySession(_pipeline(5, loop=True)).check_global("ReachabilityDeadlock")
    assert answer.value is False
    assert "STRUCTURAL_REDUCTION" in answer.techniques


def test_the_techniques_name_what_decided() -> None:
    """A walk reaching the dead marking reports RANDOM_WALK; a siphon-trap proof on the
    reduced net TOPOLOGICAL (Dekker's mutual exclusion, 6,144 markings unexplored)."""
    walked = QuerySession(_pipeline(5, loop=False)).check_global("ReachabilityDeadlock")
    assert walked.techniques == ("STRUCTURAL_REDUCTION", "RANDOM_WALK")
    dekker = read_pnml(CONFORMANCE / "pnml" / "Dekker-PT-010.pnml")
    proved = QuerySession(dekker).check_global("ReachabilityDeadlock")
    assert proved.value is False
    assert proved.techniques == ("STRUCTURAL_REDUCTION", "TOPOLOGICAL")


def test_the_reductions_switch_turns_them_off_for_deadlock_too() -> None:
    limits = QueryLimits(reductions=False)
    answer = QuerySession(_pipeline(5, loop=False), limits).check_global("ReachabilityDeadlock")
    assert answer.value is True
    assert "STRUCTURAL_REDUCTION" not in answer.techniques
