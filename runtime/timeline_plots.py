"""Draw a merged timeline: ``events.png`` (the paper's Fig. 5) and ``telemetry.png`` (Figs. 7-9).

`runtime.timeline` merges the logs and summarises them; this module only draws. It is
imported when plotting (matplotlib is slow to load) and uses the Agg canvas attached to
each figure, so no global backend is chosen and no display is needed.

Three things keep the figures readable however long the mission:

* labels (command ids, transitions fired) are placed, not just drawn: each goes on the
  first of a few stacked levels above its lane where its rendered extent (measured with
  the Agg renderer) overlaps no label already placed, else it is left out and the lane's
  name says how many were named (`place_labels`);
* heading is drawn continuous (`continuous_heading`): each step is the shortest turn, and
  the axis is labelled in compass degrees, so a mission near north does not jump between
  0 and 360;
* the track shows the vehicle's workspace, the way-points and the phases
  (`runtime.timeline_context`), without knowing which vehicle it is.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

from runtime.eventlog import EventLogError
from runtime.telemetry import TelemetryRecord
from runtime.timeline import (
    CONTROLLER,
    DPI,
    EVENTS_FIGSIZE,
    TELEMETRY_FIGSIZE,
    Command,
    MergedTimeline,
    commands_of,
    telemetry_gaps,
)
from runtime.timeline_context import Phase, PlotContext, plot_context

__all__ = [
    "Label",
    "PlotContext",
    "continuous_heading",
    "draw_events",
    "draw_telemetry",
    "place_labels",
    "plot_timeline",
]

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
_MAX_NAMES: Final = 80  # command names above the telemetry plot: beyond this, a smear
_MAX_PHASES: Final = 16  # phases coloured apart; more could not be told apart
_MAX_NUMBERED: Final = 40  # way-points numbered on the track
_HEADING_STEPS: Final = (5.0, 10.0, 15.0, 30.0, 45.0, 90.0, 180.0, 360.0)  # divide a turn
_LABEL_GAP_PX: Final = 2.0  # free pixels kept between two labels
_MAX_LEVELS: Final = 3  # stacked label rows per lane: more reads as a wall of text
_LABEL_DX_PX: Final = 2.0  # a label starts this far right of its point...
_LABEL_DY_PX: Final = 4.0  # ...and this far above it
_PHASE_COLOURS: Final = (
    "tab:blue",
    "tab:orange",
    "tab:green",
    "tab:purple",
    "tab:brown",
    "tab:pink",
    "tab:olive",
    "tab:cyan",
)


def plot_timeline(
    timeline: MergedTimeline, out_dir: Path, context: PlotContext | None = None
) -> list[Path]:
    """Write ``events.png`` and ``telemetry.png`` into ``out_dir``; return their paths.

    ``events.png``: one lane per command name, with each command's life from sent to its
    final reply as a bar, markers for sent, received by the vehicle, replies issued (hollow)
    and received (filled: ack, done, timeout, error), a lane of transitions fired and one of
    the link (handshakes, reconnects, resets shaded until the next handshake).
    ``telemetry.png``: x and y, depth and heading against time with every command's sending
    time as a vertical line and the phases shaded, and the x-y track in phase colours with
    the estimate, the way-points and the workspace outline.

    Times are seconds from the first command sent, on the controller's clock. Sizes are
    fixed (`EVENTS_FIGSIZE`, `TELEMETRY_FIGSIZE` at `DPI`).

    Raises:
        EventLogError: the folder cannot be made or a file cannot be written.
    """
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise EventLogError(f"{out}: cannot create the plot folder: {error.strerror}") from None
    if context is None:
        context = plot_context(timeline)
    commands = commands_of(timeline)
    fig = new_figure(EVENTS_FIGSIZE)
    draw_events(fig, timeline, commands)
    written = [_save(fig, out / "events.png")]
    fig = new_figure(TELEMETRY_FIGSIZE)
    draw_telemetry(fig, timeline, commands, context)
    written.append(_save(fig, out / "telemetry.png"))
    return written


def new_figure(size: tuple[float, float]) -> Any:
    """A figure of ``size`` inches at `DPI` with its own Agg canvas."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=size, dpi=DPI)
    FigureCanvasAgg(fig)
    return fig


