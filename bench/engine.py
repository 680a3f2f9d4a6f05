"""Messages per second and latency per message of the CORAL Engine; print the figures.

Run: ``.venv/bin/python bench/engine.py [--repeat R]``.

A *message* is one reply from the vehicle: the engine fires its reply transition and then
every engine transition it enables, and returns the commands to send. The vehicle is
scripted (it answers every command at once with its first reply kind, in the order sent),
so only the engine is measured: no sockets, no event log.

Nets: the paper's pool mission, and two generated 10,000-transition missions: a chain
(one command in flight at a time, as in bench/compile.py) and 100 parallel chains (100
commands in flight, 100 enabled reply transitions at every step). Target (issue 6): at
least 100,000 messages per second on the large nets, and a per-message cost that does
not grow with the size of the net.

The engine runs only certified nets. Verifying the generated nets is not what this
measures, so the benchmark builds their approvals itself (``--verify`` verifies them and
uses real certificates instead, which takes longer).
"""

from __future__ import annotations

import argparse
import gc
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

from compile import generate_mission  # bench/compile.py, beside this file

from analysis.certificate import (
    CertificateCheck,
    check_certificate,
    make_certificate,
    write_certificate,
)
from analysis.verify import verify
from coral_lang.compiler import compile_mission, compile_source
from coral_lang.net import Net
from runtime.engine import Engine, Outcome

REPO = Path(__file__).resolve().parent.parent
POOL = REPO / "examples" / "pool_mission" / "pool_mission.coral"


def parallel_chains(chains: int, length: int) -> str:
    """``chains`` parallel chains of ``length`` transitions, every other one a query."""
    lines = ["mission parallel", "vehicle ROMEO", "const T = 60 s", "place start = 1, abort"]
    for c in range(chains):
        lines.extend(f"place c{c}_{i}" for i in range(length + 1))
    lines.append("final { " + ", ".join(f"c{c}_{length}" for c in range(chains)) + " }")
    lines.append(
        "transition fork\n    wait { start }\n    signal { "
        + ", ".join(f"c{c}_0" for c in range(chains))
        + " }"
    )
    for c in range(chains):
        for i in range(length):
            here, there = f"c{c}_{i}", f"c{c}_{i + 1}"
            if i % 2 == 0:
                lines.append(
                    f"transition t{c}_{i}\n    wait {{ {here} }}\n"
                    f"    action {{ ROMEO(XY?, x = 1.0 m, y = 2.0 m, time_out = T) "
                    f"-> {{ done: {there}, timeout: abort }} }}"
                )
            else:
                lines.append(
                    f"transition t{c}_{i}\n    wait {{ {here} }}\n    signal {{ {there} }}"
                )
    return "\n".join(lines) + "\n"


def approval_for(net: Net, really_verify: bool) -> CertificateCheck:
    """A real certificate (``--verify``) or an approval built here (see the docstring)."""
    if not really_verify:
        return CertificateCheck("bench (not verified)", net.digest(), "", "")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "cert.json"
        write_certificate(make_certificate(verify(net)), path)
        return check_certificate(net, path)


def run_once(
    net: Net, approval: CertificateCheck, freeze: bool = True
) -> tuple[int, float, list[int]]:
    """One whole mission; returns (messages, seconds, per-message latencies in ns)."""
    engine = Engine(net, approval)
    if freeze:
        gc.collect()
        gc.freeze()  # as coral-run does: the net lives as long as the process
    pending = list(engine.start(0.0).commands)
    latencies: list[int] = []
    clock = time.perf_counter_ns
    started = clock()
    head = 0
    while head < len(pending):
        cmd = pending[head]
        head += 1
        t0 = clock()
        step = engine.on_reply(cmd.command_id, cmd.command.replies[0], 0.0)
        latencies.append(clock() - t0)
        pending.extend(step.commands)
    seconds = (clock() - started) / 1e9
    if engine.outcome() is not Outcome.FINAL:
        raise SystemExit(f"{net.name}: the scripted run did not reach a final marking")
    return len(latencies), seconds, latencies


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--repeat", type=int, default=5, help="runs per net (default 5)")
    parser.add_argument("--verify", action="store_true", help="verify and certify every net")
    parser.add_argument(
        "--no-freeze", action="store_true", help="leave the net's objects to the cyclic GC"
    )
    args = parser.parse_args(argv)
    nets = [("pool mission", compile_mission(POOL))]
    for size in (100, 1_000, 10_000):  # same shape, growing: the cost must stay flat
        text = generate_mission(size)
        nets.append(
            (f"chain, {size:,} transitions", compile_source(text, "chain.coral").raise_for_errors())
        )
    nets.append(
        (
            "100 parallel chains, 10,001 transitions",
            compile_source(parallel_chains(100, 100), "parallel.coral").raise_for_errors(),
        )
    )
    print(
        f"{'net':<42} {'transitions':>11} {'messages':>9} {'msg/s':>11} "
        f"{'median us':>10} {'p99 us':>8} {'checks/msg':>10}"
    )
    for label, net in nets:
        approval = approval_for(net, args.verify)
        rates, medians, p99s = [], [], []
        messages = 0
        for _ in range(args.repeat):
            messages, seconds, lat = run_once(net, approval, not args.no_freeze)
            rates.append(messages / seconds)
            lat.sort()
            medians.append(lat[len(lat) // 2] / 1000)
            p99s.append(lat[min(len(lat) - 1, int(len(lat) * 0.99))] / 1000)
        engine = Engine(net, approval)
        pending = list(engine.start(0.0).commands)
        before = engine.checks
        count = 0
        while pending:
            cmd = pending.pop(0)
            pending.extend(engine.on_reply(cmd.command_id, cmd.command.replies[0], 0.0).commands)
            count += 1
        print(
            f"{label:<42} {len(net.transitions):>11,} {messages:>9,} "
            f"{statistics.median(rates):>11,.0f} {statistics.median(medians):>10.2f} "
            f"{statistics.median(p99s):>8.2f} {(engine.checks - before) / count:>10.2f}"
        )
    print(
        f"median of {args.repeat} runs each; load average {os.getloadavg()[0]:.1f} on "
        f"{os.cpu_count()} cores; Python {sys.version.split()[0]}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
