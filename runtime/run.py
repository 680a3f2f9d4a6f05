"""One mission run, end to end: the approved net, a link, the vehicle, the logs, the plots.

`run_mission` is what ``coral-run`` does. Three ways to reach a vehicle:

* a simulated vehicle in virtual time (default): the simulator registered for the
  mission's vehicle (`runtime.vehicle.registry`: ROMEO's physics for ROMEO, the generic
  vehicle for any other profile), with a fault plan if given, and the controller in one process,
  joined by an in-memory link through the link emulator, under
  `runtime.vclock.VirtualTimeLoop`; a mission of many minutes runs in seconds, and
  the same seed gives the same run;
* the simulator in real time (``realtime=True``): the same, over real TCP and UDP
  sockets on localhost, emulator applied on the controller's side;
* a vehicle at ``HOST:PORT`` (``vehicle=...``): real sockets, real time; the emulator
  only if a link profile is given.

Both sides log to SQLite in ``out_dir`` (``controller.sqlite``; ``vehicle.sqlite`` when
the vehicle is ours), and the timeline plots are drawn from the two logs.

``RunConfig.companions`` run beside the controller, whichever the vehicle: async context
managers entered (in order) just before ``controller.run()`` and exited after it, on
error and on a stop too. ``coral-run --watch`` and ``--tui`` are companions (the live
page with its operator actions, the terminal view); they need real time, since under
virtual time nothing outside the mission would ever get a turn.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import random
import secrets
import signal
from collections.abc import AsyncIterator, Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from runtime.controller import Controller, ControllerOptions, RunResult
from runtime.engine import Engine, Policy
from runtime.eventlog import EventLog, EventLogError, log_key
from runtime.faultplan import FaultPlan
from runtime.gate import ApprovedMission
from runtime.link import Link, LinkEmulator, LinkProfile, SocketLink
from runtime.simvehicle import VehicleSpec, serve_simulated
from runtime.vclock import run_virtual
from runtime.vehicle.model import VehicleModel

if TYPE_CHECKING:
    from coral_lang.net import Net

__all__ = [
    "Companion",
    "RunConfig",
    "controller_log_path",
    "open_for_resume",
    "resume_mission",
    "run_mission",
]

CONTROLLER_LOG = "controller.sqlite"
VEHICLE_LOG = "vehicle.sqlite"


Companion = Callable[[Controller], contextlib.AbstractAsyncContextManager[object]]
"""Something that runs beside a controller (a live server, a terminal view): given the
controller, an async context manager entered before its run and exited after it."""


def controller_log_path(out_dir: Path) -> Path:
    """Where the controller's event log goes."""
    return out_dir / CONTROLLER_LOG


@dataclass(frozen=True)
class RunConfig:
    """How to run a mission.

    Attributes:
        out_dir: logs and plots go here; must not hold an earlier run's logs.
        psk: the pre-shared key (the simulator is given the same one).
        link: the link profile to emulate (None: the link as it is).
        seed: seeds the emulator, the simulator's noise, nonces and mission id for the
            simulator, so a simulated run is reproducible.
        vehicle: HOST, PORT of a vehicle; None runs the simulator.
        realtime: run the simulator in real time over localhost sockets.
        speed: simulator seconds per wall second in real time (1: as at sea).
        time_limit: end the run after this many seconds (None: no limit).
        policy: the engine's choice rule.
        console: receives progress lines.
        simulator: the registered simulator to run (None: the one for the mission's
            vehicle, else the generic one).
        sim_config: that simulator's settings file, if any.
        faults: replies to force (``runtime.faultplan``), simulated vehicles only.
        telemetry_host: with ``vehicle``, the local address the telemetry socket binds to
            and the control connection leaves from; None: the one the routes pick to
            reach the vehicle (``runtime.socketlink``).
        log_key_ephemeral: ``psk`` is a fresh random key that dies with this process (a
            simulated run without ``--key-file``): the logs are written unauthenticated,
            since nobody could ever verify them, and such a run may resume an
            unauthenticated log (with a warning), against a simulated vehicle only.
        companions: entered in order around ``controller.run()`` (`Companion`), exited
            in reverse order after it, also when it fails or is stopped.
    """

    out_dir: Path
    psk: bytes
    link: LinkProfile | None = None
    seed: int = 0
    vehicle: tuple[str, int] | None = None
    realtime: bool = False
    speed: float = 1.0
    time_limit: float | None = None
    policy: Policy = Policy.PRIORITY
    controller: ControllerOptions = field(default_factory=ControllerOptions)
    console: Callable[[str], None] = print
    simulator: str | None = None
    sim_config: Path | None = None
    faults: FaultPlan | None = None
    telemetry_host: str | None = None
    log_key_ephemeral: bool = False
    companions: Sequence[Companion] = ()


