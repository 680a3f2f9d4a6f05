"""The CORAL Engine: the paper's synchronous loop over a verified net.

The engine owns the marking. It reacts to one input at a time (the start of the mission,
or one reply from the vehicle): it updates the marking, then, while an engine transition
(plain or command) is enabled, chooses one by the policy, fires it and collects the
commands it emits. Reply transitions are the vehicle's: they fire only when the vehicle's
reply for that command arrives. Input transitions are the operator's: they fire only when
the operator gives that input (`Engine.give`), and never keep a run going by themselves.

The operator may also `Engine.pause` the engine: it then fires none of its own
transitions (so it sends no new command), while replies still fire their reply
transitions; `Engine.resume` runs to quiescence from where it stands.

A step costs what it touches, not the size of the net: after a firing only the
transitions that consume from a place whose count changed are re-checked, and the
enabled ones wait in a heap ordered by the policy (priority, then source order).

The engine is pure: no sockets, no clock, no log. Times are passed in; the controller
(`runtime.controller`) does the I/O and writes the event log, and `snapshot` /
`Engine.restore` carry the state across a crash.

Only a verified net runs: the constructor takes the `CertificateCheck` that
`analysis.certificate.check_certificate` returns for this very net, and refuses any other.
"""

from __future__ import annotations

import enum
import heapq
import random
import shlex
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple

from analysis.certificate import CertificateCheck
from coral_lang.diagnostics import CoralError
from coral_lang.net import Command, Net, TransitionKind
from coral_lang.profile import TIME_OUT
from runtime.policy import Policy

__all__ = [
    "CommandStatus",
    "Engine",
    "EngineError",
    "EngineSpin",
    "Firing",
    "OperatorRefused",
    "Outcome",
    "Policy",
    "SentCommand",
    "StepResult",
    "UnexpectedReply",
    "find_cycle",
]

DEFAULT_MAX_FIRINGS_PER_STEP = 1_000_000

SPIN_WINDOW = 4096
"""How many of the last firings a spin's cycle is looked for in (`find_cycle`)."""
SPIN_PREFIX = 100
"""At most this many firings of the spinning step before its cycle are kept (`EngineSpin`)."""
_SPIN_SHOWN = 12  # transitions of a cycle named in the message; a longer one is cut


class EngineError(CoralError, RuntimeError):
    """The engine cannot go on: no passing certificate, a bad snapshot, a spin."""


class OperatorRefused(EngineError):
    """An operator action the engine does not take: an input the mission does not declare,
    one already given, a run that has ended, a pause while paused. The message says which
    and is what the operator sees; the engine is unchanged."""


class Outcome(enum.Enum):
    """Where the mission stands after a step."""

    RUNNING = "running"  # commands in flight: waiting for the vehicle
    FINAL = "final"  # nothing enabled, nothing in flight, a declared final marking
    DEADLOCK = "deadlock"  # nothing enabled, nothing in flight, not a final marking


class SentCommand(NamedTuple):
    """A command the engine wants sent: ``command_id`` is unique within the mission.

    (Named tuples, not dataclasses, for the records made on every step: they are built
    several times per message and cost a third as much.)"""

    command_id: int
    transition: str
    command: Command
    sent_at: float
    timeout_at: float | None


class Firing(NamedTuple):
    """One transition fired, with the time of the step that fired it."""

    transition: str
    time: float
    command_id: int | None = None  # the command sent, or the one answered (reply)


