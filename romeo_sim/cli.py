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
import math
import sys
from collections.abc import Sequence
from pathlib import Path

from romeo_sim.config import VehicleConfigError, load_vehicle_config

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``romeo-sim``."""
    parser = argparse.ArgumentParser(
        prog="romeo-sim",
        description=(
            "Simulated ROMEO ROV in a pool: run the paper's pool mission offline, or serve "
            "the vehicle to a controller on the coral wire protocol."
        ),
    )
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    mission = commands.add_parser(
        "mission",
        help="run the scripted pool mission and write plots and the run log",
        description=(
            "Run the paper's pool mission (go to operating site, way-point navigation, "
            "docking) with a scripted driver, as fast as the CPU allows."
        ),
    )
    mission.add_argument(
        "--out", type=Path, default=Path("out/sim"), help="folder for figures and logs"
    )
    mission.add_argument("--seed", type=int, default=0, help="noise seed (default 0)")
    mission.add_argument(
        "--vehicle",
        type=Path,
        default=None,
        help="vehicle YAML overriding the bundled romeo_vehicle.yaml",
    )
    mission.add_argument("--no-plots", action="store_true", help="write only the run log")
    _add_serve_parser(commands)
    return parser


def _add_serve_parser(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
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
    )
    serve.add_argument(
        "--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)"
    )
    serve.add_argument(
        "--port", type=int, default=0, help="TCP port; 0 lets the system pick one (default 0)"
    )
    key = serve.add_mutually_exclusive_group()
    key.add_argument(
        "--key-file",
        type=Path,
        metavar="FILE",
        help="file holding the pre-shared key as hex text (white space ignored)",
    )
    key.add_argument(
        "--key-hex",
        metavar="HEX",
        help="the pre-shared key as hex on the command line; other users can see it in the "
        "process list: prefer --key-file",
    )
    serve.add_argument("--seed", type=int, default=0, help="noise seed (default 0)")
    serve.add_argument(
        "--speed",
        type=float,
        default=1.0,
        metavar="FACTOR",
        help="vehicle clock rate as a multiple of real time (default 1.0)",
    )
    serve.add_argument(
        "--vehicle",
        type=Path,
        default=None,
        help="vehicle YAML overriding the bundled romeo_vehicle.yaml",
    )
    serve.add_argument(
        "--duration",
        type=float,
        default=None,
        metavar="SECONDS",
        help="stop after this many wall-clock seconds (default: run until Ctrl-C)",
    )
    serve.add_argument(
        "--log",
        type=Path,
        metavar="FILE",
        help="write the vehicle's event log (SQLite) to this new file, created when the "
        "first controller is adopted; its mission is the wire mission id in decimal",
    )


def _serve(args: argparse.Namespace) -> int:
    try:
        from runtime.keys import KeyProblem, load_psk

        key = load_psk(args.key_file, args.key_hex, who="serve")
    except KeyProblem as exc:
        print(f"romeo-sim: {exc}", file=sys.stderr)
        return 2
    if not math.isfinite(args.speed) or args.speed <= 0.0:
        print(f"romeo-sim: --speed must be a positive number, got {args.speed}", file=sys.stderr)
        return 2
    if args.duration is not None and (not math.isfinite(args.duration) or args.duration < 0.0):
        print(f"romeo-sim: --duration must be >= 0 seconds, got {args.duration}", file=sys.stderr)
        return 2
    if not 0 <= args.port <= 65535:
        print(f"romeo-sim: --port must be in 0..65535, got {args.port}", file=sys.stderr)
        return 2
    try:
        config = None if args.vehicle is None else load_vehicle_config(args.vehicle)
    except VehicleConfigError as exc:
        print(f"romeo-sim: {exc}", file=sys.stderr)
        return 2
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
    """Entry point; returns the exit code."""
    args = build_parser().parse_args(argv)
    if args.command == "serve":
        return _serve(args)
    # Imported here so that `romeo-sim --help` stays fast.
    from romeo_sim.plots import plot_run
    from romeo_sim.scenario import mission_targets, run_pool_mission

    try:
        config = None if args.vehicle is None else load_vehicle_config(args.vehicle)
    except VehicleConfigError as exc:
        print(f"romeo-sim: {exc}", file=sys.stderr)
        return 2
    result = run_pool_mission(config, seed=args.seed)
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
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
    return 0 if result.completed else 1


if __name__ == "__main__":
    raise SystemExit(main())
