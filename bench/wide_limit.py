"""How far past ``--time-limit`` does ``coral-check verify`` end on very wide nets?

Run ``.venv/bin/python bench/wide_limit.py [--before /work/main] [--repeat 3]
[--limits 1 2 5] [--args="--method symbolic"]``. Each net
(`tests/analysis/wide_nets.py`, from this tree) is written to PNML once, then
``coral-check verify NET.pnml --time-limit T [ARGS]`` runs in a fresh process per limit
and tree (alternating this tree and ``--before``, so machine load hits both alike).
The table shows the median wall time of the whole process (interpreter start and
imports included), its overrun past the limit, and with ``--before`` the ratio of the
two medians. Exit codes other than 0-3 (a traceback) are reported and fail the bench.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
NETS = {
    "rings(2000, 10)": "rings.pnml",  # 20,000 places and transitions
    "parallel_rings(200, 10, 10)": "parallel_rings.pnml",  # 2,000 places, 20,000 transitions
}
WRITE = """
import sys
from pathlib import Path
sys.path.insert(0, sys.argv[3])
from wide_nets import parallel_rings, rings
from coral_lang.pnml import write_pnml
write_pnml(eval(sys.argv[1], {"rings": rings, "parallel_rings": parallel_rings}), Path(sys.argv[2]))
"""
VERIFY = "import sys; from analysis.cli import main; sys.argv[0] = 'coral-check'; sys.exit(main())"


def run(tree: Path, file: Path, limit: float, extra: list[str]) -> tuple[float, int]:
    """Wall seconds and exit code of one ``coral-check verify`` by ``tree``'s code."""
    start = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-c", VERIFY, "verify", str(file), "--time-limit", f"{limit:g}", *extra],
        cwd=tree,
        env={"PYTHONPATH": str(tree), "PATH": "/usr/bin:/bin"},
        capture_output=True,
        text=True,
        check=False,
    )
    seconds = time.perf_counter() - start
    if done.returncode not in (0, 1, 2, 3):
        print(done.stderr[-2000:], file=sys.stderr)
    return seconds, done.returncode


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", type=Path, help="another checkout to compare with")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--limits", type=float, nargs="*", default=[1.0, 2.0, 5.0])
    parser.add_argument("--nets", nargs="*", default=list(NETS))
    parser.add_argument("--args", default="", help="more options of coral-check verify")
    args = parser.parse_args()
    extra = args.args.split()
    trees = {"this": REPO} | ({"before": args.before} if args.before else {})
    failed = False
    with tempfile.TemporaryDirectory() as tmp:
        print(f"{'net':28} {'T':>4} ", end="")
        print("  ".join(f"{name + ' s':>9} {'over':>6}" for name in trees), end="")
        print("    ratio" if args.before else "")
        for net in args.nets:
            file = Path(tmp) / NETS.get(net, "net.pnml")
            subprocess.run(
                [sys.executable, "-c", WRITE, net, str(file), str(REPO / "tests" / "analysis")],
                cwd=REPO,
                env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"},
                check=True,
            )
            for limit in args.limits:
                seconds: dict[str, list[float]] = {name: [] for name in trees}
                for _ in range(args.repeat):
                    for name, tree in trees.items():
                        wall, code = run(tree, file, limit, extra)
                        failed |= code not in (0, 1, 2, 3)
                        seconds[name].append(wall)
                medians = {name: statistics.median(s) for name, s in seconds.items()}
                line = f"{net:28} {limit:4g} "
                line += "  ".join(f"{m:9.2f} {m - limit:6.2f}" for m in medians.values())
                if args.before:
                    line += f" {medians['before'] / medians['this']:8.2f}x"
                line += (
                    "   ("
                    + "; ".join(
                        f"{name} " + " ".join(f"{s:.2f}" for s in runs)
                        for name, runs in seconds.items()
                    )
                    + ")"
                )
                print(line, flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
