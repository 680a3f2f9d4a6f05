"""Values as a log stores them: strict JSON for event data, NULL for a missing pose value.

Strict JSON has no NaN or Infinity, and a log must stay readable by any JSON reader, so
these helpers decide, once, how a value that JSON cannot hold is written or refused.
"""

from __future__ import annotations

import enum
import json
import math
from collections.abc import Mapping
from pathlib import Path

from runtime.eventlog.records import EventLogError

__all__ = ["NotJson", "dumps_strict", "finite_seconds", "jsonable", "stored_pose"]


class NotJson(Exception):
    """A value JSON cannot hold, and where in the logged data it was."""

    def __init__(self, where: str, value: object):
        super().__init__(where)
        self.where = where
        self.value = value

    def error(self, prefix: str) -> EventLogError:
        kind = type(self.value).__name__
        return EventLogError(f"{prefix}{self.where} is of type {kind}, which JSON cannot hold")


def jsonable(value: object, where: str) -> object:
    """``value`` as plain JSON types; non-finite floats become None (NaN) or "inf"/"-inf".

    Strict JSON has no NaN or Infinity, and a log must stay readable by any JSON reader, so
    NaN (our "no value", as on the wire) is stored as null and infinities as strings.
    """
    if value is None or isinstance(value, bool | str):
        return value
    if isinstance(value, enum.Enum):
        return jsonable(value.value, where)
    if isinstance(value, int):
        return int(value)
    if isinstance(value, float):
        if math.isfinite(value):
            return float(value)
        if math.isnan(value):
            return None
        return "inf" if value > 0 else "-inf"
    if isinstance(value, Mapping):
        out: dict[str, object] = {}
        for key, item in value.items():
            if isinstance(key, enum.Enum):
                key = key.value
            if isinstance(key, bool) or not isinstance(key, str | int):
                raise NotJson(f"{where} (key {key!r})", key)
            out[str(key)] = jsonable(item, f"{where}[{key!r}]")
        return out
    if isinstance(value, list | tuple):
        return [jsonable(item, f"{where}[{index}]") for index, item in enumerate(value)]
    if isinstance(value, set | frozenset):
        items = [jsonable(item, f"{where} item") for item in value]
        return sorted(items, key=lambda item: json.dumps(item, sort_keys=True))
    tolist = getattr(value, "tolist", None)  # numpy arrays and scalars, without importing numpy
    if callable(tolist):
        return jsonable(tolist(), where)
    raise NotJson(where, value)


def dumps_strict(value: object) -> str:
    """Compact strict JSON (no NaN or Infinity: `jsonable` has replaced them)."""
    return json.dumps(value, separators=(",", ":"), allow_nan=False)


def finite_seconds(value: float, what: str, path: Path) -> float:
    """``value`` as a float; `EventLogError` naming ``path`` unless finite."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        number = math.nan
    if not math.isfinite(number):
        raise EventLogError(f"{path}: {what} must be a finite number of seconds, got {value!r}")
    return number


def stored_pose(value: float | None) -> float | None:
    """A pose value as stored: NaN (no value) becomes NULL."""
    return None if value is None or math.isnan(value) else float(value)
