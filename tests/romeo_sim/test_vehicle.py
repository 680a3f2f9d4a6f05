"""The Vehicle API: input handling, refusals, resources, watchdog, determinism, time."""

from __future__ import annotations

import dataclasses
import math

import pytest

from coral_lang.diagnostics import ProfileError
from coral_lang.profile import load_bundled_profile, parse_profile
from romeo_sim.config import VehicleConfigError, default_config
from romeo_sim.scenario import run_pool_mission
from romeo_sim.vehicle import SUPPORTED_COMMANDS, Reply, Vehicle
from tests.romeo_sim.conftest import fixed_vehicle, run

PROFILE = load_bundled_profile("ROMEO")


def kinds(replies: list[Reply]) -> list[str]:
    return [r.kind for r in replies]


def test_every_profile_command_is_supported() -> None:
    assert set(PROFILE.command_names) == set(SUPPORTED_COMMANDS)


def test_init_replies_done() -> None:
    vehicle = Vehicle(start_time=100.0)
    (reply,) = vehicle.command(7, "INIT", {})
    assert (reply.command_id, reply.command, reply.kind, reply.time) == (7, "INIT", "done", 100.0)


@pytest.mark.parametrize(
    ("name", "params", "needle"),
    [
        ("DEPHT", {"z": 2.0}, "unknown command 'DEPHT' (did you mean 'DEPTH'?)"),
        ("DEPTH", {}, "needs parameter 'z'"),
        ("DEPTH", {"z": 2.0, "speed": 1.0}, "takes no parameter 'speed'"),
        ("DEPTH", {"z": "two"}, "must be a number, got 'two'"),
        ("DEPTH", {"z": True}, "must be a number, got True"),
        ("DEPTH", {"z": -1.0}, "z: float [m] in [0, 500]: -1 is out of range"),
        ("DEPTH", {"z": math.nan}, "must be finite"),
        ("HEADING?", {"psi": 90.0}, "needs parameter 'time_out'"),
        ("XY?", {"x": 1.0, "y": 1.0, "time_out": 0.1}, "out of range"),
    ],
)
def test_malformed_commands_get_error_not_exceptions(
    name: str, params: dict[str, float | int | str], needle: str
) -> None:
    vehicle = Vehicle()
    (reply,) = vehicle.command(1, name, params)
    assert reply.kind == "error"
    assert needle in reply.detail
    assert vehicle.status() == []


@pytest.mark.parametrize(
    ("name", "params", "needle"),
    [
        ("DEPTH", {"z": 3.8}, "below the reachable bottom (3.5 m in a 4 m pool)"),
        ("LRM", {"x": 5.0, "y": 4.0}, "send FIX_XY first"),
        ("SRM", {"x": 5.0, "y": 4.0, "psi": 0.0}, "send FIX_XY first"),
        ("GOTO", {"x": 5.0, "y": 4.0, "psi": 0.0}, "send FIX_XY first"),
        ("DOCKING", {}, "send FIX_XY first"),
        ("GET_DOCK", {}, "send FIX_XY first"),
    ],
)
def test_refusals_before_anything_moves(
    name: str, params: dict[str, float | int | str], needle: str
) -> None:
    (reply,) = Vehicle().command(1, name, params)
    assert reply.kind == "error"
    assert needle in reply.detail


def test_refusals_with_a_fix() -> None:
    vehicle = fixed_vehicle()
    (reply,) = vehicle.command(10, "LRM", {"x": 11.9, "y": 4.0})
    assert reply.kind == "error" and "not reachable" in reply.detail
    (reply,) = vehicle.command(11, "DOCKING", {})
    assert reply.kind == "error" and "send GET_DOCK first" in reply.detail
    assert kinds(vehicle.command(12, "GET_DOCK", {})) == ["done"]
    assert kinds(vehicle.command(13, "DOCKING", {})) == ["ack"]


def test_parameters_that_are_not_a_mapping_get_error() -> None:
    (reply,) = Vehicle().command(1, "DEPTH", [2.0])  # type: ignore[arg-type]
    assert reply.kind == "error" and "must be a mapping" in reply.detail


def test_programming_misuse_raises_value_error() -> None:
    vehicle = Vehicle()
    with pytest.raises(ValueError, match="command_id"):
        vehicle.command("1", "INIT", {})  # type: ignore[arg-type]
    with pytest.raises(ValueError):
        vehicle.advance(-1.0)
    vehicle.advance(5.0)
    with pytest.raises(ValueError, match="back"):
        vehicle.advance_to(4.0)
    with pytest.raises(ValueError):
        vehicle.advance(math.inf)


