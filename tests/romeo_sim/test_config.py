"""The vehicle file: defaults from the brief, and clear errors naming the bad field."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from romeo_sim.config import (
    VehicleConfigError,
    bundled_config_path,
    default_config,
    load_vehicle_config,
    parse_vehicle_config,
)


def test_defaults_are_the_team_estimates() -> None:
    c = default_config()
    d = c.dynamics
    assert (d.mass.surge, d.mass.sway, d.mass.heave, d.mass.yaw) == (650, 750, 1100, 140)
    assert (d.linear_damping.surge, d.linear_damping.sway) == (45, 65)
    assert (d.linear_damping.heave, d.linear_damping.yaw) == (70, 10)
    assert (d.quadratic_damping.surge, d.quadratic_damping.heave) == (450, 700)
    assert (d.thrust_limit.surge, d.thrust_limit.heave, d.thrust_limit.yaw) == (200, 250, 25)
    assert 0.1 <= d.thruster_lag_s <= 0.15
    assert d.net_buoyancy_n == 10.0
    assert (c.pool.length_m, c.pool.width_m, c.pool.depth_m) == (12, 8, 4)
    assert c.step_hz >= 20.0 and c.watchdog_s == 30.0
    assert c.sensors.sonar_revolution_s == 10.0


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("dynamics:\n  mass: {surge: -1}\n", "x.yaml:2: dynamics.mass.surge: must be > 0, got -1"),
        (
            "dynamics:\n  mas: {surge: 1}\n",
            "x.yaml:2: dynamics.mas: unknown field (did you mean 'mass'?)",
        ),
        ("pool:\n  depth_m: deep\n", "x.yaml:2: pool.depth_m: expected a number, got 'deep'"),
        ("pool:\n  depth_m: '4'\n", "x.yaml:2: pool.depth_m: expected a number, got '4'"),
        ("step_hz: 10\n", "x.yaml:1: step_hz: must be >= 20, got 10"),
        ("sensors: 3\n", "x.yaml:1: sensors: expected a mapping"),
        ("watchdog_s: 1\nwatchdog_s: 2\n", "x.yaml:2: watchdog_s: given twice"),
        ("navigation: {gate_sigma: .nan}\n", "navigation.gate_sigma: expected a finite number"),
        (
            "sensors: {surface_clutter_max_fraction: 1.5}\n",
            "sensors.surface_clutter_max_fraction: must be <= 1, got 1.5",
        ),
        ("initial: {x_m: 30}\n", "initial: the initial position must be inside the pool"),
        ("pool: [1, 2]\n", "x.yaml:1: pool: expected a mapping"),
        ("pool: {length_m: 1\n", "x.yaml:2: <top>: invalid YAML"),
    ],
)
def test_bad_vehicle_file_names_the_field(text: str, message: str) -> None:
    with pytest.raises(VehicleConfigError) as info:
        parse_vehicle_config(text, "x.yaml", base=default_config())
    assert message in str(info.value)
    assert isinstance(info.value, ValueError)


def test_bundled_file_must_be_complete() -> None:
    with pytest.raises(VehicleConfigError, match=r"x\.yaml:1: dynamics: missing field"):
        parse_vehicle_config("step_hz: 20\nwatchdog_s: 30\n", "x.yaml", base=None)


def test_partial_file_overrides_the_bundled_one(tmp_path: Path) -> None:
    path = tmp_path / "big_pool.yaml"
    path.write_text("pool: {length_m: 25, width_m: 12.5}\nwatchdog_s: 10\n")
    config = load_vehicle_config(path)
    assert (config.pool.length_m, config.pool.width_m, config.pool.depth_m) == (25, 12.5, 4)
    assert config.watchdog_s == 10
    assert config.dynamics == default_config().dynamics


def test_bundled_file_loads_and_unreadable_file_is_refused(tmp_path: Path) -> None:
    assert load_vehicle_config(bundled_config_path()) == default_config()
    with pytest.raises(VehicleConfigError, match="cannot read vehicle file"):
        load_vehicle_config(tmp_path / "missing.yaml")


def test_construction_in_code_is_checked_too() -> None:
    with pytest.raises(VehicleConfigError, match="watchdog_s: must be > 0"):
        dataclasses.replace(default_config(), watchdog_s=0.0)
