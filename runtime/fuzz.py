"""``coral-run fuzz``: run one mission under many random schedules against the simulator.

Verification proves what a mission does whatever the network does; fuzzing shows it, on
the real code path: the CORAL Engine, the controller with its event log, the link
emulator and the simulated ROMEO served on the wire protocol, all under virtual time
(`runtime.vclock.run_virtual`), so a ten-minute mission takes a fraction of a second.
Each run draws everything random from its own *run seed*: the link emulator's delays,
stalls, losses, resets and outages, the simulator's sensor noise, the handshake nonces,
the mission id, and the engine's choice among enabled transitions (`Policy.RANDOM`, so
every order analysis allows gets tried, not just the priority order).

Run ``i`` of ``--seed S`` has run seed ``S + i``. The report names the run seed of every
failure, and ``--replay X`` (or ``--runs 1 --seed X``) runs exactly that run again: same
outcome, same events at the same virtual times (``events_digest`` proves it).

Only the simulator is ever used: there is no option to reach a vehicle, and a mission
without a passing certificate is accepted only with ``--unverified``, under an approval
that exists in this process alone (`UNVERIFIED`).

A run that ends otherwise (a deadlock, the time limit, an engine spin: a cycle of engine
transitions that never waits for the vehicle) is a failure, reported with its run seed;
the campaign goes on.

Exit codes: 0 every run reached a declared final marking, 1 some run did not, 2 bad input.
"""

from __future__ import annotations

import argparse
import asyncio
import hashlib
import json
import math
import random
import shlex
import shutil
import statistics
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, TYPE_CHECKING

from analysis.certificate import CertificateCheck, CertificateError
from coral_lang.diagnostics import CoralError
from coral_lang.mission import Mission
from coral_lang.net import Net, TransitionKind, format_tokens
from runtime.controller import Controller, ControllerOptions, RunEnd, RunResult
from runtime.engine import Engine, Policy
from runtime.eventlog import Event, EventLog
from runtime.keys import TRUSTED_KEYS_HELP
from runtime.link import LinkEmulator, LinkProfile, MemoryLink, load_link_profile
from runtime.vclock import run_virtual
from runtime.vehicle.model import VehicleModel
from runtime.vehicle.options import add_simulation_arguments, fault_plan_from_args

if TYPE_CHECKING:
    from analysis.signing import TrustStore
    from coral_lang.profile import VehicleProfile
    from runtime.faultplan import FaultPlan

__all__ = [
    "UNVERIFIED",
    "FuzzOptions",
    "FuzzReport",
    "FuzzRun",
    "build_parser",
    "fuzz",
    "main",
    "run_one",
    "run_seed",
]

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_USAGE = 2

UNVERIFIED = "unverified (fuzz only)"
"""The ``path`` of the approval `--unverified` builds: it names no file, so it can never
be mistaken for a certificate, and it is only ever handed to a simulated run."""

HISTOGRAM = "fuzz-histogram.png"
REPORT_JSON = "fuzz-report.json"
FAILURES_DIR = "failures"
PSK = bytes(range(32))  # the simulator runs in this process: the key protects nothing
SEED_LIMIT = 2**63
"""Run seeds are below this, so they fit the event log's integers and any JSON reader."""


# ---------------------------------------------------------------------------- one run


@dataclass(frozen=True)
class FuzzOptions:
    """How to fuzz.

    Attributes:
        runs: how many runs.
        seed: run ``i`` uses run seed ``seed + i``.
        link: the link profile every run emulates (each run with its own seed).
        time_limit: virtual seconds after which a run is ended (counted as a failure).
        policy: the engine's choice rule; RANDOM (default) varies the order of enabled
            transitions with the run seed, PRIORITY runs what would run at sea.
        profile: the vehicle profile the mission was compiled against (None: the
            bundled profile of the net's vehicle).
        simulator: the registered simulator (None: the one for the vehicle, else the
            generic one; ``runtime.vehicle.registry``).
        sim_config: that simulator's settings file (ROMEO: a vehicle YAML).
        faults: replies to force in every run (``runtime.faultplan``); a rule with a
            rate draws afresh in each run, from the run seed.
        vehicle_factory: builds the vehicle from a seed instead of the registry (for
            tests and scripts that shape the vehicle in code); faults still apply.
    """

    runs: int
    seed: int
    link: LinkProfile
    time_limit: float = 3600.0
    policy: Policy = Policy.RANDOM
    profile: VehicleProfile | None = None
    simulator: str | None = None
    sim_config: Path | None = None
    faults: FaultPlan | None = None
    vehicle_factory: Callable[[int], VehicleModel] | None = None


