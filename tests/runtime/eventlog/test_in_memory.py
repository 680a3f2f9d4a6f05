"""Logs held in memory (``coral-run fuzz``): the same log, written out only when wanted."""

from __future__ import annotations

import stat
from pathlib import Path

import pytest

from runtime.eventlog import EventLog, EventLogError
from runtime.telemetry import TelemetryRecord


def _memory_log() -> EventLog:
    return EventLog.create_in_memory(
        "<test run>",
        role="controller",
        mission="pool",
        meta={"fuzz_seed": 7},
        net_json='{"name": "pool"}',
        net_digest="sha256:ab",
    )


def _fill(log: EventLog) -> None:
    log.event(1.0, "mission-start", marking={"start": 1})
    log.telemetry(TelemetryRecord(1.5, 2.0, 3.0, 0.5, 90.0, 2.1, 2.9, seq=1))
    log.commit({"marking": {"start": 1}})
    log.event(2.0, "fire", transition="go")


def test_a_memory_log_reads_back_like_a_file_log_and_leaves_no_file(tmp_path: Path) -> None:
    before = set(tmp_path.iterdir())
    log = _memory_log()
    _fill(log)
    assert [e.kind for e in log.events()] == ["mission-start"]  # committed only
    log.commit()
    assert [(e.time, e.kind, e.data) for e in log.events()] == [
        (1.0, "mission-start", {"marking": {"start": 1}}),
        (2.0, "fire", {"transition": "go"}),
    ]
    assert [s.vehicle_time for s in log.samples()] == [1.5]
    assert log.checkpoint() == {"marking": {"start": 1}}
    assert (log.meta, log.mission, log.authenticated) == ({"fuzz_seed": 7}, "pool", False)
    log.close()
    assert set(tmp_path.iterdir()) == before


def test_a_saved_copy_is_an_ordinary_log_file_for_its_owner_only(tmp_path: Path) -> None:
    log = _memory_log()
    _fill(log)
    log.commit()
    copy = tmp_path / "seed-7.sqlite"
    log.save_copy(copy)
    log.close()
    assert stat.S_IMODE(copy.stat().st_mode) == 0o600
    with EventLog.open(copy) as saved:
        assert [e.kind for e in saved.events()] == ["mission-start", "fire"]
        assert [s.x for s in saved.samples()] == [2.0]
        assert (saved.role, saved.net_digest, saved.meta) == (
            "controller",
            "sha256:ab",
            {"fuzz_seed": 7},
        )
    with EventLog.open(copy, writable=True) as resumed:  # a copy is a complete log
        resumed.event(3.0, "note")
        resumed.commit()


def test_a_copy_never_overwrites_a_file(tmp_path: Path) -> None:
    existing = tmp_path / "seed-7.sqlite"
    existing.write_bytes(b"evidence")
    with _memory_log() as log, pytest.raises(EventLogError, match="already exists"):
        log.save_copy(existing)
    assert existing.read_bytes() == b"evidence"


def test_a_copy_into_a_missing_folder_is_a_clear_error(tmp_path: Path) -> None:
    with _memory_log() as log, pytest.raises(EventLogError, match="cannot create"):
        log.save_copy(tmp_path / "no such folder" / "x.sqlite")


def test_bad_meta_is_refused_by_a_memory_log_too() -> None:
    with pytest.raises(EventLogError, match="<bad>"):
        EventLog.create_in_memory("<bad>", role="controller", mission="m", meta={"x": object()})
