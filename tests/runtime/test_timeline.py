"""The timeline: two logs on one clock, the plots, the summary, the command line."""

from __future__ import annotations

import dataclasses
import itertools
import math
import random
import struct
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from runtime.cli import main as coral_run
from runtime.eventlog import Event, EventLog, EventLogError, TelemetryRecord
from runtime.timeline import (
    DPI,
    EVENTS_FIGSIZE,
    TELEMETRY_FIGSIZE,
    MergedTimeline,
    commands_of,
    merge_logs,
    plot_timeline,
    summarize,
    telemetry_gaps,
)
from runtime.timeline_context import PlotContext, plot_context
from runtime.timeline_plots import (
    Label,
    continuous_heading,
    draw_events,
    draw_telemetry,
    new_figure,
    place_labels,
)
from tests.conftest import EXAMPLES, REPO

POOL_MISSION = EXAMPLES / "pool_mission" / "pool_mission.coral"

OFFSET = 12.5  # the vehicle clock reads 12.5 s ahead of the controller's


def make_logs(
    folder: Path,
    *,
    handshake: bool = True,
    vehicle_mission: str = "42",
    controller_samples: bool = False,
) -> tuple[Path, Path]:
    """A DEPTH command, acked and done, seen from both sides, and 2 Hz telemetry with a gap."""
    ctl_path, veh_path = folder / "ctl.log", folder / "veh.log"
    with EventLog.create(ctl_path, role="controller", mission="42", meta={}) as ctl:
        if handshake:
            ctl.event(100.0, "handshake", offset=OFFSET, delay=0.25, resumed=False)
        ctl.event(
            101.0,
            "command-sent",
            command_id=1,
            transition="dive",
            name="DEPTH",
            params={"z": 2.0},
            resources=["depth"],
        )
        ctl.event(
            102.0,
            "reply",
            command_id=1,
            reply_seq=1,
            kind="ack",
            vehicle_time=114.0,
            transition="dive",
        )
        ctl.event(
            110.0,
            "reply",
            command_id=1,
            reply_seq=2,
            kind="done",
            vehicle_time=122.0,
            transition="dive",
        )
        ctl.event(110.0, "fire", transition="dive_done", marking={"at_depth": 1})
        ctl.event(111.0, "mission-end", final="ok", marking={"at_depth": 1})
        if controller_samples:
            for i in range(4):
                ctl.telemetry(TelemetryRecord(112.5 + i, 1.0, 2.0, 0.5 * i, 90.0, seq=i + 1))
        ctl.commit({"consumed": 2})
    with EventLog.create(veh_path, role="vehicle", mission=vehicle_mission, meta={}) as veh:
        veh.event(113.9, "command-received", command_id=1, name="DEPTH")
        veh.event(114.0, "reply-issued", command_id=1, reply_seq=1, kind="ack")
        veh.event(122.0, "reply-issued", command_id=1, reply_seq=2, kind="done")
        for i in range(24):
            if 10 <= i < 16:  # 3 s without telemetry
                continue
            t = 112.5 + 0.5 * i
            est = 1.1 if i > 16 else None
            veh.telemetry(
                TelemetryRecord(t, 1.0 + 0.1 * i, 2.0, min(2.0, 0.2 * i), 90.0, est, est, seq=i + 1)
            )
        veh.commit()
    return ctl_path, veh_path


