"""The paper's pool mission as a fixed script: a stand-in for the CORAL engine.

The driver sends a stage's commands together, then waits until every reply it needs has
come (the queries' ``done``, FIX_XY's ``done``) before the next stage: the simple "send
the next command when the previous query replied" logic of the paper's Petri net, without
the net. Any ``error`` or ``timeout`` stops the mission, which then surfaces the vehicle.
While waiting it tells the vehicle it is alive each poll, as the engine's link would.

Pool coordinates (default 12 x 8 x 4 m pool, origin at the south-west corner, x north
along the 12 m side, y east): the vehicle starts at the surface at (2, 2) facing north;
GET_DOCK records the docking point there after FIX_XY; the operating site is the pool's
centre (6, 4) with heading 0; the four way-points are the corners of a 3 m square
around it, (7.5, 2.5), (7.5, 5.5), (4.5, 5.5), (4.5, 2.5): north-west, north-east,
south-east, south-west corners, flown clockwise seen from above.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from coral_lang.profile import VehicleProfile
from romeo_sim.config import VehicleConfig
from romeo_sim.recorder import Recorder
from romeo_sim.vehicle import Reply, Vehicle

__all__ = [
    "PHASES",
    "MissionResult",
    "Phase",
    "PoolMission",
    "Stage",
    "mission_targets",
    "pool_mission_stages",
    "run_pool_mission",
]

Params = Mapping[str, float | int | str]

_LATE_REPLIES = ("FIX_XY",)  # non-query commands whose outcome comes after a while


@dataclass(frozen=True)
class Stage:
    """Commands sent together; the next stage waits for their final replies."""

    phase: str
    commands: tuple[tuple[str, Params], ...]


@dataclass(frozen=True)
class PoolMission:
    """Geometry and time-outs of the pool mission (defaults fit the default pool)."""

    depth_m: float = 2.0
    fix_heading_deg: float = 90.0
    site: tuple[float, float, float] = (6.0, 4.0, 0.0)
    waypoints: tuple[tuple[float, float], ...] = (
        (7.5, 2.5),
        (7.5, 5.5),
        (4.5, 5.5),
        (4.5, 2.5),
    )
    settle_time_out_s: float = 60.0
    goto_time_out_s: float = 120.0
    waypoint_time_out_s: float = 60.0
    hover_time_out_s: float = 60.0
    docking_time_out_s: float = 150.0


@dataclass(frozen=True)
class Phase:
    """A stretch of the mission on the vehicle clock, as the paper's Figures 7-9."""

    name: str
    start: float
    end: float


@dataclass
class MissionResult:
    """How a scripted run ended, and everything it recorded."""

    completed: bool
    reason: str
    vehicle: Vehicle
    recorder: Recorder
    mission: PoolMission
    phases: list[Phase] = field(default_factory=list)
    final_replies: dict[int, Reply] = field(default_factory=dict)

    @property
    def dock(self) -> tuple[float, float] | None:
        """The docking point GET_DOCK recorded, if any."""
        dock = self.vehicle.dock
        return None if dock is None else (dock[0], dock[1])


PHASES = ("go to operating site", "way-point navigation", "docking")


def pool_mission_stages(mission: PoolMission) -> list[Stage]:
    """The paper's three phases as a fixed sequence of stages."""
    site_x, site_y, site_psi = mission.site
    go, waypoints, docking = PHASES
    stages = [
        Stage(go, (("INIT", {}),)),
        Stage(
            go,
            (
                ("DEPTH", {"z": mission.depth_m}),
                ("HEADING", {"psi": mission.fix_heading_deg}),
                ("DEPTH?", {"z": mission.depth_m, "time_out": mission.settle_time_out_s}),
                (
                    "HEADING?",
                    {"psi": mission.fix_heading_deg, "time_out": mission.settle_time_out_s},
                ),
            ),
        ),
        Stage(go, (("FIX_XY", {}),)),
        Stage(go, (("GET_DOCK", {}),)),
        Stage(
            go,
            (
                ("GOTO", {"x": site_x, "y": site_y, "psi": site_psi}),
                (
                    "XYPSI?",
                    {
                        "x": site_x,
                        "y": site_y,
                        "psi": site_psi,
                        "time_out": mission.goto_time_out_s,
                    },
                ),
            ),
        ),
    ]
    for x, y in mission.waypoints:
        stages.append(
            Stage(
                waypoints,
                (
                    ("LRM", {"x": x, "y": y}),
                    ("XY?", {"x": x, "y": y, "time_out": mission.waypoint_time_out_s}),
                ),
            )
        )
    stages.append(
        Stage(
            docking,
            (
                ("SRM", {"x": site_x, "y": site_y, "psi": site_psi}),
                (
                    "XYPSI?",
                    {
                        "x": site_x,
                        "y": site_y,
                        "psi": site_psi,
                        "time_out": mission.hover_time_out_s,
                    },
                ),
            ),
        )
    )
    stages.append(
        Stage(
            docking,
            (("DOCKING", {}), ("DOCKING?", {"time_out": mission.docking_time_out_s})),
        )
    )
    return stages