def test_duplicate_id_is_carried_out_once_and_replayed() -> None:
    vehicle = Vehicle()
    first = vehicle.command(1, "DEPTH", {"z": 2.0})
    vehicle.command(2, "DEPTH?", {"z": 2.0, "time_out": 60.0})
    run(vehicle, 5.0)
    assert vehicle.command(1, "DEPTH", {"z": 2.0}) == first  # the same ack, same time
    assert len(vehicle.status()) == 2
    late = run(vehicle, 40.0)
    assert kinds(late) == ["done"]
    # A resend after the reply went out gets it again, and nothing runs twice.
    assert vehicle.command(2, "DEPTH?", {"z": 2.0, "time_out": 60.0}) == late
    assert len(vehicle.status()) == 1


def test_reused_id_for_another_command_is_refused() -> None:
    vehicle = Vehicle()
    vehicle.command(1, "DEPTH", {"z": 2.0})
    (reply,) = vehicle.command(1, "DEPTH", {"z": 3.0})
    assert reply.kind == "error" and "already used for DEPTH" in reply.detail
    assert vehicle.status()[0].startswith("DEPTH (id 1)")
    assert "-> 2.00 m" in vehicle.status()[0]


def test_replaced_task_ends_its_pending_query_with_timeout_at_once() -> None:
    vehicle = Vehicle()
    vehicle.command(1, "HEADING", {"psi": 90.0})
    vehicle.command(2, "HEADING?", {"psi": 90.0, "time_out": 60.0})
    vehicle.command(3, "DEPTH", {"z": 1.0})
    vehicle.command(4, "DEPTH?", {"z": 1.0, "time_out": 60.0})
    run(vehicle, 2.0)
    assert kinds(vehicle.command(5, "HEADING", {"psi": 180.0})) == ["ack"]
    replies = vehicle.advance(0.0)
    assert [(r.command_id, r.kind, r.time) for r in replies] == [(2, "timeout", 2.0)]
    assert "replaced by HEADING (id 5)" in replies[0].detail
    # The depth task and its query are untouched.
    assert any(line.startswith("DEPTH? (id 4)") for line in vehicle.status())
    assert any("stopped: replaced by HEADING (id 5)" in e.text for e in vehicle.events)


def test_goto_replaces_heading_and_srm_takes_both_resources() -> None:
    vehicle = fixed_vehicle()
    vehicle.command(10, "GOTO", {"x": 6.0, "y": 4.0, "psi": 0.0})
    status = vehicle.status()
    assert not any(line.startswith("HEADING (id 2)") for line in status)
    assert any(line.startswith("GOTO (id 10)") for line in status)
    t = vehicle.telemetry()
    assert t.heading_task == t.horizontal_task == "GOTO (id 10)"
    assert t.depth_task == "DEPTH (id 1)"


def test_second_fix_xy_interrupts_the_first() -> None:
    vehicle = Vehicle()
    vehicle.command(1, "DEPTH", {"z": 2.0})
    run(vehicle, 15.0)
    assert vehicle.command(2, "FIX_XY", {}) == []
    run(vehicle, 3.0)
    assert vehicle.command(3, "FIX_XY", {}) == []
    replies = run(vehicle, 11.0)
    assert [(r.command_id, r.kind) for r in replies] == [(2, "error"), (3, "done")]
    assert "interrupted" in replies[0].detail


def test_watchdog_surfaces_a_silent_vehicle() -> None:
    vehicle = Vehicle()
    vehicle.command(1, "DEPTH", {"z": 2.0})
    vehicle.command(2, "DEPTH?", {"z": 2.5, "time_out": 300.0})
    run(vehicle, 20.0)  # keeps the watchdog fed
    vehicle.heard_from_controller()  # last word at 20 s: the watchdog trips at 50 s
    replies = run(vehicle, 80.0, keep_alive=False)
    assert [(r.command_id, r.kind) for r in replies] == [(2, "timeout")]
    assert replies[0].time == pytest.approx(50.0, abs=0.06)
    assert "watchdog" in replies[0].detail
    (event,) = [e for e in vehicle.events if e.text.startswith("watchdog")]
    assert event.time == pytest.approx(50.0, abs=0.06)
    assert vehicle.telemetry().z < 0.1
    (line,) = vehicle.status()
    assert line.startswith("SURFACE (id -1) since 50.0 s")


def test_heard_from_controller_keeps_the_watchdog_quiet() -> None:
    config = dataclasses.replace(default_config(), watchdog_s=5.0)
    vehicle = Vehicle(config)
    vehicle.command(1, "DEPTH", {"z": 2.0})
    for _ in range(30):
        vehicle.advance(4.0)
        vehicle.heard_from_controller()
    assert not any(e.text.startswith("watchdog") for e in vehicle.events)
    vehicle.advance(6.0)
    assert any(e.text.startswith("watchdog") for e in vehicle.events)


def test_a_new_command_takes_control_back_after_the_watchdog() -> None:
    config = dataclasses.replace(default_config(), watchdog_s=5.0)
    vehicle = Vehicle(config)
    vehicle.command(1, "DEPTH", {"z": 2.0})
    vehicle.advance(10.0)
    assert kinds(vehicle.command(2, "DEPTH", {"z": 1.0})) == ["ack"]
    run(vehicle, 30.0)
    assert abs(vehicle.telemetry().z - 1.0) < 0.1


