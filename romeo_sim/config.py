"""The vehicle file: ROMEO's physical, sensor, navigation and control parameters.

Everything the simulator needs to know about the vehicle and its pool lives in one YAML
file (``romeo_vehicle.yaml`` is bundled); this module turns it into frozen dataclasses and
refuses a bad file before anything moves, naming the field, its line and how to fix it.

A user file may give only the fields it changes: it is read on top of the bundled file.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
from dataclasses import dataclass, field
from functools import cache
from importlib import resources as importlib_resources
from pathlib import Path
from typing import Any

import yaml

__all__ = [
    "Axes",
    "AxisGains",
    "ControlConfig",
    "DynamicsConfig",
    "InitialState",
    "NavigationConfig",
    "PoolConfig",
    "SensorConfig",
    "VehicleConfig",
    "VehicleConfigError",
    "default_config",
    "load_vehicle_config",
    "parse_vehicle_config",
]


class VehicleConfigError(ValueError):
    """A vehicle file that cannot be used.

    Usually a misspelt key, a missing number or a value out of its physical range (a
    negative mass, a zero step rate). The message names the file, line and YAML path of
    the field; fix that field, or delete it to fall back on the bundled value.
    """

    def __init__(self, file: str, path: str, message: str, line: int | None = None) -> None:
        where = file if line is None else f"{file}:{line}"
        self.file = file
        self.path = path
        self.line = line
        super().__init__(f"{where}: {path or '<top>'}: {message}")


class _Checked:
    """Range-checks every number field against its metadata on construction."""

    def __post_init__(self) -> None:
        _check_instance(self, "", "<config>")


# Range metadata of number fields, checked on construction and when loading a file.
_POSITIVE: dict[str, Any] = {"min": 0.0, "open": True}
_NON_NEGATIVE: dict[str, Any] = {"min": 0.0}
_ANY: dict[str, Any] = {}
_FRACTION: dict[str, Any] = {"min": 0.0, "max": 1.0}
_GAIN: dict[str, Any] = {"min": 0.0, "max": 1.0, "open": True}


@dataclass(frozen=True)
class Axes(_Checked):
    """One number per degree of freedom: surge, sway, heave (N, m, kg) and yaw (N m, kg m^2)."""

    surge: float = field(metadata=_POSITIVE)
    sway: float = field(metadata=_POSITIVE)
    heave: float = field(metadata=_POSITIVE)
    yaw: float = field(metadata=_POSITIVE)


@dataclass(frozen=True)
class DynamicsConfig(_Checked):
    """Rigid-body-plus-added-mass model of each axis: m dv/dt = tau - k v - kq |v| v."""

    mass: Axes
    linear_damping: Axes
    quadratic_damping: Axes
    thrust_limit: Axes
    thruster_lag_s: float = field(metadata=_POSITIVE)
    net_buoyancy_n: float = field(metadata=_ANY)
    radius_m: float = field(metadata=_NON_NEGATIVE)
    half_height_m: float = field(metadata=_NON_NEGATIVE)


@dataclass(frozen=True)
class PoolConfig(_Checked):
    """A rectangular pool; origin at the south-west corner at the surface."""

    length_m: float = field(metadata=_POSITIVE)
    width_m: float = field(metadata=_POSITIVE)
    depth_m: float = field(metadata=_POSITIVE)
    current_north_m_s: float = field(metadata=_ANY)
    current_east_m_s: float = field(metadata=_ANY)


@dataclass(frozen=True)
class SensorConfig(_Checked):
    """Noise levels and the scanning sonar's geometry."""

    depth_sd_m: float = field(metadata=_NON_NEGATIVE)
    compass_sd_deg: float = field(metadata=_NON_NEGATIVE)
    gyro_sd_deg_s: float = field(metadata=_NON_NEGATIVE)
    sonar_range_sd_m: float = field(metadata=_NON_NEGATIVE)
    sonar_revolution_s: float = field(metadata=_POSITIVE)
    sonar_max_range_m: float = field(metadata=_POSITIVE)
    surface_clutter_depth_m: float = field(metadata=_NON_NEGATIVE)
    surface_clutter_max_fraction: float = field(metadata=_FRACTION)
    sonar_vertical_beam_deg: float = field(metadata={"min": 0.0, "max": 180.0, "open": True})


