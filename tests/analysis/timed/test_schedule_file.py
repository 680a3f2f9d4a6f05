"""Schedule files (`analysis.timed.schedule`): the JSON round trip, and every way a
file can be wrong giving one `ScheduleError` that names the file and the field.

``coral-run run --schedule FILE`` reads files people may have edited by hand, so a
mistake must say where it is (and never surface as a traceback): each case below
breaks one field of a good schedule and checks the message points at it.
"""

from __future__ import annotations

import copy
import json
import math
import os
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from analysis.timed.schedule import (
    SCHEDULE_FORMAT,
    SCHEDULE_LIMIT,
    ScheduledCommand,
    ScheduledFiring,
    ScheduleError,
    TimedSchedule,
    read_schedule,
)
from coral_lang.timing import LinkBounds

LINK = LinkBounds("genoa-lisbon", 0.045, 9.5)


def sample() -> TimedSchedule:
    """A two-command run (its times are made up)."""
    return TimedSchedule(
        mission="pool_mission",
        net_digest="sha256:" + "ab" * 32,
        kind="worst-case",
        reason="worst case to final { mission_complete }",
        link=LINK,
        duration_s=21.25,
        final={"mission_complete": 1},
        commands=(
            ScheduledCommand("set_depth", 1, "DEPTH", 0.0, 9.5, "ack", 0.6, 0.1, 9.5),
            ScheduledCommand("check_depth", 1, "DEPTH?", 19.7, 0.045, "done", 0.5, 0.0, 1.0),
        ),
        firings=(
            ScheduledFiring(0.0, "set_depth"),
            ScheduledFiring(19.7, "set_depth.ack"),
            ScheduledFiring(19.7, "check_depth"),
            ScheduledFiring(21.25, "check_depth.done"),
        ),
    )


# -- round trip ------------------------------------------------------------------------

times = st.floats(0.0, 1e6, allow_nan=False, allow_infinity=False)
names = st.text(min_size=1, max_size=8)

commands = st.builds(
    ScheduledCommand,
    transition=names,
    occurrence=st.integers(1, 1000),
    command=names,
    sent_at=times,
    up_delay_s=times,
    reply=names,
    work_s=times,
    latency_s=times,
    down_delay_s=times,
)
links = st.tuples(names, times, times).map(
    lambda t: LinkBounds(t[0], min(t[1], t[2]), max(t[1], t[2]))
)
schedules = st.builds(
    TimedSchedule,
    mission=names,
    net_digest=names,
    kind=st.sampled_from(["worst-case", "best-case", "timeout", "deadline"]),
    reason=st.text(max_size=20),
    link=links,
    duration_s=times,
    final=st.none() | st.dictionaries(names, st.integers(0, 5), max_size=3),
    commands=st.lists(commands, max_size=3).map(tuple),
    firings=st.lists(st.builds(ScheduledFiring, times, names), max_size=4).map(tuple),
)


@given(schedules)
def test_a_schedule_survives_its_json_form(schedule: TimedSchedule) -> None:
    text = json.dumps(schedule.to_json(), indent=2)
    back = TimedSchedule.from_json(json.loads(text), "s.json")
    assert back == schedule
    assert back.to_json() == schedule.to_json()


def test_written_files_read_back(tmp_path: Path) -> None:
    path = tmp_path / "worst.json"
    sample().write(path)
    text = path.read_text(encoding="utf-8")
    assert text.endswith("}\n") and not text.endswith("\n\n")
    assert read_schedule(path) == sample()


def test_the_derived_times_are_written_for_people() -> None:
    command = sample().commands[0]
    data = command.to_json()
    assert data["delivered_at"] == pytest.approx(9.5)
    assert data["replied_at"] == pytest.approx(9.5 + 0.6 + 0.1)
    assert data["arrived_at"] == pytest.approx(19.7)
    document = sample().to_json()
    assert document["format"] == SCHEDULE_FORMAT
    assert document["link"] == LINK.to_json()


# -- malformed documents -----------------------------------------------------------------

Document = dict[str, Any]


