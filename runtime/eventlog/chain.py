"""Checking a whole log against its MAC chain, row by row, before anyone trusts it.

Why a module of its own: the writer extends the chain one commit at a time
(`runtime.eventlog.EventLog.commit`); this is the other half, which re-reads everything a
log holds and says where the first thing that does not belong is: the key, the header, a
missing or inserted row, a commit whose rows or record changed, rows no commit covers, a
checkpoint that is not the state committed last (forged, or an older one put back).

What it cannot see: a log cut back to an earlier commit, whole (commits, rows and the
checkpoint of that commit). That is still a log the key wrote; the controller's
``log-behind`` check (`runtime.controller`, the vehicle's reply numbers run ahead of the
log) is what catches it.
"""

from __future__ import annotations

import hmac
import sqlite3
from collections.abc import Iterator
from dataclasses import dataclass

from runtime.eventlog.auth import CommitMac, header_mac, key_id, state_digest

__all__ = ["HEADER_FIELDS", "ChainBroken", "ChainState", "verify_chain"]

HEADER_FIELDS = "schema_version, role, mission, created, meta, net_json, net_digest"
"""The header columns the header's MAC covers, in this order."""

_EDITED = "the log was edited (or damaged), so it is refused"


class ChainBroken(Exception):
    """The log does not verify; the message says what and where (without the path)."""


@dataclass(frozen=True)
class ChainState:
    """Where a verified log's chain stands: what a writer needs to extend it.

    Attributes:
        mac: the last MAC (the header's when no commit was made).
        commits: commit records so far.
        event_seq: the last event's seq (0: none).
        sample_n: the last telemetry sample's n (0: none).
        state_commits: commits that carried a state.
    """

    mac: bytes
    commits: int
    event_seq: int
    sample_n: int
    state_commits: int


def _rows(db: sqlite3.Connection, sql: str) -> Iterator[tuple[object, ...]]:
    return iter(db.execute(sql))  # a cursor: read as the check goes, never all at once


def _bad_mac(stored: object, expected: bytes) -> bool:
    return not isinstance(stored, str) or not hmac.compare_digest(
        stored.encode("ascii", "replace"), expected.hex().encode()
    )


def _check_header(db: sqlite3.Connection, key: bytes) -> bytes:
    row = db.execute(f"SELECT {HEADER_FIELDS}, key_id, mac FROM header WHERE id = 1").fetchone()
    if row is None:
        raise ChainBroken(f"the header row is missing; {_EDITED}")
    *fields, stored_id, stored_mac = row
    if stored_id is None and stored_mac is None:
        raise ChainBroken(
            "the log is not authenticated (written without a key), so edits to it cannot "
            "be detected"
        )
    if stored_id != key_id(key):
        raise ChainBroken(
            "the log was written with another key, or edited (its key id does not match "
            "this run's key)"
        )
    expected = header_mac(key, fields)
    if _bad_mac(stored_mac, expected):
        raise ChainBroken(
            "the header (mission, meta, net_json, net_digest, role or created) does not "
            f"match its MAC; {_EDITED}"
        )
    return expected


def verify_chain(db: sqlite3.Connection, key: bytes) -> ChainState:
    """Check the header, every commit record, event and sample, and the checkpoint.

    Reads in one transaction, so a writer appending meanwhile is seen as of one moment.

    Raises:
        ChainBroken: the first thing that does not verify, named.
        sqlite3.Error: the file cannot be read.
    """
    own = not db.in_transaction
    if own:
        db.execute("BEGIN")
    try:
        return _verify(db, key)
    finally:
        if own and db.in_transaction:
            db.execute("COMMIT")