def _save(fig: Any, path: Path) -> Path:
    try:
        fig.savefig(path, dpi=DPI)
    except OSError as error:
        raise EventLogError(f"{path}: cannot write the plot: {error.strerror}") from None
    return path


# --- labels ------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Label:
    """A text to put above the marker at ``(x, y)`` (data coordinates)."""

    x: float
    y: float
    text: str
    size: float  # points


def place_labels(ax: Any, labels: Sequence[Label], levels: int) -> int:
    """Annotate ``ax`` with as many of ``labels`` as fit; return how many were drawn.

    Labels are taken in the order given. Each is tried on ``levels`` stacked heights just
    above its point and kept at the first where it stays inside the axes and clear of every
    label kept so far; one that fits nowhere is left out. Candidates are sized with the
    renderer's text metrics (cheap, cached per text), and each label kept is measured again
    as drawn, so tens of thousands of firings cost seconds, not minutes. The axes' limits
    and position must be final (extents are in pixels).
    """
    if not labels:
        return 0
    renderer = ax.figure.canvas.get_renderer()
    frame = ax.get_window_extent(renderer)
    points = ax.transData.transform([(label.x, label.y) for label in labels])
    kept: list[tuple[float, float, float, float]] = []  # x0, y0, x1, y1 of labels drawn
    right: dict[tuple[int, int], float] = {}  # (row pixel, level) -> right edge so far
    sizes: dict[tuple[str, float], tuple[float, float]] = {}
    drawn = 0
    for label, (px, py) in zip(labels, points, strict=True):
        for level in range(levels):
            row = (round(float(py)), level)
            x0 = float(px) + _LABEL_DX_PX
            if x0 < right.get(row, -math.inf) + _LABEL_GAP_PX:
                continue  # that level is taken here already: no need to measure
            width, height = _text_size(renderer, label.text, label.size, sizes)
            y0 = float(py) + _LABEL_DY_PX + level * _level_step(renderer, label.size, sizes)
            box = (x0, y0, x0 + width, y0 + height)
            if not _inside(box, frame) or any(_overlap(box, other) for other in kept):
                continue
            text = ax.annotate(
                label.text,
                (label.x, label.y),
                xytext=(_LABEL_DX_PX * 72.0 / DPI, (y0 - float(py)) * 72.0 / DPI),
                textcoords="offset points",
                fontsize=label.size,
                ha="left",
                va="bottom",
                annotation_clip=False,
            )
            real = text.get_window_extent(renderer)
            drawn_box = (real.x0, real.y0, real.x1, real.y1)
            if not _inside(drawn_box, frame) or any(_overlap(drawn_box, o) for o in kept):
                text.remove()  # the metrics misjudged it: never draw an overlap
                continue
            kept.append(drawn_box)
            right[row] = drawn_box[2]
            drawn += 1
            break
    return drawn


def _text_size(
    renderer: Any, text: str, size: float, cache: dict[tuple[str, float], tuple[float, float]]
) -> tuple[float, float]:
    """Width and height in pixels of one line of ``text`` as a Text artist lays it out
    (at least the height of "lp", as matplotlib pads every line)."""
    key = (text, size)
    if key not in cache:
        from matplotlib.font_manager import FontProperties

        font = FontProperties(size=size)
        width, height, _ = renderer.get_text_width_height_descent(text, font, ismath=False)
        if text != "lp":
            height = max(height, _text_size(renderer, "lp", size, cache)[1])
        cache[key] = (float(width), float(height))
    return cache[key]


def _level_step(
    renderer: Any, size: float, cache: dict[tuple[str, float], tuple[float, float]]
) -> float:
    """Pixels between two stacked label levels of font ``size``."""
    return _text_size(renderer, "Ag", size, cache)[1] + _LABEL_GAP_PX + 1.0


