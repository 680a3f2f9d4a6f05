"""The generic vehicle keeps to the timed model that timed analysis proves under.

docs/analysis-methods.md (timed analysis): a task acks after its work time; a query with
a time-out tracks the task it watches from that task's start, replies ``done`` if that
completes by its time-out and ``timeout`` at the time-out otherwise; every reply goes out
at most one poll (<= the profile's reply latency) after it falls due. Scripted mode (the
replay of a schedule) gives each command the reply and times a script says.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from coral_lang.profile import VehicleProfile, load_profile
from coral_lang.timing import ProfileTiming
from runtime.vehicle import Reply
from runtime.vehicle.generic import SIMULATOR, GenericVehicle, ScriptedCommand
from runtime.vehicle.registry import SimulatorError, SimulatorRequest
from tests.conftest import EXAMPLES

POLL = 0.1


def minnow() -> VehicleProfile:
    return load_profile(EXAMPLES / "profiles" / "minnow.yaml")


def exact() -> GenericVehicle:
    """No spread: DIVE acks after 1 s, DEPTH? tracks for 60 s, INIT takes 5 s."""
    return GenericVehicle(minnow(), seed=0, variation=0.0, watchdog_s=1e6)


def test_a_query_watching_a_task_started_earlier_is_done_at_its_start_plus_w() -> None:
    vehicle = exact()
    vehicle.command(1, "DIVE", {"z": 10.0})
    assert [r.kind for r in vehicle.advance_to(20.0)] == ["ack"]
    assert vehicle.command(2, "DEPTH?", {"z": 10.0, "time_out": 100.0}) == []
    assert vehicle.advance_to(59.9) == []
    (done,) = vehicle.advance_to(100.0)
    # DIVE started at 0: tracking done at 0 + 60, not 20 + 60.
    assert (done.command_id, done.kind, done.time) == (2, "done", 60.0)


def test_a_query_whose_tracking_ends_after_its_time_out_times_out_at_it() -> None:
    vehicle = exact()
    vehicle.command(1, "DIVE", {"z": 10.0})
    vehicle.advance_to(20.0)
    vehicle.command(2, "DEPTH?", {"z": 10.0, "time_out": 30.0})  # 60 > 20 + 30
    assert vehicle.advance_to(49.9) == []
    assert vehicle.advance_to(100.0) == [
        Reply(2, "DEPTH?", "timeout", 50.0, "time-out of 30 s passed")
    ]


def test_a_query_without_a_watched_task_tracks_from_its_own_arrival() -> None:
    vehicle = exact()
    vehicle.advance_to(10.0)
    vehicle.command(1, "DEPTH?", {"z": 10.0, "time_out": 100.0})  # nothing holds depth
    (done,) = vehicle.advance_to(200.0)
    assert (done.kind, done.time) == ("done", 70.0)


@pytest.mark.parametrize("time_out", [40.03, 40.04])
def test_done_between_two_polls_before_the_time_out_is_not_lost_to_it(time_out: float) -> None:
    # DIVE starts at 0.03, so tracking completes at 60.03; the time-out falls at 60.03
    # (the tie) or 60.04: both between the polls at 60.0 and 60.1.
    vehicle = exact()
    vehicle.advance_to(0.03)
    vehicle.command(1, "DIVE", {"z": 10.0})
    vehicle.advance_to(20.0)
    vehicle.command(2, "DEPTH?", {"z": 10.0, "time_out": time_out})
    (reply,) = vehicle.advance_to(100.0)
    assert reply.kind == "done"
    assert reply.time == pytest.approx(20.0 + time_out)  # sent at the time-out's instant


def test_a_watched_task_replaced_makes_the_query_time_out_at_once() -> None:
    vehicle = exact()
    vehicle.command(1, "DIVE", {"z": 10.0})
    vehicle.command(2, "DEPTH?", {"z": 10.0, "time_out": 100.0})
    vehicle.advance_to(10.0)
    vehicle.command(3, "SURFACE", {})
    assert [(r.command_id, r.kind, r.time) for r in vehicle.advance_to(10.0)] == [
        (2, "timeout", 10.0)
    ]


def test_a_task_replaced_before_its_ack_replies_error() -> None:
    vehicle = exact()
    vehicle.command(1, "DIVE", {"z": 10.0})
    vehicle.advance_to(0.5)
    vehicle.command(2, "SURFACE", {})
    replies = vehicle.advance_to(0.5)
    assert [(r.command_id, r.kind) for r in replies] == [(1, "error")]
    assert "interrupted" in replies[0].detail
    assert [(r.command_id, r.kind, r.time) for r in vehicle.advance_to(3.0)] == [(2, "ack", 1.5)]


def test_an_ack_due_before_a_displacement_is_not_turned_into_error() -> None:
    # DIVE arrives at 0.05 s, its ack falls due at 1.05 s; SURFACE arrives at 1.08 s,
    # before the next poll (1.1 s): the ack was due first, so it stands (timed analysis
    # counts on that).
    vehicle = exact()
    vehicle.advance_to(0.05)
    vehicle.command(1, "DIVE", {"z": 10.0})
    replies = vehicle.advance_to(1.08)
    replies += vehicle.command(2, "SURFACE", {}) + vehicle.advance_to(1.08)
    assert (1, "ack") in [(r.command_id, r.kind) for r in replies]
    assert (1, "error") not in [(r.command_id, r.kind) for r in replies]


def test_the_ack_delay_lies_in_its_interval_and_uses_it() -> None:
    delays = []
    for seed in range(40):
        vehicle = GenericVehicle(minnow(), seed=seed, watchdog_s=1e6)
        vehicle.advance_to(3.0)
        vehicle.command(1, "DIVE", {"z": 10.0})
        (ack,) = vehicle.advance_to(10.0)
        delays.append(ack.time - 3.0)
    assert min(delays) >= 0.8 - 1e-9 and max(delays) <= 1.2 + POLL + 1e-9
    assert max(delays) - min(delays) > 0.2  # the spread is drawn, not ignored


def test_declared_work_intervals_win_over_the_variation() -> None:
    profile = minnow()
    commands = tuple(
        dataclasses.replace(c, work_s=(("ack", 3.0, 3.0),)) if c.name == "DIVE" else c
        for c in profile.commands
    )
    vehicle = GenericVehicle(dataclasses.replace(profile, commands=commands), variation=0.5)
    vehicle.command(1, "DIVE", {"z": 10.0})
    (ack,) = vehicle.advance_to(10.0)
    assert ack.time == 3.0


def test_a_poll_period_above_the_reply_latency_is_refused(tmp_path: Path) -> None:
    slow = dataclasses.replace(minnow(), timing=ProfileTiming(reply_latency_s=0.05))
    with pytest.raises(ValueError, match="reply_latency_s"):
        GenericVehicle(slow)
    assert GenericVehicle(slow, poll_s=0.05).time == 0.0
    settings_file = tmp_path / "generic.yaml"
    settings_file.write_text("poll_s: 0.5\n")
    with pytest.raises(SimulatorError, match=r"generic\.yaml: poll_s 0\.5 s exceeds"):
        SIMULATOR.create(SimulatorRequest(minnow(), config=settings_file))


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**32),
    wait=st.floats(0.0, 80.0),
    time_out=st.floats(5.0, 120.0),
)
def test_every_reply_time_lies_in_the_models_interval(
    seed: int, wait: float, time_out: float
) -> None:
    vehicle = GenericVehicle(minnow(), seed=seed, watchdog_s=1e6)
    vehicle.command(1, "INIT", {})
    (init,) = vehicle.advance_to(20.0)
    assert init.kind == "done" and 4.0 - 1e-9 <= init.time <= 6.0 + POLL + 1e-9
    vehicle.command(2, "DIVE", {"z": 10.0})  # starts at 20
    replies = vehicle.advance_to(20.0 + wait)
    arrival = vehicle.time
    replies += vehicle.command(3, "DEPTH?", {"z": 10.0, "time_out": time_out})
    replies += vehicle.advance_to(arrival + time_out + 1.0)
    by_id = {r.command_id: r for r in replies}
    ack = by_id[2]
    assert ack.kind == "ack" and 20.8 - 1e-9 <= ack.time <= 21.2 + POLL + 1e-9
    query = by_id[3]
    deadline = arrival + time_out
    earliest, latest = 20.0 + 48.0, 20.0 + 72.0  # DIVE's start + [0.8, 1.2] x 60 s
    if query.kind == "done":  # due at max(arrival, c), c <= deadline; sent within a poll
        assert max(arrival, earliest) - 1e-9 <= query.time <= deadline + 1e-9
        assert query.time <= max(arrival, latest) + POLL + 1e-9
    else:  # only if tracking may end after the time-out; then exactly at it
        assert query.kind == "timeout" and query.time == pytest.approx(deadline)
        assert latest > deadline
    if earliest > deadline + 1e-9:
        assert query.kind == "timeout"


# ---------------------------------------------------------------------- scripted mode


def test_scripted_commands_take_effect_reply_and_release_as_scripted() -> None:
    script = (
        ScriptedCommand("DIVE", 1, hold_s=0.5, reply="ack", work_s=0.9, release_s=0.25),
        ScriptedCommand("DEPTH?", 1, hold_s=0.0, reply="timeout", work_s=30.0, release_s=1.0),
        ScriptedCommand("INIT", 1, hold_s=0.0, reply="error", work_s=2.0, release_s=0.0),
    )
    vehicle = GenericVehicle(minnow(), watchdog_s=1e6, script=script)
    assert vehicle.command(1, "DIVE", {"z": 10.0}) == []
    assert vehicle.holders == {}  # not yet: it takes effect at 0.5
    assert vehicle.advance_to(0.5) == []
    assert vehicle.holders == {"depth": "DIVE"}
    assert vehicle.advance_to(1.64) == []  # due at 0.5 + 0.9 = 1.4, released at 1.65
    (ack,) = vehicle.advance_to(1.65)
    assert (ack.command_id, ack.kind) == (1, "ack")
    vehicle.advance_to(2.0)
    vehicle.command(2, "DEPTH?", {"z": 10.0, "time_out": 30.0})
    vehicle.command(3, "INIT", {})
    (error,) = vehicle.advance_to(4.05)
    assert (error.command_id, error.kind) == (3, "error")
    assert vehicle.advance_to(32.9) == []
    (timeout,) = vehicle.advance_to(33.0)
    assert (timeout.command_id, timeout.kind, timeout.time) == (2, "timeout", 32.0)
    # A second DIVE is not in the script: served as usual (acks after ~1 s).
    vehicle.command(4, "DIVE", {"z": 5.0})
    assert [r.kind for r in vehicle.advance_to(40.0)] == ["ack"]


def test_a_script_is_read_from_the_settings_file_and_checked(tmp_path: Path) -> None:
    settings_file = tmp_path / "script.json"
    settings_file.write_text(
        '{"poll_s": 0.05, "script": [{"command": "DIVE", "occurrence": 1, "hold_s": 0, '
        '"reply": "ack", "work_s": 2, "release_s": 0}]}'
    )
    vehicle = SIMULATOR.create(SimulatorRequest(minnow(), config=settings_file))
    vehicle.command(1, "DIVE", {"z": 3.0})
    (ack,) = vehicle.advance_to(5.0)
    assert ack.time == 2.0
    for text, message in [
        ('{"script": 3}', "expected a list"),
        ('{"script": [{"command": "DIVE"}]}', "missing occurrence"),
        (
            '{"script": [{"command": "DIVE", "occurrence": 0, "hold_s": 0, "reply": "ack", '
            '"work_s": 2, "release_s": 0}]}',
            "occurrence: expected an integer >= 1",
        ),
        (
            '{"script": [{"command": "DIVE", "occurrence": 1, "hold_s": -1, "reply": "ack", '
            '"work_s": 2, "release_s": 0}]}',
            "hold_s: must be a number >= 0",
        ),
        (
            '{"script": [{"command": "DIVE", "occurrence": 1, "hold_s": 0, "reply": "done", '
            '"work_s": 2, "release_s": 0}]}',
            "DIVE cannot reply 'done'",
        ),
    ]:
        settings_file.write_text(text)
        with pytest.raises(SimulatorError, match=message) as exc:
            SIMULATOR.create(SimulatorRequest(minnow(), config=settings_file))
        assert str(settings_file) in str(exc.value)


def test_a_handler_vehicle_task_with_an_ack_poll_holds_from_arrival() -> None:
    """The library side of a task that works before it acks (`HandlerVehicle.on` ``ack``)."""
    from runtime.vehicle.handlers import HandlerVehicle

    vehicle = HandlerVehicle(minnow(), watchdog_s=1e6)
    vehicle.on("DIVE", ack=lambda job: "ack" if job.elapsed >= 2.0 else None)
    vehicle.on("SURFACE")
    with pytest.raises(ValueError, match="ack is for tasks"):
        vehicle.on("INIT", poll=lambda job: "done", ack=lambda job: "ack")
    assert vehicle.command(1, "DIVE", {"z": 5.0}) == []
    assert vehicle.holders == {"depth": "DIVE"}
    assert [(r.kind, r.time) for r in vehicle.advance_to(3.0)] == [("ack", 2.0)]
    assert vehicle.holders == {"depth": "DIVE"}  # it keeps holding after its ack
    assert vehicle.advance_to(10.0) == []  # and is polled no more
    assert [r.kind for r in vehicle.command(2, "SURFACE", {})] == ["ack"]
    assert vehicle.advance_to(10.0) == []  # an acked task replaced says nothing more
