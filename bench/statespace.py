"""Benchmark of the explicit state-space explorer on the MCC conformance models.

Run ``.venv/bin/python bench/statespace.py --help``. Every model runs in a fresh
subprocess (so its peak resident memory is its own), ``--repeat`` times; the table
shows medians. See ``bench/README.md`` for the columns.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
_SHARED = [REPO.parent / "shared", Path("/work/shared")]  # beside the checkout, or the team's
CONFORMANCE = next((d / "conformance" for d in _SHARED if d.is_dir()), _SHARED[0] / "conformance")
SMALL_LIMIT = 300_000  # models up to this many states form the default set
STRETCH = {"Dekker-PT-020"}  # 1.2e9 edges: only with --stretch
VERIFYPN = Path("/work/shared/peers/verifypn")  # TAPAAL's verifypn 4.4.2, see its README
VERIFYPN_FLAGS = ["-n", "1", "-p", "-q", "0", "-e", "--disable-partitioning", "-s", "BFS"]
RATE_RANGE = (100_000, 10_000_000)  # the target "states/s" is a median over this range


@dataclass(frozen=True)
class Row:
    """One model's measured numbers (medians over repeats)."""

    model: str
    states: int
    edges: int
    complete: bool
    seconds: float
    cpu_seconds: float
    stored_bytes: int
    peak_rss: int
    base_rss: int
    words: int
    por_states: int | None = None
    por_seconds: float | None = None

    @property
    def rate(self) -> float:
        return self.states / self.seconds if self.seconds > 0 else float("inf")


def _oracle() -> list[dict[str, Any]]:
    import yaml

    with (CONFORMANCE / "oracle.yaml").open() as handle:
        models: list[dict[str, Any]] = yaml.safe_load(handle)["models"]
    return models


def _rss() -> int:
    """Peak resident set size of this process, bytes (Linux reports KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def worker(model: str, repeat: int, max_states: int, por: bool) -> dict[str, Any]:
    """Explore one model ``repeat`` times in this process; the numbers as a dict."""
    from analysis.encoding import CompactNet
    from analysis.statespace import explore
    from coral_lang.pnml import read_pnml

    net = read_pnml(CONFORMANCE / "pnml" / f"{model}.pnml")
    cn = CompactNet.from_net(net)
    base = _rss()
    seconds, cpu = [], []
    space = None
    for _ in range(repeat):
        space = None  # free the previous run before the next one
        started = time.process_time()
        space = explore(cn, max_states=max_states)
        cpu.append(time.process_time() - started)
        seconds.append(space.seconds)
    assert space is not None
    out: dict[str, Any] = {
        "model": model,
        "states": space.states,
        "edges": space.edges,
        "complete": space.complete,
        "seconds": statistics.median(seconds),
        "cpu_seconds": statistics.median(cpu),
        "stored_bytes": space.stored_bytes,
        "peak_rss": _rss(),
        "base_rss": base,
        "words": space.layout.n_words,
    }
    if por:
        reduced = explore(cn, max_states=max_states, por=True)
        out["por_states"] = reduced.states
        out["por_seconds"] = reduced.seconds
    return out


def peer_worker(model: str) -> dict[str, Any]:
    """Build pm4py's reachability graph of one model; states and seconds."""
    import pm4py  # type: ignore[import-not-found, unused-ignore]
    from pm4py.objects.petri_net.utils import (  # type: ignore[import-not-found, unused-ignore]
        reachability_graph,
    )

    net, initial, _ = pm4py.read_pnml(str(CONFORMANCE / "pnml" / f"{model}.pnml"))
    start = time.perf_counter()
    graph = reachability_graph.construct_reachability_graph(net, initial)
    seconds = time.perf_counter() - start
    return {"model": model, "states": len(graph.states), "seconds": seconds}


