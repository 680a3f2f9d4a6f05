"""What a log holds, as values: an `Event`, a telemetry sample, and the one error.

Readers get these back; listeners (`EventLog.add_listener`) get them as they are logged.
A sample is the shared `runtime.telemetry.TelemetryRecord`, so the vehicle models, the
wire protocol and the logs use one record.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeAlias

from coral_lang.diagnostics import CoralError
from runtime.telemetry import TelemetryRecord

__all__ = ["Event", "EventLogError", "Listener", "TelemetryRecord"]


class EventLogError(CoralError, ValueError):
    """An event log cannot be created, opened, read or written.

    The message names the file and what is wrong: it is missing, not a coral log, of
    another schema version, damaged, already open for writing by another process, or the
    disk is full or read-only. Data that JSON cannot hold is refused when it is logged.
    """


@dataclass(frozen=True)
class Event:
    """One thing that happened, as its writer saw it.

    Attributes:
        seq: order of writing in its log, 1, 2, 3... with no gaps.
        time: the writer's own clock in seconds (the controller's or the vehicle's; the
            timeline maps vehicle times onto the controller's clock).
        kind: what happened: ``fire``, ``command-sent``, ``reply``, ``handshake``... (the
            list is in ``docs/eventlog.md``; any non-empty name is stored).
        data: the event's fields, as JSON gave them back (tuples come back as lists,
            NaN as None, infinities as the strings ``"inf"`` and ``"-inf"``).
    """

    seq: int
    time: float
    kind: str
    data: dict[str, object]


Listener: TypeAlias = "Callable[[Event | TelemetryRecord], None]"
"""Called by the writer with each event or sample as it will be stored (`add_listener`)."""
