"""The event log's MAC chain: every edit an attacker can make with sqlite3 is refused.

Each edit below is made to the SQLite file directly, as the red team did. Each test also
opens the edited log *without* the key and sees it accepted: so it is the chain that
catches the edit, and the test fails if the check is disabled.
"""

from __future__ import annotations

import hashlib
import hmac
import shutil
import sqlite3
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from runtime.cli import main as run_main
from runtime.eventlog import EventLog, EventLogError, TelemetryRecord, log_key
from runtime.eventlog.auth import encode, key_id
from runtime.run import RunConfig, open_for_resume
from runtime.timeline import merge_logs
from tests.runtime.helpers import POOL_MISSION

PSK = bytes(range(32))
KEY = log_key(PSK)
OTHER_KEY = log_key(bytes(range(1, 33)))

Edit = Callable[[sqlite3.Connection], object]


def write_log(path: Path, key: bytes | None = KEY, commits: int = 4) -> None:
    """A controller log of ``commits`` commits: events, samples and a state each."""
    with EventLog.create(
        path,
        role="controller",
        mission="pool",
        meta={"seed": 1},
        net_json='{"places": ["a"]}',
        net_digest="sha256:00",
        mac_key=key,
    ) as log:
        for n in range(1, commits + 1):
            for i in range(3):
                log.event(10.0 * n + i, "fire", transition=f"t{n}.{i}", marking={"a": n})
            log.telemetry(TelemetryRecord(float(n), 1.0, -0.0, 3.0, 4.0, seq=n))
            log.commit({"step": n, "marking": {"a": n}})
        log.event(99.0, "mission-end", end="final")  # committed by close, without a state


def edited(tmp_path: Path, edit: Edit, key: bytes | None = KEY) -> Path:
    path = tmp_path / "ctl.sqlite"
    write_log(path, key)
    db = sqlite3.connect(path)
    with db:
        edit(db)
    db.close()
    return path


def refused(path: Path, match: str, key: bytes = KEY) -> str:
    """The edited log opens without a key (the edit is well formed), and is refused with."""
    with EventLog.open(path) as log:
        log.checkpoint()
        list(log.events())
    for writable in (False, True):
        with pytest.raises(EventLogError, match=match) as caught:
            EventLog.open(path, writable=writable, mac_key=key)
        assert str(caught.value).startswith(f"{path}: ")
    return str(caught.value)


# --- the honest log ------------------------------------------------------------------------


def test_an_honest_log_verifies_and_a_resumed_writer_extends_its_chain(tmp_path: Path) -> None:
    path = tmp_path / "ctl.sqlite"
    write_log(path)
    with EventLog.open(path, mac_key=KEY) as log:
        assert log.authenticated and log.schema_version == 2
        assert log.checkpoint() == {"step": 4, "marking": {"a": 4}}
    with EventLog.open(path, writable=True, mac_key=KEY) as log:
        log.event(100.0, "resume")
        log.telemetry(TelemetryRecord(9.0, 1.0, 2.0, 3.0, 4.0, seq=1))
        log.commit({"step": 5})
    with EventLog.open(path) as log:
        log.verify(KEY)
        assert log.count() == 14 and log.checkpoint() == {"step": 5}


def test_a_failed_commit_leaves_the_chain_where_it_was(tmp_path: Path) -> None:
    path = tmp_path / "ctl.sqlite"
    log = EventLog.create(path, role="controller", mission="m", meta={}, mac_key=KEY)
    log.commit({"count": 0})
    db = log._db  # white box: SQLite's page limit stands in for a full disk
    assert db is not None
    db.execute(f"PRAGMA max_page_count = {db.execute('PRAGMA page_count').fetchone()[0]}")
    for i in range(2000):
        log.event(float(i), "fire", pad="x" * 100)
    with pytest.raises(EventLogError, match="disk is full"):
        log.commit({"count": 2000})
    db.execute("PRAGMA max_page_count = 1073741823")
    log.commit({"count": 2000})
    log.close()
    with EventLog.open(path, mac_key=KEY) as again:
        assert again.count() == 2000


def test_the_log_key_is_derived_with_its_own_label() -> None:
    assert len(KEY) == 32 and KEY != PSK and log_key(PSK) == KEY
    assert hmac.new(PSK, b"coral/1 event log key", hashlib.sha256).digest() == KEY
    assert KEY != OTHER_KEY
    assert key_id(KEY) != key_id(OTHER_KEY) and len(key_id(KEY)) == 16
    with pytest.raises(ValueError, match="empty"):
        log_key(b"")


