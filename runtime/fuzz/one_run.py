"""One fuzz run: a mission against a simulated vehicle, everything random from one seed.

The real code path (the CORAL Engine, the controller with its event log, the link
emulator, the simulated vehicle served on the wire protocol) under virtual time
(`runtime.vclock.run_virtual`). Each run draws everything random from its *run seed*:
the link emulator's delays, stalls, losses, resets and outages, the simulator's sensor
noise, the handshake nonces, the mission id, and the engine's choice among enabled
transitions, each from a generator of its own (`_rng`), so one purpose drawing more
never shifts another. The same seed gives the same events at the same virtual times
(`FuzzRun.events_digest`).

Each run also counts the messages whose one-way delay exceeded the link's analysis bound
(``LinkProfile.analysis_bounds().max_delay_s``): timed analysis assumes none does, so a
run with one is outside what it proved. `CountingEmulator` counts at the emulator, where
every delay is decided: each stream chunk is one protocol message (commands, replies,
and the heartbeats and acknowledgements between them: the link cannot tell them apart
through the encryption, so all are counted, a superset of the commands and replies
analysis reasons about); its delay is arrival minus send, head-of-line blocking
included; chunks lost with their connection and telemetry datagrams are not counted.
Counting draws nothing and changes no fate, so a run's events are the same with it.

`FuzzOptions` is plain, picklable data: the vehicle is described by a
`runtime.simvehicle.VehicleSpec` built per run, never by a callable, so runs can be
handed to worker processes.
"""

from __future__ import annotations

import asyncio
import hashlib
import json
import random
import time
from collections import Counter
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from analysis.certificate import CertificateCheck
from coral_lang.net import Net, format_tokens
from runtime.controller import Controller, ControllerOptions, RunEnd, RunResult
from runtime.emulator import ConnectAttempt, Direction, StreamPath
from runtime.engine import Engine, Policy
from runtime.eventlog import Event, EventLog
from runtime.link import LinkEmulator, LinkProfile
from runtime.simvehicle import VehicleSpec, serve_simulated
from runtime.vclock import run_virtual

if TYPE_CHECKING:
    from coral_lang.profile import VehicleProfile
    from runtime.faultplan import FaultPlan
    from runtime.vehicle.model import VehicleModel

__all__ = [
    "PSK",
    "SEED_LIMIT",
    "CountingEmulator",
    "FuzzOptions",
    "FuzzRun",
    "events_digest",
    "failed_log_path",
    "make_vehicle",
    "run_one",
    "run_seed",
]

PSK = bytes(range(32))  # the simulator runs in this process: the key protects nothing
SEED_LIMIT = 2**63
"""Run seeds are below this, so they fit the event log's integers and any JSON reader."""


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

    Every field is plain data, so the options pickle (for runs in worker processes). A
    vehicle shaped in code rather than by a settings file is a registered simulator
    (``runtime.vehicle.registry``), not a callable here.
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

    def vehicle(self, net: Net) -> VehicleSpec:
        """The simulated vehicle every run of ``net`` builds (with its own seed).

        Raises:
            coral_lang.diagnostics.ProfileError: no profile given and none bundled for
                the net's vehicle.
        """
        profile = self.profile
        if profile is None:
            from coral_lang.profile import load_bundled_profile

            profile = load_bundled_profile(net.vehicle or "")
        return VehicleSpec(profile, self.simulator, self.sim_config, self.faults)


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
        messages: stream messages the link delivered, both ways (`CountingEmulator`).
        over_bound: how many of them took longer than the link's analysis bound.
        longest_delay: the longest one-way delay of a delivered message, s.
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
    messages: int = 0
    over_bound: int = 0
    longest_delay: float = 0.0

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
            "messages": self.messages,
            "messages_over_link_bound": self.over_bound,
            "longest_message_delay_s": self.longest_delay,
        }


class CountingEmulator(LinkEmulator):
    """A `LinkEmulator` that also counts the stream messages delivered later than
    ``bound`` after they were sent (module docstring); every fate is the parent's.

    Args:
        profile: the link profile.
        seed: the emulator's seed.
        bound: the longest one-way delay analysis assumes, s.
    """

    def __init__(self, profile: LinkProfile, seed: int, bound: float) -> None:
        super().__init__(profile, seed)
        self.bound = bound
        self.messages = 0
        self.over_bound = 0
        self.longest_delay = 0.0

    def connect(self, now: float) -> ConnectAttempt:
        attempt = super().connect(now)
        path = attempt.path
        if path is None:
            return attempt
        return ConnectAttempt(attempt.latency, _CountedPath(self, path), attempt.outage)

    def note(self, delay: float) -> None:
        """One message delivered ``delay`` seconds after it was sent."""
        self.messages += 1
        self.longest_delay = max(self.longest_delay, delay)
        if delay > self.bound + 1e-9:
            self.over_bound += 1


