"""Navigation: what the vehicle believes about itself. Guidance uses only this.

* Depth: an alpha-beta filter on the depth gauge, predicting with the heave model under
  the thrust the thrusters deliver (the vehicle computes that from its own commands with
  the same lag model), so depth rate comes out smooth enough for the space-trap queries.
* Heading: the rate gyro integrated, pulled towards the compass (complementary filter).
* Horizontal: an extended Kalman filter on [x, y, u, v, cn, ce] (position north/east,
  body surge and sway velocity through the water, water current north/east). The motion
  model is the vehicle's nonlinear surge/sway dynamics under the delivered thrust,
  rotated by the estimated heading, plus the current; the measurements are
  sonar ranges to the pool walls taken within a few degrees of a wall's normal (oblique
  echoes are weak and ambiguous near corners). Each return is gated on its innovation,
  which drops most false short ranges near the surface.
* FIX_XY: one sonar revolution of near-normal returns; per axis, the median wall distance
  and the returns consistent with it give the first estimate and its variance. Too few
  consistent returns on an axis: FIX_XY fails (and the vehicle replies ``error``).
"""

from __future__ import annotations

import math
import statistics
from dataclasses import dataclass

import numpy as np

from romeo_sim.config import NavigationConfig, SensorConfig
from romeo_sim.dynamics import Dynamics, wrap_angle
from romeo_sim.pool import WALL_NAMES, Pool, nearest_wall
from romeo_sim.sensors import SonarPing

__all__ = ["FixResult", "HorizontalEKF", "Navigation"]

_COV_STRIDE = 10  # steps between covariance propagations when no measurement comes
_INF = math.inf
_PI = math.pi
_HALF_PI = 0.5 * math.pi


@dataclass(frozen=True)
class FixResult:
    """Outcome of one FIX_XY: the initial estimate, or why there is none."""

    ok: bool
    x: float
    y: float
    sd_x: float
    sd_y: float
    returns_x: int
    returns_y: int
    detail: str


