"""The per-step code, written for speed, against the plain arithmetic it stands for.

Each step of the simulator runs the dynamics, the sensors, the filters and the
autopilots; they are written with locals, constants formed once and reused arrays (issue
18), and must still give the very bits the plain formulas give, because a fuzz run's
meaning (its events for a seed) depends on them. Each test here computes the plain way
(the formula of the module docstring, numpy as ``f @ p @ f.T``) beside the real code and
compares with ``==`` on every float and the bytes of every array.
"""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from romeo_sim.config import default_config
from romeo_sim.control import AxisController
from romeo_sim.dynamics import Dynamics, wrap_angle
from romeo_sim.navigation import HorizontalEKF
from romeo_sim.pool import Pool, nearest_wall
from romeo_sim.sensors import _BLOCK, NoiseStream

CONFIG = default_config()
H = CONFIG.step_s
finite = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False)
small = st.floats(-2.0, 2.0, allow_nan=False, allow_infinity=False)


def same(a: float, b: float) -> bool:
    """Equal bits (0.0 and -0.0 differ; so would two NaNs with different payloads)."""
    return math.copysign(1.0, a) == math.copysign(1.0, b) and (a == b or (a != a and b != b))


def test_noise_stream_hands_out_the_generators_draws_in_order_across_blocks() -> None:
    sequence = np.random.SeedSequence(42)
    stream = NoiseStream(sequence)
    normal_seed, uniform_seed = np.random.SeedSequence(42).spawn(2)
    normals = np.random.default_rng(normal_seed).standard_normal(2 * _BLOCK + 5).tolist()
    uniforms = np.random.default_rng(uniform_seed).random(_BLOCK + 3).tolist()
    assert [stream.normal() for _ in range(2 * _BLOCK + 5)] == normals
    assert [stream.uniform() for _ in range(_BLOCK + 3)] == uniforms


@given(error=finite, v=small, drift=small, integral=small)
def test_axis_controller_is_the_cascade_formula(
    error: float, v: float, drift: float, integral: float
) -> None:
    ctl = CONFIG.control
    d = CONFIG.dynamics
    fast = AxisController(
        ctl.depth, d.mass.heave, d.linear_damping.heave, d.quadratic_damping.heave,
        d.thrust_limit.heave, d.net_buoyancy_n, H,
    )  # fmt: skip
    fast.integral = integral
    m, kv, ki, kp, top = d.mass.heave, ctl.depth.kv, ctl.depth.ki, ctl.depth.kp, ctl.depth.v_max
    k, kq, bias = d.linear_damping.heave, d.quadratic_damping.heave, d.net_buoyancy_n

    def velocity(v_ref: float, v: float) -> float:
        return m * kv * (v_ref - v) + k * v_ref + kq * abs(v_ref) * v_ref + bias

    v_ref = kp * error
    clamped = v_ref > top or v_ref < -top
    v_ref = (top if v_ref > top else -top if v_ref < -top else v_ref) - drift
    force = velocity(v_ref, v) + m * ki * integral
    expected_integral = integral
    if not clamped and -d.thrust_limit.heave < force < d.thrust_limit.heave:
        expected_integral += error * H
    assert same(fast.velocity(error, v), velocity(error, v))
    assert same(fast.position(error, v, drift), force)
    assert same(fast.integral, expected_integral)


