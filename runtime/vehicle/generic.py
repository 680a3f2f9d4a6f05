"""A simulated vehicle for any profile: rehearse a mission before its vehicle has a simulator.

ROMEO has a physics simulator; a new vehicle usually has nothing but its profile. The
profile already says what a mission may expect of each command (its reply kinds, the
first one the expected reply, its resources, its nominal ``duration_s``), which is enough
to exercise a mission, the controller and an integrator's setup end to end.
`GenericVehicle` replies from the profile alone:

* a **task** replies its first kind (``ack``) at once and holds its resources until
  another command takes them;
* a **query** or an **action** replies its first kind (``done``) after its ``duration_s``
  times a factor drawn uniformly in ``[1 - variation, 1 + variation]``, rounded up to the
  next poll (0.1 s); a query whose ``time_out`` is shorter than that replies ``timeout`` at
  its time-out;
* everything else (parameter checks, resources, replaced tasks' queries timing out, the
  watchdog) is `runtime.vehicle.handlers.HandlerVehicle`'s, of which this is the first user.

It never replies ``error`` to a valid command: to rehearse failures, wrap it in a fault
plan (``coral-vehicle serve --fault``). Same seed, same calls at the same times: same
replies.

Telemetry is a plausible pose, not physics: the vehicle moves at 1 m/s towards the last
``x``/``y`` (or ``x1``/``y1``, the end of a line) given to a task, at 0.3 m/s towards the
last ``z`` given to a task (0 after a task whose name contains ``SURFACE``, or after the
watchdog or the controller's make-safe request), and heads along its horizontal motion
unless a task gave a ``psi``. It has no navigation filter: ``est_x``/``est_y`` are None.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass
from pathlib import Path

from coral_lang.diagnostics import ProfileError
from coral_lang.profile import VehicleProfile
from coral_lang.safefile import PROFILE_LIMIT, UnreadableFile, read_text_file
from coral_lang.yamlsource import expect_keys, load_yaml
from runtime.telemetry import TelemetryRecord
from runtime.vehicle.handlers import HandlerVehicle, Job, Outcome
from runtime.vehicle.registry import SimulatorError, SimulatorRequest

__all__ = ["SIMULATOR", "GenericSimulator", "GenericVehicle", "load_generic_settings"]

HORIZONTAL_SPEED = 1.0
"""m/s of the simulated pose towards its horizontal target."""
VERTICAL_SPEED = 0.3
"""m/s of the simulated pose towards its depth target."""


class GenericVehicle(HandlerVehicle):
    """Replies to every command of ``profile`` as the profile says it should (module doc).

    Args:
        profile: any vehicle profile.
        seed: seeds the duration factors (drawn in the order the commands arrive).
        variation: the relative spread of durations, in [0, 1).
        watchdog_s: vehicle seconds of controller silence before it makes itself safe
            (stops everything and heads for the surface).
        poll_s: vehicle seconds between polls; durations are rounded up to it.
        start_time: the vehicle clock at construction, s.

    Raises:
        ValueError: ``variation`` outside [0, 1), or a bad ``watchdog_s``/``poll_s``.
    """

    def __init__(
        self,
        profile: VehicleProfile,
        *,
        seed: int = 0,
        variation: float = 0.2,
        watchdog_s: float = 30.0,
        poll_s: float = 0.1,
        start_time: float = 0.0,
    ) -> None:
        if not (math.isfinite(variation) and 0.0 <= variation < 1.0):
            raise ValueError(f"variation must be in [0, 1), got {variation!r}")
        super().__init__(
            profile,
            watchdog_s=watchdog_s,
            poll_s=poll_s,
            on_watchdog=self._head_for_surface,
            telemetry=self._pose,
            start_time=start_time,
        )
        self.variation = float(variation)
        self._rng = random.Random(seed)
        self._due: dict[int, tuple[float, float]] = {}  # command id -> (due time, duration)
        self._x = self._y = self._z = self._psi = 0.0
        self._target_xy: tuple[float, float] | None = None
        self._target_z = 0.0
        self._target_psi: float | None = None
        self._pose_time = start_time
        for spec in profile.commands:
            if spec.kind == "task":
                self.on(spec.name, start=self._start_task)
            else:
                self.on(spec.name, start=self._start_timed, poll=self._poll_timed, stop=self._drop)

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
        return None

    def _start_timed(self, job: Job) -> Outcome:
        factor = self._rng.uniform(1.0 - self.variation, 1.0 + self.variation)
        duration = job.spec.duration_s * factor
        if duration <= 0.0:
            return job.spec.replies[0], "simulated: immediate"
        self._due[job.command_id] = (job.started + duration, duration)
        return None

    def _poll_timed(self, job: Job) -> Outcome:
        due, duration = self._due[job.command_id]
        if job.now < due - 1e-9:
            return None
        del self._due[job.command_id]
        return job.spec.replies[0], f"simulated: took {duration:.1f} s"

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
        "any profile: tasks ack at once, queries and actions reply after their duration_s "
        "(seeded, +/-20 %)"
    )
    vehicles: tuple[str, ...] = ()

    def create(self, request: SimulatorRequest) -> GenericVehicle:
        """A `GenericVehicle` for ``request.profile``, seeded with ``request.seed``.

        ``request.config`` is an optional settings file (`load_generic_settings`).

        Raises:
            SimulatorError: the settings file is unreadable or wrong (file, line, column
                and field named).
        """
        settings = {} if request.config is None else load_generic_settings(request.config)
        return GenericVehicle(request.profile, seed=request.seed, **settings)


GENERIC_SETTINGS: dict[str, tuple[float, float | None, bool]] = {
    "watchdog_s": (0.0, None, False),
    "variation": (0.0, 1.0, True),
    "poll_s": (0.0, None, False),
}
"""The fields of a generic settings file: (lower bound, upper bound, upper bound open?);
every value must exceed its lower bound, except ``variation``, which may be 0."""


def load_generic_settings(path: Path) -> dict[str, float]:
    """The generic vehicle's settings file: YAML with any of ``watchdog_s`` (vehicle
    seconds of silence before it makes itself safe; default 30), ``variation`` (relative
    spread of durations in [0, 1); default 0.2) and ``poll_s`` (default 0.1).

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
        expect_keys(document, data, "", (), GENERIC_SETTINGS)
        settings: dict[str, float] = {}
        for key, value in data.items():
            low, high, open_high = GENERIC_SETTINGS[key]
            number = (
                value if isinstance(value, int | float) and not isinstance(value, bool) else None
            )
            ok = number is not None and math.isfinite(number)
            if ok and number is not None:
                ok = (number >= low if key == "variation" else number > low) and (
                    high is None or (number < high if open_high else number <= high)
                )
            if not ok or number is None:
                bound = f"in [{low:g}, {high:g})" if high is not None else f"> {low:g}"
                raise document.error(key, f"must be a number {bound}, got {value!r}")
            settings[key] = float(number)
        return settings
    except ProfileError as exc:
        raise SimulatorError(f"simulator 'generic': {exc}") from None


SIMULATOR = GenericSimulator()
"""The object ``runtime.vehicle.generic:SIMULATOR`` names in the registry."""
