"""Vehicle profiles: the only vehicle-specific part of coral.

A profile (YAML) lists the commands a vehicle accepts, their parameters (name, type,
unit, range), the reply kinds each can produce, the vehicle resources each drives, a
nominal duration (and optionally a work time per reply kind, for timed analysis), and for
tracking (space-trap) queries the tracking criterion; optionally the vehicle's workspace,
which plots draw, and the timing assumptions timed analysis proves under. The schema is
documented in ``docs/profiles.md``; ROMEO's profile (Table 1 of the paper) is bundled.
"""

from __future__ import annotations

import functools
import math
import re
from dataclasses import dataclass, field
from importlib import resources as importlib_resources
from pathlib import Path
from typing import Literal, cast

from coral_lang import units
from coral_lang.diagnostics import ProfileError, did_you_mean
from coral_lang.safefile import PROFILE_LIMIT, UnreadableFile, read_text_file
from coral_lang.timing import DEFAULT_REPLY_LATENCY_S, DEFAULT_TOLERANCE, ProfileTiming
from coral_lang.yamlsource import Plain, Problems, YamlDocument, expect_keys, load_yaml

ParamType = Literal["float", "int", "string"]
CommandKind = Literal["task", "query", "action"]
PARAM_TYPES: tuple[str, ...] = ("float", "int", "string")
COMMAND_KINDS: tuple[str, ...] = ("task", "query", "action")
TIME_OUT = "time_out"
#: The signals a ``space_trap`` may track (their meaning: ``docs/profiles.md``).
SPACE_TRAP_SIGNALS: tuple[str, ...] = ("depth", "heading", "xy", "xypsi", "docked")


@dataclass(frozen=True)
class ParamSpec:
    """One parameter of a command. ``minimum``/``maximum`` are inclusive, in ``unit``."""

    name: str
    type: ParamType
    unit: str | None = None
    minimum: float | None = None
    maximum: float | None = None
    description: str = ""

    def describe(self) -> str:
        """E.g. ``z: float [m] in [0, 500]``."""
        text = f"{self.name}: {self.type}"
        if self.unit:
            text += f" [{self.unit}]"
        if self.minimum is not None or self.maximum is not None:
            low = "-inf" if self.minimum is None else f"{self.minimum:g}"
            high = "inf" if self.maximum is None else f"{self.maximum:g}"
            text += f" in [{low}, {high}]"
        return text


@dataclass(frozen=True)
class SpaceTrap:
    """The paper's tracking criterion for a query: the signal tracks its reference
    "of order n" when every derivative k <= n stayed within ``eps[k]`` over the last
    ``window_s`` seconds."""

    signal: str
    order: int
    eps: tuple[float, ...]
    window_s: float


@dataclass(frozen=True)
class Workspace:
    """Where the vehicle works (a pool, a survey box), in the missions' local frame in
    metres: ``x`` north from ``x_min`` to ``x_max``, ``y`` east from ``y_min`` to ``y_max``.

    Only drawn (``coral-run``'s telemetry plot outlines it), never enforced: a geofence
    would have to be the vehicle's own, and a command's ranges already bound its targets.
    """

    x_min: float
    x_max: float
    y_min: float
    y_max: float


