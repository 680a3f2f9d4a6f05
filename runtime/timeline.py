"""Merge the controller's and the vehicle's event logs on one clock, plot and summarise them.

This is the paper's off-line analysis (section IV): "the events' sequence, including the
corresponding timestamps, has been recorded by both the Romeo Supervisor HCI and CORAL
engine machines. The logged data have been merged off-line", with the INIT handshake giving
the offset between the two clocks. `merge_logs` does the merge, `plot_timeline` draws the
events' sequence (like Fig. 5) and the telemetry (like Figs. 7-9), `summarize` says in a
few lines what is in them; ``coral-run timeline LOG...`` (`runtime.cli`) calls the three.

Clocks. Every log is timed by its writer's own clock. The controller logs a ``handshake``
event on every connection, whose ``offset`` is `runtime.protocol.ClockSync.vehicle_ahead`
(vehicle clock minus controller clock, built on the paper's t_offset formula). A vehicle
time ``t_v`` is put on the controller's axis as ``t_v - offset``, using the last handshake
made before ``t_v`` (the first one for anything earlier), so each reconnect's fresh
estimate applies from then on. Telemetry samples are always vehicle-timed, whichever log
holds them, and are converted the same way. Without any handshake vehicle times are taken
as they are and the summary says so.
"""

from __future__ import annotations

import bisect
import dataclasses
import itertools
import math
import statistics
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

from runtime.eventlog import Event, EventLog, EventLogError, TelemetrySample

