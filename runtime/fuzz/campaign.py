"""Many fuzz runs: run ``i`` of ``--seed S`` has run seed ``S + i``, and what they add up to.

`fuzz` runs a campaign, in this process, in local worker processes or on a Ray cluster
(`runtime.fuzz.on_ray`), the same runs wherever (Ctrl-C stops it early, keeping the runs
so far); `FuzzReport` holds the runs and the figures drawn from them: the share that
reached a declared final marking, the virtual mission times, which of the net's
transitions the runs fired (`Coverage`, with the branches never rehearsed as
`NeverFired`), and, for deadlocked runs, whether analysis predicts their dead marking.
"""

from __future__ import annotations

import math
import multiprocessing
import statistics
import time
from collections import Counter
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from analysis.certificate import CertificateCheck
from coral_lang.net import Net, TransitionKind
from runtime.controller import RunEnd
from runtime.fuzz.one_run import FuzzOptions, FuzzRun, run_one, run_seed

if TYPE_CHECKING:
    from runtime.fuzz.on_ray import RayTarget, ReplayMismatch

__all__ = [
    "Coverage",
    "FuzzReport",
    "LinkBoundCount",
    "NeverFired",
    "Progress",
    "fuzz",
    "predicted_deadlocks",
]


@dataclass(frozen=True)
class NeverFired:
    """A transition no run fired: a branch of the mission the campaign never rehearsed.

    Attributes:
        transition: its name (a reply transition is ``COMMAND_TRANSITION.KIND``).
        line: ``file:line`` of the mission text that made it (None: no source, e.g. PNML).
        command: the vehicle command it sends (command transitions) or answers (reply
            transitions); None for a plain transition.
        reply: the reply kind, for a reply transition; else None.
    """

    transition: str
    line: str | None
    command: str | None
    reply: str | None

    def describe(self) -> str:
        """E.g. ``check_depth.timeout (pool.coral:30): DEPTH? replied timeout``."""
        where = f" ({self.line})" if self.line else ""
        if self.reply is not None:
            return f"{self.transition}{where}: {self.command or '?'} replied {self.reply}"
        if self.command is not None:
            return f"{self.transition}{where}: sends {self.command}"
        return f"{self.transition}{where}"

    def to_json(self) -> dict[str, object]:
        """JSON-ready form."""
        return {
            "transition": self.transition,
            "line": self.line,
            "command": self.command,
            "reply": self.reply,
        }


@dataclass(frozen=True)
class Coverage:
    """Which of the net's transitions the runs fired, summed over all runs.

    Attributes:
        transitions: how many transitions the net has.
        fired: transition -> times fired over all runs (fired ones only, in net order).
        never: the transitions no run fired, in net order.
    """

    transitions: int
    fired: Mapping[str, int]
    never: tuple[NeverFired, ...]

    @property
    def exercised(self) -> int:
        """How many transitions fired at least once."""
        return len(self.fired)

    @property
    def share(self) -> float:
        """``exercised / transitions`` (1 for a net without transitions)."""
        return self.exercised / self.transitions if self.transitions else 1.0

    @classmethod
    def of(cls, net: Net, runs: Iterable[FuzzRun]) -> Coverage:
        """The coverage of ``runs`` of ``net``."""
        totals: Counter[str] = Counter()
        for run in runs:
            totals.update(run.fired)
        fired = {t.name: totals[t.name] for t in net.transitions if totals[t.name]}
        never = tuple(_never_fired(net, t.name) for t in net.transitions if t.name not in fired)
        return cls(transitions=len(net.transitions), fired=fired, never=never)

    def to_json(self) -> dict[str, object]:
        """JSON-ready form (``coverage`` in ``fuzz-report.json``)."""
        return {
            "transitions": self.transitions,
            "exercised": self.exercised,
            "fired": dict(self.fired),
            "never": [n.to_json() for n in self.never],
        }


def _never_fired(net: Net, name: str) -> NeverFired:
    transition = net.transition(name)
    line = None if transition.span is None else f"{transition.span.file}:{transition.span.line}"
    command = None if transition.command is None else transition.command.name
    reply = None
    if transition.kind is TransitionKind.REPLY:
        reply = transition.reply
        if transition.reply_to is not None:
            sender = net.transition(transition.reply_to).command
            command = None if sender is None else sender.name
    return NeverFired(transition=name, line=line, command=command, reply=reply)


