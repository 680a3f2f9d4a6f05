"""Exploration rate on generated wide nets: thousands of transitions, few enabled.

Run ``.venv/bin/python bench/wide.py [--before /work/main] [--repeat 3]``. Each net is
explored in a fresh subprocess by this tree and, with ``--before``, by another checkout
(alternating, one after the other, so machine load hits both alike); the table shows
medians of states/s and the ratio. Both sides must find the same states and edges.

The nets (`tests/analysis/wide_nets.py`, taken from this tree for both sides) are
rings of one token each, with extra transitions that never fire or with parallel
copies of each step: what matters is that enabling costs what a marking enables, not
the width of the net. ``rings(3, 100)`` (300 transitions) is the narrow reference.
``count_rings`` put two or three tokens on each ring, so its places are counts, not
one-hot components: the same test for nets of counts, whose narrow reference is
``count_rings(2, 40, 2)`` (80 transitions; the same states as the wide one built on it).
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
NETS = [
    "rings(3, 100)",  # narrow reference: 300 transitions, 10^6 states
    "rings(2, 500, idle=4000)",  # 5,000 transitions, 2.5e5 states
    "parallel_rings(2, 300, 10)",  # 6,000 transitions, 9e4 states, 20 enabled each
    "rings(2, 700, idle=18000)",  # 19,400 transitions, 4.9e5 states
    "count_rings(2, 40, 2)",  # narrow reference of counts: 80 transitions, 6.7e5 states
    "count_rings(2, 40, 2, idle=4000)",  # the same states, 4,080 transitions
    "count_rings(1, 80, 3, idle=18000)",  # 18,080 transitions, 8.9e4 states, 3 tokens
]
CHILD = """
import sys, time
sys.path.insert(0, sys.argv[2])
from wide_nets import count_rings, parallel_rings, rings
from analysis.statespace import explore
names = {"rings": rings, "parallel_rings": parallel_rings, "count_rings": count_rings}
net = eval(sys.argv[1], names)
start = time.perf_counter()
space = explore(net, max_states=10**7)
print(len(net.transitions), space.states, space.edges, time.perf_counter() - start)
"""


def run(tree: Path, net: str, timeout: float) -> tuple[int, int, int, float] | None:
    """Transitions, states, edges and seconds of one exploration by ``tree``'s code;
    None when it did not finish within ``timeout`` seconds."""
    try:
        done = subprocess.run(
            [sys.executable, "-c", CHILD, net, str(REPO / "tests" / "analysis")],
            cwd=tree,
            env={"PYTHONPATH": str(tree), "PATH": "/usr/bin:/bin"},
            capture_output=True,
            text=True,
            timeout=timeout,
            check=True,
        )
    except subprocess.TimeoutExpired:
        return None
    n_t, states, edges, seconds = done.stdout.split()
    return int(n_t), int(states), int(edges), float(seconds)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", type=Path, help="another checkout to compare with")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--timeout", type=float, default=120.0, help="seconds per run")
    parser.add_argument("--nets", nargs="*", default=NETS)
    args = parser.parse_args()
    trees = {"this": REPO} | ({"before": args.before} if args.before else {})
    print(f"{'net':28} {'trans':>6} {'states':>9} {'edges':>9} ", end="")
    print("  ".join(f"{name + ' s':>9} {name + ' st/s':>12}" for name in trees), end="")
    print("    ratio" if args.before else "")
    for net in args.nets:
        seconds: dict[str, list[float]] = {name: [] for name in trees}
        counts: set[tuple[int, int, int]] = set()
        for _ in range(args.repeat):
            for name, tree in trees.items():
                result = run(tree, net, args.timeout)
                if result is None:
                    seconds[name].append(float("inf"))
                    continue
                counts.add(result[:3])
                seconds[name].append(result[3])
        if len(counts) != 1:
            print(f"{net}: the trees disagree or none finished: {sorted(counts)}")
            return 1
        (n_t, states, edges) = counts.pop()
        medians = {name: statistics.median(s) for name, s in seconds.items()}
        line = f"{net:28} {n_t:6} {states:9} {edges:9} "
        line += "  ".join(f"{m:9.2f} {states / m:12,.0f}" for m in medians.values())
        if args.before:
            line += f" {medians['before'] / medians['this']:8.2f}x"
        print(line, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
