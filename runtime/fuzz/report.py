"""What a fuzz campaign shows: the text report, the histogram, a replay, the progress bar.

Text first: the report says how often the mission reached a declared final marking, how
long it took, which branches no run rehearsed, and, for every failure, the command that
replays it exactly (``--replay SEED``). The JSON report (`FuzzReport.to_json`) holds all
of it; the text shows the first of long lists and says where the rest is.
"""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path
from typing import IO

from runtime.fuzz.campaign import Coverage, FuzzReport, LinkBoundCount
from runtime.fuzz.one_run import FuzzRun, run_seed

__all__ = [
    "FAILURES_DIR",
    "HISTOGRAM",
    "NEVER_SHOWN",
    "REPORT_JSON",
    "ProgressBar",
    "format_replay",
    "format_report",
    "plot_histogram",
]

HISTOGRAM = "fuzz-histogram.png"
REPORT_JSON = "fuzz-report.json"
FAILURES_DIR = "failures"


def format_report(report: FuzzReport, command: str) -> str:
    """The text report; ``command`` is how to call fuzz again on this mission."""
    runs = report.runs
    total = len(runs)
    ok = total - len(report.failures)
    opts = report.options
    lines = [
        f"fuzz: mission '{report.mission}', {total} run(s) over link '{opts.link.name}', "
        f"run seeds {opts.seed}..{run_seed(opts.seed, max(total - 1, 0))}, engine policy "
        f"{opts.policy.value}"
        + (f" (interrupted: {opts.runs - total} runs not done)" if report.interrupted else ""),
        f"  reached a declared final marking: {ok}/{total}"
        + (f" ({100.0 * report.success_rate:.1f} %)" if total else ""),
    ]
    endings = Counter(r.ending() for r in runs)
    for ending, count in sorted(endings.items(), key=lambda item: (-item[1], item[0])):
        lines.append(f"    {count:6d}  {ending}")
    stats = report.durations()
    if stats:
        lines.append(
            f"  mission time (virtual): median {stats['median']:.1f} s, p90 {stats['p90']:.1f} s, "
            f"max {stats['max']:.1f} s"
        )
    if runs:
        lines.append("  longest runs:")
        for run in report.longest():
            lines.append(
                f"    seed {run.seed}: {run.duration:.1f} s, {run.ending()}, {_run_detail(run)}"
            )
    if runs:
        lines.append(_link_bound_line(report.link_bound(), total))
    coverage = report.coverage()
    if coverage is not None:
        lines.extend(_coverage_lines(coverage))
    failures = report.failures
    if failures:
        lines.append(f"  failures ({len(failures)}); each replays exactly with the command shown:")
        for run in failures[:20]:
            note = ""
            predicted = report.predicted(run)
            if predicted is True:
                note = " (a deadlock analysis predicts: coral-check verify reports it)"
            elif predicted is False:
                note = " (NOT among analysis's dead markings: please report this)"
            lines.append(f"    seed {run.seed}: {run.ending()} after {run.duration:.1f} s{note}")
            if run.detail:
                lines.append(f"      {run.detail}")
            lines.append(f"      {command} --replay {run.seed}")
        if len(failures) > 20:
            lines.append(f"    ... and {len(failures) - 20} more in {REPORT_JSON}")
    if report.mismatches:
        lines.append(
            f"  NOT REPRODUCIBLE ({len(report.mismatches)}): failed runs that did something "
            "else when run again here to keep their logs; a run must depend on its run seed "
            "alone, so this is a bug: please report it"
        )
        for mismatch in report.mismatches:
            lines.append(
                f"    seed {mismatch.seed}: events {mismatch.worker_digest} on the worker, "
                f"{mismatch.driver_digest} here (the log kept is this re-run)"
            )
    lines.append(
        f"  {report.wall_seconds:.1f} s wall, {report.schedules_per_second:.2f} schedules/s"
        + (f", {report.ran_on}" if report.ran_on else "")
    )
    return "\n".join(lines)


def _link_bound_line(count: LinkBoundCount, total: int) -> str:
    bound = f"the analysis bound {count.max_delay_s:.4g} s of link '{count.link}'"
    if not count.messages_over:
        return (
            f"  link: no message took longer than {bound} (longest "
            f"{count.longest_delay_s:.4g} s): every run is within what timed analysis assumes"
        )
    return (
        f"  link: {count.messages_over} of {count.messages} messages, in "
        f"{count.runs_over}/{total} run(s), took longer than {bound} (longest "
        f"{count.longest_delay_s:.4g} s): those runs are outside what timed analysis proved"
    )