def _log_key(config: RunConfig) -> bytes | None:
    """The key the run's logs are authenticated with; None when nobody could check it."""
    return None if config.log_key_ephemeral else log_key(config.psk)


def _meta(mission: ApprovedMission, config: RunConfig) -> dict[str, object]:
    return {
        "mission_path": str(mission.path.resolve()),
        "certificate": mission.approval.path,
        "link": None if config.link is None else config.link.name,
        "seed": config.seed,
        "vehicle": "sim" if config.vehicle is None else f"{config.vehicle[0]}:{config.vehicle[1]}",
        "realtime": config.realtime or config.vehicle is not None,
        "speed": config.speed,
        "profiles": [str(Path(p.file).resolve()) for p in mission.mission.profiles if p.file],
        "include_path": [str(Path(p).resolve()) for p in mission.mission.include_path],
        "faults": None if config.faults is None else str(config.faults),
    }


def _simulated_vehicle(mission: ApprovedMission, config: RunConfig) -> VehicleModel | None:
    """The simulated vehicle of the run, None when it runs against a real one.

    Built before any log is written, so a simulator or fault plan that cannot be used is
    reported as bad input and leaves nothing behind. `VehicleSpec` is the same builder
    ``coral-run fuzz`` uses, so the options mean the same in both.
    """
    from runtime.vehicle.registry import SimulatorError

    if config.vehicle is not None:
        if config.faults is not None:
            raise SimulatorError("a fault plan applies to a simulated vehicle, not to --vehicle")
        return None

    profile = mission.mission.profile
    if profile is None:
        raise SimulatorError(
            f"{mission.path}: no vehicle profile to simulate '{mission.net.vehicle}' with"
        )
    spec = VehicleSpec(profile, config.simulator, config.sim_config, config.faults)
    return spec.build(config.seed)


def run_mission(mission: ApprovedMission, config: RunConfig) -> RunResult:
    """Run ``mission`` as ``config`` says; returns the controller's result."""
    model = _simulated_vehicle(mission, config)
    config.out_dir.mkdir(parents=True, exist_ok=True)
    rng = random.Random(config.seed)
    simulated = config.vehicle is None
    mission_id = rng.getrandbits(63) if simulated else secrets.randbits(63)
    log = EventLog.create(
        controller_log_path(config.out_dir),
        role="controller",
        mission=mission.net.name,
        meta=_meta(mission, config),
        net_json=_net_json(mission),
        net_digest=mission.net.digest(),
        mac_key=_log_key(config),
    )
    try:
        engine = Engine(mission.net, mission.approval, policy=config.policy, seed=config.seed)

        def make(link: Link, now: float, nonces: Callable[[int], bytes]) -> Controller:
            return Controller.start_new(
                engine,
                link,
                config.psk,
                log,
                mission_id=mission_id,
                now=now,
                options=_options(config),
                nonces=nonces,
                console=config.console,
            )

        return _drive(config, make, rng, mission.net.name, model)
    finally:
        log.close()


def resume_mission(mission: ApprovedMission, log_path: Path, config: RunConfig) -> RunResult:
    """Continue the mission logged in ``log_path`` after the controller died.

    The whole log is verified against the run's key first (`open_for_resume`), so a log
    edited by hand is refused before anything is built, connected or written.

    Raises:
        runtime.eventlog.EventLogError: the log cannot be opened for writing, does not
            verify (edited, written with another key, or unauthenticated while the run has
            a real key), is the log of another net, or holds no usable committed state
            (each a `CoralError`, so ``coral-run`` reports it as bad input, naming the log).
        runtime.engine.EngineError: the log's state does not belong to this net.
    """
    log = open_for_resume(log_path, config)
    try:
        model = _simulated_vehicle(mission, config)
        if log.net_digest is not None and log.net_digest != mission.net.digest():
            raise EventLogError(
                f"{log_path} is the log of net {log.net_digest}, but {mission.path} "
                f"compiles to {mission.net.digest()}: resume with the mission that was running"
            )
        _check_resumable(log, log_path)
        rng = random.Random(config.seed ^ 0x5EED)

        def make(link: Link, now: float, nonces: Callable[[int], bytes]) -> Controller:
            log.event(now, "resume", pid=os.getpid())

            def restore(state: Mapping[str, object]) -> Engine:
                engine = Engine.restore(
                    mission.net, mission.approval, state, policy=config.policy, seed=config.seed
                )
                check_verified_state(mission.net, engine.marking)
                return engine

            return Controller.resume(
                restore,
                link,
                config.psk,
                log,
                options=_options(config),
                nonces=nonces,
                console=config.console,
            )

        return _drive(config, make, rng, mission.net.name, model)
    finally:
        log.close()