def test_the_row_encoding_tells_types_and_fields_apart() -> None:
    assert encode([1]) != encode([1.0]) != encode(["1"]) != encode([b"1"]) != encode([None])
    assert encode(["ab", "c"]) != encode(["a", "bc"])
    assert encode([-0.0]) == encode([0.0])  # SQLite may give -0.0 back as 0.0
    assert encode([True]) == encode([1])


# --- edits of rows -------------------------------------------------------------------------


def _swap_events(db: sqlite3.Connection) -> None:
    a, b = (db.execute("SELECT data FROM events WHERE seq = ?", (s,)).fetchone()[0] for s in (5, 6))
    db.execute("UPDATE events SET data = ? WHERE seq = 5", (b,))
    db.execute("UPDATE events SET data = ? WHERE seq = 6", (a,))


@pytest.mark.parametrize(
    ("edit", "said"),
    [
        (lambda db: db.execute("UPDATE events SET data = '{}' WHERE seq = 5"), "commit 2 "),
        (lambda db: db.execute("UPDATE events SET time = 0.5 WHERE seq = 1"), "commit 1 "),
        (lambda db: db.execute("UPDATE events SET kind = 'note' WHERE seq = 9"), "commit 3 "),
        (_swap_events, "commit 2 "),
        (lambda db: db.execute("DELETE FROM events WHERE seq = 5"), "event 5 .*missing"),
        (lambda db: db.execute("DELETE FROM events WHERE seq = 13"), "event 13 .*missing"),
        (
            lambda db: db.execute("UPDATE events SET seq = seq + 100 WHERE seq = 12"),
            "event 12 .*missing",
        ),
        (
            lambda db: db.execute(
                "INSERT INTO events (seq, time, kind, data) VALUES (14, 1.0, 'fire', '{}')"
            ),
            "event 14 is not covered by any commit",
        ),
        (lambda db: db.execute("UPDATE telemetry SET x = 2.0 WHERE n = 2"), "commit 2 "),
        (lambda db: db.execute("DELETE FROM telemetry WHERE n = 3"), "sample 3 .*missing"),
        (
            lambda db: db.execute(
                "INSERT INTO telemetry (n, time, seq, x, y, z, psi) VALUES (5, 1, 1, 1, 1, 1, 1)"
            ),
            "sample 5 is not covered",
        ),
        (lambda db: db.execute("DELETE FROM commits WHERE n = 2"), "commit record 2 is missing"),
        (lambda db: db.execute("UPDATE commits SET event_seq = 5 WHERE n = 2"), "commit 2 "),
        (lambda db: db.execute("UPDATE commits SET mac = NULL WHERE n = 3"), "commit 3 "),
    ],
    ids=[
        "event-data",
        "event-time",
        "event-kind",
        "events-reordered",
        "event-deleted",
        "last-event-deleted",
        "event-renumbered",
        "event-inserted",
        "sample-changed",
        "sample-deleted",
        "sample-inserted",
        "commit-deleted",
        "commit-moved",
        "commit-mac-removed",
    ],
)
def test_an_edited_row_is_refused_naming_where(tmp_path: Path, edit: Edit, said: str) -> None:
    refused(edited(tmp_path, edit), said)


def test_a_row_given_another_type_is_refused_by_the_chain_and_by_readers(tmp_path: Path) -> None:
    """The same bytes as a BLOB: the chain's encoding tags each value's type, so the MAC
    no longer matches; a reader without the key refuses the row too (no writer makes it)."""
    path = edited(
        tmp_path, lambda db: db.execute("UPDATE events SET data = CAST(data AS BLOB) WHERE seq = 1")
    )
    with EventLog.open(path) as log, pytest.raises(EventLogError, match="event 1 holds values"):
        list(log.events())
    for writable in (False, True):
        with pytest.raises(EventLogError, match="commit 1 "):
            EventLog.open(path, writable=writable, mac_key=KEY)


@pytest.mark.parametrize("column", ["mission", "meta", "net_json", "net_digest", "role", "created"])
def test_an_edited_header_is_refused(tmp_path: Path, column: str) -> None:
    value = {"role": "vehicle", "meta": '{"seed": 2}'}.get(column, "edited")
    path = edited(tmp_path, lambda db: db.execute(f"UPDATE header SET {column} = ?", (value,)))
    refused(path, r"the header \(mission, meta, net_json, net_digest, role or created\)")


