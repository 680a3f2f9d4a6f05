"""A hypothesis strategy drawing small timed missions with their own vehicle profile.

Timed analysis has two independent explorers (``method="clock"``, the reference, and
``method="events"``) and a simulated vehicle that must stay within what they prove;
comparing them needs missions that exercise every rule of the timed model
(``docs/analysis-methods.md``) without exploding the state space. Each drawn mission:

* forks into 1-3 branches from ``start``; each branch is a chain of 1-2 steps, a step
  being a task (``ack``/``error``), an action (``done``/``error``), a task followed by a
  query watching its resource (sent after the ack), or a task and its query sent in
  parallel (the query may then arrive before the task and watch nothing); at most
  ``max_commands`` commands in all (default 3: four already make the clock explorer
  take seconds on some draws);
* branches pick their resources from two, so they sometimes share one (displacement:
  a task replaced by another branch's task, a query timing out at once);
* sometimes a ``skip`` transition competes with a branch's first command for its token
  (a conflict);
* joins every combination of branch outcomes into ``done`` (all succeeded) or
  ``failed``, both with ``over``; sometimes one combination has no join (a dead end
  that is not final) and sometimes ``failed`` is not declared final;
* sometimes asserts ``within T s { over }`` (``over`` is marked with either outcome).

Work times and time-outs come from small ranges of whole and half seconds so that
time-outs are sometimes adequate and sometimes not; the link bounds are drawn too.
Every mission is 1-safe by construction (each place holds at most one token), and the
strategy compiles it and rejects (``assume``) any that does not compile.

The checks at the end (`check_witnesses`, `summary`) are shared by the timed tests: a
witness schedule claims a run of the timed model with concrete times, and they do not
trust the explorer that made it: they replay its firings through the net (each must be
enabled) and hold every command's delays to the link bounds and the profile's reply
latency, so a witness that is not a run of the model fails whatever both explorers think.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from hypothesis import assume
from hypothesis import strategies as st

from analysis.timed import TimedReport, TimedSchedule
from coral_lang.compiler import compile_source
from coral_lang.net import Net, PlaceKind
from coral_lang.profile import VehicleProfile, parse_profile
from coral_lang.timing import LinkBounds

__all__ = [
    "EPS",
    "TimedMission",
    "check_schedule",
    "check_witnesses",
    "marking_over_time",
    "stuck_set",
    "summary",
    "timed_missions",
]

EPS = 1e-6
"""Seconds: the explorers work in whole microseconds, schedules print floats."""

VEHICLE = "BOT"
RESOURCES = ("r0", "r1")

# Step kinds: a task alone, an action alone, a task then its query after the ack, a
# task and its query sent together.
TASK, ACTION, AFTER, PARALLEL = "task", "action", "after", "parallel"


@dataclass(frozen=True)
class TimedMission:
    """One drawn mission: its text, its profile, the compiled net and the link bounds."""

    source: str
    profile_text: str
    profile: VehicleProfile
    net: Net
    link: LinkBounds

    def describe(self) -> str:
        """Everything needed to reproduce it, for a failing example's report."""
        return (
            f"link {self.link}\n--- profile ---\n{self.profile_text}--- mission ---\n{self.source}"
        )


_halves = st.integers(min_value=0, max_value=12).map(lambda n: n / 2)


@st.composite
def _interval(draw: st.DrawFn, low: int, high: int) -> tuple[float, float]:
    """A work-time interval [a, b] in half seconds, ``low/2 <= a <= b <= high/2``."""
    a = draw(st.integers(min_value=low, max_value=high))
    b = draw(st.integers(min_value=a, max_value=high))
    return a / 2, b / 2


