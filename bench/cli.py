"""Whole-process time of ``coral-check``: start-up, compile, lint, verify, report.

Runs the command ``--runs`` times in fresh processes (as a user or a pre-commit hook
would) and prints the median wall and CPU seconds. Target (issue "coral-check: lint and
pre-mission verification reports"): lint plus verify of the pool mission under 0.5 s
median wall time.

    .venv/bin/python bench/cli.py                      # coral-check on the pool mission
    .venv/bin/python bench/cli.py --runs 21 -- lint examples/pool_mission/pool_mission.coral

Everything after ``--`` replaces the default arguments of ``coral-check``.

With ``PYTHONDONTWRITEBYTECODE`` set, every run compiles coral's modules from source
(about 8,000 lines), which an installed package never does (pip writes the bytecode
at install time). ``--cached-bytecode`` measures that installed case: the runs share a
private bytecode cache (``PYTHONPYCACHEPREFIX``), warmed by one run first.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
DEFAULT_ARGS = ["examples/pool_mission/pool_mission.coral"]
TARGET_S = 0.5


def coral_check_command() -> list[str]:
    """The installed console script next to this interpreter, else ``python -m``."""
    script = Path(sys.executable).with_name("coral-check")
    if script.is_file():
        return [str(script)]
    return [sys.executable, "-m", "analysis.cli"]


def run_once(command: Sequence[str], env: dict[str, str] | None = None) -> tuple[float, float, int]:
    """Wall seconds, CPU seconds (user + system) and exit code of one run."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    completed = subprocess.run(
        command,
        cwd=REPO,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        check=False,
    )
    wall = time.perf_counter() - started
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu, completed.returncode


def main(argv: Sequence[str] | None = None) -> int:
    """Run the bench; returns 0 (the figures are for people, not a pass/fail gate)."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0] if __doc__ else None)
    parser.add_argument("--runs", type=int, default=11, help="fresh processes (default 11)")
    parser.add_argument(
        "--cached-bytecode",
        action="store_true",
        help="measure with compiled bytecode, as an installed package runs",
    )
    parser.add_argument("args", nargs="*", help="coral-check arguments (after --)")
    args = parser.parse_args(argv)
    command = [*coral_check_command(), *(args.args or DEFAULT_ARGS)]
    print(f"command: {' '.join(command)}")
    env = dict(os.environ)
    if args.cached_bytecode:
        env.pop("PYTHONDONTWRITEBYTECODE", None)
        env["PYTHONPYCACHEPREFIX"] = tempfile.mkdtemp(prefix="coral-bench-pycache-")
        run_once(command, env)  # writes the bytecode
        print(f"bytecode cached in {env['PYTHONPYCACHEPREFIX']}")
    elif os.environ.get("PYTHONDONTWRITEBYTECODE"):
        print("PYTHONDONTWRITEBYTECODE is set: each run compiles coral from source")
    walls, cpus, codes = [], [], set()
    for _ in range(args.runs):
        wall, cpu, code = run_once(command, env)
        walls.append(wall)
        cpus.append(cpu)
        codes.add(code)
    median = statistics.median(walls)
    print(
        f"runs {args.runs}  median wall {median:.3f} s  (min {min(walls):.3f}, "
        f"max {max(walls):.3f})  median CPU {statistics.median(cpus):.3f} s  "
        f"exit codes {sorted(codes)}"
    )
    verdict = "meets" if median < TARGET_S else "misses"
    print(f"target: median wall under {TARGET_S} s: {verdict} it")
    return 0


if __name__ == "__main__":
    sys.exit(main())