NEVER_SHOWN = 20
"""At most this many never-fired transitions in the text report (all are in the JSON)."""


def _coverage_lines(coverage: Coverage) -> list[str]:
    lines = [
        f"  coverage: exercised {coverage.exercised} of {coverage.transitions} transitions "
        f"({100.0 * coverage.share:.1f} %)"
    ]
    never = coverage.never
    if not never:
        return lines
    replies = sum(n.reply is not None for n in never)
    lines.append(
        f"  never fired ({len(never)}"
        + (f", {replies} of them replies the vehicle never gave" if replies else "")
        + "): branches this campaign never rehearsed"
    )
    shown = never[:NEVER_SHOWN]
    name_width = max(len(n.transition) for n in shown)
    line_width = max(len(n.line or "-") for n in shown)
    for n in shown:
        what = (
            f"{n.command or '?'} replied {n.reply}"
            if n.reply is not None
            else (f"sends {n.command}" if n.command is not None else "")
        )
        row = f"    {n.transition:<{name_width}}  {n.line or '-':<{line_width}}  {what}"
        lines.append(row.rstrip())
    if len(never) > NEVER_SHOWN:
        lines.append(f"    ... and {len(never) - NEVER_SHOWN} more in {REPORT_JSON}")
    if replies:
        lines.append(
            "    replies a healthy simulator does not give need reply fuzzing: "
            "--vary-replies 0.05, or --fault RULE to force one (docs/fuzz.md, Coverage)"
        )
    return lines


def _run_detail(run: FuzzRun) -> str:
    return (
        f"{run.connections} connection(s), {run.commands_resent} command(s) re-sent, "
        f"{run.duplicate_replies} duplicate repl{'y' if run.duplicate_replies == 1 else 'ies'}"
    )


def plot_histogram(report: FuzzReport, path: Path) -> Path:
    """The distribution of virtual mission times, final and failed runs stacked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    good = [r.duration for r in report.runs if r.ok]
    bad = [r.duration for r in report.runs if not r.ok]
    figure, axes = plt.subplots(figsize=(7.0, 4.0))
    try:
        axes.hist(
            [good, bad],
            bins=min(40, max(5, len(report.runs) // 5)),
            stacked=True,
            color=["tab:blue", "tab:red"],
            label=[f"final marking ({len(good)})", f"other end ({len(bad)})"],
        )
        stats = report.durations()
        for name, style in (("median", "-"), ("p90", "--")):
            if name in stats:
                axes.axvline(stats[name], color="black", linestyle=style, linewidth=1, label=name)
        axes.set_xlabel("mission time (virtual seconds)")
        axes.set_ylabel("runs")
        axes.set_title(
            f"{report.mission}: {len(report.runs)} runs over '{report.options.link.name}'"
        )
        axes.legend()
        figure.tight_layout()
        figure.savefig(path, dpi=100)
    finally:
        plt.close(figure)
    return path


def format_replay(run: FuzzRun) -> str:
    """The events of one run (telemetry aside), one a line, then how it ended."""
    lines = [f"replay of run seed {run.seed}:"]
    for event in run.events:
        detail = ", ".join(f"{k}={_short(v)}" for k, v in event.data.items() if v is not None)
        lines.append(f"  t={event.time:9.3f}  {event.kind:<16} {detail}")
    lines.append(
        f"ended: {run.ending()} after {run.duration:.1f} s (virtual); {_run_detail(run)}; "
        f"events {run.events_digest}"
    )
    if run.detail:
        lines.append(f"  {run.detail}")
    return "\n".join(lines)


def _short(value: object) -> str:
    text = json.dumps(value, sort_keys=True) if isinstance(value, dict | list) else str(value)
    return text if len(text) <= 80 else text[:77] + "..."


class ProgressBar:
    """A one-line text bar on a terminal (stderr); silent when the stream is not one."""

    def __init__(self, stream: IO[str], width: int = 30) -> None:
        self._stream = stream
        self._width = width
        self._shown = False
        isatty = getattr(stream, "isatty", None)
        self.enabled = bool(isatty()) if callable(isatty) else False

    def __call__(self, done: int, total: int, failed: int) -> None:
        if not self.enabled:
            return
        filled = self._width * done // max(total, 1)
        bar = "#" * filled + "." * (self._width - filled)
        self._stream.write(f"\rfuzz [{bar}] {done}/{total} runs, {failed} failed")
        self._stream.flush()
        self._shown = True

    def close(self) -> None:
        """End the bar's line, if one was drawn."""
        if self._shown:
            self._stream.write("\n")
            self._stream.flush()
            self._shown = False
