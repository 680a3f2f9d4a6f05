"""The product's claim, tested hard: a verified mission behaves as verified, whatever the
network does.

Three levels, all under virtual time and all derandomized (the "ci" hypothesis profile):

* Engine-level schedules (`runtime.schedule`): hypothesis draws, per command, the reply
  (where the vehicle can give several), the delay each way, the vehicle's work time, the
  order among replies due together, and outages; the engine gets the replies in
  delivery-time order. Thousands of orderings per second.
* A stateful machine drives the Engine and the plain reference interpreter
  (``tests/runtime/reference.py``) side by side, reply by reply, in any order, with
  bogus and repeated replies and snapshot/restore thrown in; they must agree at every
  step.
* Network-level runs: the controller, its event log, the link emulator (hostile and
  Genoa-Lisbon profiles, seeds drawn by hypothesis) and the simulated ROMEO served on
  the wire protocol, as ``coral-run fuzz`` runs them.

The properties:

* refinement: every marking the engine passes through is a state of the verified
  reachability graph, and every firing is an edge of it;
* a mission verified free of deadlock reaches a declared final marking under every
  schedule (in every schedule here the vehicle eventually replies);
* a mission verified free of resource conflicts never has two commands in flight on one
  vehicle resource;
* nothing is lost: every command sent is logged and answered exactly once, every reply
  is consumed exactly once, and the vehicle carries out each command once however often
  a reconnect re-sends it.

Missions: the pool mission (verified), the racy mission (deadlock violated: see
``test_racy.py``), and two of ``examples/faulty`` (one with a resource conflict, one
with a deadlock), so that each property is also tried where it does not hold.
"""

from __future__ import annotations

import dataclasses
import json
from collections import Counter
from collections.abc import Sequence
from pathlib import Path
from typing import ClassVar

import pytest
from hypothesis import HealthCheck, find, given, settings, target
from hypothesis import strategies as st
from hypothesis.stateful import (
    RuleBasedStateMachine,
    initialize,
    invariant,
    precondition,
    rule,
)

from coral_lang.net import Transition, TransitionKind
from runtime.controller import RunEnd
from runtime.engine import Engine, Outcome, Policy, StepResult
from runtime.fuzz import FuzzOptions, FuzzRun, run_one
from runtime.link import BUILTIN_PROFILES
from runtime.schedule import Delivery, Schedule, ScheduleRun, Timing, run_schedule
from runtime.schedule_strategies import schedules
from tests.conftest import EXAMPLES
from tests.runtime.reference import Analysed, Pick, ReferenceNet, analysed

MISSIONS: dict[str, Path] = {
    "pool": EXAMPLES / "pool_mission" / "pool_mission.coral",
    "racy": EXAMPLES / "racy" / "racy_mission.coral",
    "conflict": EXAMPLES / "faulty" / "resource_conflict.coral",
    "deadlock": EXAMPLES / "faulty" / "deadlock.coral",
}

POLICIES = st.sampled_from(list(Policy))
ENGINE_SEEDS = st.integers(0, 2**32 - 1)


def mission(name: str) -> Analysed:
    """The named mission, compiled, verified and explored once per process."""
    return analysed(MISSIONS[name])


# What verification proves of each mission, written out so that collecting the tests
# does not verify anything; `test_the_mission_table_matches_verification` holds it true.
DEADLOCK_FREE = ["pool", "conflict"]
CONFLICT_FREE = ["pool", "racy", "deadlock"]


def test_the_mission_table_matches_verification() -> None:
    for name in MISSIONS:
        assert mission(name).proven("deadlock") is (name in DEADLOCK_FREE), name
        assert mission(name).proven("resource_conflicts") is (name in CONFLICT_FREE), name