def plain_dynamics_step(body: Dynamics, cu: float, cv: float, cw: float, cr: float) -> None:
    """`Dynamics.step` as the model reads, attribute by attribute."""
    lu, lv, lw, lr = body.limit
    cu = lu if cu > lu else -lu if cu < -lu else cu
    cv = lv if cv > lv else -lv if cv < -lv else cv
    cw = lw if cw > lw else -lw if cw < -lw else cw
    cr = lr if cr > lr else -lr if cr < -lr else cr
    a = body._lag
    body.tu += a * (cu - body.tu)
    body.tv += a * (cv - body.tv)
    body.tw += a * (cw - body.tw)
    body.tr += a * (cr - body.tr)
    h = body.h
    (au, bu, qu), (av, bv, qv), (aw, bw, qw), (ar, br, qr) = body.coef
    u, v, w, r = body.u, body.v, body.w, body.r
    u += au * body.tu - (bu + qu * abs(u)) * u
    v += av * body.tv - (bv + qv * abs(v)) * v
    w += aw * (body.tw - body.buoyancy) - (bw + qw * abs(w)) * w
    r += ar * body.tr - (br + qr * abs(r)) * r
    c, s = math.cos(body.psi), math.sin(body.psi)
    pool = body.pool
    vn = c * u - s * v + pool.current_north
    ve = s * u + c * v + pool.current_east
    x, y, z = body.x + h * vn, body.y + h * ve, body.z + h * w
    rad = body._radius
    if x < rad or x > pool.length - rad or y < rad or y > pool.width - rad:
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
    elif z > body._bottom:
        z, w = body._bottom, min(w, 0.0)
    body.x, body.y, body.z = x, y, z
    psi = body.psi + h * r
    body.psi = wrap_angle(psi) if psi >= math.pi or psi < -math.pi else psi
    body.u, body.v, body.w, body.r = u, v, w, r


STATE = ("x", "y", "z", "psi", "u", "v", "w", "r", "tu", "tv", "tw", "tr")


@given(
    start=st.tuples(
        st.floats(0.0, 12.0), st.floats(0.0, 8.0), st.floats(-0.5, 4.0), st.floats(-3.2, 3.2)
    ),
    speeds=st.tuples(small, small, small, small),
    forces=st.lists(st.tuples(finite, finite, finite, finite), min_size=1, max_size=5),
    current=st.tuples(st.floats(-0.3, 0.3), st.floats(-0.3, 0.3)),
)
def test_dynamics_step_is_the_plain_model(
    start: tuple[float, float, float, float],
    speeds: tuple[float, float, float, float],
    forces: list[tuple[float, float, float, float]],
    current: tuple[float, float],
) -> None:
    pool = Pool(CONFIG.pool)
    pool.current_north, pool.current_east = current
    fast, plain = (Dynamics(CONFIG.dynamics, pool, H, *start) for _ in range(2))
    for body in (fast, plain):
        body.u, body.v, body.w, body.r = speeds
    for cu, cv, cw, cr in forces:
        fast.step(cu, cv, cw, cr)
        plain_dynamics_step(plain, cu, cv, cw, cr)
        for name in STATE:
            assert same(getattr(fast, name), getattr(plain, name)), name


def random_ekf(seed: int) -> HorizontalEKF:
    rng = np.random.default_rng(seed)
    body = Dynamics(CONFIG.dynamics, Pool(CONFIG.pool), H, 2.0, 2.0, 1.0, 0.0)
    ekf = HorizontalEKF(body, CONFIG.navigation, CONFIG.sensors, Pool(CONFIG.pool), H)
    a = rng.normal(size=(6, 6)) * 0.1
    x, y = rng.uniform(1.0, 7.0, size=2).tolist()
    ekf.reset(x, y, 0.01, 0.02, 0.003)
    ekf.p = ekf.p + a @ a.T
    ekf.u, ekf.v, ekf.cn, ekf.ce = rng.normal(scale=0.2, size=4).tolist()
    return ekf


def plain_propagate(ekf: HorizontalEKF, p: np.ndarray, k: int) -> np.ndarray:
    """The covariance over ``k`` steps, the Jacobian built by indexing a fresh identity."""
    (_, bu, qu), (_, bv, qv) = ekf._coef
    hk = ekf._h * k
    c, s = ekf._c, ekf._s
    f = np.eye(6)
    f[0, 2] = c * hk
    f[0, 3] = -s * hk
    f[1, 2] = s * hk
    f[1, 3] = c * hk
    f[0, 4] = f[1, 5] = hk
    f[2, 2] = max(0.0, 1.0 - k * (bu + 2.0 * qu * abs(ekf.u)))
    f[3, 3] = max(0.0, 1.0 - k * (bv + 2.0 * qv * abs(ekf.v)))
    result: np.ndarray = f @ p @ f.T + k * ekf._q_step
    return result


