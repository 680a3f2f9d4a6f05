"""`EventLog`: one side's log, created at mission start, opened to resume or to read.

The rule that makes ``coral-run --resume`` lose and repeat nothing lives here: `commit`
writes everything buffered since the last commit and the new checkpoint in one durable
SQLite transaction (see the package's documentation and ``docs/eventlog.md``).
"""

from __future__ import annotations

import contextlib
import datetime as dt
import json
import math
import os
import sqlite3
import sys
import threading
from collections.abc import Callable, Collection, Iterator, Mapping, Sequence
from pathlib import Path
from types import TracebackType
from typing import Any, Final, Literal, TypeAlias

from runtime.eventlog.auth import CommitMac, header_mac, key_id, state_digest
from runtime.eventlog.chain import HEADER_FIELDS, ChainBroken, ChainState, verify_chain
from runtime.eventlog.jsonvalues import (
    NotJson,
    dumps_strict,
    finite_seconds,
    jsonable,
    stored_pose,
)
from runtime.eventlog.records import Event, EventLogError, Listener
from runtime.eventlog.storage import (
    APPLICATION_ID,
    READABLE_VERSIONS,
    SCHEMA,
    SCHEMA_VERSION,
    check_log_key,
    check_schema,
    explain,
    hold_lock,
    is_real,
    no_tables,
    utf8_text,
)
from runtime.telemetry import TelemetryRecord

__all__ = ["EventLog", "LogRole"]


LogRole: TypeAlias = Literal["controller", "vehicle"]
_ROLES: Final = ("controller", "vehicle")

_BATCH: Final = 2000  # rows fetched per query while iterating, so a long log never sits in memory

