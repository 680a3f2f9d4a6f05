"""The timeline: two logs on one clock, the plots, the summary, the command line."""

from __future__ import annotations

import struct
from pathlib import Path

import pytest

from runtime.eventlog import EventLog, EventLogError, TelemetrySample
from runtime.timeline import (
    DPI,
    EVENTS_FIGSIZE,
    TELEMETRY_FIGSIZE,
    merge_logs,
    plot_timeline,
    summarize,
    telemetry_gaps,
)
from tests.conftest import REPO

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
                ctl.telemetry(TelemetrySample(112.5 + i, i + 1, 1.0, 2.0, 0.5 * i, 90.0))
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
                TelemetrySample(t, i + 1, 1.0 + 0.1 * i, 2.0, min(2.0, 0.2 * i), 90.0, est, est)
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
    # Events keep their own clock; only the merged time is converted.
    assert timeline.events[2][2].time == 113.9
    assert timeline.samples[0].time == 100.0 and timeline.samples[-1].time == pytest.approx(111.5)
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
        veh.telemetry(TelemetrySample(230.0, 1, 0.0, 0.0, 0.0, 0.0))
    timeline = merge_logs([ctl_path, veh_path])
    vehicle = [t for t, source, _ in timeline.events if source == "vehicle"]
    assert vehicle == [37.5, 202.5, 210.0]
    assert timeline.samples[0].time == 210.0
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
    assert [s.time for s in timeline.samples] == [100.0, 101.0, 102.0, 103.0]
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
    def at(*times: float) -> list[TelemetrySample]:
        return [TelemetrySample(t, i, 0.0, 0.0, 0.0, 0.0) for i, t in enumerate(times)]

    assert telemetry_gaps(at()) == [] and telemetry_gaps(at(1.0)) == []
    assert telemetry_gaps(at(0.0, 0.5, 1.0, 1.5, 4.0, 4.5)) == [(1.5, 2.5)]
    assert telemetry_gaps(at(0.0, 2.0, 4.0, 6.0)) == []  # slow but steady
    assert telemetry_gaps(at(0.0, 0.1, 0.2, 0.3, 0.9)) == []  # under the 1 s floor


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
