"""The event log: round trips, atomic commits under a real kill -9, one writer, clear errors."""

from __future__ import annotations

import json
import math
import os
import random
import signal
import sqlite3
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from runtime.eventlog import (
    APPLICATION_ID,
    SCHEMA_VERSION,
    Event,
    EventLog,
    EventLogError,
    TelemetryRecord,
)
from tests.conftest import REPO

NET = '{"places": ["a", "b"], "transitions": ["t"]}'


def new_log(tmp_path: Path, name: str = "ctl.log", **kwargs: object) -> EventLog:
    args: dict[str, object] = {"role": "controller", "mission": "42", "meta": {"name": "pool"}}
    args.update(kwargs)
    return EventLog.create(tmp_path / name, **args)  # type: ignore[arg-type]


def sample(time: float, seq: int = 1, est: float | None = None) -> TelemetryRecord:
    return TelemetryRecord(time, 1.0 + time, 2.0, 3.0, 90.0, est, est, seq=seq)


# --- round trips ---------------------------------------------------------------------------


def test_header_events_samples_and_state_round_trip(tmp_path: Path) -> None:
    with new_log(
        tmp_path, meta={"name": "pool", "speed": 2.5}, net_json=NET, net_digest="sha256:ab"
    ) as log:
        log.event(10.0, "handshake", offset=12.5, delay=0.4, resumed=False)
        log.event(
            10.5,
            "command-sent",
            command_id=1,
            transition="t",
            name="DEPTH",
            params={"z": 2.0},
            resources=["depth"],
        )
        log.telemetry(sample(1000.0, 1))
        log.telemetry(sample(1000.5, 2, est=4.0))
        log.commit({"marking": {"a": 1}, "in_flight": [1], "consumed": 0, "next_id": 2})
    log = EventLog.open(tmp_path / "ctl.log")
    assert (log.role, log.mission, log.meta) == ("controller", "42", {"name": "pool", "speed": 2.5})
    assert (log.net_json, log.net_digest) == (NET, "sha256:ab")
    assert len(log.created) == 20 and log.created.endswith("Z")
    assert list(log.events()) == [
        Event(1, 10.0, "handshake", {"offset": 12.5, "delay": 0.4, "resumed": False}),
        Event(
            2,
            10.5,
            "command-sent",
            {
                "command_id": 1,
                "transition": "t",
                "name": "DEPTH",
                "params": {"z": 2.0},
                "resources": ["depth"],
            },
        ),
    ]
    assert list(log.samples()) == [sample(1000.0, 1), sample(1000.5, 2, est=4.0)]
    assert log.checkpoint() == {"marking": {"a": 1}, "in_flight": [1], "consumed": 0, "next_id": 2}
    assert log.checkpoint_seq() == 2
    log.close()


def test_a_vehicle_log_has_no_net_and_no_checkpoint_until_one_is_committed(tmp_path: Path) -> None:
    with EventLog.create(tmp_path / "veh.log", role="vehicle", mission="42", meta={}) as log:
        log.event(5.0, "command-received", command_id=1, name="DEPTH")
    with EventLog.open(tmp_path / "veh.log") as log:
        assert (log.role, log.net_json, log.net_digest) == ("vehicle", None, None)
        assert log.checkpoint() is None and log.checkpoint_seq() == 0
        assert log.count() == 1


def test_events_filter_by_kind_and_iterate_past_one_batch(tmp_path: Path) -> None:
    with new_log(tmp_path) as log:
        for i in range(4500):
            log.event(float(i), "fire" if i % 3 else "reply", n=i)
            if i % 1000 == 999:
                log.commit({"n": i})
    with EventLog.open(tmp_path / "ctl.log") as log:
        everything = list(log.events())
        assert [e.seq for e in everything] == list(range(1, 4501))
        replies = list(log.events(["reply"]))
        assert [e.data["n"] for e in replies] == list(range(0, 4500, 3))
        assert list(log.events([])) == []
        assert list(log.events("reply")) == replies  # one kind, not its letters
        assert log.count("fire") == 3000 and log.count() == 4500


def test_data_may_have_fields_named_kind_and_time(tmp_path: Path) -> None:
    with new_log(tmp_path) as log:
        log.event(3.0, "reply", command_id=7, reply_seq=2, kind="done", time=99.0)
    with EventLog.open(tmp_path / "ctl.log") as log:
        (event,) = log.events()
    assert (event.time, event.kind) == (3.0, "reply")
    assert event.data == {"command_id": 7, "reply_seq": 2, "kind": "done", "time": 99.0}