class StepChecker:
    """Checks every step of a run against the verified reachability graph.

    Replays the engine's firings from the initial marking with the net's own firing
    rule: each must be an edge of the graph (from a reachable marking, enabled there, to
    a reachable marking), and the engine's marking after the step must be the replayed
    one. With ``conflicts``, no vehicle resource may be driven by two commands in flight.
    """

    def __init__(self, mission: Analysed, *, conflicts: bool = False) -> None:
        self.mission = mission
        self.conflicts = conflicts
        self.marking = mission.net.initial_marking()
        self.steps = 0
        self.most_busy = 0

    def __call__(self, engine: Engine, step: StepResult, delivery: Delivery | None) -> None:
        net = self.mission.net
        self.steps += 1
        for firing in step.firings:
            transition = net.transition(firing.transition)
            assert self.mission.is_edge(self.marking, transition), (
                f"step {self.steps}: firing {transition.name} in "
                f"{net.marking_dict(self.marking)} is not an edge of the verified graph"
            )
            self.marking = net.fire(self.marking, transition)
        assert tuple(engine.marking) == self.marking, f"step {self.steps}: markings differ"
        busy = Counter(r for c in engine.in_flight() for r in c.command.resources)
        self.most_busy = max(self.most_busy, *busy.values(), 0)
        if self.conflicts:
            assert self.most_busy <= 1, f"step {self.steps}: two commands drive {busy}"


def run(
    name: str,
    schedule: Schedule,
    *,
    policy: Policy = Policy.PRIORITY,
    seed: int = 0,
    checker: StepChecker | None = None,
) -> ScheduleRun:
    """Run the named mission's engine under ``schedule``."""
    m = mission(name)
    engine = Engine(m.net, m.approval, policy=policy, seed=seed)
    return run_schedule(engine, schedule, Timing(m.net), observe=checker)


# --------------------------------------------------------------------------- engine level


@pytest.mark.slow
@pytest.mark.parametrize("name", list(MISSIONS))
@settings(max_examples=150)
@given(schedule=schedules(), policy=POLICIES, seed=ENGINE_SEEDS)
def test_refinement_every_marking_and_firing_is_in_the_verified_graph(
    name: str, schedule: Schedule, policy: Policy, seed: int
) -> None:
    checker = StepChecker(mission(name))
    result = run(name, schedule, policy=policy, seed=seed, checker=checker)
    assert result.outcome is not Outcome.RUNNING
    assert tuple(mission(name).net.marking_from(result.marking)) == checker.marking


@pytest.mark.slow
@pytest.mark.parametrize("name", DEADLOCK_FREE)
@settings(max_examples=200)
@given(schedule=schedules(), policy=POLICIES, seed=ENGINE_SEEDS)
def test_a_mission_verified_deadlock_free_always_reaches_a_final_marking(
    name: str, schedule: Schedule, policy: Policy, seed: int
) -> None:
    result = run(name, schedule, policy=policy, seed=seed)
    assert result.outcome is Outcome.FINAL, (result.marking, result.trace)


@pytest.mark.slow
@pytest.mark.parametrize("name", CONFLICT_FREE)
@settings(max_examples=200)
@given(schedule=schedules(), policy=POLICIES, seed=ENGINE_SEEDS)
def test_a_mission_verified_conflict_free_never_drives_one_resource_twice(
    name: str, schedule: Schedule, policy: Policy, seed: int
) -> None:
    run(
        name, schedule, policy=policy, seed=seed, checker=StepChecker(mission(name), conflicts=True)
    )


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(set(MISSIONS) - set(CONFLICT_FREE)))
def test_where_analysis_reports_a_conflict_a_schedule_shows_it(name: str) -> None:
    """The conflict property has teeth: where analysis reports a conflict, hypothesis
    finds a schedule with two commands in flight on one resource."""

    def conflicts(schedule: Schedule) -> bool:
        checker = StepChecker(mission(name))
        run(name, schedule, checker=checker)
        return checker.most_busy > 1

    found = find(schedules(), conflicts, settings=settings(database=None, max_examples=500))
    assert conflicts(found)