def test_a_refused_log_is_left_exactly_as_it_was(tmp_path: Path) -> None:
    path = edited(tmp_path, lambda db: db.execute("UPDATE events SET data = '{}' WHERE seq = 2"))
    before = path.read_bytes()
    with pytest.raises(EventLogError, match="commit 1 "):
        EventLog.open(path, writable=True, mac_key=KEY)
    assert path.read_bytes() == before  # evidence: not even switched to WAL
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ctl.sqlite"]


# --- the checkpoint ------------------------------------------------------------------------


def test_a_forged_checkpoint_is_refused(tmp_path: Path) -> None:
    forged = '{"step": 4, "marking": {"mission_complete": 1}}'
    path = edited(tmp_path, lambda db: db.execute("UPDATE checkpoint SET state = ?", (forged,)))
    refused(path, "checkpoint's state is not the one commit 4 wrote")


def test_an_older_genuine_checkpoint_put_back_is_refused(tmp_path: Path) -> None:
    """The attacker kept a copy of the checkpoint row of commit 2 and puts it back."""
    path = tmp_path / "early.sqlite"
    write_log(path, commits=2)
    db = sqlite3.connect(path)
    early = db.execute("SELECT commits, event_seq, state FROM checkpoint").fetchone()
    db.close()
    replayed = edited(
        tmp_path,
        lambda db: db.execute("UPDATE checkpoint SET commits = ?, event_seq = ?, state = ?", early),
    )
    refused(replayed, "the state of commit 2, not that of commit 4.*put back")


@pytest.mark.parametrize(
    ("edit", "said"),
    [
        (lambda db: db.execute("DELETE FROM checkpoint"), "checkpoint row is missing"),
        (lambda db: db.execute("UPDATE checkpoint SET commits = 9"), "commits or event_seq"),
        (lambda db: db.execute("UPDATE checkpoint SET event_seq = 1"), "commits or event_seq"),
    ],
    ids=["deleted", "commits", "event-seq"],
)
def test_an_edited_checkpoint_row_is_refused(tmp_path: Path, edit: Edit, said: str) -> None:
    refused(edited(tmp_path, edit), said)


def test_a_checkpoint_in_a_log_that_never_committed_a_state_is_forged(tmp_path: Path) -> None:
    path = tmp_path / "ctl.sqlite"
    with EventLog.create(path, role="controller", mission="m", meta={}, mac_key=KEY) as log:
        log.event(1.0, "fire")
    db = sqlite3.connect(path)
    with db:
        db.execute("INSERT INTO checkpoint VALUES (1, 1, 1, '{\"engine\": {}}')")
    db.close()
    refused(path, "checkpoint row was forged")


# --- keys and unauthenticated logs ---------------------------------------------------------


def test_a_log_of_another_key_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "ctl.sqlite"
    write_log(path, OTHER_KEY)
    refused(path, "written with another key, or edited")


def test_removing_the_mac_makes_it_unauthenticated_which_a_key_refuses(tmp_path: Path) -> None:
    path = edited(tmp_path, lambda db: db.execute("UPDATE header SET key_id = NULL, mac = NULL"))
    refused(path, "not authenticated")
    with EventLog.open(path) as log:
        assert not log.authenticated


def test_a_log_written_without_a_key_reads_but_does_not_verify(tmp_path: Path) -> None:
    path = tmp_path / "ctl.sqlite"
    write_log(path, key=None)
    with EventLog.open(path) as log:
        assert not log.authenticated and log.count() == 13
        with pytest.raises(EventLogError, match="not authenticated"):
            log.verify(KEY)
    with EventLog.open(path, writable=True) as log:  # appending stays unauthenticated
        log.commit({"step": 5})
    with EventLog.open(path) as log:
        assert log.checkpoint() == {"step": 5}


def test_appending_to_an_authenticated_log_needs_its_key(tmp_path: Path) -> None:
    path = tmp_path / "ctl.sqlite"
    write_log(path)
    with pytest.raises(EventLogError, match="appending to it needs its key"):
        EventLog.open(path, writable=True)
    with pytest.raises(EventLogError, match="at least 16 bytes"):
        EventLog.open(path, mac_key=b"short")
    with EventLog.open(path, writable=True, mac_key=KEY):  # the refusal released the lock
        pass