__all__ = [
    "DPI",
    "EVENTS_FIGSIZE",
    "TELEMETRY_FIGSIZE",
    "MergedTimeline",
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

_LINK_KINDS: Final = frozenset(
    {
        "connect",
        "disconnect",
        "handshake",
        "reconnect",
        "reset",
        "resume",
        "rejected",
        "telemetry-lost",
        "telemetry-rejected",
    }
)
_RESTART_KINDS: Final = frozenset({"reset", "resume"})  # the controller restarted
_REPLY_STYLE: Final[dict[str, tuple[str, str]]] = {
    "ack": ("|", "tab:gray"),
    "done": ("o", "tab:green"),
    "timeout": ("x", "tab:red"),
    "error": ("X", "tab:red"),
}
_PLOTTED_KINDS: Final = frozenset(
    {
        "fire",
        "command-sent",
        "command-resent",
        "reply",
        "reply-ack",
        "command-received",
        "reply-issued",
    }
)
_FINAL_REPLIES: Final = frozenset({"done", "timeout", "error"})
_MAX_LABELS: Final = 80  # beyond this many commands, labels would only cover each other


@dataclass(frozen=True)
class MergedTimeline:
    """Both logs of one mission on the controller's clock.

    Attributes:
        events: ``(time, source, event)`` sorted by time, ``time`` on the controller's
            clock, ``source`` ``"controller"`` or ``"vehicle"``; ``event`` is as logged
            (a vehicle event keeps its own clock in ``event.time``).
        samples: telemetry on the controller's clock, sorted by time: the vehicle log's
            (every sample sent) when it has any, else those the controller received.
        offset: the first handshake's offset (vehicle clock minus controller clock, the
            INIT estimate of the paper), or None when the controller logged no handshake.
        mission: the mission both logs belong to.
        offsets: every handshake as ``(controller time, offset)``, in time order.
        logs: the file of each source.
        sample_source: which log ``samples`` came from (None: no telemetry at all).
        received_samples: how many samples the controller's log holds (datagrams that
            arrived), to compare with the vehicle's.
    """

    events: list[tuple[float, str, Event]]
    samples: list[TelemetrySample]
    offset: float | None
    mission: str
    offsets: list[tuple[float, float]] = field(default_factory=list)
    logs: dict[str, Path] = field(default_factory=dict)
    sample_source: str | None = None
    received_samples: int = 0

    @property
    def start(self) -> float:
        """Time zero of the plots: the first command sent, as in the paper, else the first
        event or sample (controller clock)."""
        for time, source, event in self.events:
            if source == CONTROLLER and event.kind == "command-sent":
                return time
        firsts = [self.events[0][0]] if self.events else []
        if self.samples:
            firsts.append(self.samples[0].time)
        return min(firsts, default=0.0)

    @property
    def end(self) -> float:
        """The last event or sample (controller clock)."""
        lasts = [self.events[-1][0]] if self.events else []
        if self.samples:
            lasts.append(self.samples[-1].time)
        return max(lasts, default=self.start)


# --- merging ---------------------------------------------------------------------------------


@dataclass
class _Loaded:
    path: Path
    role: str
    mission: str
    events: list[Event]
    samples: list[TelemetrySample]


def _load(path: Path) -> _Loaded:
    with EventLog.open(path) as log:
        return _Loaded(path, log.role, log.mission, list(log.events()), list(log.samples()))


def merge_logs(paths: Sequence[str | Path]) -> MergedTimeline:
    """Merge one controller log and, optionally, one vehicle log (in any order).

    Raises:
        EventLogError: no controller log, two logs of the same role, logs of different
            missions, or any log unreadable (missing, damaged, still being written).
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
    # An empty mission means its writer did not know it (a vehicle knows only the wire id).
    if (
        vehicle is not None
        and "" not in (vehicle.mission, controller.mission)
        and (vehicle.mission != controller.mission)
    ):
        raise EventLogError(
            f"{controller.path} is of mission {controller.mission!r} but {vehicle.path} of "
            f"mission {vehicle.mission!r}: they are not two sides of one mission"
        )

    offsets = sorted(
        (event.time, value)
        for event in controller.events
        if event.kind == "handshake" and (value := _number(event.data, "offset")) is not None
    )
    to_controller = _converter(offsets)

    events: list[tuple[float, str, Event]] = [(e.time, CONTROLLER, e) for e in controller.events]
    if vehicle is not None:
        events += [(to_controller(e.time), VEHICLE, e) for e in vehicle.events]
    rank = {CONTROLLER: 0, VEHICLE: 1}
    events.sort(key=lambda item: (item[0], rank[item[1]], item[2].seq))

    source: str | None = None
    raw: list[TelemetrySample] = []
    if vehicle is not None and vehicle.samples:
        source, raw = VEHICLE, vehicle.samples
    elif controller.samples:
        source, raw = CONTROLLER, controller.samples
    samples = sorted(
        (dataclasses.replace(s, time=to_controller(s.time)) for s in raw), key=lambda s: s.time
    )
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
    )


def _converter(offsets: Sequence[tuple[float, float]]) -> Callable[[float], float]:
    """Vehicle time to controller time, with the last handshake before it (see module doc)."""
    if not offsets:
        return lambda t: t
    # Each handshake's moment on the vehicle clock, to find the last one before a vehicle time.
    marks = sorted((time + offset, offset) for time, offset in offsets)
    starts = [mark for mark, _ in marks]

    def convert(t: float) -> float:
        index = max(bisect.bisect_right(starts, t) - 1, 0)
        return t - marks[index][1]

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
class _Command:
    """One command's life on the controller's axis."""

    command_id: int
    name: str
    sent: float | None = None
    resent: list[float] = field(default_factory=list)  # after reconnects
    received: float | None = None  # by the vehicle
    issued: list[tuple[float, str]] = field(default_factory=list)  # replies, vehicle side
    replies: list[tuple[float, str]] = field(default_factory=list)  # replies, controller side

    @property
    def finished(self) -> float | None:
        finals = [t for t, kind in self.replies if kind in _FINAL_REPLIES]
        return min(finals) if finals else None


def _commands(timeline: MergedTimeline) -> list[_Command]:
    """Every command's sent, received, issued and replied times, in order of command id."""
    has_vehicle_log = VEHICLE in timeline.logs
    to_controller = _converter(timeline.offsets)
    commands: dict[int, _Command] = {}

    def get(command_id: int, name: str | None) -> _Command:
        command = commands.setdefault(command_id, _Command(command_id, name or "?"))
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


def telemetry_gaps(
    samples: Sequence[TelemetrySample], minimum: float = 1.0
) -> list[tuple[float, float]]:
    """Holes in the telemetry as ``(time of the last sample before, length)``.

    A hole is an interval longer than ``minimum`` seconds and three times the median interval,
    so a slow but steady rate is not reported as gaps.
    """
    times = [s.time for s in samples]
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
    for source in (CONTROLLER, VEHICLE):
        if source not in timeline.logs:
            continue
        counts = Counter(event.kind for _, s, event in timeline.events if s == source)
        listed = ", ".join(f"{kind} {counts[kind]}" for kind in sorted(counts)) or "none"
        lines.append(f"{source} events ({sum(counts.values())}): {listed}")
    commands = _commands(timeline)
    if commands:
        lines.append(_command_line(commands, start))
    lines.append(_telemetry_line(timeline, start))
    return "\n".join(lines)


def _command_line(commands: Sequence[_Command], start: float) -> str:
    sent = [c for c in commands if c.sent is not None]
    received = [c for c in commands if c.received is not None]
    finished = Counter(
        next((kind for _, kind in c.replies if kind in _FINAL_REPLIES), "unfinished") for c in sent
    )
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
    gaps = telemetry_gaps(timeline.samples)
    if not gaps:
        return line + "; no gaps"
    shown = ", ".join(f"at {t - start:.1f} s ({length:.1f} s long)" for t, length in gaps[:5])
    more = f" and {len(gaps) - 5} more" if len(gaps) > 5 else ""
    return line + f"; {len(gaps)} gaps: {shown}{more}"


# --- plots ---------------------------------------------------------------------------------


def plot_timeline(timeline: MergedTimeline, out_dir: Path) -> list[Path]:
    """Write ``events.png`` (like the paper's Fig. 5) and ``telemetry.png`` (Figs. 7-9).

    ``events.png``: one lane per command name, with each command's life from sent to its
    final reply as a bar, markers for sent, received by the vehicle, replies issued (hollow)
    and received (filled: ack, done, timeout, error), a lane of transitions fired and one of
    the link (handshakes, reconnects, resets shaded until the next handshake).
    ``telemetry.png``: x and y, depth and heading against time with every command's sending
    time as a vertical line, and the x-y track, true and estimated.

    Times are seconds from the first command sent, on the controller's clock. Sizes are
    fixed (`EVENTS_FIGSIZE`, `TELEMETRY_FIGSIZE` at `DPI`). Returns the files written.
    """
    # Imported here: matplotlib is slow to load and only plotting needs it. The Agg canvas
    # is attached to each figure, so no global backend is chosen and no display is needed.
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise EventLogError(f"{out}: cannot create the plot folder: {error.strerror}") from None
    commands = _commands(timeline)
    written = []

    fig = Figure(figsize=EVENTS_FIGSIZE, dpi=DPI)
    FigureCanvasAgg(fig)
    _draw_events(fig, timeline, commands)
    written.append(_save(fig, out / "events.png"))

    fig = Figure(figsize=TELEMETRY_FIGSIZE, dpi=DPI)
    FigureCanvasAgg(fig)
    _draw_telemetry(fig, timeline, commands)
    written.append(_save(fig, out / "telemetry.png"))
    return written


def _save(fig: Any, path: Path) -> Path:
    try:
        fig.savefig(path, dpi=DPI)
    except OSError as error:
        raise EventLogError(f"{path}: cannot write the plot: {error.strerror}") from None
    return path


def _draw_events(fig: Any, timeline: MergedTimeline, commands: Sequence[_Command]) -> None:
    start = timeline.start
    ax = fig.add_axes((0.11, 0.1, 0.86, 0.72))
    fig.suptitle(f"mission {timeline.mission}: events' sequence", fontsize="medium")
    lanes: dict[str, int] = {}
    for command in commands:
        lanes.setdefault(command.name, len(lanes))
    fired_lane = len(lanes)
    link_lane = fired_lane + 1
    other_lane = fired_lane + 2
    names = [*lanes, "fired", "link"]
    if any(
        e.kind not in _PLOTTED_KINDS | _LINK_KINDS | {"mission-end"} for _, _, e in timeline.events
    ):
        names.append("other")

    # Points are gathered per style and drawn with one call each: a long mission has tens of
    # thousands of firings, and one matplotlib call per point would take minutes.
    points: dict[tuple[str, str, str, float], tuple[list[float], list[float]]] = {}

    def point(t: float, y: float, label: str, marker: str, color: str, size: float) -> None:
        xs, ys = points.setdefault((label, marker, color, size), ([], []))
        xs.append(t - start)
        ys.append(y)

    bars: tuple[list[float], list[float], list[float]] = ([], [], [])
    labels: list[tuple[float, float, str, int]] = []  # x, y, text, font size
    for command in commands:
        y = lanes[command.name]
        begin = command.sent if command.sent is not None else command.received
        end = command.finished or max((t for t, _ in command.replies), default=begin)
        if begin is not None and end is not None and end > begin:
            bars[0].append(y)
            bars[1].append(begin - start)
            bars[2].append(end - start)
        if command.sent is not None:
            point(command.sent, y, "sent", ">", "tab:blue", 6)
            labels.append((command.sent - start, y, f"#{command.command_id}", 6))
        for time in command.resent:
            point(time, y, "re-sent", ">", "tab:cyan", 5)
        if command.received is not None:
            point(command.received, y, "received by vehicle", "v", "navy", 5)
        for time, kind in command.issued:
            marker, color = _REPLY_STYLE.get(kind, ("s", "black"))
            point(time, y + 0.18, "reply issued (vehicle)", marker, color, -5)
        for time, kind in command.replies:
            marker, color = _REPLY_STYLE.get(kind, ("s", "black"))
            point(time, y, f"reply {kind}", marker, color, 7)
    if len(labels) > _MAX_LABELS:
        labels.clear()

    fired = [(t, e) for t, s, e in timeline.events if s == CONTROLLER and e.kind == "fire"]
    for time, event in fired:
        point(time, fired_lane, "transition fired", "d", "tab:olive", 4)
        transition = _text(event.data, "transition")
        if transition and len(fired) <= _MAX_LABELS:
            labels.append((time - start, fired_lane, transition, 5))
    ends: list[float] = []
    for time, source, event in timeline.events:
        if event.kind in _LINK_KINDS:
            marker = "*" if event.kind == "handshake" else "."
            color = "tab:purple" if source == CONTROLLER else "tab:pink"
            point(time, link_lane, f"{source} link", marker, color, 6)
        elif event.kind == "mission-end":
            ends.append(time - start)
        elif event.kind not in _PLOTTED_KINDS:
            point(time, other_lane, "other event", ".", "tab:brown", 4)

    if bars[0]:
        ax.hlines(*bars, color="tab:blue", alpha=0.25, lw=5)
    shown: set[str] = set()
    for (label, marker, color, size), (xs, ys) in points.items():
        hollow = size < 0  # vehicle-side replies: hollow, one legend entry for all kinds
        ax.plot(
            xs,
            ys,
            marker,
            ls="none",
            color=color,
            mfc="none" if hollow else color,
            ms=abs(size),
            alpha=0.8 if hollow else 1.0,
            label=None if label in shown or hollow else label,
        )
        shown.add(label)
    if "reply issued (vehicle)" in shown:
        ax.plot([], [], "o", mfc="none", color="tab:gray", label="reply issued (vehicle)")
    for at_x, at_y, text, size in labels:
        rotation = 45 if size == 5 else 0
        ax.annotate(
            text,
            (at_x, at_y),
            xytext=(0, 7 if size == 6 else 6),
            textcoords="offset points",
            fontsize=size,
            ha="center" if rotation == 0 else "left",
            rotation=rotation,
        )
    for index, at_x in enumerate(ends):
        ax.axvline(at_x, color="black", ls="--", lw=1, label=None if index else "mission end")
    _shade_outages(ax, timeline)

    ax.set_yticks(range(len(names)))
    ax.set_yticklabels(names, fontsize="small")
    ax.set_ylim(-0.8, len(names) - 0.2)
    ax.invert_yaxis()
    ax.grid(True, alpha=0.3)
    ax.set_xlabel("time since the first command sent [s] (controller clock)")
    ax.set_xlim(*_x_limits(timeline))
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="lower center", bbox_to_anchor=(0.5, 1.01), fontsize="x-small", ncols=6)