@pytest.mark.slow
@pytest.mark.parametrize("name", list(MISSIONS))
@settings(max_examples=100)
@given(schedule=schedules(), policy=POLICIES, seed=ENGINE_SEEDS)
def test_nothing_lost_every_command_is_answered_and_every_reply_consumed_once(
    name: str, schedule: Schedule, policy: Policy, seed: int
) -> None:
    result = run(name, schedule, policy=policy, seed=seed)
    ids = [c.command_id for c in result.sent]
    assert ids == list(range(1, len(ids) + 1))  # ids unique, none skipped
    assert sorted(d.command_id for d in result.deliveries) == ids  # each answered once
    assert not result.unexpected  # ... and each answer consumed
    replies = [f for f in result.firings if mission(name).net.transition(f.transition).reply]
    assert [f.command_id for f in replies] == [d.command_id for d in result.deliveries]
    assert [f.transition for f in replies] == [
        f"{d.transition}.{d.kind}" for d in result.deliveries
    ]


def test_the_nominal_schedule_completes_the_pool_mission() -> None:
    result = run("pool", Schedule())
    assert result.outcome is Outcome.FINAL
    assert result.marking == {"mission_complete": 1}


def test_an_outage_holds_replies_and_delivers_them_in_the_order_due() -> None:
    from runtime.schedule import MessageFate, Outage

    # INIT answers at 500 ms; the link is down from 100 ms to 30 s.
    result = run("pool", Schedule((MessageFate(),), (Outage(100, 29_900),)))
    assert result.deliveries[0].time_ms == 30_000
    # The next two commands were sent together at 30 s and answer in order.
    assert [d.time_ms for d in result.deliveries[1:3]] == [30_500, 30_500]
    assert [d.command_id for d in result.deliveries[1:3]] == [2, 3]


# --------------------------------------------------------------------------- step by step