@dataclass(frozen=True)
class CommandSpec:
    """A command of the vehicle, as the profile declares it."""

    name: str
    kind: CommandKind
    params: tuple[ParamSpec, ...]
    replies: tuple[str, ...]
    reply_meanings: tuple[tuple[str, str], ...]
    resources: tuple[str, ...]
    duration_s: float
    description: str = ""
    space_trap: SpaceTrap | None = None
    work_s: tuple[tuple[str, float, float], ...] = ()

    def work_interval(self, kind: str, tolerance: float) -> tuple[float, float]:
        """The vehicle's work time for a ``kind`` reply, as [min, max] seconds.

        What the profile's ``work_s`` gives for ``kind``, else ``duration_s`` spread by
        ``tolerance`` (the profile's `ProfileTiming.tolerance`). Measured from the
        command's arrival at the vehicle, except a query's ``done``: from the start of
        the task it watches (``docs/analysis-methods.md``, timed analysis).
        """
        for name, low, high in self.work_s:
            if name == kind:
                return low, high
        return self.duration_s * (1.0 - tolerance), self.duration_s * (1.0 + tolerance)

    def param(self, name: str) -> ParamSpec | None:
        """The parameter called ``name``, or None."""
        return next((p for p in self.params if p.name == name), None)

    def signature(self) -> str:
        """E.g. ``DEPTH?(z, time_out) -> done | timeout``."""
        return (
            f"{self.name}({', '.join(p.name for p in self.params)}) -> {' | '.join(self.replies)}"
        )

    def canonical(self) -> dict[str, object]:
        """What the command means to the vehicle and the runtime, as plain JSON data.

        A certificate records this for every command its mission uses, so that a
        profile edited after verification is noticed. It keeps everything that can
        change how a run behaves or what verification assumed (kind, parameters with
        their types, units and ranges, reply kinds in order, resources, nominal
        duration, tracking criterion) and leaves out the descriptions and reply
        meanings, which are for people: rewording them keeps a certificate valid.
        """
        trap = self.space_trap
        return {
            "kind": self.kind,
            "params": [
                {
                    "name": p.name,
                    "type": p.type,
                    "unit": p.unit,
                    "min": p.minimum,
                    "max": p.maximum,
                }
                for p in self.params
            ],
            "replies": list(self.replies),
            "resources": list(self.resources),
            "duration_s": self.duration_s,
            "space_trap": None
            if trap is None
            else {
                "signal": trap.signal,
                "order": trap.order,
                "eps": list(trap.eps),
                "window_s": trap.window_s,
            },
        } | self._canonical_work()

    def _canonical_work(self) -> dict[str, object]:
        """``{"work_s": {kind: [min, max]}}`` when the command declares work times, else
        nothing: a profile without them keeps the canonical form (and so the digest of
        every certificate) it had before work times existed. A mapping, so reordering
        the entries in the file changes nothing."""
        if not self.work_s:
            return {}
        return {"work_s": {kind: [low, high] for kind, low, high in self.work_s}}


@dataclass(frozen=True)
class VehicleProfile:
    """Everything coral knows about one vehicle's command interface."""

    name: str
    description: str
    resources: tuple[str, ...]
    commands: tuple[CommandSpec, ...]
    file: str
    workspace: Workspace | None = None
    timing: ProfileTiming = field(default_factory=ProfileTiming)

    def command(self, name: str) -> CommandSpec | None:
        """The command called ``name``, or None."""
        return next((c for c in self.commands if c.name == name), None)

    def canonical_timing(self) -> dict[str, object] | None:
        """The ``timing`` block as plain JSON data, or None when it is the default.

        For what a certificate records: None for a profile without a ``timing`` block
        (or one that spells out the defaults, which means the same), so that adding
        timed analysis leaves the digest of every existing certificate as it was.
        """
        if self.timing == ProfileTiming():
            return None
        return {
            "tolerance": self.timing.tolerance,
            "reply_latency_s": self.timing.reply_latency_s,
        }

    @property
    def command_names(self) -> tuple[str, ...]:
        """Command names in profile order."""
        return tuple(c.name for c in self.commands)


_PROFILE_NAME = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.-]{0,63}")


def bundled_profile_path(system: str) -> Path | None:
    """Path of the bundled profile for ``system`` (``ROMEO`` -> ``romeo.yaml``), if any.

    ``system`` becomes a file name, so only plain names of up to 64 characters are
    looked up: a 300-character vehicle name made the file system raise "file name too
    long", and a name with ``/`` or ``..`` must never reach outside the folder.
    """
    if not _PROFILE_NAME.fullmatch(system) or ".." in system:
        return None
    candidate = importlib_resources.files("coral_lang") / "profiles" / f"{system.lower()}.yaml"
    path = Path(str(candidate))
    return path if path.is_file() else None


def bundled_profiles() -> list[str]:
    """Names of the vehicles whose profiles ship with coral."""
    folder = Path(str(importlib_resources.files("coral_lang") / "profiles"))
    return sorted(p.stem.upper() for p in folder.glob("*.yaml"))


