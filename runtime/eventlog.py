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

Only one process may write a log at a time: the writer holds SQLite's exclusive lock for as
long as the log is open, so a second controller started on the same file is refused, and
the kernel drops the lock when the writer dies (even by ``kill -9``), so a resume can take
it over at once.

Import rule: like `runtime.protocol`, this module imports only the standard library and
``coral_lang.diagnostics``, so the vehicle simulator may use it without pulling in the engine.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import enum
import json
import math
import os
import sqlite3
import threading
from collections.abc import Collection, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any, Final, Literal, TypeAlias

from coral_lang.diagnostics import CoralError

__all__ = [
    "APPLICATION_ID",
    "SCHEMA_VERSION",
    "Event",
    "EventLog",
    "EventLogError",
    "LogRole",
    "TelemetrySample",
]

SCHEMA_VERSION: Final = 1
"""Version of the tables below; a log of another version is refused, never guessed at."""

APPLICATION_ID: Final = 0x434F524C
"""SQLite's ``application_id`` of a coral event log ("CORL"): tells our logs from other
SQLite files before any table is read."""

LogRole: TypeAlias = Literal["controller", "vehicle"]
_ROLES: Final = ("controller", "vehicle")

_BATCH: Final = 2000  # rows fetched per query while iterating, so a long log never sits in memory

_SCHEMA: Final = """
CREATE TABLE header (
    id             INTEGER PRIMARY KEY CHECK (id = 1),
    schema_version INTEGER NOT NULL,
    role           TEXT    NOT NULL CHECK (role IN ('controller', 'vehicle')),
    mission        TEXT    NOT NULL,
    created        TEXT    NOT NULL,
    meta           TEXT    NOT NULL,
    net_json       TEXT,
    net_digest     TEXT
);
CREATE TABLE events (
    seq  INTEGER PRIMARY KEY,
    time REAL    NOT NULL,
    kind TEXT    NOT NULL,
    data TEXT    NOT NULL
);
CREATE INDEX events_by_kind ON events (kind, seq);
CREATE TABLE telemetry (
    n     INTEGER PRIMARY KEY,
    time  REAL    NOT NULL,
    seq   INTEGER NOT NULL,
    x     REAL,
    y     REAL,
    z     REAL,
    psi   REAL,
    est_x REAL,
    est_y REAL
);
CREATE TABLE checkpoint (
    id        INTEGER PRIMARY KEY CHECK (id = 1),
    commits   INTEGER NOT NULL,
    event_seq INTEGER NOT NULL,
    state     TEXT    NOT NULL
);
"""


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


@dataclass(frozen=True)
class TelemetrySample:
    """One telemetry sample, always timed by the *vehicle's* clock.

    The vehicle logs the samples it sends, the controller the datagrams it receives; both
    keep the datagram's vehicle time here, so the timeline converts every sample the same
    way. Units and axes as in `runtime.protocol.Telemetry`.

    Attributes:
        time: vehicle clock (s).
        seq: the datagram's sequence number (restarts at 1 on every connection).
        x: north (m). y: east (m). z: depth, down positive (m). psi: heading (deg).
        est_x: the navigation filter's estimate of x, None before FIX_XY initialises it.
        est_y: likewise for y.
    """

    time: float
    seq: int
    x: float
    y: float
    z: float
    psi: float
    est_x: float | None = None
    est_y: float | None = None


# --- JSON -----------------------------------------------------------------------------------


class _NotJson(Exception):
    def __init__(self, where: str, value: object):
        super().__init__(where)
        self.where = where
        self.value = value

    def error(self, prefix: str) -> EventLogError:
        kind = type(self.value).__name__
        return EventLogError(f"{prefix}{self.where} is of type {kind}, which JSON cannot hold")