def verifypn(model: str, binary: Path, timeout: float) -> dict[str, Any] | None:
    """Run verifypn's full BFS (no reductions) on one model: its wall seconds, peak
    resident memory (from ``wait4``, the child's own) and state count; ``None`` when it
    fails or runs out of time."""
    cmd = [str(binary), *VERIFYPN_FLAGS, str(CONFORMANCE / "pnml" / f"{model}.pnml")]
    started = time.perf_counter()
    with tempfile.TemporaryFile("w+") as sink:
        child = subprocess.Popen(cmd, stdout=sink, stderr=subprocess.DEVNULL)
        while True:  # wait4 gives this child's own peak RSS (RUSAGE_CHILDREN mixes all)
            pid, status, usage = os.wait4(child.pid, os.WNOHANG)
            if pid:
                break
            if time.perf_counter() - started > timeout:
                child.kill()
                os.wait4(child.pid, 0)
                child.returncode = -9
                return None
            time.sleep(0.005)
        seconds = time.perf_counter() - started
        child.returncode = os.waitstatus_to_exitcode(status)
        sink.seek(0)
        out = sink.read()
    peak = usage.ru_maxrss * 1024
    states = next(
        (
            int(line.split()[2])
            for line in out.splitlines()
            if line.startswith("STATE_SPACE STATES")
        ),
        None,
    )
    if states is None:
        return None
    return {"states": states, "seconds": seconds, "peak_rss": peak}


def _run(args: list[str], python: str, timeout: float) -> dict[str, Any] | None:
    env = dict(os.environ, PYTHONPATH=str(REPO))
    try:
        done = subprocess.run(
            [python, str(Path(__file__).resolve()), *args],
            capture_output=True,
            text=True,
            timeout=timeout,
            env=env,
            check=False,
        )
    except subprocess.TimeoutExpired:
        return None
    if done.returncode != 0:
        sys.stderr.write(done.stderr[-2000:])
        return None
    result: dict[str, Any] = json.loads(done.stdout.strip().splitlines()[-1])
    return result


def _mib(n: float) -> str:
    return f"{n / 2**20:,.0f}"


def _header(por: bool, peers: bool) -> str:
    head = (
        f"{'model':<38} {'states':>11} {'edges':>13} {'s':>8} {'states/s':>11} {'st/cpu-s':>11} "
        f"{'peakMiB':>8} {'B/state':>8} {'rssB/st':>8} {'W':>2}"
    )
    if por:
        head += f" {'POR states':>11} {'POR%':>6}"
    if peers:
        head += f" {'pm4py st/s':>11} {'ratio':>7}"
    return head


def _line(r: Row, por: bool, peers: bool, peer: dict[str, Any] | None, peer_timeout: float) -> str:
    line = (
        f"{r.model:<38} {r.states:>11,} {r.edges:>13,} {r.seconds:>8.3f} "
        f"{r.rate:>11,.0f} {r.states / max(r.cpu_seconds, 1e-9):>11,.0f} "
        f"{_mib(r.peak_rss):>8} {r.stored_bytes / r.states:>8.1f} "
        f"{(r.peak_rss - r.base_rss) / r.states:>8.1f} {r.words:>2}"
    )
    if por and r.por_states is not None:
        line += f" {r.por_states:>11,} {100 * r.por_states / r.states:>5.1f}%"
    if peers:
        if peer is None:  # pm4py did not finish: its rate is below states / timeout
            ceiling = r.states / peer_timeout
            line += (
                f" {'<' + format(ceiling, ',.0f'):>11} {'>' + format(r.rate / ceiling, '.0f'):>6}x"
            )
        else:
            rate = peer["states"] / peer["seconds"] if peer["seconds"] > 0 else float("inf")
            line += f" {rate:>11,.0f} {r.rate / rate:>6.0f}x"
    if not r.complete:
        line += "  (incomplete: budget)"
    return line


def _peer_columns(r: Row, peer: dict[str, Any] | None) -> str:
    """verifypn's seconds and peak MiB, and coral's over verifypn's (time: coral's search
    against verifypn's whole run; memory: both processes' peak resident sets)."""
    if peer is None:
        return f" {'failed':>8}"
    agree = "" if peer["states"] == r.states else f"  (verifypn: {peer['states']:,} states!)"
    return (
        f" {peer['seconds']:>8.3f} {_mib(peer['peak_rss']):>7}"
        f" {r.seconds / max(peer['seconds'], 1e-9):>7.2f} {r.peak_rss / peer['peak_rss']:>7.2f}"
        + agree
    )


