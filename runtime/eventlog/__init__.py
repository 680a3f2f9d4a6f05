"""The event log: what each side of a mission did and when, in one SQLite file per side.

The controller and the vehicle each write one (paper, section IV: "the events' sequence,
including the corresponding timestamps, has been recorded by both ... machines. The logged
data have been merged off-line"). `runtime.timeline` merges the two afterwards.

A log holds, once, a header (schema version, role, mission, creation date, metadata and, for
the controller, the compiled net), then every event (a firing, a command sent, a reply, a
handshake...) with the writer's own clock, every telemetry sample, and the engine's latest
*checkpoint*: the marking, the commands in flight and the last reply consumed.

The one rule that makes ``coral-run --resume`` lose and repeat nothing: `EventLog.commit`
writes everything buffered since the last commit *and* the new checkpoint in one SQLite
transaction, durable (``synchronous=FULL``) when it returns. A process killed at any moment
leaves the last committed state and exactly the events that led to it, never half a commit.
``docs/eventlog.md`` has the schema, the rule and the event kinds.

Only one process may write a log at a time: the writer holds an advisory lock on the file
(``flock``) for as long as the log is open, so a second writer is refused; the kernel drops
the lock when the writer dies (even by ``kill -9``), so a resume can take it over at once.
Readers take no lock: the log is in WAL mode while written, so ``coral-run timeline`` reads
the committed events of a mission that is still running, and never blocks its writer.

A log created with a key (``mac_key``, `log_key` of the run's pre-shared key) carries a MAC
chain (`runtime.eventlog.auth`, checked by `runtime.eventlog.chain`): opening it with the
key verifies every row, so a log edited by hand is refused instead of resumed from.

The package, one module per part, everything public re-exported here:
`runtime.eventlog.records` (`Event`, the telemetry record, `EventLogError`),
`runtime.eventlog.jsonvalues` (how values are stored), `runtime.eventlog.storage` (the
SQLite file: schema, lock, errors), `runtime.eventlog.log` (`EventLog`), and the MAC chain
in `runtime.eventlog.auth` and `runtime.eventlog.chain`.

Import rule: like `runtime.protocol`, this package imports only the standard library,
``coral_lang.diagnostics`` and the shared `runtime.telemetry`, so the vehicle simulator may
use it without pulling in the engine.
"""

from __future__ import annotations

from runtime.eventlog.auth import log_key
from runtime.eventlog.log import EventLog, LogRole
from runtime.eventlog.records import (
    Event,
    EventLogError,
    Listener,
    TelemetryRecord,
)
from runtime.eventlog.storage import APPLICATION_ID, READABLE_VERSIONS, SCHEMA_VERSION

__all__ = [
    "APPLICATION_ID",
    "READABLE_VERSIONS",
    "SCHEMA_VERSION",
    "Event",
    "EventLog",
    "EventLogError",
    "Listener",
    "LogRole",
    "TelemetryRecord",
    "log_key",
]
