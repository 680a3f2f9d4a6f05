"""Put a real vehicle on the coral wire: one handler per command, the library does the rest.

An integrator knows how to make their vehicle dive or report a GPS fix; they should not
have to re-implement what every coral vehicle must do the same way. `HandlerVehicle` is a
`runtime.vehicle.model.VehicleModel` built from a profile and a handler per command::

    vehicle = HandlerVehicle(load_profile("minnow.yaml"), on_watchdog=autopilot.surface)
    vehicle.on("DIVE", start=lambda job: autopilot.set_depth(job["z"]), stop=hold_depth)
    vehicle.on("DEPTH?", poll=lambda job: "done" if abs(gauge() - job["z"]) < 0.5 else None)

and then `runtime.vehicle.server.VehicleServer` (or `runtime.vehicle.run_vehicle`) serves
it. What the library does, so that every vehicle behaves as ``docs/vehicles.md`` says:

* **Input checks.** An unknown command, a command with no handler, a missing, extra,
  mistyped, non-finite or out-of-range parameter: ``error`` with a detail, before any
  handler runs. Handlers see only parameters that passed, in the profile's units.
* **Resources.** A task (or an action) that needs a resource held by another stops the
  holder first (its ``stop`` is called *before* the new ``start``, so two handlers never
  drive one actuator at once); every pending query watching a resource of the stopped
  command replies ``timeout``, naming the replacement; a stopped action replies
  ``error`` (interrupted). A replacement that its own ``start`` then refuses leaves the
  resources free: the old task is already stopped.
* **Queries and actions** are polled every ``poll_s`` vehicle seconds until their handler
  names a reply kind. A command with a ``time_out`` parameter that can reply ``timeout``
  replies ``timeout`` when that time passes, stamped with that exact time; at that
  instant it is polled one last time first, so a handler whose answer is due at or
  before its time-out never loses to the time-out between two polls.
* **A task that works before it replies** (``on(..., ack=poll)``): it holds its
  resources from its arrival, and its ``ack`` poll is called every ``poll_s`` until it
  names the reply; replaced (or stopped by the watchdog) before that, it replies
  ``error`` (interrupted). A task without one replies when it starts.
* **The watchdog.** After ``watchdog_s`` vehicle seconds without `heard_from_controller`
  or a command (armed by the first of them), every task is stopped, every pending query
  replies ``timeout`` and every running action ``error``, and ``on_watchdog`` runs: the
  integrator's make-safe (surface, drop a weight). The controller's make-safe request
  (`HandlerVehicle.make_safe`, when the operator stops ``coral-run``) does the same at
  once.
* **Replies.** Every kind a handler gives is checked against the profile (``error`` is
  always allowed: it is the protocol's refusal); anything else becomes ``error`` with a
  detail naming the kind. A handler that raises `Refused` gets ``error`` with its reason;
  one that raises anything else gets ``error`` with the exception text, and the vehicle
  goes on (a driver fault must not take the vehicle off the wire). Replies carry the
  vehicle time they fell due at, and come out in time order.

Time is injected, never read: the server moves it with `HandlerVehicle.advance_to`, in
steps of ``poll_s``; handlers get the vehicle time in `Job.now`. A query therefore replies
at the first poll at or after the moment its handler would say so (0.1 s late at most by
default).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

from coral_lang import units
from coral_lang.diagnostics import did_you_mean
from coral_lang.profile import TIME_OUT, CommandSpec, VehicleProfile
from runtime.telemetry import TelemetryRecord
from runtime.vehicle.model import Params, Reply

__all__ = [
    "HandlerVehicle",
    "Job",
    "Outcome",
    "PollHandler",
    "Refused",
    "StartHandler",
    "StopHandler",
    "TelemetrySource",
    "VehicleEvent",
    "check_params",
]

Outcome = str | tuple[str, str] | None
"""What a start or poll handler returns: a reply kind, or (kind, detail), or None while
the work goes on (for a task's start, None means its expected kind, ``ack``)."""

_EPS = 1e-9


class Refused(Exception):
    """Raised by a handler to refuse a command: the vehicle replies ``error`` with ``detail``.

    For the vehicle's own reasons, which the profile cannot express: a leak alarm, no
    position estimate yet, a line outside the survey area. (Bad parameters never reach a
    handler: the library refuses them first.)
    """

    def __init__(self, detail: str) -> None:
        super().__init__(detail)
        self.detail = detail


@dataclass(eq=False)
class Job:
    """One command being carried out, as its handlers see it.

    Attributes:
        command_id: the vehicle-side id of the command (unique over the vehicle's life).
        name: the command's name.
        spec: the command as the profile declares it.
        params: its parameters, checked against the profile, in the profile's units
            (float parameters as float, int as int, string as str).
        started: vehicle time when the command arrived, s.
        now: vehicle time of the current call (start, poll or stop), s.
    """

    command_id: int
    name: str
    spec: CommandSpec
    params: Mapping[str, float | int | str]
    started: float
    now: float

    def __getitem__(self, name: str) -> float:
        """The numeric parameter ``name`` as a float (``job["z"]``).

        Raises:
            KeyError: the command has no such parameter.
            TypeError: it is a string parameter (use `text`).
        """
        value = self.params[name]
        if isinstance(value, str):
            raise TypeError(f"parameter {name!r} of {self.name} is text; use job.text({name!r})")
        return float(value)

    def text(self, name: str) -> str:
        """The string parameter ``name``."""
        value = self.params[name]
        if not isinstance(value, str):
            raise TypeError(f"parameter {name!r} of {self.name} is a number; use job[{name!r}]")
        return value

    @property
    def elapsed(self) -> float:
        """Vehicle seconds since the command arrived."""
        return self.now - self.started


StartHandler = Callable[[Job], Outcome]
"""Called once when the command arrives (after the parameter checks and resource
stops); raise `Refused` to refuse it."""
PollHandler = Callable[[Job], Outcome]
"""Called every ``poll_s`` vehicle seconds while a query or action runs."""
StopHandler = Callable[[Job], None]
"""Called when the vehicle ends a command its handler had not finished itself: a task
replaced or stopped by the watchdog, a query timed out or orphaned, an action
interrupted."""
TelemetrySource = Callable[[float], TelemetryRecord | None]
"""Given the vehicle time, the state to send as telemetry (None: nothing to send)."""


@dataclass(frozen=True)
class VehicleEvent:
    """Something the vehicle did on its own account (the watchdog, a handler fault)."""

    time: float
    text: str


@dataclass(frozen=True)
class _Handlers:
    start: StartHandler | None
    poll: PollHandler | None
    stop: StopHandler | None


@dataclass(eq=False)
class _Running:
    """A command that has not finished: a task holding resources, a pending query or action."""

    job: Job
    handlers: _Handlers
    deadline: float | None = None
    time_out: str = ""
    holds: tuple[str, ...] = field(default=())
    replied: bool = False  # a task: its one reply is out (it may still hold resources)

    @property
    def polled(self) -> bool:
        """Still waiting for a poll to name its reply."""
        return self.handlers.poll is not None and not self.replied

    @property
    def kind(self) -> str:
        return self.job.spec.kind


def check_params(spec: CommandSpec, params: Params) -> dict[str, float | int | str]:
    """``params`` checked against ``spec``: every parameter present, typed, finite, in range,
    and no other. Float parameters come back as float (a whole number on the wire is a
    valid float), int as int, string as str; units are the profile's, unchanged.

    Raises:
        Refused: the first problem found, worded for the operator.
    """
    if not isinstance(params, Mapping):
        raise Refused(f"parameters must be a mapping, got {type(params).__name__}")
    known = {p.name for p in spec.params}
    extra = sorted(str(k) for k in params if k not in known)
    if extra:
        raise Refused(
            f"{spec.name} takes no parameter {', '.join(repr(e) for e in extra)} "
            f"(signature: {spec.signature()})"
        )
    values: dict[str, float | int | str] = {}
    for p in spec.params:
        if p.name not in params:
            raise Refused(f"{spec.name} needs parameter '{p.name}' (signature: {spec.signature()})")
        raw = params[p.name]
        if p.type == "string":
            if not isinstance(raw, str):
                raise Refused(f"parameter '{p.name}' of {spec.name} must be text, got {raw!r}")
            values[p.name] = raw
            continue
        if isinstance(raw, bool) or not isinstance(raw, int | float):
            raise Refused(f"parameter '{p.name}' of {spec.name} must be a number, got {raw!r}")
        if p.type == "int" and not isinstance(raw, int):
            raise Refused(
                f"parameter '{p.name}' of {spec.name} must be a whole number, got {raw!r}"
            )
        if not math.isfinite(raw):
            raise Refused(f"parameter '{p.name}' of {spec.name} must be finite, got {raw!r}")
        if (p.minimum is not None and raw < p.minimum) or (
            p.maximum is not None and raw > p.maximum
        ):
            raise Refused(
                f"{spec.name}: parameter {p.name} = {raw:g} is out of range ({p.describe()})"
            )
        values[p.name] = raw if p.type == "int" else float(raw)
    return values


class HandlerVehicle:
    """A `VehicleModel` made of a profile and one handler per command (module docstring).

    Args:
        profile: the vehicle's profile; the commands, parameters, reply kinds and
            resources it declares are the only ones the vehicle accepts.
        watchdog_s: vehicle seconds without a word from the controller before the
            vehicle makes itself safe.
        poll_s: vehicle seconds between two polls of a running query or action.
        on_watchdog: the make-safe, called once each time the watchdog trips or the
            controller asks for it (`make_safe`), after every command was stopped.
        telemetry: given the vehicle time, the state to send as telemetry; None (or a
            source returning None) sends none.
        start_time: the vehicle clock at construction, s.

    Raises:
        ValueError: ``watchdog_s``, ``poll_s`` not positive finite numbers, or
            ``start_time`` not finite.
    """

    def __init__(
        self,
        profile: VehicleProfile,
        *,
        watchdog_s: float = 30.0,
        poll_s: float = 0.1,
        on_watchdog: Callable[[], None] | None = None,
        telemetry: TelemetrySource | None = None,
        start_time: float = 0.0,
    ) -> None:
        for what, value in (("watchdog_s", watchdog_s), ("poll_s", poll_s)):
            if not math.isfinite(value) or value <= 0.0:
                raise ValueError(f"{what} must be a positive finite number, got {value!r}")
        if not math.isfinite(start_time):
            raise ValueError(f"start_time must be finite, got {start_time!r}")
        self._profile = profile
        self._watchdog_s = float(watchdog_s)
        self._poll_s = float(poll_s)
        self._on_watchdog = on_watchdog
        self._telemetry = telemetry
        self._start = float(start_time)
        self._clock = float(start_time)
        self._ticks = 0  # poll instants start + k * poll_s done, k = 1.._ticks
        self._handlers: dict[str, _Handlers] = {}
        self._running: list[_Running] = []  # in arrival order
        self._owners: dict[str, _Running] = {}
        self._seen: set[int] = set()
        self._outbox: list[Reply] = []
        self._events: list[VehicleEvent] = []
        self._armed = False
        self._last_heard = self._clock
        self._tripped = False
        self._telemetry_failed = False

    # ------------------------------------------------------------------ set-up

    @property
    def profile(self) -> VehicleProfile:
        """The profile the vehicle answers to."""
        return self._profile

    def on(
        self,
        name: str,
        *,
        start: StartHandler | None = None,
        poll: PollHandler | None = None,
        stop: StopHandler | None = None,
        ack: PollHandler | None = None,
    ) -> None:
        """Register the handlers of command ``name``.

        * A **task** takes ``start`` (None: accept at once) and ``stop``; it replies once,
          when it starts (``start`` returning None replies its first kind, ``ack``), then
          holds its resources until another command takes them or the watchdog trips.
          Given ``ack``, a task whose ``start`` returns None replies later: when ``ack``,
          polled every ``poll_s``, names a kind (a vehicle that acknowledges a manoeuvre
          only once it is under way); it holds its resources from its arrival.
        * A **query** or an **action** takes ``poll`` (and optionally ``start`` and
          ``stop``): it replies when ``start`` or a ``poll`` names a kind.

        Raises:
            ValueError: the profile has no such command, it already has handlers, a task
                was given a ``poll`` (or a query or action an ``ack``), or a query or
                action was given neither ``start`` nor ``poll`` (nothing would ever make
                it reply).
        """
        spec = self._profile.command(name)
        if spec is None:
            names = self._profile.command_names
            raise ValueError(
                f"{self._profile.name}'s profile has no command {name!r}"
                f"{did_you_mean(name, names)}; it has {', '.join(names)}"
            )
        if name in self._handlers:
            raise ValueError(f"command {name!r} already has handlers")
        for what, fn in (("start", start), ("poll", poll), ("stop", stop), ("ack", ack)):
            if fn is not None and not callable(fn):
                raise ValueError(f"{what} of {name!r} must be callable, got {fn!r}")
        if spec.kind == "task" and poll is not None:
            raise ValueError(
                f"{name} is a task: it replies once, when it starts, and then holds "
                f"{', '.join(spec.resources) or 'no resource'} until replaced; give it "
                "start and stop, not poll"
            )
        if spec.kind != "task" and ack is not None:
            raise ValueError(f"{name} is a {spec.kind}: ack is for tasks; give it a poll")
        if spec.kind != "task" and start is None and poll is None:
            raise ValueError(
                f"{name} is {'an' if spec.kind == 'action' else 'a'} {spec.kind}: give it a "
                "poll (or a start that returns its reply kind), or nothing will ever answer it"
            )
        self._handlers[name] = _Handlers(start, poll if spec.kind != "task" else ack, stop)

    @property
    def unhandled(self) -> tuple[str, ...]:
        """Commands of the profile with no handler (they reply ``error``), profile order."""
        return tuple(n for n in self._profile.command_names if n not in self._handlers)

    # ------------------------------------------------------------------ VehicleModel

    @property
    def time(self) -> float:
        """The vehicle clock, s."""
        return self._clock

    @property
    def watchdog_s(self) -> float:
        """Vehicle seconds of controller silence before the vehicle makes itself safe."""
        return self._watchdog_s

    def heard_from_controller(self) -> None:
        """The controller is alive: reset (and arm) the watchdog."""
        self._armed = True
        self._last_heard = self._clock
        self._tripped = False

    def make_safe(self, reason: str) -> list[Reply]:
        """The controller's make-safe request: what the watchdog does, at once.

        Every command stops (its ``stop`` handler runs), pending queries reply
        ``timeout``, running actions ``error``, and ``on_watchdog`` runs: the integrator's
        one make-safe serves both the silence and the request. The watchdog then stays
        tripped until the controller speaks again, so it does not make the vehicle safe a
        second time. Returns every reply due now, those included.
        """
        self._tripped = True
        self._note(f"make-safe requested by the controller ({reason or 'no reason given'})")
        self._make_safe_now("stopped: the controller asked the vehicle to make itself safe")
        out = self._outbox
        self._outbox = []
        return out

    def telemetry(self) -> TelemetryRecord | None:
        """The telemetry source's state at the vehicle time, or None.

        A source that raises gives None (noted once in `events`): no telemetry is better
        than no vehicle.
        """
        if self._telemetry is None:
            return None
        try:
            sample = self._telemetry(self._clock)
        except Exception as exc:
            if not self._telemetry_failed:
                self._telemetry_failed = True
                self._note(f"telemetry source raised {type(exc).__name__}: {exc}")
            return None
        if sample is not None and not isinstance(sample, TelemetryRecord):
            # A source written against another record (or returning a tuple) would fail
            # deep in the server; it is named here once, and sends nothing.
            if not self._telemetry_failed:
                self._telemetry_failed = True
                self._note(
                    f"telemetry source returned {type(sample).__name__}, not a "
                    "runtime.telemetry.TelemetryRecord: no telemetry is sent"
                )
            return None
        return sample

    def command(self, command_id: int, name: str, params: Params) -> list[Reply]:
        """Start carrying out one command; return the replies due at once.

        Replies this command causes for *other* commands (the queries of a task it
        replaces, an action it interrupts) come from the next `advance_to`, stamped with
        this command's time.
        """
        self.heard_from_controller()
        if command_id in self._seen:
            return [
                Reply(
                    command_id,
                    str(name),
                    "error",
                    self._clock,
                    f"command id {command_id} was already used; not carried out",
                )
            ]
        self._seen.add(command_id)
        before = len(self._outbox)
        self._dispatch(command_id, str(name), params)
        new = self._outbox[before:]
        del self._outbox[before:]
        self._outbox.extend(r for r in new if r.command_id != command_id)
        return [r for r in new if r.command_id == command_id]

    def advance_to(self, t: float) -> list[Reply]:
        """Move the clock to ``t``: polls every ``poll_s``, time-outs and the watchdog at
        their exact times; return the replies that fell due, in time order.

        Raises:
            ValueError: ``t`` before `time` or not finite (a bug in the caller).
        """
        if not math.isfinite(t) or t < self._clock - _EPS:
            raise ValueError(f"cannot move the vehicle clock from {self._clock} back to {t}")
        t = float(t)
        limit = t + _EPS
        while True:
            polling = any(r.polled for r in self._running)
            next_poll = self._poll_instant(self._ticks + 1) if polling else math.inf
            at = min(next_poll, self._next_deadline())
            if at > limit:
                break
            self._clock = max(self._clock, at)
            is_poll = next_poll <= at + _EPS
            if is_poll:
                self._ticks += 1
            self._instant(is_poll)
        self._clock = max(self._clock, t)
        self._sync_grid()
        out = self._outbox
        self._outbox = []
        return out

    # ------------------------------------------------------------------ reporting

    @property
    def events(self) -> tuple[VehicleEvent, ...]:
        """What the vehicle did on its own account, oldest first."""
        return tuple(self._events)

    @property
    def holders(self) -> dict[str, str]:
        """Resource -> the name of the command holding it, for status lines and tests."""
        return {res: run.job.name for res, run in self._owners.items()}

    def holder(self, resources: tuple[str, ...]) -> Job | None:
        """The one task holding every one of ``resources`` now, or None (nothing to
        watch, a resource free, or two commands sharing them): what a query watches."""
        owners = {id(run): run for res in resources if (run := self._owners.get(res))}
        if not resources or len(owners) != 1 or any(r not in self._owners for r in resources):
            return None
        (run,) = owners.values()
        return run.job if run.kind == "task" else None

    def status(self) -> list[str]:
        """One line per command still running, in arrival order."""
        lines = []
        for run in self._running:
            line = f"{run.job.name} ({run.kind}) since {run.job.started:.1f} s"
            if run.holds:
                line += f", holds {', '.join(run.holds)}"
            if run.deadline is not None:
                line += f", times out at {run.deadline:.1f} s"
            lines.append(line)
        return lines

    # ------------------------------------------------------------------ internals

    def _note(self, text: str) -> None:
        self._events.append(VehicleEvent(self._clock, text))

    def _emit(self, job: Job, kind: str, detail: str = "") -> None:
        self._outbox.append(Reply(job.command_id, job.name, kind, self._clock, detail))

    def _error(self, command_id: int, name: str, detail: str) -> None:
        self._outbox.append(Reply(command_id, name, "error", self._clock, detail))

    def _poll_instant(self, k: int) -> float:
        """The k-th poll instant, rounded to the nanosecond so that replies read 0.3 s,
        not 0.30000000000000004 s."""
        return round(self._start + k * self._poll_s, 9)

    def _sync_grid(self) -> None:
        """Skip the poll instants that passed with nothing to poll."""
        k = math.floor((self._clock - self._start) / self._poll_s)
        while self._poll_instant(k + 1) <= self._clock + _EPS:
            k += 1
        self._ticks = max(self._ticks, k)

    def _next_deadline(self) -> float:
        deadlines = [r.deadline for r in self._running if r.deadline is not None]
        if self._armed and not self._tripped:
            deadlines.append(self._last_heard + self._watchdog_s)
        return min(deadlines, default=math.inf)

    def _dispatch(self, command_id: int, name: str, params: Params) -> None:
        spec = self._profile.command(name)
        if spec is None:
            self._error(
                command_id,
                name,
                f"unknown command '{name}'{did_you_mean(name, self._profile.command_names)}",
            )
            return
        try:
            values = check_params(spec, params)
        except Refused as exc:
            self._error(command_id, name, exc.detail)
            return
        handlers = self._handlers.get(name)
        if handlers is None:
            self._error(command_id, name, f"{name} is not implemented on this vehicle")
            return
        now = self._clock
        job = Job(command_id, name, spec, values, now, now)
        run = _Running(job, handlers)
        takes = spec.resources if spec.kind != "query" else ()
        if takes:
            self._displace(run, takes)
        answer = self._call(handlers.start, run)
        if spec.kind == "task":
            if answer is None and handlers.poll is not None:
                # It works before it replies, holding its resources from now on.
                run.holds = takes
                self._running.append(run)
                for resource in takes:
                    self._owners[resource] = run
                return
            kind, detail = answer if answer is not None else (spec.replies[0], "")
            run.replied = True
            self._emit(job, kind, detail)
            # A task runs until replaced or stopped by the watchdog; one that holds nothing
            # can only be stopped by the watchdog, so it is kept only if it has a stop.
            if kind != "error" and (takes or handlers.stop is not None):
                run.holds = takes
                self._running.append(run)
                for resource in takes:
                    self._owners[resource] = run
            return
        if answer is not None:
            self._emit(job, *answer)
            return
        if handlers.poll is None:
            self._emit(
                job, "error", f"the handler of {name} gave no reply and has no poll to give one"
            )
            return
        time_out = spec.param(TIME_OUT)
        if time_out is not None and "timeout" in spec.replies:
            seconds = float(values[TIME_OUT])
            if time_out.unit is not None:
                seconds = units.convert(seconds, time_out.unit, "s")
            run.deadline = now + seconds
            run.time_out = f"{values[TIME_OUT]:g} {time_out.unit or 's'}"
        run.holds = takes
        self._running.append(run)
        for resource in takes:
            self._owners[resource] = run

    def _displace(self, newcomer: _Running, resources: tuple[str, ...]) -> None:
        """Stop whatever holds ``resources``, for ``newcomer``."""
        old: list[_Running] = []
        for resource in resources:
            holder = self._owners.get(resource)
            if holder is not None and holder not in old:
                old.append(holder)
        for holder in old:
            self._stop_holder(holder, f"replaced by {newcomer.job.name}")

    def _stop_holder(self, holder: _Running, why: str) -> None:
        """End a task or action that holds resources, and the queries watching them.

        Each gets one last poll first, as at a time-out: an answer that fell due since
        the last poll was already given (timed analysis counts on it), so the stop must
        not turn it into ``error`` or ``timeout``."""
        watched = set(holder.holds)
        queries = [
            r
            for r in self._running
            if r.kind == "query" and watched.intersection(r.job.spec.resources)
        ]
        for run in [holder, *queries]:
            if run.polled and run in self._running:
                self._answer(run, self._call(run.handlers.poll, run))
        was_running = holder in self._running
        self._finish(holder)
        self._call_stop(holder)
        what = holder.kind
        if was_running and (what == "action" or (what == "task" and not holder.replied)):
            self._emit(holder.job, "error", f"interrupted: {why}")
        self._note(f"{holder.job.name} stopped: {why}")
        for query in queries:
            if query not in self._running:
                continue
            self._finish(query)
            self._call_stop(query)
            self._emit(query.job, "timeout", f"its {what} {holder.job.name} was {why}")

    def _finish(self, run: _Running) -> None:
        """Forget ``run``: it no longer runs nor holds anything."""
        if run in self._running:
            self._running.remove(run)
        for resource in run.holds:
            if self._owners.get(resource) is run:
                del self._owners[resource]

    def _instant(self, poll: bool) -> None:
        """Everything that falls due at the current clock: watchdog, polls, time-outs."""
        now = self._clock
        if self._armed and not self._tripped and now - self._last_heard >= self._watchdog_s - _EPS:
            self._trip_watchdog()
        if poll:
            for run in list(self._running):
                if run not in self._running or not run.polled:
                    continue
                self._answer(run, self._call(run.handlers.poll, run))
        for run in list(self._running):
            if run.deadline is not None and run.deadline <= now + _EPS and run in self._running:
                if not poll and run.polled:  # one last look: an answer due now wins
                    self._answer(run, self._call(run.handlers.poll, run))
                    if run not in self._running:
                        continue
                self._finish(run)
                self._call_stop(run)
                self._emit(run.job, "timeout", f"time-out of {run.time_out} passed")

    def _answer(self, run: _Running, answer: tuple[str, str] | None) -> None:
        """A poll's answer: a query or action is done; a task replied (and holds on)."""
        if answer is None or run not in self._running:
            return
        if run.kind == "task":
            run.replied = True
            self._emit(run.job, *answer)
            if answer[0] == "error" or not (run.holds or run.handlers.stop is not None):
                self._finish(run)
            return
        self._finish(run)
        self._emit(run.job, *answer)

    def _trip_watchdog(self) -> None:
        self._tripped = True
        silence = self._clock - self._last_heard
        self._note(f"watchdog: no word from the controller for {silence:.1f} s; making safe")
        self._make_safe_now("stopped by the watchdog")

    def _make_safe_now(self, why: str) -> None:
        """Stop every command with the watchdog's replies, then the integrator's make-safe."""
        for run in list(self._running):
            self._finish(run)
            self._call_stop(run)
            if run.kind == "query":
                self._emit(run.job, "timeout", why)
            elif run.kind == "action" or not run.replied:
                self._emit(run.job, "error", why)
        if self._on_watchdog is not None:
            try:
                self._on_watchdog()
            except Exception as exc:
                self._note(f"on_watchdog raised {type(exc).__name__}: {exc}")

    def _call(
        self, handler: StartHandler | PollHandler | None, run: _Running
    ) -> tuple[str, str] | None:
        """Run a start or poll handler; its answer as (kind, detail), checked, or None."""
        if handler is None:
            return None
        job = run.job
        job.now = self._clock
        try:
            outcome = handler(job)
        except Refused as exc:
            return "error", exc.detail
        except Exception as exc:
            self._note(f"{job.name}: handler raised {type(exc).__name__}: {exc}")
            return "error", f"vehicle fault in {job.name}: {type(exc).__name__}: {exc}"
        if outcome is None:
            return None
        if isinstance(outcome, str):
            kind, detail = outcome, ""
        elif (
            isinstance(outcome, tuple)
            and len(outcome) == 2
            and isinstance(outcome[0], str)
            and isinstance(outcome[1], str)
        ):
            kind, detail = outcome
        else:
            return "error", f"the handler of {job.name} returned {outcome!r}, not a reply kind"
        replies = job.spec.replies
        if kind != "error" and kind not in replies:
            return "error", (
                f"the handler of {job.name} answered '{kind}', which is not a reply of "
                f"{job.name} in the profile ({', '.join(replies)})"
            )
        return kind, detail

    def _call_stop(self, run: _Running) -> None:
        stop = run.handlers.stop
        if stop is None:
            return
        run.job.now = self._clock
        try:
            stop(run.job)
        except Exception as exc:
            self._note(f"{run.job.name}: stop raised {type(exc).__name__}: {exc}")