def load_profile(path: str | Path) -> VehicleProfile:
    """Load and validate a profile file.

    Raises:
        ProfileError: unreadable file, invalid YAML, or a field that breaks the schema;
            the message names the file, line, column and YAML path of the field.
    """
    path = Path(path)
    try:
        text = read_text_file(path, PROFILE_LIMIT)  # regular files only, at most 1 MB
    except UnreadableFile as exc:
        raise ProfileError(str(path), "", f"cannot read profile: {exc.reason}") from None
    return parse_profile(text, str(path))


def load_bundled_profile(system: str) -> VehicleProfile:
    """Load the bundled profile for ``system``; ProfileError if there is none.

    Profiles are immutable, so a loaded one is reused until its file changes: every
    compile needs it, and YAML validation would otherwise dominate small compiles.
    """
    path = bundled_profile_path(system)
    if path is None:
        known = ", ".join(bundled_profiles())
        raise ProfileError(
            system, "", f"no bundled profile for vehicle '{system}' (bundled: {known})"
        )
    return _load_cached(str(path), path.stat().st_mtime_ns)


@functools.lru_cache(maxsize=16)
def _load_cached(path: str, mtime_ns: int) -> VehicleProfile:
    del mtime_ns  # part of the cache key only
    return load_profile(path)


def parse_profile(text: str, file: str = "<profile>") -> VehicleProfile:
    """Validate profile YAML ``text`` into a `VehicleProfile`.

    Raises:
        ProfileError: the text is not YAML coral reads, or breaks the schema. Every
            mistake is reported, each with the file, line, column and field path
            (``commands.DEPTH?.params[1].unit``), in one error (`ProfileError.errors`).
    """
    doc = load_yaml(text, file)
    root = _mapping(doc, doc.data, "")
    problems = Problems()
    problems.check(
        expect_keys,
        doc,
        root,
        "",
        ["vehicle", "commands"],
        ["description", "resources", "version", "workspace", "timing"],
    )
    name = problems.check(_vehicle_name, doc, root["vehicle"]) if "vehicle" in root else None
    if "version" in root:
        problems.check(_version, doc, root["version"])
    listed = problems.check(_string_list, doc, root.get("resources", []), "resources")
    resources = tuple(listed) if listed is not None else None
    commands = None
    if "commands" in root:
        commands = problems.check(_commands, doc, root["commands"], resources)
    description = problems.check(_string, doc, root.get("description", ""), "description")
    workspace = None
    if "workspace" in root:
        workspace = problems.check(_workspace, doc, root["workspace"])
    timing: ProfileTiming | None = ProfileTiming()
    if "timing" in root:
        timing = problems.check(_timing, doc, root["timing"])
    problems.raise_any()
    assert name is not None and commands is not None and description is not None
    assert timing is not None
    return VehicleProfile(
        name=name,
        description=description,
        resources=resources or (),
        commands=commands,
        file=file,
        workspace=workspace,
        timing=timing,
    )


def _timing(doc: YamlDocument, node: Plain) -> ProfileTiming:
    """``timing: {tolerance: 0.2, reply_latency_s: 0.1}``, both optional (defaults:
    `DEFAULT_TOLERANCE`, `DEFAULT_REPLY_LATENCY_S`)."""
    spec = _mapping(doc, node, "timing")
    problems = Problems()
    problems.check(expect_keys, doc, spec, "timing", [], ["tolerance", "reply_latency_s"])
    tolerance: float | None = DEFAULT_TOLERANCE
    if "tolerance" in spec:
        tolerance = problems.check(_tolerance, doc, spec["tolerance"], "timing.tolerance")
    latency: float | None = DEFAULT_REPLY_LATENCY_S
    if "reply_latency_s" in spec:
        latency = problems.check(_latency, doc, spec["reply_latency_s"], "timing.reply_latency_s")
    problems.raise_any()
    assert tolerance is not None and latency is not None
    return ProfileTiming(tolerance=tolerance, reply_latency_s=latency)


def _latency(doc: YamlDocument, node: Plain, path: str) -> float:
    latency = _number(doc, node, path)
    if latency < 0:
        raise doc.error(path, f"reply latency must be >= 0 seconds, got {latency:g}")
    return latency


def _tolerance(doc: YamlDocument, node: Plain, path: str) -> float:
    tolerance = _number(doc, node, path)
    if not 0.0 <= tolerance < 1.0:
        raise doc.error(
            path, f"tolerance must be at least 0 and below 1 (a fraction), got {tolerance:g}"
        )
    return tolerance


