"""Figures like the paper's 7-9: events on a time line above the vehicle's telemetry.

Each figure has, on one time axis, the commands sent and the replies received (one lane
per command name), the x and y positions (true and estimated), depth and heading; beside
them, the x-y track (true and estimated) in the pool with the way-points and the dock.
`plot_run` draws the whole run and, given phases, one figure per phase. matplotlib's Agg
backend is used, so no display is needed; each figure is written as PNG and SVG.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # the backend is chosen before pyplot loads

from romeo_sim.recorder import Recorder

__all__ = ["plot_run", "plot_window"]

_REPLY_STYLE: dict[str, tuple[str, str]] = {
    "ack": ("|", "tab:gray"),
    "done": ("o", "tab:green"),
    "timeout": ("x", "tab:red"),
    "error": ("X", "tab:red"),
}


def plot_run(
    recorder: Recorder,
    folder: str | Path,
    *,
    stem: str = "mission",
    targets: Sequence[tuple[float, float]] = (),
    dock: tuple[float, float] | None = None,
    pool: tuple[float, float] | None = None,
    phases: Sequence[tuple[str, float, float]] = (),
) -> list[Path]:
    """Draw the whole run, and one figure per phase; returns the files written.

    Args:
        recorder: the run.
        folder: where to write (created if needed).
        stem: file name of the whole-run figure, without extension.
        targets: way-points to mark on the track.
        dock: the docking point, if recorded.
        pool: (length, width) of the pool, to draw its walls.
        phases: (name, start, end) on the vehicle clock; one extra figure each.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    if not recorder.telemetry:
        raise ValueError("nothing to plot: the recorder holds no telemetry")
    start = recorder.telemetry[0].vehicle_time
    end = recorder.telemetry[-1].vehicle_time
    written = plot_window(recorder, folder / stem, start, end, "whole mission", targets, dock, pool)
    for index, (name, t0, t1) in enumerate(phases, start=1):
        slug = re.sub(r"[^a-z0-9]+", "_", name.lower()).strip("_")
        written += plot_window(
            recorder,
            folder / f"phase{index}_{slug}",
            t0,
            t1,
            f"phase {index}: {name}",
            targets,
            dock,
            pool,
        )
    return written


def plot_window(
    recorder: Recorder,
    base: Path,
    start: float,
    end: float,
    title: str,
    targets: Sequence[tuple[float, float]] = (),
    dock: tuple[float, float] | None = None,
    pool: tuple[float, float] | None = None,
) -> list[Path]:
    """One figure over [start, end] s; writes ``base``.png and ``base``.svg."""
    samples = [t for t in recorder.telemetry if start - 1e-9 <= t.vehicle_time <= end + 1e-9]
    fig = plt.figure(figsize=(13.0, 8.5))
    grid = fig.add_gridspec(5, 2, width_ratios=(2.2, 1.0), hspace=0.12, wspace=0.18)
    events_ax = fig.add_subplot(grid[0:2, 0])
    xy_ax = fig.add_subplot(grid[2, 0], sharex=events_ax)
    depth_ax = fig.add_subplot(grid[3, 0], sharex=events_ax)
    heading_ax = fig.add_subplot(grid[4, 0], sharex=events_ax)
    track_ax = fig.add_subplot(grid[:, 1])
    fig.suptitle(f"ROMEO pool mission: {title} ({start:.0f}-{end:.0f} s)")

    _draw_events(events_ax, recorder, start, end)
    times = [t.vehicle_time for t in samples]
    est = [t for t in samples if t.est_x is not None]
    est_times = [t.vehicle_time for t in est]
    est_xs = [t.est_x for t in est if t.est_x is not None]
    est_ys = [t.est_y for t in est if t.est_y is not None]
    xy_ax.plot(times, [t.x for t in samples], color="tab:blue", label="x true")
    xy_ax.plot(times, [t.y for t in samples], color="tab:orange", label="y true")
    xy_ax.plot(est_times, est_xs, "--", color="tab:blue", label="x est.")
    xy_ax.plot(est_times, est_ys, "--", color="tab:orange", label="y est.")
    xy_ax.set_ylabel("x, y [m]")
    xy_ax.legend(loc="upper left", fontsize="x-small", ncols=4)
    depth_ax.plot(times, [t.z for t in samples], color="tab:blue", label="true")
    depth_ax.plot(times, [t.est_z for t in samples], "--", color="tab:cyan", label="est.")
    depth_ax.invert_yaxis()
    depth_ax.set_ylabel("depth [m]")
    depth_ax.legend(loc="upper right", fontsize="x-small", ncols=2)
    heading_ax.plot(times, [t.psi for t in samples], ".", ms=1.5, color="tab:purple")
    heading_ax.set_ylabel("heading [deg]")
    heading_ax.set_ylim(-5, 365)
    heading_ax.set_yticks([0, 90, 180, 270, 360])
    heading_ax.set_xlabel("vehicle time [s]")
    for ax in (events_ax, xy_ax, depth_ax):
        ax.tick_params(labelbottom=False)
    for ax in (events_ax, xy_ax, depth_ax, heading_ax):
        ax.grid(True, alpha=0.3)
        ax.set_xlim(start, max(end, start + 1.0))

    _draw_track(track_ax, samples, est, targets, dock, pool)
    base.parent.mkdir(parents=True, exist_ok=True)
    paths = [base.with_suffix(".png"), base.with_suffix(".svg")]
    fig.savefig(paths[0], dpi=110, bbox_inches="tight")
    fig.savefig(paths[1], bbox_inches="tight")
    plt.close(fig)
    return paths