class HorizontalEKF:
    """EKF on [x, y, u, v, cn, ce]: position, body velocity and the water current.

    The state lives in plain floats (it moves every step); the 6 x 6 covariance in a
    numpy array, carried lazily: in one stride over the steps since it last moved, when
    a measurement needs it or every ``_COV_STRIDE`` steps. The Jacobian barely changes
    over a stride of half a second at ROV speeds, and this keeps the cost per step small.
    For the same reason the stride's Jacobian is written into one reused array through a
    flat view of it, and the process noise of each stride length is formed once.
    The current is a random walk; it lets the filter follow a vehicle that drifts
    although its thrust model says it should not (in a still pool it stays near zero).

    Args:
        body: the dynamics, for the surge/sway motion model.
        config: gating and process noise.
        sensors: sonar and compass noise, for the measurement variance.
        pool: wall positions.
        step_s: prediction step, s.
    """

    def __init__(
        self,
        body: Dynamics,
        config: NavigationConfig,
        sensors: SensorConfig,
        pool: Pool,
        step_s: float,
    ) -> None:
        self._coef = body.coef[:2]
        (self._au, self._bu, self._qu), (self._av, self._bv, self._qv) = self._coef
        self._pool = pool
        self._h = step_s
        self._gate2 = config.gate_sigma**2
        self._gate_max2 = config.gate_max_m**2
        q_velocity = (config.process_accel_sd_m_s2 * step_s) ** 2
        q_current = config.current_walk_m_s**2 * step_s
        self._q_step = np.diag([1e-8, 1e-8, q_velocity, q_velocity, q_current, q_current])
        # k * _q_step for the stride lengths k = 0.._COV_STRIDE (propagate adds one).
        self._q_strides = [k * self._q_step for k in range(_COV_STRIDE + 1)]
        self._current_var = config.current_sd_m_s**2
        self._r_range = sensors.sonar_range_sd_m**2
        self._r_psi = math.radians(sensors.compass_sd_deg) ** 2
        self._near = math.radians(config.near_normal_deg)
        self.x = self.y = self.u = self.v = self.cn = self.ce = 0.0
        self.p = np.zeros((6, 6))
        self._f = np.eye(6)
        self._f_t = self._f.T
        # The Jacobian's 36 entries row by row, written through without numpy indexing.
        self._f_flat = self._f.data.cast("B").cast("d")
        self._c, self._s = 1.0, 0.0  # heading of the last prediction, for the Jacobian
        self.accepted = 0
        self.rejected = 0
        self._pending = 0

    def reset(self, x: float, y: float, var_x: float, var_y: float, var_v: float) -> None:
        """Start from (x, y) at rest in still water, with the given variances."""
        self.x, self.y, self.u, self.v, self.cn, self.ce = x, y, 0.0, 0.0, 0.0, 0.0
        cv = self._current_var
        self.p = np.diag([var_x, var_y, var_v, var_v, cv, cv])
        self.accepted = self.rejected = 0
        self._pending = 0

    def sd_xy(self) -> tuple[float, float]:
        """Standard deviations of x and y, m."""
        if self._pending:
            self.propagate()
        return math.sqrt(self.p[0, 0]), math.sqrt(self.p[1, 1])

    def ground_velocity(self) -> tuple[float, float]:
        """Estimated velocity over the ground (north, east), m/s: body velocity + current."""
        c, s, u, v = self._c, self._s, self.u, self.v
        return c * u - s * v + self.cn, s * u + c * v + self.ce

    def predict(self, psi: float, force_u: float, force_v: float) -> None:
        """One step of the motion model under the delivered surge and sway forces."""
        h = self._h
        c = math.cos(psi)
        s = math.sin(psi)
        u, v = self.u, self.v
        self.x += h * (c * u - s * v + self.cn)
        self.y += h * (s * u + c * v + self.ce)
        self.u = u + self._au * force_u - (self._bu + self._qu * abs(u)) * u
        self.v = v + self._av * force_v - (self._bv + self._qv * abs(v)) * v
        self._c, self._s = c, s
        pending = self._pending + 1
        self._pending = pending
        if pending >= _COV_STRIDE:
            self.propagate()

    def propagate(self) -> None:
        """Carry the covariance over the steps predicted since it last moved."""
        k = self._pending
        if k == 0:
            return
        self._pending = 0
        hk = self._h * k
        c, s = self._c, self._s
        f = self._f_flat  # f[i, j] is f[6 * i + j]
        f[2] = c * hk  # [0, 2]
        f[3] = -s * hk  # [0, 3]
        f[8] = s * hk  # [1, 2]
        f[9] = c * hk  # [1, 3]
        f[4] = f[11] = hk  # [0, 4], [1, 5]
        f[14] = max(0.0, 1.0 - k * (self._bu + 2.0 * self._qu * abs(self.u)))  # [2, 2]
        f[21] = max(0.0, 1.0 - k * (self._bv + 2.0 * self._qv * abs(self.v)))  # [3, 3]
        # f @ p @ f.T, as ndarray.dot: the same cblas_dgemm calls with the same arguments
        # (numpy sends both to BLAS for 6 x 6 doubles; the transpose is passed as a flag),
        # so the same bits, without the matmul ufunc's dispatch (tests/romeo_sim pins it).
        p = self._f.dot(self.p).dot(self._f_t)
        p += self._q_strides[k] if k <= _COV_STRIDE else k * self._q_step
        self.p = p

    def update(self, psi: float, head: float, measured: float) -> bool | None:
        """Fuse one sonar range; None when not near-normal, else accepted (True) or gated.

        The range along a beam ``alpha`` off a wall's normal is ``distance / cos(alpha)``;
        the filter fuses ``range cos(alpha)`` against the wall distance, whose Jacobian is
        +/-1 on x or y. Heading noise enters the measurement variance.
        """
        if measured == _INF:
            return None
        # `nearest_wall`, written out: most pings are not near-normal, and end here.
        bearing = psi + head
        quarter = round(bearing / _HALF_PI)
        alpha = bearing - quarter * _HALF_PI
        if abs(alpha) > self._near:
            return None
        wall = quarter % 4
        if self._pending:
            self.propagate()
        ca = math.cos(alpha)
        z = measured * ca
        sa = measured * math.sin(alpha)
        r = self._r_range * ca * ca + sa * sa * self._r_psi
        pool = self._pool
        if wall == 0:
            index, sign, innovation = 0, -1.0, z - (pool.length - self.x)
        elif wall == 2:
            index, sign, innovation = 0, 1.0, z - self.x
        elif wall == 1:
            index, sign, innovation = 1, -1.0, z - (pool.width - self.y)
        else:
            index, sign, innovation = 1, 1.0, z - self.y
        p = self.p
        s_var = float(p[index, index]) + r
        squared = innovation * innovation
        # Gate on the innovation's spread, and never beyond an absolute bound: after a
        # long spell of rejected echoes (at the surface) the spread has grown so much that
        # a surface echo would pass the first test alone, and one such echo is enough to
        # corrupt the current estimate that station keeping relies on.
        if squared > self._gate2 * s_var or squared > self._gate_max2:
            self.rejected += 1
            return False
        self.accepted += 1
        g = sign * innovation / s_var
        column = p[:, index]  # a view: the outer product below is formed before p changes
        dx, dy, du, dv, dcn, dce = column.tolist()
        self.x += dx * g
        self.y += dy * g
        self.u += du * g
        self.v += dv * g
        self.cn += dcn * g
        self.ce += dce * g
        gain = np.multiply.outer(column, column)  # np.outer, without its reshaping
        gain *= 1.0 / s_var
        p -= gain
        return True


class _FixCollector:
    """Near-normal wall distances gathered during one FIX_XY revolution."""

    def __init__(self, near: float) -> None:
        self._near = near
        self.samples: list[list[float]] = [[], [], [], []]

    def add(self, psi: float, head: float, measured: float) -> None:
        if measured == math.inf:
            return
        wall, alpha = nearest_wall(psi + head)
        if abs(alpha) <= self._near:
            self.samples[wall].append(measured * math.cos(alpha))


