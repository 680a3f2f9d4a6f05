"""The SQLite file under a log: its schema, the writer's lock, and errors said plainly.

Every SQLite error becomes one `EventLogError` sentence naming the file and what was being
done; the schema is checked against the one `EventLog.create` writes before any row is
trusted; the one-writer rule is an ``flock`` held for as long as the writer has the file.
"""

from __future__ import annotations

import fcntl
import functools
import os
import sqlite3
from pathlib import Path
from typing import Any, Final, TypeGuard

from runtime.eventlog.records import EventLogError

__all__ = [
    "APPLICATION_ID",
    "HELD",
    "MIN_LOG_KEY",
    "READABLE_VERSIONS",
    "SCHEMA",
    "SCHEMA_VERSION",
    "check_log_key",
    "check_schema",
    "explain",
    "hold_lock",
    "is_real",
    "no_tables",
    "schema_of",
    "utf8_text",
    "written_schema",
]


SCHEMA_VERSION: Final = 2
"""Version of the tables below, the one written; a log of a version not in
`READABLE_VERSIONS` is refused, never guessed at."""

READABLE_VERSIONS: Final = (1, 2)
"""Versions read: 1 is the same without the MAC chain (``header.key_id``, ``header.mac``,
``commits``), so a version 1 log reads as an unauthenticated one."""

APPLICATION_ID: Final = 0x434F524C
"""SQLite's ``application_id`` of a coral event log ("CORL"): tells our logs from other
SQLite files before any table is read."""

SCHEMA: Final = """
CREATE TABLE header (
    id             INTEGER PRIMARY KEY CHECK (id = 1),
    schema_version INTEGER NOT NULL,
    role           TEXT    NOT NULL CHECK (role IN ('controller', 'vehicle')),
    mission        TEXT    NOT NULL,
    created        TEXT    NOT NULL,
    meta           TEXT    NOT NULL,
    net_json       TEXT,
    net_digest     TEXT,
    key_id         TEXT,
    mac            TEXT
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
CREATE TABLE commits (
    n         INTEGER PRIMARY KEY,
    event_seq INTEGER NOT NULL,
    sample_n  INTEGER NOT NULL,
    state_sha TEXT,
    mac       TEXT
);
"""

MIN_LOG_KEY: Final = 16


_SQLITE_BUSY: Final = 5
_SQLITE_LOCKED: Final = 6
_SQLITE_READONLY: Final = 8
_SQLITE_IOERR: Final = 10
_SQLITE_CORRUPT: Final = 11
_SQLITE_FULL: Final = 13
_SQLITE_CANTOPEN: Final = 14
_SQLITE_NOTADB: Final = 26


def explain(path: Path, doing: str, error: sqlite3.Error) -> EventLogError:
    """One clear sentence for a SQLite error, naming the file and what we were doing."""
    code = getattr(error, "sqlite_errorcode", -1) & 0xFF
    if code in (_SQLITE_BUSY, _SQLITE_LOCKED) and doing == "read the log":
        why = (
            "it is busy (another process is recovering or checkpointing it); try again in a moment"
        )
    elif code in (_SQLITE_BUSY, _SQLITE_LOCKED):
        why = HELD
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


HELD: Final = (
    "it is open for writing by another process (a second controller or vehicle on the same "
    "log?); only one writer at a time: wait for it to end or use another file"
)


def hold_lock(path: Path, fd: int) -> int:
    """Take the writer's lock on the open file ``fd`` (closed on refusal); returns ``fd``.

    ``flock`` locks are apart from SQLite's own (POSIX record) locks on Linux, so holding
    one neither disturbs SQLite nor keeps readers out; the kernel drops it with the
    process, ``kill -9`` included.
    """
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError as error:
        os.close(fd)
        if isinstance(error, BlockingIOError):
            raise EventLogError(f"{path}: cannot open the log: {HELD}") from None
        raise EventLogError(f"{path}: cannot lock the log: {error.strerror}") from None
    return fd


def check_log_key(path: Path, key: bytes | None) -> bytes | None:
    """``key`` as bytes (None stays None); `EventLogError` when too short."""
    if key is None:
        return None
    if not isinstance(key, bytes | bytearray) or len(key) < MIN_LOG_KEY:
        raise EventLogError(
            f"{path}: a log key must be at least {MIN_LOG_KEY} bytes (use log_key(psk))"
        )
    return bytes(key)


def utf8_text(raw: bytes) -> str:
    """Text columns as UTF-8, every other byte string a SQLite error: so a file edited to
    hold invalid text is refused like any damage, with its name (bench/redteam.py found a
    UnicodeDecodeError escaping ``PRAGMA quick_check`` on a flipped byte)."""
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        raise sqlite3.DataError(
            "it holds text that is not UTF-8: the file is damaged or edited"
        ) from None


def schema_of(db: sqlite3.Connection) -> list[tuple[Any, ...]]:
    """Every table, index, view and trigger of ``db``, as ``sqlite_master`` lists them."""
    return [
        tuple(row)
        for row in db.execute(
            "SELECT type, name, tbl_name, sql FROM sqlite_master ORDER BY type, name"
        )
    ]


@functools.cache
def written_schema() -> tuple[tuple[Any, ...], ...]:
    """The tables and index exactly as `EventLog.create` writes them (version 2)."""
    db = sqlite3.connect(":memory:")
    try:
        for statement in SCHEMA.split(";"):
            if statement.strip():
                db.execute(statement)
        return tuple(schema_of(db))
    finally:
        db.close()


def check_schema(db: sqlite3.Connection, path: Path, version: int) -> None:
    """Refuse a log whose tables are not the ones coral writes.

    Why: the MAC chain authenticates rows, but SQLite reads through the schema stored in
    the file. A view named ``checkpoint`` can show the genuine row while the log is
    verified and a forged one once it is in WAL mode; a trigger can rewrite rows as the
    resumed run commits, or abort it mid-mission. A version 2 log must have exactly the
    schema of `EventLog.create`; a version 1 log (never resumed with a key) at least no
    view or trigger.
    """
    rows = schema_of(db)
    if version >= 2:
        sound = tuple(rows) == written_schema()
    else:
        sound = all(row[0] in ("table", "index") for row in rows)
    if not sound:
        raise EventLogError(
            f"{path}: the log's tables are not the ones coral writes (a view, trigger, "
            "index or altered table was added); the file was edited"
        )


def is_real(value: object) -> TypeGuard[int | float]:
    """A number SQLite hands back for a REAL column (never a bool, text or blob)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def no_tables(db: sqlite3.Connection) -> bool:
    """True for an empty database (a file SQLite created, not a log yet)."""
    return bool(db.execute("SELECT count(*) FROM sqlite_master").fetchone()[0] == 0)
