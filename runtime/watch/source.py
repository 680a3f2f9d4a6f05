"""Reading a controller log's new rows, again and again, while its writer goes on.

`EventLog.open` checks the file (a coral log, a readable version, not damaged) and gives the
header; its iterators always start from the first row. Following a running mission wants
only the rows after the last ones read, every half second, so `LogReader` keeps its own
read-only connection and asks for ``seq > last`` and ``n > last``: each poll costs what was
added since the previous one, however long the log. Like every log reader it takes no lock
and never blocks the writer (WAL, ``docs/eventlog.md``, "Live readers").
"""

from __future__ import annotations

import json
import math
import sqlite3
from pathlib import Path
from typing import Final

from runtime.eventlog import Event, EventLog, EventLogError, TelemetrySample

__all__ = ["LogReader"]

_BATCH: Final = 5000
"""Rows read per query: a long finished log is loaded in slices, never one huge fetch."""


class LogReader:
    """The header of a controller log and its rows, read incrementally.

    Raises `EventLogError` (a `CoralError`) naming the file when it is not a readable
    controller log.
    """

    def __init__(self, path: Path) -> None:
        with EventLog.open(path) as log:
            if log.role != "controller":
                raise EventLogError(
                    f"{path}: a {log.role} log; watch the controller's log (controller.sqlite), "
                    "which holds the net and the marking"
                )
            self.mission = log.mission
            self.net_json = log.net_json
            self.meta = dict(log.meta)
        self.path = path
        self.last_seq = 0
        self.last_sample = 0
        try:
            self._db = sqlite3.connect(
                f"{path.resolve().as_uri()}?mode=ro", uri=True, timeout=2.0, check_same_thread=False
            )
        except sqlite3.Error as error:
            raise EventLogError(f"{path}: cannot read the log: {error}") from None

    def read(self) -> tuple[list[Event], list[TelemetrySample]]:
        """The events and samples committed since the last call (all of them at first)."""
        try:
            events = self._events()
            samples = self._samples()
        except sqlite3.Error as error:
            raise EventLogError(f"{self.path}: cannot read the log: {error}") from None
        return events, samples

    def _events(self) -> list[Event]:
        events: list[Event] = []
        while True:
            rows = self._db.execute(
                "SELECT seq, time, kind, data FROM events WHERE seq > ? ORDER BY seq LIMIT ?",
                (self.last_seq, _BATCH),
            ).fetchall()
            for seq, time, kind, data in rows:
                self.last_seq = int(seq)
                try:
                    loaded = json.loads(data)
                except (TypeError, ValueError, RecursionError):
                    loaded = None
                if not isinstance(loaded, dict) or not isinstance(time, int | float):
                    raise EventLogError(f"{self.path}: event {seq} is damaged or edited")
                events.append(Event(int(seq), float(time), str(kind), loaded))
            if len(rows) < _BATCH:
                return events

    def _samples(self) -> list[TelemetrySample]:
        samples: list[TelemetrySample] = []
        while True:
            rows = self._db.execute(
                "SELECT n, time, seq, x, y, z, psi, est_x, est_y FROM telemetry WHERE n > ? "
                "ORDER BY n LIMIT ?",
                (self.last_sample, _BATCH),
            ).fetchall()
            for n, time, seq, x, y, z, psi, est_x, est_y in rows:
                self.last_sample = int(n)
                if not isinstance(time, int | float):
                    raise EventLogError(f"{self.path}: telemetry row {n} is damaged or edited")
                samples.append(
                    TelemetrySample(
                        float(time), int(seq), _real(x), _real(y), _real(z), _real(psi),
                        est_x, est_y,
                    )
                )  # fmt: skip
            if len(rows) < _BATCH:
                return samples

    def close(self) -> None:
        self._db.close()


def _real(value: object) -> float:
    return float(value) if isinstance(value, int | float) else math.nan