class EngineSpin(EngineError):
    """A step fired more than ``max_firings_per_step`` engine transitions without waiting
    for the vehicle: a cycle of engine transitions (a livelock) that the mission cannot
    leave. The mission has failed; the controller ends the run as ``spin``.

    The engine is left in the middle of that step: do not use it further (its last
    snapshot before the step is the state to restore, if any).

    Attributes:
        cycle: the transitions of the repeating cycle, in firing order, starting with the
            first one fired when the step entered it (the first is not repeated at the end).
        sources: ``file:line`` of each transition of ``cycle`` ("" where unknown).
        prefix: the step's firings before it entered the cycle (the reply transition that
            began the step first, if any); the first `SPIN_PREFIX` of them.
        marking: the marking when the engine gave up.
        limit: the firing limit that was passed.
        irregular: the tail of the step is not periodic (random choices, or a cycle longer
            than `SPIN_WINDOW`): ``cycle`` is then only the stretch between the last two
            firings of the last transition fired.
    """

    def __init__(
        self,
        *,
        cycle: tuple[str, ...],
        sources: tuple[str, ...],
        prefix: tuple[Firing, ...],
        marking: dict[str, int],
        limit: int,
        irregular: bool = False,
    ) -> None:
        self.cycle = cycle
        self.sources = sources
        self.prefix = prefix
        self.marking = marking
        self.limit = limit
        self.irregular = irregular
        super().__init__(
            f"engine spin: more than {limit} firings without waiting for the vehicle; "
            f"{'irregular ' if irregular else ''}cycle {self.describe()}"
        )

    def describe(self) -> str:
        """The cycle as ``ping (m.coral:14) -> pong (m.coral:18) -> ping``."""
        if not self.cycle:
            return "(none found)"
        steps = [
            f"{name} ({where})" if where else name
            for name, where in zip(self.cycle, self.sources, strict=True)
        ]
        if len(steps) > _SPIN_SHOWN:
            cut = len(steps) - (_SPIN_SHOWN - 1)
            steps = [*steps[: _SPIN_SHOWN - 1], f"... ({cut} more)"]
        return " -> ".join([*steps, self.cycle[0]])

    def to_json(self) -> dict[str, object]:
        """The spin as JSON-ready data (the controller's ``engine-spin`` event)."""
        return {
            "cycle": list(self.cycle),
            "sources": list(self.sources),
            "marking": dict(self.marking),
            "limit": self.limit,
            "irregular": self.irregular,
            "message": str(self),
        }


def find_cycle(fired: Sequence[str], window: int = SPIN_WINDOW) -> tuple[int, int, bool]:
    """Where the repeating cycle at the end of ``fired`` starts, and its length.

    Looks at the last ``window`` names for the longest stretch at the end that repeats one
    period at least twice. If it covers at least half of them, the cycle is that shortest
    period, starting where the periodic stretch begins (followed back through all of
    ``fired``: after the firings that led into the cycle). Otherwise (``irregular``: random
    choices, or a cycle too long for the window) the cycle is the stretch from the
    previous firing of the last name to the end. Costs O(window), plus O(len(fired)) to
    find where a cycle longer than the window began: once, when the engine gives up.

    Returns:
        ``(start, length, irregular)``; ``fired[start:start + length]`` is the cycle;
        length 0 when no name repeats in the window.
    """
    n = len(fired)
    w = min(n, window)
    if w < 2:
        return n, 0, True
    back = list(reversed(fired[n - w :]))  # back[0] is the last firing
    # The prefix function (Knuth-Morris-Pratt): border[i] is the length of the longest
    # proper prefix of back[:i + 1] that is also its suffix, so back[:i + 1] has the
    # period i + 1 - border[i].
    border = [0] * w
    k = 0
    for i in range(1, w):
        while k and back[i] != back[k]:
            k = border[k - 1]
        if back[i] == back[k]:
            k += 1
        border[i] = k
    for length in range(w, 1, -1):
        period = length - border[length - 1]
        if 2 * period <= length:
            break
    else:
        length, period = 0, 0
    if period and 2 * length >= w:
        start = n - length
        while start > 0 and fired[start - 1] == fired[start - 1 + period]:
            start -= 1
        return start, period, False
    last = fired[-1]
    for i in range(n - 2, n - w - 1, -1):
        if fired[i] == last:
            return i, n - 1 - i, True
    return n, 0, True


@dataclass(frozen=True)
class UnexpectedReply:
    """A reply the net cannot take: unknown command id, command already answered, or a
    reply kind the net has no transition for. The marking is left as it was."""

    command_id: int
    kind: str
    reason: str


class StepResult(NamedTuple):
    """What one step did: the firings in order, the commands to send, and the outcome."""

    firings: tuple[Firing, ...]
    commands: tuple[SentCommand, ...]
    outcome: Outcome
    unexpected: UnexpectedReply | None = None