def test_data_is_captured_when_logged_not_when_committed(tmp_path: Path) -> None:
    marking = {"a": 1}
    with new_log(tmp_path) as log:
        log.event(1.0, "fire", transition="t", marking=marking)
        marking["a"] = 0
        marking["b"] = 1
        log.commit()
    with EventLog.open(tmp_path / "ctl.log") as log:
        assert next(log.events()).data["marking"] == {"a": 1}


def test_non_finite_floats_sets_tuples_and_numpy_become_plain_json(tmp_path: Path) -> None:
    with new_log(tmp_path, meta={"limit": math.inf}) as log:
        log.event(
            1.0,
            "note",
            nan=math.nan,
            up=math.inf,
            down=-math.inf,
            pair=(1, 2),
            resources=frozenset({"heading", "depth"}),
            vector=np.array([1.5, 2.5]),
            count=np.int64(3),
            keys={1: "one"},
        )
        log.commit({"x": math.nan})
    with EventLog.open(tmp_path / "ctl.log") as log:
        data = next(log.events()).data
        assert data == {
            "nan": None,
            "up": "inf",
            "down": "-inf",
            "pair": [1, 2],
            "resources": ["depth", "heading"],
            "vector": [1.5, 2.5],
            "count": 3,
            "keys": {"1": "one"},
        }
        assert log.meta == {"limit": "inf"}
        assert log.checkpoint() == {"x": None}
    # What is stored is strict JSON, readable by any JSON reader.
    db = sqlite3.connect(tmp_path / "ctl.log")
    (text,) = db.execute("SELECT data FROM events").fetchone()
    db.close()
    assert "NaN" not in text and "Infinity" not in text
    json.loads(text, parse_constant=lambda name: pytest.fail(f"non-standard JSON {name}"))


def test_telemetry_nan_pose_reads_back_as_nan_and_nan_estimate_as_none(tmp_path: Path) -> None:
    with new_log(tmp_path) as log:
        log.telemetry(TelemetryRecord(1.0, math.nan, 2.0, 3.0, 4.0, math.nan, None, seq=1))
    with EventLog.open(tmp_path / "ctl.log") as log:
        (got,) = log.samples()
    assert math.isnan(got.x) and (got.y, got.est_x, got.est_y) == (2.0, None, None)


def test_what_json_cannot_hold_is_refused_when_logged_naming_the_field(tmp_path: Path) -> None:
    with new_log(tmp_path) as log:
        with pytest.raises(
            EventLogError, match=r"event 'fire': data\['where'\] is of type PosixPath"
        ):
            log.event(1.0, "fire", where=tmp_path)
        with pytest.raises(
            EventLogError, match=r"checkpoint: state\['f'\] is of type builtin_function"
        ):
            log.commit({"f": len})  # not print: Ray, once started in this process, wraps it
        with pytest.raises(EventLogError, match="finite"):
            log.event(math.nan, "fire")
        with pytest.raises(EventLogError, match="finite"):
            log.event("soon", "fire")  # type: ignore[arg-type]
        with pytest.raises(EventLogError, match="finite"):
            log.telemetry(sample(math.inf))
        with pytest.raises(EventLogError, match="needs a kind"):
            log.event(1.0, "")
        assert log.pending == 0
    with pytest.raises(
        EventLogError, match=r"meta\['x'\] is of type object, which JSON cannot hold"
    ):
        new_log(tmp_path, "other.log", meta={"x": object()})
    assert not (tmp_path / "other.log").exists()


# --- commits -------------------------------------------------------------------------------


def test_nothing_is_written_before_commit_and_close_commits_the_rest(tmp_path: Path) -> None:
    log = new_log(tmp_path)
    log.event(1.0, "fire", transition="a")
    log.commit({"step": 1})
    log.event(2.0, "fire", transition="b")
    log.telemetry(sample(1.0))
    assert log.pending == 2
    assert [e.data["transition"] for e in log.events()] == ["a"]  # committed events only
    assert list(log.samples()) == []
    log.close()
    log.close()  # twice is fine
    with EventLog.open(tmp_path / "ctl.log") as log:
        assert [e.data["transition"] for e in log.events()] == ["a", "b"]
        assert len(list(log.samples())) == 1
        assert log.checkpoint() == {"step": 1}  # close commits no state
        assert log.checkpoint_seq() == 1  # event 2 came after the checkpoint