def _vehicle_name(doc: YamlDocument, node: Plain) -> str:
    name = _string(doc, node, "vehicle")
    if not name.isidentifier():
        raise doc.error(
            "vehicle", f"vehicle name '{name}' must be an identifier (letters, digits, _)"
        )
    return name


def _commands(
    doc: YamlDocument, node: Plain, resources: tuple[str, ...] | None
) -> tuple[CommandSpec, ...]:
    """Every command; ``resources`` None: the profile's own list was malformed, so
    which resources a command may use is not checked."""
    commands_node = _mapping(doc, node, "commands")
    if not commands_node:
        raise doc.error("commands", "a profile must declare at least one command")
    problems = Problems()
    commands = [
        problems.check(_command, doc, name, spec, f"commands.{name}", resources)
        for name, spec in commands_node.items()
    ]
    problems.raise_any()
    return tuple(c for c in commands if c is not None)


def _workspace(doc: YamlDocument, node: Plain) -> Workspace:
    """``workspace: {x: [min, max], y: [min, max]}``, metres, each min < max."""
    spec = _mapping(doc, node, "workspace")
    problems = Problems()
    problems.check(expect_keys, doc, spec, "workspace", ["x", "y"], [])
    axes = [
        problems.check(_axis, doc, spec[axis], f"workspace.{axis}")
        for axis in ("x", "y")
        if axis in spec
    ]
    problems.raise_any()
    bounds = [bound for axis in axes if axis is not None for bound in axis]
    return Workspace(*bounds)


def _axis(doc: YamlDocument, node: Plain, path: str) -> tuple[float, float]:
    pair = _list(doc, node, path)
    if len(pair) != 2:
        raise doc.error(path, f"expected [min, max] in metres, got {len(pair)} values")
    low, high = (_number(doc, value, f"{path}[{i}]") for i, value in enumerate(pair))
    if low >= high:
        raise doc.error(path, f"min {low:g} must be below max {high:g}")
    return low, high


def _command(
    doc: YamlDocument, name: str, node: Plain, path: str, resources: tuple[str, ...] | None
) -> CommandSpec:
    problems = Problems()
    if not (name.rstrip("?").isidentifier() and name.count("?") <= 1):
        problems.add(
            doc.error(
                path, f"command name '{name}' must be an identifier, optionally ending in '?'"
            )
        )
    spec = problems.check(_mapping, doc, node, path)
    if spec is None:
        problems.raise_any()
    assert spec is not None
    problems.check(
        expect_keys,
        doc,
        spec,
        path,
        ["kind", "replies"],
        ["params", "resources", "duration_s", "description", "space_trap", "work_s"],
    )
    kind = (
        problems.check(_command_kind, doc, spec["kind"], f"{path}.kind") if "kind" in spec else None
    )
    params = problems.check(_params, doc, spec.get("params", []), f"{path}.params")
    replies = None
    if "replies" in spec:
        replies = problems.check(_replies, doc, spec["replies"], f"{path}.replies")
    used = problems.check(
        _used_resources, doc, spec.get("resources", []), f"{path}.resources", resources
    )
    duration = problems.check(_duration, doc, spec.get("duration_s", 0.0), f"{path}.duration_s")
    trap = None
    if "space_trap" in spec:
        if kind is not None and kind != "query":
            problems.add(
                doc.error(f"{path}.space_trap", "only queries (kind: query) have a space_trap")
            )
        else:
            trap = problems.check(_space_trap, doc, spec["space_trap"], f"{path}.space_trap")
    description = problems.check(_string, doc, spec.get("description", ""), f"{path}.description")
    if kind == "query":
        if params is not None:
            problems.check(_query_time_out, doc, params, path)
        if replies is not None and "timeout" not in replies[0]:
            problems.add(doc.error(f"{path}.replies", "a query must be able to reply 'timeout'"))
    work: tuple[tuple[str, float, float], ...] | None = ()
    if "work_s" in spec:
        timed_query = kind == "query" and params is not None and _has_time_out(params)
        work = problems.check(
            _work_times,
            doc,
            spec["work_s"],
            f"{path}.work_s",
            None if replies is None else replies[0],
            timed_query,
        )
    problems.raise_any()
    assert kind is not None and params is not None and replies is not None
    assert used is not None and duration is not None and description is not None
    assert work is not None
    return CommandSpec(
        name=name,
        kind=kind,
        params=params,
        replies=replies[0],
        reply_meanings=replies[1],
        resources=used,
        duration_s=duration,
        description=description,
        space_trap=trap,
        work_s=work,
    )