class _CountedPath(StreamPath):
    """A connection's streams whose delivered chunks `CountingEmulator.note` sees."""

    def __init__(self, emulator: CountingEmulator, original: StreamPath) -> None:
        super().__init__(
            emulator,
            original.number,
            original.established_at,
            original.ends_at,
            original.end_cause,
            original.outage,
        )
        self._counter = emulator

    def chunk(self, direction: Direction, size: int, now: float) -> float:
        arrival = super().chunk(direction, size, now)
        if size > 0 and arrival < self.ends_at:  # a message, not lost with the connection
            self._counter.note(arrival - now)
        return arrival


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
    log = _open_log(net, approval, seed, options, keep_log)
    kept: Path | None = keep_log
    try:
        emulator = CountingEmulator(options.link, seed, options.link.analysis_bounds().max_delay_s)
        result, vehicle_commands = run_virtual(
            _simulate(net, approval, seed, options, log, emulator)
        )
        digest, fired, events = _read_events(log, keep_events)
        if keep_log is None and keep_failed_logs is not None and result.end is not RunEnd.FINAL:
            kept = failed_log_path(keep_failed_logs, seed)
            log.commit()  # what close would add, so the copy is the log a file would be
            log.save_copy(kept)
    finally:
        log.close()
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
        messages=emulator.messages,
        over_bound=emulator.over_bound,
        longest_delay=emulator.longest_delay,
    )


def failed_log_path(folder: Path, seed: int) -> Path:
    """Where a failed run's log is kept: ``FOLDER/seed-SEED.sqlite``, the folder made and
    an older log of the same seed removed (a log is never overwritten in place)."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"seed-{seed}.sqlite"
    path.unlink(missing_ok=True)
    return path


def _open_log(
    net: Net,
    approval: CertificateCheck,
    seed: int,
    options: FuzzOptions,
    keep_log: Path | None,
) -> EventLog:
    """The run's controller log: at ``keep_log`` if given, else in memory only.

    A fuzz run's log is kept only when the run failed (then `EventLog.save_copy` writes
    it out) or when asked for: in memory, its commits cost no file system work.
    """
    meta = {"fuzz_seed": seed, "link": options.link.name, "certificate": approval.path}
    net_json = json.dumps(net.canonical(), sort_keys=True)
    if keep_log is None:
        return EventLog.create_in_memory(
            f"<fuzz run, seed {seed}>",
            role="controller",
            mission=net.name,
            meta=meta,
            net_json=net_json,
            net_digest=net.digest(),
        )
    log = EventLog.create(
        keep_log,
        role="controller",
        mission=net.name,
        meta=meta,
        net_json=net_json,
        net_digest=net.digest(),
    )
    log.relax_durability()
    return log


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
    net: Net,
    approval: CertificateCheck,
    seed: int,
    options: FuzzOptions,
    log: EventLog,
    emulator: LinkEmulator,
) -> tuple[RunResult, int]:
    """One controller run against a simulated vehicle over an emulated in-memory link."""
    model = make_vehicle(net, options, _rng(seed, "vehicle").getrandbits(63))
    async with serve_simulated(
        model,
        PSK,
        emulator,
        nonces=_rng(seed, "vehicle-nonces").randbytes,
    ) as (server, link):
        engine = Engine(
            net, approval, policy=options.policy, seed=_rng(seed, "engine").getrandbits(63)
        )
        controller = Controller.start_new(
            engine,
            link,
            PSK,
            log,
            mission_id=_rng(seed, "mission").getrandbits(63),
            now=asyncio.get_running_loop().time(),
            options=ControllerOptions(time_limit=options.time_limit),
            nonces=_rng(seed, "controller-nonces").randbytes,
            console=_quiet,
        )
        result = await controller.run()
    return result, server.stats.commands


def make_vehicle(net: Net, options: FuzzOptions, seed: int) -> VehicleModel:
    """The simulated vehicle of one run, seeded with ``seed``, faults injected.

    Raises:
        runtime.vehicle.registry.SimulatorError: no simulator for it.
        runtime.faultplan.FaultPlanError: a fault rule does not fit the profile.
        coral_lang.diagnostics.ProfileError: no profile given and none bundled.
    """
    return options.vehicle(net).build(seed)


def _quiet(line: str) -> None:
    del line  # progress lines of the controller, the link and the vehicle: not wanted here