V1_SCHEMA = """
CREATE TABLE header (id INTEGER PRIMARY KEY CHECK (id = 1), schema_version INTEGER NOT NULL,
    role TEXT NOT NULL, mission TEXT NOT NULL, created TEXT NOT NULL, meta TEXT NOT NULL,
    net_json TEXT, net_digest TEXT);
CREATE TABLE events (seq INTEGER PRIMARY KEY, time REAL NOT NULL, kind TEXT NOT NULL,
    data TEXT NOT NULL);
CREATE TABLE telemetry (n INTEGER PRIMARY KEY, time REAL NOT NULL, seq INTEGER NOT NULL,
    x REAL, y REAL, z REAL, psi REAL, est_x REAL, est_y REAL);
CREATE TABLE checkpoint (id INTEGER PRIMARY KEY CHECK (id = 1), commits INTEGER NOT NULL,
    event_seq INTEGER NOT NULL, state TEXT NOT NULL);
PRAGMA application_id = 1129271884;
PRAGMA user_version = 1;
INSERT INTO header VALUES (1, 1, 'controller', 'pool', '2026-05-21T07:00:00Z', '{}', NULL, NULL);
INSERT INTO events VALUES (1, 1.0, 'fire', '{"transition": "t"}');
INSERT INTO checkpoint VALUES (1, 1, 1, '{"step": 1}');
"""


def test_a_version_1_log_reads_as_unauthenticated(tmp_path: Path) -> None:
    path = tmp_path / "v1.sqlite"
    db = sqlite3.connect(path)
    db.executescript(V1_SCHEMA)
    db.close()
    with EventLog.open(path) as log:
        assert (log.schema_version, log.authenticated) == (1, False)
        assert [e.kind for e in log.events()] == ["fire"] and log.checkpoint() == {"step": 1}
    with pytest.raises(EventLogError, match=r"not authenticated \(schema version 1"):
        EventLog.open(path, mac_key=KEY)
    with EventLog.open(path, writable=True) as log:  # a simulated resume may still append
        log.event(2.0, "resume")
        log.commit({"step": 2})
    with EventLog.open(path) as log:
        assert log.count() == 2 and log.checkpoint() == {"step": 2}


# --- what the chain cannot see -------------------------------------------------------------


def test_a_whole_tail_cut_back_to_an_earlier_commit_still_verifies(tmp_path: Path) -> None:
    """Documented limit (docs/eventlog.md): the log alone cannot tell it was cut back to
    a state its writer had committed; the controller's log-behind check does, from the
    vehicle's reply numbers."""
    path = tmp_path / "ctl.sqlite"
    write_log(path, commits=2)
    db = sqlite3.connect(path)
    counts = db.execute(
        "SELECT (SELECT max(n) FROM commits), (SELECT max(seq) FROM events), "
        "(SELECT max(n) FROM telemetry)"
    ).fetchone()
    checkpoint = db.execute("SELECT commits, event_seq, state FROM checkpoint").fetchone()
    db.close()
    with EventLog.open(path, writable=True, mac_key=KEY) as log:  # the run goes on
        log.event(200.0, "fire")
        log.telemetry(TelemetryRecord(9.0, 1.0, 2.0, 3.0, 4.0, seq=9))
        log.commit({"step": 3})
    db = sqlite3.connect(path)
    with db:
        db.execute("DELETE FROM commits WHERE n > ?", (counts[0],))
        db.execute("DELETE FROM events WHERE seq > ?", (counts[1],))
        db.execute("DELETE FROM telemetry WHERE n > ?", (counts[2],))
        db.execute("UPDATE checkpoint SET commits = ?, event_seq = ?, state = ?", checkpoint)
    db.close()
    with EventLog.open(path, mac_key=KEY) as log:
        assert log.checkpoint() == {"step": 2, "marking": {"a": 2}}


# --- any single change, found by hypothesis ------------------------------------------------

CELLS = [
    ("events", "seq", ["time", "kind", "data"], 13),
    ("telemetry", "n", ["time", "seq", "x", "y", "z", "psi", "est_x"], 4),
    ("commits", "n", ["event_seq", "sample_n", "state_sha", "mac"], 5),
    ("header", "id", ["mission", "created", "meta", "net_json", "net_digest"], 1),
    ("checkpoint", "id", ["commits", "event_seq", "state"], 1),
]