def test_a_commit_without_anything_new_writes_nothing(tmp_path: Path) -> None:
    with new_log(tmp_path) as log:
        log.commit({"a": 1})
        log.commit()
        assert log.checkpoint() == {"a": 1}
        log.commit({"a": 2})
        assert log.checkpoint() == {"a": 2}


def test_a_failed_commit_writes_nothing_keeps_the_buffer_and_can_be_retried(tmp_path: Path) -> None:
    log = new_log(tmp_path)
    log.event(1.0, "fire", n=0)
    log.commit({"count": 1})
    db = log._db  # white box: SQLite's page limit stands in for a full disk
    assert db is not None
    pages = db.execute("PRAGMA page_count").fetchone()[0]
    db.execute(f"PRAGMA max_page_count = {pages}")
    for i in range(1, 2000):
        log.event(float(i), "fire", n=i, pad="x" * 100)
    with pytest.raises(EventLogError, match="disk is full"):
        log.commit({"count": 2000})
    assert log.count() == 1 and log.checkpoint() == {"count": 1}
    assert log.pending == 1999
    db.execute("PRAGMA max_page_count = 1073741823")
    log.commit({"count": 2000})
    assert log.count() == 2000 and log.checkpoint() == {"count": 2000}
    log.close()


def test_commit_may_run_in_another_thread(tmp_path: Path) -> None:
    with new_log(tmp_path) as log:
        log.event(1.0, "fire")
        worker = threading.Thread(target=log.commit, args=({"done": True},))
        worker.start()
        worker.join()
        assert log.checkpoint() == {"done": True}


CHILD = """
import random, sys
from runtime.eventlog import EventLog, TelemetryRecord
path, seed = sys.argv[1], int(sys.argv[2])
rng = random.Random(seed)
log = EventLog.open(path, writable=True)
state = log.checkpoint() or {"count": 0, "samples": 0, "commits": 0}
count, samples, commits = state["count"], state["samples"], state["commits"]
print("ready", flush=True)
while True:
    for _ in range(rng.randint(1, 400)):
        count += 1
        log.event(float(count), "tick", n=count)
    for _ in range(rng.randint(0, 3)):
        samples += 1
        log.telemetry(TelemetryRecord(float(samples), 1.0, 2.0, 3.0, 4.0, seq=samples))
    commits += 1
    log.commit({"count": count, "samples": samples, "commits": commits})
"""


