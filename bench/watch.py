"""Engine messages per second of a running controller with and without live viewers.

Run: ``.venv/bin/python bench/watch.py [--chains C] [--length L] [--rounds R] [--viewers V]
[--durable]``.

Issue 13's target: a run with 50 connected viewers, one of them stalled, is at most 5 %
slower than the same run with 0 viewers. Printed too, stricter: the same against a run
with no server at all (what ``--watch`` costs before anyone connects).

The workload makes the engine the bottleneck: a generated mission of ``C`` parallel chains
of ``L`` transitions, every other one a query (``bench/engine.py``'s shape), run by the
real `Controller` (protocol codec, MACs, event log, telemetry) on a real asyncio loop in
real time against a vehicle that answers every command at once (an echo `VehicleModel`
behind the real `VehicleServer`, over the in-memory link), so nothing waits for physics.
The log is written with relaxed durability (no fsync per commit): with fsync the disk
would dominate and hide what viewers cost, so this is the stricter measure;
``--durable`` keeps ``coral-run``'s own durability (an fsync per commit) instead. A *message*
is a command sent or a reply consumed; the rate is messages per wall second of
``controller.run()`` (``msg/s``, the target's figure); ``msg/cpu-s`` divides by the
CPU time of the run's process instead, steadier on a shared machine but blind to the CPU
the viewers' process takes from the run.

Three configurations, alternated in each of ``R`` rounds so a busy moment of the shared
machine hits them alike; medians are printed:

* ``none``: no server at all;
* ``server``: the live server (`serve_live`, loopback, operate right, token file) and
  its `LiveFeed`, no viewer;
* ``viewers``: the same with ``V`` (default 50) viewers connected before the run starts:
  ``V - 1`` aiohttp clients reading the SSE stream and one raw socket that sent its
  request and never reads (its receive buffer shrunk to 4 KiB so it stalls at once).

Fairness: the viewers live in a separate process, as browsers would, so their own
parsing is not charged to the run's process; but it shares the machine's cores with it,
and everything the server does (the listener per row, one snapshot serialised per
publication, writes to 49 sockets) runs in the controller's process and event loop,
which is what is measured.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import gc
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from engine import approval_for, parallel_chains  # bench/engine.py, beside this file

from analysis.certificate import CertificateCheck
from coral_lang.compiler import compile_source
from coral_lang.net import Net
from runtime.controller import Controller, ControllerOptions, RunEnd
from runtime.engine import Engine
from runtime.eventlog import EventLog
from runtime.link import MemoryLink
from runtime.vehicle.model import Params, Reply, TelemetryRecord
from runtime.vehicle.server import VehicleServer
from runtime.watch.feed import LiveFeed
from runtime.watch.live import serve_live

PSK = bytes(range(32))
CONFIGS = ("none", "server", "viewers")

VIEWERS_SCRIPT = r"""
import asyncio, socket, sys
import aiohttp

async def reader(session, url, ready):
    async with session.get(url + "events") as stream:
        first = True
        async for line in stream.content:
            if first and line.startswith(b"data: "):
                first = False
                ready.release()

async def main(url, host, port, count):
    ready = asyncio.Semaphore(0)
    stalled = socket.socket()
    stalled.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    stalled.connect((host, port))
    stalled.sendall(b"GET /events HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
    connector = aiohttp.TCPConnector(limit=0)
    async with aiohttp.ClientSession(connector=connector) as session:
        tasks = [asyncio.create_task(reader(session, url, ready)) for _ in range(count - 1)]
        for _ in range(count - 1):
            await ready.acquire()
        print("ready", flush=True)
        await asyncio.get_running_loop().run_in_executor(None, sys.stdin.read)
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
    stalled.close()

asyncio.run(main(sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])))
"""


class EchoVehicle:
    """A `VehicleModel` that answers every command ``done`` at once (and never tires)."""

    def __init__(self) -> None:
        self._time = 0.0

    @property
    def time(self) -> float:
        return self._time

    @property
    def watchdog_s(self) -> float:
        return 1e6

    def advance_to(self, t: float) -> list[Reply]:
        self._time = max(self._time, t)
        return []

    def command(self, command_id: int, name: str, params: Params) -> list[Reply]:
        return [Reply(command_id, name, "done", self._time)]

    def heard_from_controller(self) -> None:
        pass

    def make_safe(self, reason: str) -> list[Reply]:
        return []

    def telemetry(self) -> TelemetryRecord:
        t = self._time
        return TelemetryRecord(t, t % 50.0, 2.0, 1.0, 90.0, t % 50.0, 2.0)


@dataclass
class Figures:
    messages: int
    seconds: float
    cpu: float


async def one_run(
    net: Net,
    approval: CertificateCheck,
    net_json: str,
    folder: Path,
    config: str,
    viewers: int,
    durable: bool = False,
) -> Figures:
    """One whole mission under ``config``; the controller's figures."""
    loop = asyncio.get_running_loop()
    vehicle = VehicleServer(
        EchoVehicle(), PSK, clock=loop.time, telemetry_hz=10.0, log=lambda line: None
    )
    link = MemoryLink(vehicle, None)
    path = folder / f"{config}-{time.monotonic_ns()}.sqlite"
    log = EventLog.create(path, role="controller", mission=net.name, meta={}, net_json=net_json)
    if not durable:
        log.relax_durability()
    controller = Controller.start_new(
        Engine(net, approval),
        link,
        PSK,
        log,
        mission_id=1,
        now=loop.time(),
        console=lambda line: None,
        options=ControllerOptions(time_limit=3600.0),
    )
    feed: LiveFeed | None = None
    child: asyncio.subprocess.Process | None = None
    figures = Figures(0, 0.0, 0.0)
    try:
        async with contextlib.AsyncExitStack() as stack:
            if config != "none":
                feed = LiveFeed(log, net_json)
                operate = getattr(controller, "operate", None)
                url = await stack.enter_async_context(
                    serve_live(
                        feed,
                        host="127.0.0.1",
                        port=0,
                        operate=operate,
                        token_file=folder / "watch.token" if operate is not None else None,
                        console=lambda line: None,
                        info={"mission": net.name},
                    )
                )
                if config == "viewers":
                    child = await _viewers(url, viewers)
            gc.collect()
            started, cpu = time.perf_counter(), time.process_time()
            result = await controller.run()
            figures.seconds = time.perf_counter() - started
            figures.cpu = time.process_time() - cpu
            if result.end is not RunEnd.FINAL:
                raise SystemExit(f"the run ended {result.end.value}: {result.detail}")
            figures.messages = result.commands_sent + result.replies
    finally:
        if child is not None:
            await _stop(child)
        if feed is not None:
            feed.close()
        log.close()
        await link.aclose()
        await vehicle.stop()
        path.unlink(missing_ok=True)
    return figures