@given(seed=st.integers(0, 2**32 - 1), psis=st.lists(st.floats(-3.2, 3.2), min_size=1))
def test_ekf_covariance_is_carried_as_f_p_ft_plus_kq(seed: int, psis: list[float]) -> None:
    ekf = random_ekf(seed)
    for psi in psis[:25]:
        p = ekf.p.copy()
        pending = ekf._pending + 1
        ekf.predict(psi, 3.0, -2.0)
        if pending >= 10:  # predict propagated by itself
            assert ekf._pending == 0
        else:
            ekf.propagate()
        assert ekf.p.tobytes() == plain_propagate(ekf, p, pending).tobytes()


@given(
    seed=st.integers(0, 2**32 - 1),
    psi=st.floats(-3.2, 3.2),
    head=st.floats(-3.2, 3.2),
    measured=st.floats(0.0, 15.0) | st.just(math.inf),
)
def test_ekf_update_is_the_plain_kalman_update(
    seed: int, psi: float, head: float, measured: float
) -> None:
    ekf = random_ekf(seed)
    p = ekf.p.copy()
    state = (ekf.x, ekf.y, ekf.u, ekf.v, ekf.cn, ekf.ce)
    result = ekf.update(psi, head, measured)
    # The plain way: the nearest wall, gating on the innovation, np.outer for the gain.
    if measured == math.inf:
        assert result is None
        return
    wall, alpha = nearest_wall(psi + head)
    if abs(alpha) > ekf._near:
        assert result is None
        return
    ca = math.cos(alpha)
    z = measured * ca
    sa = measured * math.sin(alpha)
    r = ekf._r_range * ca * ca + sa * sa * ekf._r_psi
    x, y = state[0], state[1]
    index, sign, innovation = {
        0: (0, -1.0, z - (ekf._pool.length - x)),
        2: (0, 1.0, z - x),
        1: (1, -1.0, z - (ekf._pool.width - y)),
        3: (1, 1.0, z - y),
    }[wall]
    column = p[:, index].copy()
    s_var = float(column[index]) + r
    squared = innovation * innovation
    if squared > ekf._gate2 * s_var or squared > ekf._gate_max2:
        assert result is False
        assert ekf.p.tobytes() == p.tobytes()
        return
    assert result is True
    g = sign * innovation / s_var
    expected = [value + d * g for value, d in zip(state, column.tolist(), strict=True)]
    assert all(
        same(a, b)
        for a, b in zip((ekf.x, ekf.y, ekf.u, ekf.v, ekf.cn, ekf.ce), expected, strict=True)
    )
    p -= np.outer(column, column) * (1.0 / s_var)
    assert ekf.p.tobytes() == p.tobytes()


def test_dot_chain_gives_the_bits_of_matmul_for_the_ekf_shapes() -> None:
    """`HorizontalEKF.propagate` writes ``f @ p @ f.T`` as ``f.dot(p).dot(f.T)``; numpy
    hands both to the same BLAS call, so the bits agree (a reassociated product would
    not: it differs in almost every case, which this checks too)."""
    rng = np.random.default_rng(18)
    f = np.eye(6)
    reassociated = 0
    for _ in range(3000):
        f[0, 2], f[0, 3], f[1, 2], f[1, 3], f[0, 4], f[1, 5], f[2, 2], f[3, 3] = rng.normal(size=8)
        a = rng.normal(size=(6, 6)) * 10.0 ** rng.integers(-8, 3)
        p = a @ a.T
        assert f.dot(p).dot(f.T).tobytes() == (f @ p @ f.T).tobytes()
        reassociated += (f @ (p @ f.T)).tobytes() != (f @ p @ f.T).tobytes()
    assert reassociated > 2500