def _drop(*path: str | int) -> Callable[[Document], None]:
    """An edit deleting the field at ``path``."""

    def edit(doc: Document) -> None:
        target: Any = doc
        for step in path[:-1]:
            target = target[step]
        del target[path[-1]]

    return edit


def _set(value: object, *path: str | int) -> Callable[[Document], None]:
    """An edit setting the field at ``path`` to ``value``."""

    def edit(doc: Document) -> None:
        target: Any = doc
        for step in path[:-1]:
            target = target[step]
        target[path[-1]] = value

    return edit


TOP = ["format", "mission", "net_digest", "kind", "reason", "link", "duration_s", "final"]
TOP += ["commands", "firings"]
COMMAND = ["transition", "occurrence", "command", "sent_at", "up_delay_s", "reply"]
COMMAND += ["work_s", "latency_s", "down_delay_s"]

MALFORMED: list[tuple[str, Callable[[Document], None], str]] = [
    *((f"missing {key}", _drop(key), f"{key}: missing") for key in TOP),
    *(
        (f"missing link {key}", _drop("link", key), f"link.{key}: missing")
        for key in LINK.to_json()
    ),
    *(
        (f"missing command {key}", _drop("commands", 1, key), f"commands[1].{key}: missing")
        for key in COMMAND
    ),
    ("missing firing time", _drop("firings", 2, "time"), "firings[2].time: missing"),
    ("missing firing name", _drop("firings", 0, "transition"), "firings[0].transition: missing"),
    ("wrong format", _set("coral-schedule/2", "format"), "format: expected 'coral-schedule/1'"),
    ("format not text", _set(1, "format"), "format: expected 'coral-schedule/1', got 1"),
    ("mission a number", _set(3, "mission"), "mission: expected a string"),
    ("kind null", _set(None, "kind"), "kind: expected a string"),
    ("duration text", _set("21", "duration_s"), "duration_s: expected a number"),
    ("duration boolean", _set(True, "duration_s"), "duration_s: expected a number"),
    ("duration negative", _set(-0.5, "duration_s"), "duration_s: expected a number >= 0"),
    ("link a list", _set([], "link"), "link: expected an object"),
    ("link name a number", _set(7, "link", "name"), "link.name: expected a string"),
    ("link delay negative", _set(-1, "link", "min_delay_s"), "link.min_delay_s: expected a num"),
    ("link min above max", _set(10.0, "link", "min_delay_s"), "link: link bounds must satisfy"),
    ("final a list", _set([], "final"), "final: expected an object"),
    ("final count negative", _set(-1, "final", "done"), "final.done: expected a token count"),
    ("final count fraction", _set(0.5, "final", "done"), "final.done: expected a token count"),
    ("final count boolean", _set(True, "final", "done"), "final.done: expected a token count"),
    ("commands an object", _set({}, "commands"), "commands: expected a list"),
    ("command a number", _set(5, "commands", 0), "commands[0]: expected an object"),
    ("occurrence 0", _set(0, "commands", 1, "occurrence"), "commands[1].occurrence: expected"),
    ("occurrence -1", _set(-1, "commands", 0, "occurrence"), "commands[0].occurrence: expected"),
    ("occurrence 1.0", _set(1.0, "commands", 0, "occurrence"), "commands[0].occurrence: expected"),
    ("occurrence text", _set("1", "commands", 0, "occurrence"), "commands[0].occurrence: expected"),
    (
        "occurrence true",
        _set(True, "commands", 0, "occurrence"),
        "commands[0].occurrence: expected",
    ),
    ("sent_at negative", _set(-1, "commands", 1, "sent_at"), "commands[1].sent_at: expected a n"),
    ("reply a list", _set(["ack"], "commands", 0, "reply"), "commands[0].reply: expected a str"),
    ("firings text", _set("none", "firings"), "firings: expected a list"),
    ("firing a list", _set([0.0, "t"], "firings", 3), "firings[3]: expected an object"),
    ("firing time text", _set("0", "firings", 1, "time"), "firings[1].time: expected a number"),
]


def _document() -> Document:
    """The sample's JSON form, ending in a marking with a ``done`` place."""
    doc = copy.deepcopy(sample().to_json())
    doc["final"] = {"done": 1}
    return doc


