"""``coral-vehicle``: serve a simulated vehicle for any profile on the coral wire protocol.

``coral-vehicle serve --profile minnow.yaml --key-file KEY`` serves the vehicle of that
profile (the simulator made for it, else the generic one) to a controller, on localhost
by default, until Ctrl-C or ``--duration``; it prints ``listening on HOST:PORT`` first.
``--fault``/``--faults`` force replies to rehearse failures (``docs/vehicles.md``).
``--log FILE`` writes the vehicle's event log (`VehicleLogFile`; ``romeo-sim serve`` uses
it too). ``coral-vehicle list`` prints the registered simulators.

Exit codes: 0 after a clean stop; 1 the address cannot be bound; 2 bad usage or input
(a profile, key, fault plan or simulator that cannot be used, or a ``--log`` file that
already exists).
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from coral_lang.cliframe import (
    EXIT_FAILED,
    EXIT_OK,
    EXIT_USAGE,
    CommandParser,
    command_parser,
    run_main,
    subcommands,
)
from coral_lang.diagnostics import CoralError
from coral_lang.profile import VehicleProfile, load_bundled_profile, load_profile
from runtime.vehicle.model import VehicleModel
from runtime.vehicle.options import (
    LOG_HELP,
    add_seed_argument,
    add_serve_arguments,
    add_simulation_arguments,
    fault_plan_from_args,
)

if TYPE_CHECKING:
    from runtime.eventlog import EventLog

__all__ = ["LOG_HELP", "VehicleLogFile", "build_parser", "main"]

EXIT_BIND = EXIT_FAILED
"""The address cannot be bound (`runtime.vehicle.server.run_vehicle`'s 1)."""


class VehicleLogFile:
    """A served vehicle's event log: checked at start, created at the first adoption.

    Why not at start: the log's header names its mission, and a served vehicle learns the
    mission only from the controller's first ``Hello``. The header ``mission`` is that
    wire mission id in decimal (``meta`` records it too, as ``mission_id``), which the
    controller's log also records, so ``coral-run timeline`` can pair the two. A later
    mission served by the same process goes on in the same log (its ``adopt`` events name
    its id). An existing file is refused at start: a log is never overwritten. With
    ``mac_key`` (`runtime.eventlog.log_key` of the pre-shared key) the log is
    authenticated as the controller's is (``docs/eventlog.md``).

    Use: pass the instance as ``open_event_log`` to `runtime.vehicle.server.run_vehicle`
    (it is called with the mission id) and `close` it after serving.
    """

    def __init__(
        self, path: Path, meta: Mapping[str, object], *, mac_key: bytes | None = None
    ) -> None:
        """Check that ``path`` can be a new log.

        Raises:
            EventLogError: ``path`` exists (or is a dangling link) or its folder does not.
        """
        from runtime.eventlog import EventLogError

        if os.path.lexists(path):
            raise EventLogError(
                f"{path}: already exists; a vehicle log is never overwritten: give --log a "
                "new file (or move this one away)"
            )
        if not path.absolute().parent.is_dir():
            raise EventLogError(f"{path}: no such folder for the vehicle log")
        self.path = path
        self._meta = dict(meta)
        self._mac_key = mac_key
        self.log: EventLog | None = None

    def __call__(self, mission_id: int) -> EventLog:
        """Create the log for mission ``mission_id`` (once)."""
        from runtime.eventlog import EventLog

        if self.log is None:
            self.log = EventLog.create(
                self.path,
                role="vehicle",
                mission=str(mission_id),
                meta={**self._meta, "mission_id": mission_id},
                mac_key=self._mac_key,
            )
        return self.log

    def close(self) -> None:
        """Close the log if it was created (commits what is left)."""
        if self.log is not None:
            self.log.close()


def build_parser() -> CommandParser:
    """The argument parser of ``coral-vehicle``: ``list`` and ``serve``."""
    parser = command_parser(
        "coral-vehicle",
        "Serve a simulated vehicle for any vehicle profile on the coral wire protocol, "
        "with faults on request, so a mission can be rehearsed over real sockets.",
        epilog="exit codes: 0 clean stop, 1 cannot bind the address, 2 bad usage or input",
    )
    commands = subcommands(parser)
    commands.add_parser(
        "list",
        help="list the registered simulators",
        description="List the registered simulators: NAME and where it is implemented.",
    )
    serve = commands.add_parser(
        "serve",
        help="serve a simulated vehicle to a controller",
        description="Serve a simulated vehicle on TCP (handshake, commands, replies; one "
        "controller at a time, a reconnecting one resumes its mission) and UDP telemetry. "
        "Prints 'listening on HOST:PORT' when ready.",
        epilog="exit codes: 0 clean stop, 1 cannot bind the address, 2 bad usage or input",
    )
    which = serve.add_mutually_exclusive_group(required=True)
    which.add_argument("--profile", type=Path, metavar="FILE", help="the vehicle profile (YAML)")
    which.add_argument("--vehicle", metavar="NAME", help="a bundled profile by name (ROMEO)")
    add_serve_arguments(serve)
    add_seed_argument(serve, "seed of the simulated vehicle")
    add_simulation_arguments(serve)
    return parser


def _profile(args: argparse.Namespace) -> VehicleProfile:
    if args.profile is not None:
        return load_profile(args.profile)
    return load_bundled_profile(str(args.vehicle))


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``coral-vehicle``; returns the exit code (2 on bad usage)."""
    return run_main(build_parser(), argv, _dispatch)


def _dispatch(args: argparse.Namespace) -> int:
    if args.command == "list":
        from runtime.vehicle.registry import simulators

        for name, target in sorted(simulators().items()):
            print(f"{name:10} {target}")
        return EXIT_OK
    from runtime.keys import load_psk
    from runtime.vehicle.registry import create_vehicle

    try:
        key = load_psk(args.key_file, args.key_hex, who="coral-vehicle serve")
        profile = _profile(args)
        plan = fault_plan_from_args(args)
        model = create_vehicle(
            profile, simulator=args.simulator, seed=args.seed, config=args.sim_config, faults=plan
        )
    except (CoralError, OSError) as exc:
        print(f"coral-vehicle: {exc}", file=sys.stderr)
        return EXIT_USAGE
    return _serve(args, key, profile, model)


def _serve(
    args: argparse.Namespace, key: bytes, profile: VehicleProfile, model: VehicleModel
) -> int:
    def log(line: str) -> None:
        print(f"coral-vehicle: {line}", file=sys.stderr, flush=True)

    meta = {
        "seed": args.seed,
        "speed": args.speed,
        "profile": profile.file,
        "vehicle": profile.name,
    }
    log(f"{profile.name} ({type(model).__name__}), speed {args.speed:g}")
    return serve_with_log(model, key, args, meta, log)


def serve_with_log(
    model: VehicleModel,
    key: bytes,
    args: argparse.Namespace,
    meta: Mapping[str, object],
    log: Callable[[str], None],
) -> int:
    """`runtime.vehicle.server.run_vehicle` as a ``serve`` command runs it: with the
    vehicle's own authenticated log when ``args.log`` names one (a `VehicleLogFile` with
    ``meta``), closed after serving; an existing log file is exit 2, before serving, and
    so is a log that cannot take its last commit, after serving (as a controller whose
    log fails).

    ``args`` holds the ``serve`` options both ``coral-vehicle`` and ``romeo-sim`` have:
    ``log``, ``host``, ``port``, ``speed``, ``duration``.
    """
    from runtime.eventlog import log_key
    from runtime.vehicle.server import run_vehicle

    event_log = None
    if args.log is not None:
        try:
            event_log = VehicleLogFile(args.log, meta, mac_key=log_key(key))
        except CoralError as exc:
            log(str(exc))
            return EXIT_USAGE
    closed = True
    try:
        code = run_vehicle(
            model,
            key,
            host=args.host,
            port=args.port,
            speed=args.speed,
            duration=args.duration,
            open_event_log=event_log,
            log=log,
        )
    finally:
        if event_log is not None:
            closed = _close_log(event_log, log)
    return code if closed else EXIT_USAGE


def _close_log(event_log: VehicleLogFile, log: Callable[[str], None]) -> bool:
    """Close the vehicle's log; a log that cannot take its last commit (a full disk, the
    file changed under it) is said in one line, not a traceback. False then."""
    try:
        event_log.close()
    except CoralError as exc:
        log(f"the vehicle log was not closed cleanly: {exc}")
        return False
    return True


if __name__ == "__main__":
    raise SystemExit(main())
