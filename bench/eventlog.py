"""Events appended per second to an event log, with and without the MAC chain.

Run: ``.venv/bin/python bench/eventlog.py [--events N] [--per-commit K] [--runs R]``.

Each run creates a log in a temporary folder, appends ``N`` events shaped like the
engine's (a ``fire`` with a marking, a ``command-sent`` with parameters), commits a state
every ``K`` events, closes it, then opens it again with the key to verify it. Unkeyed and
keyed runs alternate, so a busy moment on a shared machine hits both alike; the table
gives the median of ``R`` runs of each.

Two durabilities: ``full`` (``synchronous=FULL``, what the controller's log uses: one
fsync per commit, which dominates) and ``relaxed`` (``relax_durability``, ``coral-run
fuzz``'s, where the MAC's own cost shows). Target: the MAC costs well under a tenth of an
append at the engine's commit rate, and the chain does not slow with the log's length.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from runtime.eventlog import EventLog, log_key

KEY = log_key(bytes(32))


def one_run(
    path: Path, *, events: int, per_commit: int, keyed: bool, relaxed: bool
) -> tuple[float, float]:
    """Wall and CPU seconds to create, fill and close the log ``path``."""
    marking = {f"p{i}": i % 2 for i in range(12)}
    started, cpu = time.perf_counter(), time.process_time()
    log = EventLog.create(
        path, role="controller", mission="bench", meta={}, mac_key=KEY if keyed else None
    )
    if relaxed:
        log.relax_durability()
    for n in range(events):
        if n % 2:
            log.event(float(n), "fire", transition=f"t{n % 40}", marking=marking)
        else:
            log.event(
                float(n),
                "command-sent",
                command_id=n,
                transition=f"t{n % 40}",
                name="GOTO",
                params={"x": 1.5, "y": -2.0, "z": 0.5},
                resources=["xy"],
            )
        if n % per_commit == per_commit - 1:
            log.commit({"engine": {"marking": marking, "next_command_id": n}, "consumed": n})
    log.close()
    return time.perf_counter() - started, time.process_time() - cpu


def verify_seconds(folder: Path, events: int, per_commit: int) -> float:
    """Wall seconds to open a keyed log of ``events`` events and verify all of it."""
    path = folder / "verify.sqlite"
    if not path.exists():
        one_run(path, events=events, per_commit=per_commit, keyed=True, relaxed=True)
    started = time.perf_counter()
    EventLog.open(path, mac_key=KEY).close()
    return time.perf_counter() - started


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--events", type=int, default=20_000, help="events per run")
    parser.add_argument("--per-commit", type=int, default=5, help="events per commit")
    parser.add_argument("--runs", type=int, default=5, help="runs of each kind (median)")
    options = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        print(
            f"{options.events} events, a state commit every {options.per_commit}, "
            f"median of {options.runs} runs"
        )
        print(
            f"{'durability':<11}{'no MAC ev/s':>14}{'MAC ev/s':>12}{'MAC cost':>10}"
            f"{'no MAC ev/cpu-s':>17}{'MAC ev/cpu-s':>14}{'MAC cpu':>9}"
        )
        for relaxed in (False, True):
            times: dict[bool, list[tuple[float, float]]] = {False: [], True: []}
            for _ in range(options.runs):
                for keyed in (False, True):
                    path = folder / f"log-{keyed}.sqlite"
                    path.unlink(missing_ok=True)
                    times[keyed].append(
                        one_run(
                            path,
                            events=options.events,
                            per_commit=options.per_commit,
                            keyed=keyed,
                            relaxed=relaxed,
                        )
                    )
            rates = [
                options.events / statistics.median(t[i] for t in times[keyed])
                for i in (0, 1)
                for keyed in (False, True)
            ]
            plain, mac, plain_cpu, mac_cpu = rates
            name = "relaxed" if relaxed else "full"
            print(
                f"{name:<11}{plain:>14,.0f}{mac:>12,.0f}{plain / mac - 1:>10.1%}"
                f"{plain_cpu:>17,.0f}{mac_cpu:>14,.0f}{plain_cpu / mac_cpu - 1:>9.1%}"
            )
        checks = [
            verify_seconds(folder, options.events, options.per_commit) for _ in range(options.runs)
        ]
        rate = options.events / statistics.median(checks)
        print(f"verify on open (keyed, {options.events} events): {rate:,.0f} events/s")


if __name__ == "__main__":
    main()