def _jsonable(value: object, where: str) -> object:
    """``value`` as plain JSON types; non-finite floats become None (NaN) or "inf"/"-inf".

    Strict JSON has no NaN or Infinity, and a log must stay readable by any JSON reader, so
    NaN (our "no value", as on the wire) is stored as null and infinities as strings.
    """
    if value is None or isinstance(value, bool | str):
        return value
    if isinstance(value, enum.Enum):
        return _jsonable(value.value, where)
    if isinstance(value, int):
        return int(value)
    if isinstance(value, float):
        if math.isfinite(value):
            return float(value)
        if math.isnan(value):
            return None
        return "inf" if value > 0 else "-inf"
    if isinstance(value, Mapping):
        out: dict[str, object] = {}
        for key, item in value.items():
            if isinstance(key, enum.Enum):
                key = key.value
            if isinstance(key, bool) or not isinstance(key, str | int):
                raise _NotJson(f"{where} (key {key!r})", key)
            out[str(key)] = _jsonable(item, f"{where}[{key!r}]")
        return out
    if isinstance(value, list | tuple):
        return [_jsonable(item, f"{where}[{index}]") for index, item in enumerate(value)]
    if isinstance(value, set | frozenset):
        items = [_jsonable(item, f"{where} item") for item in value]
        return sorted(items, key=lambda item: json.dumps(item, sort_keys=True))
    tolist = getattr(value, "tolist", None)  # numpy arrays and scalars, without importing numpy
    if callable(tolist):
        return _jsonable(tolist(), where)
    raise _NotJson(where, value)


def _dumps(value: object) -> str:
    return json.dumps(value, separators=(",", ":"), allow_nan=False)


def _finite(value: float, what: str, path: Path) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        number = math.nan
    if not math.isfinite(number):
        raise EventLogError(f"{path}: {what} must be a finite number of seconds, got {value!r}")
    return number


def _pose(value: float | None) -> float | None:
    return None if value is None or math.isnan(value) else float(value)


# --- SQLite errors --------------------------------------------------------------------------

_SQLITE_BUSY: Final = 5
_SQLITE_LOCKED: Final = 6
_SQLITE_READONLY: Final = 8
_SQLITE_IOERR: Final = 10
_SQLITE_CORRUPT: Final = 11
_SQLITE_FULL: Final = 13
_SQLITE_CANTOPEN: Final = 14
_SQLITE_NOTADB: Final = 26


def _explain(path: Path, doing: str, error: sqlite3.Error) -> EventLogError:
    """One clear sentence for a SQLite error, naming the file and what we were doing."""
    code = getattr(error, "sqlite_errorcode", -1) & 0xFF
    if code in (_SQLITE_BUSY, _SQLITE_LOCKED) and doing == "read the log":
        why = (
            "it is open for writing by another process (the mission is still running?); "
            "read it once that process has ended"
        )
    elif code in (_SQLITE_BUSY, _SQLITE_LOCKED):
        why = (
            "it is open for writing by another process (a second controller or vehicle "
            "on the same log?); only one writer at a time: wait for it to end or use "
            "another file"
        )
    elif code == _SQLITE_NOTADB:
        why = "it is not a SQLite database, so not a coral event log"
    elif code == _SQLITE_CORRUPT:
        why = f"the file is damaged (truncated or overwritten): {error}"
    elif code == _SQLITE_FULL:
        why = "the disk is full; free some space"
    elif code == _SQLITE_READONLY:
        why = "the file or its folder is read-only"
    elif code == _SQLITE_CANTOPEN:
        why = "the file cannot be opened (missing folder, or no permission)"
    elif code == _SQLITE_IOERR:
        why = f"input/output error ({error}); the disk may be full or failing"
    else:
        why = str(error)
    return EventLogError(f"{path}: cannot {doing}: {why}")


def _no_tables(db: sqlite3.Connection) -> bool:
    return bool(db.execute("SELECT count(*) FROM sqlite_master").fetchone()[0] == 0)


# --- the log --------------------------------------------------------------------------------


