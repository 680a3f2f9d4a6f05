"""States, seconds and peak memory of `--method symbolic` (analysis/symbolic) on the
larger conformance instances and on generated nets with more than 10^9 states.

    PYTHONPATH=$PWD python bench/symbolic.py [--time-limit S] [--models A,B|all] [--no-explicit]
        [--strategy saturation|sets|chaining] [--before TREE [--rounds R]]

Each instance runs in a child process so that its peak resident memory (ru_maxrss)
is its own; the oracle's state count is printed beside ours where known. The explicit
explorer (`analysis.statespace.explore`, full search, same time limit, at most
`EXPLICIT_STATES` states) runs beside it in its own child: its states/s and peak
memory, or why it stopped.

`--before TREE` compares instead: each instance's child run from another checkout
(its own `bench/symbolic.py`, with `PYTHONPATH=TREE`) and from this one alternately,
`--rounds` times, and prints the median seconds of each, their ratio, and whether every
run finished (the machine is shared: only alternating runs give honest ratios).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
from pathlib import Path

import yaml

ROOT = Path("/work/shared/conformance")
LARGE = [
    "SharedMemory-PT-000010",
    "DoubleExponent-PT-003",
    "Kanban-PT-00005",
    "FMS-PT-00005",
    "Peterson-PT-3",
    "Dekker-PT-020",
    "Referendum-PT-0015",
    # small state spaces that the chained fixpoint did not finish in 15 s (all now fast)
    "Peterson-PT-2",
    "Anderson-PT-04",
    "DoubleExponent-PT-002",
    "SatelliteMemory-PT-X00100Y0003",
]
GENERATED = ["cycles:40", "cycles:120", "ring:40:12", "ring:60:20"]
EXPLICIT_STATES = 50_000_000


def _net(spec: str) -> object:
    from coral_lang.net import Net, Place, Transition
    from coral_lang.pnml.read import read_pnml

    kind, *args = spec.split(":")
    if kind == "cycles":  # n independent two-place cycles: 2^n markings
        n = int(args[0])
        places = [Place(f"{s}{i}", initial=int(s == "a")) for i in range(n) for s in "ab"]
        trs = [
            Transition(f"{a}{i}", inputs=((f"{a}{i}", 1),), outputs=((f"{b}{i}", 1),))
            for i in range(n)
            for a, b in (("a", "b"), ("b", "a"))
        ]
        return Net(spec, tuple(places), tuple(trs))
    if kind == "ring":  # k tokens on an n-place ring: C(n+k-1, k) markings
        n, k = int(args[0]), int(args[1])
        places = [Place(f"p{i}", initial=k if i == 0 else 0) for i in range(n)]
        trs = [
            Transition(f"t{i}", inputs=((f"p{i}", 1),), outputs=((f"p{(i + 1) % n}", 1),))
            for i in range(n)
        ]
        return Net(spec, tuple(places), tuple(trs))
    return read_pnml(ROOT / "pnml" / f"{spec}.pnml")


def _child(spec: str, time_limit: float, strategy: str | None) -> None:
    from analysis.symbolic import SymbolicLimits, explore_symbolic

    limits = SymbolicLimits(time_limit=time_limit)
    if strategy is not None:  # an older checkout's SymbolicLimits has no strategy
        limits = SymbolicLimits(time_limit=time_limit, strategy=strategy)  # type: ignore[arg-type]
    result = explore_symbolic(_net(spec), limits)  # type: ignore[arg-type]
    peak_kib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    print(
        json.dumps(
            {
                "states": str(result.states),
                "complete": result.complete,
                "reason": result.reason,
                "seconds": round(result.seconds, 2),
                "peak_mib": round(peak_kib / 1024),
                "deadlock": result.deadlock,
            }
        )
    )


def _explicit_child(spec: str, time_limit: float) -> None:
    from analysis.budget import Budget
    from analysis.statespace import explore

    space = explore(_net(spec), max_states=EXPLICIT_STATES, budget=Budget(time_limit))  # type: ignore[arg-type]
    peak_kib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    rate = space.states / space.seconds if space.seconds > 0 else 0.0
    print(
        json.dumps(
            {
                "states": space.states,
                "complete": space.complete,
                "reason": space.stopped_reason,
                "rate": round(rate),
                "peak_mib": round(peak_kib / 1024),
            }
        )
    )


def _run(
    flag: str,
    spec: str,
    time_limit: float,
    strategy: str | None = None,
    tree: Path | None = None,
) -> dict[str, object] | str:
    """One child run, of this checkout or (`tree`) of another one's bench script."""
    script = Path(__file__).resolve() if tree is None else tree / "bench" / "symbolic.py"
    cmd = [sys.executable, str(script), flag, spec, "--time-limit", str(time_limit)]
    if strategy is not None:
        cmd += ["--strategy", strategy]
    env = None
    if tree is not None:
        env = {**os.environ, "PYTHONPATH": str(tree)}
    out = subprocess.run(cmd, capture_output=True, text=True, check=False, env=env)
    if out.returncode != 0:
        return f"failed: {out.stderr.strip().splitlines()[-1:]}"
    row: dict[str, object] = json.loads(out.stdout.strip().splitlines()[-1])
    return row