@dataclass(frozen=True)
class FuzzRun:
    """What one run did.

    Attributes:
        index: its position in the fuzz (0 for ``--replay``).
        seed: the run seed that reproduces it.
        end: how the controller's run ended.
        marking: the marking it ended in.
        duration: virtual seconds from the mission's start to its end.
        connections: connections the controller made (more than one: resets, outages).
        commands_sent: commands the engine sent.
        commands_resent: commands sent again after a reconnect.
        replies: replies consumed.
        duplicate_replies: replies the vehicle sent again that were already consumed.
        unexpected_replies: replies the net had no transition for.
        vehicle_commands: commands the vehicle carried out (each command id once).
        events_digest: SHA-256 of the controller's event sequence (times included):
            two runs with the same digest did the same thing at the same times.
        wall_seconds: real time the run took.
        detail: why the run ended so, when there is more to say (a spin: its cycle).
        events: the controller's events, when asked for (`run_one` ``keep_events``).
        log: where the controller's log was kept (failures and replays), if anywhere.
        fired: how often each net transition fired (reply transitions included: a reply
            the net consumes fires its reply transition); never-fired ones are absent.
    """

    index: int
    seed: int
    end: RunEnd
    marking: dict[str, int]
    duration: float
    connections: int
    commands_sent: int
    commands_resent: int
    replies: int
    duplicate_replies: int
    unexpected_replies: int
    vehicle_commands: int
    events_digest: str
    wall_seconds: float
    detail: str = ""
    events: tuple[Event, ...] = field(default=(), repr=False, compare=False)
    log: Path | None = None
    fired: Mapping[str, int] = field(default_factory=dict, repr=False, compare=False)

    @property
    def ok(self) -> bool:
        """True when the run reached a declared final marking."""
        return self.end is RunEnd.FINAL

    def ending(self) -> str:
        """E.g. ``final { mission_complete }`` or ``deadlock { depth_failed, aborted }``."""
        return f"{self.end.value} {format_tokens(self.marking.items())}"

    def to_json(self) -> dict[str, object]:
        """The run as JSON-ready data (for ``fuzz-report.json``)."""
        return {
            "index": self.index,
            "seed": self.seed,
            "end": self.end.value,
            "final": self.ok,
            "marking": self.marking,
            "duration": self.duration,
            "connections": self.connections,
            "commands_sent": self.commands_sent,
            "commands_resent": self.commands_resent,
            "replies": self.replies,
            "duplicate_replies": self.duplicate_replies,
            "unexpected_replies": self.unexpected_replies,
            "vehicle_commands": self.vehicle_commands,
            "events_digest": self.events_digest,
            "wall_seconds": self.wall_seconds,
            "detail": self.detail,
            "log": None if self.log is None else str(self.log),
            "transitions_fired": len(self.fired),
        }


def run_seed(base: int, index: int) -> int:
    """The run seed of run ``index`` of a fuzz started with ``--seed base``."""
    return (base + index) % SEED_LIMIT


def _rng(seed: int, purpose: str) -> random.Random:
    """An independent generator per purpose (string seeds hash with SHA-512: stable)."""
    return random.Random(f"coral-fuzz/{seed}/{purpose}")