class EventLog:
    """One side's event log: create it at mission start, open it to resume or to read.

    Writing is buffered: `event` and `telemetry` only append to memory, and `commit` writes
    the buffer and the new checkpoint in one transaction. So the engine logs freely (tens
    of thousands of events cost one transaction per commit, not one each) and decides
    where the consistent points are. Nothing is written without a commit, except that
    `close` commits the pending buffer (without a checkpoint). Readers see committed
    events only.

    An instance may be used from several threads (one at a time, guarded by a lock), so
    an asyncio engine can run `commit` in a worker thread.
    """

    role: str
    mission: str
    created: str
    meta: dict[str, object]
    net_json: str | None
    net_digest: str | None
    path: Path
    writable: bool

    def __init__(
        self,
        connection: sqlite3.Connection,
        path: Path,
        *,
        writable: bool,
        header: tuple[object, ...],
    ) -> None:
        """Internal: use `create` or `open`."""
        self._db: sqlite3.Connection | None = connection
        self.path = path
        self.writable = writable
        role, mission, created, meta, net_json, net_digest = header
        self.role = str(role)
        self.mission = str(mission)
        self.created = str(created)
        loaded = json.loads(str(meta))
        self.meta = dict(loaded) if isinstance(loaded, dict) else {}
        self.net_json = None if net_json is None else str(net_json)
        self.net_digest = None if net_digest is None else str(net_digest)
        self._events: list[tuple[float, str, str]] = []
        self._samples: list[tuple[object, ...]] = []
        self._lock = threading.Lock()

    # --- opening ----------------------------------------------------------------------------

    @classmethod
    def create(
        cls,
        path: str | Path,
        *,
        role: LogRole,
        mission: str,
        meta: Mapping[str, object],
        net_json: str | None = None,
        net_digest: str | None = None,
    ) -> EventLog:
        """Start a new log at ``path`` and hold it for writing.

        Args:
            path: the new file; an existing file is never overwritten (a previous mission's
                log is evidence), so this raises instead.
            role: ``controller`` or ``vehicle``.
            mission: the mission both sides know, so the timeline can check that two logs
                belong together (use the same string on both sides: the wire mission id).
            meta: anything worth keeping with the log (mission name, options, versions);
                JSON, with non-finite floats stored as in `Event.data`.
            net_json: the compiled net, stored once (the controller's log).
            net_digest: its digest (``Net.digest()``), which the certificate names.

        Raises:
            EventLogError: the file exists, the folder is missing or read-only, the disk is
                full, or ``meta`` holds something JSON cannot.
        """
        target = Path(path)
        if role not in _ROLES:
            raise EventLogError(f"{target}: role must be 'controller' or 'vehicle', not {role!r}")
        try:
            meta_json = _dumps(_jsonable(dict(meta), "meta"))
        except _NotJson as bad:
            raise bad.error(f"{target}: ") from None
        try:
            # O_EXCL: refuse an existing file atomically, even against a racing creator.
            os.close(os.open(target, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644))
        except FileExistsError:
            raise EventLogError(
                f"{target}: already exists; a log is never overwritten. Choose a new file, "
                "or open this one to resume (coral-run --resume)"
            ) from None
        except OSError as error:
            raise EventLogError(f"{target}: cannot create: {error.strerror}") from None
        created = dt.datetime.now(dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")
        header = (role, mission, created, meta_json, net_json, net_digest)
        try:
            db = cls._connect(target, writable=True)
        except sqlite3.Error as error:
            target.unlink(missing_ok=True)  # ours (O_EXCL above): leave nothing half-made
            raise _explain(target, "create the log", error) from None
        try:
            # One transaction: an interrupted creation leaves no half-made log.
            db.execute("BEGIN EXCLUSIVE")
            db.execute(f"PRAGMA application_id = {APPLICATION_ID}")
            db.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
            for statement in _SCHEMA.split(";"):
                if statement.strip():
                    db.execute(statement)
            db.execute(
                "INSERT INTO header (id, schema_version, role, mission, created, meta, "
                "net_json, net_digest) VALUES (1, ?, ?, ?, ?, ?, ?, ?)",
                (SCHEMA_VERSION, *header),
            )
            db.execute("COMMIT")
        except sqlite3.Error as error:
            db.close()
            target.unlink(missing_ok=True)
            raise _explain(target, "create the log", error) from None
        return cls(db, target, writable=True, header=header)

    @classmethod
    def open(cls, path: str | Path, *, writable: bool = False) -> EventLog:
        """Open an existing log: writable to resume a mission, read-only for the timeline.

        A writable log is held exclusively until `close` (a second writer, or a reader,
        is refused meanwhile). A log left by a killed writer opens normally: SQLite rolls
        its uncommitted tail back and the last commit is intact.

        Raises:
            EventLogError: the file is missing, empty, not a SQLite database, another
                application's database, of another schema version, damaged, or open for
                writing by another process.
        """
        target = Path(path)
        try:
            info = target.stat()
        except FileNotFoundError:
            raise EventLogError(f"{target}: no such event log") from None
        except OSError as error:
            raise EventLogError(f"{target}: cannot read: {error.strerror}") from None
        if not target.is_file():
            raise EventLogError(f"{target}: not a file, so not an event log")
        if info.st_size == 0:
            raise EventLogError(
                f"{target}: the file is empty, not a coral event log (its creation was "
                "interrupted?)"
            )
        try:
            db = cls._connect(target, writable=writable)
        except sqlite3.Error as error:
            raise _explain(target, "open the log", error) from None
        try:
            header = cls._check(db, target, writable=writable)
        except BaseException:
            db.close()
            raise
        return cls(db, target, writable=writable, header=header)

    @staticmethod
    def _connect(path: Path, *, writable: bool) -> sqlite3.Connection:
        # timeout=0: a log held by another writer is refused at once, with a clear message,
        # instead of waiting for a process that may run for hours.
        db = sqlite3.connect(path, timeout=0, isolation_level=None, check_same_thread=False)
        try:
            if writable:
                # Exclusive before WAL: no shared-memory index, and the lock is held from
                # the first access until close, which is what refuses a second writer.
                db.execute("PRAGMA locking_mode = EXCLUSIVE")
                db.execute("PRAGMA journal_mode = WAL")
                db.execute("PRAGMA synchronous = FULL")
            else:
                db.execute("PRAGMA query_only = ON")
        except BaseException:
            db.close()
            raise
        return db

    @staticmethod
    def _check(db: sqlite3.Connection, path: Path, *, writable: bool) -> tuple[object, ...]:
        """Take the lock (writable), check it is a sound coral log, return its header."""
        try:
            if writable:
                db.execute("BEGIN EXCLUSIVE")
                db.execute("COMMIT")
            app = db.execute("PRAGMA application_id").fetchone()[0]
            if app != APPLICATION_ID:
                hint = " (its creation was interrupted?)" if app == 0 and _no_tables(db) else ""
                raise EventLogError(
                    f"{path}: a SQLite database, but not a coral event log "
                    f"(application_id {app:#x}, expected {APPLICATION_ID:#x}){hint}"
                )
            version = db.execute("PRAGMA user_version").fetchone()[0]
            if version != SCHEMA_VERSION:
                raise EventLogError(
                    f"{path}: event log schema version {version}; this coral reads version "
                    f"{SCHEMA_VERSION} only (use the coral that wrote it)"
                )
            problems = [row[0] for row in db.execute("PRAGMA quick_check(5)")]
            if problems != ["ok"]:
                raise EventLogError(
                    f"{path}: the file is damaged (truncated or overwritten): "
                    + "; ".join(str(p) for p in problems)
                )
            row = db.execute(
                "SELECT schema_version, role, mission, created, meta, net_json, net_digest "
                "FROM header WHERE id = 1"
            ).fetchone()
        except sqlite3.Error as error:
            raise _explain(path, "open the log" if writable else "read the log", error) from None
        if row is None:
            raise EventLogError(f"{path}: the header row is missing; the file is damaged")
        if row[0] != SCHEMA_VERSION:
            raise EventLogError(
                f"{path}: event log schema version {row[0]}; this coral reads version "
                f"{SCHEMA_VERSION} only (use the coral that wrote it)"
            )
        if row[1] not in _ROLES:
            raise EventLogError(f"{path}: unknown role {row[1]!r} in the header")
        try:
            json.loads(row[4])
        except (TypeError, ValueError):
            raise EventLogError(
                f"{path}: the header's meta is not JSON; the file is damaged"
            ) from None
        return tuple(row[1:])

    # --- writing ----------------------------------------------------------------------------

    def event(self, time: float, kind: str, /, **data: object) -> None:
        """Buffer one event; it is written by the next `commit` (or `close`).

        ``time`` and ``kind`` are positional-only, so ``data`` may itself have fields
        named ``time`` or ``kind`` (a reply's kind: ``log.event(t, "reply", kind="done")``).
        The data is converted to JSON now, so later changes to a dict passed in (a marking
        the engine goes on updating) do not change what was logged.

        Raises:
            EventLogError: the log is closed or read-only, ``time`` is not finite,
                ``kind`` is empty, or a field holds something JSON cannot (a set is
                stored as a sorted list, a numpy value as its Python equivalent).
        """
        self._writable()
        if not kind:
            raise EventLogError(f"{self.path}: an event needs a kind")
        moment = _finite(time, f"the time of event {kind!r}", self.path)
        try:
            text = _dumps(_jsonable(data, "data"))
        except _NotJson as bad:
            raise bad.error(f"{self.path}: event {kind!r}: ") from None
        with self._lock:
            self._events.append((moment, kind, text))

    def telemetry(self, sample: TelemetrySample) -> None:
        """Buffer one telemetry sample; it is written by the next `commit` (or `close`).

        Pose values that are NaN are stored as NULL and read back as NaN (``est_x``,
        ``est_y``: as None).
        """
        self._writable()
        moment = _finite(sample.time, "a telemetry sample's time", self.path)
        row = (
            moment,
            int(sample.seq),
            _pose(sample.x),
            _pose(sample.y),
            _pose(sample.z),
            _pose(sample.psi),
            _pose(sample.est_x),
            _pose(sample.est_y),
        )
        with self._lock:
            self._samples.append(row)

    @property
    def pending(self) -> int:
        """How many events and samples are buffered, waiting for a commit."""
        return len(self._events) + len(self._samples)

    def commit(self, state: Mapping[str, object] | None = None) -> None:
        """Write every buffered event and sample, and ``state`` if given, in ONE transaction.

        This is the engine's consistency point: log a command before sending it and commit
        it with the state that has it in flight; commit the last consumed reply seq with
        the marking that reply produced. When this returns, all of it is on disk
        (``synchronous=FULL``); if the process dies before, none of it is, and the log
        still holds the previous commit whole.

        Args:
            state: the new checkpoint (JSON; e.g. marking, commands in flight, last consumed
                reply seq, next command id); None keeps the previous one.

        Raises:
            EventLogError: the log is closed or read-only, the state holds something JSON
                cannot, or the disk is full or failing. On a write failure nothing of this
                commit is written and the buffer is kept, so the caller may retry.
        """
        self._writable()
        state_json = None
        if state is not None:
            try:
                state_json = _dumps(_jsonable(dict(state), "state"))
            except _NotJson as bad:
                raise bad.error(f"{self.path}: checkpoint: ") from None
        with self._lock:
            if state_json is None and not self._events and not self._samples:
                return
            db = self._connection()
            try:
                db.execute("BEGIN IMMEDIATE")
                if self._events:
                    db.executemany(
                        "INSERT INTO events (time, kind, data) VALUES (?, ?, ?)", self._events
                    )
                if self._samples:
                    db.executemany(
                        "INSERT INTO telemetry (time, seq, x, y, z, psi, est_x, est_y) "
                        "VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
                        self._samples,
                    )
                if state_json is not None:
                    db.execute(
                        "INSERT INTO checkpoint (id, commits, event_seq, state) "
                        "VALUES (1, 1, (SELECT coalesce(max(seq), 0) FROM events), ?) "
                        "ON CONFLICT (id) DO UPDATE SET commits = commits + 1, "
                        "event_seq = excluded.event_seq, state = excluded.state",
                        (state_json,),
                    )
                db.execute("COMMIT")
            except sqlite3.Error as error:
                if db.in_transaction:
                    with contextlib.suppress(sqlite3.Error):
                        db.execute("ROLLBACK")
                raise _explain(self.path, "commit to the log", error) from None
            self._events.clear()
            self._samples.clear()

    # --- reading ----------------------------------------------------------------------------

    def checkpoint(self) -> dict[str, object] | None:
        """The latest committed state, or None if no commit carried one.

        Raises:
            EventLogError: the stored state is not a JSON object. `commit` only ever
                writes one, so the log was damaged or edited: resuming must stop with a
                message naming the log, not a JSON traceback or a silent fresh start.
        """
        row = self._query_one("SELECT state FROM checkpoint WHERE id = 1")
        if row is None:
            return None
        try:
            loaded = json.loads(str(row[0]))
        except (ValueError, RecursionError) as error:
            raise EventLogError(
                f"{self.path}: the checkpoint is not valid JSON ({error}); "
                "the log was damaged or edited"
            ) from None
        if not isinstance(loaded, dict):
            raise EventLogError(
                f"{self.path}: the checkpoint is not a JSON object; the log was damaged or edited"
            )
        return dict(loaded)

    def checkpoint_seq(self) -> int:
        """The seq of the last event committed together with the latest checkpoint (0: none).

        Events after it were committed without a new state (by `close`, or commits that
        gave no state): a resuming engine may look at them, but its state is the checkpoint.
        """
        row = self._query_one("SELECT event_seq FROM checkpoint WHERE id = 1")
        return 0 if row is None else int(row[0])

    def events(self, kinds: Collection[str] | None = None) -> Iterator[Event]:
        """Committed events in the order they were written, optionally only some kinds.

        ``kinds`` is a collection of kinds; a single string is taken as one kind.
        """
        if isinstance(kinds, str):
            kinds = [kinds]
        wanted = None if kinds is None else sorted(set(kinds))
        if wanted is not None and not wanted:
            return
        where = "" if wanted is None else f" AND kind IN ({', '.join('?' * len(wanted))})"
        last = 0
        while True:
            rows = self._query_all(
                f"SELECT seq, time, kind, data FROM events WHERE seq > ?{where} "
                f"ORDER BY seq LIMIT {_BATCH}",
                (last, *(wanted or ())),
            )
            for seq, time, kind, data in rows:
                loaded = json.loads(data)
                yield Event(seq, time, kind, dict(loaded) if isinstance(loaded, dict) else {})
            if len(rows) < _BATCH:
                return
            last = rows[-1][0]

    def samples(self) -> Iterator[TelemetrySample]:
        """Committed telemetry samples in the order they were written."""
        last = 0
        nan = math.nan
        while True:
            rows = self._query_all(
                "SELECT n, time, seq, x, y, z, psi, est_x, est_y FROM telemetry WHERE n > ? "
                f"ORDER BY n LIMIT {_BATCH}",
                (last,),
            )
            for _, time, seq, x, y, z, psi, est_x, est_y in rows:
                yield TelemetrySample(
                    time,
                    seq,
                    nan if x is None else x,
                    nan if y is None else y,
                    nan if z is None else z,
                    nan if psi is None else psi,
                    est_x,
                    est_y,
                )
            if len(rows) < _BATCH:
                return
            last = rows[-1][0]

    def count(self, kind: str | None = None) -> int:
        """How many committed events there are (of one kind, if given)."""
        if kind is None:
            row = self._query_one("SELECT count(*) FROM events")
        else:
            row = self._query_one("SELECT count(*) FROM events WHERE kind = ?", (kind,))
        return 0 if row is None else int(row[0])

    # --- closing ----------------------------------------------------------------------------

    def close(self) -> None:
        """Commit the pending buffer (without a checkpoint), release the lock, close.

        Pending events are committed rather than dropped because they are facts that
        happened; the checkpoint stays the last one given to `commit`, so a resume still
        starts from a consistent state (`checkpoint_seq` tells which events came after it).
        A writable log is switched back to a plain rollback journal, so a finished log is
        one self-contained file, readable even from read-only media. Closing twice is fine.

        Raises:
            EventLogError: the pending buffer could not be written (disk full...); the file
                is closed anyway and holds everything committed before.
        """
        if self._db is None:
            return
        try:
            if self.writable:
                self.commit()
        finally:
            db, self._db = self._db, None
            self._events.clear()
            self._samples.clear()
            try:
                if self.writable:
                    db.execute("PRAGMA journal_mode = DELETE")
            except sqlite3.Error:
                pass  # still a valid WAL database; the next opener checkpoints it
            finally:
                db.close()

    @property
    def closed(self) -> bool:
        """True once `close` was called."""
        return self._db is None

    def __enter__(self) -> EventLog:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def __repr__(self) -> str:
        mode = "writable" if self.writable else "read-only"
        state = "closed" if self._db is None else mode
        return (
            f"EventLog({str(self.path)!r}, role={self.role!r}, mission={self.mission!r}, {state})"
        )

    def relax_durability(self) -> None:
        """Stop waiting for the disk at each commit (``synchronous=OFF``).

        Commits stay atomic, but one cut short by a power loss (not a process crash) may
        be lost. Only for logs that will never be resumed, such as ``coral-run fuzz``'s,
        where the waits were three quarters of a run's time.
        """
        self._writable()
        self._connection().execute("PRAGMA synchronous = OFF")

    # --- helpers ----------------------------------------------------------------------------

    def _connection(self) -> sqlite3.Connection:
        if self._db is None:
            raise EventLogError(f"{self.path}: the log is closed")
        return self._db

    def _writable(self) -> None:
        self._connection()
        if not self.writable:
            raise EventLogError(f"{self.path}: opened read-only; open it with writable=True")

    def _query_all(self, sql: str, params: tuple[object, ...] = ()) -> list[tuple[Any, ...]]:
        with self._lock:
            db = self._connection()
            try:
                return [tuple(row) for row in db.execute(sql, params).fetchall()]
            except sqlite3.Error as error:
                raise _explain(self.path, "read the log", error) from None

    def _query_one(self, sql: str, params: tuple[object, ...] = ()) -> tuple[Any, ...] | None:
        rows = self._query_all(sql, params)
        return rows[0] if rows else None