def _compare(specs: list[str], before: Path, rounds: int, time_limit: float) -> None:
    """This checkout against `before`, alternating, medians of `rounds` runs each."""
    here = Path(__file__).resolve().parent.parent
    print(
        f"{'instance':38} {'before s':>9} {'after s':>9} {'ratio':>6} "
        f"{'before':>9} {'after':>9}  states"
    )
    for spec in specs:
        runs: dict[str, list[dict[str, object]]] = {"before": [], "after": []}
        for r in range(rounds):
            order = ("before", "after") if r % 2 == 0 else ("after", "before")
            for side in order:
                row = _run("--child", spec, time_limit, tree=before if side == "before" else here)
                runs[side].append(row if isinstance(row, dict) else {"complete": False})
        seconds = {
            side: statistics.median(float(str(x.get("seconds", "nan"))) for x in rows)
            for side, rows in runs.items()
        }
        done = {
            side: "complete" if all(x["complete"] for x in rows) else "stopped"
            for side, rows in runs.items()
        }
        ratio = seconds["before"] / seconds["after"] if seconds["after"] else float("nan")
        print(
            f"{spec:38} {seconds['before']:9.2f} {seconds['after']:9.2f} {ratio:6.2f} "
            f"{done['before']:>9} {done['after']:>9}  {runs['after'][0].get('states', '')}",
            flush=True,
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--time-limit", type=float, default=60.0)
    parser.add_argument(
        "--models", default=",".join(GENERATED + LARGE), help="comma-separated, or 'all' (47)"
    )
    parser.add_argument("--no-explicit", action="store_true", help="symbolic only")
    parser.add_argument(
        "--strategy", choices=["saturation", "sets", "chaining"], help="the fixpoint's schedule"
    )
    parser.add_argument("--before", type=Path, help="another checkout to compare against")
    parser.add_argument("--rounds", type=int, default=3, help="alternating runs per side")
    parser.add_argument("--child", help=argparse.SUPPRESS)
    parser.add_argument("--explicit-child", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        _child(args.child, args.time_limit, args.strategy)
        return
    if args.explicit_child:
        _explicit_child(args.explicit_child, args.time_limit)
        return
    specs = args.models.split(",")
    if args.models == "all":
        specs = sorted(path.stem for path in (ROOT / "pnml").glob("*.pnml"))
    if args.before is not None:
        _compare(specs, args.before.resolve(), args.rounds, args.time_limit)
        return
    oracle = {m["model"]: m for m in yaml.safe_load((ROOT / "oracle.yaml").read_text())["models"]}
    print(
        f"{'instance':28} {'states':>26} {'oracle':>12} {'s':>8} {'MiB':>6}  "
        f"{'explicit st/s':>13} {'MiB':>6}  note"
    )
    for spec in specs:
        row = _run("--child", spec, args.time_limit, args.strategy)
        if isinstance(row, str):
            print(f"{spec:28} {row}")
            continue
        explicit: dict[str, object] | str = "not run"
        if not args.no_explicit:
            explicit = _run("--explicit-child", spec, args.time_limit)
        if isinstance(explicit, dict):
            done = "" if explicit["complete"] else f" (stopped: {explicit['reason']})"
            side = f"{explicit['rate']!s:>13} {explicit['peak_mib']!s:>6}"
        else:
            done, side = f" (explicit {explicit})", f"{'-':>13} {'-':>6}"
        expected = oracle.get(spec, {}).get("states", "")
        note = "complete" if row["complete"] else f"inconclusive: {row['reason']}"
        print(
            f"{spec:28} {row['states']!s:>26} {expected!s:>12} {row['seconds']!s:>8} "
            f"{row['peak_mib']!s:>6}  {side}  {note}{done}",
            flush=True,
        )


if __name__ == "__main__":
    main()
