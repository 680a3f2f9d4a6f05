"""Schedules per second of ``coral-run fuzz`` on the pool mission; print the figures.

Run: ``.venv/bin/python bench/fuzz.py [--runs N] [--link PROFILE] [--seed S]``.

Two figures:

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
import random
import statistics
import tempfile
import time
from pathlib import Path

from analysis.certificate import check_certificate, make_certificate, write_certificate
from analysis.verify import verify
from coral_lang.cliframe import positive_int
from coral_lang.compiler import compile_mission
from runtime.engine import Engine, Outcome, Policy
from runtime.fuzz import FuzzOptions, fuzz
from runtime.link import load_link_profile
from runtime.schedule import MessageFate, Outage, Schedule, Timing, run_schedule

REPO = Path(__file__).resolve().parent.parent
POOL = REPO / "examples" / "pool_mission" / "pool_mission.coral"


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
        "--engine-schedules",
        type=positive_int,
        default=2000,
        help="engine-level schedules (default 2000)",
    )
    args = parser.parse_args(argv)
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
    for workers in args.workers:
        cpu = time.process_time()
        report = fuzz(net, approval, options, workers=workers)
        cpu = time.process_time() - cpu
        durations = [r.duration for r in report.runs]
        runs = [(r.seed, r.end, r.events_digest) for r in report.runs]
        first = runs if first is None else first
        reached = len(report.runs) - len(report.failures)
        print(
            f"  {workers:>7} {len(report.runs):>5} {report.wall_seconds:>8.2f} {cpu:>21.2f} "
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
