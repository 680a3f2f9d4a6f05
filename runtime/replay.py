"""Replay a timed schedule: watch the run timed analysis found happen, and check it did.

``coral-check verify --timed`` proves a mission's worst case and finds the runs in which
a query times out; it exports each as a `analysis.timed.TimedSchedule` (every command's
link delays, reply kind and work time). ``coral-run run MISSION --schedule FILE`` plays
one against the generic simulated vehicle, under virtual time and the engine's PRIORITY
policy, logging like any run (``coral-run timeline`` plots it), and then says whether the
run followed the schedule.

How the delays are kept. The link carries encrypted frames, so it cannot tell a
command from a heartbeat; the vehicle can. The emulated link therefore delays *every*
message by the schedule's link minimum (``link.min_delay_s``: the handshake, heartbeats
and acknowledgements too), and the generic vehicle runs in scripted mode
(`runtime.vehicle.generic.ScriptedCommand`): a command takes effect ``up_delay_s - min``
after it arrives, gives the scheduled reply ``work_s`` later, and releases it
``latency_s + down_delay_s - min`` after it fell due. The engine sees each command reach
the vehicle, and each reply come back, exactly when the schedule says.

How commands are matched. A schedule names a command by (transition, occurrence); the
vehicle sees only its name. With one constant link delay, commands reach the vehicle in
the order they were sent, so the n-th command of a name the vehicle receives is the n-th
the schedule sends: the vehicle matches by (name, occurrence of that name). Two commands
of one name sent at the same instant would be told apart only by the engine's order, so
a schedule where they differ (delays, reply or work) is refused as ambiguous.

What "followed" means. The firings of the replay (``fire`` events of the controller's
log, engine and reply transitions) must be the schedule's, in the order of their
scheduled times (firings at one scheduled instant in any order), each within a tolerance
of its scheduled time: the vehicle's poll period plus the vehicle server's step
(`REPLY_SLACK_S`), accumulated over the replies consumed up to that firing (each reply
may go out that much late, and everything after it shifts). Mission time starts when the
first commands leave: after the handshake, which timed analysis does not model. The end
marking must be the schedule's final marking (when it has one) and the duration its
duration, within the same tolerance. The first firing that differs is reported.
"""

from __future__ import annotations

import json
import math
import re
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from analysis.timed import ScheduleError, TimedSchedule, read_schedule
from coral_lang.diagnostics import CoralError
from coral_lang.linkprofile import LinkProfile
from coral_lang.net import Net, TransitionKind, format_tokens

if TYPE_CHECKING:
    from runtime.controller import RunResult
    from runtime.eventlog import EventLog

__all__ = [
    "REPLAY_SETTINGS",
    "REPLY_SLACK_S",
    "SERVER_STEP_S",
    "Replay",
    "ReplayError",
    "ReplayVerdict",
    "load_replay",
]

REPLAY_SETTINGS = "replay-vehicle.json"
"""The scripted generic vehicle's settings file, written beside the logs."""
SERVER_STEP_S = 0.05
"""The vehicle server's step (`runtime.vehicle.server.VehicleServer`'s ``tick``): a reply
released between two steps goes out at the next."""
POLL_S = 0.05
"""The scripted vehicle's poll period (at most the profile's reply latency)."""
REPLY_SLACK_S = POLL_S + SERVER_STEP_S
"""How late the replay may send one reply: one poll and one server step."""
_SAME_INSTANT = 1e-6


class ReplayError(CoralError, ValueError):
    """A schedule that cannot be replayed: unreadable, of another net, or ambiguous."""


@dataclass(frozen=True)
class ReplayVerdict:
    """Whether a replay followed its schedule.

    Attributes:
        followed: same firings in the same order, within tolerance, same end.
        lines: what to print, one line each.
    """

    followed: bool
    lines: tuple[str, ...]


