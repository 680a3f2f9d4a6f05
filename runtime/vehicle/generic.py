"""A simulated vehicle for any profile: rehearse a mission before its vehicle has a simulator.

ROMEO has a physics simulator; a new vehicle usually has nothing but its profile. The
profile already says what a mission may expect of each command (its reply kinds, the
first one the expected reply, its resources, its work time), which is enough to exercise
a mission, the controller and an integrator's setup end to end. `GenericVehicle` replies
from the profile alone, and keeps to the timed model timed analysis proves under
(``docs/analysis-methods.md``), so a fuzz run against it stays within what
``coral-check verify --timed`` proved:

* a **task** takes its resources when it arrives and holds them until another command
  takes them; it replies its first kind (``ack``) after a work time ``w`` drawn uniformly
  from ``spec.work_interval("ack", tolerance)`` (``duration_s`` x [1 - tolerance,
  1 + tolerance] unless the profile's ``work_s`` gives an interval; ROMEO: 0.5 s +-20 %);
  replaced before that, it replies ``error`` (interrupted);
* an **action**, or a **query** without a ``time_out``, replies its first kind after a
  work time drawn the same way; an action's resources are free again once it replies;
* a **query with a time_out** ``T`` tracks the task it watches: the one task holding
  every one of its resources when it arrives (`HandlerVehicle.holder`). Tracking completes
  at ``c = start(task) + w`` (``w`` from ``work_interval("done")``), or ``arrival + w``
  when it watches none; it replies ``done`` at ``max(arrival, c)`` if ``c <= arrival +
  T``, else ``timeout`` at ``arrival + T``; a watched task replaced before then makes it
  time out at once. A ``done`` due at or before the time-out is never lost to it, even
  when both fall between two polls (`HandlerVehicle` polls a query once more at its
  time-out);
* every reply goes out at the first poll at or after it falls due: at most ``poll_s``
  later, which must not exceed the profile's ``timing.reply_latency_s`` (analysis assumes
  no vehicle is later than that);
* everything else (parameter checks, resources, the watchdog) is
  `runtime.vehicle.handlers.HandlerVehicle`'s, of which this is the first user.

The spread is the profile's ``timing.tolerance`` (default 0.2); a settings file's
``variation`` overrides it for the intervals derived from ``duration_s`` (declared
``work_s`` intervals always win). It never replies ``error`` to a valid command: to
rehearse failures, wrap it in a fault plan (``coral-vehicle serve --fault``). Work times
are drawn in the order the commands arrive, one per command: same seed, same calls at
the same times, same replies.

**Scripted mode** (a settings file's ``script``, `ScriptedCommand`): ``coral-run run
--schedule`` replays a timed schedule found by analysis. Each command, recognised by its
name and how many of that name arrived before it, takes effect ``hold_s`` after it
arrives (the part of its link delay beyond the link's minimum), gives the scripted
``reply`` ``work_s`` after taking effect, and releases it ``release_s`` after it fell
due (reply latency plus the reply's link delay beyond the minimum). A command the script
does not name is served as above.

Telemetry is a plausible pose, not physics: the vehicle moves at 1 m/s towards the last
``x``/``y`` (or ``x1``/``y1``, the end of a line) given to a task, at 0.3 m/s towards the
last ``z`` given to a task (0 after a task whose name contains ``SURFACE``, or after the
watchdog or the controller's make-safe request), and heads along its horizontal motion
unless a task gave a ``psi``. It has no navigation filter: ``est_x``/``est_y`` are None.
"""

from __future__ import annotations

import heapq
import math
import random
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

from coral_lang import units
from coral_lang.diagnostics import ProfileError
from coral_lang.profile import TIME_OUT, VehicleProfile
from coral_lang.safefile import PROFILE_LIMIT, UnreadableFile, read_text_file
from coral_lang.yamlsource import YamlDocument, expect_keys, load_yaml
from runtime.telemetry import TelemetryRecord
from runtime.vehicle.handlers import HandlerVehicle, Job, Outcome
from runtime.vehicle.model import Params, Reply
from runtime.vehicle.registry import SimulatorError, SimulatorRequest

__all__ = [
    "SIMULATOR",
    "GenericSettings",
    "GenericSimulator",
    "GenericVehicle",
    "ScriptedCommand",
    "load_generic_settings",
]