def run_child(path: Path, *args: str) -> subprocess.Popen[str]:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    child = subprocess.Popen(
        [sys.executable, "-c", CHILD, str(path), *args],
        cwd=REPO,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert child.stdout is not None
    line = child.stdout.readline()
    if line != "ready\n":
        child.kill()
        pytest.fail(f"child did not start: {line!r} {child.communicate()[1]}")
    return child


def assert_consistent(path: Path) -> int:
    """The checkpoint matches exactly the committed ticks and samples; returns the count."""
    with EventLog.open(path) as log:
        state = log.checkpoint()
        assert state is not None
        ticks = [e.data["n"] for e in log.events(["tick"])]
        assert ticks == list(range(1, len(ticks) + 1))
        assert state["count"] == len(ticks)
        assert state["samples"] == len(list(log.samples()))
        assert log.checkpoint_seq() == len(ticks)
        return len(ticks)


@pytest.mark.slow
def test_kill_9_at_random_moments_never_leaves_half_a_commit(tmp_path: Path) -> None:
    path = tmp_path / "ctl.log"
    with new_log(tmp_path) as log:
        log.commit({"count": 0, "samples": 0, "commits": 0})
    rng = random.Random(20260521)
    counts = [0]
    for round_ in range(5):
        child = run_child(path, str(round_))
        # Let it commit a while (tens of commits), then kill it wherever it is.
        time.sleep(rng.uniform(0.05, 0.4))
        child.send_signal(signal.SIGKILL)
        _, err = child.communicate()
        assert child.returncode == -signal.SIGKILL, err
        # Each round resumes from the previous checkpoint and goes on from there.
        counts.append(assert_consistent(path))
    assert counts == sorted(counts) and counts[-1] > 0
    with EventLog.open(path, writable=True) as log:  # a resume after the last kill
        log.event(0.0, "tick", n=counts[-1] + 1)
        log.commit({"count": counts[-1] + 1, "samples": len(list(log.samples())), "commits": 0})
    assert assert_consistent(path) == counts[-1] + 1


# --- one writer ----------------------------------------------------------------------------


def test_a_second_writer_is_refused_while_a_reader_reads_the_live_log(tmp_path: Path) -> None:
    with new_log(tmp_path) as log:
        log.event(1.0, "fire")
        log.commit({"step": 1})
        log.event(2.0, "fire")  # pending: a reader must not see it
        with pytest.raises(
            EventLogError, match=r"open for writing by another process.*only one writer"
        ):
            EventLog.open(tmp_path / "ctl.log", writable=True)
        with EventLog.open(tmp_path / "ctl.log") as reader:
            assert [e.time for e in reader.events()] == [1.0]
            assert reader.checkpoint() == {"step": 1}
            log.commit({"step": 2})  # the reader does not block the writer
            assert [e.time for e in reader.events()] == [1.0, 2.0]
            assert reader.checkpoint() == {"step": 2}
        log.event(3.0, "fire")  # the refusal did not disturb the writer
        log.commit()
    with EventLog.open(tmp_path / "ctl.log") as log:
        assert log.count() == 3


def test_a_reader_holding_a_snapshot_never_blocks_commits_or_close(tmp_path: Path) -> None:
    path = tmp_path / "ctl.log"
    log = new_log(tmp_path)
    log.event(1.0, "fire")
    log.commit({"step": 1})
    reader = sqlite3.connect(path, isolation_level=None)
    reader.execute("BEGIN")
    assert reader.execute("SELECT count(*) FROM events").fetchone() == (1,)
    started = time.monotonic()
    for step in range(2, 20):
        log.event(float(step), "fire")
        log.commit({"step": step})
    log.close()  # cannot switch out of WAL while read: must not wait for the reader
    assert time.monotonic() - started < 1.5
    assert reader.execute("SELECT count(*) FROM events").fetchone() == (1,)  # its snapshot
    reader.execute("COMMIT")
    reader.close()
    with EventLog.open(path) as again:
        assert again.count() == 19 and again.checkpoint() == {"step": 19}


@pytest.mark.slow
def test_a_writer_in_another_process_is_refused_and_a_kill_9_frees_the_log(tmp_path: Path) -> None:
    path = tmp_path / "ctl.log"
    with new_log(tmp_path) as log:
        log.commit({"count": 0, "samples": 0, "commits": 0})
    child = run_child(path, "7")
    try:
        with pytest.raises(EventLogError, match="open for writing by another process"):
            EventLog.open(path, writable=True)
    finally:
        child.send_signal(signal.SIGKILL)
        child.communicate()
    count = assert_consistent(path)  # read-only, straight after the crash
    with EventLog.open(path, writable=True) as log:
        assert log.checkpoint() is not None and log.count("tick") == count


# --- refusals and damaged files ------------------------------------------------------------


def test_an_existing_file_is_never_overwritten(tmp_path: Path) -> None:
    new_log(tmp_path).close()
    with pytest.raises(EventLogError, match="already exists; a log is never overwritten"):
        new_log(tmp_path)
    other = tmp_path / "notes.txt"
    other.write_text("keep me")
    with pytest.raises(EventLogError, match="already exists"):
        EventLog.create(other, role="vehicle", mission="1", meta={})
    assert other.read_text() == "keep me"


def test_creating_where_no_file_can_be_made_says_why(tmp_path: Path) -> None:
    with pytest.raises(EventLogError, match=r"missing/ctl.log: cannot create: No such file"):
        EventLog.create(tmp_path / "missing" / "ctl.log", role="controller", mission="1", meta={})
    (tmp_path / "file").write_text("")
    with pytest.raises(EventLogError, match="cannot create: Not a directory"):
        EventLog.create(tmp_path / "file" / "ctl.log", role="controller", mission="1", meta={})
    with pytest.raises(EventLogError, match="role must be"):
        EventLog.create(tmp_path / "x.log", role="boat", mission="1", meta={})  # type: ignore[arg-type]


def test_a_folder_where_nothing_can_be_written_is_a_clear_error(tmp_path: Path) -> None:
    # /proc refuses new files even to root, unlike a chmod-ed folder.
    with pytest.raises(EventLogError, match=r"^/proc/ctl.log: cannot create"):
        EventLog.create("/proc/ctl.log", role="controller", mission="1", meta={})


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda p: None, "no such event log"),
        (lambda p: p.mkdir(), "not a file"),
        (lambda p: p.write_bytes(b""), "the file is empty"),
        (lambda p: p.write_text("time,kind\n1.0,fire\n" * 50), "not a SQLite database"),
    ],
    ids=["missing", "folder", "empty", "text"],
)
def test_what_is_not_a_log_is_named_as_such(tmp_path: Path, make: object, message: str) -> None:
    path = tmp_path / "x.log"
    make(path)  # type: ignore[operator]
    for writable in (False, True):
        with pytest.raises(EventLogError, match=message) as caught:
            EventLog.open(path, writable=writable)
        assert str(caught.value).startswith(str(path))