@dataclass(frozen=True)
class LinkBoundCount:
    """Messages whose one-way delay exceeded the link's analysis bound, over a campaign.

    Timed analysis (``coral-check verify --timed``) assumes no message takes longer than
    ``max_delay_s``; a run with such a message is outside what it proved (its times may
    exceed the proven worst case). Counted per message on the command stream, both ways
    (`runtime.fuzz.one_run.CountingEmulator`).

    Attributes:
        link: the link profile's name.
        max_delay_s: the bound (``LinkProfile.analysis_bounds().max_delay_s``).
        messages: stream messages delivered in all runs.
        messages_over: how many of them took longer than the bound.
        runs_over: runs with at least one such message.
        longest_delay_s: the longest one-way delay of any delivered message.
    """

    link: str
    max_delay_s: float
    messages: int
    messages_over: int
    runs_over: int
    longest_delay_s: float

    def to_json(self) -> dict[str, object]:
        """JSON-ready form (``link_bound`` in ``fuzz-report.json``)."""
        return {
            "link": self.link,
            "max_delay_s": self.max_delay_s,
            "messages": self.messages,
            "messages_over": self.messages_over,
            "runs_over": self.runs_over,
            "longest_delay_s": self.longest_delay_s,
        }


@dataclass
class FuzzReport:
    """The runs of one fuzz and what they add up to."""

    mission: str
    mission_path: str
    options: FuzzOptions
    runs: list[FuzzRun]
    wall_seconds: float
    interrupted: bool = False
    predicted_deadlocks: set[tuple[tuple[str, int], ...]] | None = None
    """The dead markings analysis finds (None: not explored, or too large to explore)."""
    net: Net | None = field(default=None, repr=False)
    """The mission's net, for `coverage` (None: no coverage reported)."""
    ran_on: str = ""
    """Where the runs ran, e.g. ``in 2 local processes``, ``on Ray at HOST:PORT (8 CPUs)``."""
    mismatches: list[ReplayMismatch] = field(default_factory=list)
    """Failed runs whose re-run for their log did something else (Ray only; a bug)."""

    @property
    def failures(self) -> list[FuzzRun]:
        """The runs that did not reach a declared final marking."""
        return [r for r in self.runs if not r.ok]

    @property
    def success_rate(self) -> float:
        """Share of runs that reached a declared final marking (0 if none ran)."""
        return (len(self.runs) - len(self.failures)) / len(self.runs) if self.runs else 0.0

    @property
    def schedules_per_second(self) -> float:
        """Runs per second of wall time."""
        return len(self.runs) / self.wall_seconds if self.wall_seconds > 0 else math.inf

    def durations(self) -> dict[str, float]:
        """Median, p90 and max of the virtual mission times (all runs)."""
        times = sorted(r.duration for r in self.runs)
        if not times:
            return {}
        return {
            "median": statistics.median(times),
            "p90": _percentile(times, 0.9),
            "max": times[-1],
        }

    def predicted(self, run: FuzzRun) -> bool | None:
        """Whether a deadlocked run's marking is one analysis predicts (None: unknown)."""
        if self.predicted_deadlocks is None or run.end is not RunEnd.DEADLOCK:
            return None
        return tuple(sorted(run.marking.items())) in self.predicted_deadlocks

    def coverage(self) -> Coverage | None:
        """Which transitions the runs fired (None when the report has no `net`)."""
        return None if self.net is None else Coverage.of(self.net, self.runs)

    def link_bound(self) -> LinkBoundCount:
        """How often the emulated link exceeded the delay timed analysis assumes."""
        bounds = self.options.link.analysis_bounds()
        return LinkBoundCount(
            link=bounds.name,
            max_delay_s=bounds.max_delay_s,
            messages=sum(r.messages for r in self.runs),
            messages_over=sum(r.over_bound for r in self.runs),
            runs_over=sum(r.over_bound > 0 for r in self.runs),
            longest_delay_s=max((r.longest_delay for r in self.runs), default=0.0),
        )

    def longest(self, count: int = 5) -> list[FuzzRun]:
        """The ``count`` longest runs, longest first."""
        return sorted(self.runs, key=lambda r: (-r.duration, r.seed))[:count]

    def to_json(self) -> dict[str, object]:
        """The report as JSON-ready data."""
        coverage = self.coverage()
        return {
            "mission": self.mission,
            "mission_path": self.mission_path,
            "link": self.options.link.name,
            "seed": self.options.seed,
            "runs_requested": self.options.runs,
            "vehicle": self.options.profile.name if self.options.profile else None,
            "simulator": self.options.simulator,
            "faults": None if self.options.faults is None else str(self.options.faults),
            "runs": [r.to_json() for r in self.runs],
            "interrupted": self.interrupted,
            "success_rate": self.success_rate,
            "durations": self.durations(),
            "wall_seconds": self.wall_seconds,
            "schedules_per_second": self.schedules_per_second,
            "coverage": None if coverage is None else coverage.to_json(),
            "link_bound": self.link_bound().to_json(),
            "ran_on": self.ran_on,
            "nondeterministic": [m.to_json() for m in self.mismatches],
        }


