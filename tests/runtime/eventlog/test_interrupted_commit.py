"""A commit interrupted by Ctrl-C (or SIGTERM taken as it) leaves the log consistent.

The interruption can land before the transaction's COMMIT (nothing is written; the
buffer stays for a retry) or after it (the rows are on disk; the log's chain must count
them, or the next commit reuses their numbers and fails on a UNIQUE constraint).
"""

from __future__ import annotations

import sqlite3
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from runtime.eventlog import EventLog, log_key

KEY = log_key(bytes(range(32)))


class _Interrupting:
    """The log's connection, raising KeyboardInterrupt around one statement."""

    def __init__(self, db: sqlite3.Connection, statement: str, after: bool) -> None:
        self._db = db
        self._statement = statement
        self._after = after
        self.fired = False

    def execute(self, sql: str, *args: Any) -> sqlite3.Cursor:
        return self._around(sql, lambda: self._db.execute(sql, *args))

    def executemany(self, sql: str, rows: Any) -> sqlite3.Cursor:
        return self._around(sql, lambda: self._db.executemany(sql, rows))

    def _around(self, sql: str, run: Callable[[], sqlite3.Cursor]) -> sqlite3.Cursor:
        hit = not self.fired and sql.startswith(self._statement)
        if hit and not self._after:
            self.fired = True
            raise KeyboardInterrupt
        cursor = run()
        if hit:
            self.fired = True
            raise KeyboardInterrupt
        return cursor

    def __getattr__(self, name: str) -> object:
        return getattr(self._db, name)


@pytest.mark.parametrize(
    ("statement", "after"),
    [
        ("BEGIN", True),
        ("INSERT INTO events", False),
        ("INSERT INTO events", True),
        ("INSERT INTO commits", True),
        ("COMMIT", False),
        ("COMMIT", True),
    ],
)
def test_an_interrupted_commit_leaves_a_log_that_goes_on_and_verifies(
    tmp_path: Path, statement: str, after: bool
) -> None:
    path = tmp_path / "ctl.log"
    log = EventLog.create(path, role="controller", mission="1", meta={}, mac_key=KEY)
    log.event(1.0, "first")
    log.commit({"n": 1})
    log.event(2.0, "second")
    real = log._db
    assert real is not None
    interrupting = _Interrupting(real, statement, after)
    log._db = interrupting  # type: ignore[assignment]
    with pytest.raises(KeyboardInterrupt):
        log.commit({"n": 2})
    assert interrupting.fired
    log._db = real
    assert not real.in_transaction
    # The retry writes what was not written, once; what was written is not written again.
    log.event(3.0, "third")
    log.commit({"n": 3})
    log.close()
    reopened = EventLog.open(path, mac_key=KEY)
    kinds = [event.kind for event in reopened.events()]
    assert kinds == ["first", "second", "third"]
    assert [event.seq for event in reopened.events()] == [1, 2, 3]
    assert reopened.checkpoint() == {"n": 3}
    reopened.verify(KEY)
    reopened.close()


class _FailingThenInterrupted(_Interrupting):
    """An INSERT fails with a database error, then Ctrl-C lands in the ROLLBACK."""

    def _around(self, sql: str, run: Callable[[], sqlite3.Cursor]) -> sqlite3.Cursor:
        if sql.startswith("INSERT INTO events"):
            raise sqlite3.OperationalError("disk I/O error")
        if sql.startswith("ROLLBACK") and not self.fired:
            self.fired = True
            raise KeyboardInterrupt
        return run()


def test_ctrl_c_in_the_rollback_of_a_failed_commit_does_not_block_the_next(
    tmp_path: Path,
) -> None:
    path = tmp_path / "ctl.log"
    log = EventLog.create(path, role="controller", mission="1", meta={}, mac_key=KEY)
    log.event(1.0, "first")
    real = log._db
    assert real is not None
    log._db = _FailingThenInterrupted(real, "", after=False)  # type: ignore[assignment]
    with pytest.raises(KeyboardInterrupt):
        log.commit({"n": 1})
    log._db = real
    assert real.in_transaction  # left open by the interrupted rollback
    log.commit({"n": 1})
    log.close()
    reopened = EventLog.open(path, mac_key=KEY)
    assert [event.kind for event in reopened.events()] == ["first"]
    reopened.verify(KEY)
    reopened.close()
