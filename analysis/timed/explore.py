"""The timed explorer: every symbolic state, and what they add up to.

Breadth-first over `analysis.timed.semantics` states. A new state whose zone lies
inside the zone of a known state with the same marking, timers and holders adds no
run, so it is dropped (inclusion, as zone-based model checkers do); nothing is
over-approximated. A state is remembered with the step that made it, so a witness run
can be replayed (`analysis.timed.witness`).

A run that comes back to the marking, timers and holders of one of its earlier states
can go round again, so the mission has no worst time: the exploration stops and says
so (inconclusive; untimed analysis decides whether the mission can spin).
"""

from __future__ import annotations

import dataclasses
import functools
import heapq
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

from analysis.budget import Budget, memory_limit_reason
from analysis.report import Verdict
from analysis.timed.eventtime import EventSemantics, EventState, NotSafe
from analysis.timed.eventtime import Successor as EventSuccessor
from analysis.timed.model import US, CommandModel, ModelError, TimedModel, build_model, seconds
from analysis.timed.options import TimedOptions
from analysis.timed.results import DeadlineResult, FinalTiming, QueryAdequacy, TimedReport
from analysis.timed.schedule import TimedSchedule
from analysis.timed.semantics import EngineSpin, Semantics, State, Successor
from analysis.timed.witness import schedule_of
from analysis.timed.zones import NOW, START, Zone
from coral_lang.net import Net, PlaceKind, format_tokens
from coral_lang.profile import VehicleProfile

__all__ = ["analyse_timed"]

MERGE = True
"""Merge states whose zones' union is a zone (tests turn it off to compare)."""


def analyse_timed(
    net: Net, profiles: Sequence[VehicleProfile], options: TimedOptions
) -> TimedReport:
    """Timed analysis of ``net`` (package docstring); never raises for a net it
    cannot model: the report is then inconclusive with the reason."""
    started = time.perf_counter()
    try:
        model = build_model(net, profiles, options.link)
    except ModelError as exc:
        return TimedReport(
            complete=False,
            reason=str(exc),
            link=options.link,
            states=0,
            seconds=time.perf_counter() - started,
            queries=_unknown_queries(net, str(exc)),
            deadlines=(),
        )
    events = options.method == "events"
    if options.method == "auto":
        try:
            events = EventSemantics(model).groups() > 1
        except NotSafe:  # pragma: no cover - raised while exploring, not here
            events = False
    try:
        search = _Search(model, options, started, events=events)
        search.run()
        return search.report()
    except NotSafe:
        search = _Search(model, options, started, events=False)
        search.run()
        return search.report()


AnyState = State | EventState


@dataclass
class _Node:
    """A symbolic state, the step that made it, and the other steps whose zones were
    merged into it (each with its zone then, for reconstructing witnesses)."""

    state: AnyState
    parent: int
    label: str
    alternatives: list[tuple[int, str, Zone]] = field(default_factory=list)
    expanded: bool = False


@dataclass
class _Extreme:
    """Best and worst end time to one final marking, and where they were seen."""

    best: int
    best_node: int
    worst: int
    worst_node: int


@dataclass
class _Findings:
    finals: dict[int, _Extreme] = field(default_factory=dict)
    timeouts: dict[int, int] = field(default_factory=dict)  # command -> node
    waited: dict[int, int] = field(default_factory=dict)  # command -> latest done wait
    sent: set[int] = field(default_factory=set)
    missed: dict[int, int] = field(default_factory=dict)  # deadline -> node
    reached: dict[int, int] = field(default_factory=dict)  # deadline -> latest time
    stuck: dict[tuple[int, ...], int] = field(default_factory=dict)  # marking -> node