class Navigation:
    """The vehicle's estimates: depth, heading and (after FIX_XY) horizontal position.

    Args:
        body: dynamics, for the motion models (not for the true state).
        config: filter settings.
        sensors: noise levels.
        pool: wall positions.
        step_s: the fixed step, s.
    """

    def __init__(
        self,
        body: Dynamics,
        config: NavigationConfig,
        sensors: SensorConfig,
        pool: Pool,
        step_s: float,
    ) -> None:
        self._body = body
        self._config = config
        self._sensors = sensors
        self._pool = pool
        self._h = step_s
        self.ekf = HorizontalEKF(body, config, sensors, pool, step_s)
        self.has_fix = False
        self.z = body.z
        self.w = 0.0
        self.psi = body.psi
        self.r = 0.0
        self._started = False
        self._collector: _FixCollector | None = None
        self._heave_coef = body.coef[2]
        self._alpha = config.depth_alpha
        self._beta_h = config.depth_beta / step_s
        self._compass_alpha = config.compass_alpha

    @property
    def fixing(self) -> bool:
        """True while a FIX_XY revolution is being collected."""
        return self._collector is not None

    def step(self, depth: float, compass: float, gyro: float, ping: SonarPing) -> None:
        """Fuse one step of sensor readings (depth m, heading rad, yaw rate rad/s, ping)."""
        body = self._body
        h = self._h
        if not self._started:
            self._started = True
            self.z, self.psi = depth, compass
        # Depth: model prediction, then alpha-beta correction.
        aw, bw, qw = self._heave_coef
        w = self.w
        w += aw * (body.tw - body.buoyancy) - (bw + qw * abs(w)) * w
        z = self.z + h * w
        residual = depth - z
        self.z = z + self._alpha * residual
        self.w = w + self._beta_h * residual
        # Heading: integrate the gyro, pull towards the compass.
        psi = self.psi + h * gyro
        gap = compass - psi
        if gap >= _PI or gap < -_PI:
            gap = wrap_angle(gap)
        psi += self._compass_alpha * gap
        if psi >= _PI or psi < -_PI:
            psi = wrap_angle(psi)
        self.psi = psi
        self.r = gyro
        if self._collector is not None:
            self._collector.add(psi, ping.head, ping.range)
        if self.has_fix:
            ekf = self.ekf
            ekf.predict(psi, body.tu, body.tv)
            ekf.update(psi, ping.head, ping.range)

    def start_fix(self) -> None:
        """Begin collecting a revolution of wall returns (the estimate, if any, runs on)."""
        self._collector = _FixCollector(math.radians(self._config.near_normal_deg))

    def cancel_fix(self) -> None:
        """Drop a FIX_XY in progress."""
        self._collector = None

    def finish_fix(self) -> FixResult:
        """Close the revolution: initialise the EKF, or explain why not."""
        collector = self._collector
        self._collector = None
        samples = [[], [], [], []] if collector is None else collector.samples
        length, width = self._pool.length, self._pool.width
        xs = [length - d for d in samples[0]] + list(samples[2])
        ys = [width - d for d in samples[1]] + list(samples[3])
        x, var_x, nx = self._robust(xs)
        y, var_y, ny = self._robust(ys)
        need = int(self._config.fix_min_returns)
        counts = ", ".join(f"{n} {len(s)}" for n, s in zip(WALL_NAMES, samples, strict=True))
        if nx < need or ny < need:
            return FixResult(
                False,
                x,
                y,
                math.sqrt(var_x),
                math.sqrt(var_y),
                nx,
                ny,
                f"too few consistent wall returns: x {nx}, y {ny} (need {need}); "
                f"near-normal returns per wall: {counts}",
            )
        self.ekf.reset(x, y, var_x, var_y, 0.05**2)
        self.has_fix = True
        return FixResult(
            True,
            x,
            y,
            math.sqrt(var_x),
            math.sqrt(var_y),
            nx,
            ny,
            f"x {x:.2f} m, y {y:.2f} m (sd {math.sqrt(var_x):.2f}, {math.sqrt(var_y):.2f} m; "
            f"{nx} + {ny} returns)",
        )

    def _robust(self, values: list[float]) -> tuple[float, float, int]:
        """Median, then the mean and variance of the values within the inlier band of it."""
        if not values:
            return math.nan, math.inf, 0
        middle = statistics.median(values)
        band = self._config.fix_inlier_m
        inliers = [v for v in values if abs(v - middle) <= band]
        if not inliers:  # an even count whose two middle values lie far apart
            return middle, math.inf, 0
        mean = sum(inliers) / len(inliers)
        sd = max(self._sensors.sonar_range_sd_m, 0.02)
        spread = sum((v - mean) ** 2 for v in inliers) / len(inliers)
        return mean, max(sd * sd, spread) / len(inliers) + 0.02**2, len(inliers)
