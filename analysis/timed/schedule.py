"""A timed schedule: every delay and work time of one run, as analysis found it.

Timed analysis (`analysis.timed`) proves bounds; where it finds the worst case, or a
query that can time out, it shows the run that does it as a `TimedSchedule`: for each
command the engine sends, when it sent it, how long the link took each way, which reply
the vehicle gave and after how much work. ``coral-check verify --timed
--export-schedules DIR`` writes them as JSON files (``docs/analysis-methods.md``), and
``coral-run run --schedule FILE`` plays one against the generic simulated vehicle over
a link that keeps exactly those delays, so a person can watch the worst case happen.

A command is named by its transition and *occurrence* (the n-th firing of that
transition, from 1), not by the engine's command id: two commands sent at the same
instant may be numbered in either order, and the replay must still find each one.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

from coral_lang.safefile import UnreadableFile, read_text_file
from coral_lang.timing import LinkBounds

__all__ = [
    "SCHEDULE_FORMAT",
    "SCHEDULE_LIMIT",
    "ScheduleError",
    "ScheduledCommand",
    "ScheduledFiring",
    "TimedSchedule",
    "read_schedule",
]

SCHEDULE_FORMAT = "coral-schedule/1"
SCHEDULE_LIMIT = 8 * 1024 * 1024
"""Largest schedule file read, in bytes."""


class ScheduleError(ValueError):
    """A schedule file that cannot be used: the message names the file and field."""


@dataclass(frozen=True)
class ScheduledCommand:
    """One command of a timed run, from the engine's send to the reply's arrival.

    Attributes:
        transition: the COMMAND transition that sent it.
        occurrence: which firing of that transition (1 = the first).
        command: the command's name (``DEPTH?``).
        sent_at: engine time it was sent, s from the mission's start.
        up_delay_s: link delay to the vehicle.
        reply: the reply kind the vehicle gave.
        work_s: vehicle seconds from the command's arrival to the reply falling due
            (a query's included: whatever it waited for).
        latency_s: from the reply falling due to the vehicle sending it (polling).
        down_delay_s: link delay of the reply back to the engine.
    """

    transition: str
    occurrence: int
    command: str
    sent_at: float
    up_delay_s: float
    reply: str
    work_s: float
    latency_s: float
    down_delay_s: float

    @property
    def delivered_at(self) -> float:
        """When the command reached the vehicle."""
        return self.sent_at + self.up_delay_s

    @property
    def replied_at(self) -> float:
        """When the vehicle sent its reply."""
        return self.delivered_at + self.work_s + self.latency_s

    @property
    def arrived_at(self) -> float:
        """When the reply reached the engine."""
        return self.replied_at + self.down_delay_s

    def to_json(self) -> dict[str, object]:
        """JSON-ready form; the derived times are included for people reading it."""
        return {
            "transition": self.transition,
            "occurrence": self.occurrence,
            "command": self.command,
            "sent_at": self.sent_at,
            "up_delay_s": self.up_delay_s,
            "reply": self.reply,
            "work_s": self.work_s,
            "latency_s": self.latency_s,
            "down_delay_s": self.down_delay_s,
            "delivered_at": self.delivered_at,
            "replied_at": self.replied_at,
            "arrived_at": self.arrived_at,
        }


@dataclass(frozen=True)
class ScheduledFiring:
    """One firing of the run, in order: an engine transition or a reply consumed."""

    time: float
    transition: str

    def to_json(self) -> dict[str, object]:
        """JSON-ready form."""
        return {"time": self.time, "transition": self.transition}


@dataclass(frozen=True)
class TimedSchedule:
    """One run with all its times (module docstring).

    Attributes:
        mission: the net's name.
        net_digest: `coral_lang.net.Net.digest` of the net it is a run of.
        kind: ``worst-case``, ``best-case``, ``timeout`` or ``deadline``.
        reason: one line for people (``worst case to final { mission_complete }``).
        link: the link bounds analysis assumed.
        duration_s: engine time from the mission's start to its last firing.
        final: the marking the run ends in (None: a run cut short, e.g. at a deadline).
        commands: every command sent, in send order.
        firings: every firing, in order.
    """

    mission: str
    net_digest: str
    kind: str
    reason: str
    link: LinkBounds
    duration_s: float
    final: dict[str, int] | None
    commands: tuple[ScheduledCommand, ...]
    firings: tuple[ScheduledFiring, ...]

    def to_json(self) -> dict[str, object]:
        """The schedule file's content."""
        return {
            "format": SCHEDULE_FORMAT,
            "mission": self.mission,
            "net_digest": self.net_digest,
            "kind": self.kind,
            "reason": self.reason,
            "link": self.link.to_json(),
            "duration_s": self.duration_s,
            "final": self.final,
            "commands": [c.to_json() for c in self.commands],
            "firings": [f.to_json() for f in self.firings],
        }

    def write(self, path: Path) -> None:
        """Write the schedule file (JSON, sorted keys, one trailing newline)."""
        path.write_text(
            json.dumps(self.to_json(), indent=2, sort_keys=True) + "\n", encoding="utf-8"
        )

    @classmethod
    def from_json(cls, data: object, source: str = "<schedule>") -> TimedSchedule:
        """Read a schedule back; `ScheduleError` names ``source`` and the bad field."""
        return _Reader(source).schedule(data)


def read_schedule(path: Path) -> TimedSchedule:
    """Read a schedule file.

    Raises:
        ScheduleError: unreadable, not JSON, or a field missing or wrong (named).
    """
    try:
        text = read_text_file(path, SCHEDULE_LIMIT)
    except UnreadableFile as exc:
        raise ScheduleError(f"{path}: cannot read schedule: {exc.reason}") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ScheduleError(
            f"{path}:{exc.lineno}:{exc.colno}: not a JSON schedule: {exc.msg}"
        ) from None
    return TimedSchedule.from_json(data, str(path))


class _Reader:
    """Validates a decoded schedule, naming the field of the first mistake."""

    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, where: str, message: str) -> ScheduleError:
        return ScheduleError(f"{self.source}: {where}: {message}")

    def mapping(self, data: object, where: str) -> dict[str, object]:
        if not isinstance(data, dict):
            raise self.fail(where, "expected an object")
        return data

    def field(self, data: dict[str, object], key: str, where: str) -> object:
        if key not in data:
            raise self.fail(f"{where}.{key}" if where else key, "missing")
        return data[key]

    def text(self, data: dict[str, object], key: str, where: str) -> str:
        value = self.field(data, key, where)
        if not isinstance(value, str):
            raise self.fail(f"{where}.{key}" if where else key, "expected a string")
        return value

    def number(self, data: dict[str, object], key: str, where: str) -> float:
        value = self.field(data, key, where)
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.fail(f"{where}.{key}" if where else key, "expected a number")
        if not math.isfinite(value) or value < 0:
            raise self.fail(f"{where}.{key}" if where else key, "expected a number >= 0")
        return float(value)

    def schedule(self, data: object) -> TimedSchedule:
        root = self.mapping(data, "schedule")
        fmt = self.field(root, "format", "")
        if fmt != SCHEDULE_FORMAT:
            raise self.fail("format", f"expected {SCHEDULE_FORMAT!r}, got {fmt!r}")
        link_data = self.mapping(self.field(root, "link", ""), "link")
        try:
            link = LinkBounds(
                self.text(link_data, "name", "link"),
                self.number(link_data, "min_delay_s", "link"),
                self.number(link_data, "max_delay_s", "link"),
            )
        except ValueError as exc:
            if isinstance(exc, ScheduleError):
                raise
            raise self.fail("link", str(exc)) from None
        final_data = self.field(root, "final", "")
        final: dict[str, int] | None = None
        if final_data is not None:
            marking = self.mapping(final_data, "final")
            final = {}
            for place, count in marking.items():
                if isinstance(count, bool) or not isinstance(count, int) or count < 0:
                    raise self.fail(f"final.{place}", "expected a token count >= 0")
                final[place] = count
        commands_data = self.field(root, "commands", "")
        if not isinstance(commands_data, list):
            raise self.fail("commands", "expected a list")
        commands = tuple(
            self.command(item, f"commands[{i}]") for i, item in enumerate(commands_data)
        )
        firings_data = self.field(root, "firings", "")
        if not isinstance(firings_data, list):
            raise self.fail("firings", "expected a list")
        firings = []
        for i, item in enumerate(firings_data):
            where = f"firings[{i}]"
            entry = self.mapping(item, where)
            firings.append(
                ScheduledFiring(
                    self.number(entry, "time", where), self.text(entry, "transition", where)
                )
            )
        return TimedSchedule(
            mission=self.text(root, "mission", ""),
            net_digest=self.text(root, "net_digest", ""),
            kind=self.text(root, "kind", ""),
            reason=self.text(root, "reason", ""),
            link=link,
            duration_s=self.number(root, "duration_s", ""),
            final=final,
            commands=commands,
            firings=tuple(firings),
        )

    def command(self, data: object, where: str) -> ScheduledCommand:
        entry = self.mapping(data, where)
        occurrence = self.field(entry, "occurrence", where)
        if isinstance(occurrence, bool) or not isinstance(occurrence, int) or occurrence < 1:
            raise self.fail(f"{where}.occurrence", "expected an integer >= 1")
        return ScheduledCommand(
            transition=self.text(entry, "transition", where),
            occurrence=occurrence,
            command=self.text(entry, "command", where),
            sent_at=self.number(entry, "sent_at", where),
            up_delay_s=self.number(entry, "up_delay_s", where),
            reply=self.text(entry, "reply", where),
            work_s=self.number(entry, "work_s", where),
            latency_s=self.number(entry, "latency_s", where),
            down_delay_s=self.number(entry, "down_delay_s", where),
        )
