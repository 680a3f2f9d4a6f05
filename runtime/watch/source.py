"""Reading a controller log's new rows, again and again, while its writer goes on.

`EventLog.open` checks the file (a coral log, a readable version, not damaged) and gives the
header. Following a running mission wants only the rows after the last ones read, every
half second, so `LogReader` keeps the log open and asks `EventLog.events` and
`EventLog.numbered_samples` for what comes after the last ``seq`` and ``n`` it saw: each
poll costs what was added since the previous one, however long the log, and every row is
checked as any reader checks it. Like every log reader it takes no lock and never blocks
the writer (WAL, ``docs/eventlog.md``, "Live readers").
"""

from __future__ import annotations

from pathlib import Path

from runtime.eventlog import Event, EventLog, EventLogError, TelemetryRecord

__all__ = ["LogReader"]


class LogReader:
    """The header of a controller log and its rows, read incrementally.

    Raises `EventLogError` (a `CoralError`) naming the file when it is not a readable
    controller log, or when a row read later is damaged.
    """

    def __init__(self, path: Path) -> None:
        log = EventLog.open(path)
        if log.role != "controller":
            log.close()
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
        self._log = log

    def read(self) -> tuple[list[Event], list[TelemetryRecord]]:
        """The events and samples committed since the last call (all of them at first)."""
        events = list(self._log.events(after=self.last_seq))
        numbered = list(self._log.numbered_samples(after=self.last_sample))
        if events:
            self.last_seq = events[-1].seq
        if numbered:
            self.last_sample = numbered[-1][0]
        return events, [sample for _, sample in numbered]

    def close(self) -> None:
        self._log.close()