@pytest.fixture(scope="module")
def honest(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("honest") / "ctl.sqlite"
    write_log(path)
    return path


@settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    where=st.sampled_from(CELLS),
    data=st.data(),
    value=st.one_of(st.integers(-3, 3), st.floats(allow_nan=False), st.text(max_size=5), st.none()),
)
def test_any_single_change_is_refused(
    honest: Path,
    tmp_path: Path,
    where: tuple[str, str, list[str], int],
    data: st.DataObject,
    value: object,
) -> None:
    table, key_column, columns, rows = where
    column = data.draw(st.sampled_from(columns))
    row = data.draw(st.integers(1, rows))
    path = tmp_path / f"edit-{table}-{column}-{row}.sqlite"
    shutil.copy(honest, path)
    db = sqlite3.connect(path)
    try:
        with db:
            before = db.execute(
                f"SELECT {column} FROM {table} WHERE {key_column} = ?", (row,)
            ).fetchone()[0]
            db.execute(f"UPDATE {table} SET {column} = ? WHERE {key_column} = ?", (value, row))
            after = db.execute(
                f"SELECT {column} FROM {table} WHERE {key_column} = ?", (row,)
            ).fetchone()[0]
    except sqlite3.IntegrityError:
        return  # a NOT NULL column: SQLite itself refused the edit
    finally:
        db.close()
    if encode([before]) == encode([after]):
        return  # not a change (the same value, or one SQLite stored as the same)
    with pytest.raises(EventLogError):
        EventLog.open(path, mac_key=KEY)


# --- live readers --------------------------------------------------------------------------


def test_a_live_log_verifies_and_merges_while_its_writer_appends(tmp_path: Path) -> None:
    path = tmp_path / "ctl.sqlite"
    writer = EventLog.create(path, role="controller", mission="pool", meta={}, mac_key=KEY)
    try:
        writer.event(1.0, "handshake", offset=0.5, delay=0.1, resumed=False)
        writer.event(2.0, "command-sent", command_id=1, transition="t", name="DEPTH", params={})
        writer.commit({"step": 1})
        writer.event(3.0, "reply", command_id=1, reply_seq=1, kind="done")  # pending
        with EventLog.open(path, mac_key=KEY) as reader:
            assert reader.count() == 2
            writer.commit({"step": 2})
            reader.verify(KEY)  # what was committed since verifies too
            assert reader.count() == 3
        timeline = merge_logs([path])
        assert len(timeline.events) == 3
        with pytest.raises(EventLogError, match="open for writing by another process"):
            EventLog.open(path, writable=True, mac_key=KEY)
    finally:
        writer.close()


# --- coral-run --resume: the red team's attack ---------------------------------------------


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, Path]:
    """The pool mission in virtual time with a key file, stopped by a time limit at 60 s
    and, in another folder, at 100 s: the same run (same seed), so the first one's
    checkpoint is a genuine earlier state of the second."""
    tmp = tmp_path_factory.mktemp("runs")
    key = tmp / "psk.hex"
    key.write_text(PSK.hex())
    key.chmod(0o600)
    for name, limit in (("early", "60"), ("late", "100")):
        code = run_main(
            [
                str(POOL_MISSION),
                "--verify",
                "--certificate",
                str(tmp / "cert.json"),
                "--key-file",
                str(key),
                "--out",
                str(tmp / name),
                "--time-limit",
                limit,
                "--no-plots",
                "-q",
            ]
        )
        assert code == 1  # the time limit
        (tmp / name / "vehicle.sqlite").unlink()  # a resumed simulator starts a new one
    return key, tmp / "early" / "controller.sqlite", tmp / "late" / "controller.sqlite"


