"""The terminal view: what a frame shows, when it draws, and following a log to its end.

Frames are rendered into in-memory consoles (a terminal, and not one); the drawing policy
is driven with virtual wall times through `TerminalView.tick`, so no test waits for a
second to pass.
"""

from __future__ import annotations

import asyncio
import io
import re
import threading
import time
from collections.abc import Mapping
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from rich.console import Console

from runtime.cli import main as coral_run
from runtime.eventlog import EventLog, EventLogError
from runtime.tui import (
    MAX_COMMANDS,
    TerminalView,
    render,
    run_terminal_view,
    summary_line,
    watch_log_tui,
)
from tests.conftest import EXAMPLES

POOL_MISSION = EXAMPLES / "pool_mission" / "pool_mission.coral"


def console(*, terminal: bool, height: int = 200) -> Console:
    return Console(
        file=io.StringIO(), width=100, height=height, force_terminal=terminal, record=True
    )


def text_of(frame: object, *, now: float | None = None) -> str:
    out = console(terminal=True)
    out.print(frame)
    return out.export_text()


def command(
    command_id: int,
    name: str,
    sent_at: float,
    *,
    params: Mapping[str, object] | None = None,
    replies: list[tuple[str, float]] = (),  # type: ignore[assignment]
    awaiting: list[str] | None = None,
    timeout_at: float | None = None,
    sends: int = 1,
) -> dict[str, object]:
    """A command as `Snapshot.to_json()` gives it; without ``awaiting`` in the shape logs had
    before the engine's extension (no awaiting, no timeout_at)."""
    entry: dict[str, object] = {
        "command_id": command_id,
        "name": name,
        "transition": name.lower(),
        "params": dict(params or {}),
        "sent_at": sent_at,
        "sends": sends,
        "replies": [{"kind": k, "time": t} for k, t in replies],
        "status": f"{replies[-1][0]} at {replies[-1][1]:.1f} s" if replies else "awaiting reply",
    }
    if awaiting is not None:
        entry["awaiting"] = awaiting
        entry["timeout_at"] = timeout_at
    return entry


def extended(**changes: object) -> dict[str, object]:
    """A snapshot with every field the page and the terminal view read."""
    snap: dict[str, object] = {
        "start": 0.0,
        "time": 75.5,
        "seq": 40,
        "marking": {"at_wp1": 2, "check_site.pending": 1, "abort_requested.armed": 1},
        "enabled": ["log_position"],
        "in_flight": ["check_site"],
        "offered": ["abort_requested"],
        "commands": [
            command(6, "FIX_XY", 17.0, replies=[("done", 27.7)], awaiting=[]),
            command(
                7,
                "XYPSI?",
                28.5,
                params={"x": 6.0, "y": 4.0, "psi": 90.0, "time_out": 90.0},
                awaiting=["done", "timeout"],
                timeout_at=118.5,
                sends=2,
            ),
        ],
        "commands_total": 7,
        "telemetry": {
            "time": 72.5,
            "vehicle_time": 72.4,
            "x": 2.5,
            "y": -1.25,
            "depth": 1.98,
            "heading": 89.9,
        },
        "track": [],
        "fired": [],
        "link": {"handshakes": 1, "reconnects": 2, "round_trip": 0.44, "in_outage": False},
        "paused": False,
        "operator": [
            {
                "time": 70.0,
                "action": "pause",
                "input": None,
                "origin": "cli 127.0.0.1:40022",
                "accepted": True,
                "message": "paused",
            }
        ],
        "end": None,
        "unknown_firings": 0,
    }
    snap.update(changes)
    return snap


def test_a_frame_shows_marking_commands_telemetry_link_and_operator() -> None:
    shown = text_of(render(extended(), mission="pool_mission"))
    assert re.search(r"pool_mission\s+t 75\.5 s\s+seq 40\s+LIVE", shown)
    assert re.search(r"at_wp1\s+2\s", shown)
    assert re.search(r"check_site\.pending\s+1\s+command in flight \(check_site\)", shown)
    assert re.search(r"abort_requested\.armed\s+1\s+input abort_requested not given", shown)
    # The command still out first, with its awaited replies and the time-out countdown.
    line = next(row for row in shown.splitlines() if "XYPSI?" in row)
    assert re.search(
        r"7\s+XYPSI\?\(x=6, y=4, psi=90, time_out=90\)\s+28\.5 s \(x2\)\s+done, timeout\s+in 43 s\s*$",
        line,
    ), line
    assert shown.index("XYPSI?") < shown.index("FIX_XY")
    assert re.search(r"6\s+FIX_XY\(\)\s+17\.0 s\s+done at 27\.7 s", shown)
    assert "... 5 more" in shown  # commands_total 7, two listed
    assert "x 2.50 m  y -1.25 m  depth 1.98 m  heading 89.9°  (3.0 s old)" in shown
    assert "handshakes 1  reconnects 2  round trip 0.44 s  in outage no" in shown
    assert "enabled    log_position" in shown
    assert "inputs     abort_requested" in shown
    assert "70.0 s pause from cli 127.0.0.1:40022: accepted; paused" in shown


