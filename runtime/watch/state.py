"""What a mission looks like at one moment, computed from its controller log alone.

The watch page (and the terminal view) show a mission as it runs and replay one that has
ended; both are the same question asked of the log: given the events (and telemetry
samples) logged up to time t, what is the marking, which transitions may fire, which
commands are out and what came back, where has the vehicle been, how is the link, what
did the operator do, and has the mission ended? `WatchState` answers it incrementally
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

Bounded whatever the log's length: a snapshot is sent to every viewer at every change, so
its size may not grow with the mission. The track is decimated (`Track`), the firings and
the operator's actions keep their most recent entries, and the commands list keeps every
command still in flight and the most recent finished ones (``commands_total`` says how
many were sent). The state itself keeps no more than what it shows.
"""

from __future__ import annotations

import bisect
import itertools
import json
import math
from collections import deque
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Final

from runtime.eventlog import Event
from runtime.telemetry import TelemetryRecord

__all__ = [
    "FINISHED_COMMANDS_KEPT",
    "FIRED_KEPT",
    "LINK_COUNTERS",
    "OPERATOR_KEPT",
    "TRACK_POINTS",
    "CommandStatus",
    "NetFacts",
    "Snapshot",
    "Track",
    "WatchState",
    "arcs_from_net_json",
    "clock_rate",
    "net_facts",
    "snapshot_at",
]

LINK_COUNTERS: Final = ("handshakes", "reconnects", "rejected", "telemetry-lost", "resends")
"""Link health as the operator reads it: how often the link was (re)established, lost,
how much it dropped or refused, and how many commands had to be sent again."""

_COUNTED: Final = {
    "handshake": "handshakes",
    "reconnect": "reconnects",
    "rejected": "rejected",
    "telemetry-rejected": "rejected",
    "telemetry-lost": "telemetry-lost",
    "command-resent": "resends",
}

TRACK_POINTS: Final = 1000
"""Track points a snapshot carries at most (plus the newest sample)."""

FIRED_KEPT: Final = 500
"""Most recent firings a snapshot carries, for the events timeline."""

FINISHED_COMMANDS_KEPT: Final = 200
"""Most recent answered commands a snapshot carries (every command in flight is kept)."""

OPERATOR_KEPT: Final = 100
"""Most recent operator actions a snapshot carries."""

_ENGINE_KINDS: Final = frozenset({"plain", "command"})
"""Transition kinds the engine fires by itself (not replies, not operator inputs)."""

Pairs = tuple[tuple[str, int], ...]
"""Arcs as (place, weight) pairs."""


@dataclass(frozen=True)
class NetFacts:
    """What the model needs of the net: arcs, kinds, and each command's replies and
    time-out (``time_out`` parameter, as the engine reads it)."""

    arcs: Mapping[str, tuple[Pairs, Pairs]] = field(default_factory=dict)
    kinds: Mapping[str, str] = field(default_factory=dict)
    replies: Mapping[str, tuple[str, ...]] = field(default_factory=dict)
    time_outs: Mapping[str, float] = field(default_factory=dict)
    inputs: Mapping[str, str] = field(default_factory=dict)
    """INPUT transition name -> the input it gives."""
    consumers: Mapping[str, tuple[str, ...]] = field(default_factory=dict)
    """Place -> the transitions with an input arc from it (`WatchState._enabled`)."""
    sourceless: tuple[str, ...] = ()
    """Transitions with no input arc: always enabled."""


def net_facts(net_json: str | None) -> NetFacts:
    """`NetFacts` from a log's ``net_json`` (the net's canonical form); empty when the log
    has no net or it cannot be read, so a damaged header still shows the markings the log
    states outright. Entries that do not have the expected shape are skipped one by one."""
    if net_json is None:
        return NetFacts()
    try:
        net = json.loads(net_json)
    except ValueError:
        return NetFacts()
    transitions = net.get("transitions") if isinstance(net, dict) else None
    if not isinstance(transitions, list):
        return NetFacts()
    arcs: dict[str, tuple[Pairs, Pairs]] = {}
    kinds: dict[str, str] = {}
    replies: dict[str, tuple[str, ...]] = {}
    time_outs: dict[str, float] = {}
    inputs: dict[str, str] = {}
    for entry in transitions:
        if not isinstance(entry, dict) or not isinstance(entry.get("name"), str):
            continue
        name = entry["name"]
        arcs[name] = (_pairs(entry.get("inputs")), _pairs(entry.get("outputs")))
        kind = entry.get("kind")
        kinds[name] = kind if isinstance(kind, str) else "plain"
        given = entry.get("operator_input")
        if isinstance(given, str):
            inputs[name] = given
        command = entry.get("command")
        if not isinstance(command, list) or len(command) < 5:
            continue
        if isinstance(command[4], list):
            replies[name] = tuple(str(kind) for kind in command[4])
        limit = _param(command[2], "time_out")
        if limit is not None:
            time_outs[name] = limit
    consumers: dict[str, list[str]] = {}
    for name, (ins, _) in arcs.items():
        for place, _weight in ins:
            consumers.setdefault(place, []).append(name)
    sourceless = tuple(name for name, (ins, _) in arcs.items() if not ins)
    return NetFacts(
        arcs,
        kinds,
        replies,
        time_outs,
        inputs,
        {place: tuple(names) for place, names in consumers.items()},
        sourceless,
    )