def open_for_resume(log_path: Path, config: RunConfig) -> EventLog:
    """Open the controller's log for a resume, verified under the run's key.

    A run with a real key (``--key-file``, ``--key-hex``, and always with ``--vehicle``)
    resumes only a log that verifies under it: not edited, not of another key, and
    authenticated at all (a version 1 log, or one written without a key, could have been
    edited undetectably). A simulated run whose key is ephemeral cannot verify anything;
    it resumes only an unauthenticated log, and says so.

    Raises:
        runtime.eventlog.EventLogError: the log does not verify, or cannot be resumed
            by this run; the message names the log and what is wrong.
    """
    key = _log_key(config)
    if key is not None:
        return EventLog.open(log_path, writable=True, mac_key=key)
    with EventLog.open(log_path) as probe:
        authenticated = probe.authenticated
    if authenticated:
        raise EventLogError(
            f"{log_path}: the log is authenticated with its run's key; resume it with that "
            "key (--key-file FILE)"
        )
    if config.vehicle is not None:  # a real vehicle never runs on an ephemeral key
        raise EventLogError(
            f"{log_path}: the log is not authenticated; a real vehicle is resumed only "
            "from a log that verifies under its key"
        )
    config.console(
        f"coral-run: warning: {log_path} is not authenticated (no MAC chain): edits to it "
        "cannot be detected; resuming it only because the vehicle is simulated"
    )
    return EventLog.open(log_path, writable=True)


def _check_resumable(log: EventLog, log_path: Path) -> None:
    """Refuse a log whose committed state cannot be resumed, before anything starts.

    `Controller.resume` checks the same and raises ValueError; checking here first
    keeps a bad log from getting a ``resume`` event or a vehicle connection, and makes
    the refusal an `EventLogError` that names the log (``coral-run`` exit 2).
    """
    state = log.checkpoint()  # EventLogError if it is not a JSON object
    if state is None:
        raise EventLogError(
            f"{log_path}: no committed state to resume from (the run stopped before its "
            "first checkpoint, or the checkpoint row was removed); start the mission anew"
        )
    if not isinstance(state.get("engine"), dict):
        raise EventLogError(
            f"{log_path}: the committed state has no engine state; the log was damaged or edited"
        )
    for field_name in ("mission_id", "consumed"):
        value = state.get(field_name)
        if isinstance(value, bool) or not isinstance(value, int):
            raise EventLogError(
                f"{log_path}: the committed state's {field_name!r} is not a whole number; "
                "the log was damaged or edited"
            )


def check_verified_state(net: Net, marking: Sequence[int]) -> None:
    """Refuse to resume from a marking the verified net can never reach.

    A committed checkpoint is always a reachable marking (the engine only fires enabled
    transitions), so one that is not was damaged or edited: resuming from it would drive
    the vehicle from a state analysis never saw. The state space is explored again (the
    certificate proved it finite; the pool mission takes well under a second); if the
    search cannot finish within its default budget, the check is skipped and said so.

    Raises:
        runtime.engine.EngineError: the marking is not a reachable state of ``net``.
    """
    import numpy as np

    from analysis.statespace import explore
    from runtime.engine import EngineError

    target = np.asarray(marking, dtype=np.int64)
    space = explore(net, stop_when=lambda first, block: bool((block == target).all(axis=1).any()))
    if space.find(lambda block: (block == target).all(axis=1)) is not None:
        return
    if space.complete:
        raise EngineError(
            f"the log's marking {net.marking_dict(marking)} is not a reachable state of the "
            "verified net: the log was damaged or edited; do not resume from it"
        )


def _options(config: RunConfig) -> ControllerOptions:
    if config.time_limit is None:
        return config.controller
    from dataclasses import replace

    return replace(config.controller, time_limit=config.time_limit)


def _net_json(mission: ApprovedMission) -> str:
    import json

    return json.dumps(mission.net.canonical(), sort_keys=True)


MakeController = Callable[[Link, float, Callable[[int], bytes]], Controller]


