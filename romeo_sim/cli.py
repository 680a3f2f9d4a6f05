"""``romeo-sim``: run the simulated ROMEO offline, or serve it on the wire protocol.

``romeo-sim mission --out DIR`` runs the paper's pool mission with the scripted driver,
writes figures like the paper's 7-9 (PNG and SVG) and the run log (JSON and CSV) into
DIR, and prints a summary. The exit code is 0 when the mission completed, 1 when it did
not, 2 for a bad vehicle file or arguments.

``romeo-sim serve --key-file FILE`` serves the vehicle to a controller (the CORAL engine)
on TCP and UDP (`runtime.vehicle.server.VehicleServer`) until Ctrl-C or ``--duration``; it
prints ``listening on HOST:PORT`` first; ``--log FILE`` writes the vehicle's event log
(`runtime.vehicle.cli.VehicleLogFile`: created at the first controller's Hello, named
after its wire mission id). The exit code is 0 after a clean stop, 2 for a missing or bad
key, an existing log file, a bad vehicle file or arguments, 1 if the address cannot be
bound.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from coral_lang.cliframe import (
    EXIT_FAILED,
    EXIT_OK,
    EXIT_USAGE,
    CommandParser,
    command_parser,
    run_main,
    subcommands,
)
from romeo_sim.config import VehicleConfigError, load_vehicle_config
from runtime.vehicle.options import add_seed_argument, add_serve_arguments

__all__ = ["build_parser", "main"]

VEHICLE_HELP = "vehicle YAML overriding the bundled romeo_vehicle.yaml (docs/sim.md)"


def build_parser() -> CommandParser:
    """The argument parser of ``romeo-sim``: ``mission`` and ``serve``."""
    parser = command_parser(
        "romeo-sim",
        "Simulated ROMEO ROV in a pool: run the paper's pool mission offline, or serve "
        "the vehicle to a controller on the coral wire protocol.",
        epilog="exit codes: 0 the mission completed / a clean stop, 1 the mission did not "
        "complete / the address cannot be bound, 2 bad usage or input",
    )
    commands = subcommands(parser)
    mission = commands.add_parser(
        "mission",
        help="run the scripted pool mission and write plots and the run log",
        description=(
            "Run the paper's pool mission (go to operating site, way-point navigation, "
            "docking) with a scripted driver, as fast as the CPU allows."
        ),
        epilog="exit codes: 0 the mission completed, 1 it did not, 2 bad usage or input",
    )
    mission.add_argument(
        "--out", type=Path, default=Path("out/sim"), help="folder for figures and logs"
    )
    add_seed_argument(mission, "noise seed")
    mission.add_argument("--vehicle", type=Path, default=None, metavar="YAML", help=VEHICLE_HELP)
    mission.add_argument("--no-plots", action="store_true", help="write only the run log")
    serve = commands.add_parser(
        "serve",
        help="serve the simulated vehicle to a controller on the coral wire protocol",
        description=(
            "Serve the simulated ROMEO on the coral wire protocol (docs/protocol.md): TCP for "
            "the handshake, commands and replies (one controller at a time; a reconnecting "
            "controller resumes its mission), UDP telemetry at 2 Hz of vehicle time to the "
            "port the controller announces. Prints 'listening on HOST:PORT' when ready. A "
            "pre-shared key of at least 16 bytes is required."
        ),
        epilog="exit codes: 0 clean stop, 1 cannot bind the address, 2 bad usage or input",
    )
    add_serve_arguments(serve)
    add_seed_argument(serve, "noise seed")
    serve.add_argument("--vehicle", type=Path, default=None, metavar="YAML", help=VEHICLE_HELP)
    return parser


def _serve(args: argparse.Namespace) -> int:
    from runtime.keys import KeyProblem, load_psk

    try:
        key = load_psk(args.key_file, args.key_hex, who="serve")
    except KeyProblem as exc:
        print(f"romeo-sim: {exc}", file=sys.stderr)
        return EXIT_USAGE
    try:
        config = None if args.vehicle is None else load_vehicle_config(args.vehicle)
    except VehicleConfigError as exc:
        print(f"romeo-sim: {exc}", file=sys.stderr)
        return EXIT_USAGE
    from romeo_sim.vehicle import Vehicle
    from runtime.vehicle.cli import serve_with_log

    vehicle_file = None if args.vehicle is None else str(args.vehicle.resolve())
    meta = {"seed": args.seed, "speed": args.speed, "vehicle": "ROMEO", "config": vehicle_file}
    return serve_with_log(
        Vehicle(config, seed=args.seed),
        key,
        args,
        meta,
        lambda line: print(f"romeo-sim: {line}", file=sys.stderr, flush=True),
    )


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``romeo-sim``; returns the exit code (2 on bad usage)."""
    return run_main(build_parser(), argv, _dispatch)


def _dispatch(args: argparse.Namespace) -> int:
    if args.command == "serve":
        return _serve(args)
    # Imported here so that `romeo-sim --help` stays fast.
    from romeo_sim.plots import plot_run
    from romeo_sim.scenario import mission_targets, run_pool_mission

    try:
        config = None if args.vehicle is None else load_vehicle_config(args.vehicle)
    except VehicleConfigError as exc:
        print(f"romeo-sim: {exc}", file=sys.stderr)
        return EXIT_USAGE
    out: Path = args.out
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        print(f"romeo-sim: cannot write to {out}: {exc.strerror or exc}", file=sys.stderr)
        return EXIT_USAGE
    result = run_pool_mission(config, seed=args.seed)
    written = [result.recorder.write_json(out / "run.json"), *result.recorder.write_csv(out)]
    if not args.no_plots:
        pool = result.vehicle.config.pool
        written += plot_run(
            result.recorder,
            out,
            targets=mission_targets(result.mission),
            dock=result.dock,
            pool=(pool.length_m, pool.width_m),
            phases=[(p.name, p.start, p.end) for p in result.phases],
        )
    state = "completed" if result.completed else "FAILED"
    print(f"pool mission {state}: {result.reason}")
    for phase in result.phases:
        print(f"  {phase.name}: {phase.start:.1f}-{phase.end:.1f} s")
    print(f"wrote {len(written)} files to {out}")
    return EXIT_OK if result.completed else EXIT_FAILED


if __name__ == "__main__":
    raise SystemExit(main())