HORIZONTAL_SPEED = 1.0
"""m/s of the simulated pose towards its horizontal target."""
VERTICAL_SPEED = 0.3
"""m/s of the simulated pose towards its depth target."""
_EPS = 1e-9


@dataclass(frozen=True)
class ScriptedCommand:
    """What the vehicle does with one command in scripted mode (module docstring).

    Attributes:
        command: the command's name.
        occurrence: which arrival of that name (1 = the first).
        hold_s: vehicle seconds between its arrival and its taking effect.
        reply: the reply kind it gives.
        work_s: from taking effect to the reply falling due.
        release_s: from the reply falling due to the vehicle sending it.
    """

    command: str
    occurrence: int
    hold_s: float
    reply: str
    work_s: float
    release_s: float


class GenericVehicle(HandlerVehicle):
    """Replies to every command of ``profile`` as the profile says it should (module doc).

    Args:
        profile: any vehicle profile.
        seed: seeds the work times (drawn in the order the commands arrive).
        variation: the relative spread of work times derived from ``duration_s``, in
            [0, 1); None: the profile's ``timing.tolerance``.
        watchdog_s: vehicle seconds of controller silence before it makes itself safe
            (stops everything and heads for the surface).
        poll_s: vehicle seconds between polls; a reply goes out at the first poll at or
            after it falls due. At most the profile's ``timing.reply_latency_s``.
        start_time: the vehicle clock at construction, s.
        script: scripted mode: what to do with each command named there.

    Raises:
        ValueError: ``variation`` outside [0, 1), a bad ``watchdog_s``/``poll_s``, a
            ``poll_s`` above the profile's reply latency, or a script naming a command or
            reply kind the profile does not have.
    """

    def __init__(
        self,
        profile: VehicleProfile,
        *,
        seed: int = 0,
        variation: float | None = None,
        watchdog_s: float = 30.0,
        poll_s: float = 0.1,
        start_time: float = 0.0,
        script: tuple[ScriptedCommand, ...] | None = None,
    ) -> None:
        tolerance = profile.timing.tolerance if variation is None else variation
        if not (math.isfinite(tolerance) and 0.0 <= tolerance < 1.0):
            raise ValueError(f"variation must be in [0, 1), got {variation!r}")
        latency = profile.timing.reply_latency_s
        if math.isfinite(poll_s) and poll_s > latency + _EPS:
            raise ValueError(
                f"poll_s {poll_s:g} s exceeds the profile's timing.reply_latency_s "
                f"({latency:g} s): replies would go out later than timed analysis assumes; "
                f"poll at most every {latency:g} s"
            )
        super().__init__(
            profile,
            watchdog_s=watchdog_s,
            poll_s=poll_s,
            on_watchdog=self._head_for_surface,
            telemetry=self._pose,
            start_time=start_time,
        )
        self.variation = float(tolerance)
        self._rng = random.Random(seed)
        self._due: dict[int, tuple[float, str, str]] = {}  # command id -> (due, kind, detail)
        self._x = self._y = self._z = self._psi = 0.0
        self._target_xy: tuple[float, float] | None = None
        self._target_z = 0.0
        self._target_psi: float | None = None
        self._pose_time = start_time
        # Scripted mode: the script, arrivals per name, and what is held back.
        self._script = None if script is None else self._check_script(profile, script)
        self._arrived: Counter[str] = Counter()
        self._entries: dict[int, ScriptedCommand] = {}
        self._exact_due: dict[int, float] = {}
        self._pending: list[tuple[float, int, int, str, Params]] = []  # (at, order, id, ...)
        self._held: list[tuple[float, int, Reply]] = []  # (release, order, reply)
        self._order = 0
        for spec in profile.commands:
            if spec.kind == "task":
                self.on(spec.name, start=self._start_task, ack=self._poll_due)
            else:
                self.on(spec.name, start=self._start_timed, poll=self._poll_due, stop=self._drop)

    @staticmethod
    def _check_script(
        profile: VehicleProfile, script: tuple[ScriptedCommand, ...]
    ) -> dict[tuple[str, int], ScriptedCommand]:
        table: dict[tuple[str, int], ScriptedCommand] = {}
        for entry in script:
            spec = profile.command(entry.command)
            if spec is None:
                raise ValueError(
                    f"script: {profile.name}'s profile has no command {entry.command!r}"
                )
            if entry.reply != "error" and entry.reply not in spec.replies:
                raise ValueError(
                    f"script: {entry.command} cannot reply {entry.reply!r} "
                    f"(it replies {', '.join(spec.replies)})"
                )
            key = (entry.command, entry.occurrence)
            if key in table:
                raise ValueError(f"script: {entry.command} #{entry.occurrence} is scripted twice")
            table[key] = entry
        return table

    # ------------------------------------------------------------------ scripted mode

    def command(self, command_id: int, name: str, params: Params) -> list[Reply]:
        """`HandlerVehicle.command`; in scripted mode the command may take effect later
        (its ``hold_s``) and its replies go out at their scripted times."""
        if self._script is None:
            return super().command(command_id, name, params)
        self._arrived[str(name)] += 1
        entry = self._script.get((str(name), self._arrived[str(name)]))
        if entry is not None:
            self._entries[command_id] = entry
        if entry is not None and entry.hold_s > 0.0:
            self.heard_from_controller()
            self._order += 1
            at = self.time + entry.hold_s
            heapq.heappush(self._pending, (at, self._order, command_id, str(name), params))
            return []
        return self._release(super().command(command_id, name, params), self.time)

    def advance_to(self, t: float) -> list[Reply]:
        """`HandlerVehicle.advance_to`, with scripted commands taking effect on the way."""
        if self._script is None:
            return super().advance_to(t)
        out: list[Reply] = []
        while self._pending and self._pending[0][0] <= t + _EPS:
            at, _, command_id, name, params = heapq.heappop(self._pending)
            out += super().advance_to(max(at, self.time))
            out += super().command(command_id, name, params)
        out += super().advance_to(t)
        return self._release(out, t)

    def _release(self, replies: list[Reply], now: float) -> list[Reply]:
        """Hold each reply until its scripted release; the ones due by ``now``, in order."""
        for reply in replies:
            entry = self._entries.get(reply.command_id)
            release = reply.time
            if entry is not None:
                due = self._exact_due.get(reply.command_id, reply.time)
                if reply.kind != entry.reply:
                    due = reply.time
                release = max(reply.time, due + entry.release_s)
            self._order += 1
            heapq.heappush(self._held, (release, self._order, reply))
        ready: list[Reply] = []
        while self._held and self._held[0][0] <= now + _EPS:
            ready.append(heapq.heappop(self._held)[2])
        return ready

    # ------------------------------------------------------------------ handlers

    def _start_task(self, job: Job) -> Outcome:
        self._move_to(job.now)
        numbers = {k: float(v) for k, v in job.params.items() if not isinstance(v, str)}
        if "SURFACE" in job.name.upper():
            self._target_z = 0.0
        elif "z" in numbers:
            self._target_z = numbers["z"]
        for x, y in (("x1", "y1"), ("x", "y")):
            if x in numbers and y in numbers:
                self._target_xy = (numbers[x], numbers[y])
                break
        if "psi" in numbers:
            self._target_psi = numbers["psi"] % 360.0
        return self._work(job)

    def _start_timed(self, job: Job) -> Outcome:
        return self._work(job)

    def _work(self, job: Job) -> Outcome:
        """Decide when ``job`` replies, and what; reply now if that is now."""
        entry = self._entries.get(job.command_id)
        if entry is not None:
            due = job.started + entry.work_s
            self._exact_due[job.command_id] = due
            return self._schedule(job, due, entry.reply, f"scripted: took {entry.work_s:.1f} s")
        spec = job.spec
        kind = spec.replies[0]
        seconds = self._time_out(job)
        if seconds is None:
            work = self._draw(job, kind)
            return self._schedule(job, job.started + work, kind, f"simulated: took {work:.1f} s")
        done = "done" if "done" in spec.replies else kind
        work = self._draw(job, done)
        watched = self.holder(spec.resources)
        origin = job.started if watched is None else watched.started
        complete = origin + work
        if complete > job.started + seconds + _EPS:
            return None  # the time-out comes first: HandlerVehicle replies it
        what = "tracking" if watched is None else f"tracking {watched.name}"
        return self._schedule(
            job, max(job.started, complete), done, f"simulated: {what} took {work:.1f} s"
        )

    def _draw(self, job: Job, kind: str) -> float:
        low, high = job.spec.work_interval(kind, self.variation)
        return self._rng.uniform(low, high)

    @staticmethod
    def _time_out(job: Job) -> float | None:
        """A query's time-out in seconds, when it has one it may reply ``timeout`` to."""
        spec = job.spec
        param = spec.param(TIME_OUT)
        if spec.kind != "query" or param is None or "timeout" not in spec.replies:
            return None
        seconds = float(job.params[TIME_OUT])
        return units.convert(seconds, param.unit, "s") if param.unit is not None else seconds

    def _schedule(self, job: Job, due: float, kind: str, detail: str) -> Outcome:
        if due <= job.now + _EPS:
            return kind, detail
        self._due[job.command_id] = (due, kind, detail)
        return None

    def _poll_due(self, job: Job) -> Outcome:
        due = self._due.get(job.command_id)
        if due is None or job.now < due[0] - _EPS:
            return None
        del self._due[job.command_id]
        return due[1], due[2]

    def _drop(self, job: Job) -> None:
        self._due.pop(job.command_id, None)

    def _head_for_surface(self) -> None:
        self._move_to(self.time)
        self._target_z = 0.0
        self._target_xy = None

    # ------------------------------------------------------------------ telemetry

    def _move_to(self, now: float) -> None:
        dt = max(0.0, now - self._pose_time)
        self._pose_time = max(self._pose_time, now)
        if dt == 0.0:
            return
        dz = self._target_z - self._z
        self._z += math.copysign(min(abs(dz), VERTICAL_SPEED * dt), dz)
        if self._target_xy is not None:
            dx, dy = self._target_xy[0] - self._x, self._target_xy[1] - self._y
            distance = math.hypot(dx, dy)
            if distance > 0.0:
                step = min(distance, HORIZONTAL_SPEED * dt)
                self._x += dx / distance * step
                self._y += dy / distance * step
                if self._target_psi is None:
                    self._psi = math.degrees(math.atan2(dy, dx)) % 360.0
        if self._target_psi is not None:
            self._psi = self._target_psi

    def _pose(self, now: float) -> TelemetryRecord:
        self._move_to(now)
        return TelemetryRecord(now, self._x, self._y, self._z, self._psi)