def _draw_events(ax: Any, recorder: Recorder, start: float, end: float) -> None:
    lanes: dict[str, int] = {}
    for command in recorder.commands:
        lanes.setdefault(command.command, len(lanes))
    for reply in recorder.replies:
        lanes.setdefault(reply.command, len(lanes))
    vehicle_lane = len(lanes)
    for command in recorder.commands:
        if start <= command.time <= end:
            ax.plot(command.time, lanes[command.command], ">", color="tab:blue", ms=6)
    seen: set[str] = set()
    for reply in recorder.replies:
        if not start <= reply.time <= end:
            continue
        marker, color = _REPLY_STYLE.get(reply.kind, ("s", "black"))
        label = reply.kind if reply.kind not in seen else None
        seen.add(reply.kind)
        ax.plot(reply.time, lanes[reply.command], marker, color=color, ms=7, label=label)
    for event in recorder.events:
        if start <= event.time <= end:
            ax.plot(event.time, vehicle_lane, "*", color="tab:olive", ms=6)
    ax.plot([], [], ">", color="tab:blue", label="command sent")
    ax.plot([], [], "*", color="tab:olive", label="vehicle event")
    ax.set_yticks(range(vehicle_lane + 1))
    ax.set_yticklabels([*lanes, "(vehicle)"], fontsize="small")
    ax.set_ylim(-0.7, vehicle_lane + 0.7)
    ax.invert_yaxis()
    ax.legend(loc="upper right", fontsize="x-small", ncols=3)
    ax.set_title("commands and replies", fontsize="small", loc="left")


def _draw_track(
    ax: Any,
    samples: Sequence[Any],
    est: Sequence[Any],
    targets: Sequence[tuple[float, float]],
    dock: tuple[float, float] | None,
    pool: tuple[float, float] | None,
) -> None:
    # North (x) up, east (y) to the right, as on a chart.
    if pool is not None:
        length, width = pool
        ax.plot([0, width, width, 0, 0], [0, 0, length, length, 0], color="black", lw=1.2)
    ax.plot([t.y for t in samples], [t.x for t in samples], color="tab:blue", label="true")
    ax.plot([t.est_y for t in est], [t.est_x for t in est], "--", color="tab:red", label="estimate")
    if samples:
        ax.plot(samples[0].y, samples[0].x, "o", color="tab:blue", ms=5)
    if targets:
        ax.plot(
            [p[1] for p in targets],
            [p[0] for p in targets],
            "s",
            mfc="none",
            color="tab:green",
            ms=9,
            label="way-points",
        )
    if dock is not None:
        ax.plot(dock[1], dock[0], "^", color="tab:purple", ms=10, label="dock")
    ax.set_aspect("equal")
    ax.set_xlabel("y, east [m]")
    ax.set_ylabel("x, north [m]")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper right", fontsize="x-small")
    ax.set_title("x-y track", fontsize="small", loc="left")
