"""States, seconds and peak memory of `--method symbolic` (analysis/symbolic) on the
larger conformance instances and on generated nets with more than 10^9 states.

    PYTHONPATH=$PWD python bench/symbolic.py [--time-limit S] [--models A,B]

Each instance runs in a child process so that its peak resident memory (ru_maxrss)
is its own; the oracle's state count is printed beside ours where known.
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
]
GENERATED = ["cycles:40", "cycles:120", "ring:40:12", "ring:60:20"]


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


def _child(spec: str, time_limit: float) -> None:
    from analysis.symbolic import SymbolicLimits, explore_symbolic

    result = explore_symbolic(_net(spec), SymbolicLimits(time_limit=time_limit))  # type: ignore[arg-type]
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--time-limit", type=float, default=60.0)
    parser.add_argument("--models", default=",".join(GENERATED + LARGE))
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        _child(args.child, args.time_limit)
        return
    oracle = {m["model"]: m for m in yaml.safe_load((ROOT / "oracle.yaml").read_text())["models"]}
    print(f"{'instance':28} {'states':>26} {'oracle':>12} {'s':>8} {'MiB':>6}  note")
    for spec in args.models.split(","):
        cmd = [sys.executable, __file__, "--child", spec, "--time-limit", str(args.time_limit)]
        out = subprocess.run(cmd, capture_output=True, text=True, check=False)
        if out.returncode != 0:
            print(f"{spec:28} failed: {out.stderr.strip().splitlines()[-1:]}")
            continue
        row = json.loads(out.stdout.strip().splitlines()[-1])
        expected = oracle.get(spec, {}).get("states", "")
        note = "complete" if row["complete"] else f"inconclusive: {row['reason']}"
        print(
            f"{spec:28} {row['states']:>26} {expected!s:>12} {row['seconds']:>8} "
            f"{row['peak_mib']:>6}  {note}",
            flush=True,
        )


if __name__ == "__main__":
    main()