class EngineAgainstReference(RuleBasedStateMachine):
    """The Engine and the reference interpreter, fed the same replies in any order.

    Subclasses set ``name`` (a key of `MISSIONS`) and ``policy``. Under
    `Policy.PRIORITY` the two must fire the very same transitions; under
    `Policy.RANDOM` every engine choice must be one the reference allows (an enabled
    transition of the top priority) and the engine must stop exactly when the reference
    has nothing left to fire.
    """

    name: ClassVar[str]
    policy: ClassVar[Policy]

    def __init__(self) -> None:
        super().__init__()
        self.mission = mission(self.name)
        self.engine = Engine(self.mission.net, self.mission.approval, policy=self.policy)
        self.reference = ReferenceNet(self.mission.net)
        self.now = 0.0
        self.seed = 0

    def _follow(self, step: StepResult) -> Pick:
        """A chooser that makes the reference take the engine's choices, checking each."""
        net = self.mission.net
        choices = iter(
            net.transition(f.transition)
            for f in step.firings
            if net.transition(f.transition).kind is not TransitionKind.REPLY
        )

        def pick(candidates: Sequence[Transition]) -> Transition:
            chosen = next(choices, None)
            assert chosen is not None, "the engine stopped while the reference can go on"
            names = [c.name for c in candidates]
            if self.policy is Policy.PRIORITY:
                assert chosen == candidates[0], (chosen.name, names)
            assert chosen in candidates, (chosen.name, names)
            return chosen

        return pick

    def _compare(self, step: StepResult, expected: list[tuple[str, int | None]] | None) -> None:
        """The engine's step is the reference's: same firings, same commands, same outcome."""
        net = self.mission.net
        assert expected is not None
        assert [(f.transition, f.command_id) for f in step.firings] == expected
        assert [c.command_id for c in step.commands] == [
            i for name, i in expected if net.transition(name).kind is TransitionKind.COMMAND
        ]
        assert step.outcome is self.reference.outcome()

    @initialize(seed=ENGINE_SEEDS)
    def start(self, seed: int) -> None:
        self.seed = seed
        self.engine = Engine(self.mission.net, self.mission.approval, policy=self.policy, seed=seed)
        step = self.engine.start(self.now)
        self._compare(step, self.reference.start(self._follow(step)))

    @precondition(lambda self: bool(self.reference.in_flight))
    @rule(data=st.data(), wait=st.floats(0.0, 30.0))
    def reply(self, data: st.DataObject, wait: float) -> None:
        """The vehicle answers any command in flight, with any of its reply kinds."""
        command_id = data.draw(st.sampled_from(sorted(self.reference.in_flight)))
        command = self.reference.in_flight[command_id].command
        assert command is not None
        kind = data.draw(st.sampled_from(command.replies))
        self.now += wait
        step = self.engine.on_reply(command_id, kind, self.now)
        assert step.unexpected is None
        self._compare(step, self.reference.on_reply(command_id, kind, self._follow(step)))

    @rule(data=st.data())
    def bogus_reply(self, data: st.DataObject) -> None:
        """A reply the net cannot take: an id never sent or already answered, or a kind the
        command does not have. Both sides ignore it and nothing changes."""
        never_sent = self.reference.next_id + data.draw(st.integers(0, 3))
        command_id = data.draw(st.sampled_from([*sorted(self.reference.answered), never_sent]))
        kind = data.draw(st.sampled_from(["ack", "done", "error", "timeout", "bogus"]))
        before = self.engine.marking_dict()
        step = self.engine.on_reply(command_id, kind, self.now)
        assert step.unexpected is not None and not step.firings and not step.commands
        assert self.reference.on_reply(command_id, kind) is None
        assert self.engine.marking_dict() == before

    @precondition(lambda self: bool(self.reference.in_flight))
    @rule(data=st.data())
    def wrong_kind(self, data: st.DataObject) -> None:
        """A reply kind the command in flight has no transition for changes nothing."""
        command_id = data.draw(st.sampled_from(sorted(self.reference.in_flight)))
        command = self.reference.in_flight[command_id].command
        assert command is not None
        kind = "not-" + "-".join(command.replies)
        step = self.engine.on_reply(command_id, kind, self.now)
        assert step.unexpected is not None
        assert self.reference.on_reply(command_id, kind) is None
        assert command_id in {c.command_id for c in self.engine.in_flight()}

    @rule()
    def crash_and_restore(self) -> None:
        """The controller dies and resumes from its last snapshot (through JSON)."""
        state = json.loads(json.dumps(self.engine.snapshot()))
        self.engine = Engine.restore(
            self.mission.net, self.mission.approval, state, policy=self.policy, seed=self.seed
        )

    @invariant()
    def same_state(self) -> None:
        assert self.engine.marking_dict() == self.reference.marking
        assert {c.command_id: c.transition for c in self.engine.in_flight()} == {
            i: t.name for i, t in self.reference.in_flight.items()
        }
        assert self.engine.next_command_id == self.reference.next_id
        assert self.engine.outcome() is self.reference.outcome()

    @invariant()
    def in_the_verified_graph(self) -> None:
        marking = self.mission.net.marking_from(self.reference.marking)
        assert marking in self.mission.reachable

    @invariant()
    def no_conflict_where_verified(self) -> None:
        if self.mission.proven("resource_conflicts"):
            busy = self.reference.busy_resources()
            assert len(busy) == len(set(busy)), busy


MACHINE_SETTINGS = settings(
    max_examples=60,
    stateful_step_count=40,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)


def _machine(name: str, policy: Policy) -> type[EngineAgainstReference]:
    return type(
        f"EngineAgainstReference_{name}_{policy.value}",
        (EngineAgainstReference,),
        {"name": name, "policy": policy},
    )


# The pool mission's machines take seconds each: `make test` runs them, `make check`
# (the inner loop) keeps the two small nets, which exercise the same comparison.
TestPoolPriority = _machine("pool", Policy.PRIORITY).TestCase
TestPoolPriority.settings = MACHINE_SETTINGS
TestPoolPriority.pytestmark = [pytest.mark.slow]  # type: ignore[attr-defined]
TestPoolRandom = _machine("pool", Policy.RANDOM).TestCase
TestPoolRandom.settings = MACHINE_SETTINGS
TestPoolRandom.pytestmark = [pytest.mark.slow]  # type: ignore[attr-defined]
TestRacyPriority = _machine("racy", Policy.PRIORITY).TestCase
TestRacyPriority.settings = MACHINE_SETTINGS
TestConflictRandom = _machine("conflict", Policy.RANDOM).TestCase
TestConflictRandom.settings = MACHINE_SETTINGS