def test_the_countdown_follows_the_time_given() -> None:
    assert "in 13 s" in text_of(render(extended(), now=105.5))
    assert re.search(r"done, timeout\s+due", text_of(render(extended(), now=120.0)))


def test_times_are_shown_from_the_logs_start() -> None:
    # A real-time run's controller clock is the machine's monotonic clock: 28,000 s in.
    base = 28_000.0
    snap = extended(
        start=base,
        time=base + 75.5,
        commands=[command(6, "FIX_XY", base + 17.0, replies=[("done", base + 27.7)], awaiting=[])],
        end={"time": base + 80.0, "end": "final"},
        operator=[{"time": base + 70.0, "action": "pause", "accepted": False, "message": "no"}],
    )
    shown = text_of(render(snap, mission="m"))
    assert "m  t 75.5 s" in shown and "ENDED final at 80.0 s" in shown
    assert re.search(r"6\s+FIX_XY\(\)\s+17\.0 s\s+done at 27\.7 s", shown)
    assert "70.0 s pause from ?: refused; no" in shown
    assert summary_line(snap).startswith("mission t 75.5 s ENDED final at 80.0 s")
    # Without a start, the view counts from the first snapshot holding an event.
    del snap["start"]
    view = TerminalView(lambda: snap, console(terminal=False))
    assert view.origin(extended(seq=0, start=None, time=0.0, commands=[])) == 0.0
    assert view.origin(snap) == base + 17.0
    assert view.origin(extended(start=None, time=base + 99.0, commands=[])) == base + 17.0


def test_a_snapshot_without_the_engine_fields_still_renders() -> None:
    snap = {
        "time": 3.0,
        "seq": 5,
        "marking": {"set_depth.pending": 1},
        "commands": [command(1, "INIT", 0.0, replies=[("done", 2.0)]), command(2, "DEPTH", 2.0)],
        "telemetry": None,
        "link": {"handshakes": 1, "reconnects": 0, "rejected": 0, "telemetry-lost": 0},
        "end": None,
        "unknown_firings": 1,
    }
    shown = text_of(render(snap, mission="m"))
    assert re.search(r"2\s+DEPTH\(\)\s+2\.0 s\s+reply\s*$", shown, re.MULTILINE)
    assert "no telemetry yet" in shown
    assert "(1 firings of unknown transitions)" in shown
    assert "enabled" not in shown and "operator" not in shown


def test_the_header_says_paused_and_how_the_mission_ended() -> None:
    assert "PAUSED" in text_of(render(extended(paused=True)))
    end = {
        "time": 12.0,
        "end": "stopped",
        "final": False,
        "stopped_by": "SIGINT",
        "made_safe": True,
    }
    shown = text_of(render(extended(end=end)))
    assert "ENDED stopped at 12.0 s (by SIGINT, made safe)" in shown
    assert "LIVE" not in shown
    assert "in 43 s" not in shown  # nothing counts down once the mission has ended
    line = summary_line(extended(end={"time": 9.0, "end": "final", "final": True}), mission="m")
    assert line.startswith("m t 75.5 s ENDED final at 9.0 s | marking ")


def test_a_log_cannot_send_the_terminal_escape_sequences() -> None:
    evil = "p\x1b[2J\x1b]0;owned\x07\nq"
    snap = extended(
        marking={evil: 1},
        commands=[command(1, evil, 0.0, params={evil: evil})],
        operator=[{"time": 1.0, "action": evil, "origin": evil, "message": evil}],
        link={evil: evil},
        end={"time": 2.0, "end": evil},
    )
    for terminal in (True, False):
        out = console(terminal=terminal)
        out.print(render(snap, mission=evil))
        out.print(summary_line(snap, mission=evil))
        written = out.file.getvalue()  # type: ignore[attr-defined]
        assert "\x1b[2J" not in written and "\x1b]0" not in written and "\x07" not in written
        assert "p?[2J?]0;owned??q" in written