def run_one(
    net: Net,
    approval: CertificateCheck,
    seed: int,
    options: FuzzOptions,
    *,
    index: int = 0,
    keep_log: Path | None = None,
    keep_failed_logs: Path | None = None,
    keep_events: bool = False,
) -> FuzzRun:
    """Run ``net`` once against the simulator, everything random drawn from ``seed``.

    Args:
        net: the mission.
        approval: its certificate check (or the `UNVERIFIED` one).
        seed: the run seed.
        options: link, vehicle, time limit, policy.
        index: the run's position, for the report.
        keep_log: keep the controller's log at this path (it must not exist).
        keep_failed_logs: if the run fails, keep its log in this folder as
            ``seed-SEED.sqlite`` (replacing an older one of the same seed).
        keep_events: return the controller's events in `FuzzRun.events`.

    Raises:
        runtime.eventlog.EventLogError: the log cannot be written.
    """
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="coral-fuzz-") as scratch:
        log_path = keep_log if keep_log is not None else Path(scratch) / "controller.sqlite"
        log = EventLog.create(
            log_path,
            role="controller",
            mission=net.name,
            meta={"fuzz_seed": seed, "link": options.link.name, "certificate": approval.path},
            net_json=json.dumps(net.canonical(), sort_keys=True),
            net_digest=net.digest(),
        )
        try:
            log.relax_durability()
            result, vehicle_commands = run_virtual(_simulate(net, approval, seed, options, log))
            digest, fired, events = _read_events(log, keep_events)
        finally:
            log.close()
        kept: Path | None = keep_log
        if keep_log is None and keep_failed_logs is not None and result.end is not RunEnd.FINAL:
            keep_failed_logs.mkdir(parents=True, exist_ok=True)
            kept = keep_failed_logs / f"seed-{seed}.sqlite"
            kept.unlink(missing_ok=True)
            shutil.move(str(log_path), kept)
    return FuzzRun(
        index=index,
        seed=seed,
        end=result.end,
        marking=dict(result.marking),
        duration=result.ended_at - result.started_at,
        connections=result.connections,
        commands_sent=result.commands_sent,
        commands_resent=result.commands_resent,
        replies=result.replies,
        duplicate_replies=result.duplicate_replies,
        unexpected_replies=result.unexpected_replies,
        vehicle_commands=vehicle_commands,
        events_digest=digest,
        wall_seconds=time.perf_counter() - started,
        detail=result.detail,
        events=events,
        log=kept,
        fired=fired,
    )


def _read_events(log: EventLog, keep: bool) -> tuple[str, dict[str, int], tuple[Event, ...]]:
    """One pass over the log: the events' digest, the transitions fired, and the events
    themselves only if ``keep`` (a long mission's events need not all sit in memory)."""
    h = hashlib.sha256()
    fired: Counter[str] = Counter()
    kept: list[Event] = []
    for event in log.events():
        h.update(_digest_line(event))
        if event.kind == "fire":
            transition = event.data.get("transition")
            if isinstance(transition, str):
                fired[transition] += 1
        if keep:
            kept.append(event)
    return "sha256:" + h.hexdigest(), dict(fired), tuple(kept)


def events_digest(events: Iterable[Event]) -> str:
    """SHA-256 of an event sequence: kinds, times and data, in order."""
    h = hashlib.sha256()
    for event in events:
        h.update(_digest_line(event))
    return "sha256:" + h.hexdigest()


def _digest_line(event: Event) -> bytes:
    line = json.dumps([event.seq, event.time, event.kind, event.data], sort_keys=True)
    return line.encode() + b"\n"


async def _simulate(
    net: Net, approval: CertificateCheck, seed: int, options: FuzzOptions, log: EventLog
) -> tuple[RunResult, int]:
    """One controller run against a simulated vehicle over an emulated in-memory link."""
    from runtime.vehicle.server import VehicleServer

    loop = asyncio.get_running_loop()
    server = VehicleServer(
        make_vehicle(net, options, _rng(seed, "vehicle").getrandbits(63)),
        PSK,
        clock=loop.time,
        nonces=_rng(seed, "vehicle-nonces").randbytes,
        log=_quiet,
    )
    link = MemoryLink(server, LinkEmulator(options.link, seed=seed))
    engine = Engine(net, approval, policy=options.policy, seed=_rng(seed, "engine").getrandbits(63))
    try:
        controller = Controller.start_new(
            engine,
            link,
            PSK,
            log,
            mission_id=_rng(seed, "mission").getrandbits(63),
            now=loop.time(),
            options=ControllerOptions(time_limit=options.time_limit),
            nonces=_rng(seed, "controller-nonces").randbytes,
            console=_quiet,
        )
        result = await controller.run()
    finally:
        await link.aclose()
        await server.stop()
    return result, server.stats.commands