_READ_TIMEOUT: Final = 2.0
"""Seconds SQLite may wait on a lock held for an instant (WAL recovery, a checkpoint);
the one-writer rule is the ``flock``, refused at once, not a SQLite lock."""


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
    schema_version: int
    authenticated: bool

    def __init__(
        self,
        connection: sqlite3.Connection,
        path: Path,
        *,
        writable: bool,
        header: tuple[object, ...],
        version: int = SCHEMA_VERSION,
        authenticated: bool = False,
        lock: int | None = None,
    ) -> None:
        """Internal: use `create` or `open`."""
        self._db: sqlite3.Connection | None = connection
        self._lock_fd = lock
        self.path = path
        self.writable = writable
        self.schema_version = version
        self.authenticated = authenticated
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
        # Where the chain stands (writers): the key, the last MAC, and the last commit,
        # event and sample, kept in memory so an append costs the same at any length.
        self._key: bytes | None = None
        self._chain = ChainState(b"", 0, 0, 0, 0)
        # In-process observers of the rows written (`add_listener`); a tuple, replaced
        # whole, so calling them never holds the lock and an empty one costs one test.
        self._listeners: tuple[Listener, ...] = ()
        # What to call when a listener is dropped for raising (by id; the entry keeps the
        # listener alive so its id cannot be reused while registered).
        self._on_drop: dict[int, tuple[Listener, Callable[[BaseException], None]]] = {}

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
        mac_key: bytes | None = None,
    ) -> EventLog:
        """Start a new log at ``path`` and hold it for writing.

        The file (and SQLite's ``-wal`` and ``-shm`` beside it, which take its mode) is
        readable by its owner only: a log holds the mission, positions and commands.

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
            mac_key: the log key (`log_key` of the run's pre-shared key): the header and
                every commit are chained under it, so edits are detected when the log is
                opened with it. None writes an unauthenticated log (a run whose key dies
                with it, ``coral-run fuzz``): readable, but never trusted for a resume.

        Raises:
            EventLogError: the file exists, the folder is missing or read-only, the disk is
                full, or ``meta`` holds something JSON cannot.
        """
        target = Path(path)
        header = cls._new_header(target, role, mission, meta, net_json, net_digest)
        key = check_log_key(target, mac_key)
        try:
            # O_EXCL: refuse an existing file atomically, even against a racing creator.
            fd = os.open(target, os.O_RDWR | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, 0o600)
        except FileExistsError:
            raise EventLogError(
                f"{target}: already exists; a log is never overwritten. Choose a new file, "
                "or open this one to resume (coral-run --resume)"
            ) from None
        except OSError as error:
            raise EventLogError(f"{target}: cannot create: {error.strerror}") from None
        try:
            os.fchmod(fd, 0o600)  # whatever the umask: owner only
            hold_lock(target, fd)
        except BaseException:
            with contextlib.suppress(OSError):
                os.close(fd)
            target.unlink(missing_ok=True)
            raise
        auth: tuple[str | None, str | None] = (None, None)
        mac = b""
        if key is not None:
            mac = header_mac(key, (SCHEMA_VERSION, *header))
            auth = (key_id(key), mac.hex())
        try:
            db = cls._connect(target, writable=True)
        except sqlite3.Error as error:
            os.close(fd)
            target.unlink(missing_ok=True)  # ours (O_EXCL above): leave nothing half-made
            raise explain(target, "create the log", error) from None
        try:
            cls._start_writing(db)
            cls._initialise(db, header, auth)
        except sqlite3.Error as error:
            db.close()
            os.close(fd)
            target.unlink(missing_ok=True)
            raise explain(target, "create the log", error) from None
        log = cls(db, target, writable=True, header=header, authenticated=key is not None, lock=fd)
        log._key = key
        log._chain = ChainState(mac, 0, 0, 0, 0)
        return log

    @classmethod
    def create_in_memory(
        cls,
        name: str,
        *,
        role: LogRole,
        mission: str,
        meta: Mapping[str, object],
        net_json: str | None = None,
        net_digest: str | None = None,
    ) -> EventLog:
        """Start a new, unauthenticated log held in memory only, gone when closed.

        For runs whose log is kept only if something is to be learnt from it, such as
        ``coral-run fuzz``'s: a commit costs no file system work at all (a fuzz run's
        log was a sixth of its time on disk even without waiting for the disk), and
        `save_copy` writes the log out as an ordinary log file when it is wanted.
        Everything else is as for `create` (``name`` stands for the path in messages).

        Raises:
            EventLogError: ``meta`` holds something JSON cannot.
        """
        target = Path(name)
        header = cls._new_header(target, role, mission, meta, net_json, net_digest)
        db = cls._connect(":memory:", writable=True)
        try:
            cls._initialise(db, header, (None, None))
        except sqlite3.Error as error:
            db.close()
            raise explain(target, "create the log", error) from None
        log = cls(db, target, writable=True, header=header, authenticated=False)
        log._chain = ChainState(b"", 0, 0, 0, 0)
        return log

    def save_copy(self, path: str | Path) -> None:
        """Write everything committed so far to a new log file at ``path``.

        The copy is an ordinary log (``coral-run timeline`` and `open` read it), readable
        by its owner only; an existing file is never overwritten. Events still buffered
        are not in it: commit first.

        Raises:
            EventLogError: the file exists, or cannot be written.
        """
        target = Path(path)
        source = self._connection()
        try:
            fd = os.open(target, os.O_RDWR | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, 0o600)
        except FileExistsError:
            raise EventLogError(f"{target}: already exists; a log is never overwritten") from None
        except OSError as error:
            raise EventLogError(f"{target}: cannot create: {error.strerror}") from None
        try:
            os.fchmod(fd, 0o600)
            copy = sqlite3.connect(target, isolation_level=None)
            try:
                with self._lock:
                    source.backup(copy)
                copy.execute("PRAGMA journal_mode = DELETE")
            finally:
                copy.close()
        except sqlite3.Error as error:
            target.unlink(missing_ok=True)
            raise explain(target, "write a copy of the log", error) from None
        except OSError as error:
            target.unlink(missing_ok=True)
            raise EventLogError(f"{target}: cannot write a copy of the log: {error}") from None
        finally:
            os.close(fd)

    @staticmethod
    def _new_header(
        target: Path,
        role: LogRole,
        mission: str,
        meta: Mapping[str, object],
        net_json: str | None,
        net_digest: str | None,
    ) -> tuple[object, ...]:
        """A new log's header fields, stamped now (`EventLogError`: a bad role or meta)."""
        if role not in _ROLES:
            raise EventLogError(f"{target}: role must be 'controller' or 'vehicle', not {role!r}")
        try:
            meta_json = dumps_strict(jsonable(dict(meta), "meta"))
        except NotJson as bad:
            raise bad.error(f"{target}: ") from None
        created = dt.datetime.now(dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")
        return (role, mission, created, meta_json, net_json, net_digest)

    @staticmethod
    def _initialise(
        db: sqlite3.Connection, header: tuple[object, ...], auth: tuple[str | None, str | None]
    ) -> None:
        """Lay out a new log's tables and its header, in one transaction (an interrupted
        creation leaves no half-made log)."""
        db.execute("BEGIN EXCLUSIVE")
        db.execute(f"PRAGMA application_id = {APPLICATION_ID}")
        db.execute(f"PRAGMA user_version = {SCHEMA_VERSION}")
        for statement in SCHEMA.split(";"):
            if statement.strip():
                db.execute(statement)
        db.execute(
            f"INSERT INTO header (id, {HEADER_FIELDS}, key_id, mac) "
            "VALUES (1, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
            (SCHEMA_VERSION, *header, *auth),
        )
        db.execute("COMMIT")

    @classmethod
    def open(
        cls, path: str | Path, *, writable: bool = False, mac_key: bytes | None = None
    ) -> EventLog:
        """Open an existing log: writable to resume a mission, read-only for the timeline.

        A writable log is held until `close`: a second writer is refused meanwhile, while
        readers may open it at any time and see what was committed. A log left by a killed
        writer opens normally: SQLite rolls its uncommitted tail back and the last commit
        is intact.

        Args:
            path: the log.
            writable: to append to it (a resume).
            mac_key: the log key: verify the whole log under it first (`verify`), and keep
                extending its chain. Required to append to an authenticated log; a log
                that is not authenticated is refused with a key (its edits could not be
                told). None opens any readable log without verifying it
                (`authenticated` says whether it could be).

        Raises:
            EventLogError: the file is missing, empty, not a SQLite database, another
                application's database, of another schema version, damaged, open for
                writing by another process, or (with ``mac_key``) it does not verify:
                written with another key, edited, or not authenticated.
        """
        target = Path(path)
        key = check_log_key(target, mac_key)
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
        fd = None
        if writable:
            try:
                fd = hold_lock(target, os.open(target, os.O_RDONLY | os.O_CLOEXEC))
            except OSError as error:
                raise EventLogError(f"{target}: cannot open: {error.strerror}") from None
        try:
            log = cls._open_locked(target, writable=writable, key=key, lock=fd)
        except BaseException:
            if fd is not None:
                os.close(fd)
            raise
        return log

    @classmethod
    def _open_locked(
        cls, target: Path, *, writable: bool, key: bytes | None, lock: int | None
    ) -> EventLog:
        try:
            db = cls._connect(target, writable=writable)
        except sqlite3.Error as error:
            raise explain(target, "open the log", error) from None
        try:
            version, header, authenticated = cls._check(db, target, writable=writable)
            log = cls(
                db,
                target,
                writable=writable,
                header=header,
                version=version,
                authenticated=authenticated,
                lock=lock,
            )
        except BaseException:
            db.close()
            raise
        try:
            if key is not None:
                log._chain = log._verify(key)
                log._key = key
            elif writable and authenticated:
                raise EventLogError(
                    f"{target}: the log is authenticated: appending to it needs its key "
                    "(the run's pre-shared key)"
                )
            elif writable:
                log._chain = log._unverified_chain()
            if writable:
                cls._start_writing(db)
        except sqlite3.Error as error:
            log._abandon()
            raise explain(target, "open the log", error) from None
        except BaseException:
            log._abandon()
            raise
        return log

    def _abandon(self) -> None:
        """Close a log refused while opening, leaving the file exactly as it was."""
        self._lock_fd = None  # the caller closes it
        self.writable = False  # nothing to commit, no journal mode to switch back
        self.close()

    @staticmethod
    def _connect(path: Path | str, *, writable: bool) -> sqlite3.Connection:
        db = sqlite3.connect(
            path, timeout=_READ_TIMEOUT, isolation_level=None, check_same_thread=False
        )
        try:
            # Nothing in the file itself may run code of its own: no function calls
            # from its schema (views and triggers are refused outright, `check_schema`).
            db.execute("PRAGMA trusted_schema = OFF")
            db.text_factory = utf8_text
            if not writable:
                db.execute("PRAGMA query_only = ON")
        except BaseException:
            db.close()
            raise
        return db

    @staticmethod
    def _start_writing(db: sqlite3.Connection) -> None:
        """Switch to WAL, durable commits; only once the log was found sound, so that a
        refused log is left untouched.

        WAL: readers (the timeline of a running mission) read the last commit while the
        writer appends, and neither waits for the other.
        """
        db.execute("PRAGMA journal_mode = WAL")
        db.execute("PRAGMA synchronous = FULL")

    @staticmethod
    def _check(
        db: sqlite3.Connection, path: Path, *, writable: bool
    ) -> tuple[int, tuple[object, ...], bool]:
        """Check it is a sound coral log; return its version, header and whether it has
        a MAC chain."""
        try:
            app = db.execute("PRAGMA application_id").fetchone()[0]
            if app != APPLICATION_ID:
                hint = " (its creation was interrupted?)" if app == 0 and no_tables(db) else ""
                raise EventLogError(
                    f"{path}: a SQLite database, but not a coral event log "
                    f"(application_id {app:#x}, expected {APPLICATION_ID:#x}){hint}"
                )
            version = db.execute("PRAGMA user_version").fetchone()[0]
            if version not in READABLE_VERSIONS:
                raise EventLogError(
                    f"{path}: event log schema version {version}; this coral reads versions "
                    f"{', '.join(map(str, READABLE_VERSIONS))} only (use the coral that wrote it)"
                )
            problems = [row[0] for row in db.execute("PRAGMA quick_check(5)")]
            if problems != ["ok"]:
                raise EventLogError(
                    f"{path}: the file is damaged (truncated or overwritten): "
                    + "; ".join(str(p) for p in problems)
                )
            check_schema(db, path, version)
            auth = ", mac" if version >= 2 else ", NULL"
            row = db.execute(f"SELECT {HEADER_FIELDS}{auth} FROM header WHERE id = 1").fetchone()
        except sqlite3.Error as error:
            raise explain(path, "open the log" if writable else "read the log", error) from None
        except UnicodeDecodeError:  # SQLite's own message quoted the damaged bytes
            raise EventLogError(
                f"{path}: the file is damaged or edited: it holds text that is not UTF-8"
            ) from None
        if row is None:
            raise EventLogError(f"{path}: the header row is missing; the file is damaged")
        if row[0] != version:
            raise EventLogError(
                f"{path}: the header says schema version {row[0]!r}, the file {version}; "
                "the file is damaged or edited"
            )
        if row[1] not in _ROLES:
            raise EventLogError(f"{path}: unknown role {row[1]!r} in the header")
        try:
            json.loads(row[4])
        except (TypeError, ValueError, RecursionError):
            raise EventLogError(
                f"{path}: the header's meta is not JSON; the file is damaged"
            ) from None
        return int(version), tuple(row[1:7]), row[7] is not None

    # --- verifying --------------------------------------------------------------------------

    def verify(self, mac_key: bytes) -> None:
        """Check the whole log under ``mac_key``: header, every row, the checkpoint.

        Proves that every committed row and the checkpoint are what a holder of the key
        wrote, in that order, and that the checkpoint is the state committed last. It
        cannot tell a log cut back to an earlier commit (``docs/eventlog.md``, "The MAC
        chain").

        Raises:
            EventLogError: naming the log and the first thing that does not verify: not
                authenticated (schema 1, or written without a key), written with another
                key, the header, a missing, inserted or changed row, or a checkpoint
                forged or put back.
        """
        self._verify(check_log_key(self.path, mac_key))

    def _verify(self, key: bytes | None) -> ChainState:
        assert key is not None
        if self.schema_version < 2:
            raise EventLogError(
                f"{self.path}: the log is not authenticated (schema version "
                f"{self.schema_version}, before the MAC chain), so edits to it cannot be "
                "detected"
            )
        with self._lock:
            db = self._connection()
            try:
                return verify_chain(db, key)
            except ChainBroken as broken:
                raise EventLogError(f"{self.path}: {broken}") from None
            except sqlite3.Error as error:
                raise explain(self.path, "read the log", error) from None

    def _unverified_chain(self) -> ChainState:
        """Where an unauthenticated log stands, for a writer to go on appending."""
        n = self._query_one("SELECT coalesce(max(n), 0) FROM commits") if self._chained else None
        seq = self._query_one("SELECT coalesce(max(seq), 0) FROM events")
        sample = self._query_one("SELECT coalesce(max(n), 0) FROM telemetry")
        states = self._query_one("SELECT commits FROM checkpoint WHERE id = 1")
        return ChainState(
            b"",
            0 if n is None else int(n[0]),
            0 if seq is None else int(seq[0]),
            0 if sample is None else int(sample[0]),
            0 if states is None else int(states[0]),
        )

    @property
    def _chained(self) -> bool:
        return self.schema_version >= 2

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
        moment = finite_seconds(time, f"the time of event {kind!r}", self.path)
        try:
            plain = jsonable(data, "data")
            text = dumps_strict(plain)
        except NotJson as bad:
            raise bad.error(f"{self.path}: event {kind!r}: ") from None
        with self._lock:
            self._events.append((moment, str(kind), text))
            seq = self._chain.event_seq + len(self._events)
        if self._listeners:  # `plain` is what JSON gives back, and this call's own copy
            self._tell(Event(seq, moment, str(kind), plain))  # type: ignore[arg-type]

    def telemetry(self, sample: TelemetryRecord) -> None:
        """Buffer one telemetry sample; it is written by the next `commit` (or `close`).

        Pose values that are NaN are stored as NULL and read back as NaN (``est_x``,
        ``est_y``: as None). The record's ``vehicle_time`` is the table's ``time`` column
        (the column kept its name, so logs written before the one record still read).
        """
        self._writable()
        moment = finite_seconds(sample.vehicle_time, "a telemetry sample's vehicle time", self.path)
        row = (
            moment,
            int(sample.seq),
            stored_pose(sample.x),
            stored_pose(sample.y),
            stored_pose(sample.z),
            stored_pose(sample.psi),
            stored_pose(sample.est_x),
            stored_pose(sample.est_y),
        )
        with self._lock:
            self._samples.append(row)
        if self._listeners:
            nan = math.nan
            x, y, z, psi = (nan if v is None else v for v in row[2:6])
            self._tell(TelemetryRecord(moment, x, y, z, psi, row[6], row[7], row[1]))

    def add_listener(
        self,
        listener: Listener,
        *,
        replay: bool = False,
        on_drop: Callable[[BaseException], None] | None = None,
    ) -> Callable[[], None]:
        """Call ``listener`` with every event and sample logged from now on; returns the
        function that removes it.

        Why: a live viewer of the run (`runtime.watch.feed`) wants each row the moment the
        engine logs it, without polling the file. The listener is called synchronously, in
        the writer's thread, right after `event` or `telemetry` buffered the row, with the
        row as a reader will get it back once committed (``seq`` included, the data as
        JSON returns it, NaN poses as NaN): so it must be tiny, it runs in the engine's
        path. This is in-process only; nothing of it reaches the file. A listener that
        raises is reported once on stderr and dropped, so it can never break logging;
        ``on_drop`` (if given) is then called with the error, so the listener's owner
        learns it no longer hears the log instead of silently freezing (a live view
        would otherwise go on claiming to be live). An ``on_drop`` that raises is
        ignored. With no listener, logging costs one test more.

        ``replay=True`` first gives the listener every row the log already holds,
        committed or buffered, in order (events, then samples), before this returns: a
        viewer attached after the mission started (or to a resumed one) starts from its
        beginning, and misses nothing in between. Call it from the writer's thread.

        Raises:
            EventLogError: with ``replay``, a stored row is damaged (as `events` would).
        """
        rows: list[Event | TelemetryRecord] = []
        with self._lock:
            if replay:
                rows = self._rows_so_far()
            self._listeners = (*self._listeners, listener)
            if on_drop is not None:
                self._on_drop[id(listener)] = (listener, on_drop)

        def remove() -> None:
            self._listeners = tuple(known for known in self._listeners if known is not listener)
            self._forget(listener)

        for row in rows:
            listener(row)
        return remove

    def _rows_so_far(self) -> list[Event | TelemetryRecord]:
        """Every row stored or buffered, as readers get them back (caller holds the lock)."""
        db = self._connection()
        try:
            stored = db.execute("SELECT seq, time, kind, data FROM events ORDER BY seq").fetchall()
            numbered = db.execute(
                "SELECT time, seq, x, y, z, psi, est_x, est_y FROM telemetry ORDER BY n"
            ).fetchall()
        except sqlite3.Error as error:
            raise explain(self.path, "read the log", error) from None
        rows: list[Event | TelemetryRecord] = [self._event(*row) for row in stored]
        first = self._chain.event_seq + 1
        rows.extend(
            Event(seq, moment, kind, json.loads(text))
            for seq, (moment, kind, text) in enumerate(self._events, first)
        )
        nan = math.nan
        for time, seq, *pose in [*numbered, *self._samples]:
            x, y, z, psi = (nan if v is None else v for v in pose[:4])
            rows.append(TelemetryRecord(time, x, y, z, psi, pose[4], pose[5], seq))
        return rows

    def _forget(self, listener: Listener) -> Callable[[BaseException], None] | None:
        """Drop ``listener``'s ``on_drop``; the callback it had, if any."""
        entry = self._on_drop.get(id(listener))
        if entry is None or entry[0] is not listener:
            return None
        del self._on_drop[id(listener)]
        return entry[1]

    def _tell(self, row: Event | TelemetryRecord) -> None:
        for listener in self._listeners:
            try:
                listener(row)
            except Exception as error:  # a viewer must never break the log
                self._listeners = tuple(known for known in self._listeners if known is not listener)
                print(
                    f"{self.path}: event-log listener {listener!r} failed and was removed: "
                    f"{type(error).__name__}: {error}",
                    file=sys.stderr,
                )
                on_drop = self._forget(listener)
                if on_drop is not None:
                    with contextlib.suppress(Exception):  # nor may its owner's callback
                        on_drop(error)

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
                state_json = dumps_strict(jsonable(dict(state), "state"))
            except NotJson as bad:
                raise bad.error(f"{self.path}: checkpoint: ") from None
        with self._lock:
            if state_json is None and not self._events and not self._samples:
                return
            db = self._connection()
            chain = self._chain
            events = [(chain.event_seq + i, *row) for i, row in enumerate(self._events, 1)]
            samples = [(chain.sample_n + i, *row) for i, row in enumerate(self._samples, 1)]
            state_sha = None if state_json is None else state_digest(state_json)
            after = self._next_chain(events, samples, state_sha)
            self._abandon_open_transaction(db)
            began = False
            try:
                db.execute("BEGIN IMMEDIATE")
                began = True
                if events:
                    db.executemany(
                        "INSERT INTO events (seq, time, kind, data) VALUES (?, ?, ?, ?)", events
                    )
                if samples:
                    db.executemany(
                        "INSERT INTO telemetry (n, time, seq, x, y, z, psi, est_x, est_y) "
                        "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                        samples,
                    )
                if state_json is not None:
                    db.execute(
                        "INSERT INTO checkpoint (id, commits, event_seq, state) "
                        "VALUES (1, ?, ?, ?) ON CONFLICT (id) DO UPDATE SET "
                        "commits = excluded.commits, event_seq = excluded.event_seq, "
                        "state = excluded.state",
                        (after.state_commits, after.event_seq, state_json),
                    )
                if self._chained:
                    db.execute(
                        "INSERT INTO commits (n, event_seq, sample_n, state_sha, mac) "
                        "VALUES (?, ?, ?, ?, ?)",
                        (
                            after.commits,
                            after.event_seq,
                            after.sample_n,
                            state_sha,
                            after.mac.hex() if self._key is not None else None,
                        ),
                    )
                db.execute("COMMIT")
                self._committed(after)  # only now: a failed commit leaves the chain as it was
            except sqlite3.Error as error:
                if db.in_transaction:
                    with contextlib.suppress(sqlite3.Error):
                        db.execute("ROLLBACK")
                raise explain(self.path, "commit to the log", error) from None
            except BaseException:
                # Ctrl-C (or SIGTERM taken as it) can land anywhere in here. Before COMMIT
                # the transaction is still open: roll it back, the buffer stays for a
                # retry. After it, the rows are on disk: the chain must say so, or the
                # next commit would reuse their numbers.
                if db.in_transaction:
                    with contextlib.suppress(sqlite3.Error):
                        db.execute("ROLLBACK")
                elif began:
                    self._committed(after)
                raise

    def _abandon_open_transaction(self, db: sqlite3.Connection) -> None:
        """Roll back a transaction an interrupted commit left open (a second Ctrl-C
        during its own rollback): the log never holds one open between commits, and
        what it wrote was never committed, so the chain is still right."""
        if db.in_transaction:
            try:
                db.execute("ROLLBACK")
            except sqlite3.Error as error:
                raise explain(self.path, "roll back an interrupted commit", error) from None

    def _committed(self, after: ChainState) -> None:
        """Bookkeeping once a commit is on disk (idempotent: it may run twice)."""
        self._chain = after
        self._events.clear()
        self._samples.clear()

    def _next_chain(
        self,
        events: Sequence[tuple[object, ...]],
        samples: Sequence[tuple[object, ...]],
        state_sha: str | None,
    ) -> ChainState:
        """The chain once this commit is written: counters, and its MAC if keyed."""
        chain = self._chain
        commits = chain.commits + 1
        event_seq = chain.event_seq + len(events)
        sample_n = chain.sample_n + len(samples)
        mac = b""
        if self._key is not None:
            commit = CommitMac(
                self._key,
                chain.mac,
                n=commits,
                event_seq=event_seq,
                sample_n=sample_n,
                state_sha=state_sha,
            )
            for event in events:
                commit.event(event)
            for sample in samples:
                commit.sample(sample)
            mac = commit.digest()
        return ChainState(
            mac,
            commits,
            event_seq,
            sample_n,
            chain.state_commits + (state_sha is not None),
        )

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

    def events(self, kinds: Collection[str] | None = None, *, after: int = 0) -> Iterator[Event]:
        """Committed events in the order they were written, optionally only some kinds.

        ``kinds`` is a collection of kinds; a single string is taken as one kind. Only
        events numbered above ``after`` are read: a reader following a running mission
        asks for what was added since its last ``seq`` (`runtime.watch`).
        """
        if isinstance(kinds, str):
            kinds = [kinds]
        wanted = None if kinds is None else sorted(set(kinds))
        if wanted is not None and not wanted:
            return
        where = "" if wanted is None else f" AND kind IN ({', '.join('?' * len(wanted))})"
        last = after
        while True:
            rows = self._query_all(
                f"SELECT seq, time, kind, data FROM events WHERE seq > ?{where} "
                f"ORDER BY seq LIMIT {_BATCH}",
                (last, *(wanted or ())),
            )
            for seq, time, kind, data in rows:
                yield self._event(seq, time, kind, data)
            if len(rows) < _BATCH:
                return
            last = rows[-1][0]

    def _event(self, seq: int, time: object, kind: object, data: object) -> Event:
        """One events row as an `Event`; a row no writer could have made is refused by
        name (an edited log must give a message, never a traceback in a reader)."""
        if not is_real(time) or not isinstance(kind, str) or not isinstance(data, str):
            raise EventLogError(
                f"{self.path}: event {seq} holds values of the wrong type; the file is "
                "damaged or edited"
            )
        try:
            loaded = json.loads(data)
        except (ValueError, RecursionError):
            raise EventLogError(
                f"{self.path}: the data of event {seq} is not JSON (or nested too deep); "
                "the file is damaged or edited"
            ) from None
        if not isinstance(loaded, dict):
            raise EventLogError(
                f"{self.path}: the data of event {seq} is not a JSON object; the file is "
                "damaged or edited"
            )
        return Event(seq, float(time), kind, loaded)

    def samples(self) -> Iterator[TelemetryRecord]:
        """Committed telemetry samples in the order they were written."""
        for _, sample in self.numbered_samples():
            yield sample

    def numbered_samples(self, *, after: int = 0) -> Iterator[tuple[int, TelemetryRecord]]:
        """Committed telemetry samples numbered above ``after``, each with its row number
        (``n``), in the order they were written: what a reader following a running
        mission asks for since the last number it read."""
        last = after
        nan = math.nan
        while True:
            rows = self._query_all(
                "SELECT n, time, seq, x, y, z, psi, est_x, est_y FROM telemetry WHERE n > ? "
                f"ORDER BY n LIMIT {_BATCH}",
                (last,),
            )
            for n, time, seq, x, y, z, psi, est_x, est_y in rows:
                if not (
                    is_real(time)
                    and isinstance(seq, int)
                    and all(v is None or is_real(v) for v in (x, y, z, psi, est_x, est_y))
                ):
                    raise EventLogError(
                        f"{self.path}: telemetry row {n} holds values of the wrong type; "
                        "the file is damaged or edited"
                    )
                yield (
                    n,
                    TelemetryRecord(
                        time,
                        nan if x is None else x,
                        nan if y is None else y,
                        nan if z is None else z,
                        nan if psi is None else psi,
                        est_x,
                        est_y,
                        seq,
                    ),
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
        one self-contained file, readable even from read-only media (unless a reader still
        has it open: then it stays in WAL mode, as valid, and the writer does not wait).
        Closing twice is fine.

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
                    db.execute("PRAGMA busy_timeout = 0")  # never wait for a reader
                    db.execute("PRAGMA journal_mode = DELETE")
            except sqlite3.Error:
                pass  # still a valid WAL database; the next opener checkpoints it
            finally:
                db.close()
                lock, self._lock_fd = self._lock_fd, None
                if lock is not None:
                    os.close(lock)  # after SQLite's: the next writer may take it over now

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
                raise explain(self.path, "read the log", error) from None
            except UnicodeDecodeError:  # in SQLite's message about a damaged page
                raise EventLogError(
                    f"{self.path}: the file is damaged or edited: it holds text that is not UTF-8"
                ) from None

    def _query_one(self, sql: str, params: tuple[object, ...] = ()) -> tuple[Any, ...] | None:
        rows = self._query_all(sql, params)
        return rows[0] if rows else None
