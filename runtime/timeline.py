"""Merge the controller's and the vehicle's event logs on one clock, and summarise them.

This is the paper's off-line analysis (section IV): "the events' sequence, including the
corresponding timestamps, has been recorded by both the Romeo Supervisor HCI and CORAL
engine machines. The logged data have been merged off-line", with the INIT handshake giving
the offset between the two clocks. `merge_logs` does the merge, `plot_timeline` draws the
events' sequence (like Fig. 5) and the telemetry (like Figs. 7-9; the drawing itself is in
`runtime.timeline_plots`), `summarize` says in a few lines what is in them;
``coral-run timeline LOG...`` (`runtime.cli`) calls the three.

Clocks. Every log is timed by its writer's own clock. The controller logs a ``handshake``
event on every connection, whose ``offset`` is `runtime.protocol.ClockSync.vehicle_ahead`
(vehicle clock minus controller clock, built on the paper's t_offset formula). A simulator
run with ``--realtime --speed S`` makes the vehicle clock run S times as fast as the
controller's, so an offset alone is not enough: a vehicle time ``t_v`` is put on the
controller's axis as ``h_c + (t_v - h_v) / rate``, where ``(h_c, h_v)`` is the last
handshake made before ``t_v`` (the first one for anything earlier) on the two clocks
(``h_v = h_c + offset``) and ``rate`` is vehicle seconds per controller second: the
``speed`` a log's meta records (1 in virtual time), else estimated from the replies when
they clearly disagree with 1, else 1. With rate 1 this is ``t_v - offset``. Telemetry
samples are always vehicle-timed, whichever log holds them, and are converted the same way.
Without any handshake vehicle times are taken as they are and the summary says so.

The logs may be read while the controller still writes its log (a live reader): nothing
here needs a ``mission-end`` event or a closed log.
"""

from __future__ import annotations

import bisect
import itertools
import json
import math
import statistics
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Final

from runtime.eventlog import Event, EventLog, EventLogError
from runtime.telemetry import TelemetryRecord

if TYPE_CHECKING:
    from runtime.timeline_plots import PlotContext

__all__ = [
    "DPI",
    "EVENTS_FIGSIZE",
    "TELEMETRY_FIGSIZE",
    "Command",
    "MergedTimeline",
    "commands_of",
    "merge_logs",
    "plot_timeline",
    "summarize",
    "telemetry_gaps",
]

EVENTS_FIGSIZE: Final = (12.0, 6.5)
"""Size of ``events.png`` in inches; at `DPI` it is 1200 x 650 pixels."""
TELEMETRY_FIGSIZE: Final = (12.0, 8.0)
"""Size of ``telemetry.png`` in inches; at `DPI` it is 1200 x 800 pixels."""
DPI: Final = 100

CONTROLLER: Final = "controller"
VEHICLE: Final = "vehicle"

FINAL_REPLIES: Final = frozenset({"done", "timeout", "error"})
# A rate estimated from the replies is used only outside this band around 1: link delays
# make the estimate noisy, and a real vehicle's clock never runs 25 % fast.
_RATE_BAND: Final = (0.8, 1.25)
_RATE_MIN_REPLIES: Final = 5
_RATE_MAX_PAIRS: Final = 400