def run_pool_mission(
    config: VehicleConfig | None = None,
    *,
    seed: int = 0,
    mission: PoolMission | None = None,
    profile: VehicleProfile | None = None,
    sample_interval: float = 0.5,
    poll_s: float = 0.5,
) -> MissionResult:
    """Run the pool mission offline, as fast as the CPU allows.

    Args:
        config: vehicle file; bundled defaults if None.
        seed: noise seed.
        mission: geometry and time-outs; `PoolMission` defaults if None.
        profile: command profile; bundled ROMEO if None.
        sample_interval: telemetry period of the recorder, s.
        poll_s: how often the driver looks for replies, s (replies carry their own
            vehicle time, so this only delays the next command by at most ``poll_s``).

    Returns:
        The outcome and the recording.
    """
    mission = PoolMission() if mission is None else mission
    vehicle = Vehicle(config, profile, seed=seed)
    recorder = Recorder(sample_interval)
    result = MissionResult(False, "", vehicle, recorder, mission)
    next_id = 1
    phase_name = ""
    phase_start = 0.0
    for stage in pool_mission_stages(mission):
        if stage.phase != phase_name:
            if phase_name:
                result.phases.append(Phase(phase_name, phase_start, vehicle.time))
            phase_name, phase_start = stage.phase, vehicle.time
        awaited: dict[int, str] = {}
        deadline = vehicle.time
        for name, params in stage.commands:
            cid = next_id
            next_id += 1
            for reply in recorder.command(vehicle, cid, name, params):
                if reply.kind == "error":
                    return _abort(result, recorder, vehicle, next_id, reply)
                result.final_replies[cid] = reply
            if name.endswith("?") or name in _LATE_REPLIES:
                awaited[cid] = name
                deadline = max(deadline, vehicle.time + float(params.get("time_out", 0.0)) + 30.0)
        while awaited:
            if vehicle.time > deadline:
                names = ", ".join(awaited.values())
                result.reason = f"no final reply from {names} by {vehicle.time:.1f} s"
                return result
            vehicle.heard_from_controller()
            for reply in recorder.advance_to(vehicle, vehicle.time + poll_s):
                if reply.command_id in awaited:
                    del awaited[reply.command_id]
                    result.final_replies[reply.command_id] = reply
                    if reply.kind != "done":
                        return _abort(result, recorder, vehicle, next_id, reply)
    result.phases.append(Phase(phase_name, phase_start, vehicle.time))
    # Let the record show the vehicle resting at the surface after DOCKING? replied.
    recorder.advance_to(vehicle, vehicle.time + 2.0)
    result.completed = True
    result.reason = f"all queries done; docked at {vehicle.time:.1f} s"
    return result


def _abort(
    result: MissionResult, recorder: Recorder, vehicle: Vehicle, next_id: int, reply: Reply
) -> MissionResult:
    result.reason = (
        f"{reply.command} (id {reply.command_id}) replied {reply.kind} at "
        f"{reply.time:.1f} s: {reply.detail}"
    )
    recorder.command(vehicle, next_id, "SURFACE", {})
    recorder.advance_to(vehicle, vehicle.time + 30.0)
    return result


def mission_targets(mission: PoolMission) -> Sequence[tuple[float, float]]:
    """The site and way-points, for plots."""
    return [(mission.site[0], mission.site[1]), *mission.waypoints]
