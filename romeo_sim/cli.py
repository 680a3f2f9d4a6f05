"""``romeo-sim``: run the simulated ROMEO offline (the network server comes later).

``romeo-sim mission --out DIR`` runs the paper's pool mission with the scripted driver,
writes figures like the paper's 7-9 (PNG and SVG) and the run log (JSON and CSV) into
DIR, and prints a summary. The exit code is 0 when the mission completed, 1 when it did
not, 2 for a bad vehicle file or arguments.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from romeo_sim.config import VehicleConfigError, load_vehicle_config

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``romeo-sim``."""
    parser = argparse.ArgumentParser(
        prog="romeo-sim",
        description="Simulated ROMEO ROV in a pool: run the paper's pool mission offline.",
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
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns the exit code."""
    args = build_parser().parse_args(argv)
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
