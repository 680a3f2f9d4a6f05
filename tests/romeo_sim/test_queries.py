"""Space-trap queries: done for reachable references, timeout for unreachable ones."""

from __future__ import annotations

import pytest

from coral_lang.profile import load_bundled_profile
from romeo_sim.vehicle import Reply, Vehicle
from tests.romeo_sim.conftest import fixed_vehicle, run

PROFILE = load_bundled_profile("ROMEO")


def _window(name: str) -> float:
    spec = PROFILE.command(name)
    assert spec is not None and spec.space_trap is not None
    return spec.space_trap.window_s


def _final(replies: list[Reply], command_id: int) -> Reply:
    (reply,) = [r for r in replies if r.command_id == command_id]
    return reply


def test_depth_query_done_when_depth_tracks_its_reference() -> None:
    vehicle = Vehicle()
    vehicle.command(1, "DEPTH", {"z": 2.0})
    assert vehicle.command(2, "DEPTH?", {"z": 2.0, "time_out": 60.0}) == []
    reply = _final(run(vehicle, 60.0), 2)
    assert reply.kind == "done"
    assert _window("DEPTH?") <= reply.time < 30.0


def test_depth_query_times_out_for_a_depth_nobody_commands() -> None:
    vehicle = Vehicle()
    vehicle.command(1, "DEPTH", {"z": 2.0})
    vehicle.command(2, "DEPTH?", {"z": 3.0, "time_out": 40.0})
    reply = _final(run(vehicle, 60.0), 2)
    assert (reply.kind, reply.time) == ("timeout", 40.0)


def test_query_reference_is_its_own_parameter_not_the_set_point() -> None:
    vehicle = Vehicle()
    vehicle.command(1, "DEPTH", {"z": 1.0})
    run(vehicle, 20.0)
    # DEPTH? asks about 1 m while the task also holds 1 m: done; a query about 1.5 m: not.
    vehicle.command(2, "DEPTH?", {"z": 1.0, "time_out": 20.0})
    vehicle.command(3, "DEPTH?", {"z": 1.5, "time_out": 20.0})
    replies = run(vehicle, 25.0)
    assert _final(replies, 2).kind == "done"
    assert _final(replies, 3).kind == "timeout"


def test_query_window_opens_at_arrival() -> None:
    vehicle = Vehicle()
    vehicle.command(1, "DEPTH", {"z": 2.0})
    run(vehicle, 40.0)  # long settled
    vehicle.command(2, "DEPTH?", {"z": 2.0, "time_out": 30.0})
    reply = _final(run(vehicle, 10.0), 2)
    assert reply.kind == "done"
    assert reply.time - 40.0 == pytest.approx(_window("DEPTH?"), abs=0.051)


def test_heading_query_done_and_timeout() -> None:
    vehicle = Vehicle()
    vehicle.command(1, "HEADING", {"psi": 450.0 - 360.0})
    vehicle.command(2, "HEADING?", {"psi": -270.0, "time_out": 40.0})  # same as 90
    vehicle.command(3, "HEADING?", {"psi": 100.0, "time_out": 40.0})
    replies = run(vehicle, 45.0)
    assert _final(replies, 2).kind == "done"
    assert _final(replies, 3).kind == "timeout"


def test_xy_query_done_for_a_reachable_way_point() -> None:
    vehicle = fixed_vehicle()
    assert [r.kind for r in vehicle.command(10, "LRM", {"x": 5.0, "y": 4.0})] == ["ack"]
    vehicle.command(11, "XY?", {"x": 5.0, "y": 4.0, "time_out": 60.0})
    assert _final(run(vehicle, 60.0), 11).kind == "done"


def test_xy_query_times_out_when_the_target_is_out_of_reach_in_time() -> None:
    vehicle = fixed_vehicle()
    vehicle.command(10, "LRM", {"x": 10.0, "y": 6.0})
    start = vehicle.time
    vehicle.command(11, "XY?", {"x": 10.0, "y": 6.0, "time_out": 5.0})
    reply = _final(run(vehicle, 10.0), 11)
    assert reply.kind == "timeout"
    assert reply.time == pytest.approx(start + 5.0, abs=0.051)