def arcs_from_net_json(net_json: str | None) -> dict[str, tuple[Pairs, Pairs]]:
    """Each transition's input and output arcs from a log's ``net_json`` (see `net_facts`)."""
    return dict(net_facts(net_json).arcs)


def _param(params: object, name: str) -> float | None:
    """A numeric command parameter of the canonical ``[[name, value], ...]`` list: the
    engine's rule for ``time_out`` (an int or a float; anything else is no time-out)."""
    if not isinstance(params, list):
        return None
    for item in params:
        if isinstance(item, list) and len(item) == 2 and item[0] == name:
            value = item[1]
            if isinstance(value, int | float) and not isinstance(value, bool):
                return float(value)
    return None


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
    """One command's line on the page: when it went out, what it awaits, what came back.

    ``awaiting`` is the reply kinds the net maps for it (empty once a reply came);
    ``timeout_at`` the controller time its ``time_out`` runs out (the first send plus the
    parameter, as the engine computes it), None when it has none.
    """

    command_id: int
    name: str
    transition: str
    params: dict[str, object]
    sent_at: float
    replies_expected: tuple[str, ...] = ()
    timeout_at: float | None = None
    sends: int = 1
    replies: list[tuple[str, float]] = field(default_factory=list)

    @property
    def in_flight(self) -> bool:
        return not self.replies

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
            "awaiting": list(self.replies_expected) if last is None else [],
            "timeout_at": self.timeout_at,
        }


class Track:
    """The vehicle's track, decimated so it never holds more than `TRACK_POINTS` points.

    Sample number k is kept when k is a multiple of the current stride; when the kept
    points exceed the bound, every other one is dropped and the stride doubles. So the
    points stay evenly spaced (in samples), the first sample is always kept, the result
    depends only on the samples (not on how they were batched), and the newest sample is
    added at the end when the stride skipped it.

    Points are ``[t, x, y, depth, heading]``, rounded to the millimetre and millisecond;
    heading is *continuous* (each step the shortest turn from the previous reading, as
    `runtime.timeline_plots.continuous_heading` draws it), so a plot never jumps at north;
    its value modulo 360 is the reading.
    """

    def __init__(self, limit: int = TRACK_POINTS) -> None:
        if limit < 2:
            raise ValueError("a track keeps at least two points")
        self.limit = limit
        self.count = 0
        self.stride = 1
        self._kept: list[list[float | None]] = []
        self._last: list[float | None] | None = None
        self._heading: float | None = None

    def add(self, t: float, x: float, y: float, depth: float, heading: float) -> None:
        psi = _finite(heading)
        if psi is not None:
            if self._heading is None:
                psi = psi % 360.0
            else:
                turn = (psi - self._heading) % 360.0
                psi = self._heading + (turn - 360.0 if turn > 180.0 else turn)
            self._heading = psi
        point = [_round(t), _round(_finite(x)), _round(_finite(y)), _round(_finite(depth))]
        point.append(_round(psi))
        if self.count % self.stride == 0:
            self._kept.append(point)
            if len(self._kept) > self.limit:
                self._kept = self._kept[::2]
                self.stride *= 2
        self._last = point
        self.count += 1

    def points(self) -> list[list[float | None]]:
        """The kept points and, if the stride skipped it, the newest sample."""
        out = [list(p) for p in self._kept]
        if self._last is not None and (self.count - 1) % self.stride != 0:
            out.append(list(self._last))
        return out


def _round(value: float | None) -> float | None:
    return None if value is None else round(value, 3)


