"""Task functions: what each running command asks of the autopilots.

A task holds one or more of ROMEO's resources (``depth``, ``heading``, ``horizontal``)
until another command takes one of them (then the whole task stops) or, for actions such
as FIX_XY, until it finishes. Each step the vehicle asks the owner of each resource for a
reference:

* depth owner: a depth set point (or "float up" once a surfacing task is shallow enough);
* heading owner: a heading set point;
* horizontal owner: either body-frame position errors (hover, as SRM) or body-frame
  velocity references (transit, as LRM), and a heading it wants. The vehicle uses that
  heading when the task also holds ``heading`` (SRM, GOTO, DOCKING) or when LRM runs and
  nobody holds ``heading`` (LRM heads the target although the profile lists only
  ``horizontal`` for it; with a HEADING task running, LRM crabs towards the target
  instead).

Guidance works on the navigation estimate, never on the true state.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from romeo_sim.config import ControlConfig
from romeo_sim.dynamics import wrap_angle
from romeo_sim.navigation import Navigation

__all__ = [
    "DepthTask",
    "DockingTask",
    "FixTask",
    "GotoTask",
    "Guidance",
    "HeadingTask",
    "HorizontalTask",
    "LrmTask",
    "SrmTask",
    "Task",
]


@dataclass
class Guidance:
    """A horizontal task's wish for this step (reused, mutated in place).

    Attributes:
        hover: True for position errors (``a``, ``b`` = surge, sway error, m), False for
            velocity references (``a``, ``b`` = surge, sway speed, m/s).
        psi: heading wanted, rad, or None for no preference.
    """

    hover: bool = False
    a: float = 0.0
    b: float = 0.0
    psi: float | None = None


class Task:
    """A running command that holds resources.

    Args:
        command_id: the command's id, for replies and status.
        name: command name (``DEPTH``, ...).
        resources: the resources it holds.
        started: vehicle time when it started, s.
    """

    def __init__(
        self, command_id: int, name: str, resources: tuple[str, ...], started: float
    ) -> None:
        self.command_id = command_id
        self.name = name
        self.resources = resources
        self.started = started

    def label(self) -> str:
        """E.g. ``DEPTH (id 3)``."""
        return f"{self.name} (id {self.command_id})"

    def describe(self, nav: Navigation, now: float) -> str:
        """One-line status for `Vehicle.status`."""
        return f"{self.label()} since {self.started:.1f} s{self._detail(nav)}"

    def _detail(self, nav: Navigation) -> str:
        return ""


class DepthTask(Task):
    """Auto-depth to ``target`` (m); ``surfacing`` tasks stop thrusting when shallow."""

    def __init__(
        self,
        command_id: int,
        name: str,
        started: float,
        target: float,
        surfacing: bool = False,
    ) -> None:
        super().__init__(command_id, name, ("depth",), started)
        self.target = target
        self.surfacing = surfacing

    def _detail(self, nav: Navigation) -> str:
        return f", depth {nav.z:.2f} m -> {self.target:.2f} m"


class HeadingTask(Task):
    """Auto-heading to ``target`` (rad)."""

    def __init__(self, command_id: int, name: str, started: float, target: float) -> None:
        super().__init__(command_id, name, ("heading",), started)
        self.target = target

    def _detail(self, nav: Navigation) -> str:
        error = math.degrees(wrap_angle(self.target - nav.psi))
        return f", heading {math.degrees(nav.psi) % 360:.1f} deg, error {error:.1f} deg"


class HorizontalTask(Task):
    """A task on ``horizontal``: produces a `Guidance` each step."""

    def __init__(
        self,
        command_id: int,
        name: str,
        resources: tuple[str, ...],
        started: float,
        control: ControlConfig,
    ) -> None:
        super().__init__(command_id, name, resources, started)
        self.control = control
        self.wish = Guidance()
        self.switches: list[str] = []  # mode changes to log, drained by the vehicle

    def guide(self, nav: Navigation, owns_yaw: bool) -> Guidance:
        """This step's wish, from the navigation estimate."""
        raise NotImplementedError

    def _range_bearing(self, nav: Navigation, x: float, y: float) -> tuple[float, float]:
        dx = x - nav.ekf.x
        dy = y - nav.ekf.y
        return math.hypot(dx, dy), math.atan2(dy, dx)

    def _transit(
        self, nav: Navigation, psi_ref: float, distance: float, bearing: float, owns_yaw: bool
    ) -> Guidance:
        """Velocity references for heading-the-target travel over ``distance``."""
        wish = self.wish
        ctl = self.control
        speed = min(ctl.lrm_u_max_m_s, ctl.horizontal.kp * distance)
        wish.hover = False
        if owns_yaw:
            cos_err = math.cos(wrap_angle(psi_ref - nav.psi))
            # Scale surge by heading error: full speed on course, none when off by >= 90.
            wish.a = speed * cos_err * cos_err if cos_err > 0.0 else 0.0
            wish.b = 0.0
            wish.psi = psi_ref
        else:
            off = bearing - nav.psi
            wish.a = speed * math.cos(off)
            wish.b = speed * math.sin(off)
            wish.psi = None
        return wish

    def _hover(self, nav: Navigation, x: float, y: float, psi: float) -> Guidance:
        wish = self.wish
        dx = x - nav.ekf.x
        dy = y - nav.ekf.y
        c = math.cos(nav.psi)
        s = math.sin(nav.psi)
        wish.hover = True
        wish.a = c * dx + s * dy
        wish.b = -s * dx + c * dy
        wish.psi = psi
        return wish


