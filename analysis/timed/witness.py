"""Concrete runs from symbolic ones: every delay and work time of a witness.

The explorer keeps, for each symbolic state, the label of the step that made it. To
show a run, the steps are replayed with a `ConstraintLog` instead of a zone: every
moment (each time ``now`` moves, each timer start) is a variable of its own, and every
constraint the semantics adds is kept as an edge ``x_i - x_j <= c``. The constraints
of one run are a system of difference constraints, so shortest paths solve it
(Bellman-Ford, queue-based): ``x_v = d(start -> v)`` gives every moment its latest
possible value at once (so the run ends as late as it can: the worst case), and
``x_v = -d(v -> start)`` its earliest (the best case).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass

from analysis.timed.eventtime import EventSemantics, EventState
from analysis.timed.eventtime import Successor as EventSuccessor
from analysis.timed.model import TimedModel, seconds
from analysis.timed.schedule import ScheduledCommand, ScheduledFiring, TimedSchedule
from analysis.timed.semantics import Record, Semantics, State, Successor
from analysis.timed.zones import INF, NOW, START
from coral_lang.net import Net

__all__ = ["ConstraintLog", "WitnessError", "replay", "schedule_of"]

AnyState = State | EventState


class WitnessError(Exception):
    """A symbolic run could not be replayed (a bug: the explorer found it)."""


class ConstraintLog:
    """A zone stand-in that records constraints instead of solving them.

    Index `START` and `NOW` keep their meaning; ``now`` gets a fresh underlying moment
    each time it elapses. Immutable and persistent (each log points at the one it grew
    from), so the branches of a replay never see each other's constraints.
    """

    __slots__ = ("_edge", "_moments", "_names", "_parent")

    def __init__(
        self,
        parent: ConstraintLog | None,
        edge: tuple[int, int, int] | None,
        names: tuple[int, ...],
        moments: int,
    ) -> None:
        self._parent = parent
        self._edge = edge
        self._names = names  # index -> underlying moment
        self._moments = moments

    @classmethod
    def initial(cls) -> ConstraintLog:
        """START and NOW, equal."""
        first = cls(None, (0, 1, 0), (0, 1), 2)
        return cls(first, (1, 0, 0), (0, 1), 2)

    @property
    def edges(self) -> list[tuple[int, int, int]]:
        """Every constraint ``(i, j, c)``: moment i - moment j <= c."""
        out = []
        log: ConstraintLog | None = self
        while log is not None:
            if log._edge is not None:
                out.append(log._edge)
            log = log._parent
        return out

    @property
    def moments(self) -> int:
        """How many underlying moments."""
        return self._moments

    def moment(self, index: int) -> int:
        """The underlying moment of variable ``index``."""
        return self._names[index]

    def constrain(self, i: int, j: int, c: int) -> ConstraintLog:
        return ConstraintLog(self, (self._names[i], self._names[j], c), self._names, self._moments)

    def elapse(self) -> ConstraintLog:
        fresh = self._moments
        names = list(self._names)
        edge = (names[NOW], fresh, 0)  # the new now is not earlier than the old
        names[NOW] = fresh
        return ConstraintLog(self, edge, tuple(names), fresh + 1)

    def stamp_now(self) -> tuple[ConstraintLog, int]:
        names = (*self._names, self._names[NOW])
        return ConstraintLog(self, None, names, self._moments), len(names) - 1

    def fresh(self) -> tuple[ConstraintLog, int]:
        moment = self._moments
        names = (*self._names, moment)
        log = ConstraintLog(self, (0, moment, 0), names, moment + 1)  # START <= it
        return log, len(names) - 1

    def bound(self, i: int, j: int) -> int:
        del i, j  # figures are read from the explorer's zones, not from a replay
        return INF


def replay(
    model: TimedModel, labels: Sequence[str], *, events: bool
) -> tuple[AnyState, list[Record], ConstraintLog]:
    """Replay the steps named by ``labels`` (the first names an initial state); with
    the explorer gives whole runs (to an end state) when it wants them.

    Raises:
        WitnessError: a label names no step (the explorer and the replay disagree).
    """
    log = ConstraintLog.initial()
    sem: Semantics | EventSemantics = (
        EventSemantics(model, initial_zone=log) if events else Semantics(model, initial_zone=log)
    )
    options: Sequence[Successor | EventSuccessor] = sem.initial()
    records: list[Record] = []
    state: AnyState | None = None
    for label in labels:
        chosen = next((s for s in options if s.label == label), None)
        if chosen is None:
            raise WitnessError(f"no step {label!r} to replay")
        state = chosen.state
        records.extend(chosen.records)
        options = sem.successors(state)  # type: ignore[arg-type]
    if state is None:
        raise WitnessError("an empty run")
    assert isinstance(state.zone, ConstraintLog)
    return state, records, state.zone


def _shortest(
    moments: int, edges: list[tuple[int, int, int]], source: int, reverse: bool
) -> list[int]:
    """Shortest distances from ``source`` over the constraint graph (edge j -> i of
    weight c for ``x_i - x_j <= c``; reversed when ``reverse``)."""
    adjacency: list[list[tuple[int, int]]] = [[] for _ in range(moments)]
    for i, j, c in edges:
        if reverse:
            adjacency[i].append((j, c))
        else:
            adjacency[j].append((i, c))
    dist = [INF] * moments
    dist[source] = 0
    queue = deque([source])
    queued = [False] * moments
    queued[source] = True
    relaxations = 0
    limit = moments * max(len(edges), 1) + 1
    while queue:
        u = queue.popleft()
        queued[u] = False
        du = dist[u]
        for v, c in adjacency[u]:
            if du + c < dist[v]:
                dist[v] = du + c
                relaxations += 1
                if relaxations > limit:
                    raise WitnessError("inconsistent timing constraints (negative cycle)")
                if not queued[v]:
                    queued[v] = True
                    queue.append(v)
    return dist


def _solve(log: ConstraintLog, latest: bool) -> list[int]:
    """Moment values (us): each as late as possible, or each as early as possible."""
    if latest:
        values = _shortest(log.moments, log.edges, START, reverse=False)
        return values
    back = _shortest(log.moments, log.edges, START, reverse=True)
    return [-d if d < INF else 0 for d in back]


def schedule_of(
    model: TimedModel,
    labels: Sequence[str],
    *,
    kind: str,
    reason: str,
    latest: bool,
    events: bool,
) -> TimedSchedule:
    """The run named by ``labels`` with concrete times: each moment as late as
    possible (``latest``: the worst case) or as early as possible.

    Raises:
        WitnessError: the run cannot be replayed (a bug).
    """
    state, records, log = replay(model, labels, events=events)
    values = _solve(log, latest)
    if any(v >= INF for v in values):  # pragma: no cover - every moment follows START
        raise WitnessError("a moment of the run has no bound")
    marking = (
        EventSemantics(model).marking_of(state) if isinstance(state, EventState) else state.marking
    )
    return _build(model, model.net, state.over, marking, records, log, values, kind, reason)


@dataclass
class _Command:
    """One command of a replayed run, filled in as its records come."""

    ref: int
    occurrence: int
    sent: int
    arrived: int | None = None
    due: int | None = None
    reply: str = ""
    back: int | None = None


def _build(
    model: TimedModel,
    net: Net,
    over: bool,
    marking: tuple[int, ...],
    records: list[Record],
    log: ConstraintLog,
    values: list[int],
    kind: str,
    reason: str,
) -> TimedSchedule:
    def at(var: int) -> int:
        return values[log.moment(var)]

    owner = {
        reply: command.transition
        for command in model.commands.values()
        for _, reply in command.replies
    }
    commands: dict[tuple[int, int], _Command] = {}
    occurrences: dict[int, int] = {}
    firings: list[ScheduledFiring] = []
    for record in records:
        key = (record.ref, record.origin)
        if record.what == "send":
            occurrences[record.ref] = occurrences.get(record.ref, 0) + 1
            commands[key] = _Command(record.ref, occurrences[record.ref], at(record.origin))
        elif record.what == "arrive":
            commands[key].arrived = at(record.var)
        elif record.what == "due":
            commands[key].due = at(record.var)
            commands[key].reply = record.kind
        elif record.what == "fire":
            firings.append(
                ScheduledFiring(seconds(at(record.var)), net.transitions[record.ref].name)
            )
            command_of = owner.get(record.ref)
            if command_of is not None and (command_of, record.origin) in commands:
                commands[(command_of, record.origin)].back = at(record.var)
    scheduled = []
    link_high = model.link.max_delay_s
    for entry in commands.values():
        command = model.commands[entry.ref]
        arrived = entry.sent if entry.arrived is None else entry.arrived
        due = arrived if entry.due is None else entry.due
        back = due if entry.back is None else entry.back
        total = seconds(back - due)
        latency = max(0.0, total - link_high)
        scheduled.append(
            ScheduledCommand(
                transition=command.name,
                occurrence=entry.occurrence,
                command=command.command,
                sent_at=seconds(entry.sent),
                up_delay_s=seconds(arrived - entry.sent),
                reply=entry.reply,
                work_s=seconds(due - arrived),
                latency_s=latency,
                down_delay_s=total - latency,
            )
        )
    # Records come in exploration order, which with event times is not time order.
    scheduled.sort(key=lambda c: c.sent_at)
    firings.sort(key=lambda f: f.time)
    final = {p: n for p, n in net.marking_dict(marking).items() if n}
    end = max((at(r.var) for r in records if r.var >= 0), default=0)
    return TimedSchedule(
        mission=net.name,
        net_digest=net.digest(),
        kind=kind,
        reason=reason,
        link=model.link,
        duration_s=seconds(end),
        final=final if over else None,
        commands=tuple(scheduled),
        firings=tuple(firings),
    )