def _shade_outages(ax: Any, timeline: MergedTimeline) -> None:
    """Shade the link's outages: each reconnect until the next handshake, and each controller
    restart (reset, resume) from the last event it logged before until the next handshake."""
    controller = [(t, e) for t, s, e in timeline.events if s == CONTROLLER]
    handshakes = [t for t, e in controller if e.kind == "handshake"]
    span = max(timeline.end - timeline.start, 1.0)
    shown: set[str] = set()
    for index, (time, event) in enumerate(controller):
        if event.kind == "reconnect":
            begin, color, label = time, "tab:orange", "reconnect"
        elif event.kind in _RESTART_KINDS:
            begin = controller[index - 1][0] if index > 0 else time
            color, label = "tab:red", "controller restart"
        else:
            continue
        later = bisect.bisect_left(handshakes, time)
        until = handshakes[later] if later < len(handshakes) else time + 0.01 * span
        until = max(until, begin + 0.003 * span)  # always visible
        start = timeline.start
        ax.axvspan(
            begin - start,
            until - start,
            color=color,
            alpha=0.18,
            lw=0,
            label=None if label in shown else label,
        )
        shown.add(label)


def _x_limits(timeline: MergedTimeline) -> tuple[float, float]:
    begin = min(
        0.0, (timeline.events[0][0] if timeline.events else timeline.start) - timeline.start
    )
    if timeline.samples:
        begin = min(begin, timeline.samples[0].time - timeline.start)
    end = max(timeline.end - timeline.start, begin + 1.0)
    margin = 0.02 * (end - begin)
    return begin - margin, end + margin