@dataclass(frozen=True)
class Replay:
    """A schedule checked against its mission, ready to run (`load_replay`)."""

    path: Path
    schedule: TimedSchedule

    @property
    def link(self) -> LinkProfile:
        """The emulated link: every message takes exactly the schedule's minimum delay."""
        return LinkProfile(name=f"replay of {self.schedule.link.name}", delay_s=self.min_delay)

    @property
    def min_delay(self) -> float:
        """The link's minimum one-way delay the schedule assumed."""
        return self.schedule.link.min_delay_s

    @property
    def time_limit(self) -> float:
        """A run that goes on this long has certainly diverged: end it."""
        return 2.0 * self.schedule.duration_s + 60.0

    def script(self) -> list[dict[str, object]]:
        """The scripted vehicle's entries (`runtime.vehicle.generic.ScriptedCommand`).

        Raises:
            ReplayError: a delay below the link's minimum, or two commands of one name
                sent at the same instant with different timings (ambiguous).
        """
        low = self.min_delay
        seen: Counter[str] = Counter()
        entries: list[dict[str, object]] = []
        by_name: dict[str, list[tuple[float, dict[str, object], str]]] = {}
        for i, cmd in enumerate(self.schedule.commands):
            where = f"{self.path}: commands[{i}] ({cmd.transition} #{cmd.occurrence})"
            for what, delay in (("up_delay_s", cmd.up_delay_s), ("down_delay_s", cmd.down_delay_s)):
                if delay < low - _SAME_INSTANT:
                    raise ReplayError(
                        f"{where}: {what} {delay:g} s is below the link's minimum {low:g} s"
                    )
            seen[cmd.command] += 1
            entry: dict[str, object] = {
                "command": cmd.command,
                "occurrence": seen[cmd.command],
                "hold_s": max(0.0, cmd.up_delay_s - low),
                "reply": cmd.reply,
                "work_s": cmd.work_s,
                "release_s": max(0.0, cmd.latency_s + cmd.down_delay_s - low),
            }
            timing = json.dumps([entry[k] for k in ("hold_s", "reply", "work_s", "release_s")])
            for sent_at, other, other_timing in by_name.get(cmd.command, []):
                if abs(sent_at - cmd.sent_at) <= _SAME_INSTANT and other_timing != timing:
                    raise ReplayError(
                        f"{where}: sent at {cmd.sent_at:g} s, the same instant as {cmd.command} "
                        f"#{other['occurrence']}, with other delays or another reply: the "
                        "vehicle matches commands by name and order, and cannot tell them apart"
                    )
            by_name.setdefault(cmd.command, []).append((cmd.sent_at, entry, timing))
            entries.append(entry)
        return entries

    def write_settings(self, folder: Path, reply_latency_s: float) -> Path:
        """Write the scripted vehicle's settings file into ``folder``; its path.

        Raises:
            ReplayError: the profile allows no reply latency (no poll period fits).
        """
        if reply_latency_s <= 0.0:
            raise ReplayError(
                "the profile's timing.reply_latency_s is 0: no simulated vehicle can poll "
                "that fast; the schedule cannot be replayed"
            )
        settings = {
            "poll_s": min(POLL_S, reply_latency_s),
            "watchdog_s": 1e6,  # outside the timed model (heartbeats keep it quiet anyway)
            "script": self.script(),
        }
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / REPLAY_SETTINGS
        # JSON is read back as YAML (the simulator's settings reader): YAML 1.1 takes
        # '1e-05' for a string, so every exponent number gets its decimal point.
        text = re.sub(r"(?<=[\s:\[,])(-?\d+)e([-+]\d+)", r"\1.0e\2", json.dumps(settings, indent=2))
        path.write_text(text + "\n", encoding="utf-8")
        return path

    def check(self, log: EventLog, result: RunResult) -> ReplayVerdict:
        """Did the run logged in ``log`` follow the schedule? (module docstring)."""
        events = list(log.events(("handshake", "fire", "reply")))
        origin = next((e.time for e in events if e.kind == "handshake"), None)
        if origin is None:
            return ReplayVerdict(False, ("replay: DIVERGED: the controller never connected",))
        fired: list[tuple[float, str, int]] = []  # (mission time, transition, replies so far)
        replies = 0
        for event in events:
            if event.kind == "reply":
                replies += 1
            elif event.kind == "fire":
                transition = event.data.get("transition")
                fired.append((max(0.0, event.time - origin), str(transition), replies))
        return _compare(self.schedule, fired, result, max(0.0, result.ended_at - origin))


def load_replay(path: Path, net: Net) -> Replay:
    """Read the schedule file ``path`` and check it is a run of ``net``.

    Raises:
        ReplayError: unreadable or malformed (the file and field named), or a schedule
            of another net (both digests named), or not replayable (`Replay.script`).
    """
    try:
        schedule = read_schedule(path)
    except ScheduleError as exc:
        raise ReplayError(str(exc)) from None
    digest = net.digest()
    if schedule.net_digest != digest:
        raise ReplayError(
            f"{path} is a schedule of net {schedule.net_digest} (mission "
            f"'{schedule.mission}'), but this mission compiles to {digest}: export the "
            "schedule again from this mission (coral-check verify --timed)"
        )
    _check_against(path, schedule, net)
    replay = Replay(path, schedule)
    replay.script()  # refuse an ambiguous schedule before anything runs
    return replay


