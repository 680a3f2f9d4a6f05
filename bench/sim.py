"""Simulator speed: simulated seconds per wall-clock second for the scripted pool mission.

Run: ``.venv/bin/python bench/sim.py [--runs N]``. Reports the median of N runs (the
first, which warms caches, is not counted) and the ratio to real time; the target is at
least 1,000x (a 400-second mission in under 0.4 s). CPU time is shown too: on a
shared, loaded machine wall time says more about the neighbours than about the code.
"""

from __future__ import annotations

import argparse
import statistics
import time

from coral_lang.profile import load_bundled_profile
from romeo_sim.config import default_config
from romeo_sim.scenario import run_pool_mission

TARGET_RATIO = 1000.0


def main() -> int:
    """Run the benchmark; exit code 1 when below the target."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=11, help="timed runs (default 11)")
    args = parser.parse_args()
    profile = load_bundled_profile("ROMEO")
    config = default_config()
    run_pool_mission(config, profile=profile)  # warm-up
    walls: list[float] = []
    cpus: list[float] = []
    simulated = 0.0
    for seed in range(args.runs):
        start = time.perf_counter()
        cpu_start = time.process_time()
        result = run_pool_mission(config, profile=profile, seed=seed)
        walls.append(time.perf_counter() - start)
        cpus.append(time.process_time() - cpu_start)
        simulated = result.vehicle.time
        if not result.completed:
            print(f"seed {seed}: mission did not complete: {result.reason}")
    wall = statistics.median(walls)
    ratio = simulated / wall
    steps = simulated * config.step_hz
    print(
        f"pool mission: {simulated:.1f} simulated s, median wall {wall * 1e3:.1f} ms "
        f"over {args.runs} runs (min {min(walls) * 1e3:.1f}, max {max(walls) * 1e3:.1f})"
    )
    cpu = statistics.median(cpus)
    print(
        f"CPU time: median {cpu * 1e3:.1f} ms, {simulated / cpu:,.0f}x real time "
        "(what the ratio would be on an idle core)"
    )
    print(
        f"ratio {ratio:,.0f}x real time ({wall / steps * 1e6:.1f} us per {1e3 / config.step_hz:g}"
        f"-ms step, recorder sampling at 2 Hz included); target {TARGET_RATIO:,.0f}x"
    )
    return 0 if ratio >= TARGET_RATIO else 1


if __name__ == "__main__":
    raise SystemExit(main())