def test_current_is_estimated_and_the_mission_still_completes() -> None:
    base = default_config()
    pool = dataclasses.replace(base.pool, current_north_m_s=0.05, current_east_m_s=0.03)
    result = run_pool_mission(dataclasses.replace(base, pool=pool))
    assert result.completed, result.reason
    ekf = result.vehicle.nav.ekf
    assert abs(ekf.cn - 0.05) < 0.02 and abs(ekf.ce - 0.03) < 0.02
    final = result.recorder.telemetry[-1]
    assert result.dock is not None
    assert math.hypot(final.x - result.dock[0], final.y - result.dock[1]) < 0.4


def test_same_seed_same_trajectory_bit_identical() -> None:
    a = run_pool_mission(seed=3)
    b = run_pool_mission(seed=3)
    assert a.recorder.telemetry == b.recorder.telemetry
    assert a.recorder.replies == b.recorder.replies
    c = run_pool_mission(seed=4)
    assert c.recorder.telemetry != a.recorder.telemetry


def test_advance_granularity_does_not_change_the_run() -> None:
    def drive(chunk: float) -> list[object]:
        vehicle = Vehicle(seed=5)
        vehicle.command(1, "DEPTH", {"z": 2.0})
        vehicle.command(2, "HEADING", {"psi": 45.0})
        vehicle.command(3, "HEADING?", {"psi": 45.0, "time_out": 30.0})
        replies: list[object] = []
        while vehicle.time < 20.0 - 1e-9:
            replies += vehicle.advance_to(min(20.0, vehicle.time + chunk))
        return [vehicle.telemetry(), *replies]

    assert drive(0.013) == drive(0.5) == drive(20.0)


def test_clock_between_steps() -> None:
    vehicle = Vehicle(start_time=10.0)
    vehicle.advance(0.07)
    assert vehicle.time == pytest.approx(10.07)
    assert vehicle.state_time == pytest.approx(10.05)
    assert vehicle.telemetry().vehicle_time == pytest.approx(10.05)


def test_status_lines_say_what_runs() -> None:
    vehicle = fixed_vehicle()
    vehicle.command(10, "GOTO", {"x": 6.0, "y": 4.0, "psi": 0.0})
    vehicle.command(11, "XYPSI?", {"x": 6.0, "y": 4.0, "psi": 0.0, "time_out": 60.0})
    run(vehicle, 2.0)
    lines = vehicle.status()
    assert lines[0].startswith("DEPTH (id 1) since 0.0 s, depth 2.0")
    assert lines[1].startswith("GOTO (id 10) since 30.5 s, LRM mode, target (6.0, 4.0)")
    assert lines[2].startswith("XYPSI? (id 11) since 30.5 s, time-out at 90.5 s, range ")


def test_replies_are_kinds_the_profile_declares(mission_replies: list[Reply]) -> None:
    for reply in mission_replies:
        spec = PROFILE.command(reply.command)
        assert spec is not None
        assert reply.kind in spec.replies, reply


@pytest.fixture
def mission_replies() -> list[Reply]:
    result = run_pool_mission(seed=0)
    return result.recorder.replies


def test_profile_with_a_command_the_vehicle_lacks_is_refused() -> None:
    profile = parse_profile(
        "vehicle: ROMEO\nresources: [depth]\ncommands:\n"
        "  HOVER:\n    kind: task\n    replies: [ack]\n",
        "odd.yaml",
    )
    with pytest.raises(VehicleConfigError, match=r"odd.yaml: commands.HOVER: .*cannot carry"):
        Vehicle(profile=profile)


def test_profile_with_an_unknown_space_trap_signal_is_refused_when_it_loads() -> None:
    with pytest.raises(ProfileError, match="unknown space-trap signal 'altitude'"):
        parse_profile(
            "vehicle: ROMEO\nresources: [depth]\ncommands:\n"
            "  DEPTH?:\n    kind: query\n    replies: [done, timeout]\n"
            "    params: [{name: time_out, type: float, unit: s}]\n"
            "    space_trap: {signal: altitude, order: 0, eps: [0.1], window_s: 1}\n",
            "odd.yaml",
        )


def test_query_without_a_space_trap_is_refused_naming_the_command() -> None:
    """The schema allows a query without a tracking criterion; the simulator, which
    answers queries only by one, says which command lacks it instead of crashing."""
    profile = parse_profile(
        "vehicle: ROMEO\nresources: [depth]\ncommands:\n"
        "  DEPTH?:\n    kind: query\n    replies: [done, timeout]\n"
        "    params: [{name: time_out, type: float, unit: s}]\n",
        "odd.yaml",
    )
    with pytest.raises(
        VehicleConfigError,
        match=r"odd.yaml: commands.DEPTH\?: query 'DEPTH\?' declares no space_trap",
    ):
        Vehicle(profile=profile)
