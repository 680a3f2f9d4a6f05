"""``coral-run run MISSION --schedule FILE``: replay a timed schedule and say if it was followed.

The schedules are built by hand here (timed analysis exports them; these tests do not
depend on it): a tiny MINNOW mission whose query is done in time, the same mission with
DIVE's command taking the link's longest delay so that its query times out, a schedule
that lies about a time (divergence, exit 1), and the pool mission, whose schedule is
taken from a run of its own and then replayed.
"""

from __future__ import annotations

import json
from collections import Counter
from collections.abc import Callable
from pathlib import Path

import pytest

from analysis.timed import ScheduledCommand, ScheduledFiring, TimedSchedule
from coral_lang.mission import load_mission
from coral_lang.net import Net
from coral_lang.profile import load_bundled_profile, load_profile
from coral_lang.timing import LinkBounds
from runtime.cli import main
from runtime.eventlog import EventLog
from runtime.replay import REPLY_SLACK_S
from tests.conftest import EXAMPLES
from tests.runtime.helpers import POOL_MISSION

MINNOW = EXAMPLES / "profiles" / "minnow.yaml"
LINK = LinkBounds("test-link", 0.2, 2.0)

TINY = """\
mission tiny
vehicle MINNOW

place start = 1
place diving, at_depth, failed
final { at_depth }
final { failed }

transition dive
    wait   { start }
    action { MINNOW(DIVE, z = 10.0 m) -> { ack: diving, error: failed } }

transition check
    wait   { diving }
    action { MINNOW(DEPTH?, z = 10.0 m, time_out = 70 s) -> { done: at_depth, timeout: failed } }
"""


@pytest.fixture
def tiny(tmp_path: Path) -> tuple[Path, Net]:
    path = tmp_path / "tiny.coral"
    path.write_text(TINY)
    return path, load_mission(path, [load_profile(MINNOW)]).net


def _schedule(
    net: Net,
    commands: tuple[ScheduledCommand, ...],
    firings: list[tuple[float, str]],
    final: dict[str, int] | None,
    kind: str = "worst-case",
) -> TimedSchedule:
    return TimedSchedule(
        mission=net.name,
        net_digest=net.digest(),
        kind=kind,
        reason="built by hand",
        link=LINK,
        duration_s=max(t for t, _ in firings),
        final=final,
        commands=commands,
        firings=tuple(ScheduledFiring(t, name) for t, name in firings),
    )


def _tiny_done(net: Net) -> TimedSchedule:
    """Every delay at the link's minimum: DEPTH? tracks DIVE (started at 0.2) for 60 s."""
    dive = ScheduledCommand("dive", 1, "DIVE", 0.0, 0.2, "ack", 1.0, 0.1, 0.2)
    sent = dive.arrived_at  # 1.5
    check = ScheduledCommand("check", 1, "DEPTH?", sent, 0.2, "done", 60.2 - 1.7, 0.0, 0.2)
    firings = [(0.0, "dive"), (sent, "dive.ack"), (sent, "check"), (check.arrived_at, "check.done")]
    return _schedule(net, (dive, check), firings, {"at_depth": 1}, "best-case")


def _tiny_timeout(net: Net) -> TimedSchedule:
    """DIVE's command takes the link's longest delay (2 s) and tracking its longest work
    (72 s): done at 74 s, after DEPTH?'s time-out at 3.2 + 70 s: it times out."""
    dive = ScheduledCommand("dive", 1, "DIVE", 0.0, 2.0, "ack", 0.8, 0.0, 0.2)
    sent = dive.arrived_at  # 3.0
    check = ScheduledCommand("check", 1, "DEPTH?", sent, 0.2, "timeout", 70.0, 0.0, 0.2)
    firings = [
        (0.0, "dive"),
        (sent, "dive.ack"),
        (sent, "check"),
        (check.arrived_at, "check.timeout"),
    ]
    return _schedule(net, (dive, check), firings, {"failed": 1}, "timeout")


def _replay(mission: Path, schedule: Path, out: Path, *extra: str) -> int:
    return main(
        [
            "run",
            str(mission),
            *extra,
            "--verify",
            "--certificate",
            str(out.parent / f"{mission.stem}.certificate.json"),
            "--schedule",
            str(schedule),
            "--out",
            str(out),
            "--no-plots",
            "-q",
        ]
    )