@dataclass(frozen=True)
class MergedTimeline:
    """Both logs of one mission on the controller's clock.

    Attributes:
        events: ``(time, source, event)`` sorted by time, ``time`` on the controller's
            clock, ``source`` ``"controller"`` or ``"vehicle"``; ``event`` is as logged
            (a vehicle event keeps its own clock in ``event.time``).
        samples: ``(time, sample)`` sorted by time, ``time`` on the controller's clock;
            ``sample`` is as logged (it keeps the vehicle's clock in ``vehicle_time``).
            The vehicle log's (every sample sent) when it has any, else those the
            controller received.
        offset: the first handshake's offset (vehicle clock minus controller clock, the
            INIT estimate of the paper), or None when the controller logged no handshake.
        mission: the mission both logs belong to (the controller's name for it).
        offsets: every handshake as ``(controller time, offset)``, in time order.
        logs: the file of each source.
        sample_source: which log ``samples`` came from (None: no telemetry at all).
        received_samples: how many samples the controller's log holds (datagrams that
            arrived), to compare with the vehicle's.
        rate: vehicle clock seconds per controller clock second (the simulator's
            ``--speed`` in a real-time run; 1 otherwise).
        rate_source: where ``rate`` came from, for the summary.
        mission_id: the wire mission id the controller used, when its log says.
        meta: the controller log's ``meta`` (mission file, profiles, options).
        vehicle_name: the vehicle the mission's net commands (from the logged net).
        net_digest: the digest of the net the controller ran.
    """

    events: list[tuple[float, str, Event]]
    samples: list[tuple[float, TelemetryRecord]]
    offset: float | None
    mission: str
    offsets: list[tuple[float, float]] = field(default_factory=list)
    logs: dict[str, Path] = field(default_factory=dict)
    sample_source: str | None = None
    received_samples: int = 0
    rate: float = 1.0
    rate_source: str = "assumed"
    mission_id: int | None = None
    meta: dict[str, object] = field(default_factory=dict)
    vehicle_name: str | None = None
    net_digest: str | None = None

    @property
    def start(self) -> float:
        """Time zero of the plots: the first command sent, as in the paper, else the first
        event or sample (controller clock)."""
        for time, source, event in self.events:
            if source == CONTROLLER and event.kind == "command-sent":
                return time
        firsts = [self.events[0][0]] if self.events else []
        if self.samples:
            firsts.append(self.samples[0][0])
        return min(firsts, default=0.0)

    @property
    def end(self) -> float:
        """The last event or sample (controller clock)."""
        lasts = [self.events[-1][0]] if self.events else []
        if self.samples:
            lasts.append(self.samples[-1][0])
        return max(lasts, default=self.start)

    @property
    def ended(self) -> bool:
        """Whether the controller logged the mission's end (a live or killed run has not)."""
        return any(s == CONTROLLER and e.kind == "mission-end" for _, s, e in self.events)

    def to_controller(self, vehicle_time: float) -> float:
        """A vehicle-clock time on the controller's clock (see the module doc)."""
        return _converter(self.offsets, self.rate)(vehicle_time)


# --- merging ---------------------------------------------------------------------------------


@dataclass
class _Loaded:
    path: Path
    role: str
    mission: str
    events: list[Event]
    samples: list[TelemetryRecord]
    meta: dict[str, object]
    net_json: str | None
    net_digest: str | None
    checkpoint: dict[str, object] | None


def _load(path: Path) -> _Loaded:
    with EventLog.open(path) as log:
        try:
            checkpoint = log.checkpoint()
        except EventLogError:  # damaged: the timeline can still show what was logged
            checkpoint = None
        return _Loaded(
            path,
            log.role,
            log.mission,
            list(log.events()),
            list(log.samples()),
            dict(log.meta),
            log.net_json,
            log.net_digest,
            checkpoint,
        )


def merge_logs(paths: Sequence[str | Path]) -> MergedTimeline:
    """Merge one controller log and, optionally, one vehicle log (in any order).

    The vehicle log's ``mission`` may be the controller's mission name or the wire
    mission id in decimal (a served vehicle knows only the id), or empty (unknown).

    Raises:
        EventLogError: no controller log, two logs of the same role, logs of different
            missions, or any log unreadable (missing, damaged).
    """
    if not paths:
        raise EventLogError("timeline: give the controller's log, and the vehicle's if you have it")
    loaded = [_load(Path(p)) for p in paths]
    by_role: dict[str, _Loaded] = {}
    for log in loaded:
        if log.role in by_role:
            raise EventLogError(
                f"{by_role[log.role].path} and {log.path} are both {log.role} logs; give one "
                "controller log and at most one vehicle log"
            )
        by_role[log.role] = log
    controller = by_role.get(CONTROLLER)
    if controller is None:
        raise EventLogError(
            f"{loaded[0].path}: a vehicle log; the timeline needs the controller's log too "
            "(it holds the handshakes that give the clock offset)"
        )
    vehicle = by_role.get(VEHICLE)
    mission_id = _mission_id(controller)
    if vehicle is not None:
        _check_same_mission(controller, vehicle, mission_id)

    offsets = sorted(
        (event.time, value)
        for event in controller.events
        if event.kind == "handshake" and (value := _number(event.data, "offset")) is not None
    )
    rate, rate_source = _clock_rate(controller, vehicle)
    to_controller = _converter(offsets, rate)

    events: list[tuple[float, str, Event]] = [(e.time, CONTROLLER, e) for e in controller.events]
    if vehicle is not None:
        events += [(to_controller(e.time), VEHICLE, e) for e in vehicle.events]
    rank = {CONTROLLER: 0, VEHICLE: 1}
    events.sort(key=lambda item: (item[0], rank[item[1]], item[2].seq))

    source: str | None = None
    raw: list[TelemetryRecord] = []
    if vehicle is not None and vehicle.samples:
        source, raw = VEHICLE, vehicle.samples
    elif controller.samples:
        source, raw = CONTROLLER, controller.samples
    samples = sorted(((to_controller(s.vehicle_time), s) for s in raw), key=lambda item: item[0])
    logs = {CONTROLLER: controller.path}
    if vehicle is not None:
        logs[VEHICLE] = vehicle.path
    return MergedTimeline(
        events=events,
        samples=samples,
        offset=offsets[0][1] if offsets else None,
        mission=controller.mission or (vehicle.mission if vehicle is not None else ""),
        offsets=offsets,
        logs=logs,
        sample_source=source,
        received_samples=len(controller.samples),
        rate=rate,
        rate_source=rate_source,
        mission_id=mission_id,
        meta=controller.meta,
        vehicle_name=_net_vehicle(controller.net_json),
        net_digest=controller.net_digest,
    )


