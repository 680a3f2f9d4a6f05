"""The timed semantics with partial-order reduction: event times, not a global clock.

`analysis.timed.semantics` keeps one clock, ``now``, and so orders every pair of
events, even events of two branches that never meet: N such branches give every
interleaving a zone of its own, and 3 branches are already out of reach. Here each
event gets a time variable of its own, constrained only against the events it depends
on, and two independent events commute exactly (same constraints, in either order).
The state then depends on which events happened, not on the order they were explored
in, and a stubborn set explores one group of dependent timers at a time (Valmari's
deadlock-preserving reduction; every end state is kept, with its whole zone).

What depends on what (each is a *sync*, with the time of its last event kept):

* a vehicle resource: arrivals of commands that take or watch it, queries' outcomes on
  it, actions releasing it. Their order decides who displaces whom and what a query
  watches, so they are totally ordered (each new one at or after the last);
* a conflict cluster: engine transitions that share an input place race for tokens
  (the first enabled wins), so every event putting a token into or taking one out of
  an input place of such a transition is ordered;
* a deadline: events that change a place an ``assert within`` names are ordered, so
  the marking of those places at each of them is the real one at that time.

Events that touch a sync must happen while every timer waiting to touch the same sync
has not yet been forced to fire (its deadline is not before them). An engine
transition fires when its last input token arrives: at the latest of its tokens'
times, one successor per token that can be the latest.

Exact on 1-safe nets (no place holds two tokens): `NotSafe` is raised otherwise, and
the explorer falls back to the global-clock semantics. Missions are almost always
1-safe.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

from analysis.timed.base import SemanticsBase, watched_start
from analysis.timed.model import TimedModel
from analysis.timed.semantics import (
    DOWN,
    UP,
    WAIT,
    WORK,
    Act,
    EngineSpin,
    Holder,
    Record,
    Renumbering,
)
from analysis.timed.zones import INF, START, Zone, ZoneLike

__all__ = ["EventSemantics", "EventState", "NotSafe"]


class NotSafe(Exception):
    """A place would hold two tokens: this semantics does not apply."""


@dataclass(frozen=True)
class EventState:
    """Tokens (place -> time variable of the token), timers, holders, the last time of
    each sync, sink firings (transitions with no output, whose time still counts
    towards the end), the deadlines decided, and the zone."""

    tokens: tuple[tuple[int, int], ...]
    acts: tuple[Act, ...]
    holders: tuple[Holder, ...]
    syncs: tuple[tuple[str, int], ...]
    sinks: tuple[int, ...]
    settled: frozenset[int]
    zone: ZoneLike

    def key(self) -> tuple[object, ...]:
        """Everything but the zone."""
        return (self.tokens, self.acts, self.holders, self.syncs, self.sinks, self.settled)

    @property
    def over(self) -> bool:
        """No timer runs: the run has ended."""
        return not self.acts


class Successor(NamedTuple):
    """As `analysis.timed.semantics.Successor`."""

    label: str
    state: EventState
    records: tuple[Record, ...]


class _Builder:
    def __init__(self, sem: EventSemantics, state: EventState) -> None:
        self.sem = sem
        self.tokens = dict(state.tokens)
        self.acts = list(state.acts)
        self.holders = list(state.holders)
        self.syncs = dict(state.syncs)
        self.sinks = list(state.sinks)
        self.settled = set(state.settled)
        self.zone: ZoneLike | None = state.zone
        self.records: list[Record] = []

    def copy(self) -> _Builder:
        clone = _Builder.__new__(_Builder)
        clone.sem = self.sem
        clone.tokens = dict(self.tokens)
        clone.acts = list(self.acts)
        clone.holders = list(self.holders)
        clone.syncs = dict(self.syncs)
        clone.sinks = list(self.sinks)
        clone.settled = set(self.settled)
        clone.zone = self.zone
        clone.records = list(self.records)
        return clone

    def constrain(self, i: int, j: int, c: int) -> bool:
        """Add ``x_i - x_j <= c``; False (and the builder dead) when empty."""
        if self.zone is None:
            return False
        self.zone = self.zone.constrain(i, j, c)
        return self.zone is not None

    def fresh(self) -> int:
        assert self.zone is not None
        self.zone, var = self.zone.fresh()
        return var

    def record(
        self, what: str, ref: int, kind: str, var: int, origin: int = -1, value: int = 0
    ) -> None:
        keep = self.sem.keep
        self.records.append(Record(what, ref, kind, var if keep else -1, origin, value))


_Apply = Callable[[_Builder, int], list[tuple[str, _Builder]]]


class EventSemantics(SemanticsBase[EventState, Successor]):
    """Successors of `EventState` (module docstring) for one `TimedModel`."""

    def __init__(self, model: TimedModel, *, initial_zone: ZoneLike | None = None) -> None:
        super().__init__(model, initial_zone)
        net = model.net
        engine = model.engine
        self._pending = {
            net.place_index(t.pending) for t in net.transitions if t.pending is not None
        }
        self._place_syncs = self._sync_places(engine)
        self._touches = self._direct_touches()
        self._footprints = self._future_footprints()

    # ------------------------------------------------------------------ static structure

    def _sync_places(self, engine: tuple[int, ...]) -> dict[int, tuple[str, ...]]:
        """Place -> the syncs (conflict clusters, deadlines) a token change there is."""
        parent = {t: t for t in engine}

        def find(t: int) -> int:
            while parent[t] != t:
                parent[t] = parent[parent[t]]
                t = parent[t]
            return t

        shared = set()
        for users in self._consumers.values():
            if len(users) > 1:
                shared.update(users)
                for u in users[1:]:
                    parent[find(u)] = find(users[0])
        out: dict[int, set[str]] = {}
        for t in shared:
            for p, _ in self._inputs[t]:
                out.setdefault(p, set()).add(f"k:{find(t)}")
        for deadline in self.model.deadlines:
            for p, _ in deadline.places:
                out.setdefault(p, set()).add(f"d:{deadline.index}")
        return {p: tuple(sorted(s)) for p, s in out.items()}

    def _zero_time_places(self, places: set[int]) -> set[int]:
        """``places`` and every place the engine can mark from them without a command
        round trip (what an event's zero-time reaction can touch)."""
        seen = set(places)
        todo = list(places)
        while todo:
            p = todo.pop()
            for t in self._consumers.get(p, ()):
                for q, _ in self._outputs[t]:
                    if q not in seen:
                        seen.add(q)
                        todo.append(q)
        return seen

    def _direct_touches(self) -> dict[tuple[int, int], frozenset[str]]:
        """(command, phase) -> the syncs the timer's next event touches."""
        out: dict[tuple[int, int], frozenset[str]] = {}
        for ref, command in self.model.commands.items():
            resources = {f"r:{r}" for r in command.resources}
            arrival = resources if (command.takes_resources or command.watched) else set()
            if command.takes_resources:
                # stopping a holder frees all its resources, and times out the queries
                # on any of them: those are touched too
                arrival = arrival | {f"r:{r}" for r in self._displaceable(command.resources)}
            out[(ref, UP)] = frozenset(arrival)
            out[(ref, WORK)] = frozenset(resources if command.takes_resources else ())
            out[(ref, WAIT)] = frozenset(resources)
            outputs = {p for _, reply in command.replies for p, _ in self._outputs[reply]}
            reach = self._zero_time_places(outputs)
            syncs = {s for p in reach for s in self._place_syncs.get(p, ())}
            # an arrival also takes the pending token, and consumes what it enables
            for p in reach:
                for t in self._consumers.get(p, ()):
                    for q, _ in self._inputs[t]:
                        syncs.update(self._place_syncs.get(q, ()))
            out[(ref, DOWN)] = frozenset(syncs)
        return out

    def _displaceable(self, resources: tuple[str, ...]) -> set[str]:
        """Every resource a command that takes ``resources`` can free by stopping the
        holders of them (each holder's other resources included)."""
        out = set(resources)
        for other in self.model.commands.values():
            if other.takes_resources and out.intersection(other.resources):
                out.update(other.resources)
        return out

    def _future_footprints(self) -> dict[tuple[int, int], frozenset[str]]:
        """(command, phase) -> every sync the timer and everything after it may touch
        (its command's remaining events, the engine's reactions, the commands those
        send, and so on): timers with disjoint footprints are independent."""
        below: dict[int, frozenset[str]] = {}

        def downstream(ref: int, stack: tuple[int, ...]) -> frozenset[str]:
            if ref in below:
                return below[ref]
            if ref in stack:
                return frozenset()
            command = self.model.commands[ref]
            syncs = {f"r:{r}" for r in command.resources}
            syncs.update(self._touches[(ref, UP)])
            syncs.update(self._touches[(ref, DOWN)])
            outputs = {p for _, reply in command.replies for p, _ in self._outputs[reply]}
            seen = set(outputs)
            todo = list(outputs)
            while todo:
                p = todo.pop()
                syncs.update(self._place_syncs.get(p, ()))
                for t in self._consumers.get(p, ()):
                    for q, _ in self._inputs[t]:
                        syncs.update(self._place_syncs.get(q, ()))
                    if t in self.model.commands:
                        syncs.update(downstream(t, (*stack, ref)))
                    for q, _ in self._outputs[t]:
                        if q not in seen:
                            seen.add(q)
                            todo.append(q)
            result = frozenset(syncs)
            if not stack:
                below[ref] = result
            return result

        out = {}
        for ref in self.model.commands:
            everything = downstream(ref, ())
            for phase in (UP, WORK, WAIT, DOWN):
                out[(ref, phase)] = everything
        return out

    def groups(self) -> int:
        """How many groups the commands fall into when commands whose footprints
        meet are put together: with one, nothing is independent and event times only
        add variables (the explorer then takes the global clock)."""
        parent = {ref: ref for ref in self.model.commands}

        def find(ref: int) -> int:
            while parent[ref] != ref:
                parent[ref] = parent[parent[ref]]
                ref = parent[ref]
            return ref

        owner: dict[str, int] = {}
        for ref in self.model.commands:
            for sync in self._footprints[(ref, UP)]:
                other = owner.setdefault(sync, ref)
                parent[find(ref)] = find(other)
        return len({find(ref) for ref in parent})

    # ------------------------------------------------------------------ states

    def marking_of(self, state: EventState) -> tuple[int, ...]:
        """The net marking of ``state``."""
        marking = [0] * len(self.model.net.places)
        for p, _ in state.tokens:
            marking[p] += 1
        for act in state.acts:
            pending = self.model.net.transitions[act.ref].pending
            if pending is not None:
                marking[self.model.net.place_index(pending)] += 1
        return tuple(marking)

    def end_bounds(self, state: EventState) -> tuple[int, int]:
        """Earliest and latest end of the run (its last event), us."""
        zone = state.zone
        assert isinstance(zone, Zone)
        last = [v for _, v in state.tokens] + list(state.sinks)
        if not last:
            return 0, 0
        high = max(zone.bound(v, START) for v in last)
        zone2, end = zone.fresh()
        for v in last:
            narrowed = zone2.constrain(v, end, 0)
            assert narrowed is not None
            zone2 = narrowed
        return -zone2.bound(START, end), high

    def initial(self) -> list[Successor]:
        """The states the mission can rest in at time 0."""
        net = self.model.net
        tokens = []
        for p, place in enumerate(net.places):
            if place.initial > 1:
                raise NotSafe(f"{place.name} starts with {place.initial} tokens")
            if place.initial == 1:
                tokens.append((p, START))
        state = EventState(tuple(tokens), (), (), (), (), frozenset(), self._initial_zone)
        builder = _Builder(self, state)
        out = []
        self.last_raw_by_label = {}
        for label, b in self._engine_step(builder, "start"):
            if b.zone is not None:
                out.append(Successor(label, self._finish(b), tuple(b.records)))
                self.last_raw_by_label[label] = self.last_raw
        return out

    def parent_vars(self, n: int) -> list[int]:
        """For the last `raw_step`: the step's zone starts with the predecessor's ``n``
        variables, unchanged."""
        return list(range(n))

    def successors(self, state: EventState) -> list[Successor]:
        """The successors by the events of one stubborn group of timers."""
        out: list[Successor] = []
        self.last_raw_by_label = {}
        for index in self._stubborn(state):
            act = state.acts[index]
            for label, apply in self._events(act):
                builder = _Builder(self, state)
                for tail, done in apply(builder, index):
                    if done.zone is not None:
                        name = f"{label}@{index}{tail}"
                        out.append(Successor(name, self._finish(done), tuple(done.records)))
                        self.last_raw_by_label[name] = self.last_raw
        return out

    def _stubborn(self, state: EventState) -> list[int]:
        """The timers of one group closed under shared footprints."""
        acts = state.acts
        if not acts:
            return []
        prints = [self._footprints[(a.ref, a.phase)] for a in acts]
        group_of = list(range(len(acts)))

        def find(i: int) -> int:
            while group_of[i] != i:
                group_of[i] = group_of[group_of[i]]
                i = group_of[i]
            return i

        owner: dict[str, int] = {}
        for i, fp in enumerate(prints):
            for sync in fp:
                j = owner.setdefault(sync, i)
                if j != i:
                    group_of[find(i)] = find(j)
        groups: dict[int, list[int]] = {}
        for i in range(len(acts)):
            groups.setdefault(find(i), []).append(i)
        # The group of the earliest-written command goes first, and keeps going until it
        # is done: states then differ by what one group did, and merge (explorer).
        return min(groups.values(), key=lambda g: (min(acts[i].ref for i in g), len(g)))

    # ------------------------------------------------------------------ events

    def _events(self, act: Act) -> list[tuple[str, _Apply]]:
        name = self.model.net.transitions[act.ref].name
        if act.phase == UP:
            return [(f"arrive {name}", self._arrive)]
        if act.phase == WORK:
            return [(f"due {name}.{act.kind}", self._work_due)]
        if act.phase == WAIT:
            return [(f"done {name}", self._done), (f"timeout {name}", self._timeout)]
        return [(f"reply {name}.{act.kind}", self._reply)]

    def _touch(self, b: _Builder, syncs: frozenset[str], t: int, skip: int) -> bool:
        """Event at ``t`` touching ``syncs``: at or after their last events, before the
        deadline of every other timer waiting to touch them; they move to ``t``."""
        if not syncs:
            return True
        for sync in syncs:
            last = b.syncs.get(sync)
            if last is not None and not b.constrain(last, t, 0):
                return False
        for i, other in enumerate(b.acts):
            if i == skip:
                continue
            if syncs & self._touches[(other.ref, other.phase)] and not self._before_deadline(
                b, other, t
            ):
                return False
            if not self._before_later_touches(b, other, syncs, t):
                return False
        for sync in syncs:
            b.syncs[sync] = t
        return True

    def _before_later_touches(self, b: _Builder, act: Act, syncs: frozenset[str], t: int) -> bool:
        """``t`` no later than the latest moment a later event of ``act``'s own command
        (its work ending, its reply reaching the engine) that touches ``syncs`` can
        come: that event comes after ``t`` in the order of those syncs, so a ``t``
        past its latest moment is no run at all."""
        model = self.model
        command = model.commands[act.ref]
        latency = command.latency
        high = model.link_high
        slowest = max([h for _, _, h in command.work] + [command.time_out or 0])
        later_work = act.phase == UP and bool(
            syncs & (self._touches[(act.ref, WORK)] | self._touches[(act.ref, WAIT)])
        )
        if later_work and not b.constrain(t, act.a, high + slowest):
            return False
        if act.phase == DOWN or not syncs & self._touches[(act.ref, DOWN)]:
            return True
        if act.phase == UP:
            return b.constrain(t, act.a, 2 * high + slowest + latency)
        if act.phase == WORK:
            return b.constrain(t, act.a, command.interval(act.kind)[1] + high + latency)
        assert command.time_out is not None
        return b.constrain(t, act.a, command.time_out + high + latency) and b.constrain(
            t, act.b, command.interval(command.tracked)[1] + high + latency
        )

    def _before_deadline(self, b: _Builder, act: Act, t: int) -> bool:
        """``t`` no later than the latest moment ``act`` may still fire."""
        model = self.model
        if act.phase == UP:
            return b.constrain(t, act.a, model.link_high)
        if act.phase == WORK:
            return b.constrain(t, act.a, model.commands[act.ref].interval(act.kind)[1])
        if act.phase == WAIT:
            command = model.commands[act.ref]
            assert command.time_out is not None
            return b.constrain(t, act.a, command.time_out) and b.constrain(
                t, act.b, command.interval(command.tracked)[1]
            )
        latency = model.commands[act.ref].latency
        return b.constrain(t, act.a, model.link_high + latency)

    def _within(self, b: _Builder, t: int, start: int, low: int, high: int) -> bool:
        """``low <= t - start <= high`` (either end may be unbounded, +-`INF`)."""
        return (low <= -INF or b.constrain(start, t, -low)) and (
            high >= INF or b.constrain(t, start, high)
        )

    def _place(
        self, b: _Builder, index: int, windows: list[tuple[int, int, int]], *, touch: bool = True
    ) -> int | None:
        """The time variable of timer ``index``'s next event: ``low <= t - start <=
        high`` for each ``(start, low, high)`` of ``windows`` and, with ``touch``, at its
        place in the order of the syncs its phase touches (`_touch`). None if no such
        time exists."""
        act = b.acts[index]
        t = b.fresh()
        if not all(self._within(b, t, start, low, high) for start, low, high in windows):
            return None
        if touch and not self._touch(b, self._touches[(act.ref, act.phase)], t, index):
            return None
        return t

    def _arrive(self, b: _Builder, index: int) -> list[tuple[str, _Builder]]:
        act = b.acts[index]
        model = self.model
        command = model.commands[act.ref]
        t = self._place(b, index, [(act.a, model.link_low, model.link_high)])
        if t is None:
            return []
        b.record("arrive", act.ref, "", t, act.origin)
        if command.takes_resources and not self._displace(b, command.resources, t, index):
            return []
        out: list[tuple[str, _Builder]] = []
        if command.watched:
            out.extend(self._watch(b, index, t))
        for kind, _, _ in command.work:
            if command.watched and kind == command.tracked:
                continue
            branch = b.copy()
            branch.acts[index] = Act(WORK, act.ref, kind, t, -1, (), act.origin)
            if command.takes_resources:
                for resource in command.resources:
                    branch.holders.append(Holder(resource, act.ref, t, command.kind == "task"))
            out.append((f" {kind}", branch))
        return out

    def _watch(self, base: _Builder, index: int, t: int) -> list[tuple[str, _Builder]]:
        act = base.acts[index]
        command = self.model.commands[act.ref]
        watch, start = watched_start(base.holders, command.resources, t)
        low, high = command.interval(command.tracked)
        out: list[tuple[str, _Builder]] = []
        tracked = base.copy()
        if tracked.constrain(start, t, -low):
            tracked.record("done", act.ref, "done", t, act.origin, 0)
            tracked.acts[index] = Act(DOWN, act.ref, command.tracked, t, -1, (), act.origin)
            tracked.record("due", act.ref, command.tracked, t, act.origin)
            out.append((" tracked", tracked))
        waiting = base.copy()
        if waiting.constrain(t, start, high - 1):
            waiting.acts[index] = Act(WAIT, act.ref, "", t, start, watch, act.origin)
            out.append((" waits", waiting))
        return out

    def _displace(self, b: _Builder, resources: tuple[str, ...], t: int, skip: int) -> bool:
        stopped = {h.var for h in b.holders if h.resource in resources}
        # Every resource of a stopped command: a query watching any of them times out
        # (as the vehicle does), whichever command it found holding them on arrival.
        released = {h.resource for h in b.holders if h.var in stopped}
        if not stopped:
            return True
        b.holders = [h for h in b.holders if h.var not in stopped]
        for i, act in enumerate(b.acts):
            if i == skip:
                continue
            if act.phase == WORK and act.a in stopped:
                command = self.model.commands[act.ref]
                if command.reply_transition("error") is not None:
                    if not self._before_deadline(b, act, t):
                        return False
                    b.acts[i] = Act(DOWN, act.ref, "error", t, -1, (), act.origin)
                    b.record("due", act.ref, "error", t, act.origin)
            elif act.phase == WAIT and released.intersection(
                self.model.commands[act.ref].resources
            ):
                if not self._before_deadline(b, act, t):
                    return False
                b.acts[i] = Act(DOWN, act.ref, "timeout", t, -1, (), act.origin)
                b.record("due", act.ref, "timeout", t, act.origin)
                b.record("timeout", act.ref, "timeout", t, act.origin)
        return True

    def _work_due(self, b: _Builder, index: int) -> list[tuple[str, _Builder]]:
        act = b.acts[index]
        command = self.model.commands[act.ref]
        low, high = command.interval(act.kind)
        t = self._place(b, index, [(act.a, low, high)])
        if t is None:
            return []
        if command.kind == "action" or act.kind == "error":  # it lets its resources go
            b.holders = [h for h in b.holders if h.var != act.a]
        b.acts[index] = Act(DOWN, act.ref, act.kind, t, -1, (), act.origin)
        b.record("due", act.ref, act.kind, t, act.origin)
        return [("", b)]

    def _done(self, b: _Builder, index: int) -> list[tuple[str, _Builder]]:
        act = b.acts[index]
        command = self.model.commands[act.ref]
        assert command.time_out is not None
        low, high = command.interval(command.tracked)
        t = self._place(b, index, [(act.b, low, high), (act.a, 0, command.time_out)])
        if t is None:
            return []
        assert b.zone is not None
        waited = b.zone.bound(t, act.a)
        b.record("done", act.ref, "done", t, act.origin, waited)
        b.acts[index] = Act(DOWN, act.ref, command.tracked, t, -1, (), act.origin)
        b.record("due", act.ref, command.tracked, t, act.origin)
        return [("", b)]

    def _timeout(self, b: _Builder, index: int) -> list[tuple[str, _Builder]]:
        act = b.acts[index]
        command = self.model.commands[act.ref]
        assert command.time_out is not None
        high = command.interval(command.tracked)[1]
        # at the time-out, the tracking not yet complete (done wins a tie)
        windows = [(act.a, command.time_out, command.time_out), (act.b, -INF, high - 1)]
        t = self._place(b, index, windows)
        if t is None:
            return []
        b.acts[index] = Act(DOWN, act.ref, "timeout", t, -1, (), act.origin)
        b.record("due", act.ref, "timeout", t, act.origin)
        b.record("timeout", act.ref, "timeout", t, act.origin)
        return [("", b)]

    def _reply(self, b: _Builder, index: int) -> list[tuple[str, _Builder]]:
        act = b.acts[index]
        model = self.model
        command = model.commands[act.ref]
        window = (act.a, model.link_low, model.link_high + command.latency)
        # the syncs it touches are its reply's output places', touched as they fill
        t = self._place(b, index, [window], touch=False)
        if t is None:
            return []
        b.acts.pop(index)
        reply = command.reply_transition(act.kind)
        assert reply is not None
        if not self._produce(b, reply, t, -1):
            return []
        b.record("fire", reply, act.kind, t, act.origin)
        return self._engine_step(b, "")

    def _produce(self, b: _Builder, transition: int, t: int, skip: int) -> bool:
        """Tokens of ``transition``'s outputs, stamped ``t`` (touching their syncs)."""
        syncs: set[str] = set()
        for p, w in self._outputs[transition]:
            if p in self._pending:
                continue  # a command's pending token is its timer
            if w > 1 or p in b.tokens:
                raise NotSafe(f"{self.model.net.places[p].name} would hold two tokens")
            b.tokens[p] = t
            syncs.update(self._place_syncs.get(p, ()))
        if not self._outputs[transition]:
            b.sinks.append(t)  # its time still counts towards the run's end
        return self._touch(b, frozenset(syncs), t, skip)

    # ------------------------------------------------------------------ the engine

    def _engine_step(self, b: _Builder, label: str) -> list[tuple[str, _Builder]]:
        """Fire what is enabled, each transition at the time of its latest input token
        (one branch per token that can be the latest), until nothing is enabled."""
        out: list[tuple[str, _Builder]] = []
        stack: list[tuple[str, _Builder, int]] = [(label, b, 0)]
        while stack:
            tail, builder, steps = stack.pop()
            if builder.zone is None:
                continue
            if steps > 10_000:
                raise EngineSpin("the engine can keep firing without time passing")
            enabled = [
                t for t in self._engine if all(p in builder.tokens for p, _ in self._inputs[t])
            ]
            if not enabled:  # at rest: deadlines are judged on resting markings
                out.extend((tail + more, done) for more, done in self._check_deadlines(builder))
                continue
            choices = self._choose(builder, enabled)
            for t in choices:
                inputs = [p for p, w in self._inputs[t]]
                if any(w > 1 for _, w in self._inputs[t]):
                    raise NotSafe(f"{self.model.net.transitions[t].name} takes two tokens")
                # One branch per input token that can be the latest (named by its place:
                # variable numbers differ between exploration and witness replays).
                latest_of: dict[int, int] = {}
                for p in sorted(inputs):
                    latest_of.setdefault(builder.tokens[p], p)
                stamps = sorted(latest_of)
                for latest in stamps or [START]:
                    branch = builder.copy() if (len(choices) > 1 or len(stamps) > 1) else builder
                    ok = all(branch.constrain(s, latest, 0) for s in stamps)
                    if not ok:
                        continue
                    consumed: set[str] = set()
                    for p in inputs:
                        del branch.tokens[p]
                        consumed.update(self._place_syncs.get(p, ()))
                    if not self._touch(branch, frozenset(consumed), latest, -1):
                        continue
                    if not self._produce(branch, t, latest, -1):
                        continue
                    if t in self.model.commands:
                        origin = latest if self.keep else -1
                        branch.acts.append(Act(UP, t, "", latest, -1, (), origin))
                        branch.record("fire", t, "", latest, origin)
                        branch.record("send", t, "", latest, origin)
                    else:
                        branch.record("fire", t, "", latest)
                    suffix = tail
                    if len(choices) > 1:
                        suffix += f" {self.model.net.transitions[t].name}"
                    if len(stamps) > 1:
                        suffix += f" last:{self.model.net.places[latest_of[latest]].name}"
                    stack.append((suffix, branch, steps + 1))
        return out

    def _choose(self, b: _Builder, enabled: list[int]) -> list[int]:
        """The enabled transitions to branch on next, as the global-clock semantics
        chooses them: with priorities, every enabled one of the highest; else those of
        a stubborn set seeded with the first (a transition that takes a token, or one
        that is not yet enabled but could take it once another fires, races with it)."""
        transitions = self.model.net.transitions
        if self._prioritised:
            top = max(transitions[t].priority for t in enabled)
            return [t for t in enabled if transitions[t].priority == top]
        members = {enabled[0]}
        todo = [enabled[0]]
        while todo:
            t = todo.pop()
            missing = [p for p, _ in self._inputs[t] if p not in b.tokens]
            if not missing:
                added = [u for p, _ in self._inputs[t] for u in self._consumers.get(p, ())]
            else:
                added = list(self._producers.get(missing[0], ()))
            for u in added:
                if u not in members:
                    members.add(u)
                    todo.append(u)
        return [t for t in enabled if t in members]

    def _check_deadlines(self, b: _Builder) -> list[tuple[str, _Builder]]:
        """Deadlines whose places are all marked in this resting marking: settled, in
        time or late (one branch each when both are possible). They were marked at the
        last event that changed one of those places (such events are ordered, so that
        one is the latest)."""
        out: list[tuple[str, _Builder]] = [("", b)]
        for deadline in self.model.deadlines:
            if deadline.index in b.settled:
                continue
            if not all(p in b.tokens for p, _ in deadline.places):
                continue
            t = b.syncs.get(f"d:{deadline.index}", START)
            split: list[tuple[str, _Builder]] = []
            for tail, builder in out:
                builder.settled.add(deadline.index)
                late = builder.copy()
                if late.constrain(START, t, -(deadline.deadline + 1)):
                    late.record("miss", deadline.index, "", t)
                    split.append((f"{tail} late{deadline.index}", late))
                if builder.constrain(t, START, deadline.deadline):
                    assert builder.zone is not None
                    reached = builder.zone.bound(t, START)
                    builder.record("reach", deadline.index, "", t, value=reached)
                    split.append((tail, builder))
            out = split
        return out

    # ------------------------------------------------------------------ normal form

    def _finish(self, b: _Builder) -> EventState:
        acts = sorted(b.acts, key=lambda a: (a.phase, a.ref, a.kind))
        # What no running timer can touch any more is forgotten: a resource's holder and
        # a sync's last time matter only to later events on them.
        wanted: set[str] = {f"d:{d.index}" for d in self.model.deadlines}
        wanted.difference_update(f"d:{i}" for i in b.settled)
        for a in acts:
            wanted.update(self._footprints[(a.ref, a.phase)])
        holders = sorted(
            (h for h in b.holders if f"r:{h.resource}" in wanted),
            key=lambda h: (h.resource, h.ref),
        )
        tokens = sorted(b.tokens.items())
        syncs = sorted((k, v) for k, v in b.syncs.items() if k in wanted)
        assert b.zone is not None
        if self.keep or not isinstance(b.zone, Zone):
            return EventState(
                tuple(tokens),
                tuple(acts),
                tuple(holders),
                tuple(syncs),
                tuple(b.sinks),
                frozenset(b.settled),
                b.zone,
            )
        renumber = Renumbering([START])
        self.last_raw = (b.zone, renumber.order)
        new_tokens = tuple((p, renumber.use(v)) for p, v in tokens)
        new_acts = tuple(renumber.act(a) for a in acts)
        new_holders = tuple(renumber.holder(h) for h in holders)
        new_syncs = tuple((s, renumber.use(v)) for s, v in syncs)
        new_sinks = tuple(sorted(renumber.use(v) for v in b.sinks))
        return EventState(
            new_tokens,
            new_acts,
            new_holders,
            new_syncs,
            new_sinks,
            frozenset(b.settled),
            b.zone.keep(renumber.order),
        )
