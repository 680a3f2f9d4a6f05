"""`verify`'s deadlock property falls back on the reduced net when the full search
stops undecided; declared final markings stay no deadlock on the reduced net."""

from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st

from analysis.reduce.deadlock import decide_deadlock, is_dead, replay
from analysis.report import Verdict
from analysis.statespace import explore
from analysis.verify import REDUCED, REDUCED_BY, VerifyOptions, verify
from coral_lang import compile_mission
from coral_lang.net import FinalMarking, Net, Place, Transition
from tests.analysis.reduce.test_preservation import MAX_STATES, _complete, any_nets
from tests.conftest import EXAMPLES


def _deadlock(net: Net, max_states: int) -> tuple[Verdict, str, tuple[str, ...] | None]:
    report = verify(net, VerifyOptions(structural=False, max_states=max_states))
    result = next(p for p in report.properties if p.key == "deadlock")
    trace = None
    if result.evidence is not None:
        trace = tuple(step.transition for step in result.evidence.trace)
    return result.verdict, result.method, trace


def _chains(chains: int, length: int, loop: bool) -> Net:
    """Independent chains of ``length`` steps: (length + 1) ** chains markings, one
    marking per chain once the series rules have run."""
    places: list[Place] = []
    transitions: list[Transition] = []
    for c in range(chains):
        names = [f"c{c}p{i}" for i in range(length + 1)]
        places += [Place(n, initial=1 if i == 0 else 0) for i, n in enumerate(names)]
        transitions += [
            Transition(f"c{c}t{i}", inputs=((names[i], 1),), outputs=((names[i + 1], 1),))
            for i in range(length)
        ]
        if loop:
            transitions.append(
                Transition(f"c{c}back", inputs=((names[-1], 1),), outputs=((names[0], 1),))
            )
    return Net(name="chains", places=tuple(places), transitions=tuple(transitions))


def test_a_deadlock_the_full_search_cannot_reach_is_found_on_the_reduced_net() -> None:
    net = _chains(4, 6, loop=False)  # 2401 markings in full
    verdict, method, trace = _deadlock(net, max_states=100)
    # the chains reduce to one transition: a random walk reaches its dead marking
    assert (verdict, method) == (Verdict.VIOLATED, REDUCED_BY["random walk"])
    assert trace is not None
    reached = replay(net, trace)
    assert reached is not None and is_dead(net, reached)


def test_deadlock_freedom_is_proven_on_the_reduced_net() -> None:
    # the reduced net is one transition without inputs: no siphon, so no deadlock
    verdict, method, _ = _deadlock(_chains(4, 6, loop=True), max_states=100)
    assert (verdict, method) == (Verdict.PROVEN, REDUCED_BY["siphon-trap"])


def test_a_complete_full_search_still_decides_alone() -> None:
    verdict, method, _ = _deadlock(_chains(2, 2, loop=False), max_states=100)
    assert verdict is Verdict.VIOLATED and method not in (REDUCED, *REDUCED_BY.values())


def test_the_pool_mission_is_proven_on_the_reduced_net_with_its_finals() -> None:
    # 82 markings in full, 42 once reduced: the full search stops, the reduced one ends.
    net = compile_mission(EXAMPLES / "pool_mission" / "pool_mission.coral")
    assert net.finals
    verdict, method, _ = _deadlock(net, max_states=60)
    assert (verdict, method) == (Verdict.PROVEN, REDUCED)


def test_a_faulty_missions_deadlock_is_found_on_the_reduced_net_and_is_not_final() -> None:
    net = compile_mission(EXAMPLES / "faulty" / "deadlock.coral")  # 38 full, 18 reduced
    full, _, _ = _deadlock(net, max_states=100_000)
    verdict, method, trace = _deadlock(net, max_states=12)
    assert full is Verdict.VIOLATED
    assert (verdict, method) == (Verdict.VIOLATED, REDUCED)
    assert trace is not None
    reached = replay(net, trace)
    assert reached is not None and is_dead(net, reached)
    assert not net.final_test().matches(reached)


def _with_finals(net: Net, finals: list[tuple[int, ...]]) -> Net:
    declared = tuple(
        FinalMarking(tuple((net.places[i].name, v) for i, v in enumerate(m) if v)) for m in finals
    )
    return Net(net.name, net.places, net.transitions, finals=declared)


@given(any_nets, st.data())
@settings(max_examples=60, deadline=None)
def test_final_dead_markings_are_no_deadlock_on_the_reduced_net_either(
    net: Net, data: st.DataObject
) -> None:
    space = _complete(net)
    dead = [tuple(int(v) for v in space.markings[int(s)]) for s in space.deadlocks]
    finals = [m for m in dead if data.draw(st.booleans())]
    marked = _with_finals(net, finals)
    accepted = marked.final_test().matches if marked.finals else None
    answer = decide_deadlock(marked, max_states=MAX_STATES, accepted=accepted)
    expected = any(m not in finals for m in dead)
    assert answer.deadlock == expected
    if answer.deadlock:
        assert answer.trace is not None
        reached = replay(marked, answer.trace)
        assert reached is not None and is_dead(marked, reached)
        assert tuple(reached) not in finals


def test_the_reduced_space_is_smaller_than_the_full_one() -> None:
    net = _chains(3, 5, loop=False)
    answer = decide_deadlock(net, max_states=10_000)
    assert answer.states < explore(net).states
