"""What the page and the terminal view add to the state model: enabled and in-flight
transitions, awaited replies and time-outs, the operator's actions, link figures, the
bounded track and firings, and a snapshot whose size does not grow with the log."""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from coral_lang.mission import load_mission
from coral_lang.net import Net, TransitionKind
from coral_lang.profile import TIME_OUT
from runtime.eventlog import Event, EventLog, TelemetryRecord
from runtime.watch.state import (
    FINISHED_COMMANDS_KEPT,
    FIRED_KEPT,
    OPERATOR_KEPT,
    TRACK_POINTS,
    Track,
    WatchState,
    clock_rate,
    snapshot_at,
)
from tests.runtime.watch.conftest import POOL_MISSION

Rows = tuple[str, list[Event], list[TelemetryRecord]]


@pytest.fixture(scope="module")
def rows(pool_log: Path) -> Rows:
    with EventLog.open(pool_log) as log:
        assert log.net_json is not None
        return log.net_json, list(log.events()), list(log.samples())


@pytest.fixture(scope="module")
def pool_net() -> Net:
    """The mission's net, compiled again from its source: independent of the log."""
    return load_mission(POOL_MISSION, []).net


def _engine_enabled(net: Net, marking: dict[str, int]) -> list[str]:
    full = net.marking_from(marking)
    return sorted(
        t.name
        for t in net.transitions
        if t.kind in (TransitionKind.PLAIN, TransitionKind.COMMAND) and net.enabled(full, t)
    )


def test_enabled_in_flight_awaiting_and_time_outs_follow_a_real_run(
    rows: Rows, pool_net: Net
) -> None:
    net_json, events, samples = rows
    end = next(e for e in events if e.kind == "mission-end")
    probes = sorted({e.time for e in events if e.kind in ("fire", "reply") and e.time < end.time})
    assert len(probes) > 20
    seen_timeout = seen_in_flight = 0
    for t in probes:
        snap = snapshot_at(net_json, events, samples, t)
        assert snap.enabled == _engine_enabled(pool_net, snap.marking), t
        sent = {
            int(str(e.data["command_id"])): e
            for e in events
            if e.kind == "command-sent" and e.time <= t
        }
        answered = {
            int(str(e.data["command_id"])) for e in events if e.kind == "reply" and e.time <= t
        }
        out = sorted({str(sent[c].data["transition"]) for c in set(sent) - answered})
        assert snap.in_flight == out, t
        seen_in_flight += bool(out)
        for command in snap.commands:
            transition = pool_net.transition(str(command["transition"]))
            assert transition.command is not None
            waiting = command["command_id"] not in answered
            assert command["awaiting"] == (list(transition.command.replies) if waiting else [])
            limit = dict(transition.command.params).get(TIME_OUT)
            if isinstance(limit, int | float):
                assert command["timeout_at"] == pytest.approx(
                    float(str(command["sent_at"])) + limit
                )
                seen_timeout += 1
            else:
                assert command["timeout_at"] is None
    assert seen_timeout and seen_in_flight  # the pool mission has queries with a time-out
    final = snapshot_at(net_json, events, samples, end.time)
    assert final.enabled == [] and final.end is not None