class FixTask(HorizontalTask):
    """FIX_XY: thrusters off in the horizontal plane for one sonar revolution."""

    def __init__(
        self, command_id: int, started: float, control: ControlConfig, ends: float
    ) -> None:
        super().__init__(command_id, "FIX_XY", ("horizontal",), started, control)
        self.ends = ends

    def guide(self, nav: Navigation, owns_yaw: bool) -> Guidance:
        wish = self.wish
        wish.hover, wish.a, wish.b, wish.psi = False, 0.0, 0.0, None
        return wish

    def _detail(self, nav: Navigation) -> str:
        return f", sonar revolution ends at {self.ends:.1f} s"


class LrmTask(HorizontalTask):
    """LRM: head the target; surge speed scaled by range and heading error."""

    def __init__(
        self, command_id: int, started: float, control: ControlConfig, x: float, y: float
    ) -> None:
        super().__init__(command_id, "LRM", ("horizontal",), started, control)
        self.x, self.y = x, y
        self._psi_ref: float | None = None

    def guide(self, nav: Navigation, owns_yaw: bool) -> Guidance:
        distance, bearing = self._range_bearing(nav, self.x, self.y)
        # Close in, the bearing swings wildly with estimate noise: keep the last course.
        if self._psi_ref is None or distance > self.control.lrm_hold_range_m:
            self._psi_ref = bearing
        return self._transit(nav, self._psi_ref, distance, bearing, owns_yaw)

    def _detail(self, nav: Navigation) -> str:
        distance, _ = self._range_bearing(nav, self.x, self.y)
        return f", target ({self.x:.1f}, {self.y:.1f}), range {distance:.1f} m"


class SrmTask(HorizontalTask):
    """SRM: hover on the target with the given heading."""

    def __init__(
        self,
        command_id: int,
        started: float,
        control: ControlConfig,
        x: float,
        y: float,
        psi: float,
    ) -> None:
        super().__init__(command_id, "SRM", ("horizontal", "heading"), started, control)
        self.x, self.y, self.psi = x, y, psi

    def guide(self, nav: Navigation, owns_yaw: bool) -> Guidance:
        return self._hover(nav, self.x, self.y, self.psi)

    def _detail(self, nav: Navigation) -> str:
        distance, _ = self._range_bearing(nav, self.x, self.y)
        return f", target ({self.x:.1f}, {self.y:.1f}), range {distance:.1f} m"


