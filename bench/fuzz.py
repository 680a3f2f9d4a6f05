"""Schedules per second of ``coral-run fuzz`` on the pool mission; print the figures.

Run: ``.venv/bin/python bench/fuzz.py [--runs N] [--link PROFILE] [--seed S] [--before TREE]``.

Three figures:

* per core, before and after (``--before TREE``, a checkout of an older version, e.g.
  ``git worktree add /tmp/before REV``): the same seeds run serially in a fresh process
  of each tree, alternately, ``--rounds`` times; printed: schedules per second of each
  round, the medians and their ratio. Only the package code differs: both processes run
  this file's measuring loop, with the older tree first on the import path.

* network level, what ``coral-run fuzz`` does: each schedule is one whole run of the
  pool mission through the controller, its event log, the link emulator and the
  simulated ROMEO under virtual time (default 20 runs over 'genoa-lisbon'). Printed:
  runs, wall seconds, schedules/s, CPU seconds, median virtual mission time, and how
  many runs reached a final marking.
* engine level, what the property tests do (`runtime.schedule`): the engine alone fed
  replies from random schedules (delays, work times, failures, outages drawn from a
  seeded generator; no hypothesis, whose own overhead is not the engine's).

The pool mission is verified first and runs under its real certificate.
"""

from __future__ import annotations

import argparse
import os
import random
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from analysis.certificate import (
    CertificateCheck,
    check_certificate,
    make_certificate,
    write_certificate,
)
from analysis.verify import verify
from coral_lang.cliframe import positive_int
from coral_lang.compiler import compile_mission
from coral_lang.net import Net
from runtime.engine import Engine, Outcome, Policy
from runtime.fuzz import FuzzOptions, FuzzReport, fuzz
from runtime.link import load_link_profile
from runtime.schedule import MessageFate, Outage, Schedule, Timing, run_schedule

REPO = Path(__file__).resolve().parent.parent
POOL = REPO / "examples" / "pool_mission" / "pool_mission.coral"


SERIAL = """
import sys, time
from pathlib import Path
from analysis.certificate import CertificateCheck, tool_version
from coral_lang.compiler import compile_mission
from runtime.fuzz import FuzzOptions, run_one
from runtime.link import load_link_profile
runs, seed, link = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
net = compile_mission(Path("examples/pool_mission/pool_mission.coral"))
approval = CertificateCheck(
    path="unverified (fuzz only)", net_digest=net.digest(), issued="", tool_version=tool_version()
)
options = FuzzOptions(runs=runs, seed=seed, link=load_link_profile(link))
run_one(net, approval, seed + runs, options)  # warm-up (imports, caches): not timed
wall, cpu = time.perf_counter(), time.process_time()
for index in range(runs):
    run_one(net, approval, seed + index, options)
print(runs / (time.perf_counter() - wall), runs / (time.process_time() - cpu))
"""
"""Runs seeds ``seed .. seed+runs-1`` serially; prints schedules per wall and per CPU second.
The same text runs in both trees, so only their packages differ."""