def _broken(
    samples: Sequence[TelemetrySample], value: Callable[[TelemetrySample], float | None]
) -> tuple[list[float], list[float]]:
    """Times and values with NaN at each telemetry gap, so lines are not drawn across it."""
    gaps = {t for t, _ in telemetry_gaps(samples)}
    times: list[float] = []
    values: list[float] = []
    for sample in samples:
        got = value(sample)
        times.append(sample.time)
        values.append(math.nan if got is None else got)
        if sample.time in gaps:
            times.append(sample.time)
            values.append(math.nan)
    return times, values


def _draw_telemetry(fig: Any, timeline: MergedTimeline, commands: Sequence[_Command]) -> None:
    start = timeline.start
    samples = timeline.samples
    grid = fig.add_gridspec(
        3, 2, width_ratios=(2.2, 1.0), left=0.07, right=0.97, top=0.92, bottom=0.07, hspace=0.1
    )
    xy_ax = fig.add_subplot(grid[0, 0])
    depth_ax = fig.add_subplot(grid[1, 0], sharex=xy_ax)
    heading_ax = fig.add_subplot(grid[2, 0], sharex=xy_ax)
    track_ax = fig.add_subplot(grid[:, 1])
    source = f"{timeline.sample_source} log" if timeline.sample_source else "no telemetry"
    fig.suptitle(f"mission {timeline.mission}: telemetry ({source})", fontsize="medium")

    def shifted(
        value: Callable[[TelemetrySample], float | None],
    ) -> tuple[list[float], list[float]]:
        times, values = _broken(samples, value)
        return [t - start for t in times], values

    xy_ax.plot(*shifted(lambda s: s.x), color="tab:blue", label="x (north)")
    xy_ax.plot(*shifted(lambda s: s.y), color="tab:orange", label="y (east)")
    xy_ax.plot(*shifted(lambda s: s.est_x), "--", color="tab:blue", label="x est.")
    xy_ax.plot(*shifted(lambda s: s.est_y), "--", color="tab:orange", label="y est.")
    xy_ax.set_ylabel("x, y [m]")
    depth_ax.plot(*shifted(lambda s: s.z), color="tab:blue")
    depth_ax.invert_yaxis()
    depth_ax.set_ylabel("depth [m]")
    heading_ax.plot(*shifted(lambda s: s.psi), ".", ms=1.5, color="tab:purple")
    heading_ax.set_ylabel("heading [deg]")
    heading_ax.set_ylim(-5, 365)
    heading_ax.set_yticks([0, 90, 180, 270, 360])
    heading_ax.set_xlabel("time since the first command sent [s] (controller clock)")

    sent = [c for c in commands if c.sent is not None]
    for ax in (xy_ax, depth_ax, heading_ax):
        for command in sent:
            assert command.sent is not None
            ax.axvline(command.sent - start, color="dimgray", lw=0.7, alpha=0.6, ls=":")
        ax.grid(True, alpha=0.3)
    if len(sent) <= _MAX_LABELS:
        for command in sent:
            assert command.sent is not None
            xy_ax.annotate(
                command.name,
                (command.sent - start, 1.0),
                xycoords=("data", "axes fraction"),
                fontsize=5,
                rotation=90,
                va="bottom",
                ha="center",
            )
    for ax in (xy_ax, depth_ax):
        ax.tick_params(labelbottom=False)
    xy_ax.set_xlim(*_x_limits(timeline))
    if samples:
        xy_ax.legend(loc="lower left", fontsize="x-small", ncols=4)
    else:
        xy_ax.text(0.5, 0.5, "no telemetry in the logs", transform=xy_ax.transAxes, ha="center")

    # North (x) up, east (y) to the right, as on a chart.
    track_ax.plot([s.y for s in samples], [s.x for s in samples], color="tab:blue", label="true")
    estimated = [s for s in samples if s.est_x is not None and s.est_y is not None]
    track_ax.plot(
        [s.est_y for s in estimated],
        [s.est_x for s in estimated],
        "--",
        color="tab:red",
        label="estimate",
    )
    if samples:
        track_ax.plot(samples[0].y, samples[0].x, "o", color="tab:blue", ms=5, label="start")
        track_ax.legend(loc="upper right", fontsize="x-small")
    track_ax.set_aspect("equal", adjustable="datalim")
    track_ax.set_xlabel("y, east [m]")
    track_ax.set_ylabel("x, north [m]")
    track_ax.grid(True, alpha=0.3)
    track_ax.set_title("x-y track", fontsize="small", loc="left")
