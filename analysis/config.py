"""coral-check's defaults from a configuration file, found the way ruff and mypy find theirs.

A project keeps its choices (rules ignored, its own vehicle profiles, the search
budgets its missions need) in one place instead of every command line and CI job:

* ``coral.toml`` (keys at the top level), or
* ``pyproject.toml`` with a ``[tool.coral]`` table (a pyproject.toml without one is
  not a coral configuration and the search goes on),

in the current folder or the nearest folder above it; in one folder ``coral.toml``
wins. ``--config FILE`` names the file instead, ``--no-config`` ignores them all. An
option given on the command line overrides the file's value.

Keys (docs/verify.md, "Configuration"): ``select``, ``ignore`` (lists of rule codes or
prefixes), ``profile`` and ``include-path`` (lists of paths, relative to the file's
folder), ``link-rtt``, ``max-states``, ``time-limit``, ``max-edges``,
``max-deadlocks``, ``por``, and for timed analysis ``timed`` (true: ``--timed``),
``link`` (a built-in link profile's name, or a YAML file relative to the file's folder)
``timed-states`` and ``timed-method``. Output choices (``--format``, ``-o``) stay on the command
line: a config file must not make a terminal run print JSON.

A file that cannot be used is a `ConfigError` whose message names the file, the key
and (for a TOML syntax error) the line and column: the command exits 2 and checks
nothing, rather than checking with settings nobody asked for.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from analysis.cli_codes import selector_problem

__all__ = [
    "CONFIG_NAME",
    "KEYS",
    "PYPROJECT_NAME",
    "Config",
    "ConfigError",
    "find_config",
    "load_config",
    "resolve_config",
]

CONFIG_NAME = "coral.toml"
PYPROJECT_NAME = "pyproject.toml"


class ConfigError(Exception):
    """A configuration file that cannot be used; the message says which, where and why."""


@dataclass(frozen=True)
class Config:
    """The settings a configuration file gives; None for a key it does not set.

    Attributes:
        path: The file they came from; None when no file was used.
    """

    path: Path | None = None
    select: tuple[str, ...] | None = None
    ignore: tuple[str, ...] | None = None
    profile: tuple[Path, ...] | None = None
    include_path: tuple[Path, ...] | None = None
    link_rtt: float | None = None
    max_states: int | None = None
    time_limit: float | None = None
    max_edges: int | None = None
    max_deadlocks: int | None = None
    por: bool | None = None
    timed: bool | None = None
    link: str | None = None
    timed_states: int | None = None
    timed_method: str | None = None


# -- finding the file -------------------------------------------------------------------


def find_config(start: Path) -> Path | None:
    """The configuration file for a run started in ``start``: the nearest folder at or
    above it holding ``coral.toml`` or a ``pyproject.toml`` with ``[tool.coral]``."""
    for folder in (start, *start.parents):
        candidate = folder / CONFIG_NAME
        if candidate.is_file():
            return candidate
        pyproject = folder / PYPROJECT_NAME
        if pyproject.is_file() and _tool_table(pyproject) is not None:
            return pyproject
    return None


def resolve_config(explicit: str | Path | None, *, disabled: bool, cwd: Path) -> Config:
    """The settings of a run: from ``explicit`` (``--config``), none (``--no-config``),
    or the file `find_config` finds from ``cwd``."""
    if disabled:
        return Config()
    if explicit is not None:
        path = Path(explicit)
        if not path.is_file():
            why = "it is a directory" if path.is_dir() else "no such file"
            raise ConfigError(f"--config {explicit}: {why}")
        return load_config(path)
    found = find_config(cwd)
    return Config() if found is None else load_config(found)


# -- reading it -------------------------------------------------------------------------


def load_config(path: Path) -> Config:
    """The settings in ``path``: a ``pyproject.toml`` (its ``[tool.coral]`` table, empty
    when it has none) or any other TOML file (its top level)."""
    if path.name == PYPROJECT_NAME:
        table = _tool_table(path) or {}
        where = "tool.coral"
    else:
        table = _read_toml(path)
        where = ""
    return _parse(path, table, where)


def _read_toml(path: Path) -> dict[str, Any]:
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read: {exc.strerror}") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(f"{path}: not UTF-8 text (at byte {exc.start})") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        # tomllib's message ends "(at line L, column C)", or "(at end of document)",
        # which is given a line and column too: an editor jumps to either.
        message = str(exc)
        if message.endswith("(at end of document)"):
            lines = text.split("\n")
            end = f"line {len(lines)}, column {len(lines[-1]) + 1}"
            message = message.replace("(at end of document)", f"(at end of document, {end})")
        raise ConfigError(f"{path}: invalid TOML: {message}") from None


def _tool_table(pyproject: Path) -> dict[str, Any] | None:
    tool = _read_toml(pyproject).get("tool")
    if not isinstance(tool, dict) or "coral" not in tool:
        return None
    table = tool["coral"]
    if not isinstance(table, dict):
        raise ConfigError(f"{pyproject}: [tool.coral] must be a table")
    return table


def _parse(path: Path, table: Mapping[str, Any], where: str) -> Config:
    values: dict[str, Any] = {}
    for key, raw in table.items():
        reader = _READERS.get(key)
        name = f"{where}.{key}" if where else key
        if reader is None:
            hint = " (keys use dashes)" if key.replace("_", "-") in _READERS else ""
            raise ConfigError(f"{path}: unknown key '{name}'{hint}; known keys: {', '.join(KEYS)}")
        try:
            values[key.replace("-", "_")] = reader(raw, path.parent)
        except ValueError as exc:
            raise ConfigError(f"{path}: {name}: {exc}") from None
    return Config(path=path, **values)


def _strings(raw: object) -> list[str]:
    if not isinstance(raw, list) or not all(isinstance(item, str) for item in raw):
        raise ValueError(f"expected a list of strings, got {_show(raw)}")
    return list(raw)


def _codes(raw: object, _folder: Path) -> tuple[str, ...]:
    codes = [code.strip().upper() for code in _strings(raw)]
    problem = selector_problem(codes)
    if problem is not None:
        raise ValueError(problem)
    return tuple(codes)


def _files(raw: object, folder: Path) -> tuple[Path, ...]:
    return tuple(folder / item for item in _strings(raw))


def _folders(raw: object, folder: Path) -> tuple[Path, ...]:
    paths = _files(raw, folder)
    for path in paths:
        if not path.is_dir():
            raise ValueError(f"{path}: no such folder")
    return paths


def _number(raw: object, *, positive: bool) -> float:
    if isinstance(raw, bool) or not isinstance(raw, int | float) or not math.isfinite(raw):
        raise ValueError(f"expected a number, got {_show(raw)}")
    if raw < 0 or (positive and raw == 0):
        raise ValueError(f"must be {'more than 0' if positive else '0 or more'}, got {raw}")
    return float(raw)


def _count(raw: object, _folder: Path) -> int:
    if isinstance(raw, bool) or not isinstance(raw, int):
        raise ValueError(f"expected a whole number, got {_show(raw)}")
    if raw < 1:
        raise ValueError(f"must be at least 1, got {raw}")
    return raw


def _link(raw: object, folder: Path) -> str:
    """A link profile: a built-in name as written, a YAML file relative to ``folder``
    (as ``profile`` paths are); which names exist is checked when it is loaded."""
    if not isinstance(raw, str) or not raw.strip():
        raise ValueError(f"expected a link profile name or YAML file, got {_show(raw)}")
    if Path(raw).suffix.lower() in (".yaml", ".yml"):
        return str(folder / raw)
    return raw


def _method(raw: object, _folder: Path) -> str:
    if raw not in ("auto", "events", "clock"):
        raise ValueError(f"expected 'auto', 'events' or 'clock', got {_show(raw)}")
    return str(raw)


def _flag(raw: object, _folder: Path) -> bool:
    if not isinstance(raw, bool):
        raise ValueError(f"expected true or false, got {_show(raw)}")
    return raw


def _show(raw: object) -> str:
    kind = {bool: "a boolean", str: "a string", list: "a list", dict: "a table"}
    for python_type, name in kind.items():
        if isinstance(raw, python_type):
            return f"{name} ({raw!r})" if python_type is not dict else name
    return repr(raw)


_READERS: dict[str, Callable[[object, Path], Any]] = {
    "select": _codes,
    "ignore": _codes,
    "profile": _files,
    "include-path": _folders,
    "link-rtt": lambda raw, _folder: _number(raw, positive=False),
    "max-states": _count,
    "time-limit": lambda raw, _folder: _number(raw, positive=True),
    "max-edges": _count,
    "max-deadlocks": _count,
    "por": _flag,
    "timed": _flag,
    "link": _link,
    "timed-states": _count,
    "timed-method": _method,
}
KEYS: tuple[str, ...] = tuple(_READERS)
"""The keys a configuration may set, as written in the file."""