# --------------------------------------------------------------------------- network level


def check_run(name: str, run: FuzzRun) -> None:
    """Nothing lost and refinement, from a network-level run's controller log."""
    m = mission(name)
    assert run.end in (RunEnd.FINAL, RunEnd.DEADLOCK), run.end
    sent = [e.data["command_id"] for e in run.events if e.kind == "command-sent"]
    replies = [e.data for e in run.events if e.kind == "reply"]
    # Every command sent is logged once, with consecutive ids, and counted once as sent
    # (re-sends apart: see the regression test below).
    assert sent == list(range(1, len(sent) + 1))
    assert run.commands_sent == len(sent)
    # Every command is answered (acknowledged or reported failed) exactly once ...
    assert sorted(int(str(r["command_id"])) for r in replies) == sent
    # ... every reply is consumed exactly once, in the vehicle's order, none skipped ...
    assert [r["reply_seq"] for r in replies] == list(range(1, len(replies) + 1))
    assert run.unexpected_replies == 0 and run.replies == len(replies)
    # ... and the vehicle carried out each command once, however often it was re-sent.
    assert run.vehicle_commands == len(sent)
    # Refinement, from the log.
    marking = m.net.initial_marking()
    for event in run.events:
        if event.kind == "fire":
            transition = m.net.transition(str(event.data["transition"]))
            assert m.is_edge(marking, transition), transition.name
            marking = m.net.fire(marking, transition)
    assert m.net.marking_dict(marking) == run.marking


NETWORK_SETTINGS = settings(
    max_examples=6, suppress_health_check=[HealthCheck.too_slow], deadline=None
)


@pytest.mark.slow
@NETWORK_SETTINGS
@given(
    name=st.sampled_from(["pool", "racy"]),
    profile=st.sampled_from(["hostile", "genoa-lisbon"]),
    seed=st.integers(0, 2**63 - 1),
)
def test_nothing_lost_over_emulated_links_with_resets_and_outages(
    name: str, profile: str, seed: int
) -> None:
    m = mission(name)
    options = FuzzOptions(runs=1, seed=seed, link=BUILTIN_PROFILES[profile])
    result = run_one(m.net, m.approval, seed, options, keep_events=True)
    target(float(result.connections), label="connections")  # seek resets and outages
    check_run(name, result)
    if m.proven("deadlock"):
        assert result.end is RunEnd.FINAL, result.marking


@pytest.mark.slow
@settings(NETWORK_SETTINGS, max_examples=12)
@given(seed=st.integers(0, 2**63 - 1), vary=st.booleans())
def test_the_pool_mission_over_the_hostile_link_loses_nothing_and_always_ends(
    seed: int, vary: bool
) -> None:
    m = mission("pool")
    options = FuzzOptions(
        runs=1, seed=seed, link=BUILTIN_PROFILES["hostile"], policy=Policy.PRIORITY
    )
    if vary:
        options = dataclasses.replace(options, policy=Policy.RANDOM)
    result = run_one(m.net, m.approval, seed, options, keep_events=True)
    target(float(result.connections), label="connections")
    check_run("pool", result)
    assert result.end is RunEnd.FINAL


def test_the_controller_counts_every_command_sent_once() -> None:
    """Regression: a first connection lost in the handshake made the first real send of
    the commands in flight count as a re-send."""
    m = mission("pool")
    options = FuzzOptions(
        runs=1, seed=306, link=BUILTIN_PROFILES["hostile"], policy=Policy.PRIORITY
    )
    result = run_one(m.net, m.approval, 306, options, keep_events=True)
    first = next(e for e in result.events if e.kind in ("connection-lost", "handshake"))
    assert first.kind == "connection-lost"  # this seed loses its first connection early
    assert result.commands_sent == sum(e.kind == "command-sent" for e in result.events)