def png_size(path: Path) -> tuple[int, int]:
    head = path.read_bytes()[:24]
    assert head[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = struct.unpack(">II", head[16:24])
    return width, height


def test_vehicle_times_are_mapped_onto_the_controller_clock_and_merged_in_order(
    tmp_path: Path,
) -> None:
    ctl, veh = make_logs(tmp_path)
    timeline = merge_logs([veh, ctl])  # any order
    assert timeline.offset == OFFSET and timeline.mission == "42"
    got = [(round(t, 6), source, event.kind) for t, source, event in timeline.events]
    assert got == [
        (100.0, "controller", "handshake"),
        (101.0, "controller", "command-sent"),
        (101.4, "vehicle", "command-received"),
        (101.5, "vehicle", "reply-issued"),
        (102.0, "controller", "reply"),
        (109.5, "vehicle", "reply-issued"),
        (110.0, "controller", "reply"),
        (110.0, "controller", "fire"),
        (111.0, "controller", "mission-end"),
    ]
    # Events and samples keep their own clock; only the merged time is converted.
    assert timeline.events[2][2].time == 113.9
    assert timeline.samples[0][0] == 100.0 and timeline.samples[-1][0] == pytest.approx(111.5)
    assert [s.vehicle_time for _, s in timeline.samples[:2]] == [112.5, 113.0]
    assert timeline.sample_source == "vehicle" and len(timeline.samples) == 18
    assert (timeline.start, timeline.end) == (101.0, 111.5)
    assert merge_logs([ctl, veh]) == timeline


def test_each_vehicle_time_uses_the_last_handshake_before_it(tmp_path: Path) -> None:
    ctl_path, veh_path = tmp_path / "ctl.log", tmp_path / "veh.log"
    with EventLog.create(ctl_path, role="controller", mission="m", meta={}) as ctl:
        ctl.event(100.0, "handshake", offset=12.5)
        ctl.event(200.0, "reconnect")
        ctl.event(200.5, "handshake", offset=20.0)  # on the vehicle clock: 220.5
    with EventLog.create(veh_path, role="vehicle", mission="m", meta={}) as veh:
        veh.event(50.0, "note")  # before any handshake: the first one applies
        veh.event(215.0, "note")
        veh.event(230.0, "note")
        veh.telemetry(TelemetryRecord(230.0, 0.0, 0.0, 0.0, 0.0, seq=1))
    timeline = merge_logs([ctl_path, veh_path])
    vehicle = [t for t, source, _ in timeline.events if source == "vehicle"]
    assert vehicle == [37.5, 202.5, 210.0]
    assert timeline.samples[0][0] == 210.0
    assert timeline.offset == 12.5 and timeline.offsets == [(100.0, 12.5), (200.5, 20.0)]
    assert "2 handshakes, 12.500 .. 20.000 s" in summarize(timeline)


def test_without_a_handshake_vehicle_times_are_kept_and_the_summary_says_so(tmp_path: Path) -> None:
    ctl, veh = make_logs(tmp_path, handshake=False)
    timeline = merge_logs([ctl, veh])
    assert timeline.offset is None
    assert [t for t, s, _ in timeline.events if s == "vehicle"] == [113.9, 114.0, 122.0]
    assert "offset unknown" in summarize(timeline)


def test_a_controller_log_alone_gives_the_telemetry_it_received(tmp_path: Path) -> None:
    ctl, _ = make_logs(tmp_path, controller_samples=True)
    timeline = merge_logs([ctl])
    assert timeline.sample_source == "controller" and timeline.received_samples == 4
    assert [t for t, _ in timeline.samples] == [100.0, 101.0, 102.0, 103.0]
    assert set(timeline.logs) == {"controller"}


def test_the_vehicle_log_is_preferred_for_telemetry_and_both_counts_are_reported(
    tmp_path: Path,
) -> None:
    ctl, veh = make_logs(tmp_path, controller_samples=True)
    timeline = merge_logs([ctl, veh])
    assert timeline.sample_source == "vehicle" and len(timeline.samples) == 18
    assert "18 samples (vehicle log), 4 received by the controller" in summarize(timeline)


@pytest.mark.parametrize(
    ("which", "message"),
    [
        ("two controllers", "are both controller logs"),
        ("two vehicles", "are both vehicle logs"),
        ("vehicle only", "needs the controller's log"),
        ("missions", "is of mission '42' but .* of mission '43'"),
        ("none", "give the controller's log"),
        ("missing", "no such event log"),
    ],
)
def test_logs_that_do_not_belong_together_are_refused(
    tmp_path: Path, which: str, message: str
) -> None:
    ctl, veh = make_logs(tmp_path, vehicle_mission="43" if which == "missions" else "42")
    paths = {
        "two controllers": [ctl, ctl],
        "two vehicles": [ctl, veh, veh],
        "vehicle only": [veh],
        "missions": [ctl, veh],
        "none": [],
        "missing": [ctl, tmp_path / "nope.log"],
    }[which]
    with pytest.raises(EventLogError, match=message):
        merge_logs(paths)


def test_summary_names_the_logs_offset_counts_delays_and_gaps(tmp_path: Path) -> None:
    ctl, veh = make_logs(tmp_path)
    text = summarize(merge_logs([ctl, veh]))
    assert "mission 42: controller log" in text and "vehicle log" in text
    assert "vehicle ahead of the controller by 12.500 s" in text
    assert (
        "controller events (6): command-sent 1, fire 1, handshake 1, mission-end 1, reply 2" in text
    )
    assert "vehicle events (3): command-received 1, reply-issued 2" in text
    assert "commands: 1 sent (done 1), 1 received by the vehicle" in text
    assert "max 0.40 s (DEPTH #1 at 0.0 s)" in text
    assert "1 gaps: at 3.5 s (3.5 s long)" in text
    assert "span: 10.5 s" in text


def test_gaps_are_long_against_the_usual_rate() -> None:
    assert telemetry_gaps([]) == [] and telemetry_gaps([1.0]) == []
    assert telemetry_gaps([0.0, 0.5, 1.0, 1.5, 4.0, 4.5]) == [(1.5, 2.5)]
    assert telemetry_gaps([0.0, 2.0, 4.0, 6.0]) == []  # slow but steady
    assert telemetry_gaps([0.0, 0.1, 0.2, 0.3, 0.9]) == []  # under the 1 s floor


def test_plots_are_written_at_their_documented_size(tmp_path: Path) -> None:
    ctl, veh = make_logs(tmp_path)
    written = plot_timeline(merge_logs([ctl, veh]), tmp_path / "plots")
    assert [p.name for p in written] == ["events.png", "telemetry.png"]
    sizes = [png_size(p) for p in written]
    expected = [
        (round(EVENTS_FIGSIZE[0] * DPI), round(EVENTS_FIGSIZE[1] * DPI)),
        (round(TELEMETRY_FIGSIZE[0] * DPI), round(TELEMETRY_FIGSIZE[1] * DPI)),
    ]
    assert sizes == expected
    assert all(p.stat().st_size > 20_000 for p in written)  # drawn, not blank


def test_an_empty_mission_still_plots_and_summarises(tmp_path: Path) -> None:
    with EventLog.create(tmp_path / "ctl.log", role="controller", mission="0", meta={}):
        pass
    timeline = merge_logs([tmp_path / "ctl.log"])
    assert timeline.events == [] and timeline.samples == []
    assert "telemetry: none" in summarize(timeline)
    assert [png_size(p) for p in plot_timeline(timeline, tmp_path)] == [(1200, 650), (1200, 800)]


def test_reconnects_re_sends_and_a_restart_are_counted_and_drawn(tmp_path: Path) -> None:
    ctl_path, veh_path = tmp_path / "ctl.log", tmp_path / "veh.log"
    with EventLog.create(ctl_path, role="controller", mission="pool", meta={}) as ctl:
        ctl.event(0.0, "handshake", offset=-3.0)
        ctl.event(
            1.0, "command-sent", command_id=1, transition="go", name="GOTO", params={}, resources=[]
        )
        ctl.event(5.0, "reconnect")
        ctl.event(6.0, "rejected", reason="bad-tag", detail="")
        ctl.event(8.0, "handshake", offset=-3.0)
        ctl.event(8.1, "command-resent", command_id=1)
        ctl.event(20.0, "resume", pid=1234)  # the controller restarted
        ctl.event(22.0, "handshake", offset=-3.0, resumed=True)
        ctl.event(23.0, "reply", command_id=1, reply_seq=1, kind="done", vehicle_time=19.5)
        ctl.event(24.0, "mission-end", final=True, marking={})
    with EventLog.create(veh_path, role="vehicle", mission="", meta={}) as veh:  # it knows no name
        veh.event(7.0, "command-received", command_id=1, name="GOTO")
        veh.event(19.5, "reply-issued", command_id=1, reply_seq=1, kind="done")
    timeline = merge_logs([veh_path, ctl_path])
    assert timeline.mission == "pool"
    assert [t for t, s, _ in timeline.events if s == "vehicle"] == [10.0, 22.5]
    text = summarize(timeline)
    assert "commands: 1 sent (done 1, 1 re-sends), 1 received by the vehicle" in text
    assert "max 9.00 s (GOTO #1 at 0.0 s)" in text
    assert "reconnect 1" in text and "resume 1" in text
    written = plot_timeline(timeline, tmp_path / "plots")
    assert [png_size(p) for p in written] == [(1200, 650), (1200, 800)]


def test_the_documented_plot_sizes_are_the_real_ones() -> None:
    doc = (REPO / "docs" / "eventlog.md").read_text()
    for name, (width, height) in (("events", EVENTS_FIGSIZE), ("telemetry", TELEMETRY_FIGSIZE)):
        assert f"`{name}.png` ({round(width * DPI)} x {round(height * DPI)} px)" in doc


# --- clocks running at different rates (the simulator's --realtime --speed) -------------------


def _rate_logs(
    folder: Path, *, speed: float | None, realtime: bool | None = True, vehicle_log: bool = True
) -> list[Path]:
    """A handshake at controller 10 s = vehicle 50 s, then a vehicle running ``5 x``."""
    ctl_path, veh_path = folder / "ctl.log", folder / "veh.log"
    meta: dict[str, object] = {} if realtime is None else {"realtime": realtime}
    with EventLog.create(ctl_path, role="controller", mission="m", meta=meta) as ctl:
        ctl.event(10.0, "handshake", offset=40.0)
        for i in range(6):  # a reply every 2 s, issued 0.1 s (vehicle: 0.5 s) before arrival
            vehicle_time = 50.0 + 5.0 * (1 + 2 * i) - 0.5
            ctl.event(
                11.0 + 2 * i, "reply", command_id=i + 1, kind="done", vehicle_time=vehicle_time
            )
        ctl.event(22.0, "mission-end", end="final")
    if not vehicle_log:
        return [ctl_path]
    veh_meta: dict[str, object] = {} if speed is None else {"speed": speed}
    with EventLog.create(veh_path, role="vehicle", mission="m", meta=veh_meta) as veh:
        veh.event(100.0, "note")
        veh.telemetry(TelemetryRecord(110.0, 0.0, 0.0, 0.0, 0.0, seq=1))
    return [ctl_path, veh_path]


def test_a_faster_vehicle_clock_is_scaled_back_onto_the_controllers(tmp_path: Path) -> None:
    timeline = merge_logs(_rate_logs(tmp_path, speed=5.0))
    assert timeline.rate == 5.0 and timeline.rate_source == "vehicle log's meta 'speed'"
    # 50 s of vehicle time after the handshake is 10 s of the controller's.
    assert [t for t, s, _ in timeline.events if s == "vehicle"] == [20.0]
    assert timeline.samples[0][0] == 22.0
    assert timeline.to_controller(50.0) == 10.0
    assert "vehicle clock runs 5 x the controller's" in summarize(timeline)


def test_the_speed_of_a_virtual_time_run_is_ignored(tmp_path: Path) -> None:
    # In virtual time both sides read one loop clock, whatever the speed setting said.
    timeline = merge_logs(_rate_logs(tmp_path, speed=5.0, realtime=False))
    assert timeline.rate == 1.0 and [t for t, s, _ in timeline.events if s == "vehicle"] == [60.0]


def test_without_a_recorded_speed_the_rate_is_estimated_from_the_replies(tmp_path: Path) -> None:
    timeline = merge_logs(_rate_logs(tmp_path, speed=None, vehicle_log=False))
    assert timeline.rate == pytest.approx(5.0, rel=1e-6)
    assert timeline.rate_source == "estimated from the replies"
    commands = commands_of(timeline)
    # Reply issued times come from the controller's reply events, scaled: 0.1 s before.
    assert [round(c.issued[0][0], 6) for c in commands] == [10.9 + 2 * i for i in range(6)]


def test_replies_that_agree_with_one_keep_the_rate_at_one(tmp_path: Path) -> None:
    ctl_path = tmp_path / "ctl.log"
    with EventLog.create(ctl_path, role="controller", mission="m", meta={}) as ctl:
        ctl.event(0.0, "handshake", offset=3.0)
        for i in range(8):
            delay = 0.05 + 0.4 * (i % 3)  # link jitter
            ctl.event(1.0 + i, "reply", command_id=i, kind="ack", vehicle_time=4.0 + i - delay)
    timeline = merge_logs([ctl_path])
    assert timeline.rate == 1.0 and timeline.rate_source == "assumed"
    assert "clock rate" not in summarize(timeline)


@given(
    rate=st.floats(0.05, 100.0),
    offsets=st.lists(st.floats(-1e4, 1e4), min_size=1, max_size=4, unique=True),
    elapsed=st.floats(0.0, 1e3),
)
@settings(max_examples=80, deadline=None)
def test_each_handshake_maps_onto_itself_and_vehicle_seconds_scale_by_the_rate(
    rate: float, offsets: list[float], elapsed: float
) -> None:
    handshakes = [(1e5 * i, offset) for i, offset in enumerate(offsets)]  # far apart
    timeline = MergedTimeline([], [], offsets[0], "m", offsets=handshakes, rate=rate)
    for time, offset in handshakes:
        assert timeline.to_controller(time + offset) == pytest.approx(time, abs=1e-6)
        # Until the next handshake, rate vehicle seconds are one controller second.
        later = timeline.to_controller(time + offset + rate * elapsed)
        assert later == pytest.approx(time + elapsed, abs=1e-6)


@pytest.mark.slow
def test_a_real_time_run_at_speed_50_ends_on_the_controllers_axis(tmp_path: Path) -> None:
    """The reported bug: with --realtime --speed S the vehicle's events ran S times too far."""
    out = tmp_path / "run"
    argv = [str(POOL_MISSION), "--verify", "--certificate", str(tmp_path / "c.json")]
    argv += ["--sim", "--realtime", "--speed", "50", "--link", "lan", "--no-plots", "-q"]
    assert coral_run([*argv, "--out", str(out)]) == 0
    timeline = merge_logs([out / "controller.sqlite", out / "vehicle.sqlite"])
    assert timeline.rate == 50.0
    end = next(t for t, _, e in timeline.events if e.kind == "mission-end")
    vehicle = [t for t, s, _ in timeline.events if s == "vehicle"]
    assert end - 0.5 < vehicle[-1] < end + 0.1  # unscaled: about 50 x the mission's length
    assert timeline.samples[-1][0] < end + 0.5
    for command in commands_of(timeline):  # a reply is issued before it is consumed
        issued = min(t for t, _ in command.issued)
        assert issued < command.replies[0][0] + 0.1


# --- a vehicle log named by the wire mission id; a log still being written ------------------

MISSION_ID = 3553260803050964941


def _id_logs(folder: Path, vehicle_mission: str, *, in_checkpoint: bool = False) -> list[Path]:
    ctl_path, veh_path = folder / "ctl.log", folder / "veh.log"
    with EventLog.create(ctl_path, role="controller", mission="pool_mission", meta={}) as ctl:
        if not in_checkpoint:
            ctl.event(0.0, "mission-start", mission_id=MISSION_ID, marking={"start": 1})
        ctl.event(0.5, "handshake", offset=0.0)
        ctl.commit({"mission_id": MISSION_ID, "consumed": 0} if in_checkpoint else None)
    with EventLog.create(veh_path, role="vehicle", mission=vehicle_mission, meta={}) as veh:
        veh.event(1.0, "adopt", mission_id=MISSION_ID)
    return [ctl_path, veh_path]


@pytest.mark.parametrize("in_checkpoint", [False, True])
@pytest.mark.parametrize("vehicle_mission", ["pool_mission", str(MISSION_ID), ""])
def test_a_vehicle_log_may_name_the_mission_or_its_wire_id(
    tmp_path: Path, vehicle_mission: str, in_checkpoint: bool
) -> None:
    timeline = merge_logs(_id_logs(tmp_path, vehicle_mission, in_checkpoint=in_checkpoint))
    assert timeline.mission == "pool_mission" and timeline.mission_id == MISSION_ID
    assert [s for _, s, _ in timeline.events] == ["controller", "controller", "vehicle"][
        in_checkpoint:
    ]


@pytest.mark.parametrize("vehicle_mission", [str(MISSION_ID + 1), "other_mission"])
def test_a_vehicle_log_of_another_mission_id_is_refused(
    tmp_path: Path, vehicle_mission: str
) -> None:
    message = (
        rf"is of mission 'pool_mission' \(mission_id {MISSION_ID}\) but .*veh.log of "
        rf"mission '{vehicle_mission}': they are not two sides of one mission"
    )
    with pytest.raises(EventLogError, match=message):
        merge_logs(_id_logs(tmp_path, vehicle_mission))


def _unfinished_log(path: Path, log: EventLog | None = None) -> EventLog:
    """A mission cut short: a command sent and never answered, no mission-end."""
    log = log or EventLog.create(path, role="controller", mission="m", meta={"realtime": True})
    log.event(0.0, "mission-start", mission_id=7, marking={"start": 1})
    log.event(0.1, "fire", transition="go", command_id=1)
    log.event(0.1, "command-sent", command_id=1, transition="go", name="GOTO", params={"x": 1.0})
    log.event(0.4, "handshake", offset=2.0)
    log.telemetry(TelemetryRecord(3.0, 0.0, 0.0, 0.0, 0.0, seq=1))
    log.commit({"mission_id": 7, "consumed": 0})
    return log


@pytest.mark.slow
def test_a_mission_without_an_end_merges_summarises_and_plots(tmp_path: Path) -> None:
    _unfinished_log(tmp_path / "ctl.log").close()
    timeline = merge_logs([tmp_path / "ctl.log"])
    assert not timeline.ended and timeline.end == 1.0
    text = summarize(timeline)
    assert "not ended: no mission-end in the controller log" in text
    assert "commands: 1 sent (unfinished 1)" in text
    assert [png_size(p) for p in plot_timeline(timeline, tmp_path)] == [(1200, 650), (1200, 800)]


def test_a_log_still_open_for_writing_can_be_merged(tmp_path: Path) -> None:
    log = _unfinished_log(tmp_path / "ctl.log")
    try:
        log.event(5.0, "note", text="not committed yet")  # a reader must not see it
        try:
            timeline = merge_logs([tmp_path / "ctl.log"])
        except EventLogError as error:
            if "open for writing" in str(error):
                pytest.skip("this event log does not allow a reader beside its writer yet")
            raise
        assert [e.kind for _, _, e in timeline.events][-1] == "handshake"
        assert "not ended" in summarize(timeline)
    finally:
        log.close()


# --- readable plots: labels, heading, workspace, way-points, phases --------------------------


def _timeline_of(
    events: list[tuple[float, str, dict[str, object]]],
    samples: list[TelemetryRecord] | None = None,
) -> MergedTimeline:
    """A controller-only timeline built directly: plot tests need no file."""
    logged = [
        (t, "controller", Event(i + 1, t, kind, data)) for i, (t, kind, data) in enumerate(events)
    ]
    timed = [(s.vehicle_time, s) for s in samples or []]
    return MergedTimeline(logged, timed, None, "m", logs={"controller": Path("ctl.log")})


def _drawn_label_boxes(fig: Any, ax: Any) -> list[Any]:
    renderer = fig.canvas.get_renderer()
    return [text.get_window_extent(renderer) for text in ax.texts]


@pytest.mark.parametrize("firings", [1, 12, 400, 5000])
def test_no_two_labels_of_the_events_plot_overlap(firings: int) -> None:
    rng = random.Random(firings)
    names = ["go", "check_depth.done", "reach_wp12", "x", "a_rather_long_transition_name"]
    events: list[tuple[float, str, dict[str, object]]] = []
    for i in range(firings):
        t = rng.uniform(0.0, 100.0) if i % 3 else round(rng.uniform(0.0, 100.0))  # some at once
        events.append((t, "fire", {"transition": rng.choice(names)}))
    for i in range(60):  # command ids in three lanes, some close together
        events.append((i * 1.5, "command-sent", {"command_id": i + 1, "name": f"C{i % 3}"}))
    events.sort(key=lambda e: e[0])
    timeline = _timeline_of(events)
    fig = new_figure(EVENTS_FIGSIZE)
    ax = draw_events(fig, timeline, commands_of(timeline))
    boxes = _drawn_label_boxes(fig, ax)
    frame = ax.get_window_extent(fig.canvas.get_renderer())
    assert boxes  # something is named
    for a, b in itertools.combinations(boxes, 2):
        assert not a.overlaps(b), (a, b)
    assert all(frame.x0 <= b.x0 and b.x1 <= frame.x1 for b in boxes)
    fired = [t.get_text() for t in ax.texts if not t.get_text().startswith("#")]
    lane = [label.get_text() for label in ax.get_yticklabels() if "fired" in label.get_text()]
    if len(fired) < firings:
        assert lane == [f"fired\n{len(fired)} of {firings}\nnamed"]
    else:
        assert lane == ["fired"]


def test_labels_that_do_not_fit_are_left_out_rather_than_stacked() -> None:
    fig = new_figure((4.0, 2.0))
    ax = fig.add_axes((0.1, 0.1, 0.8, 0.8))
    ax.set_xlim(0, 10)
    ax.set_ylim(-1, 1)
    same_place = [Label(5.0, 0.0, f"label{i}", 6) for i in range(10)]
    assert place_labels(ax, same_place, levels=2) == 2  # one per level, the rest left out
    assert [t.get_text() for t in ax.texts] == ["label0", "label1"]
    assert place_labels(ax, [Label(9.99, 0.0, "off the right edge", 6)], levels=3) == 0


@given(
    start=st.floats(0.0, 360.0, exclude_max=True),
    turns=st.lists(st.floats(-179.0, 179.0), max_size=40),
)
@settings(max_examples=100, deadline=None)
def test_a_continuous_heading_follows_each_turn_and_keeps_the_compass_value(
    start: float, turns: list[float]
) -> None:
    readings = [start]
    for turn in turns:
        readings.append((readings[-1] + turn) % 360.0)
    drawn = continuous_heading(readings)
    for reading, value in zip(readings, drawn, strict=True):
        assert math.isclose((value - reading + 180.0) % 360.0, 180.0, abs_tol=1e-6)
    for turn, (a, b) in zip(turns, itertools.pairwise(drawn), strict=True):
        assert b - a == pytest.approx(turn, abs=1e-6)
    assert -90.0 <= (min(drawn) + max(drawn)) / 2.0 < 270.0


def test_a_heading_crossing_north_is_drawn_without_a_jump() -> None:
    psi = [350.0 + 2.0 * i for i in range(10)]  # 350, 352, ..., 358, 0, 2, ..., 8
    samples = [
        TelemetryRecord(float(i), 1.0, 1.0, 1.0, value % 360.0, seq=i + 1)
        for i, value in enumerate(psi)
    ]
    timeline = _timeline_of([], samples)
    fig = new_figure(TELEMETRY_FIGSIZE)
    axes = draw_telemetry(fig, timeline, [], PlotContext())
    line = axes["heading"].get_lines()[0]
    values = [float(v) for v in line.get_ydata()]
    assert max(abs(b - a) for a, b in itertools.pairwise(values)) == pytest.approx(2.0)
    assert values[0] == pytest.approx(-10.0) and values[-1] == pytest.approx(8.0)
    fig.canvas.draw()
    ticks = [t.get_text() for t in axes["heading"].get_yticklabels() if t.get_text()]
    assert "350" in ticks and "0" in ticks and not any("-" in t for t in ticks)
    low, high = axes["heading"].get_ylim()
    assert -20.0 < low < -10.0 and 8.0 < high < 20.0


def test_waypoints_and_legs_come_from_the_commands_and_the_workspace_from_the_profile(
    tmp_path: Path,
) -> None:
    usv = EXAMPLES / "profiles" / "usv.yaml"
    path = tmp_path / "ctl.log"
    meta: dict[str, object] = {"profiles": [str(usv)], "realtime": False}
    with EventLog.create(
        path, role="controller", mission="m", meta=meta, net_json='{"vehicle": "USV"}'
    ) as log:
        log.event(0.0, "command-sent", command_id=1, name="GPS_FIX?", params={"time_out": 5.0})
        log.event(
            1.0,
            "command-sent",
            command_id=2,
            name="GOTO_WAYPOINT",
            params={"x": 1.5, "y": 0.25, "speed": 3.0},
        )
        log.event(
            2.0,
            "command-sent",
            command_id=3,
            name="WAYPOINT?",
            params={"x": 1.5, "y": 0.25, "time_out": 9.0},
        )
        log.event(
            5.0,
            "command-sent",
            command_id=4,
            name="GOTO_WAYPOINT",
            params={"x": -1.0, "y": 2.0, "speed": 3.0},
        )
        log.event(9.0, "mission-end", end="final")
    context = plot_context(merge_logs([path]))
    assert context.workspace is None  # usv.yaml declares none: no outline, no error
    # km in the profile, metres on the plot; the query repeating the point adds none.
    assert [(w.x, w.y, w.command_id) for w in context.waypoints] == [
        (1500.0, 250.0, 2),
        (-1000.0, 2000.0, 4),
    ]
    assert context.phase_source == "way-points"
    assert [(p.name, p.start, p.end) for p in context.phases] == [
        ("start", 0.0, 1.0),
        ("to (1500, 250)", 1.0, 5.0),
        ("to (-1000, 2000)", 5.0, 9.0),
    ]


@pytest.mark.slow
def test_the_pool_mission_plot_has_the_pool_its_way_points_and_its_phases(tmp_path: Path) -> None:
    out = tmp_path / "run"
    argv = [str(POOL_MISSION), "--verify", "--certificate", str(tmp_path / "c.json")]
    assert coral_run([*argv, "--out", str(out), "--no-plots", "-q"]) == 0
    timeline = merge_logs([out / "controller.sqlite", out / "vehicle.sqlite"])
    context = plot_context(timeline)
    space = context.workspace
    assert space is not None and (space.x_min, space.x_max, space.y_min, space.y_max) == (
        0,
        12,
        0,
        8,
    )
    assert [(w.command, w.x, w.y) for w in context.waypoints] == [
        ("GOTO", 6.0, 4.0),
        ("LRM", 4.0, 2.0),
        ("LRM", 8.0, 2.0),
        ("LRM", 8.0, 6.0),
        ("LRM", 4.0, 6.0),
        ("SRM", 6.0, 4.0),
    ]
    assert context.phase_source == "mission"
    assert [p.name for p in context.phases] == [
        "pool_mission",
        "go_to_operating_site",
        "waypoint_navigation",
        "docking",
    ]
    assert all(a.end == b.start for a, b in itertools.pairwise(context.phases))
    assert context.phases[-1].end == timeline.end
    fig = new_figure(TELEMETRY_FIGSIZE)
    axes = draw_telemetry(fig, timeline, commands_of(timeline), context)
    outline = [p for p in axes["track"].patches if p.get_label() == "workspace (profile)"]
    assert [(o.get_x(), o.get_y(), o.get_width(), o.get_height()) for o in outline] == [
        (0, 0, 8, 12)
    ]
    legend = [t.get_text() for t in axes["track"].get_legend().get_texts()]
    assert {"way-points", "workspace (profile)", "docking", "waypoint_navigation"} <= set(legend)
    # A profile without a workspace (every profile before it existed) still plots.
    written = plot_timeline(
        timeline, tmp_path / "plots", dataclasses.replace(context, workspace=None)
    )
    assert [png_size(p) for p in written] == [(1200, 650), (1200, 800)]