def _check_against(path: Path, schedule: TimedSchedule, net: Net) -> None:
    """Each scheduled command names a command transition of ``net``, its command, one
    of its mapped replies, and a (transition, occurrence) no other entry names: a file
    edited by hand is refused here, naming the entry, not half-way through the run."""
    replies: dict[str, set[str]] = {}
    for reply in net.transitions:
        if reply.kind is TransitionKind.REPLY and reply.reply_to is not None and reply.reply:
            replies.setdefault(reply.reply_to, set()).add(reply.reply)
    seen: set[tuple[str, int]] = set()
    for i, cmd in enumerate(schedule.commands):
        where = f"{path}: commands[{i}]"
        tr = next((t for t in net.transitions if t.name == cmd.transition), None)
        if tr is None or tr.kind is not TransitionKind.COMMAND or tr.command is None:
            raise ReplayError(f"{where}.transition: {cmd.transition!r} sends no command here")
        if tr.command.name != cmd.command:
            raise ReplayError(
                f"{where}.command: {cmd.transition} sends {tr.command.name}, not {cmd.command}"
            )
        if cmd.reply not in replies.get(tr.name, set()):
            known = ", ".join(sorted(replies.get(tr.name, set()))) or "none"
            raise ReplayError(
                f"{where}.reply: {cmd.transition} takes no reply {cmd.reply!r} (it takes: {known})"
            )
        key = (cmd.transition, cmd.occurrence)
        if key in seen:
            raise ReplayError(
                f"{where}.occurrence: {cmd.transition} #{cmd.occurrence} is listed twice"
            )
        seen.add(key)


def _tolerance(replies: int) -> float:
    return 1e-6 + replies * REPLY_SLACK_S


def _compare(
    schedule: TimedSchedule,
    fired: list[tuple[float, str, int]],
    result: RunResult,
    duration: float,
) -> ReplayVerdict:
    """The verdict: the first difference, or that there is none."""
    # In time order (a stable sort: the schedule's order among firings at one instant).
    wanted = sorted(schedule.firings, key=lambda f: f.time)
    lines = [
        f"replay: {len(fired)} firing(s); the schedule ({schedule.kind}: {schedule.reason}) "
        f"has {len(wanted)}; tolerance {REPLY_SLACK_S:g} s per reply consumed (one vehicle "
        f"poll {POLL_S:g} s + one server step {SERVER_STEP_S:g} s), accumulated"
    ]
    i = 0
    while i < len(wanted):
        # The firings scheduled at one instant may come in any order.
        j = i
        while j + 1 < len(wanted) and abs(wanted[j + 1].time - wanted[i].time) <= _SAME_INSTANT:
            j += 1
        group = wanted[i : j + 1]
        got = fired[i : j + 1]
        if len(got) < len(group):
            missing = group[len(got)]
            lines.append(
                f"replay: DIVERGED at firing {i + len(got) + 1}: the schedule fires "
                f"{missing.transition} at {missing.time:.3f} s; the run had ended "
                f"({result.end.value} {format_tokens(result.marking.items())})"
            )
            return ReplayVerdict(False, tuple(lines))
        if sorted(g.transition for g in group) != sorted(t for _, t, _ in got):
            k = next(
                (
                    n
                    for n, (g, f) in enumerate(zip(group, got, strict=True))
                    if g.transition != f[1]
                ),
                0,
            )
            lines.append(
                f"replay: DIVERGED at firing {i + k + 1}: the schedule fires "
                f"{group[k].transition} at {group[k].time:.3f} s, the run fired {got[k][1]} "
                f"at {got[k][0]:.3f} s"
            )
            return ReplayVerdict(False, tuple(lines))
        times = {g.transition: g.time for g in group}
        for when, transition, replies in got:
            scheduled = times[transition]
            if abs(when - scheduled) > _tolerance(replies):
                lines.append(
                    f"replay: DIVERGED at firing {i + 1}: {transition} fired at {when:.3f} s, "
                    f"scheduled at {scheduled:.3f} s (tolerance {_tolerance(replies):.3f} s)"
                )
                return ReplayVerdict(False, tuple(lines))
        i = j + 1
    if len(fired) > len(wanted) and schedule.final is not None:
        when, transition, _ = fired[len(wanted)]
        lines.append(
            f"replay: DIVERGED at firing {len(wanted) + 1}: the run fired {transition} at "
            f"{when:.3f} s after the schedule's last firing"
        )
        return ReplayVerdict(False, tuple(lines))
    marking = {p: n for p, n in result.marking.items() if n}
    if schedule.final is not None:
        final = {p: n for p, n in schedule.final.items() if n}
        if marking != final:
            lines.append(
                f"replay: DIVERGED: the run ended in {format_tokens(marking.items())}, the "
                f"schedule in {format_tokens(final.items())}"
            )
            return ReplayVerdict(False, tuple(lines))
    # A schedule cut short (final None: a deadline's run) is compared up to its end.
    last = fired[len(wanted) - 1] if wanted and fired else None
    last_replies = last[2] if last is not None else 0
    ran = last[0] if last is not None else 0.0
    if not math.isclose(ran, schedule.duration_s, abs_tol=_tolerance(last_replies)):
        lines.append(
            f"replay: DIVERGED: the last firing came at {ran:.3f} s, the schedule's at "
            f"{schedule.duration_s:.3f} s"
        )
        return ReplayVerdict(False, tuple(lines))
    lines.append(
        f"replay: followed the schedule: same {len(fired)} firing(s) in order, each within "
        f"tolerance; ended in {format_tokens(marking.items())} after {ran:.3f} s "
        f"(scheduled {schedule.duration_s:.3f} s; the run stopped at {duration:.3f} s)"
    )
    return ReplayVerdict(True, tuple(lines))