def test_xy_query_times_out_outside_the_pool() -> None:
    vehicle = fixed_vehicle()
    vehicle.command(10, "XY?", {"x": 20.0, "y": 4.0, "time_out": 10.0})
    assert _final(run(vehicle, 12.0), 10).kind == "timeout"


def test_xy_query_before_fix_xy_times_out() -> None:
    vehicle = Vehicle()
    vehicle.command(1, "XY?", {"x": 2.0, "y": 2.0, "time_out": 5.0})
    reply = _final(run(vehicle, 6.0), 1)
    assert reply.kind == "timeout"
    assert "unknown" in reply.detail


def test_xypsi_query_after_goto() -> None:
    vehicle = fixed_vehicle()
    vehicle.command(10, "GOTO", {"x": 6.0, "y": 4.0, "psi": 0.0})
    vehicle.command(11, "XYPSI?", {"x": 6.0, "y": 4.0, "psi": 0.0, "time_out": 90.0})
    vehicle.command(12, "XYPSI?", {"x": 6.0, "y": 4.0, "psi": 45.0, "time_out": 60.0})
    replies = run(vehicle, 90.0)
    assert _final(replies, 11).kind == "done"
    assert _final(replies, 12).kind == "timeout"  # heading 45 is not where GOTO leaves it
    t = vehicle.telemetry()
    assert abs(t.x - 6.0) < 0.3 and abs(t.y - 4.0) < 0.3


def test_surface_query() -> None:
    vehicle = Vehicle()
    vehicle.command(1, "DEPTH", {"z": 2.0})
    run(vehicle, 20.0)
    vehicle.command(2, "SURFACE", {})
    vehicle.command(3, "SURFACE?", {"time_out": 60.0})
    reply = _final(run(vehicle, 60.0), 3)
    assert reply.kind == "done"
    assert vehicle.telemetry().z < 0.2


def test_docking_query_without_a_dock_times_out() -> None:
    vehicle = fixed_vehicle()
    vehicle.command(10, "DOCKING?", {"time_out": 5.0})
    assert _final(run(vehicle, 6.0), 10).kind == "timeout"


def test_docking_goes_to_the_dock_and_emerges() -> None:
    vehicle = fixed_vehicle()
    assert vehicle.command(10, "GET_DOCK", {})[0].kind == "done"
    vehicle.command(11, "LRM", {"x": 6.0, "y": 5.0})
    run(vehicle, 25.0)
    vehicle.command(12, "DOCKING", {})
    vehicle.command(13, "DOCKING?", {"time_out": 120.0})
    assert _final(run(vehicle, 120.0), 13).kind == "done"
    t = vehicle.telemetry()
    assert t.z < 0.05
    assert vehicle.dock is not None
    assert abs(t.x - vehicle.dock[0]) < 0.4 and abs(t.y - vehicle.dock[1]) < 0.4


def test_lrm_heads_the_target_when_heading_is_free() -> None:
    vehicle = fixed_vehicle()  # HEADING 90 (id 2) is still running
    vehicle.command(10, "GOTO", {"x": 4.0, "y": 2.0, "psi": 0.0})  # frees heading after
    vehicle.command(11, "LRM", {"x": 8.0, "y": 2.0})  # due north of the vehicle
    run(vehicle, 15.0)
    t = vehicle.telemetry()
    assert min(t.psi, 360.0 - t.psi) < 10.0  # faces north, the target
    assert t.heading_task == "" and t.horizontal_task == "LRM (id 11)"


def test_lrm_crabs_when_a_heading_task_holds_the_heading() -> None:
    vehicle = fixed_vehicle()  # HEADING 90 (id 2) is still running
    vehicle.command(10, "LRM", {"x": 8.0, "y": 2.0})  # due north, heading stays east
    vehicle.command(11, "XY?", {"x": 8.0, "y": 2.0, "time_out": 80.0})
    replies = run(vehicle, 80.0)
    assert _final(replies, 11).kind == "done"
    assert abs(vehicle.telemetry().psi - 90.0) < 3.0