LRM_MODE, CAR_MODE, SRM_MODE = "LRM", "car", "SRM"


class GotoTask(HorizontalTask):
    """GOTO: LRM far away, car-driver-like guidance at medium range, SRM close in.

    The modes switch by range with a hysteresis band around ``goto_far_m`` and
    ``goto_near_m``. In car mode the vehicle steers, without sway, towards a point set
    back from the target along the final heading, so it arrives already aligned; the
    set-back shrinks with range.
    """

    def __init__(
        self,
        command_id: int,
        started: float,
        control: ControlConfig,
        x: float,
        y: float,
        psi: float,
        name: str = "GOTO",
    ) -> None:
        super().__init__(command_id, name, ("horizontal", "heading"), started, control)
        self.x, self.y, self.psi = x, y, psi
        self.mode: str | None = None
        self.range = math.inf

    def guide(self, nav: Navigation, owns_yaw: bool) -> Guidance:
        ctl = self.control
        distance, bearing = self._range_bearing(nav, self.x, self.y)
        self.range = distance
        band = ctl.goto_hysteresis_m
        mode = self.mode
        if mode is None:
            new = (
                LRM_MODE
                if distance > ctl.goto_far_m
                else CAR_MODE
                if distance > ctl.goto_near_m
                else SRM_MODE
            )
        elif mode == LRM_MODE:
            new = CAR_MODE if distance < ctl.goto_far_m - band else mode
        elif mode == CAR_MODE:
            if distance > ctl.goto_far_m + band:
                new = LRM_MODE
            elif distance < ctl.goto_near_m - band:
                new = SRM_MODE
            else:
                new = mode
        else:
            new = CAR_MODE if distance > ctl.goto_near_m + band else mode
        if new != mode:
            self.switches.append(
                f"{self.label()}: {mode or 'start'} -> {new} at range {distance:.2f} m"
            )
            self.mode = new
        if new == SRM_MODE:
            return self._hover(nav, self.x, self.y, self.psi)
        if new == LRM_MODE:
            return self._transit(nav, bearing, distance, bearing, owns_yaw)
        setback = min(0.6 * distance, 2.0)
        cx = self.x - setback * math.cos(self.psi)
        cy = self.y - setback * math.sin(self.psi)
        carrot = math.atan2(cy - nav.ekf.y, cx - nav.ekf.x)
        return self._transit(nav, carrot, distance, bearing, owns_yaw)

    def _detail(self, nav: Navigation) -> str:
        distance, _ = self._range_bearing(nav, self.x, self.y)
        mode = self.mode or "starting"
        return f", {mode} mode, target ({self.x:.1f}, {self.y:.1f}), range {distance:.1f} m"


class DockingTask(GotoTask):
    """DOCKING: GOTO the recorded docking point, settle over it, then emerge.

    It takes the ``depth`` resource too once it starts emerging (the profile lists only
    ``horizontal`` and ``heading``); the vehicle then treats that as a new task on depth.
    """

    def __init__(
        self,
        command_id: int,
        started: float,
        control: ControlConfig,
        x: float,
        y: float,
        psi: float,
    ) -> None:
        super().__init__(command_id, started, control, x, y, psi, name="DOCKING")
        self.emerging = False
        self._close_since: float | None = None

    def ready_to_emerge(self, nav: Navigation, now: float) -> bool:
        """True once the vehicle has hovered within reach of the dock for long enough."""
        if self.emerging:
            return False
        ctl = self.control
        if self.mode == SRM_MODE and self.range < ctl.docking_arrive_m:
            if self._close_since is None:
                self._close_since = now
            return now - self._close_since >= ctl.docking_settle_s
        self._close_since = None
        return False

    def _detail(self, nav: Navigation) -> str:
        stage = "emerging" if self.emerging else "approaching"
        return f", {stage}{super()._detail(nav)}"