@dataclass(frozen=True)
class GenericSimulator:
    """The registry's ``generic`` simulator: a `GenericVehicle` for any profile."""

    name: str = "generic"
    summary: str = (
        "any profile: every reply after its profile work time (seeded, +/-20 % unless the "
        "profile says otherwise), query time-outs as timed analysis models them"
    )
    vehicles: tuple[str, ...] = ()

    def create(self, request: SimulatorRequest) -> GenericVehicle:
        """A `GenericVehicle` for ``request.profile``, seeded with ``request.seed``.

        ``request.config`` is an optional settings file (`load_generic_settings`).

        Raises:
            SimulatorError: the settings file is unreadable or wrong (file, line, column
                and field named), or does not fit the profile (a ``poll_s`` above its
                reply latency, a script naming what it does not have).
        """
        settings = (
            GenericSettings() if request.config is None else load_generic_settings(request.config)
        )
        try:
            return GenericVehicle(
                request.profile,
                seed=request.seed,
                variation=settings.variation,
                watchdog_s=settings.watchdog_s,
                poll_s=settings.poll_s,
                script=settings.script,
            )
        except ValueError as exc:
            where = f"{request.config}: " if request.config is not None else ""
            raise SimulatorError(f"simulator 'generic': {where}{exc}") from None