@dataclass(frozen=True)
class NavigationConfig(_Checked):
    """Filters: the horizontal EKF, FIX_XY, depth and heading filters."""

    near_normal_deg: float = field(metadata=_POSITIVE)
    gate_sigma: float = field(metadata=_POSITIVE)
    gate_max_m: float = field(metadata=_POSITIVE)
    fix_min_returns: float = field(metadata=_POSITIVE)
    fix_inlier_m: float = field(metadata=_POSITIVE)
    process_accel_sd_m_s2: float = field(metadata=_POSITIVE)
    current_sd_m_s: float = field(metadata=_POSITIVE)
    current_walk_m_s: float = field(metadata=_POSITIVE)
    depth_alpha: float = field(metadata=_GAIN)
    depth_beta: float = field(metadata=_GAIN)
    compass_alpha: float = field(metadata=_GAIN)


@dataclass(frozen=True)
class AxisGains(_Checked):
    """A cascade: v_ref = clamp(kp e, v_max); tau = m kv (v_ref - v) + damping(v_ref) + ki∫e."""

    kp: float = field(metadata=_POSITIVE)
    v_max: float = field(metadata=_POSITIVE)
    kv: float = field(metadata=_POSITIVE)
    ki: float = field(metadata=_NON_NEGATIVE)


@dataclass(frozen=True)
class ControlConfig(_Checked):
    """Autopilot gains and guidance ranges."""

    depth: AxisGains
    heading: AxisGains
    horizontal: AxisGains
    lrm_u_max_m_s: float = field(metadata=_POSITIVE)
    lrm_hold_range_m: float = field(metadata=_NON_NEGATIVE)
    goto_far_m: float = field(metadata=_POSITIVE)
    goto_near_m: float = field(metadata=_POSITIVE)
    goto_hysteresis_m: float = field(metadata=_NON_NEGATIVE)
    docking_arrive_m: float = field(metadata=_POSITIVE)
    docking_settle_s: float = field(metadata=_NON_NEGATIVE)
    surface_release_m: float = field(metadata=_NON_NEGATIVE)


@dataclass(frozen=True)
class InitialState(_Checked):
    """Where the vehicle is when the simulation starts."""

    x_m: float = field(metadata=_ANY)
    y_m: float = field(metadata=_ANY)
    z_m: float = field(metadata=_NON_NEGATIVE)
    psi_deg: float = field(metadata=_ANY)


@dataclass(frozen=True)
class VehicleConfig:
    """Everything the simulator needs about the vehicle and its pool.

    Build one with `default_config`, `load_vehicle_config` or, in code,
    ``dataclasses.replace(default_config(), watchdog_s=5.0)``.
    """

    step_hz: float = field(metadata={"min": 20.0})
    watchdog_s: float = field(metadata=_POSITIVE)
    dynamics: DynamicsConfig
    pool: PoolConfig
    sensors: SensorConfig
    navigation: NavigationConfig
    control: ControlConfig
    initial: InitialState

    def __post_init__(self) -> None:
        _check_instance(self, "", "<config>")
        if self.control.goto_near_m + self.control.goto_hysteresis_m >= (
            self.control.goto_far_m - self.control.goto_hysteresis_m
        ):
            raise VehicleConfigError(
                "<config>",
                "control.goto_near_m",
                "goto_near_m + hysteresis must stay below goto_far_m - hysteresis",
            )
        p, d = self.pool, self.dynamics
        if not (d.radius_m < self.initial.x_m < p.length_m - d.radius_m) or not (
            d.radius_m < self.initial.y_m < p.width_m - d.radius_m
        ):
            raise VehicleConfigError(
                "<config>", "initial", "the initial position must be inside the pool"
            )
        if 2 * d.radius_m >= min(p.length_m, p.width_m) or d.half_height_m >= p.depth_m:
            raise VehicleConfigError("<config>", "pool", "the pool is smaller than the vehicle")

    @property
    def step_s(self) -> float:
        """The fixed integration step, s."""
        return 1.0 / self.step_hz


def _check_instance(obj: object, prefix: str, file: str) -> None:
    for f in dataclasses.fields(obj):  # type: ignore[arg-type]
        value = getattr(obj, f.name)
        path = f"{prefix}{f.name}"
        if dataclasses.is_dataclass(value):
            continue  # checked by its own __post_init__ or by the loader
        _check_number(value, f.metadata, path, file, None)


def _check_number(value: object, meta: Any, path: str, file: str, line: int | None) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise VehicleConfigError(file, path, f"expected a number, got {value!r}", line)
    number = float(value)
    if not math.isfinite(number):
        raise VehicleConfigError(file, path, "expected a finite number", line)
    low = meta.get("min")
    high = meta.get("max")
    if low is not None:
        if meta.get("open") and number <= low:
            raise VehicleConfigError(file, path, f"must be > {low:g}, got {number:g}", line)
        if number < low:
            raise VehicleConfigError(file, path, f"must be >= {low:g}, got {number:g}", line)
    if high is not None and number > high:
        raise VehicleConfigError(file, path, f"must be <= {high:g}, got {number:g}", line)
    return number


