"""The state model against a real run's log, and its bookkeeping on hand-made events."""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from runtime.eventlog import Event, EventLog, TelemetryRecord
from runtime.watch.state import WatchState, arcs_from_net_json, snapshot_at
from tests.runtime.watch.conftest import net_from_json

Rows = tuple[str, list[Event], list[TelemetryRecord]]


@pytest.fixture(scope="module")
def rows(pool_log: Path) -> Rows:
    """The log's net, events and samples, read once for the module."""
    with EventLog.open(pool_log) as log:
        assert log.net_json is not None
        return log.net_json, list(log.events()), list(log.samples())


def _expected_markings(net_json: str, events: list[Event]) -> list[tuple[float, dict[str, int]]]:
    """(time, marking) after each mission-start and fire, by `Net.fire` on the log's net."""
    net = net_from_json(net_json)
    marking: tuple[int, ...] | None = None
    out: list[tuple[float, dict[str, int]]] = []
    for event in events:
        if event.kind == "mission-start":
            stated = event.data["marking"]
            assert isinstance(stated, dict)
            marking = net.marking_from({str(p): int(n) for p, n in stated.items()})
        elif event.kind == "fire":
            assert marking is not None
            transition = net.transition(str(event.data["transition"]))
            assert net.enabled(marking, transition), event
            marking = net.fire(marking, transition)
        else:
            continue
        out.append((event.time, net.marking_dict(marking)))
    return out


def test_the_marking_at_any_time_is_that_of_the_last_firing_before_it(rows: Rows) -> None:
    net_json, events, samples = rows
    expected = _expected_markings(net_json, events)
    assert len(expected) > 40  # the pool mission fires dozens of transitions
    times = sorted({t for t, _ in expected})
    probes = [*times, *((a + b) / 2 for a, b in itertools.pairwise(times))]
    probes += [times[-1] + 100.0]
    for t in probes:
        want = [marking for time, marking in expected if time <= t][-1]
        assert snapshot_at(net_json, events, samples, t).marking == want, t
    end = next(e for e in events if e.kind == "mission-end")
    assert expected[-1][1] == end.data["marking"]  # the firings account for the final marking
    final = snapshot_at(net_json, events, samples, end.time)
    assert final.end is not None and final.end["end"] == "final"
    assert final.unknown_firings == 0


def test_commands_and_telemetry_at_a_time_come_from_the_rows_before_it(rows: Rows) -> None:
    net_json, events, samples = rows
    sent = [e for e in events if e.kind == "command-sent"]
    middle = sent[len(sent) // 2].time
    snapshot = snapshot_at(net_json, events, samples, middle)
    assert len(snapshot.commands) == sum(1 for e in sent if e.time <= middle)
    replies = {
        int(str(e.data["command_id"])) for e in events if e.kind == "reply" and e.time <= middle
    }
    for command in snapshot.commands:
        answered = command["command_id"] in replies
        assert (command["status"] == "awaiting reply") is not answered
    assert snapshot.telemetry is not None
    assert snapshot.telemetry["time"] is not None and snapshot.telemetry["time"] <= middle
    later = [s for s in samples if s.vehicle_time > float(snapshot.telemetry["vehicle_time"] or 0)]
    assert later  # a later sample exists, so the cut-off mattered
    assert snapshot.link["handshakes"] == 1
    before = snapshot_at(net_json, events, samples, -1.0)
    assert before.marking == {} and before.commands == [] and before.telemetry is None


@settings(
    max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(cuts=st.lists(st.integers(min_value=0, max_value=200), max_size=8))
def test_advancing_in_chunks_equals_reading_at_once(rows: Rows, cuts: list[int]) -> None:
    net_json, events, samples = rows
    whole = WatchState(net_json)
    whole.advance(events, samples)
    chunked = WatchState(net_json)
    bounds = sorted({0, len(events), *(min(c, len(events)) for c in cuts)})
    for a, b in itertools.pairwise(bounds):
        chunked.advance(events[a:b], samples[a * 3 : b * 3])
    chunked.advance(samples=samples[len(events) * 3 :] if len(events) * 3 < len(samples) else [])
    assert chunked.snapshot() == whole.snapshot()


NET = json.dumps(
    {
        "name": "n",
        "places": [
            ["a", 1, "mission", None, [], None, None],
            ["b", 0, "mission", None, [], None, None],
        ],
        "transitions": [{"name": "go", "inputs": [["a", 1]], "outputs": [["b", 2]]}],
    }
)


def test_bookkeeping_of_commands_link_and_end() -> None:
    state = WatchState(NET)
    state.advance(
        [
            Event(1, 0.0, "mission-start", {"mission_id": 7, "marking": {"a": 1}}),
            Event(2, 1.0, "handshake", {"offset": 10.0, "delay": 0.1, "resumed": False}),
            Event(3, 1.0, "fire", {"transition": "go", "command_id": 1}),
            Event(
                4,
                1.0,
                "command-sent",
                {"command_id": 1, "transition": "go", "name": "DEPTH", "params": {"z": 2.0}},
            ),
            Event(5, 2.0, "reconnect", {}),
            Event(
                6,
                3.0,
                "command-sent",
                {"command_id": 1, "transition": "go", "name": "DEPTH", "params": {"z": 2.0}},
            ),
            Event(7, 3.0, "rejected", {"reason": "tag", "detail": ""}),
            Event(8, 3.5, "telemetry-lost", {}),
            Event(9, 4.0, "fire", {"transition": "nowhere"}),
        ],
        [
            TelemetryRecord(15.0, 1.0, 2.0, 3.0, 90.0, seq=1),
            TelemetryRecord(16.0, 1.5, 2.0, math.nan, 91.0, seq=2),
        ],
    )
    snap = state.snapshot()
    assert snap.marking == {"b": 2}
    assert snap.unknown_firings == 1
    [command] = snap.commands
    assert command["status"] == "awaiting reply" and command["sends"] == 2
    assert command["sent_at"] == 1.0
    assert snap.link == {
        "handshakes": 1,
        "reconnects": 1,
        "rejected": 1,
        "telemetry-lost": 1,
        "resends": 0,
        "round_trip": 0.2,
        "reply_after": None,
        "outages": 1,
        "outage_seconds": 2.0,  # from the reconnect at 2 s to the log's time, 4 s: still out
        "in_outage": True,
    }
    assert snap.telemetry == {
        "time": 6.0,
        "vehicle_time": 16.0,
        "x": 1.5,
        "y": 2.0,
        "depth": None,
        "heading": 91.0,
    }
    assert snap.end is None
    state.advance(
        [
            Event(10, 5.0, "reply", {"command_id": 1, "kind": "done", "reply_seq": 1}),
            Event(11, 5.0, "fire", {"transition": "x", "marking": {"c": 1, "d": 0}}),
            Event(12, 6.0, "mission-end", {"end": "final", "final": True, "marking": {"c": 1}}),
        ]
    )
    snap2 = state.snapshot()
    assert snap2.commands[0]["status"] == "done at 5.0 s"
    assert snap2.marking == {"c": 1}  # a stated marking wins over arcs
    assert snap2.end == {"time": 6.0, "end": "final", "final": True, "marking": {"c": 1}}
    assert snap.commands[0]["status"] == "awaiting reply"  # the earlier snapshot is unchanged


def test_a_log_without_a_readable_net_has_no_arcs() -> None:
    assert arcs_from_net_json(None) == {}
    assert arcs_from_net_json("not json") == {}
    assert arcs_from_net_json("[1, 2]") == {}
    assert arcs_from_net_json(NET) == {"go": ((("a", 1),), (("b", 2),))}
