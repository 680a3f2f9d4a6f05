"""The timed semantics of a mission: symbolic states and their successors.

A symbolic state is the net's marking, the timers running (`Act`: a command on its way
to the vehicle, the vehicle's work, a query waiting for its task, a reply on its way
back, a deadline), which command holds which vehicle resource (`Holder`), and a zone
(`analysis.timed.zones.Zone`) over the moments those timers started. The model's rules
(``docs/analysis-methods.md``, timed analysis):

1. The engine fires whatever is enabled at once (zero time).
2. A command reaches the vehicle after a link delay in ``[link_low, link_high]``.
3. On arrival a task or an action takes its resources, stopping their holders: a
   stopped command whose reply is not yet due replies ``error``, and a query watching
   a resource of a stopped command replies ``timeout``, both at once. A task's or
   action's reply falls due after its work time; a task that accepted (any reply but
   ``error``) keeps its resources until stopped, an action or a refusing task lets
   them go when its reply falls due. A query with a time-out watches the task holding all its
   resources (if one does): its tracking completes a work time after that task's
   arrival (else after its own), and it replies ``done`` then if that is within its
   time-out, else ``timeout`` at the time-out.
4. A reply reaches the engine a latency plus a link delay after it fell due.

Successors are computed in two modes: exploration (variables no timer needs are
projected away, so that equal situations meet) and witness (`keep`: every moment stays
a variable, so a whole run can be given concrete times afterwards).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import NamedTuple

from analysis.timed.base import SemanticsBase, watched_start
from analysis.timed.model import TimedModel
from analysis.timed.zones import NOW, START, Zone, ZoneLike
from coral_lang.net import Transition

__all__ = [
    "DEADLINE",
    "DOWN",
    "UP",
    "WAIT",
    "WORK",
    "Act",
    "EngineSpin",
    "Holder",
    "Record",
    "Semantics",
    "State",
    "Successor",
]

UP, WORK, WAIT, DOWN, DEADLINE = range(5)
"""Timer phases: command on the link, vehicle working, query waiting, reply on the
link, an ``assert within`` deadline running."""

ENGINE_STEP_LIMIT = 10_000
"""Engine firings in one instant before the mission is declared to spin."""


class EngineSpin(Exception):
    """The engine can fire forever without time passing."""


class Act(NamedTuple):
    """A running timer.

    ``ref`` is the command transition (or deadline index); ``kind`` the reply kind
    (WORK, DOWN); ``a`` the moment the phase started (send, arrival, due; START for a
    deadline); ``b`` a waiting query's tracking start; ``watch`` the commands (by
    arrival variable) whose stopping times a waiting query out; ``origin`` the send
    moment (witness mode only, else -1).
    """

    phase: int
    ref: int
    kind: str
    a: int
    b: int
    watch: tuple[int, ...]
    origin: int


class Holder(NamedTuple):
    """A vehicle resource and the command holding it (by its arrival variable)."""

    resource: str
    ref: int
    var: int
    task: bool


class Record(NamedTuple):
    """Something a successor did, for witnesses and figures.

    ``what``: ``fire`` (a transition fired), ``send``, ``arrive`` (at the vehicle),
    ``due`` (a reply fell due), ``timeout`` (a query timed out), ``done`` (a query's
    done fell due; ``value`` = the latest it can be after the query's arrival, us),
    ``reach`` / ``miss`` (a deadline; ``value`` = latest time of reaching, us).
    ``var`` is the moment's variable and ``origin`` the command's send variable, in
    witness mode (else -1).
    """

    what: str
    ref: int
    kind: str
    var: int
    origin: int
    value: int


@dataclass(frozen=True)
class State:
    """A symbolic state (module docstring); ``settled`` holds the deadlines decided."""

    marking: tuple[int, ...]
    acts: tuple[Act, ...]
    holders: tuple[Holder, ...]
    settled: frozenset[int]
    zone: ZoneLike

    def key(self) -> tuple[object, ...]:
        """Everything but the zone: states with equal keys compare zones."""
        return (self.marking, self.acts, self.holders, self.settled)

    @property
    def over(self) -> bool:
        """No command is on its way or being worked on: the run has ended."""
        return all(act.phase == DEADLINE for act in self.acts)


class Renumbering:
    """Variables renumbered in order of first use, from the fixed ones: how a state
    keeps only what its timers need, so that equal situations meet (both explorers)."""

    def __init__(self, fixed: list[int]) -> None:
        self.order = list(fixed)
        self._index = {var: i for i, var in enumerate(fixed)}

    def use(self, var: int) -> int:
        """The new number of ``var`` (-1 stays -1: no variable)."""
        if var < 0:
            return -1
        if var not in self._index:
            self._index[var] = len(self.order)
            self.order.append(var)
        return self._index[var]

    def act(self, a: Act) -> Act:
        """``a`` over the new numbers (its send moment dropped: witness replays only)."""
        watch = tuple(sorted(self.use(v) for v in a.watch))
        return Act(a.phase, a.ref, a.kind, self.use(a.a), self.use(a.b), watch, -1)

    def holder(self, h: Holder) -> Holder:
        """``h`` over the new numbers."""
        return Holder(h.resource, h.ref, self.use(h.var), h.task)


class Successor(NamedTuple):
    """One successor: a label naming the choice (equal in both modes), the state,
    and what happened."""

    label: str
    state: State
    records: tuple[Record, ...]


class _Builder:
    """The mutable working copy of a state while one event is applied."""

    def __init__(self, sem: Semantics, state: State, zone: ZoneLike) -> None:
        self.sem = sem
        self.marking = state.marking
        self.acts = list(state.acts)
        self.holders = list(state.holders)
        self.settled = set(state.settled)
        self.zone = zone
        self.records: list[Record] = []
        self._stamp = -1

    def stamp(self) -> int:
        """A variable equal to ``now`` (one per event: every timer started by the
        event shares it)."""
        if self._stamp < 0:
            self.zone, self._stamp = self.zone.stamp_now()
        return self._stamp

    def time_var(self) -> int:
        """The moment's variable in witness mode, else -1."""
        return self.stamp() if self.sem.keep else -1

    def now_high(self) -> int:
        """Latest possible value of ``now``, us from the start."""
        return self.zone.bound(NOW, START)

    def record(self, what: str, ref: int, kind: str = "", origin: int = -1, value: int = 0) -> None:
        self.records.append(Record(what, ref, kind, self.time_var(), origin, value))

    def copy(self) -> _Builder:
        clone = _Builder.__new__(_Builder)
        clone.sem = self.sem
        clone.marking = self.marking
        clone.acts = list(self.acts)
        clone.holders = list(self.holders)
        clone.settled = set(self.settled)
        clone.zone = self.zone
        clone.records = list(self.records)
        clone._stamp = self._stamp
        return clone


class Semantics(SemanticsBase[State, Successor]):
    """Successor computation for one `TimedModel` (module docstring)."""

    def __init__(self, model: TimedModel, *, initial_zone: ZoneLike | None = None) -> None:
        super().__init__(model, initial_zone)
        self._state_now = NOW
        self.transitions: tuple[Transition, ...] = model.net.transitions

    # ------------------------------------------------------------------ net firing

    def enabled(self, marking: tuple[int, ...], t: int) -> bool:
        return all(marking[p] >= w for p, w in self._inputs[t])

    def fire(self, marking: tuple[int, ...], t: int) -> tuple[int, ...]:
        out = list(marking)
        for p, w in self._inputs[t]:
            out[p] -= w
        for p, w in self._outputs[t]:
            out[p] += w
        return tuple(out)

    def settle(self, marking: tuple[int, ...]) -> list[tuple[tuple[int, ...], tuple[int, ...]]]:
        """Every marking the engine can come to rest in from ``marking`` in one
        instant, each with one firing sequence that gets there.

        Zero-time firings are explored with stubborn sets (every marking in which
        nothing more is enabled is kept, and only those matter: time passes only
        there). With priorities, only the highest enabled priority fires, and every
        order is explored.

        Raises:
            EngineSpin: more than `ENGINE_STEP_LIMIT` firings without an end.
        """
        results: dict[tuple[int, ...], tuple[int, ...]] = {}
        done: set[tuple[int, ...]] = set()
        on_path: set[tuple[int, ...]] = {marking}
        # Depth-first, with the markings of the current path kept: coming back to one
        # of them is a zero-time cycle (the engine spins), not a diamond.
        stack: list[tuple[tuple[int, ...], tuple[int, ...], list[int]]] = [
            (marking, (), self._choices(marking))
        ]
        steps = 0
        while stack:
            m, fired, todo = stack[-1]
            if not todo:
                stack.pop()
                on_path.discard(m)
                done.add(m)
                continue
            t = todo.pop()
            child = self.fire(m, t)
            path = (*fired, t)
            steps += 1
            if child in on_path or steps > ENGINE_STEP_LIMIT:
                names = ", ".join(self.transitions[u].name for u in path[-6:])
                raise EngineSpin(f"the engine can keep firing without time passing (... {names})")
            if child in done:
                continue
            choices = self._choices(child)
            if not choices:
                results.setdefault(child, path)
                done.add(child)
                continue
            on_path.add(child)
            stack.append((child, path, choices))
        if not self._choices(marking):
            results[marking] = ()
        return sorted(results.items(), key=lambda item: item[1])

    def _choices(self, m: tuple[int, ...]) -> list[int]:
        """The engine transitions to try from ``m`` (last one first), none if at rest."""
        enabled = [t for t in self._engine if self.enabled(m, t)]
        if not enabled:
            return []
        if self._prioritised:
            top = max(self.transitions[t].priority for t in enabled)
            chosen = [t for t in enabled if self.transitions[t].priority == top]
        else:
            chosen = self._stubborn(m, enabled)
        return chosen[::-1]

    def _stubborn(self, m: tuple[int, ...], enabled: list[int]) -> list[int]:
        """The enabled transitions of a stubborn set seeded with ``enabled[0]``."""
        first = enabled[0]
        members = {first}
        todo = [first]
        while todo:
            t = todo.pop()
            if self.enabled(m, t):
                added = [u for p, _ in self._inputs[t] for u in self._consumers.get(p, ())]
            else:
                scapegoat = next(p for p, w in self._inputs[t] if m[p] < w)
                added = list(self._producers.get(scapegoat, ()))
            for u in added:
                if u not in members:
                    members.add(u)
                    todo.append(u)
        return [t for t in enabled if t in members]

    # ------------------------------------------------------------------ states

    def initial(self) -> list[Successor]:
        """The states the mission can rest in at time 0."""
        net = self.model.net
        marking = tuple(p.initial for p in net.places)
        acts = tuple(Act(DEADLINE, d.index, "", START, -1, (), -1) for d in self.model.deadlines)
        state = State(marking, acts, (), frozenset(), self._initial_zone)
        builder = _Builder(self, state, state.zone)
        self.last_raw_by_label = {}
        out = []
        for label, b in self._engine_step(builder, "start"):
            out.append(Successor(label, self._finish(b), tuple(b.records)))
            self.last_raw_by_label[label] = self.last_raw
        return out

    def invariant(self, state: State, zone: ZoneLike) -> ZoneLike | None:
        """``zone`` with every running timer's upper bound."""
        model = self.model
        out: ZoneLike | None = zone
        for act in state.acts:
            assert out is not None
            if act.phase == UP:
                out = out.constrain(NOW, act.a, model.link_high)
            elif act.phase == WORK:
                out = out.constrain(NOW, act.a, model.commands[act.ref].interval(act.kind)[1])
            elif act.phase == WAIT:
                command = model.commands[act.ref]
                assert command.time_out is not None
                out = out.constrain(NOW, act.a, command.time_out)
                if out is not None:
                    out = out.constrain(NOW, act.b, command.interval(command.tracked)[1])
            elif act.phase == DOWN:
                latency = model.commands[act.ref].latency
                out = out.constrain(NOW, act.a, model.link_high + latency)
            else:
                # missed 1 us after the deadline: reaching the places at it is in time
                out = out.constrain(NOW, START, self._deadline(act.ref) + 1)
            if out is None:
                return None
        return out

    def parent_vars(self, n: int) -> list[int]:
        """For the last `raw_step`: the variable of the step's zone standing for each of
        the predecessor's ``n`` variables (``now`` was kept aside before time passed)."""
        return [START, self._state_now, *range(2, n)]

    def successors(self, state: State) -> list[Successor]:
        """Every state one timed event (and the engine's reaction) leads to."""
        self.last_raw_by_label = {}
        # The moment of the state itself is kept as a variable of its own before time
        # passes (``now`` moves): `raw_step` maps a point back to the state with it.
        before, self._state_now = state.zone.stamp_now()
        zone = self.invariant(state, before.elapse())
        if zone is None:
            return []
        out: list[Successor] = []
        for index, act in enumerate(state.acts):
            for label, guarded, apply in self._events(index, act, zone):
                if guarded is None:
                    continue
                builder = _Builder(self, state, guarded)
                for tail, done in apply(builder):
                    out.append(Successor(f"{label}{tail}", self._finish(done), tuple(done.records)))
                    self.last_raw_by_label[f"{label}{tail}"] = self.last_raw
        return out

    # ------------------------------------------------------------------ events

    def _events(
        self, index: int, act: Act, zone: ZoneLike
    ) -> Iterator[tuple[str, ZoneLike | None, _Apply]]:
        model = self.model
        name = self.transitions[act.ref].name if act.phase != DEADLINE else ""
        if act.phase == UP:
            yield (
                f"arrive {name}@{index}",
                zone.constrain(act.a, NOW, -model.link_low),
                lambda b: self._arrive(b, index),
            )
        elif act.phase == WORK:
            low = model.commands[act.ref].interval(act.kind)[0]
            yield (
                f"due {name}.{act.kind}@{index}",
                zone.constrain(act.a, NOW, -low),
                lambda b: self._due(b, index, act.kind),
            )
        elif act.phase == WAIT:
            command = model.commands[act.ref]
            low, high = command.interval(command.tracked)
            assert command.time_out is not None
            yield (
                f"done {name}@{index}",
                zone.constrain(act.b, NOW, -low),
                lambda b: self._due(b, index, command.tracked),
            )
            timed_out = zone.constrain(act.a, NOW, -command.time_out)
            if timed_out is not None:
                timed_out = timed_out.constrain(NOW, act.b, high - 1)
            yield (f"timeout {name}@{index}", timed_out, lambda b: self._due(b, index, "timeout"))
        elif act.phase == DOWN:
            yield (
                f"reply {name}.{act.kind}@{index}",
                zone.constrain(act.a, NOW, -model.link_low),
                lambda b: self._reply(b, index),
            )
        else:
            yield (
                f"deadline {act.ref}@{index}",
                zone.constrain(START, NOW, -(self._deadline(act.ref) + 1)),
                lambda b: self._miss(b, index),
            )

    def _deadline(self, index: int) -> int:
        return next(d.deadline for d in self.model.deadlines if d.index == index)

    def _arrive(self, b: _Builder, index: int) -> list[tuple[str, _Builder]]:
        act = b.acts[index]
        command = self.model.commands[act.ref]
        arrival = b.stamp()
        b.record("arrive", act.ref, origin=act.origin)
        if command.takes_resources:
            self._displace(b, command.resources)
        out: list[tuple[str, _Builder]] = []
        base = b
        kinds = [k for k, _, _ in command.work if not (command.watched and k == command.tracked)]
        if command.watched:
            out.extend(self._watch(base, index, arrival))
        for kind in kinds:
            branch = base.copy()
            branch.acts[index] = Act(WORK, act.ref, kind, arrival, -1, (), act.origin)
            if command.takes_resources:
                for resource in command.resources:
                    branch.holders.append(
                        Holder(resource, act.ref, arrival, command.kind == "task")
                    )
            out.append((f" {kind}", branch))
        return out

    def _watch(self, base: _Builder, index: int, arrival: int) -> list[tuple[str, _Builder]]:
        """A query with a time-out arrives: it watches the task holding all its
        resources, whose tracking completes ``done``'s work time after that task's
        arrival (or its own, when no task holds them). Two cases, which may overlap:
        the tracking already completed (``done`` falls due at once), or it completes
        later (the query waits, and times out if the time-out passes first)."""
        act = base.acts[index]
        command = self.model.commands[act.ref]
        watch, start = watched_start(base.holders, command.resources, arrival)
        low, high = command.interval(command.tracked)
        out: list[tuple[str, _Builder]] = []
        tracked = base.zone.constrain(start, NOW, -low)
        if tracked is not None:
            branch = base.copy()
            branch.zone = tracked
            branch.acts[index] = Act(WAIT, act.ref, "", arrival, start, watch, act.origin)
            out.extend((" tracked", done) for _, done in self._due(branch, index, command.tracked))
        waiting = base.zone.constrain(NOW, start, high - 1)
        if waiting is not None:
            branch = base.copy()
            branch.zone = waiting
            branch.acts[index] = Act(WAIT, act.ref, "", arrival, start, watch, act.origin)
            out.append((" waits", branch))
        return out

    def _displace(self, b: _Builder, resources: tuple[str, ...]) -> None:
        """Stop every command holding one of ``resources`` (rule 3)."""
        stopped = {h.var for h in b.holders if h.resource in resources}
        # Every resource of a stopped command: a query watching any of them times out
        # (as the vehicle does), whichever command it found holding them on arrival.
        released = {h.resource for h in b.holders if h.var in stopped}
        if not stopped:
            return
        b.holders = [h for h in b.holders if h.var not in stopped]
        for i, act in enumerate(b.acts):
            if act.phase == WORK and act.a in stopped:
                command = self.model.commands[act.ref]
                if command.reply_transition("error") is not None:
                    b.acts[i] = Act(DOWN, act.ref, "error", b.stamp(), -1, (), act.origin)
                    b.record("due", act.ref, "error", origin=act.origin)
            elif act.phase == WAIT and released.intersection(
                self.model.commands[act.ref].resources
            ):
                b.acts[i] = Act(DOWN, act.ref, "timeout", b.stamp(), -1, (), act.origin)
                b.record("due", act.ref, "timeout", origin=act.origin)
                b.record("timeout", act.ref, "timeout", origin=act.origin)

    def _due(self, b: _Builder, index: int, kind: str) -> list[tuple[str, _Builder]]:
        act = b.acts[index]
        command = self.model.commands[act.ref]
        if act.phase == WAIT and kind != "timeout":
            b.record("done", act.ref, "done", origin=act.origin, value=self._waited(b, act))
        due = b.stamp()
        b.acts[index] = Act(DOWN, act.ref, kind, due, -1, (), act.origin)
        b.record("due", act.ref, kind, origin=act.origin)
        if kind == "timeout":
            b.record("timeout", act.ref, kind, origin=act.origin)
        if command.kind == "action" or kind == "error":  # it lets its resources go
            b.holders = [h for h in b.holders if h.var != act.a]
        return [("", b)]

    @staticmethod
    def _waited(b: _Builder, act: Act) -> int:
        """Latest time from a query's arrival to its ``done`` falling due, us."""
        return b.zone.bound(NOW, act.a)

    def _reply(self, b: _Builder, index: int) -> list[tuple[str, _Builder]]:
        act = b.acts.pop(index)
        command = self.model.commands[act.ref]
        reply = command.reply_transition(act.kind)
        assert reply is not None
        b.marking = self.fire(b.marking, reply)
        b.record("fire", reply, act.kind, origin=act.origin)
        return self._engine_step(b, "")

    def _miss(self, b: _Builder, index: int) -> list[tuple[str, _Builder]]:
        act = b.acts.pop(index)
        b.settled.add(act.ref)
        b.record("miss", act.ref, value=b.now_high())
        return [("", b)]

    def _engine_step(self, b: _Builder, label: str) -> list[tuple[str, _Builder]]:
        """The engine's reaction at this instant: one branch per resting marking."""
        outcomes = self.settle(b.marking)
        out = []
        for number, (marking, fired) in enumerate(outcomes):
            branch = b.copy() if len(outcomes) > 1 else b
            for t in fired:
                branch.marking = self.fire(branch.marking, t)
                if t in self.model.commands:
                    send = branch.stamp()
                    origin = send if self.keep else -1
                    branch.acts.append(Act(UP, t, "", send, -1, (), origin))
                    branch.record("fire", t, origin=origin)
                    branch.record("send", t, origin=origin)
                else:
                    branch.record("fire", t)
            assert branch.marking == marking
            self._check_deadlines(branch)
            suffix = f"{label} engine#{number}" if len(outcomes) > 1 else label
            out.append((suffix, branch))
        return out

    def _check_deadlines(self, b: _Builder) -> None:
        for deadline in self.model.deadlines:
            if deadline.index in b.settled or not deadline.reached(b.marking):
                continue
            b.settled.add(deadline.index)
            b.acts = [a for a in b.acts if not (a.phase == DEADLINE and a.ref == deadline.index)]
            b.record("reach", deadline.index, value=b.now_high())

    # ------------------------------------------------------------------ normal form

    def _finish(self, b: _Builder) -> State:
        """The builder as a state: timers in a canonical order and, in exploration
        mode, only the variables some timer still needs (renumbered in order of use),
        so that equal situations reached along different runs meet."""
        acts = sorted(b.acts, key=_act_order)
        holders = sorted(b.holders, key=lambda h: (h.resource, h.ref))
        if self.keep or not isinstance(b.zone, Zone):
            return State(b.marking, tuple(acts), tuple(holders), frozenset(b.settled), b.zone)
        renumber = Renumbering([START, NOW])
        self.last_raw = (b.zone, renumber.order)
        renamed_acts = tuple(renumber.act(a) for a in acts)
        renamed_holders = tuple(renumber.holder(h) for h in holders)
        return State(
            b.marking,
            renamed_acts,
            renamed_holders,
            frozenset(b.settled),
            b.zone.keep(renumber.order),
        )


_Apply = Callable[[_Builder], list[tuple[str, _Builder]]]


def _act_order(act: Act) -> tuple[int, int, str]:
    return (act.phase, act.ref, act.kind)