def test_a_frame_is_bounded_however_long_the_mission() -> None:
    commands = [
        command(i, "GOTO", float(i), awaiting=["done"], timeout_at=None) for i in range(1, 101)
    ]
    snap = extended(
        commands=commands,
        commands_total=250,
        marking={f"p{i}": 1 for i in range(500)},
        enabled=[f"t{i}" for i in range(300)],
    )
    shown = text_of(render(snap))
    listed = [row for row in shown.splitlines() if re.match(r"\s*\d+\s+GOTO\(\)", row)]
    assert len(listed) == MAX_COMMANDS
    assert listed[0].split()[0] == "100"  # newest first
    assert "... 220 more" in shown  # 250 sent, 30 shown
    assert "... 480 more" in shown  # places
    assert "... 290 more" in shown  # enabled transitions
    assert len(shown.splitlines()) < 80


def test_the_plain_mode_prints_one_line_at_most_once_a_second() -> None:
    out = console(terminal=False)
    state = {"seq": 0}

    def snapshot() -> dict[str, object]:
        state["seq"] += 1  # a busy mission: a change at every look
        return extended(seq=state["seq"], time=float(state["seq"]))

    view = TerminalView(snapshot, out, mission="pool_mission")
    walls = [i * 0.25 for i in range(21)]  # five virtual seconds
    drawn = [wall for wall in walls if view.tick(wall)]
    assert drawn == [0.0, 1.0, 2.0, 3.0, 4.0, 5.0]
    view.stop(5.1)  # the last state, even within the second
    lines = out.export_text().splitlines()
    assert len(lines) == 7
    assert lines[-1].startswith("pool_mission t 22.0 s LIVE | marking ")
    assert all(line.startswith("pool_mission t ") for line in lines)
    assert "\x1b" not in out.file.getvalue()  # type: ignore[attr-defined]


def test_the_plain_mode_does_not_repeat_an_unchanged_state() -> None:
    out = console(terminal=False)
    view = TerminalView(lambda: extended(), out)
    assert [view.tick(i * 0.5) for i in range(8)] == [True] + [False] * 7
    view.stop(4.0)
    assert len(out.export_text().splitlines()) == 1


def test_the_terminal_redraws_on_change_or_each_second_for_the_countdowns() -> None:
    out = console(terminal=True)
    snap = extended()
    view = TerminalView(lambda: snap, out, rate=1.0)
    view.start()
    try:
        assert [view.tick(i * 0.25) for i in range(9)] == [
            True,
            False,
            False,
            False,
            True,
            False,
            False,
            False,
            True,
        ]
        # Two seconds on, the snapshot unchanged: the countdown moved at rate 1.
        assert view.now(snap, 2.0) == pytest.approx(77.5)
        snap = extended(seq=41, time=80.0)
        assert view.tick(2.1)  # a change draws at once
        assert view.now(snap, 2.1) == pytest.approx(80.0)
    finally:
        view.stop(2.2)
    shown = out.export_text()
    assert "in 41 s" in shown and "in 38 s" in shown
    assert "\x1b[" in out.file.getvalue()  # type: ignore[attr-defined]


def test_a_clock_given_by_the_caller_wins_and_an_ended_mission_stands_still() -> None:
    view = TerminalView(lambda: extended(), console(terminal=True), clock=lambda: 100.0)
    assert view.now(extended(), 50.0) == 100.0
    still = TerminalView(lambda: extended(), console(terminal=True), rate=1.0)
    ended = extended(end={"time": 75.5, "end": "final"})
    assert still.now(ended, 50.0) == 75.5


def test_run_terminal_view_draws_until_stopped_then_leaves_the_last_frame() -> None:
    out = console(terminal=True)
    calls = {"n": 0}

    def snapshot() -> dict[str, object]:
        calls["n"] += 1
        if calls["n"] < 3:
            return extended(seq=calls["n"])
        return extended(seq=3, end={"time": 80.0, "end": "final", "final": True})

    async def main() -> None:
        stop = asyncio.Event()
        view = asyncio.create_task(
            run_terminal_view(snapshot, stop=stop, refresh=0.01, console=out, mission="pm")
        )
        while calls["n"] < 4:
            await asyncio.sleep(0.01)
        stop.set()
        await asyncio.wait_for(view, 2)

    asyncio.run(main())
    assert "ENDED final at 80.0 s" in out.export_text()