def _resume(log: Path, key: Path | None, capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    capsys.readouterr()
    args = ["--resume", str(log), "--verify", "--certificate", str(log.parent.parent / "c.json")]
    code = run_main([*args, *(["--key-file", str(key)] if key else []), "--no-plots", "-q"])
    out = capsys.readouterr()
    return code, out.out + out.err


def _copy(log: Path, tmp_path: Path) -> Path:
    (tmp_path / "run").mkdir()
    return Path(shutil.copy(log, tmp_path / "run" / "controller.sqlite"))


@pytest.mark.slow
def test_resume_refuses_an_earlier_checkpoint_put_back(
    runs: tuple[Path, Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    key, early, late = runs
    db = sqlite3.connect(early)
    row = db.execute("SELECT commits, event_seq, state FROM checkpoint").fetchone()
    db.close()
    log = _copy(late, tmp_path)
    db = sqlite3.connect(log)
    with db:
        db.execute("UPDATE checkpoint SET commits = ?, event_seq = ?, state = ?", row)
    db.close()
    code, said = _resume(log, key, capsys)
    assert code == 2 and "Traceback" not in said
    assert f"{log}: the checkpoint is the state of commit" in said and "put back" in said


def test_resume_refuses_mission_complete_written_in(
    runs: tuple[Path, Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    key, _, late = runs
    log = _copy(late, tmp_path)
    db = sqlite3.connect(log)
    with db:
        db.execute(
            "UPDATE checkpoint SET state = json_set(state, '$.engine.marking', "
            "json('{\"mission_complete\": 1}'), '$.engine.in_flight', json('[]'))"
        )
    db.close()
    code, said = _resume(log, key, capsys)
    assert code == 2 and f"{log}: the checkpoint's state is not the one commit" in said


def test_resume_refuses_another_key_and_an_unauthenticated_log(
    runs: tuple[Path, Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    key, _, late = runs
    other = tmp_path / "other.hex"
    other.write_text(bytes(range(1, 33)).hex())
    other.chmod(0o600)
    log = _copy(late, tmp_path)
    code, said = _resume(log, other, capsys)
    assert code == 2 and "written with another key, or edited" in said
    code, said = _resume(log, None, capsys)  # a simulated run on an ephemeral key
    assert code == 2 and "resume it with that key (--key-file FILE)" in said
    db = sqlite3.connect(log)
    with db:
        db.execute("UPDATE header SET key_id = NULL, mac = NULL")
    db.close()
    code, said = _resume(log, key, capsys)
    assert code == 2 and "not authenticated" in said


def test_resume_of_the_honest_log_gets_past_the_check(
    runs: tuple[Path, Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The control: the same log unedited is resumed (a fresh simulator does not know the
    mission, so the run ends, but as a run: exit 1, not bad input)."""
    key, _, late = runs
    code, said = _resume(_copy(late, tmp_path), key, capsys)
    assert code == 1 and "mission ended" in said


def test_an_unauthenticated_log_resumes_only_against_a_simulator_with_a_warning(
    runs: tuple[Path, Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    key, _, late = runs
    log = _copy(late, tmp_path)
    db = sqlite3.connect(log)
    with db:
        db.execute("UPDATE header SET key_id = NULL, mac = NULL")  # as if written without
    db.close()
    lines: list[str] = []
    config = RunConfig(out_dir=log.parent, psk=PSK, console=lines.append, log_key_ephemeral=True)
    open_for_resume(log, config).close()
    assert len(lines) == 1 and "warning" in lines[0] and "not authenticated" in lines[0]
    with pytest.raises(EventLogError, match="a real vehicle is resumed only"):
        open_for_resume(log, replace(config, vehicle=("127.0.0.1", 9)))
    capsys.readouterr()
    vehicle = ["--vehicle", "127.0.0.1:9", "--key-file", str(key)]
    # With --vehicle the key is real: refused before any connection is tried.
    code = run_main(
        ["--resume", str(log), *vehicle, "--verify", "--certificate", str(tmp_path / "c.json")]
    )
    assert code == 2 and "not authenticated" in capsys.readouterr().err


# --- the schema itself: the chain authenticates rows, SQLite reads through the file's schema


def _view_showing_a_forged_checkpoint_once_in_wal(db: sqlite3.Connection) -> None:
    """The reviewer's attack: the genuine checkpoint while the log is verified (rollback
    journal), a forged one once the writer has switched it to WAL."""
    forged = '{"engine": {}, "mission_id": 1, "consumed": 99}'
    db.execute("ALTER TABLE checkpoint RENAME TO checkpoint_real")
    db.execute(
        "CREATE VIEW checkpoint AS SELECT id, commits, event_seq, CASE WHEN "
        "(SELECT journal_mode FROM pragma_journal_mode) = 'wal' "
        f"THEN '{forged}' ELSE state END AS state FROM checkpoint_real"
    )


@pytest.mark.parametrize(
    "edit",
    [
        _view_showing_a_forged_checkpoint_once_in_wal,
        lambda db: db.execute(
            "CREATE TRIGGER t AFTER INSERT ON events BEGIN DELETE FROM events; END"
        ),
        lambda db: db.execute("CREATE INDEX extra ON telemetry (x)"),
        lambda db: db.execute("CREATE TABLE notes (text TEXT)"),
    ],
    ids=["view", "trigger", "index", "table"],
)
def test_a_log_whose_schema_was_edited_is_refused_before_any_row_is_read(
    tmp_path: Path, edit: Edit
) -> None:
    path = edited(tmp_path, edit)
    for writable, key in ((False, None), (False, KEY), (True, KEY)):
        with pytest.raises(EventLogError, match="tables are not the ones coral writes"):
            EventLog.open(path, writable=writable, mac_key=key)