@st.composite
def _profile(draw: st.DrawFn) -> str:
    """A profile: per resource a task, a tracking query and an action; one free action."""
    latency = draw(st.sampled_from([0.0, 0.1, 0.5]))
    lines = [
        f"vehicle: {VEHICLE}",
        f"resources: [{', '.join(RESOURCES)}]",
        f"timing: {{tolerance: 0.2, reply_latency_s: {latency}}}",
        "commands:",
    ]
    for i, resource in enumerate(RESOURCES):
        ack = draw(_interval(0, 4))
        error = draw(_interval(0, 2))
        done = draw(_interval(1, 10))
        act = draw(_interval(0, 6))
        lines += [
            f"  T{i}:",
            "    kind: task",
            "    replies: [ack, error]",
            f"    resources: [{resource}]",
            f"    work_s: {{ack: [{ack[0]}, {ack[1]}], error: [{error[0]}, {error[1]}]}}",
            f"  Q{i}?:",
            "    kind: query",
            "    params: [{name: time_out, type: float, unit: s}]",
            "    replies: [done, timeout]",
            f"    resources: [{resource}]",
            f"    work_s: {{done: [{done[0]}, {done[1]}]}}",
            f"  A{i}:",
            "    kind: action",
            "    replies: [done, error]",
            f"    resources: [{resource}]",
            f"    work_s: {{done: [{act[0]}, {act[1]}]}}",
        ]
    free = draw(_interval(0, 4))
    lines += [
        "  NOTE:",
        "    kind: action",
        "    replies: [done, error]",
        f"    duration_s: {free[0] + free[1]}",
    ]
    return "\n".join(lines) + "\n"


@dataclass
class _Writer:
    """Collects the mission's places and transitions as they are drawn."""

    places: list[str]
    transitions: list[str]

    def place(self, name: str) -> str:
        self.places.append(name)
        return name

    def command(self, name: str, wait: list[str], call: str, replies: dict[str, str]) -> None:
        mapped = ", ".join(f"{kind}: {place}" for kind, place in replies.items())
        self.transitions.append(
            f"transition {name}\n    wait   {{ {', '.join(wait)} }}\n"
            f"    action {{ {VEHICLE}({call}) -> {{ {mapped} }} }}\n"
        )

    def plain(self, name: str, wait: list[str], signal: list[str]) -> None:
        self.transitions.append(
            f"transition {name}\n    wait   {{ {', '.join(wait)} }}\n"
            f"    signal {{ {', '.join(signal)} }}\n"
        )


def _step(
    draw: st.DrawFn, w: _Writer, prefix: str, here: str, fail: str, spare: int
) -> tuple[str, int]:
    """One step of a branch from place ``here``, sending at most ``spare`` commands;
    returns the place it succeeds into (``fail`` gets the token otherwise) and how many
    commands it sends."""
    kind = draw(st.sampled_from([TASK, ACTION, AFTER, PARALLEL] if spare > 1 else [TASK, ACTION]))
    r = draw(st.integers(min_value=0, max_value=len(RESOURCES) - 1))
    ok = w.place(f"{prefix}_ok")
    time_out = draw(_halves.map(lambda x: x + 1.0))
    if kind == TASK:
        w.command(prefix, [here], f"T{r}", {"ack": ok, "error": fail})
    elif kind == ACTION:
        name = draw(st.sampled_from([f"A{r}", "NOTE"]))
        w.command(prefix, [here], name, {"done": ok, "error": fail})
    elif kind == AFTER:
        acked = w.place(f"{prefix}_acked")
        w.command(prefix, [here], f"T{r}", {"ack": acked, "error": fail})
        w.command(
            f"{prefix}_q",
            [acked],
            f"Q{r}?, time_out = {time_out} s",
            {"done": ok, "timeout": fail},
        )
    else:
        to_task, to_query = w.place(f"{prefix}_t"), w.place(f"{prefix}_w")
        t_ok, t_bad = w.place(f"{prefix}_tok"), w.place(f"{prefix}_tbad")
        q_ok, q_bad = w.place(f"{prefix}_qok"), w.place(f"{prefix}_qbad")
        w.plain(f"{prefix}_go", [here], [to_task, to_query])
        w.command(prefix, [to_task], f"T{r}", {"ack": t_ok, "error": t_bad})
        w.command(
            f"{prefix}_q",
            [to_query],
            f"Q{r}?, time_out = {time_out} s",
            {"done": q_ok, "timeout": q_bad},
        )
        w.plain(f"{prefix}_join", [t_ok, q_ok], [ok])
        for a, b in ((t_bad, q_ok), (t_ok, q_bad), (t_bad, q_bad)):
            w.plain(f"{prefix}_j_{a}_{b}", [a, b], [fail])
    return ok, 1 if kind in (TASK, ACTION) else 2


