"""The two timed explorers agree, and their witnesses are runs showing what they claim.

``method="clock"`` (one global clock, every interleaving) is the reference;
``method="events"`` (event times, stubborn sets, zone merging) is the fast one.
They share the model's definition (`analysis.timed.model`) but nothing of the search,
so on every drawn mission (`tests.analysis.timed.missions`) they must find the same
bounds, verdicts and margins. Witnesses are checked independently of both
(`tests.analysis.timed.missions.check_witnesses`).

`test_stuck_markings_agree` pins a disagreement found by this file and since fixed:
``events`` used to explore an order of events no real run has (a reply placed after one
that, by its deadline, had to come later) and report it as a run stuck with a command
pending, which then missed a deadline.
"""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, given, settings

from analysis.report import Verdict
from analysis.timed import TimedOptions, TimedReport, analyse_timed, explore
from coral_lang.compiler import compile_source
from coral_lang.profile import parse_profile
from coral_lang.timing import LinkBounds
from tests.analysis.timed.missions import (
    TimedMission,
    check_witnesses,
    stuck_set,
    summary,
    timed_missions,
)

BUDGET = 20_000
"""Symbolic states: the strategy keeps missions far below it (about 600 at most)."""


def analyse(mission: TimedMission, method: str) -> TimedReport:
    options = TimedOptions(mission.link, max_states=BUDGET, time_limit_s=None, method=method)
    return analyse_timed(mission.net, [mission.profile], options)


def assert_agree(mission: TimedMission, events: TimedReport, clock: TimedReport) -> None:
    e, c = summary(events), summary(clock)
    context = mission.describe()
    assert e["complete"] == c["complete"], context
    assert e["finals"] == c["finals"], context
    assert e["queries"] == c["queries"], context
    assert stuck_set(clock) == stuck_set(events), context
    assert e["deadlines"] == c["deadlines"], context


@settings(
    max_examples=60,
    derandomize=True,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)
@given(timed_missions())
def test_methods_agree_and_witnesses_are_runs(mission: TimedMission) -> None:
    events = analyse(mission, "events")
    clock = analyse(mission, "clock")
    assert clock.complete, mission.describe()  # the strategy stays within the budget
    assert_agree(mission, events, clock)
    check_witnesses(mission.net, mission.profile, clock)
    check_witnesses(mission.net, mission.profile, events)


@settings(
    max_examples=12,
    derandomize=True,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)
@given(timed_missions())
def test_merging_changes_nothing(mission: TimedMission) -> None:
    merged = analyse(mission, "events")
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(explore, "MERGE", False)
        unmerged = analyse(mission, "events")
    assert summary(merged) == summary(unmerged), mission.describe()
    assert stuck_set(merged) == stuck_set(unmerged), mission.describe()
    check_witnesses(mission.net, mission.profile, unmerged)


# The minimal reproducer of the stuck-marking disagreement: two tasks in parallel, their
# outcomes joined in every combination. Nothing can be stuck with a command pending
# (every command replies within its bounds), and clock finds nothing stuck.
PROFILE = """\
vehicle: BOT
resources: [r0, r1]
commands:
  T0: {kind: task, replies: [ack, error], resources: [r0], work_s: {ack: [2.0, 2.0], error: [0.5, 0.5]}}
  T1: {kind: task, replies: [ack, error], resources: [r1], work_s: {ack: [1.0, 1.0], error: [0.5, 0.5]}}
"""

MISSION = """\
mission m
vehicle BOT
place start = 1
place a, b, a_ok, a_bad, b_ok, b_bad, done, failed, over
final { done, over }
final { failed, over }
assert within 10 s { over }
transition fork
    wait   { start }
    signal { a, b }
transition ta
    wait   { a }
    action { BOT(T0) -> { ack: a_ok, error: a_bad } }
transition tb
    wait   { b }
    action { BOT(T1) -> { ack: b_ok, error: b_bad } }
transition j0
    wait   { a_ok, b_ok }
    signal { done, over }
transition j1
    wait   { a_bad, b_ok }
    signal { failed, over }
transition j2
    wait   { a_ok, b_bad }
    signal { failed, over }
transition j3
    wait   { a_bad, b_bad }
    signal { failed, over }
"""


def reproducer() -> TimedMission:
    profile = parse_profile(PROFILE, "bot.yaml")
    net = compile_source(MISSION, "m.coral", [profile]).net
    assert net is not None
    return TimedMission(MISSION, PROFILE, profile, net, LinkBounds("l", 0.0, 0.1))


def test_reproducer_bounds() -> None:
    # done needs both acks; T0's is the later: best 0 + 2.0 + 0 + 0 = 2.0 s, worst
    # 0.1 (up) + 2.0 (work) + 0.1 (latency: the default) + 0.1 (down) = 2.3 s. failed:
    # earliest an error with no delays (0.5 s), latest the same T0 ack at 2.3 s joined
    # with T1's error (at most 0.8 s). Every run marks `over` by 2.3 s.
    mission = reproducer()
    for method in ("clock", "events"):
        report = analyse(mission, method)
        assert [(f.final, f.best_s, f.worst_s) for f in report.finals] == [
            ({"done": 1, "over": 1}, 2.0, 2.3),
            ({"failed": 1, "over": 1}, 0.5, 2.3),
        ]
        check_witnesses(mission.net, mission.profile, report)
        assert [(d.verdict, d.latest_s) for d in report.deadlines] == [(Verdict.PROVEN, 2.3)]


def test_stuck_markings_agree() -> None:
    # events used to report stuck { b_ok, ta.pending } and { a_ok, tb.pending }, and the
    # deadline violated by a "run" in which ta's error arrived at 0.6 s, never consumed.
    mission = reproducer()
    events, clock = analyse(mission, "events"), analyse(mission, "clock")
    assert stuck_set(events) == stuck_set(clock) == set()
    assert summary(events) == summary(clock)