@dataclass(frozen=True)
class CommandStatus:
    """A command in flight, for the operator's status display."""

    command_id: int
    transition: str
    header: str
    sent_at: float
    awaiting: tuple[str, ...]
    timeout_at: float | None

    def line(self, now: float) -> str:
        """E.g. ``#7 check_depth ROMEO(DEPTH?, ...) sent 3.2 s ago, awaiting done|timeout,
        time-out in 56.8 s``."""
        text = (
            f"#{self.command_id} {self.transition} {self.header} sent "
            f"{max(0.0, now - self.sent_at):.1f} s ago, awaiting {'|'.join(self.awaiting)}"
        )
        if self.timeout_at is not None:
            left = self.timeout_at - now
            text += (
                f", time-out in {left:.1f} s"
                if left >= 0
                else f", time-out passed {-left:.1f} s ago (reply not yet here)"
            )
        return text


class _InFlight(NamedTuple):
    command_id: int
    transition: int
    sent_at: float
    timeout_at: float | None


@dataclass
class _Compiled:
    """Index arrays of the net, built once."""

    names: list[str]
    inputs: list[tuple[tuple[int, int], ...]]
    outputs: list[tuple[tuple[int, int], ...]]
    gains: list[tuple[int, ...]]  # places a firing adds tokens to (net effect)
    engine_consumers: list[tuple[int, ...]]  # per place: engine transitions reading it
    is_engine: list[bool]
    priority: list[int]
    timeout: list[float | None]  # a command's time_out parameter, if it has one
    command: list[Command | None]
    reply_of: dict[tuple[int, str], int] = field(default_factory=dict)
    input_of: dict[str, int] = field(default_factory=dict)  # operator input -> transition


def _compile(net: Net) -> _Compiled:
    pindex = {p.name: i for i, p in enumerate(net.places)}
    tindex = {t.name: i for i, t in enumerate(net.transitions)}
    consumers: list[list[int]] = [[] for _ in net.places]
    inputs, outputs, gains, is_engine, priority = [], [], [], [], []
    timeouts: list[float | None] = []
    reply_of: dict[tuple[int, str], int] = {}
    input_of: dict[str, int] = {}
    for i, tr in enumerate(net.transitions):
        ins = tuple((pindex[p], w) for p, w in tr.inputs)
        outs = tuple((pindex[p], w) for p, w in tr.outputs)
        delta: dict[int, int] = {}
        for p, w in ins:
            delta[p] = delta.get(p, 0) - w
        for p, w in outs:
            delta[p] = delta.get(p, 0) + w
        inputs.append(ins)
        outputs.append(outs)
        gains.append(tuple(p for p, d in delta.items() if d > 0))
        # Reply transitions are the vehicle's and input transitions the operator's: the
        # engine never chooses them, so they are not in its heap.
        engine = tr.kind not in (TransitionKind.REPLY, TransitionKind.INPUT)
        is_engine.append(engine)
        priority.append(tr.priority)
        limit = dict(tr.command.params).get(TIME_OUT) if tr.command is not None else None
        timeouts.append(float(limit) if isinstance(limit, int | float) else None)
        if engine:
            for p, _ in ins:
                consumers[p].append(i)
        elif tr.kind is TransitionKind.INPUT:
            if tr.operator_input is not None:
                input_of[tr.operator_input] = i
        elif tr.reply_to is not None and tr.reply is not None:
            reply_of[(tindex[tr.reply_to], tr.reply)] = i
    return _Compiled(
        names=[t.name for t in net.transitions],
        inputs=inputs,
        outputs=outputs,
        gains=gains,
        engine_consumers=[tuple(sorted(set(c))) for c in consumers],
        is_engine=is_engine,
        priority=priority,
        timeout=timeouts,
        command=[t.command for t in net.transitions],
        reply_of=reply_of,
        input_of=input_of,
    )