def _fired(out: Path) -> list[tuple[float, str]]:
    """The replay's firings on mission time (from the handshake, when commands leave)."""
    with EventLog.open(out / "controller.sqlite") as log:
        events = list(log.events(("handshake", "fire")))
    origin = next(e.time for e in events if e.kind == "handshake")
    return [
        (max(0.0, e.time - origin), str(e.data["transition"])) for e in events if e.kind == "fire"
    ]


@pytest.mark.parametrize("build", [_tiny_done, _tiny_timeout])
def test_a_replay_fires_as_scheduled(
    build: Callable[[Net], TimedSchedule],
    tiny: tuple[Path, Net],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    mission, net = tiny
    schedule = build(net)
    path = tmp_path / "schedule.json"
    schedule.write(path)
    code = _replay(mission, path, tmp_path / "run", "--profile", str(MINNOW))
    out = capsys.readouterr().out
    assert code == 0, out
    assert "replay: followed the schedule" in out
    fired = _fired(tmp_path / "run")
    assert [name for _, name in fired] == [f.transition for f in schedule.firings]
    for (when, _), wanted in zip(fired, schedule.firings, strict=True):
        assert when == pytest.approx(wanted.time, abs=2 * REPLY_SLACK_S)
    settings = json.loads((tmp_path / "run" / "replay-vehicle.json").read_text())
    assert [e["hold_s"] for e in settings["script"]] == pytest.approx(
        [c.up_delay_s - LINK.min_delay_s for c in schedule.commands]
    )


def test_firings_listed_out_of_time_order_are_compared_in_time_order(
    tiny: tuple[Path, Net], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Concurrent branches may be listed branch by branch; the run happens in time order."""
    mission, net = tiny
    right = _tiny_done(net)
    shuffled = [right.firings[i] for i in (0, 3, 1, 2)]
    path = tmp_path / "shuffled.json"
    _schedule(net, right.commands, [(f.time, f.transition) for f in shuffled], right.final).write(
        path
    )
    assert _replay(mission, path, tmp_path / "run", "--profile", str(MINNOW)) == 0
    assert "replay: followed the schedule" in capsys.readouterr().out


def test_a_schedule_the_run_does_not_follow_is_reported_with_its_first_difference(
    tiny: tuple[Path, Net], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    mission, net = tiny
    right = _tiny_done(net)
    wrong = _schedule(
        net,
        right.commands,
        [(f.time if f.transition != "check.done" else 40.0, f.transition) for f in right.firings],
        right.final,
    )
    path = tmp_path / "wrong.json"
    wrong.write(path)
    assert _replay(mission, path, tmp_path / "run", "--profile", str(MINNOW)) == 1
    out = capsys.readouterr().out
    assert "DIVERGED at firing 4: check.done fired at 60.400 s, scheduled at 40.000 s" in out


def test_a_schedule_of_another_transition_order_diverges(
    tiny: tuple[Path, Net], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    mission, net = tiny
    right = _tiny_done(net)
    firings = [(f.time, f.transition) for f in right.firings[:3]] + [(60.4, "check.timeout")]
    path = tmp_path / "wrong.json"
    _schedule(net, right.commands, firings, {"failed": 1}).write(path)
    assert _replay(mission, path, tmp_path / "run", "--profile", str(MINNOW)) == 1
    out = capsys.readouterr().out
    assert "DIVERGED at firing 4: the schedule fires check.timeout" in out
    assert "the run fired check.done" in out


def test_bad_schedules_are_refused_before_anything_runs(
    tiny: tuple[Path, Net], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    mission, net = tiny
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "coral-schedule/1", "mission": 3}')
    assert _replay(mission, bad, tmp_path / "run1", "--profile", str(MINNOW)) == 2
    assert str(bad) in capsys.readouterr().err
    other = _tiny_done(net)
    data = other.to_json()
    data["net_digest"] = "sha256:" + "0" * 64
    bad.write_text(json.dumps(data))
    assert _replay(mission, bad, tmp_path / "run2", "--profile", str(MINNOW)) == 2
    err = capsys.readouterr().err
    assert "sha256:" + "0" * 64 in err and net.digest() in err
    # Two DEPTH? sent at one instant with other timings: the vehicle cannot tell them apart.
    one = other.commands[1]
    twin = ScheduledCommand("check", 2, "DEPTH?", one.sent_at, 0.5, "done", 50.0, 0.0, 0.2)
    data = _schedule(net, (*other.commands, twin), [(0.0, "dive")], None).to_json()
    bad.write_text(json.dumps(data))
    assert _replay(mission, bad, tmp_path / "run3", "--profile", str(MINNOW)) == 2
    assert "cannot tell them apart" in capsys.readouterr().err
    assert not (tmp_path / "run3" / "controller.sqlite").exists()
    assert main(["run", str(mission), "--schedule", str(bad), "--link", "lan"]) == 2
    assert "--schedule replays" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("transition", "nowhere", "commands[1].transition: 'nowhere' sends no command here"),
        ("command", "DIVE", "commands[1].command: check sends DEPTH?, not DIVE"),
        ("reply", "maybe", "commands[1].reply: check takes no reply 'maybe'"),
        ("occurrence", None, "commands[2].occurrence: check #1 is listed twice"),
    ],
)
def test_a_schedule_edited_by_hand_is_refused_naming_the_entry(
    tiny: tuple[Path, Net],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    field: str,
    value: str | None,
    message: str,
) -> None:
    mission, net = tiny
    data = _tiny_done(net).to_json()
    commands = data["commands"]
    assert isinstance(commands, list)
    if value is None:  # the same (transition, occurrence) twice
        commands.append(dict(commands[1]))
    else:
        commands[1][field] = value
    bad = tmp_path / "edited.json"
    bad.write_text(json.dumps(data))
    assert _replay(mission, bad, tmp_path / "run", "--profile", str(MINNOW)) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "run" / "controller.sqlite").exists()


def _int(value: object) -> int:
    assert isinstance(value, int)
    return value


def _schedule_of_run(log_path: Path, net: Net, low: float) -> TimedSchedule:
    """The schedule a run over a constant ``low`` link followed, read from its log."""
    with EventLog.open(log_path) as log:
        events = list(log.events(("handshake", "fire", "command-sent", "reply")))
    origin = next(e.time for e in events if e.kind == "handshake")
    count: Counter[str] = Counter()
    sent: dict[int, tuple[str, int, str, float]] = {}
    commands: list[ScheduledCommand] = []
    firings: list[tuple[float, str]] = []
    for e in events:
        t = max(0.0, e.time - origin)
        if e.kind == "command-sent":
            name = str(e.data["transition"])
            count[name] += 1
            sent[_int(e.data["command_id"])] = (name, count[name], str(e.data["name"]), t)
        elif e.kind == "reply":
            name, n, command, at = sent[_int(e.data["command_id"])]
            work = t - at - 2 * low
            commands.append(
                ScheduledCommand(name, n, command, at, low, str(e.data["kind"]), work, 0.0, low)
            )
        elif e.kind == "fire":
            firings.append((t, str(e.data["transition"])))
    commands.sort(key=lambda c: c.sent_at)
    return _schedule(net, tuple(commands), firings, None)


@pytest.mark.slow
def test_the_pool_mission_replays_the_schedule_of_its_own_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from coral_lang.linkprofile import LinkProfile
    from runtime.gate import approve_mission
    from runtime.run import RunConfig, run_mission

    approved = approve_mission(
        POOL_MISSION, tmp_path / "pool.certificate.json", issue=True, profiles=[]
    )
    result = run_mission(
        approved,
        RunConfig(
            out_dir=tmp_path / "first",
            psk=bytes(32),
            link=LinkProfile(name="constant", delay_s=0.3),
            seed=3,
            simulator="generic",
            console=lambda line: None,
            log_key_ephemeral=True,
        ),
    )
    assert result.ok
    schedule = _schedule_of_run(tmp_path / "first" / "controller.sqlite", approved.net, 0.3)
    schedule = TimedSchedule(
        **{
            **schedule.__dict__,
            "link": LinkBounds("constant", 0.3, 3.0),
            "final": {p: n for p, n in result.marking.items() if n},
        }
    )
    assert len(schedule.commands) >= 10
    path = tmp_path / "pool.json"
    schedule.write(path)
    assert _replay(POOL_MISSION, path, tmp_path / "replay") == 0
    assert "replay: followed the schedule" in capsys.readouterr().out
    assert load_bundled_profile("ROMEO").timing.reply_latency_s >= 0.05