def _inside(box: tuple[float, float, float, float], frame: Any) -> bool:
    x0, y0, x1, y1 = box
    return bool(x0 >= frame.x0 and x1 <= frame.x1 and y0 >= frame.y0 and y1 <= frame.y1)


def _overlap(a: tuple[float, float, float, float], b: tuple[float, float, float, float]) -> bool:
    """Whether two boxes come closer than `_LABEL_GAP_PX` (so touching counts)."""
    gap = _LABEL_GAP_PX
    return a[0] < b[2] + gap and b[0] < a[2] + gap and a[1] < b[3] + gap and b[1] < a[3] + gap


# --- events.png ------------------------------------------------------------------------------


def draw_events(fig: Any, timeline: MergedTimeline, commands: Sequence[Command]) -> Any:
    """Draw the events' sequence on ``fig``; return its axes."""
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
    labels: list[Label] = []
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
            labels.append(Label(command.sent - start, y, f"#{command.command_id}", 6))
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

    fired = [(t, e) for t, s, e in timeline.events if s == CONTROLLER and e.kind == "fire"]
    fired_labels: list[Label] = []
    for time, event in fired:
        point(time, fired_lane, "transition fired", "d", "tab:olive", 4)
        transition = event.data.get("transition")
        if isinstance(transition, str) and transition:
            fired_labels.append(Label(time - start, fired_lane, transition, 5))
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
    for index, at_x in enumerate(ends):
        ax.axvline(at_x, color="black", ls="--", lw=1, label=None if index else "mission end")
    _shade_outages(ax, timeline)

    ax.set_yticks(range(len(names)))
    ax.set_ylim(-0.8, len(names) - 0.2)
    ax.invert_yaxis()
    ax.grid(True, alpha=0.3)
    ax.set_xlabel("time since the first command sent [s] (controller clock)")
    ax.set_xlim(*_x_limits(timeline))
    # Limits are final now: labels can be measured. Transitions first, they are the
    # lane's whole content; command ids are extras.
    lane_px = abs(float(ax.transData.transform((0, 0))[1] - ax.transData.transform((0, 1))[1]))
    step = _level_step(fig.canvas.get_renderer(), 5, {})
    levels = min(_MAX_LEVELS, max(1, int((lane_px - _LABEL_DY_PX) // step)))
    named = place_labels(ax, fired_labels, levels)
    place_labels(ax, labels, 1)
    if named < len(fired_labels):
        names[fired_lane] = f"fired\n{named} of {len(fired_labels)}\nnamed"
    ax.set_yticklabels(names, fontsize="small")
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="lower center", bbox_to_anchor=(0.5, 1.01), fontsize="x-small", ncols=6)
    return ax


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
        begin = min(begin, timeline.samples[0][0] - timeline.start)
    end = max(timeline.end - timeline.start, begin + 1.0)
    margin = 0.02 * (end - begin)
    return begin - margin, end + margin


# --- telemetry.png ---------------------------------------------------------------------------


def continuous_heading(values: Sequence[float]) -> list[float]:
    """Headings (degrees, any turn) made continuous, for drawing.

    Each step is the shortest turn between two readings, so crossing north never jumps by
    360; NaN (no reading) is kept. The whole series is then shifted by whole turns so the
    middle of its range lies in [-90, 270): a mission heading 350-10 is drawn as -10..10,
    one heading 80-100 or 170-190 as it is. Every value stays equal to its reading modulo
    360 (the axis is labelled modulo 360).
    """
    out: list[float] = []
    previous: float | None = None
    for value in values:
        if not math.isfinite(value):
            out.append(math.nan)
            continue
        if previous is None:
            current = value % 360.0
        else:
            turn = (value - previous) % 360.0
            current = previous + (turn - 360.0 if turn > 180.0 else turn)
        out.append(current)
        previous = current
    finite = [v for v in out if math.isfinite(v)]
    if not finite:
        return out
    middle = (min(finite) + max(finite)) / 2.0
    shift = -360.0 * math.floor((middle + 90.0) / 360.0)
    return [v + shift for v in out]


def _broken(times: Sequence[float], values: Sequence[float]) -> tuple[list[float], list[float]]:
    """Times and values with NaN at each telemetry gap, so lines are not drawn across it."""
    gaps = {t for t, _ in telemetry_gaps(times)}
    out_times: list[float] = []
    out: list[float] = []
    for time, value in zip(times, values, strict=True):
        out_times.append(time)
        out.append(value)
        if time in gaps:
            out_times.append(time)
            out.append(math.nan)
    return out_times, out


def draw_telemetry(
    fig: Any, timeline: MergedTimeline, commands: Sequence[Command], context: PlotContext
) -> dict[str, Any]:
    """Draw the telemetry on ``fig``; return its axes by name (xy, depth, heading, track)."""
    start = timeline.start
    sample_times = [time for time, _ in timeline.samples]
    samples = [sample for _, sample in timeline.samples]
    grid = fig.add_gridspec(
        3, 2, width_ratios=(2.2, 1.0), left=0.07, right=0.97, top=0.92, bottom=0.07, hspace=0.1
    )
    xy_ax = fig.add_subplot(grid[0, 0])
    depth_ax = fig.add_subplot(grid[1, 0], sharex=xy_ax)
    heading_ax = fig.add_subplot(grid[2, 0], sharex=xy_ax)
    track_ax = fig.add_subplot(grid[:, 1])
    source = f"{timeline.sample_source} log" if timeline.sample_source else "no telemetry"
    fig.suptitle(f"mission {timeline.mission}: telemetry ({source})", fontsize="medium")

    def series(value: Callable[[TelemetryRecord], float | None]) -> list[float]:
        return [math.nan if (got := value(s)) is None else got for s in samples]

    def shifted(values: Sequence[float]) -> tuple[list[float], list[float]]:
        times, out = _broken(sample_times, values)
        return [t - start for t in times], out

    xy_ax.plot(*shifted(series(lambda s: s.x)), color="tab:blue", label="x (north)")
    xy_ax.plot(*shifted(series(lambda s: s.y)), color="tab:orange", label="y (east)")
    xy_ax.plot(*shifted(series(lambda s: s.est_x)), "--", color="tab:blue", label="x est.")
    xy_ax.plot(*shifted(series(lambda s: s.est_y)), "--", color="tab:orange", label="y est.")
    xy_ax.set_ylabel("x, y [m]")
    depth_ax.plot(*shifted(series(lambda s: s.z)), color="tab:blue")
    depth_ax.invert_yaxis()
    depth_ax.set_ylabel("depth [m]")
    heading = continuous_heading(series(lambda s: s.psi))
    heading_ax.plot(*shifted(heading), color="tab:purple", lw=1.0)
    _heading_axis(heading_ax, heading)
    heading_ax.set_xlabel("time since the first command sent [s] (controller clock)")

    for index, phase in enumerate(_drawn_phases(context)):
        colour = _PHASE_COLOURS[index % len(_PHASE_COLOURS)]
        for ax in (xy_ax, depth_ax, heading_ax):
            ax.axvspan(phase.start - start, phase.end - start, color=colour, alpha=0.07, lw=0)
    sent = [c.sent - start for c in commands if c.sent is not None]
    for ax in (xy_ax, depth_ax, heading_ax):
        # One collection per axes: thousands of commands must not mean thousands of artists.
        ax.vlines(
            sent,
            0.0,
            1.0,
            transform=ax.get_xaxis_transform(),
            color="dimgray",
            lw=0.7,
            alpha=0.6,
            ls=":",
        )
        ax.grid(True, alpha=0.3)
    if len(sent) <= _MAX_NAMES:
        for command in commands:
            if command.sent is None:
                continue
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
    _draw_track(track_ax, timeline.samples, context)
    return {"xy": xy_ax, "depth": depth_ax, "heading": heading_ax, "track": track_ax}


def _drawn_phases(context: PlotContext) -> tuple[Phase, ...]:
    """The phases to colour: none when there are too many to tell apart (a long survey's
    legs), rather than a legend of hundreds of entries."""
    return context.phases if len(context.phases) <= _MAX_PHASES else ()


def _heading_axis(ax: Any, heading: Sequence[float]) -> None:
    """Limits around the data, ticks at compass-friendly steps, labels in 0-360."""
    from matplotlib.ticker import FuncFormatter, MultipleLocator

    finite = [v for v in heading if math.isfinite(v)]
    low, high = (min(finite), max(finite)) if finite else (0.0, 360.0)
    pad = max(5.0, 0.05 * (high - low))
    ax.set_ylim(low - pad, high + pad)
    span = high - low + 2 * pad
    step = next((s for s in _HEADING_STEPS if span / s <= 8), 360.0 * math.ceil(span / 2880.0))
    ax.yaxis.set_major_locator(MultipleLocator(step))
    ax.yaxis.set_major_formatter(FuncFormatter(lambda value, _: f"{value % 360.0:g}"))
    ax.set_ylabel("heading [deg]")


def _draw_track(
    ax: Any, timed: Sequence[tuple[float, TelemetryRecord]], context: PlotContext
) -> None:
    """North (x) up, east (y) to the right, as on a chart."""
    samples = [sample for _, sample in timed]
    from matplotlib.patches import Rectangle

    space = context.workspace
    if space is not None:
        ax.add_patch(
            Rectangle(
                (space.y_min, space.x_min),
                space.y_max - space.y_min,
                space.x_max - space.x_min,
                fill=False,
                ec="black",
                lw=1.2,
                label="workspace (profile)",
            )
        )
    phases = _drawn_phases(context)
    if phases and samples:
        times = [time for time, _ in timed]
        for index, phase in enumerate(phases):
            first = bisect.bisect_left(times, phase.start)
            last = bisect.bisect_right(times, phase.end)
            part = samples[max(first - 1, 0) : last]  # joined to the previous phase's end
            if part:
                ax.plot(
                    [s.y for s in part],
                    [s.x for s in part],
                    color=_PHASE_COLOURS[index % len(_PHASE_COLOURS)],
                    label=phase.name,
                )
    else:
        ax.plot([s.y for s in samples], [s.x for s in samples], color="tab:blue", label="true")
    estimated = [s for s in samples if s.est_x is not None and s.est_y is not None]
    ax.plot(
        [s.est_y for s in estimated],
        [s.est_x for s in estimated],
        "--",
        color="tab:red",
        lw=0.8,
        label="estimate",
    )
    if samples:
        ax.plot(samples[0].y, samples[0].x, "o", color="black", ms=5, label="start")
    if context.waypoints:
        ax.plot(
            [w.y for w in context.waypoints],
            [w.x for w in context.waypoints],
            "X",
            ls="none",
            color="black",
            ms=6,
            label="way-points",
        )
        numbers: dict[tuple[float, float], list[str]] = {}
        for index, waypoint in enumerate(context.waypoints, start=1):
            numbers.setdefault((waypoint.x, waypoint.y), []).append(str(index))
        if len(numbers) > _MAX_NUMBERED:
            numbers.clear()  # a survey of hundreds of points: the crosses say enough
        for (x, y), listed in numbers.items():
            ax.annotate(
                ",".join(listed),
                (y, x),
                xytext=(4, 4),
                textcoords="offset points",
                fontsize=6,
            )
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="upper right", fontsize="x-small")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("y, east [m]")
    ax.set_ylabel("x, north [m]")
    ax.grid(True, alpha=0.3)
    title = "x-y track"
    if phases and context.phase_source == "mission":
        title += " by phase (mission files)"
    elif phases and context.phase_source == "way-points":
        title += " by leg"
    ax.set_title(title, fontsize="small", loc="left")
