"""`EventLog.add_listener`: every row as a reader gets it back once committed, seq included,
removable, and a listener that raises is dropped without breaking the log."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from runtime.eventlog import Event, EventLog, TelemetryRecord


def _create(path: Path) -> EventLog:
    return EventLog.create(path, role="controller", mission="m", meta={})


def _same_sample(a: TelemetryRecord, b: TelemetryRecord) -> bool:
    def same(x: float | None, y: float | None) -> bool:
        if x is None or y is None:
            return x is y
        return (math.isnan(x) and math.isnan(y)) or x == y

    fields = [f.name for f in dataclasses.fields(TelemetryRecord)]
    return all(same(getattr(a, f), getattr(b, f)) for f in fields)


def test_the_listener_sees_each_row_as_it_is_stored(tmp_path: Path) -> None:
    seen: list[Event | TelemetryRecord] = []
    with _create(tmp_path / "log.sqlite") as log:
        log.add_listener(seen.append)
        log.event(0.5, "fire", transition="t", pair=(1, 2), bad=math.nan, big=math.inf)
        log.telemetry(TelemetryRecord(1.0, 1.0, math.nan, 3.0, 4.0, math.nan, 2.5, seq=7))
        log.commit({"s": 1})
        log.event(2.0, "reply", kind="done")
    assert seen[0] == Event(
        1, 0.5, "fire", {"transition": "t", "pair": [1, 2], "bad": None, "big": "inf"}
    )
    assert seen[2] == Event(2, 2.0, "reply", {"kind": "done"})
    with EventLog.open(tmp_path / "log.sqlite") as log:
        assert list(log.events()) == [seen[0], seen[2]]
        [stored] = list(log.samples())
    sample = seen[1]
    assert isinstance(sample, TelemetryRecord) and _same_sample(sample, stored)


def test_a_removed_listener_is_not_called(tmp_path: Path) -> None:
    seen: list[object] = []
    with _create(tmp_path / "log.sqlite") as log:
        remove = log.add_listener(seen.append)
        log.event(0.0, "a")
        remove()
        remove()  # twice is harmless
        log.event(1.0, "b")
    assert [e.kind for e in seen if isinstance(e, Event)] == ["a"]


def test_a_failing_listener_is_dropped_and_logging_goes_on(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    calls: list[int] = []
    good: list[object] = []

    def bad(row: object) -> None:
        calls.append(1)
        raise RuntimeError("viewer broke")

    with _create(tmp_path / "log.sqlite") as log:
        log.add_listener(bad)
        log.add_listener(good.append)
        for n in range(3):
            log.event(float(n), "tick")
        log.commit()
        assert log.count("tick") == 3
    assert calls == [1]  # reported once, then dropped
    assert len(good) == 3
    err = capsys.readouterr().err
    assert err.count("viewer broke") == 1 and "removed" in err


@settings(max_examples=30, deadline=None)
@given(st.lists(st.sampled_from(["event", "sample", "commit"]), max_size=40))
def test_seq_given_to_listeners_is_the_stored_one(
    tmp_path_factory: pytest.TempPathFactory, ops: list[str]
) -> None:
    path = tmp_path_factory.mktemp("seq") / "log.sqlite"
    seen: list[Event] = []
    with _create(path) as log:
        log.add_listener(lambda row: seen.append(row) if isinstance(row, Event) else None)
        for n, op in enumerate(ops):
            if op == "event":
                log.event(float(n), "e", n=n)
            elif op == "sample":
                log.telemetry(TelemetryRecord(float(n), 0.0, 0.0, 0.0, 0.0, seq=n))
            else:
                log.commit()
    with EventLog.open(path) as log:
        assert list(log.events()) == seen


def test_replay_gives_the_rows_already_logged_then_the_new_ones(tmp_path: Path) -> None:
    path = tmp_path / "log.sqlite"
    with _create(path) as log:
        log.event(0.0, "a", n=1)
        log.telemetry(TelemetryRecord(0.5, 1.0, 2.0, 3.0, 4.0, seq=1))
        log.commit()
        log.event(1.0, "b")  # buffered, not committed yet
        log.telemetry(TelemetryRecord(1.5, math.nan, 2.0, 3.0, 4.0, seq=2))
        seen: list[Event | TelemetryRecord] = []
        log.add_listener(seen.append, replay=True)
        assert [getattr(row, "kind", None) for row in seen] == ["a", "b", None, None]
        log.event(2.0, "c")
        log.commit()
    with EventLog.open(path) as log:
        events = list(log.events())
        samples = list(log.samples())
    assert [row for row in seen if isinstance(row, Event)] == events
    replayed = [row for row in seen if isinstance(row, TelemetryRecord)]
    assert len(replayed) == 2 and all(map(_same_sample, replayed, samples))


def test_on_drop_is_told_why_a_listener_was_dropped(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    dropped: list[BaseException] = []
    others: list[BaseException] = []

    def bad(row: object) -> None:
        raise ValueError("viewer broke")

    def worse(row: object) -> None:
        raise KeyError("again")

    def failing_callback(error: BaseException) -> None:
        raise RuntimeError("the owner's callback broke too")

    with _create(tmp_path / "log.sqlite") as log:
        log.add_listener(bad, on_drop=dropped.append)
        log.add_listener(worse, on_drop=failing_callback)
        remove = log.add_listener(lambda row: None, on_drop=others.append)
        remove()  # removed by its owner: never "dropped"
        for n in range(3):
            log.event(float(n), "tick")
        log.commit()
        assert log.count("tick") == 3
    assert len(dropped) == 1 and isinstance(dropped[0], ValueError)
    assert str(dropped[0]) == "viewer broke"
    assert others == []
    assert "the owner's callback broke too" not in capsys.readouterr().err
