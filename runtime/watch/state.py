"""What a mission looks like at one moment, computed from its controller log alone.

The watch page shows a mission as it runs and replays one that has ended; both are the
same question asked of the log: given the events (and telemetry samples) logged up to time
t, what is the marking, which commands are out and what came back, where is the vehicle,
how is the link, and has the mission ended? `WatchState` answers it incrementally
(`advance` takes the rows logged since the last call), so a live log is followed by
reading only its new rows, and `snapshot_at` answers it for any t of a finished log.

The model is pure (no I/O, no clock): the server feeds it rows, the tests feed it a real
run's log and check it against an independent replay.

Markings: the engine's ``fire`` events name the transition (and, in some logs, the marking
after it); ``mission-start`` and ``mission-end`` carry whole markings. The model starts
from ``mission-start``'s marking and applies each firing's arcs from the net the log
carries (``header.net_json``), unless the event gives the marking itself, which then wins.
A firing of a transition the net does not have is counted (``unknown_firings``) rather
than guessed at.
"""

from __future__ import annotations

import bisect
import itertools
import json
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Final

from runtime.eventlog import Event, TelemetrySample

__all__ = [
    "LINK_COUNTERS",
    "CommandStatus",
    "Snapshot",
    "WatchState",
    "arcs_from_net_json",
    "snapshot_at",
]

LINK_COUNTERS: Final = ("handshakes", "reconnects", "rejected", "telemetry-lost")
"""Link health as the operator reads it: how often the link was (re)established, lost,
and how much it dropped or refused."""

_COUNTED: Final = {
    "handshake": "handshakes",
    "reconnect": "reconnects",
    "rejected": "rejected",
    "telemetry-rejected": "rejected",
    "telemetry-lost": "telemetry-lost",
}

Pairs = tuple[tuple[str, int], ...]
"""Arcs as (place, weight) pairs."""


def arcs_from_net_json(net_json: str | None) -> dict[str, tuple[Pairs, Pairs]]:
    """Each transition's input and output arcs from a log's ``net_json`` (the net's
    canonical form); empty when the log has no net or it cannot be read, so a damaged
    header still shows the markings the log states outright."""
    if net_json is None:
        return {}
    try:
        net = json.loads(net_json)
    except ValueError:
        return {}
    transitions = net.get("transitions") if isinstance(net, dict) else None
    if not isinstance(transitions, list):
        return {}
    arcs: dict[str, tuple[Pairs, Pairs]] = {}
    for entry in transitions:
        if not isinstance(entry, dict) or not isinstance(entry.get("name"), str):
            continue
        arcs[entry["name"]] = (_pairs(entry.get("inputs")), _pairs(entry.get("outputs")))
    return arcs


def _pairs(value: object) -> Pairs:
    if not isinstance(value, list):
        return ()
    return tuple(
        (str(item[0]), int(item[1]))
        for item in value
        if isinstance(item, list) and len(item) == 2 and isinstance(item[1], int)
    )


def _marking(value: object) -> dict[str, int] | None:
    """A logged marking (``{place: tokens}``) with its zeros left out; None if it is not one."""
    if not isinstance(value, dict):
        return None
    return {
        str(place): int(tokens)
        for place, tokens in value.items()
        if isinstance(tokens, int) and not isinstance(tokens, bool) and tokens
    }


@dataclass
class CommandStatus:
    """One command's line on the page: when it went out, and what came back."""

    command_id: int
    name: str
    transition: str
    params: dict[str, object]
    sent_at: float
    sends: int = 1
    replies: list[tuple[str, float]] = field(default_factory=list)

    def to_json(self) -> dict[str, object]:
        last = self.replies[-1] if self.replies else None
        return {
            "command_id": self.command_id,
            "name": self.name,
            "transition": self.transition,
            "params": self.params,
            "sent_at": self.sent_at,
            "sends": self.sends,
            "replies": [{"kind": kind, "time": time} for kind, time in self.replies],
            "status": "awaiting reply" if last is None else f"{last[0]} at {last[1]:.1f} s",
        }


@dataclass(frozen=True)
class Snapshot:
    """The mission at one moment, as plain JSON-ready values (see `WatchState`)."""

    time: float
    seq: int
    marking: dict[str, int]
    commands: list[dict[str, object]]
    telemetry: dict[str, float | None] | None
    link: dict[str, int]
    end: dict[str, object] | None
    unknown_firings: int

    def to_json(self) -> dict[str, object]:
        return {
            "time": self.time,
            "seq": self.seq,
            "marking": self.marking,
            "commands": self.commands,
            "telemetry": self.telemetry,
            "link": self.link,
            "end": self.end,
            "unknown_firings": self.unknown_firings,
        }