@st.composite
def timed_missions(draw: st.DrawFn, max_branches: int = 3, max_commands: int = 3) -> TimedMission:
    """A small 1-safe mission over a drawn profile, and link bounds (module docstring)."""
    profile_text = draw(_profile())
    profile = parse_profile(profile_text, "generated.yaml")
    branches = draw(st.integers(min_value=1, max_value=max_branches))
    w = _Writer([], [])
    heads: list[str] = []
    ends: list[tuple[str, str]] = []
    budget = max(max_commands, branches)  # commands in all: keeps state spaces small
    for b in range(branches):
        head = w.place(f"b{b}")
        fail = w.place(f"b{b}_failed")
        heads.append(head)
        here = head
        for s in range(2):
            spare = budget - (branches - b - 1)  # leave one command for each later branch
            if spare < 1 or (s > 0 and draw(st.booleans())):
                break
            here, sent = _step(draw, w, f"b{b}s{s}", here, fail, spare)
            budget -= sent
        if draw(st.integers(min_value=0, max_value=4)) == 0:
            w.plain(f"b{b}_skip", [head], [here])  # competes with the first command
        ends.append((here, fail))
    w.plain("fork", ["start"], heads)
    done, failed, over = w.place("done"), w.place("failed"), w.place("over")
    missing = draw(st.integers(min_value=-4, max_value=(1 << branches) - 1))
    for combo in range(1 << branches):
        if combo == missing:
            continue  # no join for this combination: a dead end
        wait = [ends[b][(combo >> b) & 1] for b in range(branches)]
        w.plain(f"join{combo}", wait, [failed, over] if combo else [done, over])
    finals = ["final { done, over }"]
    if draw(st.integers(min_value=0, max_value=3)) > 0:
        finals.append("final { failed, over }")
    asserts: list[str] = []
    if draw(st.booleans()):
        deadline = draw(st.integers(min_value=1, max_value=30))
        asserts.append(f"assert within {deadline} s {{ over }}")
    source = "\n".join(
        [
            "mission generated",
            f"vehicle {VEHICLE}",
            "place start = 1",
            f"place {', '.join(w.places)}",
            *finals,
            *asserts,
            "",
            *w.transitions,
        ]
    )
    result = compile_source(source, "generated.coral", [profile])
    assume(result.net is not None)
    assert result.net is not None
    low = draw(st.sampled_from([0.0, 0.05, 0.5]))
    high = low + draw(st.sampled_from([0.0, 0.1, 1.0, 2.0]))
    link = LinkBounds("drawn", low, high)
    return TimedMission(source, profile_text, profile, result.net, link)


# -- checks shared by the timed tests ---------------------------------------------------


def summary(report: TimedReport) -> dict[str, Any]:
    """What two explorers of the same model must agree on (stuck markings apart)."""
    return {
        "complete": report.complete,
        "finals": [(sorted(f.final.items()), f.best_s, f.worst_s) for f in report.finals],
        "queries": [(q.transition, q.verdict, q.margin_s) for q in report.queries],
        "deadlines": [(d.index, d.verdict, d.latest_s) for d in report.deadlines],
        "unbounded": bool(report.unbounded),
    }


def stuck_set(report: TimedReport) -> set[tuple[tuple[str, int], ...]]:
    """The stuck markings, order-free."""
    return {tuple(sorted(m.items())) for m in report.stuck}