def _mission_id(controller: _Loaded) -> int | None:
    """The wire mission id: the ``mission-start`` event's, else the checkpoint's."""
    for event in controller.events:
        if (
            event.kind == "mission-start"
            and (found := _integer(event.data, "mission_id")) is not None
        ):
            return found
    if controller.checkpoint is not None:
        return _integer(controller.checkpoint, "mission_id")
    return None


def _check_same_mission(controller: _Loaded, vehicle: _Loaded, mission_id: int | None) -> None:
    """Refuse a vehicle log of another mission. Its ``mission`` may be the controller's
    name for it, the wire id in decimal, or empty (its writer did not know it)."""
    known = {controller.mission}
    if mission_id is not None:
        known.add(str(mission_id))
    if "" in (vehicle.mission, controller.mission) or vehicle.mission in known:
        return
    ids = f" (mission_id {mission_id})" if mission_id is not None else ""
    raise EventLogError(
        f"{controller.path} is of mission {controller.mission!r}{ids} but {vehicle.path} of "
        f"mission {vehicle.mission!r}: they are not two sides of one mission"
    )


def _clock_rate(controller: _Loaded, vehicle: _Loaded | None) -> tuple[float, str]:
    """Vehicle seconds per controller second, and where that figure came from.

    A run in virtual time (controller meta ``realtime`` false) shares one clock, whatever
    ``speed`` says; otherwise a positive ``speed`` in the vehicle's, then the controller's
    meta is the simulator's pace. Without one, the replies' vehicle times against their
    arrival times show a vehicle that ran clearly fast or slow.
    """
    if controller.meta.get("realtime") is False:
        return 1.0, "virtual time"
    for log in (vehicle, controller):
        speed = None if log is None else _number(log.meta, "speed")
        if log is not None and speed is not None and speed > 0:
            return speed, f"{log.role} log's meta 'speed'"
    estimate = _estimated_rate(controller.events)
    if estimate is not None and not _RATE_BAND[0] <= estimate <= _RATE_BAND[1]:
        return estimate, "estimated from the replies"
    return 1.0, "assumed"