class WatchState:
    """A controller log's state, advanced row by row in log order.

    Telemetry samples are timed by the vehicle's clock; they are put on the controller's
    with the offset of the latest handshake (``t - offset``, rate 1: a simulator run with
    ``--speed`` shows its samples at vehicle time, as its own clock said).
    """

    def __init__(self, net_json: str | None) -> None:
        self._arcs = arcs_from_net_json(net_json)
        self.time = 0.0
        self.seq = 0
        self.marking: dict[str, int] = {}
        self._commands: dict[int, CommandStatus] = {}
        self._telemetry: dict[str, float | None] | None = None
        self._link = dict.fromkeys(LINK_COUNTERS, 0)
        self.end: dict[str, object] | None = None
        self.unknown_firings = 0
        self.offset = 0.0

    def advance(
        self, events: Iterable[Event] = (), samples: Iterable[TelemetrySample] = ()
    ) -> None:
        """Take the rows logged since the last call (each in log order)."""
        for event in events:
            self._event(event)
        for sample in samples:
            self._sample(sample)

    def sample_time(self, sample: TelemetrySample) -> float:
        """A sample's time on the controller's clock (see the class)."""
        return sample.time - self.offset

    def _event(self, event: Event) -> None:
        self.seq = max(self.seq, event.seq)
        self.time = max(self.time, event.time)
        data = event.data
        kind = event.kind
        if kind == "mission-start":
            self.marking = _marking(data.get("marking")) or {}
        elif kind == "fire":
            self._fire(data)
        elif kind == "command-sent":
            self._sent(event)
        elif kind == "reply":
            command = self._commands.get(_int(data.get("command_id")))
            if command is not None:
                command.replies.append((str(data.get("kind", "?")), event.time))
        elif kind == "mission-end":
            self.end = {"time": event.time, **data}
            stated = _marking(data.get("marking"))
            if stated is not None:
                self.marking = stated
        offset = data.get("offset")
        if kind == "handshake" and isinstance(offset, int | float):
            self.offset = float(offset)
        counter = _COUNTED.get(kind)
        if counter is not None:
            self._link[counter] += 1

    def _fire(self, data: Mapping[str, object]) -> None:
        stated = _marking(data.get("marking"))
        if stated is not None:
            self.marking = stated
            return
        arcs = self._arcs.get(str(data.get("transition")))
        if arcs is None:
            self.unknown_firings += 1
            return
        inputs, outputs = arcs
        marking = dict(self.marking)
        for place, weight in inputs:
            marking[place] = marking.get(place, 0) - weight
        for place, weight in outputs:
            marking[place] = marking.get(place, 0) + weight
        self.marking = {place: tokens for place, tokens in marking.items() if tokens}

    def _sent(self, event: Event) -> None:
        data = event.data
        command_id = _int(data.get("command_id"))
        known = self._commands.get(command_id)
        if known is not None:  # a re-send after a reconnect: same id, same command
            known.sends += 1
            return
        params = data.get("params")
        self._commands[command_id] = CommandStatus(
            command_id,
            str(data.get("name", "?")),
            str(data.get("transition", "?")),
            dict(params) if isinstance(params, dict) else {},
            event.time,
        )

    def _sample(self, sample: TelemetrySample) -> None:
        self._telemetry = {
            "time": self.sample_time(sample),
            "vehicle_time": sample.time,
            "x": _finite(sample.x),
            "y": _finite(sample.y),
            "depth": _finite(sample.z),
            "heading": _finite(sample.psi),
        }

    def snapshot(self) -> Snapshot:
        """The state now, as a value the caller may keep (later rows do not change it)."""
        return Snapshot(
            time=self.time,
            seq=self.seq,
            marking=dict(sorted(self.marking.items())),
            commands=[c.to_json() for c in sorted(self._commands.values(), key=_by_id)],
            telemetry=None if self._telemetry is None else dict(self._telemetry),
            link=dict(self._link),
            end=None if self.end is None else dict(self.end),
            unknown_firings=self.unknown_firings,
        )


def _by_id(command: CommandStatus) -> int:
    return command.command_id


def _int(value: object) -> int:
    return value if isinstance(value, int) and not isinstance(value, bool) else -1


def _finite(value: float) -> float | None:
    return value if value == value and abs(value) != float("inf") else None


def snapshot_at(
    net_json: str | None,
    events: Sequence[Event],
    samples: Sequence[TelemetrySample],
    t: float,
) -> Snapshot:
    """The snapshot of a log at time ``t``: the events logged up to the first one later
    than ``t``, and every sample whose controller time (the offset of the handshakes
    before it) is at or before ``t``. Both in log order. The cut is taken on the running
    maximum of the event times, so a clock that stepped back (a controller resumed on
    another machine) still gives a prefix of the log, never a marking from a mixture."""
    state = WatchState(net_json)
    reached = list(itertools.accumulate((event.time for event in events), max))
    cut = bisect.bisect_right(reached, t)
    state.advance(events[:cut])
    # Samples: the offset is the one of the last handshake at or before t (all advanced).
    state.advance(samples=[s for s in samples if state.sample_time(s) <= t])
    state.time = t
    return state.snapshot()