@dataclass(frozen=True)
class GenericSettings:
    """A generic settings file's content (`load_generic_settings`); None: the default."""

    watchdog_s: float = 30.0
    variation: float | None = None
    poll_s: float = 0.1
    script: tuple[ScriptedCommand, ...] | None = None


GENERIC_SETTINGS: dict[str, tuple[float, float | None, bool]] = {
    "watchdog_s": (0.0, None, False),
    "variation": (0.0, 1.0, True),
    "poll_s": (0.0, None, False),
}
"""The numeric fields of a generic settings file: (lower bound, upper bound, upper bound
open?); every value must exceed its lower bound, except ``variation``, which may be 0."""

SCRIPT_FIELDS = ("command", "occurrence", "hold_s", "reply", "work_s", "release_s")
"""The fields of each entry of a settings file's ``script`` (`ScriptedCommand`)."""


def load_generic_settings(path: Path) -> GenericSettings:
    """The generic vehicle's settings file: YAML (or JSON) with any of ``watchdog_s``
    (vehicle seconds of silence before it makes itself safe; default 30), ``variation``
    (relative spread of work times in [0, 1); default: the profile's
    ``timing.tolerance``), ``poll_s`` (default 0.1; at most the profile's
    ``timing.reply_latency_s``) and ``script`` (scripted mode: a list of entries with the
    fields of `ScriptedCommand`; ``coral-run run --schedule`` writes one).

    A long watchdog is what a rehearsal of ``kill -9`` and ``coral-run --resume`` needs
    at a high ``--speed``: the controller's restart takes wall seconds.

    Raises:
        SimulatorError: unreadable file, bad YAML, an unknown field or a value out of range.
    """
    try:  # a regular file of bounded size: never a FIFO or /dev/zero
        text = read_text_file(path, PROFILE_LIMIT)
    except UnreadableFile as exc:
        raise SimulatorError(
            f"{path}: cannot read the generic vehicle's settings: {exc.reason}"
        ) from None
    try:
        document = load_yaml(text, str(path))
        data = document.data if document.data is not None else {}
        if not isinstance(data, dict):
            raise document.error("", "expected a mapping of generic vehicle settings")
        expect_keys(document, data, "", (), (*GENERIC_SETTINGS, "script"))
        numbers: dict[str, float] = {}
        for key, value in data.items():
            if key == "script":
                continue
            low, high, open_high = GENERIC_SETTINGS[key]
            number = _number(value)
            ok = number is not None
            if ok and number is not None:
                ok = (number >= low if key == "variation" else number > low) and (
                    high is None or (number < high if open_high else number <= high)
                )
            if not ok or number is None:
                bound = f"in [{low:g}, {high:g})" if high is not None else f"> {low:g}"
                raise document.error(key, f"must be a number {bound}, got {value!r}")
            numbers[key] = number
        script = None
        if "script" in data:
            entries = data["script"]
            if not isinstance(entries, list):
                raise document.error("script", "expected a list of scripted commands")
            script = tuple(
                _script_entry(document, entry, f"script[{i}]") for i, entry in enumerate(entries)
            )
        return GenericSettings(
            watchdog_s=numbers.get("watchdog_s", 30.0),
            variation=numbers.get("variation"),
            poll_s=numbers.get("poll_s", 0.1),
            script=script,
        )
    except ProfileError as exc:
        raise SimulatorError(f"simulator 'generic': {exc}") from None