@dataclass(frozen=True)
class Snapshot:
    """The mission at one moment, as plain JSON-ready values (see `WatchState`).

    Keys of `to_json` (the page and the terminal view read them):

    * ``time``, ``seq``: the log's time (controller clock) and last event number;
    * ``marking``: ``{place: tokens}``, marked places only;
    * ``enabled``: engine transitions (plain, command) the marking enables, none once
      the mission has ended; ``in_flight``: transitions with a command out;
      ``offered``: operator inputs that can still be given (their input transition is
      enabled and the mission has not ended);
    * ``commands``: every command in flight and the latest answered ones, by id (see
      `CommandStatus`), ``commands_total`` how many were sent in all;
    * ``telemetry``: the newest sample; ``track``: ``[t, x, y, depth, heading]`` points
      (`Track`), t on the controller clock;
    * ``fired``: the latest ``[t, transition]`` firings, ``fired_total`` how many in all
      (so a viewer knows which of them are new since its previous snapshot);
    * ``link``: counters (`LINK_COUNTERS`) and figures (`WatchState` says which);
    * ``paused``: the operator paused the engine; ``operator``: the latest actions
      ``{time, action, input, origin, accepted, message}``;
    * ``end``: the ``mission-end`` event's fields with its time, or None;
      ``unknown_firings``: firings of transitions the net does not have.
    """

    time: float
    seq: int
    marking: dict[str, int]
    commands: list[dict[str, object]]
    telemetry: dict[str, float | None] | None
    link: dict[str, float | int | None]
    end: dict[str, object] | None
    unknown_firings: int
    enabled: list[str] = field(default_factory=list)
    in_flight: list[str] = field(default_factory=list)
    offered: list[str] = field(default_factory=list)
    commands_total: int = 0
    paused: bool = False
    operator: list[dict[str, object]] = field(default_factory=list)
    track: list[list[float | None]] = field(default_factory=list)
    fired: list[list[object]] = field(default_factory=list)
    fired_total: int = 0

    def to_json(self) -> dict[str, object]:
        return {
            "time": self.time,
            "seq": self.seq,
            "marking": self.marking,
            "enabled": self.enabled,
            "in_flight": self.in_flight,
            "offered": self.offered,
            "commands": self.commands,
            "commands_total": self.commands_total,
            "telemetry": self.telemetry,
            "track": self.track,
            "fired": self.fired,
            "fired_total": self.fired_total,
            "link": self.link,
            "paused": self.paused,
            "operator": self.operator,
            "end": self.end,
            "unknown_firings": self.unknown_firings,
        }