def test_replay_keeps_only_the_firings_and_track_up_to_the_time(rows: Rows) -> None:
    net_json, events, samples = rows
    fires = [e for e in events if e.kind == "fire"]
    for t in (fires[3].time, fires[len(fires) // 2].time, fires[-1].time):
        snap = snapshot_at(net_json, events, samples, t)
        want = [[e.time, e.data["transition"]] for e in fires if e.time <= t][-FIRED_KEPT:]
        assert snap.fired == want
        assert all(point[0] is not None and point[0] <= t for point in snap.track)
        if snap.telemetry is not None:
            assert snap.track[-1][0] == round(float(snap.telemetry["time"] or 0), 3)
    whole = WatchState(net_json)
    whole.advance(events, samples)
    assert whole.snapshot().track[-1][1] == round(samples[-1].x, 3)  # the last is always there


def _ev(seq: int, time: float, kind: str, /, **data: object) -> Event:
    return Event(seq, time, kind, data)


def _operator(seq: int, time: float, action: str, accepted: bool, name: str | None = None) -> Event:
    return _ev(
        seq,
        time,
        "operator",
        action=action,
        input=name,
        origin="page 127.0.0.1:5000",
        accepted=accepted,
        message="ok" if accepted else "not now",
    )


def test_operator_actions_pause_and_resume_the_engine() -> None:
    state = WatchState(None)
    steps: list[tuple[Event, bool]] = [
        (_operator(1, 1.0, "pause", False), False),  # refused: nothing changes
        (_operator(2, 2.0, "pause", True), True),
        (_operator(3, 3.0, "give", False, "abort_requested"), True),
        (_operator(4, 4.0, "resume", True), False),
        (_operator(5, 5.0, "pause", True), True),
        (_operator(6, 6.0, "give", True, "abort_requested"), False),  # giving resumes
        (_operator(7, 7.0, "pause", True), True),
        (_ev(8, 8.0, "mission-end", end="final", final=True, marking={}), False),
    ]
    for event, paused in steps:
        state.advance([event])
        assert state.snapshot().paused is paused, event
    actions = state.snapshot().operator
    assert [a["action"] for a in actions] == ["pause"] * 2 + ["give", "resume", "pause", "give"] + [
        "pause"
    ]
    assert actions[2] == {
        "time": 3.0,
        "action": "give",
        "input": "abort_requested",
        "origin": "page 127.0.0.1:5000",
        "accepted": False,
        "message": "not now",
    }
    restarted = WatchState(None)
    restarted.advance([_operator(1, 1.0, "pause", True), _ev(2, 2.0, "resume")])
    assert restarted.snapshot().paused is False  # a restarted engine is not paused


def test_link_figures_count_outages_resends_and_round_trip() -> None:
    state = WatchState(None)
    state.advance(
        [
            _ev(1, 0.0, "handshake", offset=0.0, delay=0.05, resumed=False),
            _ev(2, 10.0, "reconnect"),
            _ev(3, 11.0, "reconnect"),  # still the same outage
            _ev(4, 13.0, "handshake", offset=0.0, delay=0.25, resumed=True),
            _ev(5, 13.0, "command-resent", command_id=4),
            _ev(6, 20.0, "reconnect"),
            _ev(7, 25.0, "handshake", offset=0.0, delay=0.1, resumed=True),
            _ev(8, 26.0, "rejected", reason="tag", detail=""),
            _ev(9, 30.0, "reconnect"),
            _ev(10, 31.5, "note"),
        ]
    )
    link = state.snapshot().link
    assert link["outages"] == 3 and link["reconnects"] == 4 and link["handshakes"] == 3
    assert link["outage_seconds"] == pytest.approx(3.0 + 5.0 + 1.5)  # the last one still open
    assert link["in_outage"] is True
    assert link["round_trip"] == pytest.approx(0.2)
    assert link["resends"] == 1 and link["rejected"] == 1


NET = json.dumps(
    {
        "name": "n",
        "places": [
            ["a", 1, "mission", None, [], None, None],
            ["b", 0, "mission", None, [], None, None],
            ["go.pending", 0, "pending", None, [], "go", None],
            ["stop", 0, "mission", None, [], None, None],
            ["stop.armed", 1, "armed", None, [], None, None, "stop"],
        ],
        "transitions": [
            {
                "name": "go",
                "kind": "command",
                "priority": 0,
                "inputs": [["a", 1]],
                "outputs": [["go.pending", 1]],
                "command": ["R", "XY?", [["x", 1.0], ["time_out", 30]], [], ["done", "timeout"]],
                "pending": "go.pending",
                "reply_to": None,
                "reply": None,
            },
            {
                "name": "go.done",
                "kind": "reply",
                "priority": 0,
                "inputs": [["go.pending", 1]],
                "outputs": [["b", 1]],
                "command": None,
                "pending": None,
                "reply_to": "go",
                "reply": "done",
            },
            {
                "name": "stop.operator",
                "kind": "input",
                "priority": 0,
                "inputs": [["stop.armed", 1]],
                "outputs": [["stop", 1]],
                "command": None,
                "pending": None,
                "reply_to": None,
                "reply": None,
                "operator_input": "stop",
            },
        ],
    }
)


def test_a_command_awaits_its_replies_until_its_time_out() -> None:
    state = WatchState(NET)
    state.advance([_ev(1, 0.0, "mission-start", mission_id=1, marking={"a": 1, "stop.armed": 1})])
    first = state.snapshot()
    assert first.enabled == ["go"]  # the input and the reply are not the engine's
    assert first.offered == ["stop"]
    state.advance(
        [
            _ev(2, 5.0, "fire", transition="go", command_id=1),
            _ev(3, 5.0, "command-sent", command_id=1, transition="go", name="XY?", params={}),
        ]
    )
    snap = state.snapshot()
    [command] = snap.commands
    assert command["awaiting"] == ["done", "timeout"] and command["timeout_at"] == 35.0
    assert snap.enabled == [] and snap.in_flight == ["go"]
    state.advance(
        [
            _ev(4, 9.0, "reply", command_id=1, kind="done", reply_seq=1),
            _ev(5, 9.0, "fire", transition="go.done"),
            _ev(6, 9.5, "fire", transition="stop.operator"),
        ]
    )
    done = state.snapshot()
    assert done.commands[0]["awaiting"] == [] and done.commands[0]["status"] == "done at 9.0 s"
    assert done.commands[0]["timeout_at"] == 35.0  # kept: the page shows no countdown
    assert done.in_flight == [] and done.offered == [] and done.marking == {"b": 1, "stop": 1}
    assert done.link["reply_after"] == 4.0
    assert done.fired == [[5.0, "go"], [9.0, "go.done"], [9.5, "stop.operator"]]
    assert done.fired_total == 3


@pytest.mark.slow
@settings(max_examples=40, deadline=None)
@given(
    count=st.integers(min_value=0, max_value=3000),
    limit=st.integers(min_value=2, max_value=60),
    batches=st.lists(st.integers(min_value=1, max_value=500), max_size=6),
)
def test_the_track_is_bounded_even_and_ends_with_the_newest_sample(
    count: int, limit: int, batches: list[int]
) -> None:
    track = Track(limit)
    for k in range(count):
        track.add(float(k), float(k), 0.0, 1.0, (k * 97.0) % 360.0)
    points = track.points()
    assert len(points) <= limit + 1
    if count == 0:
        assert points == []
        return
    assert points[0][0] == 0.0 and points[-1][0] == float(count - 1)
    kept = [int(p[0] or 0) for p in points[:-1]] if len(points) > 1 else []
    steps = {b - a for a, b in itertools.pairwise(kept)}
    assert len(steps) <= 1  # evenly spaced, but for the newest sample at the end
    if count > limit:
        assert len(points) > limit // 2  # decimated, not emptied
    # Headings continuous: each step the shortest turn, the same reading modulo 360.
    headings = [float(p[4] or 0) for p in points]
    for point, heading in zip(points, headings, strict=True):
        k = int(point[0] or 0)
        assert math.isclose((heading - k * 97.0) % 360.0, 0.0, abs_tol=1e-6) or math.isclose(
            (heading - k * 97.0) % 360.0, 360.0, abs_tol=1e-6
        )
    # Batching does not matter: the track depends on the samples only.
    state_a, state_b = WatchState(None), WatchState(None)
    samples = [TelemetryRecord(float(k), float(k), 1.0, 2.0, 10.0, seq=k) for k in range(count)]
    state_a.advance(samples=samples)
    start = 0
    for size in [*batches, count]:
        state_b.advance(samples=samples[start : start + size])
        start += size
    assert state_a.snapshot().track == state_b.snapshot().track


def test_headings_crossing_north_do_not_jump() -> None:
    track = Track()
    for k, psi in enumerate((350.0, 355.0, 2.0, 8.0, math.nan, 12.0, 359.0)):
        track.add(float(k), 0.0, 0.0, 0.0, psi)
    assert [p[4] for p in track.points()] == [350.0, 355.0, 362.0, 368.0, None, 372.0, 359.0]


@pytest.mark.slow
def test_a_long_log_gives_a_snapshot_of_bounded_size() -> None:
    """A day-long mission: 60 000 commands, 180 000 firings, 200 000 samples, 3 000 operator
    actions and 2 000 outages; the snapshot stays small and keeps the newest of each."""
    state = WatchState(NET)
    seq = 0
    events: list[Event] = []

    def add(time: float, kind: str, /, **data: object) -> None:
        nonlocal seq
        seq += 1
        events.append(Event(seq, time, kind, data))

    add(0.0, "mission-start", mission_id=1, marking={"a": 1})
    for n in range(60_000):
        t = float(n)
        add(t, "fire", transition="go", command_id=n)
        params = {"x": 1.0, "time_out": 30, "note": "a fairly long parameter value"}
        add(t, "command-sent", command_id=n, transition="go", name="XY?", params=params)
        add(t + 0.5, "reply", command_id=n, kind="done", reply_seq=n)
        add(t + 0.5, "fire", transition="go.done")
        add(t + 0.6, "fire", transition="t" * 40)
        if n % 20 == 0:
            add(
                t + 0.7,
                "operator",
                action="pause",
                input=None,
                origin="cli 10.0.0.1:4000",
                accepted=True,
                message="paused: no new command will be sent",
            )
        if n % 30 == 0:
            add(t + 0.8, "reconnect")
            add(t + 0.9, "handshake", offset=0.0, delay=0.01, resumed=True)
    state.advance(events)
    state.advance(
        samples=[
            TelemetryRecord(k * 0.3, 1.0 + k * 1e-4, 2.0, 3.0, float(k % 360), seq=k)
            for k in range(200_000)
        ]
    )
    snap = state.snapshot()
    size = len(json.dumps(snap.to_json()))
    assert size < 300_000, size
    assert len(snap.track) <= TRACK_POINTS + 1 and len(snap.fired) == FIRED_KEPT
    assert snap.fired_total == 180_000
    assert len(snap.operator) == OPERATOR_KEPT
    assert len(snap.commands) == FINISHED_COMMANDS_KEPT and snap.commands_total == 60_000
    assert snap.commands[-1]["command_id"] == 59_999
    assert snap.link["outages"] == 2000 and snap.unknown_firings == 60_000


def test_samples_of_a_run_at_speed_are_put_back_on_the_controllers_clock() -> None:
    # The vehicle's clock runs 5 times as fast (``--realtime --speed 5``): 50 vehicle
    # seconds after the handshake are 10 controller seconds after it, as the timeline
    # plots compute it, so the track and the plots end where the mission ends.
    meta = {"speed": 5.0, "realtime": True, "vehicle": "sim"}
    rate = clock_rate(meta)
    assert rate == 5.0
    assert clock_rate({"speed": 5.0, "realtime": True, "vehicle": "10.0.0.2:5000"}) == 1.0
    assert clock_rate({"speed": 5.0, "realtime": False, "vehicle": "sim"}) == 1.0
    state = WatchState(None, rate)
    state.advance([_ev(1, 10.0, "handshake", offset=100.0, delay=0.01)])
    sample = TelemetryRecord(160.0, 1.0, 2.0, 3.0, 90.0, seq=1)
    assert state.sample_time(sample) == pytest.approx(20.0)
    state.advance(samples=[sample])
    assert state.snapshot().telemetry is not None
    assert state.snapshot().telemetry["time"] == pytest.approx(20.0)  # type: ignore[index]
    # At rate 1 it is the offset alone, as before.
    plain = WatchState(None)
    plain.advance([_ev(1, 10.0, "handshake", offset=100.0, delay=0.01)])
    assert plain.sample_time(sample) == pytest.approx(60.0)
