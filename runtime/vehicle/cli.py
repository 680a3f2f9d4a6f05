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
import math
import os
import sys
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from coral_lang.diagnostics import CoralError
from coral_lang.profile import VehicleProfile, load_bundled_profile, load_profile
from runtime.vehicle.model import VehicleModel
from runtime.vehicle.options import add_simulation_arguments, fault_plan_from_args

if TYPE_CHECKING:
    from runtime.eventlog import EventLog

__all__ = ["LOG_HELP", "VehicleLogFile", "build_parser", "main"]

LOG_HELP = (
    "write the vehicle's event log (SQLite) to this new file, created when the first "
    "controller is adopted; its mission is the wire mission id in decimal"
)
"""The help of ``--log``, the same on ``coral-vehicle serve`` and ``romeo-sim serve``."""

EXIT_OK = 0
EXIT_BIND = 1
EXIT_USAGE = 2


def _finite(text: str, *, positive: bool) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value) or value < 0.0 or (positive and value == 0.0):
        kind = "positive" if positive else "non-negative"
        raise argparse.ArgumentTypeError(f"expected a {kind} number, got {text!r}")
    return value


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


def _port(text: str) -> int:
    if not (text.isascii() and text.isdigit()) or not 0 <= int(text) <= 65535:
        raise argparse.ArgumentTypeError(f"expected a port in 0..65535, got {text!r}")
    return int(text)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``coral-vehicle``."""
    parser = argparse.ArgumentParser(
        prog="coral-vehicle",
        description="Serve a simulated vehicle for any vehicle profile on the coral wire "
        "protocol, with faults on request, so a mission can be rehearsed over real sockets.",
        epilog="exit codes: 0 clean stop, 1 cannot bind the address, 2 bad usage or input",
    )
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    commands.add_parser("list", help="list the registered simulators")
    serve = commands.add_parser(
        "serve",
        help="serve a simulated vehicle to a controller",
        description="Serve a simulated vehicle on TCP (handshake, commands, replies; one "
        "controller at a time, a reconnecting one resumes its mission) and UDP telemetry. "
        "Prints 'listening on HOST:PORT' when ready.",
    )
    which = serve.add_mutually_exclusive_group(required=True)
    which.add_argument("--profile", type=Path, metavar="FILE", help="the vehicle profile (YAML)")
    which.add_argument("--vehicle", metavar="NAME", help="a bundled profile by name (ROMEO)")
    serve.add_argument("--host", default="127.0.0.1", help="address to listen on (127.0.0.1)")
    serve.add_argument("--port", type=_port, default=0, help="TCP port; 0 picks one (default)")
    key = serve.add_mutually_exclusive_group()
    key.add_argument("--key-file", type=Path, metavar="FILE", help="pre-shared key, hex text")
    key.add_argument(
        "--key-hex",
        metavar="HEX",
        help="pre-shared key on the command line; other users can see it in the process "
        "list: prefer --key-file",
    )
    serve.add_argument("--seed", type=int, default=0, help="seed of the simulated vehicle")
    serve.add_argument(
        "--speed",
        type=lambda t: _finite(t, positive=True),
        default=1.0,
        metavar="FACTOR",
        help="vehicle seconds per wall second (default 1)",
    )
    serve.add_argument(
        "--duration",
        type=lambda t: _finite(t, positive=False),
        default=None,
        metavar="SECONDS",
        help="stop after this many wall seconds (default: until Ctrl-C)",
    )
    serve.add_argument("--log", type=Path, metavar="FILE", help=LOG_HELP)
    add_simulation_arguments(serve)
    return parser


def _profile(args: argparse.Namespace) -> VehicleProfile:
    if args.profile is not None:
        return load_profile(args.profile)
    return load_bundled_profile(str(args.vehicle))


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the exit code."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        return EXIT_OK if exc.code == 0 else EXIT_USAGE
    from runtime.vehicle.registry import simulators

    if args.command == "list":
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
    ``meta``), closed after serving; an existing log file is exit 2, before serving.

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
    try:
        return run_vehicle(
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
            event_log.close()


if __name__ == "__main__":
    raise SystemExit(main())