class Engine:
    """Runs one verified net: `start`, then `on_reply` for each reply from the vehicle.

    Args:
        net: the compiled mission.
        approval: what `check_certificate(net, path)` returned for this net.
        policy: how to choose among enabled transitions.
        seed: the seed of the generator `Policy.RANDOM` uses.
        max_firings_per_step: a bound on the firings of one step, so a cycle of engine
            transitions that never waits for the vehicle is reported (`EngineSpin`, from
            `start` or `on_reply`), not run forever.

    Raises:
        EngineError: the approval is for another net (its digest differs).
    """

    def __init__(
        self,
        net: Net,
        approval: CertificateCheck,
        *,
        policy: Policy = Policy.PRIORITY,
        seed: int = 0,
        max_firings_per_step: int = DEFAULT_MAX_FIRINGS_PER_STEP,
    ) -> None:
        if not isinstance(approval, CertificateCheck):
            raise EngineError(
                "the engine runs only verified nets: pass the result of "
                "analysis.certificate.check_certificate(net, CERTIFICATE)"
            )
        digest = net.digest()
        if approval.net_digest != digest:
            mission = "MISSION" if approval.mission is None else shlex.quote(approval.mission)
            raise EngineError(
                f"certificate {approval.path} was issued for net {approval.net_digest}, not "
                f"for this one ({digest}); run 'coral-check verify {mission} --certificate "
                f"{shlex.quote(approval.path)}' on the mission as it is now"
            )
        self.net = net
        self.digest = digest
        self.policy = policy
        self._random = random.Random(seed)
        self._max_firings = max_firings_per_step
        self._c = _compile(net)
        self.marking: list[int] = list(net.initial_marking())
        self._finals = net.final_test()
        self._in_flight: dict[int, _InFlight] = {}
        self._next_command_id = 1
        self.firings = 0
        self.checks = 0
        """Enabling checks done so far: the engine's unit of work (tests, benchmarks)."""
        self.started = False
        self.paused = False
        """Paused by the operator: the engine fires none of its own transitions."""
        self._heap: list[tuple[int, int]] = []
        self._queued: list[bool] = []
        self._requeue_all()

    # ------------------------------------------------------------------ state

    @property
    def next_command_id(self) -> int:
        """The id the next command will get."""
        return self._next_command_id

    def in_flight(self) -> list[SentCommand]:
        """Commands sent and not yet answered, oldest first."""
        return [self._sent(f) for f in sorted(self._in_flight.values(), key=_by_id)]

    def status(self) -> list[CommandStatus]:
        """One status entry per command in flight, oldest first."""
        result = []
        for flight in sorted(self._in_flight.values(), key=_by_id):
            tr = self.net.transitions[flight.transition]
            assert tr.command is not None
            result.append(
                CommandStatus(
                    command_id=flight.command_id,
                    transition=tr.name,
                    header=tr.command.header(),
                    sent_at=flight.sent_at,
                    awaiting=tr.command.replies,
                    timeout_at=flight.timeout_at,
                )
            )
        return result

    def marking_dict(self) -> dict[str, int]:
        """The marked places, ``{name: tokens}``."""
        return self.net.marking_dict(self.marking)

    def outcome(self) -> Outcome:
        """Running while an engine transition is enabled (also while paused) or a command
        is in flight; then final or deadlock. Operator inputs not given keep no run going
        (`Net.runs_on`)."""
        if self._in_flight or self._peek() is not None:
            return Outcome.RUNNING
        return Outcome.FINAL if self._finals.matches(self.marking) else Outcome.DEADLOCK

    def snapshot(self) -> dict[str, object]:
        """The engine's state as JSON-ready data; `restore` rebuilds the engine from it."""
        return {
            "net_digest": self.digest,
            "marking": self.marking_dict(),
            "in_flight": [
                [f.command_id, self._c.names[f.transition], f.sent_at, f.timeout_at]
                for f in sorted(self._in_flight.values(), key=_by_id)
            ],
            "next_command_id": self._next_command_id,
            "firings": self.firings,
            "started": self.started,
            # Only when paused, so states written before pauses existed read the same.
            **({"paused": True} if self.paused else {}),
        }

    @classmethod
    def restore(
        cls,
        net: Net,
        approval: CertificateCheck,
        state: Mapping[str, object],
        *,
        policy: Policy = Policy.PRIORITY,
        seed: int = 0,
    ) -> Engine:
        """The engine as `snapshot` left it (after a crash, from the event log).

        A paused engine stays paused: the snapshot records the operator's hold (the
        controller commits it when the pause is taken), so a controller restarted after
        a crash or a stop never sends the next command of a mission its operator held;
        the operator resumes it (``coral-run operate ... resume``).

        Raises:
            EngineError: the snapshot is of another net, or does not fit this one.
        """
        engine = cls(net, approval, policy=policy, seed=seed)
        if state.get("net_digest") != engine.digest:
            raise EngineError(
                f"the saved state is of net {state.get('net_digest')}, not of this one "
                f"({engine.digest}): resume with the mission that was running"
            )
        try:
            marking = state["marking"]
            assert isinstance(marking, Mapping)
            engine.marking = list(net.marking_from({str(k): int(v) for k, v in marking.items()}))
            flights = state["in_flight"]
            assert isinstance(flights, list)
            for command_id, name, sent_at, timeout_at in flights:
                index = net.transition_index(str(name))
                engine._in_flight[int(command_id)] = _InFlight(
                    int(command_id),
                    index,
                    float(sent_at),
                    None if timeout_at is None else float(timeout_at),
                )
            next_id = state["next_command_id"]
            firings = state["firings"]
            assert isinstance(next_id, int) and isinstance(firings, int)
            engine._next_command_id = next_id
            engine.firings = firings
            engine.started = bool(state.get("started", True))
            engine.paused = state.get("paused") is True
        except (KeyError, AssertionError, TypeError, ValueError) as exc:
            raise EngineError(f"the saved engine state is damaged ({exc!r})") from None
        problem = engine._inconsistency()
        if problem is not None:
            raise EngineError(
                f"the saved engine state cannot be a state of this mission: {problem}; "
                "the log was damaged or edited: do not resume from it"
            )
        engine._requeue_all()
        return engine

    def _inconsistency(self) -> str | None:
        """Why a restored state cannot have come from running this net, or None.

        Cheap checks that any state the engine itself committed passes: token counts are
        not negative; every command in flight is a command transition's, with its token
        in that transition's pending place (one token per command in flight); command
        ids are positive, distinct and below the next id to hand out (ids only grow, so a
        new command never reuses one the vehicle has run).
        """
        net = self.net
        if any(tokens < 0 for tokens in self.marking):
            return "a negative token count"
        if self.firings < 0:
            return "a negative firing count"
        flying: dict[str, int] = {}
        for command_id, flight in self._in_flight.items():
            transition = net.transitions[flight.transition]
            if transition.command is None:
                return f"command #{command_id} in flight for '{transition.name}', which sends none"
            if not 0 < command_id < self._next_command_id:
                return (
                    f"command #{command_id} in flight, but the next command id is "
                    f"{self._next_command_id} (ids only grow)"
                )
            flying[transition.name] = flying.get(transition.name, 0) + 1
        for index, place in enumerate(net.places):
            if place.pending_of is not None and self.marking[index] != flying.get(
                place.pending_of, 0
            ):
                return (
                    f"place '{place.name}' holds {self.marking[index]} token(s) but "
                    f"{flying.get(place.pending_of, 0)} command(s) of '{place.pending_of}' "
                    "are in flight"
                )
        return None

    # ------------------------------------------------------------------ steps

    def start(self, now: float) -> StepResult:
        """Run the engine transitions enabled in the initial marking to quiescence.

        Raises:
            EngineError: called twice.
            EngineSpin: more than ``max_firings_per_step`` firings: a cycle.
        """
        if self.started:
            raise EngineError("the mission was already started")
        self.started = True
        return self._run(now, [])

    def on_reply(self, command_id: int, kind: str, now: float) -> StepResult:
        """The vehicle answered ``command_id`` with ``kind``: fire that reply transition,
        then every engine transition it enables, to quiescence.

        A reply the net cannot take changes nothing and comes back as ``unexpected``.

        Raises:
            EngineSpin: more than ``max_firings_per_step`` firings: a cycle.
        """
        flight = self._in_flight.get(command_id)
        if flight is None:
            return self._unexpected(command_id, kind, "no command with this id is in flight")
        reply = self._c.reply_of.get((flight.transition, kind))
        if reply is None:
            tr = self.net.transitions[flight.transition]
            return self._unexpected(
                command_id,
                kind,
                f"{tr.name} has no reply '{kind}' (expected "
                f"{'|'.join(tr.command.replies if tr.command else ())})",
            )
        if not self._enabled(reply):  # the pending token is gone: a damaged state
            return self._unexpected(command_id, kind, "the reply's pending place is empty")
        del self._in_flight[command_id]
        self._fire(reply)
        return self._run(now, [Firing(self._c.names[reply], now, command_id)])

    # ------------------------------------------------------------------ operator

    def give(self, name: str, now: float) -> StepResult:
        """The operator gives input ``name``: fire its input transition, then every engine
        transition it enables, to quiescence (like a reply).

        Offered once per run and only while the run goes on (`outcome` is RUNNING): an
        input does not revive a run that has ended. Giving an input while paused resumes
        the engine first (``paused`` becomes False): an operator who aborts wants the
        abort path to run, not to wait for a resume that may never come.

        Raises:
            OperatorRefused: the mission declares no such input, it was already given,
                the mission has not started or the run has ended; nothing changed.
            EngineSpin: more than ``max_firings_per_step`` firings: a cycle.
        """
        index = self._c.input_of.get(name)
        if index is None:
            declared = ", ".join(sorted(self._c.input_of))
            raise OperatorRefused(
                f"the mission declares no input '{name}'"
                + (f" (its inputs: {declared})" if declared else " (it declares no inputs)")
            )
        if not self.started:
            raise OperatorRefused(f"input '{name}' refused: the mission has not started")
        outcome = self.outcome()
        if outcome is not Outcome.RUNNING:
            raise OperatorRefused(f"input '{name}' refused: the run has ended ({outcome.value})")
        if not self._enabled(index):
            raise OperatorRefused(f"input '{name}' was already given (once per run)")
        self.paused = False
        self._fire(index)
        return self._run(now, [Firing(self._c.names[index], now)])

    def pause(self) -> None:
        """Hold the engine: from now on it fires none of its own transitions, so it sends
        no new command; replies still fire their reply transitions (`on_reply`).

        Raises:
            OperatorRefused: already paused, not started, or the run has ended.
        """
        if self.paused:
            raise OperatorRefused("already paused")
        if not self.started:
            raise OperatorRefused("pause refused: the mission has not started")
        outcome = self.outcome()
        if outcome is not Outcome.RUNNING:
            raise OperatorRefused(f"pause refused: the run has ended ({outcome.value})")
        self.paused = True

    def resume(self, now: float) -> StepResult:
        """Release a pause: run every engine transition enabled now to quiescence.

        Raises:
            OperatorRefused: not paused, or the run ended while paused (a reply left
                nothing to do): there is nothing to resume.
            EngineSpin: more than ``max_firings_per_step`` firings: a cycle.
        """
        if not self.paused:
            raise OperatorRefused("not paused")
        outcome = self.outcome()
        if outcome is not Outcome.RUNNING:
            raise OperatorRefused(f"resume refused: the run has ended ({outcome.value})")
        self.paused = False
        return self._run(now, [])

    def _unexpected(self, command_id: int, kind: str, reason: str) -> StepResult:
        return StepResult((), (), self.outcome(), UnexpectedReply(command_id, kind, reason))

    def _run(self, now: float, firings: list[Firing]) -> StepResult:
        commands: list[SentCommand] = []
        if self.paused:  # the operator holds the engine: the step ends with its input
            return StepResult(tuple(firings), (), self.outcome())
        names, command_of = self._c.names, self._c.command
        choose, fire, limit = self._choose, self._fire, self._max_firings
        count = 0
        while (chosen := choose()) is not None:
            count += 1
            if count > limit:
                raise self._spin(firings, limit, chosen)
            fire(chosen)
            command = command_of[chosen]
            if command is None:
                firings.append(Firing(names[chosen], now))
            else:
                sent = self._send(chosen, command, now)
                commands.append(sent)
                firings.append(Firing(names[chosen], now, sent.command_id))
        return StepResult(tuple(firings), tuple(commands), self.outcome())

    def _spin(self, firings: Sequence[Firing], limit: int, chosen: int) -> EngineSpin:
        """The error for a step that passed its firing limit, naming the cycle it is in."""
        self._queued[chosen] = True  # taken off the heap, not fired: still enabled
        heapq.heappush(self._heap, (-self._c.priority[chosen], chosen))
        fired = _Names(firings)
        start, length, irregular = find_cycle(fired)
        cycle = tuple(fired[start : start + length])
        sources = []
        for name in cycle:
            span = self.net.transitions[self.net.transition_index(name)].span
            sources.append("" if span is None else f"{span.file}:{span.line}")
        return EngineSpin(
            cycle=cycle,
            sources=tuple(sources),
            prefix=tuple(firings[: min(start, SPIN_PREFIX)]),
            marking=self.marking_dict(),
            limit=limit,
            irregular=irregular,
        )

    def _send(self, index: int, command: Command, now: float) -> SentCommand:
        command_id = self._next_command_id
        self._next_command_id += 1
        timeout = self._c.timeout[index]
        timeout_at = None if timeout is None else now + timeout
        flight = _InFlight(command_id, index, now, timeout_at)
        self._in_flight[command_id] = flight
        return self._sent(flight)

    def _sent(self, flight: _InFlight) -> SentCommand:
        tr = self.net.transitions[flight.transition]
        assert tr.command is not None
        return SentCommand(
            flight.command_id, tr.name, tr.command, flight.sent_at, flight.timeout_at
        )

    # ------------------------------------------------------------------ firing rule

    def _enabled(self, t: int) -> bool:
        self.checks += 1
        m = self.marking
        for p, w in self._c.inputs[t]:  # noqa: SIM110 (a loop: twice as fast as all())
            if m[p] < w:
                return False
        return True

    def _fire(self, t: int) -> None:
        c, m = self._c, self.marking
        for p, w in c.inputs[t]:
            m[p] -= w
        for p, w in c.outputs[t]:
            m[p] += w
        self.firings += 1
        # Only a place that gained tokens can enable a transition; one that lost tokens
        # can only disable some, and those leave the heap lazily (`_peek`). This is
        # `_consider` inlined: it runs for every firing.
        queued, inputs, consumers = self._queued, c.inputs, c.engine_consumers
        for p in c.gains[t]:
            for u in consumers[p]:
                if queued[u]:
                    continue
                self.checks += 1
                for q, w in inputs[u]:
                    if m[q] < w:
                        break
                else:
                    queued[u] = True
                    heapq.heappush(self._heap, (-c.priority[u], u))

    def _requeue_all(self) -> None:
        """Rebuild the heap from scratch (construction and restore: O(net))."""
        self._heap = []
        self._queued = [False] * len(self._c.names)
        for t, engine in enumerate(self._c.is_engine):
            if engine:
                self._consider(t)

    def _consider(self, t: int) -> None:
        """Queue ``t`` if it is an enabled engine transition not queued yet."""
        if not self._queued[t] and self._enabled(t):
            self._queued[t] = True
            heapq.heappush(self._heap, (-self._c.priority[t], t))

    def _peek(self) -> int | None:
        """The first enabled transition in policy order; stale heap entries dropped."""
        heap = self._heap
        while heap:
            t = heap[0][1]
            if self._enabled(t):
                return t
            heapq.heappop(heap)
            self._queued[t] = False
        return None

    def _choose(self) -> int | None:
        """The transition to fire next, taken off the heap; None when nothing is enabled."""
        if self.policy is Policy.RANDOM:
            return None if self._peek() is None else self._choose_random()
        heap, queued, m, inputs = self._heap, self._queued, self.marking, self._c.inputs
        while heap:
            _, t = heapq.heappop(heap)
            queued[t] = False
            self.checks += 1
            for p, w in inputs[t]:
                if m[p] < w:
                    break
            else:
                return t
        return None

    def _choose_random(self) -> int:
        """Uniform among the enabled transitions of the top priority (O(enabled): tests)."""
        top = self._heap[0][0]
        entries = [e for e in self._heap if e[0] == top and self._enabled(e[1])]
        _, chosen = entries[self._random.randrange(len(entries))]
        self._heap.remove((top, chosen))
        heapq.heapify(self._heap)
        self._queued[chosen] = False
        return chosen


def _by_id(flight: _InFlight) -> int:
    return flight.command_id


class _Names(Sequence[str]):
    """The transition names of a list of firings, without copying it (it may be long)."""

    def __init__(self, firings: Sequence[Firing]) -> None:
        self._firings = firings

    def __len__(self) -> int:
        return len(self._firings)

    def __getitem__(self, index: int | slice) -> Any:
        if isinstance(index, slice):
            return [f.transition for f in self._firings[index]]
        return self._firings[index].transition
