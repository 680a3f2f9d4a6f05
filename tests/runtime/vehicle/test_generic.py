"""The generic simulated vehicle (any profile) and the two bundled simulator plugins."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from coral_lang.profile import VehicleProfile, load_bundled_profile, load_profile
from romeo_sim.plugin import SIMULATOR as ROMEO
from romeo_sim.vehicle import Vehicle
from runtime.telemetry import TelemetryRecord
from runtime.vehicle import Reply, VehicleModel
from runtime.vehicle.generic import SIMULATOR as GENERIC
from runtime.vehicle.generic import GenericVehicle
from runtime.vehicle.registry import (
    Simulator,
    SimulatorError,
    SimulatorRequest,
    choose_simulator,
)
from tests.conftest import EXAMPLES

PROFILES = EXAMPLES / "profiles"


def minnow() -> VehicleProfile:
    return load_profile(PROFILES / "minnow.yaml")


def advance(vehicle: GenericVehicle, t: float) -> list[Reply]:
    """Advance to ``t`` with the controller's heartbeat every 10 s."""
    out: list[Reply] = []
    while vehicle.time < t:
        out += vehicle.advance_to(min(t, vehicle.time + 10.0))
        vehicle.heard_from_controller()
    return out


def script(vehicle: GenericVehicle) -> list[Reply]:
    """A fixed sequence of calls; everything the vehicle replied, in order."""
    out = vehicle.command(1, "INIT", {})
    out += advance(vehicle, 10.0)
    out += vehicle.command(2, "GPS_FIX?", {"max_hdop": 2.0, "time_out": 120.0})
    out += advance(vehicle, 70.0)
    out += vehicle.command(3, "DIVE", {"z": 15.0})
    out += vehicle.command(4, "DEPTH?", {"z": 15.0, "time_out": 180.0})
    out += advance(vehicle, 140.0)
    return out


def test_same_seed_same_replies_other_seed_other_times() -> None:
    first = script(GenericVehicle(minnow(), seed=7))
    assert first == script(GenericVehicle(minnow(), seed=7))
    assert [(r.command_id, r.kind) for r in first] == [
        (1, "done"),
        (2, "done"),
        (3, "ack"),
        (4, "done"),
    ]
    other = script(GenericVehicle(minnow(), seed=8))
    assert [r.time for r in other] != [r.time for r in first]


@pytest.mark.parametrize("variation", [0.0, 0.2, 0.5])
def test_durations_stay_within_the_variation(variation: float) -> None:
    vehicle = GenericVehicle(minnow(), seed=3, variation=variation, watchdog_s=1e6)
    took: list[float] = []
    for cid in range(1, 41):
        start = vehicle.time
        assert vehicle.command(cid, "INIT", {}) == []  # INIT: an action, 5 s nominal
        (reply,) = vehicle.advance_to(start + 20.0)
        assert (reply.command_id, reply.kind) == (cid, "done")
        took.append(reply.time - start)
    # Rounded up to the next 0.1-s poll.
    assert min(took) >= 5.0 * (1 - variation) - 1e-9
    assert max(took) <= 5.0 * (1 + variation) + 0.1 + 1e-9
    if variation == 0.0:
        assert took == pytest.approx([5.0] * 40)
    else:
        assert max(took) - min(took) > variation * 5.0  # the spread is used, not ignored


def test_a_query_with_a_short_time_out_times_out_at_it() -> None:
    vehicle = GenericVehicle(minnow(), seed=0)
    vehicle.advance_to(1.0)
    # GPS_FIX? takes 45 s +/- 20 %: at least 36 s, so a 20-s time-out passes first.
    vehicle.command(1, "GPS_FIX?", {"max_hdop": 2.0, "time_out": 20.0})
    assert vehicle.advance_to(20.9) == []
    assert vehicle.advance_to(60.0) == [
        Reply(1, "GPS_FIX?", "timeout", 21.0, "time-out of 20 s passed")
    ]


def test_tasks_ack_after_their_work_time_and_replacing_them_times_out_their_queries() -> None:
    # Timed model: a task's ack falls due after its work time (DIVE: 1 s +/- 20 %), not
    # at once; it holds its resources from its arrival all the same.
    vehicle = GenericVehicle(minnow(), seed=0)
    assert vehicle.command(1, "DIVE", {"z": 10.0}) == []
    assert vehicle.holders == {"depth": "DIVE"}
    vehicle.command(2, "DEPTH?", {"z": 10.0, "time_out": 200.0})
    (ack,) = vehicle.advance_to(5.0)
    assert (ack.command_id, ack.kind) == (1, "ack") and 0.8 <= ack.time <= 1.3
    assert vehicle.command(3, "SURFACE", {}) == []
    assert vehicle.advance_to(5.0) == [
        Reply(2, "DEPTH?", "timeout", 5.0, "its task DIVE was replaced by SURFACE")
    ]
    assert [(r.command_id, r.kind) for r in vehicle.advance_to(7.0)] == [(3, "ack")]