def _number(value: object) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return float(value) if math.isfinite(value) else None


def _script_entry(document: YamlDocument, entry: object, where: str) -> ScriptedCommand:
    if not isinstance(entry, dict):
        raise document.error(where, "expected a mapping with " + ", ".join(SCRIPT_FIELDS))
    missing = [f for f in SCRIPT_FIELDS if f not in entry]
    extra = sorted(str(k) for k in entry if k not in SCRIPT_FIELDS)
    if missing or extra:
        what = f"missing {', '.join(missing)}" if missing else f"unknown {', '.join(extra)}"
        raise document.error(where, f"{what} (fields: {', '.join(SCRIPT_FIELDS)})")
    for key in ("command", "reply"):
        if not isinstance(entry[key], str) or not entry[key]:
            raise document.error(f"{where}.{key}", f"expected a name, got {entry[key]!r}")
    occurrence = entry["occurrence"]
    if isinstance(occurrence, bool) or not isinstance(occurrence, int) or occurrence < 1:
        raise document.error(f"{where}.occurrence", f"expected an integer >= 1, got {occurrence!r}")
    seconds: dict[str, float] = {}
    for key in ("hold_s", "work_s", "release_s"):
        number = _number(entry[key])
        if number is None or number < 0.0:
            raise document.error(f"{where}.{key}", f"must be a number >= 0, got {entry[key]!r}")
        seconds[key] = number
    return ScriptedCommand(
        command=entry["command"],
        occurrence=occurrence,
        hold_s=seconds["hold_s"],
        reply=entry["reply"],
        work_s=seconds["work_s"],
        release_s=seconds["release_s"],
    )


SIMULATOR = GenericSimulator()
"""The object ``runtime.vehicle.generic:SIMULATOR`` names in the registry."""
