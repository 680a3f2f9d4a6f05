"""What the telemetry plot draws beside the telemetry: workspace, way-points, phases.

`runtime.timeline` merges the logs; this module reads, from the logs and the vehicle's
profile only, the three things that make a track readable (``romeo-sim mission`` has them
from the simulator itself; ``coral-run`` must stay vehicle-agnostic, so it may not ask
`romeo_sim`):

* the **workspace** outline: the profile's ``workspace`` (``docs/profiles.md``), found
  through the profiles the controller log's meta names, else the bundled profile of the
  net's vehicle;
* **way-points**: the ``x`` and ``y`` parameters of every command sent that has both
  (GOTO, LRM, XY?... on ROMEO; any vehicle's GOTO-like commands), converted to metres
  with the profile's units, repeats of the same point dropped;
* **phases**: the mission's own, when its source can be read again and compiles to the
  net the controller ran (same digest) from more than one file: each file is a phase
  (the pool mission's go_to_operating_site, waypoint_navigation, docking, abort), spanning
  the firings of its transitions. Otherwise the legs between way-point commands.

Everything is best-effort: a profile or mission file that has gone or changed gives no
outline or the fallback phases, never an error, because the plots of a run must not fail
on what is only decoration.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Final

from coral_lang import units
from coral_lang.diagnostics import CoralError
from coral_lang.profile import (
    VehicleProfile,
    Workspace,
    load_bundled_profile,
    load_profile,
)
from runtime.timeline import CONTROLLER, Command, MergedTimeline, commands_of

__all__ = [
    "Phase",
    "PlotContext",
    "Waypoint",
    "find_profile",
    "param_metres",
    "plot_context",
    "vehicle_profile",
]

_SAME_POINT_M: Final = 1e-6


@dataclass(frozen=True)
class Waypoint:
    """A target position a command sent, in metres (x north, y east)."""

    x: float
    y: float
    time: float  # when it was sent, controller clock
    command: str
    command_id: int


@dataclass(frozen=True)
class Phase:
    """A named span of the mission on the controller clock."""

    name: str
    start: float
    end: float


@dataclass(frozen=True)
class PlotContext:
    """What the telemetry plot draws besides the samples.

    Attributes:
        workspace: the vehicle's workspace outline, if its profile gives one.
        waypoints: targets of the commands sent, in order of sending.
        phases: consecutive spans of the mission, in time order.
        phase_source: ``"mission"`` (the mission's files) or ``"way-points"`` (legs).
    """

    workspace: Workspace | None = None
    waypoints: tuple[Waypoint, ...] = ()
    phases: tuple[Phase, ...] = ()
    phase_source: str = ""


def plot_context(timeline: MergedTimeline, profile: VehicleProfile | None = None) -> PlotContext:
    """The workspace, way-points and phases of ``timeline``.

    ``profile``: the vehicle's profile; by default the one `vehicle_profile` finds.
    """
    known = profile if profile is not None else vehicle_profile(timeline)
    commands = commands_of(timeline)
    waypoints = _waypoints(commands, known)
    phases = _mission_phases(timeline)
    source = "mission"
    if not phases:
        phases = _legs(timeline, waypoints)
        source = "way-points" if phases else ""
    return PlotContext(
        workspace=None if known is None else known.workspace,
        waypoints=tuple(waypoints),
        phases=tuple(phases),
        phase_source=source,
    )


def vehicle_profile(timeline: MergedTimeline) -> VehicleProfile | None:
    """The profile of the net's vehicle: one the run's meta names, else the bundled one."""
    return find_profile(timeline.vehicle_name, timeline.meta)


def find_profile(wanted: str | None, meta: Mapping[str, object]) -> VehicleProfile | None:
    """The profile of vehicle ``wanted``: one of the files a log's ``meta["profiles"]``
    names (the first readable one when ``wanted`` is None), else the bundled profile of
    ``wanted``; None when there is none. Shared with the watch page (`runtime.watch.info`),
    which has a log's meta and net but no merged timeline."""
    recorded = meta.get("profiles")
    candidates: list[VehicleProfile] = []
    if isinstance(recorded, list):
        for item in recorded:
            if isinstance(item, str):
                try:
                    candidates.append(load_profile(item))
                except CoralError:
                    continue
    for candidate in candidates:
        if wanted is None or candidate.name == wanted:
            return candidate
    if wanted is None:
        return None
    try:
        return load_bundled_profile(wanted)
    except CoralError:
        return None


def _waypoints(commands: list[Command], profile: VehicleProfile | None) -> list[Waypoint]:
    points: list[Waypoint] = []
    for command in commands:
        if command.sent is None:
            continue
        x = _metres(command, "x", profile)
        y = _metres(command, "y", profile)
        if x is None or y is None:
            continue
        if points and math.dist((points[-1].x, points[-1].y), (x, y)) < _SAME_POINT_M:
            continue
        points.append(Waypoint(x, y, command.sent, command.name, command.command_id))
    return points


def _metres(command: Command, name: str, profile: VehicleProfile | None) -> float | None:
    return param_metres(command.name, command.params, name, profile)


def param_metres(
    command: str, params: Mapping[str, object], name: str, profile: VehicleProfile | None
) -> float | None:
    """Parameter ``name`` of ``command`` in metres: logged in the profile's unit, which is
    converted when the profile says it is a length (USV way-points are in km). None when
    the parameter is missing or not a finite number."""
    value = params.get(name)
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        return None
    spec = None if profile is None else profile.command(command)
    param = None if spec is None else spec.param(name)
    unit = None if param is None else param.unit
    if unit is not None and units.dimension(unit) == "length":
        return units.convert(float(value), unit, "m")
    return float(value)


def _mission_phases(timeline: MergedTimeline) -> list[Phase]:
    """Phases by source file, when the mission's files still compile to the logged net."""
    files = _transition_files(timeline)
    if not files or len(set(files.values())) < 2:
        return []
    named: list[tuple[float, str]] = []
    for time, source, event in timeline.events:
        if source != CONTROLLER or event.kind != "fire":
            continue
        transition = event.data.get("transition")
        if isinstance(transition, str):
            phase = files.get(transition) or files.get(transition.split(".", 1)[0])
            if phase is not None:
                named.append((time, phase))
    return _spans(named, timeline.end)


def _transition_files(timeline: MergedTimeline) -> dict[str, str]:
    """Transition name -> the stem of the file that declares it; empty when unknown."""
    path = timeline.meta.get("mission_path")
    if not isinstance(path, str) or timeline.net_digest is None or not Path(path).is_file():
        return {}
    from coral_lang.mission import load_mission

    profiles: list[VehicleProfile] = []
    recorded = timeline.meta.get("profiles")
    try:
        if isinstance(recorded, list):
            profiles = [load_profile(p) for p in recorded if isinstance(p, str)]
        mission = load_mission(path, profiles)
    except (CoralError, OSError):
        return {}
    if mission.net.digest() != timeline.net_digest:
        return {}  # edited since the run: its files may no longer say what ran
    return {t.name: Path(t.span.file).stem for t in mission.net.transitions if t.span is not None}


def _legs(timeline: MergedTimeline, waypoints: list[Waypoint]) -> list[Phase]:
    """One phase per way-point: from the command that sent it to the next one's."""
    if not waypoints:
        return []
    named = [(timeline.start, "start")] if waypoints[0].time > timeline.start else []
    named += [(w.time, f"to ({w.x:g}, {w.y:g})") for w in waypoints]
    return _spans(named, timeline.end)


def _spans(named: list[tuple[float, str]], end: float) -> list[Phase]:
    """Consecutive runs of one name as phases; each ends where the next begins."""
    phases: list[Phase] = []
    for time, name in named:
        if phases and phases[-1].name == name:
            continue
        if phases:
            phases[-1] = Phase(phases[-1].name, phases[-1].start, time)
        phases.append(Phase(name, time, time))
    if phases:
        last = phases[-1]
        phases[-1] = Phase(last.name, last.start, max(end, last.start))
    return phases