def test_another_applications_database_is_not_a_log(tmp_path: Path) -> None:
    db = sqlite3.connect(tmp_path / "other.db")
    db.execute("CREATE TABLE things (x)")
    db.commit()
    db.close()
    with pytest.raises(EventLogError, match="a SQLite database, but not a coral event log"):
        EventLog.open(tmp_path / "other.db")


def test_another_schema_version_is_refused(tmp_path: Path) -> None:
    new_log(tmp_path).close()
    db = sqlite3.connect(tmp_path / "ctl.log")
    db.execute(f"PRAGMA user_version = {SCHEMA_VERSION + 1}")
    db.commit()
    db.close()
    with pytest.raises(
        EventLogError,
        match=f"schema version {SCHEMA_VERSION + 1}; this coral reads versions 1, {SCHEMA_VERSION}",
    ):
        EventLog.open(tmp_path / "ctl.log", writable=True)


@pytest.mark.parametrize("keep", [0.9, 0.5, 0.02])
def test_a_truncated_log_is_reported_damaged(tmp_path: Path, keep: float) -> None:
    with new_log(tmp_path) as log:
        for i in range(3000):
            log.event(float(i), "fire", transition=f"t{i}", marking={"a": i})
    path = tmp_path / "ctl.log"
    size = path.stat().st_size
    with path.open("r+b") as f:
        f.truncate(int(size * keep))
    with pytest.raises(EventLogError, match="damaged"):
        EventLog.open(path)