def _percentile(ordered: Sequence[float], q: float) -> float:
    """The ``q`` quantile of sorted data (nearest rank: a time some run really took)."""
    rank = max(1, math.ceil(q * len(ordered)))
    return ordered[rank - 1]


Progress = Callable[[int, int, int], None]
"""``progress(done, total, failed)``, called after every run."""


def fuzz(
    net: Net,
    approval: CertificateCheck,
    options: FuzzOptions,
    *,
    mission_path: str = "",
    failed_logs: Path | None = None,
    progress: Progress | None = None,
    workers: int = 1,
    ray: RayTarget | None = None,
) -> FuzzReport:
    """Run ``options.runs`` runs of ``net``; Ctrl-C stops early with the runs so far.

    Args:
        failed_logs: keep the controller log of each failed run in this folder.
        progress: told after every run.
        workers: local processes to run them in (1: in this process). A run depends on
            its run seed alone, so the report lists the same runs in the same order
            whatever the number of workers; only wall times differ.
        ray: run them as tasks on a Ray cluster instead (`runtime.fuzz.on_ray`; needs
            the ``ray`` extra); the same report again. ``workers`` must then be 1: a
            local cluster's size is ``RayTarget.cpus``.

    Raises:
        ValueError: both ``workers`` > 1 and ``ray``.
        runtime.fuzz.on_ray.RayError: Ray missing, unreachable, or a run lost for good.
    """
    if ray is not None and workers > 1:
        raise ValueError("fuzz: give workers or ray, not both (RayTarget.cpus sizes a cluster)")
    started = time.perf_counter()
    runs: list[FuzzRun] = []
    interrupted = False
    ran_on = "in this process" if workers <= 1 or options.runs <= 1 else ""
    mismatches: list[ReplayMismatch] = []
    try:
        if ray is not None:
            from runtime.fuzz.on_ray import RayCampaign, run_on_ray

            campaign = RayCampaign()
            try:
                run_on_ray(
                    net,
                    approval,
                    options,
                    ray,
                    runs,
                    campaign,
                    failed_logs=failed_logs,
                    progress=progress,
                )
            finally:
                ran_on, mismatches = campaign.where, campaign.mismatches
        elif workers <= 1 or options.runs <= 1:
            for index in range(options.runs):
                seed = run_seed(options.seed, index)
                runs.append(
                    run_one(net, approval, seed, options, index=index, keep_failed_logs=failed_logs)
                )
                if progress is not None:
                    progress(index + 1, options.runs, sum(not r.ok for r in runs))
        else:
            ran_on = f"in {min(workers, options.runs)} local processes"
            _in_workers(net, approval, options, failed_logs, progress, workers, runs)
    except KeyboardInterrupt:
        interrupted = True
    runs.sort(key=lambda r: r.index)
    report = FuzzReport(
        mission=net.name,
        mission_path=mission_path,
        options=options,
        runs=runs,
        wall_seconds=time.perf_counter() - started,
        interrupted=interrupted,
        net=net,
        ran_on=ran_on,
        mismatches=mismatches,
    )
    if any(r.end is RunEnd.DEADLOCK for r in runs):
        report.predicted_deadlocks = predicted_deadlocks(net)
    return report


def _in_workers(
    net: Net,
    approval: CertificateCheck,
    options: FuzzOptions,
    failed_logs: Path | None,
    progress: Progress | None,
    workers: int,
    runs: list[FuzzRun],
) -> None:
    """The runs in ``workers`` fresh processes (spawned: nothing of this process's
    state, its event loop or its open logs, is inherited), appended to ``runs`` as they
    finish. On Ctrl-C the runs not started are cancelled and those done are kept."""
    context = multiprocessing.get_context("spawn")
    pool = ProcessPoolExecutor(max_workers=min(workers, options.runs), mp_context=context)
    try:
        pending = [
            pool.submit(
                run_one,
                net,
                approval,
                run_seed(options.seed, index),
                options,
                index=index,
                keep_failed_logs=failed_logs,
            )
            for index in range(options.runs)
        ]
        for done in as_completed(pending):
            runs.append(done.result())
            if progress is not None:
                progress(len(runs), options.runs, sum(not r.ok for r in runs))
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def predicted_deadlocks(
    net: Net, max_states: int = 1_000_000
) -> set[tuple[tuple[str, int], ...]] | None:
    """The dead markings of ``net``'s complete state space (None if it is too large)."""
    from analysis.statespace import explore

    space = explore(net, max_states=max_states)
    if not space.complete:
        return None
    return {tuple(sorted(net.marking_dict(space.marking(int(d))).items())) for d in space.deadlocks}
