"""Shared helpers for the simulator tests: a vehicle at working depth with a position fix,
and one scripted pool mission per test session (it is the slowest thing here)."""

from __future__ import annotations

import pytest

from romeo_sim.scenario import MissionResult, run_pool_mission
from romeo_sim.vehicle import Reply, Vehicle


def run(vehicle: Vehicle, seconds: float, *, keep_alive: bool = True) -> list[Reply]:
    """Advance in 1-s chunks, telling the vehicle the controller is alive (no watchdog)."""
    replies: list[Reply] = []
    end = vehicle.time + seconds
    while vehicle.time < end - 1e-9:
        if keep_alive:
            vehicle.heard_from_controller()
        replies += vehicle.advance_to(min(end, vehicle.time + 1.0))
    return replies


def fixed_vehicle(seed: int = 0, depth: float = 2.0) -> Vehicle:
    """A vehicle at ``depth`` heading 90 with FIX_XY done; ids 1-3 used, time about 31 s."""
    vehicle = Vehicle(seed=seed)
    vehicle.command(1, "DEPTH", {"z": depth})
    vehicle.command(2, "HEADING", {"psi": 90.0})
    run(vehicle, 20.0)
    vehicle.command(3, "FIX_XY", {})
    replies = run(vehicle, 10.5)
    assert [r.kind for r in replies if r.command_id == 3] == ["done"], replies
    return vehicle


@pytest.fixture(scope="session")
def mission() -> MissionResult:
    """The paper's pool mission, seed 0."""
    return run_pool_mission(seed=0)