class WatchState:
    """A controller log's state, advanced row by row in log order.

    Telemetry samples are timed by the vehicle's clock; they are put on the controller's
    as `runtime.timeline` does: ``h_c + (t - h_v) / rate`` from the latest handshake
    (``h_c`` its controller time, ``h_v = h_c + offset`` the vehicle's), where ``rate``
    is vehicle seconds per controller second (`clock_rate`: a simulator run with
    ``--realtime --speed S`` has rate S; 1 otherwise, where this is ``t - offset``).

    Link figures, derived from the controller's events only:

    * ``round_trip``: twice the ``delay`` of the latest ``handshake`` (the clock sync's
      one-way delay estimate, assumed symmetric), None before the first;
    * ``reply_after``: seconds from the latest answered command's first send to its first
      reply (link and vehicle time together: an ``ack`` is mostly link, a ``done`` the
      command's own duration);
    * ``outages``, ``outage_seconds``: each ``reconnect`` opens an outage, closed by the
      next ``handshake``; one still open counts up to the log's time, ``in_outage`` says so.

    The operator: an accepted ``pause`` pauses the engine, an accepted ``resume`` or
    ``give`` (giving an input resumes) ends the pause, and so does the mission's end or
    a controller restart (``reset``, ``resume`` events: a restarted engine is not paused).
    """

    def __init__(self, net_json: str | None, rate: float = 1.0) -> None:
        self.rate = rate if rate > 0 and math.isfinite(rate) else 1.0
        self._anchor: tuple[float, float] | None = None
        self._net = net_facts(net_json)
        self._arcs = self._net.arcs
        self.time = 0.0
        self.seq = 0
        self.marking: dict[str, int] = {}
        self._open: dict[int, CommandStatus] = {}
        self._done: deque[CommandStatus] = deque(maxlen=FINISHED_COMMANDS_KEPT)
        self._sent_total = 0
        self._highest_id = -1
        self._telemetry: dict[str, float | None] | None = None
        self._track = Track()
        self._fired: deque[list[object]] = deque(maxlen=FIRED_KEPT)
        self._fired_total = 0
        self._operator: deque[dict[str, object]] = deque(maxlen=OPERATOR_KEPT)
        self.paused = False
        self._link = dict.fromkeys(LINK_COUNTERS, 0)
        self._round_trip: float | None = None
        self._reply_after: float | None = None
        self._outages = 0
        self._outage_seconds = 0.0
        self._outage_since: float | None = None
        self.end: dict[str, object] | None = None
        self.unknown_firings = 0
        self.offset = 0.0

    def advance(
        self, events: Iterable[Event] = (), samples: Iterable[TelemetryRecord] = ()
    ) -> None:
        """Take the rows logged since the last call (each in log order)."""
        for event in events:
            self._event(event)
        for sample in samples:
            self._sample(sample)

    def sample_time(self, sample: TelemetryRecord) -> float:
        """A sample's time on the controller's clock (see the class)."""
        if self._anchor is None:
            return sample.vehicle_time - self.offset
        controller, vehicle = self._anchor
        return controller + (sample.vehicle_time - vehicle) / self.rate

    def _event(self, event: Event) -> None:
        self.seq = max(self.seq, event.seq)
        self.time = max(self.time, event.time)
        data = event.data
        kind = event.kind
        if kind == "mission-start":
            self.marking = _marking(data.get("marking")) or {}
        elif kind == "fire":
            self._fire(data)
            self._fired.append([event.time, str(data.get("transition", "?"))])
            self._fired_total += 1
        elif kind == "command-sent":
            self._sent(event)
        elif kind == "reply":
            self._reply(event)
        elif kind == "operator":
            self._operated(event)
        elif kind in ("reset", "resume"):
            self.paused = False
        elif kind == "mission-end":
            self.end = {"time": event.time, **data}
            self.paused = False
            stated = _marking(data.get("marking"))
            if stated is not None:
                self.marking = stated
        elif kind == "handshake":
            self._handshake(event)
        elif kind == "reconnect" and self._outage_since is None:
            self._outages += 1
            self._outage_since = event.time
        counter = _COUNTED.get(kind)
        if counter is not None:
            self._link[counter] += 1

    def _handshake(self, event: Event) -> None:
        offset = event.data.get("offset")
        if isinstance(offset, int | float) and not isinstance(offset, bool):
            self.offset = float(offset)
            self._anchor = (event.time, event.time + self.offset)
        delay = event.data.get("delay")
        if isinstance(delay, int | float) and not isinstance(delay, bool):
            self._round_trip = 2.0 * float(delay)
        if self._outage_since is not None:
            self._outage_seconds += max(0.0, event.time - self._outage_since)
            self._outage_since = None

    def _fire(self, data: Mapping[str, object]) -> None:
        stated = _marking(data.get("marking"))
        if stated is not None:
            self.marking = stated
            return
        arcs = self._arcs.get(str(data.get("transition")))
        if arcs is None:
            self.unknown_firings += 1
            return
        # In place, touching only the transition's arcs: this runs for every firing a
        # live feed hears, in the engine's path (snapshots copy the marking).
        inputs, outputs = arcs
        marking = self.marking
        for place, weight in (*((p, -w) for p, w in inputs), *outputs):
            tokens = marking.get(place, 0) + weight
            if tokens:
                marking[place] = tokens
            else:
                marking.pop(place, None)

    def _find(self, command_id: int) -> CommandStatus | None:
        known = self._open.get(command_id)
        if known is None and command_id <= self._highest_id:
            # Answered already (a re-send, or a late duplicate reply): only the kept ones
            # can be found. A new id is never searched for, so sending stays O(1).
            known = next((c for c in self._done if c.command_id == command_id), None)
        return known

    def _sent(self, event: Event) -> None:
        data = event.data
        command_id = _int(data.get("command_id"))
        known = self._find(command_id)
        if known is not None:  # a re-send after a reconnect: same id, same command
            known.sends += 1
            return
        params = data.get("params")
        transition = str(data.get("transition", "?"))
        limit = self._net.time_outs.get(transition)
        self._sent_total += 1
        self._highest_id = max(self._highest_id, command_id)
        self._open[command_id] = CommandStatus(
            command_id,
            str(data.get("name", "?")),
            transition,
            dict(params) if isinstance(params, dict) else {},
            event.time,
            self._net.replies.get(transition, ()),
            None if limit is None else event.time + limit,
        )

    def _reply(self, event: Event) -> None:
        command_id = _int(event.data.get("command_id"))
        command = self._open.pop(command_id, None)
        if command is not None:
            self._done.append(command)
            self._reply_after = event.time - command.sent_at
        else:
            command = self._find(command_id)
        if command is not None:
            command.replies.append((str(event.data.get("kind", "?")), event.time))

    def _operated(self, event: Event) -> None:
        data = event.data
        action = data.get("action")
        given = data.get("input")
        accepted = data.get("accepted") is True
        self._operator.append(
            {
                "time": event.time,
                "action": str(action),
                "input": given if isinstance(given, str) else None,
                "origin": str(data.get("origin", "")),
                "accepted": accepted,
                "message": str(data.get("message", "")),
            }
        )
        if accepted and action == "pause":
            self.paused = True
        elif accepted and action in ("resume", "give"):
            self.paused = False

    def _sample(self, sample: TelemetryRecord) -> None:
        time = self.sample_time(sample)
        self._telemetry = {
            "time": time,
            "vehicle_time": sample.vehicle_time,
            "x": _finite(sample.x),
            "y": _finite(sample.y),
            "depth": _finite(sample.z),
            "heading": _finite(sample.psi),
        }
        self._track.add(time, sample.x, sample.y, sample.z, sample.psi)

    def link(self) -> dict[str, float | int | None]:
        """The link counters and figures now (see the class)."""
        outage = self._outage_seconds
        if self._outage_since is not None:
            outage += max(0.0, self.time - self._outage_since)
        return {
            **self._link,
            "round_trip": self._round_trip,
            "reply_after": self._reply_after,
            "outages": self._outages,
            "outage_seconds": outage,
            "in_outage": self._outage_since is not None,
        }

    def _enabled(self, kinds: Iterable[str]) -> list[str]:
        """The transitions of ``kinds`` the marking enables. Only transitions with an
        input arc from a marked place (or none at all) are tested: a snapshot of a large
        net costs what is marked, not the whole net."""
        wanted = set(kinds)
        marking = self.marking
        consumers = self._net.consumers
        candidates = {t for place in marking for t in consumers.get(place, ())}
        candidates.update(self._net.sourceless)
        return sorted(
            name
            for name in candidates
            if self._net.kinds.get(name, "plain") in wanted
            and all(marking.get(place, 0) >= weight for place, weight in self._arcs[name][0])
        )

    def snapshot(self) -> Snapshot:
        """The state now, as a value the caller may keep (later rows do not change it)."""
        ended = self.end is not None
        commands = sorted([*self._open.values(), *self._done], key=_by_id)
        offered = [] if ended else self._enabled(("input",))
        return Snapshot(
            time=self.time,
            seq=self.seq,
            marking=dict(sorted(self.marking.items())),
            commands=[c.to_json() for c in commands],
            telemetry=None if self._telemetry is None else dict(self._telemetry),
            link=self.link(),
            end=None if self.end is None else dict(self.end),
            unknown_firings=self.unknown_firings,
            enabled=[] if ended else self._enabled(_ENGINE_KINDS),
            in_flight=sorted({c.transition for c in self._open.values()}),
            offered=[self._net.inputs.get(name, name) for name in offered],
            commands_total=self._sent_total,
            paused=self.paused,
            operator=[dict(action) for action in self._operator],
            track=self._track.points(),
            fired=[list(item) for item in self._fired],
            fired_total=self._fired_total,
        )


