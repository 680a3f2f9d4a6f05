"""Autopilots: one cascaded PI controller per axis (surge, sway, heave, yaw).

The outer loop turns a position (or heading) error into a velocity reference, clamped to
the axis's cruise speed; the inner loop drives the estimated velocity to it with a
proportional term scaled by the axis's mass, plus feed-forward of the model's damping at
the reference speed (and of the net buoyancy on heave). A slow integral on the position
error takes out what the model does not know (buoyancy error, current); it freezes while
the thrusters saturate, so it does not wind up during a long transit.

With the default gains the heave loop behaves like s^2 + kv s + kv kp = s^2 + 1.5 s + 0.6
(natural frequency 0.77 rad/s, damping 0.97) once out of the speed clamp; yaw and the
horizontal axes are shaped the same way.
"""

from __future__ import annotations

from romeo_sim.config import AxisGains

__all__ = ["AxisController"]


class AxisController:
    """Cascade controller for one axis.

    Args:
        gains: kp (1/s), v_max (axis units/s), kv (1/s), ki (1/s^2).
        mass: mass or inertia including added mass.
        linear: linear damping coefficient.
        quadratic: quadratic damping coefficient.
        limit: thrust limit of the axis (for anti-windup).
        bias: force always fed forward (net buoyancy on heave, else 0).
        step_s: control period, s.
    """

    __slots__ = (
        "_bias",
        "_h",
        "_k",
        "_kp",
        "_kq",
        "_limit",
        "_m_ki",
        "_m_kv",
        "_vmax",
        "integral",
    )

    def __init__(
        self,
        gains: AxisGains,
        mass: float,
        linear: float,
        quadratic: float,
        limit: float,
        bias: float,
        step_s: float,
        v_max: float | None = None,
    ) -> None:
        self._kp = gains.kp
        self._vmax = gains.v_max if v_max is None else v_max
        self._k = linear
        self._kq = quadratic
        self._limit = limit
        self._bias = bias
        self._h = step_s
        # The products that lead the velocity and integral terms, formed once: the same
        # first multiplication ``m * kv`` (``m * ki``) that each step would repeat.
        self._m_kv = mass * gains.kv
        self._m_ki = mass * gains.ki
        self.integral = 0.0

    def reset(self) -> None:
        """Forget the integral (a new task took the axis)."""
        self.integral = 0.0

    def velocity(self, v_ref: float, v: float) -> float:
        """Force to drive velocity ``v`` to ``v_ref``."""
        return (
            self._m_kv * (v_ref - v) + self._k * v_ref + self._kq * abs(v_ref) * v_ref + self._bias
        )

    def position(self, error: float, v: float, drift: float = 0.0) -> float:
        """Force to drive a position ``error`` (reference minus estimate) to zero.

        Args:
            error: reference minus estimate.
            v: estimated velocity through the water.
            drift: estimated velocity of the water along the axis (the current), which
                the velocity reference cancels so that the vehicle holds ground.
        """
        top = self._vmax
        v_ref = self._kp * error
        if v_ref > top:
            clamped = True
            v_ref = top - drift
        elif v_ref < -top:
            clamped = True
            v_ref = -top - drift
        else:
            clamped = False
            v_ref = v_ref - drift
        # `velocity`, written out (one call less per axis and step), then the integral term.
        force = (
            self._m_kv * (v_ref - v)
            + self._k * v_ref
            + self._kq * abs(v_ref) * v_ref
            + self._bias
            + self._m_ki * self.integral
        )
        # Integrate only in the linear region: not speed-clamped, thrusters not saturated.
        if not clamped:
            limit = self._limit
            if -limit < force < limit:
                self.integral += error * self._h
        return force