def _has_time_out(params: tuple[ParamSpec, ...]) -> bool:
    """True if one of ``params`` is the query's ``time_out``."""
    return any(p.name == TIME_OUT for p in params)


def _work_times(
    doc: YamlDocument,
    node: Plain,
    path: str,
    replies: tuple[str, ...] | None,
    has_time_out: bool,
) -> tuple[tuple[str, float, float], ...]:
    """``work_s: {kind: [min, max]}``: per reply kind, the vehicle's work time.

    ``replies`` None: the command's reply list was malformed (already reported), so the
    kinds are not checked against it. A query with a ``time_out`` may not give
    ``timeout``: when it times out follows from the time-out the mission passes.
    """
    spec = _mapping(doc, node, path)
    problems = Problems()
    work: list[tuple[str, float, float]] = []
    for kind, value in spec.items():
        where = f"{path}.{kind}"
        if replies is not None and kind not in replies:
            problems.add(
                doc.error(
                    where,
                    f"'{kind}' is not a reply of this command{did_you_mean(kind, replies)}; "
                    f"its replies: {', '.join(replies)}",
                )
            )
        elif kind == "timeout" and has_time_out:
            problems.add(
                doc.error(
                    where,
                    "a query's 'timeout' takes the time-out the mission gives it; "
                    "declare the work time of its other replies only",
                )
            )
        interval = problems.check(_work_interval, doc, value, where)
        if interval is not None:
            work.append((kind, *interval))
    problems.raise_any()
    return tuple(work)


def _work_interval(doc: YamlDocument, node: Plain, path: str) -> tuple[float, float]:
    """``[min, max]`` seconds, finite, 0 <= min <= max."""
    pair = _list(doc, node, path)
    if len(pair) != 2:
        raise doc.error(path, f"expected [min, max] in seconds, got {len(pair)} values")
    problems = Problems()
    bounds = [problems.check(_number, doc, value, f"{path}[{i}]") for i, value in enumerate(pair)]
    problems.raise_any()
    low, high = (b for b in bounds if b is not None)
    if low < 0:
        raise doc.error(f"{path}[0]", f"work time must be >= 0 seconds, got {low:g}")
    if low > high:
        raise doc.error(path, f"min {low:g} s is greater than max {high:g} s")
    return low, high


def _command_kind(doc: YamlDocument, node: Plain, path: str) -> CommandKind:
    kind = _string(doc, node, path)
    if kind not in COMMAND_KINDS:
        raise doc.error(path, f"kind must be one of {', '.join(COMMAND_KINDS)}, not '{kind}'")
    return cast(CommandKind, kind)


def _params(doc: YamlDocument, node: Plain, path: str) -> tuple[ParamSpec, ...]:
    problems = Problems()
    params = [
        problems.check(_param, doc, p, f"{path}[{i}]") for i, p in enumerate(_list(doc, node, path))
    ]
    seen: set[str] = set()
    for i, param in enumerate(params):
        if param is None:
            continue
        if param.name in seen:
            problems.add(doc.error(f"{path}[{i}].name", f"parameter '{param.name}' declared twice"))
        seen.add(param.name)
    problems.raise_any()
    return tuple(p for p in params if p is not None)


def _query_time_out(doc: YamlDocument, params: tuple[ParamSpec, ...], path: str) -> None:
    time_out = next((p for p in params if p.name == TIME_OUT), None)
    if time_out is None:
        raise doc.error(f"{path}.params", f"a query must take a '{TIME_OUT}' parameter")
    if time_out.unit is None or units.dimension(time_out.unit) != "time":
        raise doc.error(f"{path}.params", f"'{TIME_OUT}' must have a time unit such as s")


