"""States, seconds and peak memory of `--method symbolic` (analysis/symbolic) on the
larger conformance instances and on generated nets with more than 10^9 states.

    PYTHONPATH=$PWD python bench/symbolic.py [--time-limit S] [--models A,B] [--no-explicit]
        [--strategy saturation|chaining]

Each instance runs in a child process so that its peak resident memory (ru_maxrss)
is its own; the oracle's state count is printed beside ours where known. The explicit
explorer (`analysis.statespace.explore`, full search, same time limit, at most
`EXPLICIT_STATES` states) runs beside it in its own child: its states/s and peak
memory, or why it stopped.
"""

from __future__ import annotations

import argparse
import json
import resource
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
    # small state spaces that the chained fixpoint did not finish in 15 s
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
    flag: str, spec: str, time_limit: float, strategy: str | None = None
) -> dict[str, object] | str:
    cmd = [sys.executable, __file__, flag, spec, "--time-limit", str(time_limit)]
    if strategy is not None:
        cmd += ["--strategy", strategy]
    out = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if out.returncode != 0:
        return f"failed: {out.stderr.strip().splitlines()[-1:]}"
    row: dict[str, object] = json.loads(out.stdout.strip().splitlines()[-1])
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--time-limit", type=float, default=60.0)
    parser.add_argument("--models", default=",".join(GENERATED + LARGE))
    parser.add_argument("--no-explicit", action="store_true", help="symbolic only")
    parser.add_argument(
        "--strategy", choices=["saturation", "chaining"], help="the fixpoint's schedule"
    )
    parser.add_argument("--child", help=argparse.SUPPRESS)
    parser.add_argument("--explicit-child", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        _child(args.child, args.time_limit, args.strategy)
        return
    if args.explicit_child:
        _explicit_child(args.explicit_child, args.time_limit)
        return
    oracle = {m["model"]: m for m in yaml.safe_load((ROOT / "oracle.yaml").read_text())["models"]}
    print(
        f"{'instance':28} {'states':>26} {'oracle':>12} {'s':>8} {'MiB':>6}  "
        f"{'explicit st/s':>13} {'MiB':>6}  note"
    )
    for spec in args.models.split(","):
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