def make_vehicle(net: Net, options: FuzzOptions, seed: int) -> VehicleModel:
    """The simulated vehicle of one run, seeded with ``seed``, faults injected.

    Raises:
        runtime.vehicle.registry.SimulatorError: no simulator for it.
        runtime.faultplan.FaultPlanError: a fault rule does not fit the profile.
        coral_lang.diagnostics.ProfileError: no profile given and none bundled.
    """
    from runtime.vehicle.registry import create_vehicle, inject_faults

    profile = options.profile
    if profile is None:
        from coral_lang.profile import load_bundled_profile

        profile = load_bundled_profile(net.vehicle or "")
    if options.vehicle_factory is not None:
        return inject_faults(options.vehicle_factory(seed), profile, options.faults, seed)
    return create_vehicle(
        profile,
        simulator=options.simulator,
        seed=seed,
        config=options.sim_config,
        faults=options.faults,
    )


def _quiet(line: str) -> None:
    del line  # progress lines of the controller, the link and the vehicle: not wanted here


# ---------------------------------------------------------------------------- many runs


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
) -> FuzzReport:
    """Run ``options.runs`` runs of ``net``; Ctrl-C stops early with the runs so far.

    Args:
        failed_logs: keep the controller log of each failed run in this folder.
        progress: told after every run.
    """
    started = time.perf_counter()
    runs: list[FuzzRun] = []
    interrupted = False
    try:
        for index in range(options.runs):
            seed = run_seed(options.seed, index)
            runs.append(
                run_one(net, approval, seed, options, index=index, keep_failed_logs=failed_logs)
            )
            if progress is not None:
                progress(index + 1, options.runs, sum(not r.ok for r in runs))
    except KeyboardInterrupt:
        interrupted = True
    report = FuzzReport(
        mission=net.name,
        mission_path=mission_path,
        options=options,
        runs=runs,
        wall_seconds=time.perf_counter() - started,
        interrupted=interrupted,
        net=net,
    )
    if any(r.end is RunEnd.DEADLOCK for r in runs):
        report.predicted_deadlocks = predicted_deadlocks(net)
    return report


def predicted_deadlocks(
    net: Net, max_states: int = 1_000_000
) -> set[tuple[tuple[str, int], ...]] | None:
    """The dead markings of ``net``'s complete state space (None if it is too large)."""
    from analysis.statespace import explore

    space = explore(net, max_states=max_states)
    if not space.complete:
        return None
    return {tuple(sorted(net.marking_dict(space.marking(int(d))).items())) for d in space.deadlocks}


# ---------------------------------------------------------------------------- the report


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
    lines.append(
        f"  {report.wall_seconds:.1f} s wall, {report.schedules_per_second:.2f} schedules/s"
    )
    return "\n".join(lines)


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


# ---------------------------------------------------------------------------- the command


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected at least 1, got {value}")
    return value


