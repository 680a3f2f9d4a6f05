"""Timed analysis of the pool mission and of generated missions with parallel branches.

Run: ``.venv/bin/python bench/timed.py [--branches N ...] [--repeat R] [--link P]``.

Prints, per mission, the median wall seconds of `analysis.timed.analyse_timed` over
``--repeat`` runs (compilation excluded), the symbolic states it explored, whether it
finished, and the best and worst time to the mission's first final marking. Targets
(issue 15): the pool mission under 1 s, 8 parallel branches under 10 s.

A generated mission with N branches forks N ways at once; branch i commands a task on
its own resource ``r<i>`` and then a query watching it (time-out 60 s), and ends in one
token whether it succeeded or failed; a join waits for all N. The profile is generated
too (a task's ack after 0.5 s +- 20 %, the query's tracking 30 s +- 20 %).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

from analysis.timed import TimedOptions, analyse_timed
from coral_lang.compiler import compile_source
from coral_lang.linkprofile import BUILTIN_PROFILES, load_link_profile
from coral_lang.mission import load_mission
from coral_lang.net import Net
from coral_lang.profile import VehicleProfile, parse_profile

REPO = Path(__file__).resolve().parent.parent
POOL = REPO / "examples" / "pool_mission" / "pool_mission.coral"


def branches_profile(n: int) -> VehicleProfile:
    """A vehicle with ``n`` independent resources, a task and a query on each."""
    lines = [
        "vehicle: BRANCHY",
        "description: generated for bench/timed.py",
        f"resources: [{', '.join(f'r{i}' for i in range(n))}]",
        "commands:",
    ]
    for i in range(n):
        lines += [
            f"  TASK{i}:",
            "    kind: task",
            "    replies: {ack: started, error: refused}",
            f"    resources: [r{i}]",
            "    duration_s: 0.5",
            f"  TRACK{i}?:",
            "    kind: query",
            "    params:",
            "      - {name: time_out, type: float, unit: s, min: 1.0, max: 3600.0}",
            "    replies: {done: tracked, timeout: time-out passed first}",
            f"    resources: [r{i}]",
            "    duration_s: 30.0",
        ]
    return parse_profile("\n".join(lines) + "\n", "<branches profile>")


def branches_mission(n: int) -> str:
    """The text of a mission with ``n`` parallel branches (module docstring)."""
    places = ", ".join(f"go{i}, set{i}, ok{i}, failed{i}, end{i}" for i in range(n))
    out = [
        f"mission branches_{n}",
        "vehicle BRANCHY",
        "place start = 1",
        f"place {places}, all_done",
        "final { all_done }",
        "transition fork",
        "    wait   { start }",
        f"    signal {{ {', '.join(f'go{i}' for i in range(n))} }}",
    ]
    for i in range(n):
        out += [
            f"transition set_{i}",
            f"    wait   {{ go{i} }}",
            f"    action {{ BRANCHY(TASK{i}) -> {{ ack: set{i}, error: failed{i} }} }}",
            f"transition check_{i}",
            f"    wait   {{ set{i} }}",
            f"    action {{ BRANCHY(TRACK{i}?, time_out = 60 s) "
            f"-> {{ done: ok{i}, timeout: failed{i} }} }}",
            f"transition succeeded_{i}",
            f"    wait   {{ ok{i} }}",
            f"    signal {{ end{i} }}",
            f"transition gave_up_{i}",
            f"    wait   {{ failed{i} }}",
            f"    signal {{ end{i} }}",
        ]
    out += [
        "transition join",
        f"    wait   {{ {', '.join(f'end{i}' for i in range(n))} }}",
        "    signal { all_done }",
    ]
    return "\n".join(out) + "\n"


def compile_branches(n: int) -> tuple[Net, VehicleProfile]:
    """The generated mission with ``n`` branches, compiled, and its profile."""
    profile = branches_profile(n)
    result = compile_source(branches_mission(n), f"<branches {n}>", [profile])
    return result.raise_for_errors(), profile


def measure(net: Net, profiles: list[VehicleProfile], options: TimedOptions, repeat: int) -> str:
    """One table row."""
    times = []
    report = None
    for _ in range(repeat):
        started = time.perf_counter()
        report = analyse_timed(net, profiles, options)
        times.append(time.perf_counter() - started)
    assert report is not None
    first = report.finals[0] if report.finals else None
    bounds = f"{first.best_s:9.1f} {first.worst_s:9.1f}" if first else f"{'-':>9} {'-':>9}"
    done = "yes" if report.complete else f"no ({report.reason})"
    return f"{statistics.median(times):9.3f} {report.states:>9,} {bounds}  {done}"


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--branches", type=int, nargs="*", default=[1, 2, 4, 8])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--link", default="genoa-lisbon", help="link profile (name or file)")
    parser.add_argument("--states", type=int, default=2_000_000, help="symbolic state budget")
    parser.add_argument("--time-limit", type=float, default=30.0, help="seconds per analysis")
    parser.add_argument(
        "--method",
        choices=["auto", "events", "clock", "all"],
        default="all",
        help="auto (coral-check's default), event times, one global clock, or all three "
        "side by side (default)",
    )
    args = parser.parse_args(argv)
    link = (
        BUILTIN_PROFILES[args.link]
        if args.link in BUILTIN_PROFILES
        else load_link_profile(Path(args.link))
    ).analysis_bounds()
    methods = ["auto", "events", "clock"] if args.method == "all" else [args.method]
    print(
        f"timed analysis, link {link.name} ({link.min_delay_s:g} to {link.max_delay_s:g} s "
        f"one way), median of {args.repeat}"
    )
    print(
        f"{'mission':<22} {'method':<7} {'seconds':>9} {'states':>9} {'best s':>9} "
        f"{'worst s':>9}  complete"
    )
    pool = load_mission(POOL)
    missions: list[tuple[str, Net, list[VehicleProfile]]] = [
        ("pool mission", pool.net, list(pool.profiles))
    ]
    for n in args.branches:
        net, profile = compile_branches(n)
        missions.append((f"{n} parallel branches", net, [profile]))
    for name, net, profiles in missions:
        for method in methods:
            options = TimedOptions(
                link=link, max_states=args.states, time_limit_s=args.time_limit, method=method
            )
            print(f"{name:<22} {method:<7} {measure(net, profiles, options, args.repeat)}")
            sys.stdout.flush()
    print("targets: pool mission < 1 s, 8 parallel branches < 10 s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