def _estimated_rate(events: Sequence[Event]) -> float | None:
    """Theil-Sen slope of the replies' vehicle times against their arrival times.

    The median of pairwise slopes shrugs off the link's heavy-tailed delays; only pairs at
    least a quarter of the span apart are used, so a delay is small against their distance.
    """
    pairs = sorted(
        (event.time, value)
        for event in events
        if event.kind == "reply" and (value := _number(event.data, "vehicle_time")) is not None
    )
    if len(pairs) < _RATE_MIN_REPLIES:
        return None
    step = max(1, len(pairs) // _RATE_MAX_PAIRS)
    pairs = pairs[::step]
    span = pairs[-1][0] - pairs[0][0]
    if span <= 0:
        return None
    slopes = [
        (vb - va) / (cb - ca)
        for (ca, va), (cb, vb) in itertools.combinations(pairs, 2)
        if cb - ca >= 0.25 * span
    ]
    if not slopes:
        return None
    slope = statistics.median(slopes)
    return slope if slope > 0 else None


def _net_vehicle(net_json: str | None) -> str | None:
    if net_json is None:
        return None
    try:
        net = json.loads(net_json)
    except (ValueError, RecursionError):
        return None
    vehicle = net.get("vehicle") if isinstance(net, dict) else None
    return vehicle if isinstance(vehicle, str) else None


def _converter(offsets: Sequence[tuple[float, float]], rate: float) -> Callable[[float], float]:
    """Vehicle time to controller time, from the last handshake before it (module doc)."""
    if not offsets:
        return lambda t: t
    # Each handshake on both clocks, in the vehicle's order, to find the last one before t.
    marks = sorted((time + offset, time) for time, offset in offsets)
    starts = [vehicle for vehicle, _ in marks]

    def convert(t: float) -> float:
        vehicle, controller = marks[max(bisect.bisect_right(starts, t) - 1, 0)]
        return controller + (t - vehicle) / rate

    return convert


def _number(data: dict[str, object], key: str) -> float | None:
    value = data.get(key)
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return float(value) if math.isfinite(value) else None


def _integer(data: dict[str, object], key: str) -> int | None:
    value = data.get(key)
    return value if isinstance(value, int) and not isinstance(value, bool) else None


def _text(data: dict[str, object], key: str) -> str | None:
    value = data.get(key)
    return value if isinstance(value, str) else None


# --- what the plots and the summary need ----------------------------------------------------


@dataclass
class Command:
    """One command's life on the controller's axis."""

    command_id: int
    name: str
    sent: float | None = None
    resent: list[float] = field(default_factory=list)  # after reconnects
    received: float | None = None  # by the vehicle
    issued: list[tuple[float, str]] = field(default_factory=list)  # replies, vehicle side
    replies: list[tuple[float, str]] = field(default_factory=list)  # replies, controller side
    params: dict[str, object] = field(default_factory=dict)  # as sent

    @property
    def finished(self) -> float | None:
        finals = [t for t, kind in self.replies if kind in FINAL_REPLIES]
        return min(finals) if finals else None

    @property
    def outcome(self) -> str:
        """The first final reply; else the last reply (a task's ``ack`` is its answer);
        else ``unfinished``."""
        finals = [kind for _, kind in self.replies if kind in FINAL_REPLIES]
        if finals:
            return finals[0]
        return self.replies[-1][1] if self.replies else "unfinished"


def commands_of(timeline: MergedTimeline) -> list[Command]:
    """Every command's sent, received, issued and replied times, in order of command id."""
    has_vehicle_log = VEHICLE in timeline.logs
    to_controller = _converter(timeline.offsets, timeline.rate)
    commands: dict[int, Command] = {}

    def get(command_id: int, name: str | None) -> Command:
        command = commands.setdefault(command_id, Command(command_id, name or "?"))
        if command.name == "?" and name:
            command.name = name
        return command

    for time, source, event in timeline.events:
        data = event.data
        command_id = _integer(data, "command_id")
        if command_id is None:
            continue
        name = _text(data, "name")
        if source == CONTROLLER and event.kind == "command-sent":
            command = get(command_id, name)
            if command.sent is None:
                command.sent = time
                params = data.get("params")
                if isinstance(params, dict):
                    command.params = dict(params)
            else:  # logged again for a re-send
                command.resent.append(time)
        elif source == CONTROLLER and event.kind == "command-resent":
            get(command_id, name).resent.append(time)
        elif source == CONTROLLER and event.kind == "reply":
            reply_kind = _text(data, "kind") or "?"
            command = get(command_id, name)
            command.replies.append((time, reply_kind))
            vehicle_time = _number(data, "vehicle_time")
            if not has_vehicle_log and vehicle_time is not None:
                command.issued.append((to_controller(vehicle_time), reply_kind))
        elif source == VEHICLE and event.kind == "command-received":
            command = get(command_id, name)
            if command.received is None:
                command.received = time
        elif source == VEHICLE and event.kind == "reply-issued":
            get(command_id, name).issued.append((time, _text(data, "kind") or "?"))
    return [commands[key] for key in sorted(commands)]


def telemetry_gaps(times: Sequence[float], minimum: float = 1.0) -> list[tuple[float, float]]:
    """Holes in the telemetry as ``(time of the last sample before, length)``.

    ``times`` are the samples' times in order (a merged timeline's controller-clock times).
    A hole is an interval longer than ``minimum`` seconds and three times the median interval,
    so a slow but steady rate is not reported as gaps.
    """
    steps = [b - a for a, b in itertools.pairwise(times)]
    if not steps:
        return []
    limit = max(minimum, 3.0 * statistics.median(steps))
    return [(times[i], step) for i, step in enumerate(steps) if step > limit]


# --- summary -------------------------------------------------------------------------------


def summarize(timeline: MergedTimeline) -> str:
    """A few lines: the logs, span, clock offset, events per kind, command delays, telemetry.

    Meant for the terminal after ``coral-run timeline``: enough to see at a glance whether
    both logs are there, whether the clocks were tied together, and where the link was slow
    or telemetry was lost.
    """
    start = timeline.start
    logs = ", ".join(f"{role} log {path}" for role, path in timeline.logs.items())
    lines = [f"mission {timeline.mission}: {logs}"]
    lines.append(
        f"span: {timeline.end - start:.1f} s on the controller clock; time 0 = first command "
        f"sent (controller clock {start:.3f})"
    )
    if not timeline.ended:
        lines.append(
            "not ended: no mission-end in the controller log (still running, or the "
            "controller stopped); showing what is committed so far"
        )
    if not timeline.offsets:
        clock = "no handshake in the controller log: vehicle times used as they are"
        lines.append(f"clock: {clock} (offset unknown)")
    elif len(timeline.offsets) == 1:
        lines.append(f"clock: vehicle ahead of the controller by {timeline.offsets[0][1]:.3f} s")
    else:
        values = [offset for _, offset in timeline.offsets]
        lines.append(
            f"clock: vehicle ahead by {values[0]:.3f} s at the first handshake; "
            f"{len(values)} handshakes, {min(values):.3f} .. {max(values):.3f} s "
            "(each vehicle time uses the last one before it)"
        )
    if timeline.rate != 1.0:
        lines.append(
            f"clock rate: the vehicle clock runs {timeline.rate:.3g} x the controller's "
            f"({timeline.rate_source}); vehicle times are scaled back onto the controller's"
        )
    for source in (CONTROLLER, VEHICLE):
        if source not in timeline.logs:
            continue
        counts = Counter(event.kind for _, s, event in timeline.events if s == source)
        listed = ", ".join(f"{kind} {counts[kind]}" for kind in sorted(counts)) or "none"
        lines.append(f"{source} events ({sum(counts.values())}): {listed}")
    commands = commands_of(timeline)
    if commands:
        lines.append(_command_line(commands, start))
    lines.append(_telemetry_line(timeline, start))
    return "\n".join(lines)


def _command_line(commands: Sequence[Command], start: float) -> str:
    sent = [c for c in commands if c.sent is not None]
    received = [c for c in commands if c.received is not None]
    finished = Counter(c.outcome for c in sent)
    outcome = ", ".join(f"{kind} {finished[kind]}" for kind in sorted(finished))
    resent = sum(len(c.resent) for c in commands)
    again = f", {resent} re-sends" if resent else ""
    line = f"commands: {len(sent)} sent ({outcome}{again}), {len(received)} received by the vehicle"
    delays = [
        (c.received - c.sent, c.sent, c)
        for c in commands
        if c.received is not None and c.sent is not None
    ]
    if delays:
        worst, when, command = max(delays, key=lambda item: item[0])
        median = statistics.median(delay for delay, _, _ in delays)
        line += (
            f"; sent -> received median {median:.2f} s, max {worst:.2f} s "
            f"({command.name} #{command.command_id} at {when - start:.1f} s)"
        )
    return line


def _telemetry_line(timeline: MergedTimeline, start: float) -> str:
    if not timeline.samples:
        return "telemetry: none"
    line = f"telemetry: {len(timeline.samples)} samples ({timeline.sample_source} log)"
    if timeline.sample_source == VEHICLE and CONTROLLER in timeline.logs:
        line += f", {timeline.received_samples} received by the controller"
    gaps = telemetry_gaps([time for time, _ in timeline.samples])
    if not gaps:
        return line + "; no gaps"
    shown = ", ".join(f"at {t - start:.1f} s ({length:.1f} s long)" for t, length in gaps[:5])
    more = f" and {len(gaps) - 5} more" if len(gaps) > 5 else ""
    return line + f"; {len(gaps)} gaps: {shown}{more}"


# --- plots ---------------------------------------------------------------------------------


def plot_timeline(
    timeline: MergedTimeline, out_dir: Path, context: PlotContext | None = None
) -> list[Path]:
    """Write ``events.png`` (like the paper's Fig. 5) and ``telemetry.png`` (Figs. 7-9).

    What each shows is in `runtime.timeline_plots.plot_timeline` and docs/eventlog.md.
    ``context`` (the vehicle's workspace, way-points, phases) defaults to what the logs
    and the vehicle's profile give. Returns the files written.
    """
    # Imported here: matplotlib is slow to load and only plotting needs it.
    from runtime.timeline_plots import plot_timeline as plot

    return plot(timeline, Path(out_dir), context)