def _seed(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if not 0 <= value < SEED_LIMIT:
        raise argparse.ArgumentTypeError(f"a seed is 0 .. 2**63-1, got {value}")
    return value


def _seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of seconds, got {text!r}") from None
    if not 0.0 < value < math.inf:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return value


def build_parser() -> argparse.ArgumentParser:
    """The parser of ``coral-run fuzz``."""
    parser = argparse.ArgumentParser(
        prog="coral-run fuzz",
        # No abbreviations: "--vehicle HOST:PORT" (coral-run's) must be refused, not taken
        # for --vehicle-config; fuzz never talks to a vehicle.
        allow_abbrev=False,
        description="Run a mission against a simulated vehicle under many random schedules "
        "(link delays, stalls, losses, resets, outages; the engine's order of enabled "
        "transitions; with --vary-replies or --fault, the vehicle's replies), in virtual "
        "time, and report how often it reaches a declared final marking, how long it takes, "
        "which transitions of the net it exercised, and the seed that replays each "
        "failure. Only a simulator is ever used.",
        epilog="exit codes: 0 every run reached a declared final marking, 1 some run did not, "
        "2 bad usage or input",
    )
    parser.add_argument("mission", metavar="MISSION", help="mission (.coral)")
    parser.add_argument("--runs", type=_positive_int, default=100, help="runs (default 100)")
    parser.add_argument(
        "--seed", type=_seed, default=0, help="run i uses run seed SEED + i (default 0)"
    )
    parser.add_argument(
        "--replay",
        type=_seed,
        metavar="SEED",
        help="run only the run with this run seed (from a report) and print its events",
    )
    parser.add_argument(
        "--link",
        metavar="PROFILE",
        default="genoa-lisbon",
        help="link profile: ideal, lan, genoa-lisbon (default), hostile, or a YAML file",
    )
    parser.add_argument(
        "--profile",
        action="append",
        default=[],
        type=Path,
        metavar="FILE",
        help="vehicle profile (YAML) for a vehicle that has no bundled profile; "
        "repeatable (as for coral-check and coral-run)",
    )
    parser.add_argument(
        "--vary-replies",
        type=_probability,
        default=0.0,
        metavar="P",
        help="in each run, force each command's reply, with probability P, to one of its "
        "other reply kinds (the rule '*=any@P' after any --fault rules; default 0: the "
        "simulator's own replies)",
    )
    parser.add_argument(
        "--certificate",
        type=Path,
        metavar="FILE",
        help="the mission's certificate (default MISSION.certificate.json beside it)",
    )
    parser.add_argument(
        "--trusted-keys",
        type=Path,
        metavar="PATH",
        help=TRUSTED_KEYS_HELP,
    )
    parser.add_argument(
        "--unverified",
        action="store_true",
        help="fuzz a mission that has no passing certificate (simulator only; a warning "
        "is printed)",
    )
    parser.add_argument(
        "--policy",
        choices=[p.value for p in Policy],
        default=Policy.RANDOM.value,
        help="engine choice among enabled transitions: random (default, seeded per run) "
        "or priority (what runs at sea)",
    )
    parser.add_argument(
        "--time-limit",
        type=_seconds,
        default=3600.0,
        metavar="SECONDS",
        help="end a run after this many virtual seconds, as a failure (default 3600)",
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=Path("out/fuzz"),
        help="report, histogram and failed runs' logs go here (default out/fuzz)",
    )
    parser.add_argument("--no-plot", action="store_true", help="do not draw the histogram")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    add_simulation_arguments(parser, config_aliases=("--vehicle-config",))
    return parser


def _probability(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a probability, got {text!r}") from None
    if not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f"expected a probability in [0, 1], got {text!r}")
    return value


def approval_for(
    mission: Mission,
    certificate: Path | None,
    *,
    unverified: bool,
    trusted: TrustStore | None = None,
) -> tuple[CertificateCheck, str | None]:
    """The approval to fuzz with, and the reason it is unverified (None if verified).

    The certificate is checked as a run checks it: against the net, the vehicle profile
    the mission was compiled with, and the trusted keys (``trusted``, default the
    run's default trust store), so it must be signed.

    Raises:
        CertificateError: no passing certificate and not ``unverified``.
    """
    from runtime.gate import check_mission_certificate

    net = mission.net
    try:
        return check_mission_certificate(mission, certificate, trusted=trusted), None
    except CertificateError as exc:
        if not unverified:
            raise CertificateError(
                f"{exc}; or, to fuzz it as it is against the simulator, add --unverified"
            ) from None
        from analysis.certificate import tool_version

        approval = CertificateCheck(
            path=UNVERIFIED, net_digest=net.digest(), issued="", tool_version=tool_version()
        )
        return approval, str(exc)


def main(argv: Sequence[str] | None = None, *, stderr: IO[str] | None = None) -> int:
    """``coral-run fuzz``; returns the exit code."""
    err = stderr if stderr is not None else sys.stderr
    options = build_parser().parse_args(argv)
    try:
        return _fuzz(options, err)
    except (CoralError, OSError) as exc:
        print(f"coral-run fuzz: {exc}", file=err)
        return EXIT_USAGE


def _fuzz(options: argparse.Namespace, err: IO[str]) -> int:
    from coral_lang.mission import load_mission
    from coral_lang.profile import load_profile
    from runtime.faultplan import parse_fault_rules

    mission = Path(options.mission)
    compiled = load_mission(mission, [load_profile(path) for path in options.profile])
    net = compiled.net
    link = load_link_profile(options.link)
    faults = fault_plan_from_args(options)
    if options.vary_replies > 0.0:
        vary = parse_fault_rules([f"*=any@{options.vary_replies:g}"], source="--vary-replies")
        faults = vary if faults is None else faults + vary
    from runtime.gate import trust_store

    approval, unverified = approval_for(
        compiled,
        options.certificate,
        unverified=options.unverified,
        trusted=trust_store(options.trusted_keys),
    )
    if unverified is not None:
        print(
            f"coral-run fuzz: WARNING: {mission} is NOT verified ({unverified}).\n"
            "  Fuzzing it anyway against the simulator only; this approval exists in this "
            "process alone and cannot run it on a vehicle.",
            file=err,
        )
    fuzz_options = FuzzOptions(
        runs=1 if options.replay is not None else options.runs,
        seed=options.replay if options.replay is not None else options.seed,
        link=link,
        time_limit=options.time_limit,
        policy=Policy(options.policy),
        profile=compiled.profile,
        simulator=options.simulator,
        sim_config=options.sim_config,
        faults=faults,
    )
    make_vehicle(net, fuzz_options, 0)  # a simulator or fault plan that cannot be used: now
    out: Path = options.out
    out.mkdir(parents=True, exist_ok=True)
    command = _command(options)
    if options.replay is not None:
        log = out / f"replay-seed-{options.replay}.sqlite"
        log.unlink(missing_ok=True)
        run = run_one(net, approval, options.replay, fuzz_options, keep_log=log, keep_events=True)
        print(format_replay(run))
        print(f"coral-run fuzz: log in {log} (plot it with: coral-run timeline {log})")
        return EXIT_OK if run.ok else EXIT_FAILED
    bar = ProgressBar(err)
    if options.quiet:
        bar.enabled = False
    try:
        report = fuzz(
            net,
            approval,
            fuzz_options,
            mission_path=str(mission),
            failed_logs=out / FAILURES_DIR,
            progress=bar,
        )
    finally:
        bar.close()
    print(format_report(report, command))
    (out / REPORT_JSON).write_text(json.dumps(report.to_json(), indent=2) + "\n", encoding="utf-8")
    print(f"coral-run fuzz: wrote {out / REPORT_JSON}")
    if not options.no_plot and report.runs:
        print(f"coral-run fuzz: wrote {plot_histogram(report, out / HISTOGRAM)}")
    if report.failures:
        print(f"coral-run fuzz: logs of failed runs in {out / FAILURES_DIR}/")
    if report.interrupted:
        return EXIT_FAILED
    return EXIT_OK if not report.failures else EXIT_FAILED


def _command(options: argparse.Namespace) -> str:
    """How to call fuzz again with what shapes a run (not --runs/--seed/--out)."""
    parts = ["coral-run fuzz", str(options.mission), "--link", str(options.link)]
    parts += [f"--profile {shlex.quote(str(p))}" for p in options.profile]
    if options.simulator is not None:
        parts += ["--simulator", options.simulator]
    if options.sim_config is not None:
        parts += ["--sim-config", str(options.sim_config)]
    parts += [f"--fault {shlex.quote(rule)}" for rule in options.fault]
    if options.faults is not None:
        parts += ["--faults", str(options.faults)]
    if options.vary_replies > 0.0:
        parts += ["--vary-replies", f"{options.vary_replies:g}"]
    if options.certificate is not None:
        parts += ["--certificate", str(options.certificate)]
    if options.trusted_keys is not None:
        parts += ["--trusted-keys", shlex.quote(str(options.trusted_keys))]
    if options.unverified:
        parts.append("--unverified")
    if options.policy != Policy.RANDOM.value:
        parts += ["--policy", options.policy]
    if options.time_limit != 3600.0:
        parts += ["--time-limit", f"{options.time_limit:g}"]
    return " ".join(parts)


if __name__ == "__main__":
    raise SystemExit(main())