def test_an_overwritten_page_is_reported_damaged(tmp_path: Path) -> None:
    with new_log(tmp_path) as log:
        for i in range(3000):
            log.event(float(i), "fire", transition=f"t{i}")
    path = tmp_path / "ctl.log"
    with path.open("r+b") as f:
        f.seek(path.stat().st_size // 2)
        f.write(random.Random(1).randbytes(4096))
    with pytest.raises(EventLogError, match="damaged"):
        EventLog.open(path)


def test_closed_and_read_only_logs_refuse_writes(tmp_path: Path) -> None:
    new_log(tmp_path).close()
    with EventLog.open(tmp_path / "ctl.log") as log:
        with pytest.raises(EventLogError, match="read-only"):
            log.event(1.0, "fire")
        with pytest.raises(EventLogError, match="read-only"):
            log.commit({})
    with pytest.raises(EventLogError, match="closed"):
        log.checkpoint()
    assert log.closed and "closed" in repr(log)


def test_a_finished_log_is_one_file(tmp_path: Path) -> None:
    with new_log(tmp_path) as log:
        log.event(1.0, "fire")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ctl.log"]


@pytest.mark.parametrize("umask", [0o022, 0o000])
def test_the_log_and_its_wal_files_are_readable_by_their_owner_only(
    tmp_path: Path, umask: int
) -> None:
    old = os.umask(umask)
    try:
        with new_log(tmp_path) as log:
            log.event(1.0, "fire")
            log.commit({"a": 1})
            files = sorted(p.name for p in tmp_path.iterdir())
            assert files == ["ctl.log", "ctl.log-shm", "ctl.log-wal"]
            modes = {p.name: p.stat().st_mode & 0o777 for p in tmp_path.iterdir()}
            assert modes == dict.fromkeys(files, 0o600)
    finally:
        os.umask(old)
    assert (tmp_path / "ctl.log").stat().st_mode & 0o777 == 0o600


def test_the_documented_schema_is_the_one_written(tmp_path: Path) -> None:
    doc = (REPO / "docs" / "eventlog.md").read_text()
    tables_section = doc.split("### Tables", 1)[1].split("### JSON", 1)[0]
    new_log(tmp_path).close()
    db = sqlite3.connect(tmp_path / "ctl.log")
    tables = [row[0] for row in db.execute("SELECT name FROM sqlite_master WHERE type = 'table'")]
    assert sorted(tables) == ["checkpoint", "commits", "events", "header", "telemetry"]
    for table in tables:
        assert f"`{table}`" in tables_section
        for column in (row[1] for row in db.execute(f"PRAGMA table_info({table})")):
            assert f"`{column}`" in tables_section, (table, column)
    db.close()
    assert f"`{APPLICATION_ID:#X}`".replace("0X", "0x") in doc
    assert f"`{SCHEMA_VERSION}` (`SCHEMA_VERSION`)" in doc


def test_relaxed_durability_still_commits_and_refuses_read_only_logs(tmp_path: Path) -> None:
    path = tmp_path / "fuzz.sqlite"
    with EventLog.create(path, role="controller", mission="m", meta={}) as log:
        log.relax_durability()
        assert log._connection().execute("PRAGMA synchronous").fetchone()[0] == 0
        log.event(1.0, "tick")
        log.commit({"count": 1})
    with EventLog.open(path) as log:
        assert log.checkpoint() == {"count": 1}
        assert log.count("tick") == 1
        with pytest.raises(EventLogError, match="read-only"):
            log.relax_durability()


# --- a reader given an edited log: a message naming the log and the row, never a traceback
# (bench/redteam.py found JSONDecodeError, RecursionError and TypeError here) ------------


@pytest.mark.parametrize(
    ("column", "value", "says"),
    [
        ("data", "{not json", "the data of event 1 is not JSON"),
        ("data", "[" * 100_000 + "]" * 100_000, "the data of event 1 is not JSON"),
        ("data", "[1, 2]", "the data of event 1 is not a JSON object"),
        ("time", "noon", "event 1 holds values of the wrong type"),
        ("kind", b"\x00", "event 1 holds values of the wrong type"),
    ],
    ids=["not-json", "deep", "not-object", "text-time", "blob-kind"],
)
def test_an_edited_event_row_is_refused_by_name_in_readers_and_the_timeline(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], column: str, value: object, says: str
) -> None:
    from runtime.cli import main

    path = tmp_path / "controller.sqlite"
    with EventLog.create(path, role="controller", mission="m", meta={}) as log:
        log.event(1.0, "note", text="hello")
        log.commit()
    with sqlite3.connect(path) as db:
        db.execute(f"UPDATE events SET {column} = ? WHERE seq = 1", (value,))
    with EventLog.open(path) as log, pytest.raises(EventLogError, match=says) as caught:
        list(log.events())
    assert str(path) in str(caught.value)
    assert main(["timeline", str(path), "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert says in err and str(path) in err and "Traceback" not in err


def test_an_edited_telemetry_row_is_refused_by_name(tmp_path: Path) -> None:
    path = tmp_path / "controller.sqlite"
    with EventLog.create(path, role="controller", mission="m", meta={}) as log:
        log.telemetry(TelemetryRecord(1.0, 0.0, 0.0, 1.0, 90.0, seq=1))
        log.commit()
    with sqlite3.connect(path) as db:
        db.execute("UPDATE telemetry SET x = 'north' WHERE n = 1")
    with EventLog.open(path) as log, pytest.raises(EventLogError, match="telemetry row 1"):
        list(log.samples())


def test_text_that_is_not_utf8_is_refused_as_damage_by_name(tmp_path: Path) -> None:
    """bench/redteam.py: a flipped byte in a text column raised UnicodeDecodeError out of
    the log's first check (``PRAGMA quick_check`` reports the bad row's text)."""
    path = tmp_path / "controller.sqlite"
    with EventLog.create(path, role="controller", mission="m", meta={}) as log:
        log.event(1.0, "note", text="hello")
        log.commit()
    with sqlite3.connect(path) as db:
        db.execute("UPDATE header SET mission = CAST(X'61E1' AS TEXT)")
    with pytest.raises(EventLogError, match="not UTF-8") as caught, EventLog.open(path) as log:
        list(log.events())
    assert str(path) in str(caught.value)


def test_a_damaged_page_whose_sqlite_message_is_not_utf8_is_refused_by_name(
    tmp_path: Path,
) -> None:
    """A real damaged log (tests/data/README.md): SQLite's integrity message about it is
    not UTF-8, and decoding it used to raise out of the log's first check."""
    import shutil

    path = tmp_path / "vehicle.sqlite"
    shutil.copy(REPO / "tests" / "data" / "eventlog" / "page_with_bad_utf8.sqlite", path)
    with pytest.raises(EventLogError, match="not UTF-8") as caught:
        EventLog.open(path)
    assert str(caught.value).startswith(f"{path}: ")