def serial_rate(tree: Path, runs: int, seed: int, link: str) -> tuple[float, float]:
    """Schedules per wall second and per CPU second of a serial fuzz in ``tree``'s code."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    out = subprocess.run(
        [sys.executable, "-c", SERIAL, str(runs), str(seed), link],
        cwd=tree,
        env=env,
        check=True,
        capture_output=True,
        text=True,
    ).stdout.split()
    return float(out[0]), float(out[1])


def before_and_after(before: Path, runs: int, seed: int, link: str, rounds: int) -> None:
    """Print per-core schedules per second of ``before`` and of this tree, alternately."""
    print(f"per core: {runs} serial runs of the pool mission over '{link}', {rounds} rounds")
    print(f"  {'round':>5} {'before /s':>10} {'after /s':>10}   (wall; per CPU second)")
    rates: dict[str, list[float]] = {"before": [], "after": []}
    for number in range(1, rounds + 1):
        old = serial_rate(before, runs, seed, link)
        new = serial_rate(REPO, runs, seed, link)
        rates["before"].append(old[0])
        rates["after"].append(new[0])
        print(
            f"  {number:>5} {old[0]:>10.2f} {new[0]:>10.2f}   "
            f"({old[1]:.2f} and {new[1]:.2f} per CPU second)"
        )
    old_median = statistics.median(rates["before"])
    new_median = statistics.median(rates["after"])
    print(
        f"  median {old_median:>9.2f} {new_median:>10.2f}   "
        f"after / before: {new_median / old_median:.2f}x"
    )


def _on_ray(
    net: Net, approval: CertificateCheck, options: FuzzOptions, cpus: int
) -> list[tuple[str, FuzzReport, float]]:
    """The campaign on a local Ray cluster of ``cpus``: started for it (its start and stop
    in the wall time, as for ``coral-run fuzz --ray``), then on one already running."""
    import ray

    from runtime.fuzz import RayTarget

    rows = []
    cpu = time.process_time()
    report = fuzz(net, approval, options, ray=RayTarget(address=None, cpus=cpus))
    rows.append((f"ray {cpus}", report, time.process_time() - cpu))
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    ray.init(num_cpus=cpus, include_dashboard=False, log_to_driver=False)
    try:
        cpu = time.process_time()
        report = fuzz(net, approval, options, ray=RayTarget(address=None, cpus=cpus))
        rows.append((f"ray {cpus}+", report, time.process_time() - cpu))
    finally:
        ray.shutdown()
    return rows


def random_schedule(rng: random.Random) -> Schedule:
    """A schedule like `runtime.schedule_strategies.schedules` draws, from ``rng``."""
    messages = tuple(
        MessageFate(
            reply=0 if rng.random() < 0.75 else 1,
            up_ms=rng.randrange(10_001),
            work_permille=rng.randrange(500, 1501),
            down_ms=rng.randrange(10_001),
            rank=rng.randrange(4),
        )
        for _ in range(rng.randrange(49))
    )
    outages = tuple(
        Outage(rng.randrange(600_001), rng.randrange(20_001)) for _ in range(rng.randrange(3))
    )
    return Schedule(messages, outages)


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument(
        "--runs", type=positive_int, default=20, help="network-level runs (default 20)"
    )
    parser.add_argument(
        "--link", default="genoa-lisbon", help="link profile (default genoa-lisbon)"
    )
    parser.add_argument("--seed", type=int, default=0, help="first run seed (default 0)")
    parser.add_argument(
        "--workers",
        type=positive_int,
        nargs="*",
        default=[1, 2],
        help="campaigns side by side with these numbers of local worker processes (default 1 2)",
    )
    parser.add_argument(
        "--ray",
        type=positive_int,
        nargs="*",
        default=[],
        metavar="CPUS",
        help="also on a local Ray cluster of CPUS (e.g. --ray 2; needs the ray extra): once "
        "with the cluster started for the campaign, as coral-run fuzz --ray does, once "
        "with it already running",
    )
    parser.add_argument(
        "--engine-schedules",
        type=positive_int,
        default=2000,
        help="engine-level schedules (default 2000)",
    )
    parser.add_argument(
        "--before",
        type=Path,
        help="a checkout of an older version: time it against this one, per core",
    )
    parser.add_argument(
        "--rounds", type=positive_int, default=3, help="alternate rounds for --before (3)"
    )
    args = parser.parse_args(argv)
    if args.before is not None:
        fuzz_code = args.before / "runtime"
        if not ((fuzz_code / "fuzz").is_dir() or (fuzz_code / "fuzz.py").is_file()):
            parser.error(f"--before {args.before}: not a checkout of coral (no runtime/fuzz)")
        before_and_after(args.before.resolve(), args.runs, args.seed, args.link, args.rounds)
    net = compile_mission(POOL)
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "pool.certificate.json"
        write_certificate(make_certificate(verify(net)), path)
        approval = check_certificate(net, path)

    options = FuzzOptions(runs=args.runs, seed=args.seed, link=load_link_profile(args.link))
    print(f"network level: pool mission over '{args.link}', engine policy random")
    print(
        f"  {'workers':>7} {'runs':>5} {'wall s':>8} {'CPU s (this process)':>21} "
        f"{'schedules/s':>12} {'median mission s':>17} {'final':>7}  same runs as 1 worker"
    )
    report = None
    first = None
    setups: list[tuple[str, int, bool]] = [(str(w), w, False) for w in args.workers]
    setups += [(f"ray {c}", c, True) for c in args.ray]
    for label, workers, on_ray in setups:
        if on_ray:
            rows = _on_ray(net, approval, options, workers)
        else:
            cpu = time.process_time()
            report = fuzz(net, approval, options, workers=workers)
            rows = [(label, report, time.process_time() - cpu)]
        for name, report, cpu in rows:
            durations = [r.duration for r in report.runs]
            runs = [(r.seed, r.end, r.events_digest) for r in report.runs]
            first = runs if first is None else first
            reached = len(report.runs) - len(report.failures)
            print(
                f"  {name:>7} {len(report.runs):>5} {report.wall_seconds:>8.2f} {cpu:>21.2f} "
                f"{report.schedules_per_second:>12.2f} {statistics.median(durations):>17.1f} "
                f"{reached:>3}/{len(report.runs):<3}  {'yes' if runs == first else 'NO'}"
            )
    assert report is not None

    rng = random.Random(args.seed)
    timing = Timing(net)
    schedules = [random_schedule(rng) for _ in range(args.engine_schedules)]
    finals = 0
    start = time.perf_counter()
    for i, schedule in enumerate(schedules):
        engine = Engine(net, approval, policy=Policy.RANDOM, seed=i)
        finals += run_schedule(engine, schedule, timing).outcome is Outcome.FINAL
    seconds = time.perf_counter() - start
    print("engine level: pool mission, random schedules (runtime.schedule)")
    print(f"  schedules                 {len(schedules)}")
    print(f"  wall seconds              {seconds:.2f}")
    print(f"  schedules/s               {len(schedules) / seconds:.0f}")
    print(f"  reached a final marking   {finals}/{len(schedules)}")
    return 0 if not report.failures and finals == len(schedules) else 1


if __name__ == "__main__":
    raise SystemExit(main())