def _drive(
    config: RunConfig,
    make: MakeController,
    rng: random.Random,
    mission: str,
    model: VehicleModel | None,
) -> RunResult:
    if model is None:
        assert config.vehicle is not None
        host, port = config.vehicle
        return asyncio.run(_remote(config, make, host, port))
    if config.realtime:
        return asyncio.run(_simulated(config, make, rng, mission, model, sockets=True))
    return run_virtual(_simulated(config, make, rng, mission, model, sockets=False))


def _emulator(config: RunConfig) -> LinkEmulator | None:
    return None if config.link is None else LinkEmulator(config.link, seed=config.seed)


STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)
"""Signals that stop a run cleanly (`Controller.request_stop`) while the controller runs."""


@contextlib.contextmanager
def _stop_signals(controller: Controller) -> Iterator[None]:
    """While the controller runs, SIGINT and SIGTERM stop it cleanly instead of killing it.

    Installed on the running loop (real time, or virtual time: the virtual loop polls
    its wakeup pipe on every iteration), so the handler runs between two steps of the
    controller and never inside one. The handlers in place before are put back after,
    so ``coral-run``'s own handling covers the plots and the exit. Outside the main
    thread (no signals there) nothing is installed.
    """
    loop = asyncio.get_running_loop()
    installed: list[tuple[signal.Signals, signal._HANDLER]] = []
    for sig in STOP_SIGNALS:
        previous = signal.getsignal(sig)
        try:
            loop.add_signal_handler(sig, controller.request_stop, sig.name)
        except (NotImplementedError, RuntimeError, ValueError):
            continue
        installed.append((sig, previous))
    try:
        yield
    finally:
        for sig, previous in installed:
            loop.remove_signal_handler(sig)
            if previous is not None:  # None: a handler not set from Python; leave it
                signal.signal(sig, previous)


async def _run_controller(config: RunConfig, controller: Controller) -> RunResult:
    """``controller.run()`` with the run's companions around it and the stop signals on."""
    async with _companions(config.companions, controller, config.console):
        with _stop_signals(controller):
            return await controller.run()


@contextlib.asynccontextmanager
async def _companions(
    companions: Sequence[Companion], controller: Controller, console: Callable[[str], None]
) -> AsyncIterator[None]:
    """Enter each companion in order; exit them in reverse, however the block ends.

    A companion that fails *on exit* (a viewer, a terminal that went away) is reported on
    the console and never replaces the run's result; one that fails on entry stops the
    run before it goes on (bad usage, such as an address that cannot be bound)."""
    async with contextlib.AsyncExitStack() as stack:
        for companion in companions:
            await stack.enter_async_context(_exit_reported(companion(controller), console))
        yield


@contextlib.asynccontextmanager
async def _exit_reported(
    inner: contextlib.AbstractAsyncContextManager[object], console: Callable[[str], None]
) -> AsyncIterator[None]:
    await inner.__aenter__()
    try:
        yield
    except BaseException as error:
        if not await inner.__aexit__(type(error), error, error.__traceback__):
            raise
    else:
        try:
            await inner.__aexit__(None, None, None)
        except Exception as error:
            console(f"coral-run: after the run: {type(error).__name__}: {error}")


async def _remote(config: RunConfig, make: MakeController, host: str, port: int) -> RunResult:
    link = SocketLink(
        host, port, _emulator(config), log=config.console, telemetry_host=config.telemetry_host
    )
    try:
        controller = make(link, asyncio.get_running_loop().time(), os.urandom)
        return await _run_controller(config, controller)
    finally:
        await link.aclose()


async def _simulated(
    config: RunConfig,
    make: MakeController,
    rng: random.Random,
    mission: str,
    model: VehicleModel,
    *,
    sockets: bool,
) -> RunResult:
    loop = asyncio.get_running_loop()
    vehicle_rng = random.Random(rng.getrandbits(64))
    controller_rng = random.Random(rng.getrandbits(64))
    vehicle_log = EventLog.create(
        config.out_dir / VEHICLE_LOG,
        role="vehicle",
        mission=mission,
        # In virtual time both ends share one clock, whatever --speed says.
        meta={"seed": config.seed, "speed": config.speed if sockets else 1.0},
        mac_key=_log_key(config),
    )
    try:
        async with serve_simulated(
            model,
            config.psk,
            _emulator(config),
            nonces=vehicle_rng.randbytes,
            sockets=sockets,
            speed=config.speed if sockets else 1.0,
            log=lambda line: config.console(f"  vehicle: {line}"),
            link_log=config.console,
            event_log=vehicle_log,
        ) as (_, link):
            controller = make(link, loop.time(), controller_rng.randbytes)
            return await _run_controller(config, controller)
    finally:
        vehicle_log.close()