def marking_over_time(net: Net, schedule: TimedSchedule) -> list[tuple[float, dict[str, int]]]:
    """Replay the schedule's firings from the initial marking: the marking after each
    firing, with its time. Fails the test if a firing is not enabled or time goes back."""
    marking = {p.name: p.initial for p in net.places}
    after: list[tuple[float, dict[str, int]]] = [(0.0, dict(marking))]
    last = 0.0
    for firing in schedule.firings:
        assert firing.time >= last - EPS, f"time goes back at {firing}"
        last = firing.time
        transition = net.transition(firing.transition)
        for place, weight in transition.inputs:
            assert marking[place] >= weight, f"{firing.transition} not enabled at {firing.time}"
            marking[place] -= weight
        for place, weight in transition.outputs:
            marking[place] += weight
        after.append((firing.time, dict(marking)))
    return after


def _mission_marking(net: Net, marking: dict[str, int]) -> dict[str, int]:
    return {
        p.name: marking[p.name]
        for p in net.places
        if p.kind is PlaceKind.MISSION and marking[p.name] > 0
    }


def check_schedule(net: Net, profile: VehicleProfile, schedule: TimedSchedule) -> None:
    """The schedule is a run of the timed model: firings enabled in order, its end at
    ``duration_s``, its final marking the one it names, every delay within its bound."""
    link = schedule.link
    assert schedule.net_digest == net.digest()
    steps = marking_over_time(net, schedule)
    end, marking = steps[-1]
    assert abs(end - schedule.duration_s) < EPS, (end, schedule.duration_s)
    if schedule.final is not None:
        assert _mission_marking(net, marking) == schedule.final
    sends: dict[str, list[float]] = {}
    arrivals: dict[str, list[float]] = {}
    for firing in schedule.firings:
        transition = net.transition(firing.transition)
        if transition.command is not None:
            sends.setdefault(transition.name, []).append(firing.time)
        if transition.reply_to is not None:
            arrivals.setdefault(f"{transition.reply_to}.{transition.reply}", []).append(firing.time)
    latency = profile.timing.reply_latency_s
    for c in schedule.commands:
        where = (schedule.kind, schedule.duration_s, c)
        assert link.min_delay_s - EPS <= c.up_delay_s <= link.max_delay_s + EPS, where
        assert -EPS <= c.latency_s <= latency + EPS, where
        assert c.work_s >= -EPS, where
        assert abs(sends[c.transition][c.occurrence - 1] - c.sent_at) < EPS, where
        replies = arrivals.get(f"{c.transition}.{c.reply}", [])
        # A reply arrives when the engine consumes it (its reply transition fires).
        assert any(abs(t - c.arrived_at) < EPS for t in replies), (where, replies)
        assert link.min_delay_s - EPS <= c.down_delay_s <= link.max_delay_s + EPS, where


def check_witnesses(
    net: Net, profile: VehicleProfile, report: TimedReport, *, deadlines: bool = True
) -> None:
    """Every witness of ``report`` is a run (`check_schedule`) showing what it claims
    (deadline counterexamples only if ``deadlines``)."""
    for f in report.finals:
        for schedule, bound in ((f.best, f.best_s), (f.worst, f.worst_s)):
            check_schedule(net, profile, schedule)
            assert abs(schedule.duration_s - bound) < EPS, (schedule.kind, bound)
            assert schedule.final == f.final
        assert f.best_s <= f.worst_s + EPS
    for q in report.queries:
        if q.counterexample is not None:
            check_schedule(net, profile, q.counterexample)
            assert any(
                c.transition == q.transition and c.reply == "timeout"
                for c in q.counterexample.commands
            ), q.transition
    for d in report.deadlines:
        if d.counterexample is None or not deadlines:
            continue
        check_schedule(net, profile, d.counterexample)
        assert not _marked_by(
            marking_over_time(net, d.counterexample), d.places.items(), d.deadline_s
        ), f"the deadline counterexample marks {d.places} by {d.deadline_s} s"


def _marked_by(
    steps: list[tuple[float, dict[str, int]]],
    places: Iterable[tuple[str, int]],
    deadline: float,
) -> bool:
    wanted = list(places)
    return any(
        time <= deadline + EPS and all(marking[p] >= n for p, n in wanted)
        for time, marking in steps
    )
