"""Space-trap queries: has a signal tracked its reference, "of order n", for long enough?

The paper's criterion: x(t) tracks x*(t) of order n at t0 when, for every derivative
k <= n, ||x^(k)(t) - x*^(k)(t)|| < eps_k for all t in [t0 - T, t0]. The references here
are constant (the query's own parameters), so their derivatives are zero. The vehicle
evaluates it every step on its own clock and its own estimates (it has no other view of
itself), over a window that opens no earlier than the query's arrival: a query is never
answered from history it was not there to see. ``eps``, ``n`` and ``T`` come from the
profile's ``space_trap``; the signals are:

==========  ===============================================  ===========================
signal      derivative 0 (norm)                              derivative 1 (norm)
==========  ===============================================  ===========================
depth       depth - z* (m)                                   depth rate (m/s)
heading     heading - psi*, wrapped (deg)                    yaw rate (deg/s)
xy          horizontal distance to (x*, y*) (m)              speed over ground (m/s)
xypsi       as ``xy``, and the heading as ``heading`` with   as ``xy`` and ``heading``
            the HEADING? query's tolerances (the profile
            gives one tolerance per derivative, in metres)
docked      distance to the docking point at depth 0, (m)    3-D speed (m/s)
==========  ===============================================  ===========================

Horizontal signals fail while there is no position estimate (before FIX_XY), and
``docked`` fails while no docking point is recorded: such queries time out.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from coral_lang.profile import SPACE_TRAP_SIGNALS, SpaceTrap
from romeo_sim.dynamics import wrap_angle
from romeo_sim.navigation import Navigation

__all__ = ["MEASURES", "SIGNALS", "Dock", "SpaceTrapQuery", "make_evaluator"]

#: The profile loader refuses any other signal; the two lists are one.
SIGNALS: tuple[str, ...] = SPACE_TRAP_SIGNALS
#: How status lines name each signal's derivative-0 error, and its unit.
MEASURES: dict[str, tuple[str, str]] = {
    "depth": ("depth error", "m"),
    "heading": ("heading error", "deg"),
    "xy": ("range", "m"),
    "xypsi": ("range", "m"),
    "docked": ("distance to dock", "m"),
}

#: The docking point: x, y (m) and heading (rad), recorded by GET_DOCK.
Dock = tuple[float, float, float]
#: Evaluates one step: (all derivatives within tolerance?, derivative-0 error).
Evaluator = Callable[[Navigation, "Dock | None"], tuple[bool, float]]


def make_evaluator(
    trap: SpaceTrap,
    reference: dict[str, float],
    heading_eps: tuple[float, float] = (3.0, 1.0),
) -> Evaluator:
    """Build the per-step test of ``trap`` against ``reference`` (query params, SI + rad).

    Raises:
        ValueError: an unknown signal or an order above 1 (the vehicle estimates no
            accelerations); the vehicle checks this when it is built.
    """
    if trap.signal not in SIGNALS:
        raise ValueError(f"unknown space-trap signal '{trap.signal}' (known: {SIGNALS})")
    if trap.order > 1:
        raise ValueError(f"space-trap order {trap.order} > 1 is not supported")
    e0 = trap.eps[0]
    e1 = trap.eps[1] if trap.order >= 1 else math.inf
    if trap.signal == "depth":
        z_ref = reference.get("z", 0.0)

        def depth(nav: Navigation, dock: Dock | None) -> tuple[bool, float]:
            error = abs(nav.z - z_ref)
            return error < e0 and abs(nav.w) < e1, error

        return depth
    if trap.signal == "heading":
        psi_ref = reference["psi"]

        def heading(nav: Navigation, dock: Dock | None) -> tuple[bool, float]:
            error = abs(math.degrees(wrap_angle(nav.psi - psi_ref)))
            return error < e0 and abs(math.degrees(nav.r)) < e1, error

        return heading
    if trap.signal in ("xy", "xypsi"):
        x_ref, y_ref = reference["x"], reference["y"]
        check_psi = trap.signal == "xypsi"
        check_rate = trap.order >= 1
        psi_ref = reference.get("psi", 0.0)
        h0 = heading_eps[0]
        h1 = heading_eps[1] if trap.order >= 1 else math.inf

        def xy(nav: Navigation, dock: Dock | None) -> tuple[bool, float]:
            if not nav.has_fix:
                return False, math.inf
            ekf = nav.ekf
            error = math.hypot(ekf.x - x_ref, ekf.y - y_ref)
            ok = error < e0 and (not check_rate or math.hypot(*ekf.ground_velocity()) < e1)
            if ok and check_psi:
                ok = (
                    abs(math.degrees(wrap_angle(nav.psi - psi_ref))) < h0
                    and abs(math.degrees(nav.r)) < h1
                )
            return ok, error

        return xy

    def docked(nav: Navigation, dock: Dock | None) -> tuple[bool, float]:
        if dock is None or not nav.has_fix:
            return False, math.inf
        ekf = nav.ekf
        error = math.sqrt((ekf.x - dock[0]) ** 2 + (ekf.y - dock[1]) ** 2 + nav.z**2)
        vn, ve = ekf.ground_velocity()
        speed = math.sqrt(vn * vn + ve * ve + nav.w**2)
        return error < e0 and speed < e1, error

    return docked


class SpaceTrapQuery:
    """A pending ?-command: replies ``done`` when tracked over the window, else ``timeout``.

    Args:
        command_id: the query's id.
        name: e.g. ``DEPTH?``.
        resources: the resources it watches (a task replaced on one of them ends it).
        started: arrival time on the vehicle clock, s.
        time_out: seconds after arrival at which it replies ``timeout``.
        trap: the profile's criterion.
        evaluate: the per-step test from `make_evaluator`.
        measure: how status lines name the derivative-0 error, with its unit, e.g.
            ``("range", "m")``.
    """

    def __init__(
        self,
        command_id: int,
        name: str,
        resources: tuple[str, ...],
        started: float,
        time_out: float,
        trap: SpaceTrap,
        evaluate: Evaluator,
        measure: tuple[str, str],
    ) -> None:
        self.command_id = command_id
        self.name = name
        self.resources = resources
        self.started = started
        self.deadline = started + time_out
        self.trap = trap
        self._evaluate = evaluate
        self._measure = measure
        self.good_since = started
        self.error = math.inf
        self.outcome = ""  # "done" or "timeout" once `step` has returned it
        self._window = trap.window_s - 1e-9
        self._last_chance = self.deadline - 1e-9

    def step(self, nav: Navigation, dock: Dock | None, now: float) -> str | None:
        """Evaluate at ``now``; the reply kind when one falls due, else None."""
        ok, self.error = self._evaluate(nav, dock)
        if not ok:
            self.good_since = now
        elif now - self.good_since >= self._window:
            self.outcome = "done"
            return "done"
        if now >= self._last_chance:
            self.outcome = "timeout"
            return "timeout"
        return None

    def label(self) -> str:
        """E.g. ``DEPTH? (id 4)``."""
        return f"{self.name} (id {self.command_id})"

    def describe(self, now: float) -> str:
        """One-line status for `Vehicle.status`."""
        what, unit = self._measure
        error = "unknown" if math.isinf(self.error) else f"{self.error:.2f} {unit}"
        held = max(0.0, now - self.good_since)
        return (
            f"{self.label()} since {self.started:.1f} s, time-out at {self.deadline:.1f} s, "
            f"{what} {error}, tracked for {held:.1f} of {self.trap.window_s:g} s"
        )