class _Search:
    def __init__(
        self, model: TimedModel, options: TimedOptions, started: float, *, events: bool
    ) -> None:
        self.model = model
        self.options = options
        self.started = started
        self.events = events
        self.sem: Semantics | EventSemantics = EventSemantics(model) if events else Semantics(model)
        self.nodes: list[_Node] = []
        self.zones: dict[tuple[object, ...], list[int]] = {}
        self.found = _Findings()
        self.reason = ""
        self.complete = False
        self.cycle = ""
        self.finals = list(model.net.finals)
        self._final_columns = [
            i
            for i, p in enumerate(model.net.places)
            if p.kind not in (PlaceKind.COMPLEMENT, PlaceKind.ARMED)
        ]
        self._final_values = [
            tuple(dict(f.tokens).get(model.net.places[i].name, 0) for i in self._final_columns)
            for f in self.finals
        ]

    # ------------------------------------------------------------------ search

    def _push(self, queue: list[tuple[int, int]], index: int) -> None:
        """Queue a state. With event times, states whose earliest-written running
        command comes first go first: the explorer then sees every way one group of
        timers can end before going on from any of them, so those ways merge."""
        state = self.nodes[index].state
        order = min((act.ref for act in state.acts), default=-1) if self.events else 0
        heapq.heappush(queue, (order, index))

    def run(self) -> None:
        queue: list[tuple[int, int]] = []
        try:
            for successor in self.sem.initial():
                node = self._add(successor, -1)
                if node is not None:
                    self._push(queue, node)
            # The command's budget: its time limit (from when the analysis started) and
            # memory limit; the reason is analysis.budget's, as every other stage's.
            limit = self.options.time_limit_s
            budget = Budget(
                None if limit is None else max(0.0, limit - (time.perf_counter() - self.started)),
                memory=self.options.memory_limit,
            )
            budget.limit = limit
            while queue:
                if len(self.nodes) > self.options.max_states:
                    self.reason = (
                        f"stopped after {self.options.max_states:,} symbolic states (the "
                        "budget; raise it with --timed-states)"
                    )
                    return
                if budget.expired():
                    what = "--memory-limit" if budget.memory_spent else "--time-limit"
                    self.reason = (
                        f"{budget.time_reason(len(self.nodes), 'symbolic state')} "
                        f"(raise it with {what})"
                    )
                    return
                _, index = heapq.heappop(queue)
                self.nodes[index].expanded = True
                state = self.nodes[index].state
                if state.over:
                    self._ended(index, state)
                    continue
                successors: Sequence[Successor | EventSuccessor] = self.sem.successors(
                    state  # type: ignore[arg-type]
                )
                if not successors:
                    # Timers still run, yet none can fire: with one clock that cannot
                    # happen; with event times it is an order of events no real run has
                    # (a later event was placed before one that had to come first).
                    # Either way no run ends here.
                    continue
                for successor in successors:
                    node = self._add(successor, index)
                    if node is not None:
                        self._push(queue, node)
                    if self.cycle:
                        self.reason = self.cycle
                        return
        except EngineSpin as exc:
            self.reason = str(exc)
            return
        except MemoryError:
            self.zones = {}  # the merge index: not needed for the report
            self.reason = memory_limit_reason(self.options.memory_limit)
            return
        self.complete = True

    def _add(self, successor: Successor | EventSuccessor, parent: int) -> int | None:
        """Remember ``successor`` unless a known state covers it; note what it did."""
        state = successor.state
        interesting = False
        for record in successor.records:
            if record.what == "send":
                self.found.sent.add(record.ref)
            elif record.what == "timeout" and record.ref not in self.found.timeouts:
                interesting = True
            elif record.what == "done":
                self.found.waited[record.ref] = max(
                    self.found.waited.get(record.ref, 0), record.value
                )
            elif record.what == "reach":
                self.found.reached[record.ref] = max(
                    self.found.reached.get(record.ref, 0), record.value
                )
            elif record.what == "miss" and record.ref not in self.found.missed:
                interesting = True
        key = state.key()
        known = self.zones.setdefault(key, [])
        zone = state.zone
        assert isinstance(zone, Zone)
        covered = False
        for other in known:
            node = self.nodes[other]
            other_zone = node.state.zone
            assert isinstance(other_zone, Zone)
            if other_zone.includes(zone):
                covered = True
                break
            if interesting:
                continue
            merged = other_zone.merge(zone) if MERGE else None
            if merged is None:
                continue
            # The union is a zone: one state, several ways in.
            ways = node.alternatives or [(node.parent, node.label, other_zone)]
            ways = [*ways, (parent, successor.label, zone)]
            if not node.expanded:
                node.alternatives = ways
                node.state = dataclasses.replace(node.state, zone=merged)
                return None
            # Already expanded: a new state for the union takes its place for what comes
            # (what is queued below the old one still runs: it may hold merged ways in).
            known.remove(other)  # the new one covers it from now on
            index = len(self.nodes)
            self.nodes.append(
                _Node(
                    dataclasses.replace(node.state, zone=merged),
                    node.parent,
                    node.label,
                    alternatives=ways,
                )
            )
            known.append(index)
            return index
        if covered and not interesting:
            return None
        index = len(self.nodes)
        self.nodes.append(_Node(state, parent, successor.label))
        for record in successor.records:
            if record.what == "timeout":
                self.found.timeouts.setdefault(record.ref, index)
            elif record.what == "miss":
                self.found.missed.setdefault(record.ref, index)
        if covered:
            return None  # kept for its witness only
        known.append(index)
        if parent >= 0 and self._repeats(index, key):
            names = self._path_labels(index)[-6:]
            self.cycle = (
                "the mission can come back to a state it was in, so it has no worst time "
                f"(a run repeats after: {'; '.join(names)})"
            )
        return index

    def _repeats(self, index: int, key: tuple[object, ...]) -> bool:
        node = self.nodes[index].parent
        while node >= 0:
            if self.nodes[node].state.key() == key:
                return True
            node = self.nodes[node].parent
        return False

    def _ended(self, index: int, state: AnyState) -> None:
        for deadline in self.model.deadlines:  # never reached while the run went on
            if deadline.index not in state.settled:
                self.found.missed.setdefault(deadline.index, index)
        if isinstance(state, EventState):
            assert isinstance(self.sem, EventSemantics)
            marking = self.sem.marking_of(state)
            low, high = self.sem.end_bounds(state)
        else:
            zone = state.zone
            assert isinstance(zone, Zone)
            marking = state.marking
            low, high = -zone.bound(START, NOW), zone.bound(NOW, START)
        final = self._final_of(marking)
        if final is None:
            self.found.stuck.setdefault(marking, index)
            return
        extreme = self.found.finals.get(final)
        if extreme is None:
            self.found.finals[final] = _Extreme(low, index, high, index)
            return
        if low < extreme.best:
            extreme.best, extreme.best_node = low, index
        if high > extreme.worst:
            extreme.worst, extreme.worst_node = high, index

    def _final_of(self, marking: tuple[int, ...]) -> int | None:
        values = tuple(marking[i] for i in self._final_columns)
        for number, wanted in enumerate(self._final_values):
            if values == wanted:
                return number
        return None

    def _path_labels(self, index: int) -> list[str]:
        labels = []
        while index >= 0:
            node = self.nodes[index]
            labels.append(node.label)
            index = node.parent
        return labels[::-1]

    # ------------------------------------------------------------------ report

    def _to_end(self, index: int) -> int:
        """A node where some run through node ``index`` has ended (the first successor
        each time, kept as nodes so a witness can pass through them)."""
        state = self.nodes[index].state
        steps = 0
        while not state.over and steps < 100_000:
            steps += 1
            successors = self.sem.successors(state)  # type: ignore[arg-type]
            if not successors:
                break
            first = successors[0]
            self.nodes.append(_Node(first.state, index, first.label))
            index = len(self.nodes) - 1
            state = first.state
        return index

    def _target_point(self, index: int, latest: bool) -> list[int]:
        """A valuation of node ``index``'s zone: the one where the run ends latest
        (``latest``), else where every moment is earliest (so the run ends earliest)."""
        state = self.nodes[index].state
        zone = state.zone
        assert isinstance(zone, Zone)
        if not latest:
            return zone.point([], [])
        if isinstance(state, EventState):
            last = [v for _, v in state.tokens] + list(state.sinks) or [START]
        else:
            last = [NOW]
        end = max(last, key=lambda v: zone.bound(v, START))
        return zone.point([end], [True])

    def _choose_path(self, index: int, point: list[int]) -> list[str] | None:
        """The labels of a run from the start to node ``index`` that passes through
        ``point`` of its zone.

        Walking back from the node, the point is carried to each predecessor: the
        step's zone before projection holds the predecessor's variables and the
        successor's; fixing the successor's to the point and taking any valuation of
        what is left gives a point of the predecessor that leads to it. At a merged
        state, the way in whose own zone holds the point is taken (the merged zone is
        the union of those, so one does)."""
        labels: list[str] = []
        while True:
            node = self.nodes[index]
            ways: list[tuple[int, str, Zone | None]] = (
                list(node.alternatives) if node.alternatives else [(node.parent, node.label, None)]
            )
            for parent, label, own in ways:
                if own is not None and not own.contains(point):
                    continue
                if parent < 0:
                    labels.append(label)
                    return labels[::-1]
                raw = self.sem.raw_step(self.nodes[parent].state, label)  # type: ignore[arg-type]
                if raw is None:
                    continue
                zone: Zone | None = raw[0]
                for position, var in enumerate(raw[1]):
                    if zone is None:
                        break
                    zone = zone.between(var, START, point[position], point[position])
                if zone is None:
                    continue
                before = self.nodes[parent].state.zone
                assert isinstance(before, Zone)
                values = zone.point([], [])
                point = [values[v] for v in self.sem.parent_vars(before.n)]
                labels.append(label)
                index = parent
                break
            else:
                return None

    def _schedule(
        self, index: int, kind: str, reason: str, latest: bool, target: int | None = None
    ) -> TimedSchedule:
        """A run to node ``index`` with concrete times; with ``target``, one whose end
        is that (us): the extreme the exploration found (`_choose_path` finds the way
        through merged states that attains it)."""
        labels = self._choose_path(index, self._target_point(index, latest))
        exact = labels is not None
        if labels is None:  # pragma: no cover - the union of the ways holds every point
            labels = self._path_labels(index)  # the way it was first reached
        schedule = schedule_of(
            self.model, labels, kind=kind, reason=reason, latest=latest, events=self.events
        )
        if target is None or (exact and abs(round(schedule.duration_s * US) - target) <= 1):
            return schedule
        return dataclasses.replace(
            schedule,
            reason=f"{reason} (this run takes {schedule.duration_s:.3f} s; the run attaining "
            f"{seconds(target):.3f} s was not reconstructed)",
        )

    def report(self) -> TimedReport:
        net = self.model.net
        finals = []
        if self.complete:
            for number, final in enumerate(self.finals):
                extreme = self.found.finals.get(number)
                if extreme is None:
                    continue
                name = format_tokens(final.tokens)
                finals.append(
                    FinalTiming(
                        final=dict(final.tokens),
                        best_s=seconds(extreme.best),
                        worst_s=seconds(extreme.worst),
                        best=self._schedule(
                            extreme.best_node,
                            "best-case",
                            f"best case to final {name}",
                            False,
                            extreme.best,
                        ),
                        worst=self._schedule(
                            extreme.worst_node,
                            "worst-case",
                            f"worst case to final {name}",
                            True,
                            extreme.worst,
                        ),
                    )
                )
        reason = self.reason
        if self.complete and self.found.stuck:
            stuck = "; ".join(
                format_tokens(sorted(net.marking_dict(m).items()))
                for m in list(self.found.stuck)[:3]
            )
            reason = f"runs can end in a marking that is not final: {stuck}"
        return TimedReport(
            complete=self.complete,
            reason=reason,
            link=self.model.link,
            states=len(self.nodes),
            seconds=time.perf_counter() - self.started,
            finals=tuple(finals),
            queries=self._queries(),
            deadlines=self._deadlines(),
            unbounded=self.cycle,
            stuck=tuple(
                {p: n for p, n in net.marking_dict(m).items() if n} for m in self.found.stuck
            ),
        )

    def _queries(self) -> tuple[QueryAdequacy, ...]:
        return tuple(
            self._query(ref, command)
            for ref, command in sorted(self.model.commands.items())
            if command.time_out is not None
        )

    def _query(self, ref: int, command: CommandModel) -> QueryAdequacy:
        """The adequacy of one watched query's time-out."""
        assert command.time_out is not None
        time_out = seconds(command.time_out)
        result = functools.partial(
            QueryAdequacy,
            command.name,
            command.command,
            time_out,
            span=self.model.net.transitions[ref].span,
        )
        node = self.found.timeouts.get(ref)
        if node is not None:
            reason = f"{command.name} ({command.command}) times out"
            schedule = self._schedule(self._to_end(node), "timeout", reason, False)
            detail = _timeout_detail(command.name, command.command, time_out, schedule)
            return result(Verdict.VIOLATED, detail, counterexample=schedule)
        if not self.complete:
            why = f"no time-out found before the search stopped: {self.reason}"
            return result(Verdict.INCONCLUSIVE, why)
        if ref not in self.found.sent:
            why = "never sent under these timing bounds, so it never times out"
            return result(Verdict.PROVEN, why)
        waited = seconds(self.found.waited.get(ref, 0))
        margin = time_out - waited
        detail = (
            f"replies done at most {waited:.3f} s after it arrives, "
            f"{margin:.3f} s before its {time_out:g} s time-out"
        )
        return result(Verdict.PROVEN, detail, margin_s=margin)

    def _deadlines(self) -> tuple[DeadlineResult, ...]:
        out = []
        for deadline in self.model.deadlines:
            limit = seconds(deadline.deadline)
            places = format_tokens(sorted(deadline.named.items()))
            node = self.found.missed.get(deadline.index)
            if node is not None:
                schedule = self._schedule(
                    self._to_end(node),
                    "deadline",
                    f"{places} not marked within {limit:g} s",
                    True,
                )
                out.append(
                    DeadlineResult(
                        deadline.index,
                        deadline.named,
                        limit,
                        Verdict.VIOLATED,
                        f"a run does not mark {places} within {limit:g} s "
                        f"(it ends at {schedule.duration_s:.3f} s in "
                        f"{format_tokens(sorted((schedule.final or {}).items()))})",
                        counterexample=schedule,
                    )
                )
            elif not self.complete:
                out.append(
                    DeadlineResult(
                        deadline.index,
                        deadline.named,
                        limit,
                        Verdict.INCONCLUSIVE,
                        f"no late run found before the search stopped: {self.reason}",
                    )
                )
            else:
                latest = seconds(self.found.reached.get(deadline.index, 0))
                out.append(
                    DeadlineResult(
                        deadline.index,
                        deadline.named,
                        limit,
                        Verdict.PROVEN,
                        f"every run marks {places} by {latest:.3f} s",
                        latest_s=latest,
                    )
                )
        return tuple(out)