async def _viewers(url: str, count: int) -> asyncio.subprocess.Process:
    """Start the viewers' process; return once all of them are connected."""
    host, port = url.split("//")[1].rstrip("/").rsplit(":", 1)
    child = await asyncio.create_subprocess_exec(
        sys.executable,
        "-c",
        VIEWERS_SCRIPT,
        url,
        host,
        port,
        str(count),
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
    )
    assert child.stdout is not None
    line = await asyncio.wait_for(child.stdout.readline(), 60)
    if line.strip() != b"ready":
        raise SystemExit("the viewers' process did not connect")
    return child


async def _stop(child: asyncio.subprocess.Process) -> None:
    if child.stdin is not None:
        child.stdin.close()
    try:
        await asyncio.wait_for(child.wait(), 10)
    except TimeoutError:
        child.kill()
        await child.wait()


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--chains", type=int, default=20, help="parallel chains (default 20)")
    parser.add_argument("--length", type=int, default=200, help="transitions per chain (200)")
    parser.add_argument("--rounds", type=int, default=5, help="rounds of the 3 configurations")
    parser.add_argument("--viewers", type=int, default=50, help="viewers, one stalled (50)")
    parser.add_argument(
        "--durable", action="store_true", help="fsync each commit, as coral-run does"
    )
    args = parser.parse_args(argv)
    if args.chains < 1 or args.length < 2 or args.rounds < 1 or args.viewers < 1:
        parser.error("--chains, --rounds and --viewers must be at least 1, --length 2")
    text = parallel_chains(args.chains, args.length)
    net = compile_source(text, "bench.coral").raise_for_errors()
    net_json = json.dumps(net.canonical(), sort_keys=True)
    approval = approval_for(net, False)
    gc.collect()
    gc.freeze()  # as coral-run does once the mission is approved (runtime/cli.py)
    runs: dict[str, list[Figures]] = {config: [] for config in CONFIGS}
    with tempfile.TemporaryDirectory() as tmp:
        for _ in range(args.rounds):
            for config in CONFIGS:
                runs[config].append(
                    asyncio.run(
                        one_run(
                            net, approval, net_json, Path(tmp), config, args.viewers, args.durable
                        )
                    )
                )
    rates = {c: statistics.median(f.messages / f.seconds for f in runs[c]) for c in CONFIGS}
    cpu_rates = {c: statistics.median(f.messages / f.cpu for f in runs[c]) for c in CONFIGS}
    print(
        f"{'configuration':<34} {'messages':>9} {'msg/s':>9} {'msg/cpu-s':>10} "
        f"{'wall s':>7} {'cpu s':>6}"
    )
    labels = {
        "none": "no server",
        "server": "live server, 0 viewers",
        "viewers": f"live server, {args.viewers} viewers (1 stalled)",
    }
    for config in CONFIGS:
        figures = runs[config]
        print(
            f"{labels[config]:<34} {figures[0].messages:>9,} {rates[config]:>9,.0f} "
            f"{cpu_rates[config]:>10,.0f} "
            f"{statistics.median(f.seconds for f in figures):>7.2f} "
            f"{statistics.median(f.cpu for f in figures):>6.2f}"
        )
    for config in ("server", "viewers"):
        ratio = rates[config] / rates["none"]
        cpu_ratio = cpu_rates[config] / cpu_rates["none"]
        print(
            f"{labels[config]} / no server: {ratio:.3f} ({(1 - ratio) * 100:+.1f} % slower); "
            f"per CPU second of the run's process {cpu_ratio:.3f}"
        )
    # The target compares the run with 50 viewers to the run with 0 viewers (the
    # server's own cost is what a run pays for --watch at all, shown against no server).
    for base, what in (("server", "0 viewers"), ("none", "no server")):
        slower = (1 - rates["viewers"] / rates[base]) * 100
        verdict = "met" if slower <= 5 else "NOT met"
        print(f"target (at most 5 % slower with viewers than with {what}, wall): {verdict}")
    print(
        f"median of {args.rounds} rounds; mission: {args.chains} chains x {args.length}; "
        f"{'durable' if args.durable else 'relaxed'} log; "
        f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; "
        f"Python {sys.version.split()[0]}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