def _by_id(command: CommandStatus) -> int:
    return command.command_id


def _int(value: object) -> int:
    return value if isinstance(value, int) and not isinstance(value, bool) else -1


def _finite(value: float | None) -> float | None:
    if value is None:
        return None
    return value if math.isfinite(value) else None


def clock_rate(meta: Mapping[str, object]) -> float:
    """Vehicle clock seconds per controller second for a controller log's ``meta``: the
    ``speed`` of a real-time simulated run (``--realtime --speed S``), else 1 (virtual
    time shares one clock; a real vehicle's clock runs at the controller's rate)."""
    speed = meta.get("speed")
    realtime = meta.get("realtime") is True and meta.get("vehicle") == "sim"
    if not realtime or isinstance(speed, bool) or not isinstance(speed, int | float):
        return 1.0
    return float(speed) if 0 < speed < math.inf else 1.0


def snapshot_at(
    net_json: str | None,
    events: Sequence[Event],
    samples: Sequence[TelemetryRecord],
    t: float,
    rate: float = 1.0,
) -> Snapshot:
    """The snapshot of a log at time ``t``: the events logged up to the first one later
    than ``t``, and every sample whose controller time (the offset of the handshakes
    before it) is at or before ``t``. Both in log order. The cut is taken on the running
    maximum of the event times, so a clock that stepped back (a controller resumed on
    another machine) still gives a prefix of the log, never a marking from a mixture."""
    state = WatchState(net_json, rate)
    reached = list(itertools.accumulate((event.time for event in events), max))
    cut = bisect.bisect_right(reached, t)
    state.advance(events[:cut])
    # Samples: the offset is the one of the last handshake at or before t (all advanced).
    state.advance(samples=[s for s in samples if state.sample_time(s) <= t])
    state.time = t
    return state.snapshot()