def _timeout_detail(name: str, command: str, time_out: float, schedule: TimedSchedule) -> str:
    sent = next(
        (c for c in schedule.commands if c.transition == name and c.reply == "timeout"), None
    )
    if sent is None:
        return f"{name} ({command}) can time out"
    if sent.work_s < time_out - 1e-6:
        why = (
            f"after {sent.work_s:.3f} s a command on its resources stopped the task it "
            "watched, which times it out at once"
        )
    else:
        why = f"its {time_out:g} s time-out passed before the task it watches was done"
    return (
        f"{name} ({command}) can time out: sent at {sent.sent_at:.3f} s, it reached the "
        f"vehicle after {sent.up_delay_s:.3f} s, and {why}"
    )


def _unknown_queries(net: Net, reason: str) -> tuple[QueryAdequacy, ...]:
    from coral_lang.net import TransitionKind
    from coral_lang.profile import TIME_OUT

    out = []
    for tr in net.transitions:
        if tr.kind is not TransitionKind.COMMAND or tr.command is None:
            continue
        params = dict(tr.command.params)
        value = params.get(TIME_OUT)
        if not isinstance(value, int | float) or "timeout" not in tr.command.replies:
            continue
        out.append(
            QueryAdequacy(
                tr.name,
                tr.command.name,
                float(value),
                Verdict.INCONCLUSIVE,
                f"timed analysis did not run: {reason}",
                span=tr.span,
            )
        )
    return tuple(out)
