"""4-DOF dynamics of an open-frame ROV: surge, sway, heave and yaw.

Each axis, in the body frame and relative to the water::

    m dv/dt = tau - k v - kq |v| v   (+ net buoyancy on heave)

with added mass folded into ``m``; the coupling (Coriolis, centripetal, roll and pitch)
terms of the 6-DOF model are left out, which is fair for a slow, passively stable
open-frame vehicle. The commanded generalised forces saturate at the thrust limits and
reach the water through a first-order thruster lag. Kinematics carry the body velocities
(plus the pool current) to x, y (north, east), z (depth, down positive) and heading psi
(rad, clockwise from north). Integration is semi-implicit Euler at a fixed step: the
velocities update first, then the positions with the new velocities; the lag uses its
exact discrete form. Walls, bottom and surface stop the vehicle (no bounce).
"""

from __future__ import annotations

import math

from romeo_sim.config import DynamicsConfig
from romeo_sim.pool import Pool

__all__ = ["Dynamics", "wrap_angle"]

_PI = math.pi
_TWO_PI = 2.0 * math.pi


def wrap_angle(angle: float) -> float:
    """``angle`` (rad) brought into [-pi, pi)."""
    return (angle + _PI) % _TWO_PI - _PI


class Dynamics:
    """The true state of the vehicle and its integrator.

    Attributes are plain floats, read directly by sensors and telemetry (the inner loop
    runs thousands of times per simulated mission, so there is no per-step allocation).

    Args:
        config: mass, damping, thrust limits, lag and buoyancy.
        pool: where the walls, bottom and current are.
        step_s: the fixed step, s.
        x, y, z, psi: initial position (m) and heading (rad).
    """

    def __init__(
        self,
        config: DynamicsConfig,
        pool: Pool,
        step_s: float,
        x: float,
        y: float,
        z: float,
        psi: float,
    ) -> None:
        self.pool = pool
        self.h = step_s
        m, k, kq, lim = (
            config.mass,
            config.linear_damping,
            config.quadratic_damping,
            config.thrust_limit,
        )
        self._inv_m = (1.0 / m.surge, 1.0 / m.sway, 1.0 / m.heave, 1.0 / m.yaw)
        self._k = (k.surge, k.sway, k.heave, k.yaw)
        self._kq = (kq.surge, kq.sway, kq.heave, kq.yaw)
        self.limit = (lim.surge, lim.sway, lim.heave, lim.yaw)
        # Per-step coefficients for each axis: h/m, h k/m, h kq/m (the filters use them too).
        self.coef = tuple(
            (step_s * im, step_s * im * kl, step_s * im * kql)
            for im, kl, kql in zip(self._inv_m, self._k, self._kq, strict=True)
        )
        # The same twelve numbers in one flat tuple, unpacked at once in `step`.
        self._flat_coef = tuple(c for axis in self.coef for c in axis)
        self._lag = 1.0 - math.exp(-step_s / config.thruster_lag_s)
        self.buoyancy = config.net_buoyancy_n
        self._radius = config.radius_m
        self._bottom = pool.depth - config.half_height_m
        self.x, self.y, self.z, self.psi = x, y, z, wrap_angle(psi)
        # Body velocities relative to the water: surge, sway, heave (m/s), yaw rate (rad/s).
        self.u = self.v = self.w = self.r = 0.0
        # Generalised forces the thrusters deliver now (after saturation and lag).
        self.tu = self.tv = self.tw = self.tr = 0.0

    def step(self, cu: float, cv: float, cw: float, cr: float) -> None:
        """Advance one step under commanded forces (N, N, N, N m); saturates them first."""
        lu, lv, lw, lr = self.limit
        cu = lu if cu > lu else -lu if cu < -lu else cu
        cv = lv if cv > lv else -lv if cv < -lv else cv
        cw = lw if cw > lw else -lw if cw < -lw else cw
        cr = lr if cr > lr else -lr if cr < -lr else cr
        a = self._lag
        # Locals stand in for the attributes (this runs every step); the arithmetic is
        # that of ``self.tu += a * (cu - self.tu)`` and so on, operation for operation.
        tu = self.tu
        tu += a * (cu - tu)
        tv = self.tv
        tv += a * (cv - tv)
        tw = self.tw
        tw += a * (cw - tw)
        tr = self.tr
        tr += a * (cr - tr)
        self.tu, self.tv, self.tw, self.tr = tu, tv, tw, tr
        h = self.h
        au, bu, qu, av, bv, qv, aw, bw, qw, ar, br, qr = self._flat_coef
        u, v, w, r = self.u, self.v, self.w, self.r
        u += au * tu - (bu + qu * abs(u)) * u
        v += av * tv - (bv + qv * abs(v)) * v
        w += aw * (tw - self.buoyancy) - (bw + qw * abs(w)) * w
        r += ar * tr - (br + qr * abs(r)) * r
        psi = self.psi
        c = math.cos(psi)
        s = math.sin(psi)
        pool = self.pool
        vn = c * u - s * v + pool.current_north
        ve = s * u + c * v + pool.current_east
        x = self.x + h * vn
        y = self.y + h * ve
        z = self.z + h * w
        rad = self._radius
        if x < rad or x > pool.length - rad or y < rad or y > pool.width - rad:
            # Against a wall: stop the velocity component into it.
            if x < rad:
                x, vn = rad, max(vn, 0.0)
            elif x > pool.length - rad:
                x, vn = pool.length - rad, min(vn, 0.0)
            if y < rad:
                y, ve = rad, max(ve, 0.0)
            elif y > pool.width - rad:
                y, ve = pool.width - rad, min(ve, 0.0)
            vn -= pool.current_north
            ve -= pool.current_east
            u = c * vn + s * ve
            v = -s * vn + c * ve
        if z < 0.0:
            z, w = 0.0, max(w, 0.0)
        elif z > self._bottom:
            z, w = self._bottom, min(w, 0.0)
        self.x, self.y, self.z = x, y, z
        psi += h * r
        if psi >= _PI or psi < -_PI:
            psi = wrap_angle(psi)
        self.psi = psi
        self.u, self.v, self.w, self.r = u, v, w, r