@pytest.mark.slow
@given(
    st.dictionaries(
        st.sampled_from(
            [
                "time",
                "seq",
                "marking",
                "commands",
                "telemetry",
                "link",
                "end",
                "paused",
                "operator",
                "enabled",
                "offered",
                "commands_total",
                "unknown_firings",
            ]
        ),
        st.recursive(
            st.none() | st.booleans() | st.floats() | st.integers() | st.text(max_size=5),
            lambda inner: (
                st.lists(inner, max_size=3)
                | st.dictionaries(
                    st.sampled_from(
                        ["x", "time", "end", "command_id", "awaiting", "timeout_at", "replies", "p"]
                    ),
                    inner,
                    max_size=4,
                )
            ),
            max_leaves=12,
        ),
    )
)
@settings(max_examples=60, deadline=None)
def test_any_json_shape_renders_and_the_summary_is_one_line(snap: dict[str, object]) -> None:
    text_of(render(snap))
    assert "\n" not in summary_line(snap)


@pytest.fixture(scope="module")
def pool_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("tui-pool")
    argv = [str(POOL_MISSION), "--verify", "--certificate", str(folder / "c.json")]
    argv += ["--no-plots", "-q", "--out", str(folder / "run")]
    assert coral_run(argv) == 0
    return folder / "run" / "controller.sqlite"


@pytest.mark.slow
def test_watch_log_tui_shows_a_finished_run_to_its_final_marking(pool_log: Path) -> None:
    plain = console(terminal=False)
    assert watch_log_tui(pool_log, console=plain) == 0
    lines = plain.export_text().splitlines()
    assert len(lines) == 1, lines
    assert re.match(
        r"pool_mission t 166\.\d s ENDED final at 166\.\d s \| marking mission_complete=1 \| commands 23 \(0 out\)",
        lines[0],
    )
    terminal = console(terminal=True)
    assert watch_log_tui(pool_log, console=terminal) == 0
    shown = terminal.export_text()
    assert re.search(r"mission_complete\s+1", shown)
    assert re.search(r"23\s+SURFACE\?\(time_out=60\)", shown)


def test_watch_log_tui_follows_a_live_log_to_its_end(tmp_path: Path) -> None:
    path = tmp_path / "controller.sqlite"
    log = EventLog.create(path, role="controller", mission="live_one", meta={})
    log.event(0.0, "mission-start", marking={"start": 1})
    log.commit()
    out = console(terminal=False)
    result: list[int] = []
    follower = threading.Thread(
        target=lambda: result.append(watch_log_tui(path, poll_interval=0.02, console=out))
    )
    follower.start()
    try:
        time.sleep(0.1)
        log.event(1.0, "fire", transition="go", marking={"there": 1})
        log.commit()
        time.sleep(0.1)
        log.event(2.0, "mission-end", end="final", final=True, marking={"there": 1})
        log.commit()
        follower.join(5)
    finally:
        log.close()
    assert result == [0]
    lines = out.export_text().splitlines()
    assert lines[0].startswith("live_one t 0.0 s LIVE | marking start=1 |")
    assert lines[-1].startswith("live_one t 2.0 s ENDED final at 2.0 s | marking there=1 |")


def test_ctrl_c_ends_watch_log_tui_with_0(
    pool_log: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import runtime.tui

    def interrupted(*args: object, **kwargs: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(runtime.tui, "_follow", interrupted)
    assert watch_log_tui(pool_log, console=console(terminal=False)) == 0
    assert "coral-run watch: stopped" in capsys.readouterr().err


def test_a_missing_garbage_or_vehicle_log_raises(tmp_path: Path) -> None:
    with pytest.raises(EventLogError, match=r"nothing\.sqlite: no such event log"):
        watch_log_tui(tmp_path / "nothing.sqlite")
    garbage = tmp_path / "garbage.sqlite"
    garbage.write_bytes(b"\x00not a database at all" * 50)
    with pytest.raises(EventLogError, match=r"garbage\.sqlite"):
        watch_log_tui(garbage)
    vehicle = tmp_path / "vehicle.sqlite"
    EventLog.create(vehicle, role="vehicle", mission="1", meta={}).close()
    with pytest.raises(EventLogError, match="a vehicle log"):
        watch_log_tui(vehicle)