def test_the_pose_follows_the_tasks_targets() -> None:
    vehicle = GenericVehicle(minnow(), seed=0, watchdog_s=1e6)
    vehicle.command(1, "DIVE", {"z": 3.0})
    vehicle.advance_to(5.0)
    pose = vehicle.telemetry()
    assert pose == TelemetryRecord(5.0, 0.0, 0.0, 1.5, 0.0)  # 0.3 m/s down
    vehicle.command(2, "SURVEY_LINE", {"x0": 0.0, "y0": 0.0, "x1": 0.0, "y1": 30.0, "speed": 1.0})
    vehicle.advance_to(20.0)
    pose = vehicle.telemetry()
    assert pose is not None
    assert (pose.x, pose.y, pose.z, pose.psi) == pytest.approx((0.0, 15.0, 3.0, 90.0))
    assert pose.est_x is None
    vehicle.command(3, "SURFACE", {})
    vehicle.advance_to(40.0)
    pose = vehicle.telemetry()
    assert pose is not None and pose.z == 0.0 and pose.y == pytest.approx(30.0)


def test_bad_variation_is_refused() -> None:
    with pytest.raises(ValueError, match="variation"):
        GenericVehicle(minnow(), variation=1.0)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["minnow", "glider", "usv", "ROMEO"])
def test_every_command_of_every_example_profile_gets_its_expected_reply(name: str) -> None:
    profile = (
        load_bundled_profile(name) if name.isupper() else load_profile(PROFILES / f"{name}.yaml")
    )
    vehicle = GenericVehicle(profile, seed=1, watchdog_s=1e6)
    for cid, spec in enumerate(profile.commands, start=1):
        params: dict[str, float | int | str] = {}
        for p in spec.params:
            if p.type == "string":
                params[p.name] = "x"
            elif p.name == "time_out":
                params[p.name] = p.maximum if p.maximum is not None else 1e4
            else:
                value = p.minimum if p.minimum is not None else 0.0
                params[p.name] = int(value) if p.type == "int" else value
        replies = vehicle.command(cid, spec.name, params)
        replies += vehicle.advance_to(vehicle.time + spec.duration_s * 1.3 + 1.0)
        mine = [r for r in replies if r.command_id == cid]
        assert [r.kind for r in mine] == [spec.replies[0]], (spec.name, mine)


# ---------------------------------------------------------------------- plugins


def test_the_generic_plugin(tmp_path: Path) -> None:
    assert isinstance(GENERIC, Simulator)
    assert (GENERIC.name, GENERIC.vehicles) == ("generic", ())
    vehicle = GENERIC.create(SimulatorRequest(minnow(), seed=4))
    assert isinstance(vehicle, GenericVehicle)
    assert script(vehicle) == script(GenericVehicle(minnow(), seed=4))
    with pytest.raises(SimulatorError, match="cannot read the generic vehicle's settings"):
        GENERIC.create(SimulatorRequest(minnow(), config=tmp_path / "none.yaml"))
    settings = tmp_path / "generic.yaml"
    settings.write_text("watchdog_s: 600\nvariation: 0\n")
    tuned = GENERIC.create(SimulatorRequest(minnow(), seed=4, config=settings))
    assert tuned.watchdog_s == 600.0 and tuned.variation == 0.0
    for text, field in [
        ("variation: 1.0\n", "variation: must be a number in [0, 1)"),
        ("watchdog_s: 0\n", "watchdog_s: must be a number > 0"),
        ("wachdog_s: 5\n", "did you mean 'watchdog_s'"),
        ("poll_s: fast\n", "poll_s: must be a number"),
        ("- 1\n", "expected a mapping"),
    ]:
        settings.write_text(text)
        with pytest.raises(SimulatorError, match=re.escape(field)) as exc:
            GENERIC.create(SimulatorRequest(minnow(), config=settings))
        assert str(settings) in str(exc.value)


def test_the_romeo_plugin(tmp_path: Path) -> None:
    romeo = load_bundled_profile("ROMEO")
    assert isinstance(ROMEO, Simulator)
    assert (ROMEO.name, ROMEO.vehicles) == ("romeo", ("ROMEO",))
    vehicle = ROMEO.create(SimulatorRequest(romeo, seed=2))
    assert isinstance(vehicle, Vehicle) and isinstance(vehicle, VehicleModel)
    assert vehicle.watchdog_s == vehicle.config.watchdog_s == 30.0
    bad = tmp_path / "romeo.yaml"
    bad.write_text("watchdog_s: -3\n")
    with pytest.raises(SimulatorError, match=r"simulator 'romeo': .*romeo\.yaml"):
        ROMEO.create(SimulatorRequest(romeo, config=bad))
    with pytest.raises(SimulatorError, match="cannot carry out 'GPS_FIX\\?'"):
        ROMEO.create(SimulatorRequest(minnow()))


def test_the_registry_picks_romeo_for_romeo_and_generic_for_the_rest() -> None:
    assert choose_simulator(load_bundled_profile("ROMEO")).name == "romeo"
    assert choose_simulator(minnow()).name == "generic"
    assert choose_simulator(load_bundled_profile("ROMEO"), "generic").name == "generic"