@pytest.mark.parametrize(
    ("edit", "expected"), [(e, x) for _, e, x in MALFORMED], ids=[n for n, _, _ in MALFORMED]
)
def test_each_malformed_field_is_named(
    tmp_path: Path, edit: Callable[[Document], None], expected: str
) -> None:
    doc = _document()
    edit(doc)
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(doc), encoding="utf-8")
    with pytest.raises(ScheduleError) as caught:
        read_schedule(path)
    assert str(caught.value).startswith(f"{path}: {expected}")
    with pytest.raises(ScheduleError) as again:
        TimedSchedule.from_json(doc, "mine.json")
    assert str(again.value) == str(caught.value).replace(str(path), "mine.json", 1)


@pytest.mark.parametrize("value", ["NaN", "Infinity", "-Infinity", "1e400"])
@pytest.mark.parametrize(
    ("path", "field"),
    [(("duration_s",), "duration_s"), (("commands", 0, "work_s"), "commands[0].work_s")],
)
def test_non_finite_numbers_are_refused(
    tmp_path: Path, value: str, path: tuple[str | int, ...], field: str
) -> None:
    # JSON has no such numbers but Python's parser reads them: the reader must not.
    marker = "__here__"
    doc = _document()
    _set(marker, *path)(doc)
    file = tmp_path / "odd.json"
    file.write_text(json.dumps(doc).replace(f'"{marker}"', value), encoding="utf-8")
    with pytest.raises(ScheduleError, match=f"^{re.escape(f'{file}: {field}')}: expected a num"):
        read_schedule(file)


def test_a_document_that_is_not_an_object_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "list.json"
    path.write_text("[1, 2]\n", encoding="utf-8")
    with pytest.raises(ScheduleError) as caught:
        read_schedule(path)
    assert str(caught.value) == f"{path}: schedule: expected an object"


def test_text_that_is_not_json_gives_line_and_column(tmp_path: Path) -> None:
    path = tmp_path / "broken.json"
    path.write_text('{\n  "format": "coral-schedule/1",\n  "mission": \n}\n', encoding="utf-8")
    with pytest.raises(ScheduleError) as caught:
        read_schedule(path)
    assert str(caught.value).startswith(f"{path}:4:1: not a JSON schedule: Expecting value")


@pytest.mark.parametrize("case", ["missing", "directory", "too large", "binary", "not utf-8"])
def test_files_that_cannot_be_read_are_named(tmp_path: Path, case: str) -> None:
    path = tmp_path / "schedule.json"
    reason = {
        "missing": "no such file",
        "directory": "is a directory",
        "too large": "too large",
        "binary": "NUL",
        "not utf-8": "not UTF-8",
    }[case]
    if case == "directory":
        path.mkdir()
    elif case == "too large":
        with path.open("wb") as handle:  # sparse: nothing is really written
            handle.truncate(SCHEDULE_LIMIT + 1)
    elif case == "binary":
        path.write_bytes(b'{"format": "\x00"}')
    elif case == "not utf-8":
        path.write_bytes(b'{"format": "\xff"}')
    with pytest.raises(ScheduleError) as caught:
        read_schedule(path)
    message = str(caught.value)
    assert message.startswith(f"{path}: cannot read schedule: ")
    assert reason in message


def test_a_file_at_the_size_limit_is_read_as_json(tmp_path: Path) -> None:
    # The limit refuses files above it only: one exactly at it (padded with
    # whitespace, which JSON allows) is read.
    path = tmp_path / "big.json"
    body = json.dumps(sample().to_json())
    path.write_text(body + " " * (SCHEDULE_LIMIT - len(body)), encoding="utf-8")
    assert os.path.getsize(path) == SCHEDULE_LIMIT
    assert read_schedule(path) == sample()


def test_numbers_read_back_as_floats() -> None:
    doc = _document()
    doc["duration_s"] = 21
    doc["commands"][0]["sent_at"] = 0
    schedule = TimedSchedule.from_json(doc)
    assert isinstance(schedule.duration_s, float) and schedule.duration_s == 21.0
    assert isinstance(schedule.commands[0].sent_at, float)
    assert not math.isnan(schedule.commands[0].arrived_at)