def _used_resources(
    doc: YamlDocument, node: Plain, path: str, resources: tuple[str, ...] | None
) -> tuple[str, ...]:
    used = tuple(_string_list(doc, node, path))
    if resources is None:
        return used
    problems = Problems()
    for i, resource in enumerate(used):
        if resource not in resources:
            problems.add(
                doc.error(
                    f"{path}[{i}]",
                    f"unknown resource '{resource}'{did_you_mean(resource, resources)}; "
                    f"declare it under 'resources' (have: {', '.join(resources) or 'none'})",
                )
            )
    problems.raise_any()
    return used


def _duration(doc: YamlDocument, node: Plain, path: str) -> float:
    duration = _number(doc, node, path)
    if duration < 0:
        raise doc.error(path, "duration must be >= 0 seconds")
    return duration


def _param(doc: YamlDocument, node: Plain, path: str) -> ParamSpec:
    spec = _mapping(doc, node, path)
    problems = Problems()
    problems.check(
        expect_keys, doc, spec, path, ["name", "type"], ["unit", "min", "max", "description"]
    )
    name = (
        problems.check(_param_name, doc, spec["name"], f"{path}.name") if "name" in spec else None
    )
    type_ = (
        problems.check(_param_type, doc, spec["type"], f"{path}.type") if "type" in spec else None
    )
    unit = None
    if spec.get("unit") is not None:
        unit = problems.check(_unit, doc, spec["unit"], f"{path}.unit")
        if unit is not None and type_ == "string":
            problems.add(doc.error(f"{path}.unit", "a string parameter has no unit"))
    minimum = maximum = None
    if spec.get("min") is not None:
        minimum = problems.check(_number, doc, spec["min"], f"{path}.min")
    if spec.get("max") is not None:
        maximum = problems.check(_number, doc, spec["max"], f"{path}.max")
    if minimum is not None and maximum is not None and minimum > maximum:
        problems.add(doc.error(f"{path}.min", f"min {minimum:g} is greater than max {maximum:g}"))
    if type_ == "string" and (minimum is not None or maximum is not None):
        problems.add(doc.error(path, "a string parameter has no range"))
    description = problems.check(_string, doc, spec.get("description", ""), f"{path}.description")
    problems.raise_any()
    assert name is not None and type_ is not None and description is not None
    return ParamSpec(
        name=name,
        type=type_,
        unit=unit,
        minimum=minimum,
        maximum=maximum,
        description=description,
    )


def _param_name(doc: YamlDocument, node: Plain, path: str) -> str:
    name = _string(doc, node, path)
    if not name.isidentifier():
        raise doc.error(path, f"parameter name '{name}' must be an identifier")
    return name


def _param_type(doc: YamlDocument, node: Plain, path: str) -> ParamType:
    type_ = _string(doc, node, path)
    if type_ not in PARAM_TYPES:
        raise doc.error(path, f"type must be one of {', '.join(PARAM_TYPES)}, not '{type_}'")
    return cast(ParamType, type_)


def _unit(doc: YamlDocument, node: Plain, path: str) -> str:
    unit = _string(doc, node, path)
    if not units.is_unit(unit):
        raise doc.error(path, f"unknown unit '{unit}'{did_you_mean(unit, units.UNITS)}")
    return unit


def _replies(
    doc: YamlDocument, node: Plain, path: str
) -> tuple[tuple[str, ...], tuple[tuple[str, str], ...]]:
    if isinstance(node, list):
        names = _string_list(doc, node, path)
        meanings = [(n, "") for n in names]
    elif isinstance(node, dict):
        meanings = [(k, _string(doc, v, f"{path}.{k}")) for k, v in node.items()]
        names = [k for k, _ in meanings]
    else:
        raise doc.error(path, "expected a list of reply kinds or a mapping reply -> meaning")
    if not names:
        raise doc.error(path, "a command must produce at least one reply kind")
    problems = Problems()
    for i, reply in enumerate(names):
        if not reply.isidentifier():
            problems.add(doc.error(f"{path}[{i}]", f"reply kind '{reply}' must be an identifier"))
        elif reply == "ignore":
            problems.add(
                doc.error(f"{path}[{i}]", "'ignore' is reserved for missions that drop a reply")
            )
    if len(set(names)) != len(names):
        problems.add(doc.error(path, "a reply kind is listed twice"))
    problems.raise_any()
    return tuple(names), tuple(meanings)


