"""Dynamics and autopilots: open-loop physics and the closed-loop step responses.

Bands asserted (default vehicle file, seed 0):
* depth 0 -> 2 m: overshoot < 0.10 m; 1.9 m reached before 10 s; within +/-0.10 m from
  12 s on (for the rest of a 40-s run).
* heading 0 -> 90 deg: overshoot < 2 deg; within +/-1 deg from 12 s on.
"""

from __future__ import annotations

import dataclasses
import math

from romeo_sim.config import default_config
from romeo_sim.dynamics import Dynamics, wrap_angle
from romeo_sim.pool import Pool
from romeo_sim.vehicle import Vehicle


def _trace(vehicle: Vehicle, seconds: float) -> list[tuple[float, float, float]]:
    samples = []
    for _ in range(round(seconds / 0.05)):
        vehicle.heard_from_controller()
        vehicle.advance(0.05)
        t = vehicle.telemetry()
        samples.append((t.vehicle_time, t.z, t.psi))
    return samples


def test_depth_step_response_settles_within_band() -> None:
    vehicle = Vehicle(seed=0)
    assert [r.kind for r in vehicle.command(1, "DEPTH", {"z": 2.0})] == ["ack"]
    samples = _trace(vehicle, 40.0)
    depths = [z for _, z, _ in samples]
    assert max(depths) < 2.10  # overshoot
    reached = next(t for t, z, _ in samples if z >= 1.9)
    assert reached < 10.0
    assert all(abs(z - 2.0) < 0.10 for t, z, _ in samples if t >= 12.0)


def test_heading_step_response_settles_within_band() -> None:
    vehicle = Vehicle(seed=0)
    assert [r.kind for r in vehicle.command(1, "HEADING", {"psi": 90.0})] == ["ack"]
    samples = _trace(vehicle, 40.0)
    headings = [psi for _, _, psi in samples if psi < 270.0]
    assert max(headings) < 92.0  # overshoot
    assert all(abs(psi - 90.0) < 1.0 for t, _, psi in samples if t >= 12.0)


def test_heading_takes_the_short_way_round() -> None:
    vehicle = Vehicle(seed=0)
    vehicle.command(1, "HEADING", {"psi": -30.0})  # 330 deg: turn left, not right
    samples = _trace(vehicle, 20.0)
    assert all(psi > 300.0 or psi < 1.0 for _, _, psi in samples)
    assert abs(samples[-1][2] - 330.0) < 1.0


def test_positive_buoyancy_floats_the_idle_vehicle_up() -> None:
    config = default_config()
    config = dataclasses.replace(config, initial=dataclasses.replace(config.initial, z_m=3.4))
    vehicle = Vehicle(config)
    vehicle.advance(30.0)
    assert vehicle.telemetry().z > 0.5
    # Terminal ascent: kq w^2 + k w = B  ->  700 w^2 + 70 w = 10.
    expected = (-70.0 + math.sqrt(70.0**2 + 4 * 700.0 * 10.0)) / (2 * 700.0)
    assert abs(-vehicle.body.w - expected) < 0.02 * expected
    vehicle.advance(60.0)
    assert vehicle.telemetry().z == 0.0  # at the surface, held there


def test_surge_saturates_and_reaches_the_terminal_speed_of_the_damping_model() -> None:
    config = default_config()
    pool = Pool(dataclasses.replace(config.pool, length_m=1000.0))
    body = Dynamics(config.dynamics, pool, 0.05, 1.0, 2.0, 1.0, 0.0)
    body.step(1e6, 0.0, 0.0, 0.0)
    # First-order lag: one step delivers 1 - exp(-0.05 / 0.12) of the saturated 200 N.
    assert math.isclose(body.tu, 200.0 * (1 - math.exp(-0.05 / 0.12)), rel_tol=1e-12)
    for _ in range(2000):
        body.step(1e6, 0.0, 0.0, 0.0)
    expected = (-45.0 + math.sqrt(45.0**2 + 4 * 450.0 * 200.0)) / (2 * 450.0)
    assert abs(body.u - expected) < 1e-3
    assert 0.55 < expected < 0.7  # matches "pool speeds up to about 0.5 m/s"


def test_walls_stop_the_vehicle() -> None:
    config = default_config()
    pool = Pool(config.pool)
    body = Dynamics(config.dynamics, pool, 0.05, 10.0, 4.0, 1.0, 0.0)
    for _ in range(1000):
        body.step(200.0, 0.0, 0.0, 0.0)
    assert body.x == config.pool.length_m - config.dynamics.radius_m
    assert body.u == 0.0


def test_wrap_angle() -> None:
    assert wrap_angle(math.pi) == -math.pi
    assert math.isclose(wrap_angle(3 * math.pi / 2), -math.pi / 2)
    assert math.isclose(wrap_angle(-3 * math.pi / 2), math.pi / 2)