def bundled_config_path() -> Path:
    """Path of the bundled ``romeo_vehicle.yaml``."""
    return Path(str(importlib_resources.files("romeo_sim") / "romeo_vehicle.yaml"))


@cache
def default_config() -> VehicleConfig:
    """ROMEO in the default 12 x 8 x 4 m pool, from the bundled vehicle file."""
    path = bundled_config_path()
    return parse_vehicle_config(path.read_text(encoding="utf-8"), str(path), base=None)


def load_vehicle_config(path: str | Path, *, base: VehicleConfig | None = None) -> VehicleConfig:
    """Load a vehicle file; fields it leaves out keep their value in ``base``.

    Args:
        path: the YAML file.
        base: values for the fields the file omits; the bundled ROMEO file by default.

    Raises:
        VehicleConfigError: unreadable file, invalid YAML, an unknown or missing field, or
            a value out of range; the message names the file, line and field.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise VehicleConfigError(str(path), "", f"cannot read vehicle file: {exc}") from None
    return parse_vehicle_config(text, str(path), base=default_config() if base is None else base)


def parse_vehicle_config(
    text: str, file: str = "<vehicle>", *, base: VehicleConfig | None
) -> VehicleConfig:
    """Validate vehicle-file ``text``; with ``base`` None every field is required.

    Raises:
        VehicleConfigError: see `load_vehicle_config`.
    """
    try:
        node = yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = None if mark is None else mark.line + 1
        raise VehicleConfigError(file, "", f"invalid YAML: {exc}", line) from None
    if node is None:
        node = yaml.MappingNode("tag:yaml.org,2002:map", [])
    config: VehicleConfig = _build(VehicleConfig, node, "", file, base)
    return config


def _build(cls: Any, node: yaml.Node, prefix: str, file: str, base: Any) -> Any:
    line = node.start_mark.line + 1 if node.start_mark else None
    if not isinstance(node, yaml.MappingNode):
        raise VehicleConfigError(file, prefix.rstrip("."), "expected a mapping", line)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    given: dict[str, yaml.Node] = {}
    for key_node, value_node in node.value:
        key = key_node.value
        key_line = key_node.start_mark.line + 1
        if key not in fields:
            close = difflib.get_close_matches(str(key), list(fields), n=1)
            hint = f" (did you mean '{close[0]}'?)" if close else ""
            raise VehicleConfigError(
                file,
                f"{prefix}{key}",
                f"unknown field{hint}; known here: {', '.join(fields)}",
                key_line,
            )
        if key in given:
            raise VehicleConfigError(file, f"{prefix}{key}", "given twice", key_line)
        given[key] = value_node
    values: dict[str, Any] = {}
    for name, f in fields.items():
        path = f"{prefix}{name}"
        sub_base = None if base is None else getattr(base, name)
        nested = isinstance(f.type, str) and f.type in _NESTED
        if name not in given:
            if base is None:
                raise VehicleConfigError(file, path, "missing field", line)
            values[name] = sub_base
            continue
        value_node = given[name]
        value_line = value_node.start_mark.line + 1
        if nested:
            values[name] = _build(_NESTED[str(f.type)], value_node, f"{path}.", file, sub_base)
        else:
            if not isinstance(value_node, yaml.ScalarNode):
                raise VehicleConfigError(file, path, "expected a number", value_line)
            raw = yaml.safe_load(value_node.value) if value_node.value else None
            if value_node.style in ("'", '"'):
                raw = value_node.value
            values[name] = _check_number(raw, f.metadata, path, file, value_line)
    try:
        return cls(**values)
    except VehicleConfigError as exc:
        raise VehicleConfigError(file, f"{prefix}{exc.path}", _bare(exc), line) from None


def _bare(exc: VehicleConfigError) -> str:
    text = str(exc)
    marker = f"{exc.path or '<top>'}: "
    return text.split(marker, 1)[1] if marker in text else text


_NESTED: dict[str, type] = {
    "Axes": Axes,
    "AxisGains": AxisGains,
    "ControlConfig": ControlConfig,
    "DynamicsConfig": DynamicsConfig,
    "InitialState": InitialState,
    "NavigationConfig": NavigationConfig,
    "PoolConfig": PoolConfig,
    "SensorConfig": SensorConfig,
}