def _verify(db: sqlite3.Connection, key: bytes) -> ChainState:
    mac = _check_header(db, key)
    events = _rows(db, "SELECT seq, time, kind, data FROM events ORDER BY seq")
    samples = _rows(db, "SELECT n, time, seq, x, y, z, psi, est_x, est_y FROM telemetry ORDER BY n")
    next_event = next(events, None)
    next_sample = next(samples, None)
    event_seq = sample_n = commits = 0
    states: dict[str, int] = {}  # state digest -> the last commit that carried it
    last_state: tuple[int, int, str] | None = None  # (commit, event_seq, digest)
    state_commits = 0
    for n, upto_event, upto_sample, state_sha, stored in _rows(
        db, "SELECT n, event_seq, sample_n, state_sha, mac FROM commits ORDER BY n"
    ):
        expected_n = commits + 1
        if n != expected_n:
            raise ChainBroken(f"commit record {expected_n} is missing (deleted); {_EDITED}")
        if not isinstance(upto_event, int) or not isinstance(upto_sample, int):
            raise ChainBroken(f"commit record {n} is not numeric; {_EDITED}")
        if upto_event < event_seq or upto_sample < sample_n:
            raise ChainBroken(f"commit record {n} goes back before commit {n - 1}; {_EDITED}")
        if state_sha is not None and not isinstance(state_sha, str):
            raise ChainBroken(f"commit record {n}'s state digest is not text; {_EDITED}")
        commit = CommitMac(
            key, mac, n=n, event_seq=upto_event, sample_n=upto_sample, state_sha=state_sha
        )
        while event_seq < upto_event:
            if next_event is None or next_event[0] != event_seq + 1:
                raise ChainBroken(
                    f"event {event_seq + 1} (of commit {n}) is missing (deleted or "
                    f"renumbered); {_EDITED}"
                )
            commit.event(next_event)
            event_seq += 1
            next_event = next(events, None)
        while sample_n < upto_sample:
            if next_sample is None or next_sample[0] != sample_n + 1:
                raise ChainBroken(
                    f"telemetry sample {sample_n + 1} (of commit {n}) is missing (deleted "
                    f"or renumbered); {_EDITED}"
                )
            commit.sample(next_sample)
            sample_n += 1
            next_sample = next(samples, None)
        mac = commit.digest()
        if _bad_mac(stored, mac):
            raise ChainBroken(
                f"commit {n} (events up to {upto_event}, samples up to {upto_sample}) does "
                "not match its MAC: one of its rows or its commit record was changed, or "
                f"rows were moved; {_EDITED}"
            )
        commits = n
        if state_sha is not None:
            state_commits += 1
            states[state_sha] = n
            last_state = (n, upto_event, state_sha)
    if next_event is not None:
        raise ChainBroken(
            f"event {next_event[0]} is not covered by any commit (inserted after commit "
            f"{commits}); {_EDITED}"
        )
    if next_sample is not None:
        raise ChainBroken(
            f"telemetry sample {next_sample[0]} is not covered by any commit (inserted "
            f"after commit {commits}); {_EDITED}"
        )
    _check_checkpoint(db, last_state, state_commits, states)
    return ChainState(mac, commits, event_seq, sample_n, state_commits)


def _check_checkpoint(
    db: sqlite3.Connection,
    last: tuple[int, int, str] | None,
    state_commits: int,
    states: dict[str, int],
) -> None:
    """The checkpoint row must be exactly the state the last state-carrying commit wrote."""
    row = db.execute("SELECT commits, event_seq, state FROM checkpoint WHERE id = 1").fetchone()
    if last is None:
        if row is not None:
            raise ChainBroken(
                f"the checkpoint row was forged: no commit carried a state; {_EDITED}"
            )
        return
    commit, event_seq, digest = last
    if row is None:
        raise ChainBroken(f"the checkpoint row is missing (commit {commit} wrote one); {_EDITED}")
    count, at, state = row
    actual = state_digest(state)
    if actual != digest:
        older = states.get(actual)
        if older is not None:
            raise ChainBroken(
                f"the checkpoint is the state of commit {older}, not that of commit "
                f"{commit}, the last one: an older checkpoint was put back (replayed); "
                f"{_EDITED}"
            )
        raise ChainBroken(
            f"the checkpoint's state is not the one commit {commit} wrote (forged or "
            f"edited); {_EDITED}"
        )
    if count != state_commits or at != event_seq:
        raise ChainBroken(
            f"the checkpoint's commits or event_seq field does not match commit {commit}; {_EDITED}"
        )
