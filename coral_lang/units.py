"""Units a vehicle profile and a mission may use, and conversion between compatible ones.

A mission may write ``z = 250 cm`` for a parameter the profile gives in ``m``; it may not
write ``z = 90 deg``. Conversion is exact scaling within one dimension only.
"""

from __future__ import annotations

import math

# unit -> (dimension, factor to the dimension's base unit)
UNITS: dict[str, tuple[str, float]] = {
    "m": ("length", 1.0),
    "cm": ("length", 0.01),
    "mm": ("length", 0.001),
    "km": ("length", 1000.0),
    "deg": ("angle", 1.0),
    "rad": ("angle", 180.0 / math.pi),
    "s": ("time", 1.0),
    "ms": ("time", 0.001),
    "min": ("time", 60.0),
    "h": ("time", 3600.0),
    "m/s": ("speed", 1.0),
    "knot": ("speed", 1852.0 / 3600.0),
    "deg/s": ("angular_speed", 1.0),
    "N": ("force", 1.0),
}


def is_unit(name: str) -> bool:
    """Whether coral knows the unit ``name``."""
    return name in UNITS


def dimension(unit: str) -> str:
    """The physical dimension of ``unit`` (``length``, ``angle``, ``time``, ...)."""
    return UNITS[unit][0]


def convert(value: float, from_unit: str, to_unit: str) -> float:
    """``value`` in ``from_unit`` expressed in ``to_unit``; ValueError if incompatible."""
    dim_from, factor_from = UNITS[from_unit]
    dim_to, factor_to = UNITS[to_unit]
    if dim_from != dim_to:
        raise ValueError(f"cannot convert {from_unit} ({dim_from}) to {to_unit} ({dim_to})")
    result = value * factor_from / factor_to
    rounded = round(result, 9)
    return rounded if math.isclose(rounded, result, rel_tol=1e-12, abs_tol=1e-12) else result