def _space_trap(doc: YamlDocument, node: Plain, path: str) -> SpaceTrap:
    spec = _mapping(doc, node, path)
    problems = Problems()
    problems.check(expect_keys, doc, spec, path, ["signal", "order", "eps", "window_s"], [])
    order = problems.check(_order, doc, spec["order"], f"{path}.order") if "order" in spec else None
    eps = problems.check(_tolerances, doc, spec["eps"], f"{path}.eps") if "eps" in spec else None
    if order is not None and eps is not None and len(eps) != order + 1:
        problems.add(
            doc.error(
                f"{path}.eps",
                f"order {order} needs {order + 1} tolerances "
                f"(one per derivative 0..{order}), got {len(eps)}",
            )
        )
    window = None
    if "window_s" in spec:
        window = problems.check(_window, doc, spec["window_s"], f"{path}.window_s")
    signal = None
    if "signal" in spec:
        signal = problems.check(_signal, doc, spec["signal"], f"{path}.signal")
    problems.raise_any()
    assert order is not None and eps is not None and window is not None and signal is not None
    return SpaceTrap(signal=signal, order=order, eps=eps, window_s=window)


def _order(doc: YamlDocument, node: Plain, path: str) -> int:
    if not isinstance(node, int) or isinstance(node, bool) or node < 0:
        raise doc.error(path, "order must be a whole number >= 0")
    return node


def _tolerances(doc: YamlDocument, node: Plain, path: str) -> tuple[float, ...]:
    eps = tuple(_number(doc, e, f"{path}[{i}]") for i, e in enumerate(_list(doc, node, path)))
    if any(e <= 0 for e in eps):
        raise doc.error(path, "every tolerance must be > 0")
    return eps


def _window(doc: YamlDocument, node: Plain, path: str) -> float:
    window = _number(doc, node, path)
    if window <= 0:
        raise doc.error(path, "window_s must be > 0")
    return window


def _signal(doc: YamlDocument, node: Plain, path: str) -> str:
    signal = _string(doc, node, path)
    if signal not in SPACE_TRAP_SIGNALS:
        raise doc.error(
            path,
            f"unknown space-trap signal '{signal}'{did_you_mean(signal, SPACE_TRAP_SIGNALS)}; "
            f"known signals: {', '.join(SPACE_TRAP_SIGNALS)}",
        )
    return signal


def _mapping(doc: YamlDocument, node: Plain, path: str) -> dict[str, Plain]:
    if not isinstance(node, dict):
        raise doc.error(path, f"expected a mapping, got {_kind(node)}")
    return node


def _list(doc: YamlDocument, node: Plain, path: str) -> list[Plain]:
    if not isinstance(node, list):
        raise doc.error(path, f"expected a list, got {_kind(node)}")
    return node


def _string(doc: YamlDocument, node: Plain, path: str) -> str:
    if not isinstance(node, str):
        raise doc.error(path, f"expected text, got {_kind(node)}")
    return node


def _string_list(doc: YamlDocument, node: Plain, path: str) -> list[str]:
    return [_string(doc, item, f"{path}[{i}]") for i, item in enumerate(_list(doc, node, path))]


def _number(doc: YamlDocument, node: Plain, path: str) -> float:
    if isinstance(node, bool) or not isinstance(node, int | float):
        raise doc.error(path, f"expected a number, got {_kind(node)}")
    if not math.isfinite(node):
        raise doc.error(path, "expected a finite number")
    return float(node)


def _version(doc: YamlDocument, node: Plain) -> int:
    """The profile format ``version``: a positive whole number. Checked although
    nothing reads it yet, so that ``version: "1.2"`` or ``version: -1`` is refused
    now rather than silently accepted and later misread."""
    if isinstance(node, bool) or not isinstance(node, int):
        raise doc.error("version", f"expected a positive whole number, got {_kind(node)}")
    if node < 1:
        raise doc.error("version", f"expected a positive whole number, got {node}")
    return node


def _kind(node: Plain) -> str:
    if node is None:
        return "nothing"
    if isinstance(node, bool):
        return f"a boolean ({str(node).lower()})"
    if isinstance(node, dict):
        return "a mapping"
    if isinstance(node, list):
        return "a list"
    if isinstance(node, str):
        return f"text ('{node}')"
    return f"a number ({node})"