def _summary(rows: list[Row]) -> None:
    in_range = [r for r in rows if RATE_RANGE[0] <= r.states <= RATE_RANGE[1] and r.complete]
    ranged = [r.rate for r in in_range]
    if ranged:
        print(
            f"median states/s over the {len(ranged)} models with 1e5..1e7 states: "
            f"{statistics.median(ranged):,.0f}"
        )
    cpu = [r.states / max(r.cpu_seconds, 1e-9) for r in in_range]
    if cpu:
        print(f"median states per CPU second over the same models: {statistics.median(cpu):,.0f}")
    overall = statistics.median(r.rate for r in rows)
    print(f"median states/s over all {len(rows)} models: {overall:,.0f}")


def build_parser() -> argparse.ArgumentParser:
    """The command line of the benchmark."""
    parser = argparse.ArgumentParser(
        prog="bench/statespace.py",
        description="Time the vectorised explorer on the MCC conformance models.",
    )
    parser.add_argument("--models", nargs="*", help="model names (default: up to 300k states)")
    parser.add_argument("--large", action="store_true", help="add the 6 large models")
    parser.add_argument("--stretch", action="store_true", help="add Dekker-PT-020 (1.2e9 edges)")
    parser.add_argument("--repeat", type=int, default=3, help="runs per model (median)")
    parser.add_argument("--max-states", type=int, default=20_000_000, help="state budget")
    parser.add_argument("--timeout", type=float, default=900.0, help="seconds per model")
    parser.add_argument("--por", action="store_true", help="also explore with stubborn sets")
    parser.add_argument("--peers", action="store_true", help="also time pm4py, if installed")
    parser.add_argument(
        "--peer-python", default=sys.executable, help="interpreter that has pm4py installed"
    )
    parser.add_argument("--peer-timeout", type=float, default=120.0, help="seconds for pm4py")
    parser.add_argument(
        "--peer",
        action="store_true",
        help="also run verifypn's full BFS on each model; ratios coral/verifypn",
    )
    parser.add_argument("--peer-binary", type=Path, default=VERIFYPN, help="verifypn executable")
    parser.add_argument("--worker", help=argparse.SUPPRESS)
    parser.add_argument("--peer-worker", help=argparse.SUPPRESS)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark; returns the exit code."""
    args = build_parser().parse_args(argv)
    if args.worker:
        print(json.dumps(worker(args.worker, args.repeat, args.max_states, args.por)))
        return 0
    if args.peer_worker:
        print(json.dumps(peer_worker(args.peer_worker)))
        return 0
    oracle = _oracle()
    if args.models:
        names = list(args.models)
    else:
        names = [
            m["model"]
            for m in oracle
            if m["states"] <= SMALL_LIMIT
            or (args.large and m["model"] not in STRETCH)
            or (args.stretch and m["model"] in STRETCH)
        ]
    rows: list[Row] = []
    if args.peer and not args.peer_binary.is_file():
        print(f"bench/statespace.py: --peer: no verifypn at {args.peer_binary}", file=sys.stderr)
        return 2
    head = _header(args.por, args.peers)
    if args.peer:
        head += f" {'vpn s':>8} {'vpnMiB':>7} {'t ratio':>7} {'m ratio':>7}"
    print(head, flush=True)
    for name in names:
        flags = ["--worker", name, "--repeat", str(args.repeat)]
        flags += ["--max-states", str(args.max_states)] + (["--por"] if args.por else [])
        result = _run(flags, sys.executable, args.timeout)
        if result is None:
            print(f"{name}: failed or timed out", flush=True)
            continue
        row = Row(**result)
        rows.append(row)
        peer = None
        if args.peers:
            peer = _run(["--peer-worker", name], args.peer_python, args.peer_timeout)
        line = _line(row, args.por, args.peers, peer, args.peer_timeout)
        if args.peer:
            line += _peer_columns(row, verifypn(name, args.peer_binary, args.timeout))
        print(line, flush=True)
    if rows:
        _summary(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
