"""Benchmark of ``coral-check query`` on the Model Checking Contest conformance data.

Run ``.venv/bin/python bench/queries.py --help``. For every instance and examination
(the 7 query examinations and the 5 global ones) a fresh `QuerySession` answers the
examination's formulas, as the contest runs one examination at a time; answers are
compared with ``answers.yaml``. One line per instance as it finishes, then one row per
examination:

* ``formulas``, ``answered``, ``wrong`` (answered and different from the contest's);
* ``median s``/``p90 s``: seconds per formula, the formula's own time plus its share of
  the session's common work (state space, graph) divided evenly among the formulas of
  the run;
* ``total s``: wall time of all runs of the examination.

Data: ``../shared/conformance`` when present, else the vendored ``tests/data/mcc``.
``--peer`` also runs TAPAAL's verifypn (``../shared/peers/verifypn``) on the same
formulas, one process per formula (several formulas per process gave inconsistent
answers on a tiny net, see docs/verify.md), and prints its counts, median seconds and
the ratio of coral's median to verifypn's.
"""

from __future__ import annotations

import argparse
import gzip
import statistics
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

CONFORMANCE = REPO.parent / "shared" / "conformance"
VENDORED = REPO / "tests" / "data" / "mcc"
VERIFYPN = REPO.parent / "shared" / "peers" / "verifypn"
SMALL_LIMIT = 300_000  # instances up to this many markings form the default set
STRETCH = {"Dekker-PT-020"}  # 1.2e9 edges: never in --large
TARGET_STATES = 100_000  # the target (median < 0.1 s per formula) is on instances up to here

DEADLOCK_QUERY = (
    '<?xml version="1.0"?>\n<property-set xmlns="http://mcc.lip6.fr/"><property>'
    "<id>ReachabilityDeadlock</id><formula><exists-path><finally><deadlock/></finally>"
    "</exists-path></formula></property></property-set>\n"
)


@dataclass
class Tally:
    """Per examination: seconds per formula and counts."""

    seconds: list[float] = field(default_factory=list)
    target_seconds: list[float] = field(default_factory=list)  # instances <= TARGET_STATES
    formulas: int = 0
    answered: int = 0
    wrong: int = 0
    total: float = 0.0


class Data:
    """The conformance data, from ``../shared/conformance`` or the vendored copy."""

    def __init__(self) -> None:
        import yaml

        self.root = CONFORMANCE if (CONFORMANCE / "answers.yaml").exists() else VENDORED
        with (self.root / "answers.yaml").open() as handle:
            self.models = {m["model"]: m for m in yaml.safe_load(handle)["models"]}
        self.states: dict[str, int] = {}
        if self.root == CONFORMANCE:
            with (CONFORMANCE / "oracle.yaml").open() as handle:
                for m in yaml.safe_load(handle)["models"]:
                    self.states[m["model"]] = m["states"]
        else:
            self.states = {name: m["states"] for name, m in self.models.items()}

    def read(self, relative: str) -> bytes:
        data = (self.root / relative).read_bytes()
        return gzip.decompress(data) if relative.endswith(".gz") else data

    def pnml(self, name: str) -> str:
        model = self.models[name]
        return str(model.get("pnml", f"pnml/{name}.pnml"))


def _percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


def _run_coral(data: Data, name: str, exams: list[str], budget: Any) -> dict[str, Any]:
    from analysis.examinations import GLOBAL_EXAMINATIONS, QuerySession
    from analysis.mccxml import parse_properties
    from coral_lang.pnml import parse_pnml

    model = data.models[name]
    relative = data.pnml(name)
    net = parse_pnml(data.read(relative), relative)
    out: dict[str, Any] = {}
    for exam in exams:
        start = time.perf_counter()
        session = QuerySession(net, budget)
        if exam in GLOBAL_EXAMINATIONS:
            answer = session.check_global(exam)
            expected = model["global_properties"][exam]["expected"]
            out[exam] = {
                "seconds": [time.perf_counter() - start],
                "answered": int(answer.value is not None),
                "wrong": int(answer.value is not None and answer.value != expected),
                "total": time.perf_counter() - start,
            }
            continue
        entry = model["examinations"][exam]
        if entry["queries"] is None:
            continue
        props = parse_properties(data.read(entry["queries"]), entry["queries"], net)
        expected = {f["id"]: f["expected"] for f in entry["formulas"]}
        answers = session.check(props)
        share = session.shared_seconds / max(1, len(answers))
        out[exam] = {
            "seconds": [a.seconds + share for a in answers],
            "answered": sum(a.value is not None for a in answers),
            "wrong": sum(a.value is not None and a.value != expected[a.id] for a in answers),
            "total": time.perf_counter() - start,
        }
    return out


def _peer_options(exam: str) -> list[str]:
    return ["-ltl"] if exam.startswith("LTL") else []


def _run_peer(
    data: Data, name: str, exams: list[str], peer: Path, timeout: float
) -> dict[str, Any]:
    """verifypn, one process per formula: answers compared, wall seconds measured."""
    from analysis.mccxml import parse_properties

    model = data.models[name]
    out: dict[str, Any] = {}
    with tempfile.TemporaryDirectory() as tmp:
        pnml = Path(tmp) / "model.pnml"
        pnml.write_bytes(data.read(data.pnml(name)))
        for exam in exams:
            if exam == "ReachabilityDeadlock":
                queries, expected_of = (
                    Path(tmp) / "deadlock.xml",
                    {"ReachabilityDeadlock": model["global_properties"][exam]["expected"]},
                )
                queries.write_text(DEADLOCK_QUERY)
                ids = ["ReachabilityDeadlock"]
            elif exam in model["examinations"] and model["examinations"][exam]["queries"]:
                entry = model["examinations"][exam]
                queries = Path(tmp) / f"{exam}.xml"
                queries.write_bytes(data.read(entry["queries"]))
                ids = [p.id for p in parse_properties(queries.read_bytes(), str(queries))]
                expected_of = {f["id"]: f["expected"] for f in entry["formulas"]}
            else:
                continue
            seconds, answered, wrong = [], 0, 0
            for k, ident in enumerate(ids, start=1):
                argv = [str(peer), *_peer_options(exam), "-x", str(k), str(pnml), str(queries)]
                start = time.perf_counter()
                try:
                    done = subprocess.run(
                        argv, capture_output=True, text=True, timeout=timeout, check=False
                    )
                    text = done.stdout
                except subprocess.TimeoutExpired:
                    text = ""
                seconds.append(time.perf_counter() - start)
                value = _peer_value(text, ident)
                if value is not None:
                    answered += 1
                    wrong += int(value != expected_of[ident])
            out[exam] = {"seconds": seconds, "answered": answered, "wrong": wrong}
    return out


def _peer_value(text: str, ident: str) -> bool | int | None:
    for line in text.splitlines():
        words = line.split()
        if len(words) >= 3 and words[0] == "FORMULA" and words[1] == ident:
            if words[2] in ("TRUE", "FALSE"):
                return words[2] == "TRUE"
            try:
                return int(words[2])
            except ValueError:
                return None
    return None


def build_parser() -> argparse.ArgumentParser:
    """The command line of the benchmark."""
    from analysis.examinations import EXAMINATIONS

    parser = argparse.ArgumentParser(
        prog="bench/queries.py", description="Time coral-check query on the MCC conformance data."
    )
    parser.add_argument("--models", nargs="*", help="instance names (default: up to 300k states)")
    parser.add_argument(
        "--large",
        action="store_true",
        help="add the instances above 300k states (UpperBounds and global examinations only)",
    )
    parser.add_argument(
        "--examinations", nargs="*", choices=EXAMINATIONS, help="default: all twelve"
    )
    parser.add_argument("--max-states", type=int, default=5_000_000, help="state budget")
    parser.add_argument("--max-edges", type=int, default=50_000_000, help="graph edge budget")
    parser.add_argument(
        "--time-limit", type=float, default=300.0, help="seconds per instance and examination"
    )
    parser.add_argument("--peer", action="store_true", help="also run verifypn on each formula")
    parser.add_argument("--peer-path", type=Path, default=VERIFYPN, help="the verifypn binary")
    parser.add_argument("--peer-timeout", type=float, default=60.0, help="seconds per formula")
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark; returns the exit code."""
    from analysis.examinations import EXAMINATIONS, QueryLimits

    args = build_parser().parse_args(argv)
    data = Data()
    exams = list(args.examinations or EXAMINATIONS)
    names = (
        list(args.models)
        if args.models
        else [
            n
            for n in data.models
            if data.states.get(n, 0) <= SMALL_LIMIT or (args.large and n not in STRETCH)
        ]
    )
    if args.peer and not args.peer_path.is_file():
        print(f"no verifypn at {args.peer_path}", file=sys.stderr)
        return 2
    budget = QueryLimits(
        max_states=args.max_states, time_limit=args.time_limit, max_edges=args.max_edges
    )
    print(f"data: {data.root}  instances: {len(names)}  examinations: {len(exams)}", flush=True)
    started = time.perf_counter()
    coral: dict[str, Tally] = defaultdict(Tally)
    peer: dict[str, Tally] = defaultdict(Tally)
    for name in names:
        states = data.states.get(name, 0)
        t0 = time.perf_counter()
        results = _run_coral(data, name, exams, budget)
        notes = []
        for exam, r in results.items():
            tally = coral[exam]
            tally.seconds += r["seconds"]
            if states <= TARGET_STATES:
                tally.target_seconds += r["seconds"]
            tally.formulas += len(r["seconds"])
            tally.answered += r["answered"]
            tally.wrong += r["wrong"]
            tally.total += r["total"]
            if r["wrong"] or r["answered"] < len(r["seconds"]):
                notes.append(f"{exam}: {r['wrong']} wrong, {len(r['seconds']) - r['answered']} CC")
        line = f"{name:<38} {states:>9,} {time.perf_counter() - t0:>8.2f} s"
        if args.peer:
            t1 = time.perf_counter()
            for exam, r in _run_peer(data, name, exams, args.peer_path, args.peer_timeout).items():
                tally = peer[exam]
                tally.seconds += r["seconds"]
                tally.formulas += len(r["seconds"])
                tally.answered += r["answered"]
                tally.wrong += r["wrong"]
                tally.total += sum(r["seconds"])
            line += f"  verifypn {time.perf_counter() - t1:>8.2f} s"
        print(line + ("  " + "; ".join(notes) if notes else ""), flush=True)
    print()
    head = (
        f"{'examination':<24} {'formulas':>8} {'answered':>8} {'wrong':>5} {'median s':>9} "
        f"{'p90 s':>8} {'med<=1e5':>9} {'total s':>8}"
    )
    if args.peer:
        head += f" | {'vpn ans':>7} {'wrong':>5} {'median s':>9} {'coral/vpn':>9}"
    print(head)
    for exam in exams:
        t = coral.get(exam)
        if t is None or not t.seconds:
            continue
        median = statistics.median(t.seconds)
        small = statistics.median(t.target_seconds) if t.target_seconds else float("nan")
        row = (
            f"{exam:<24} {t.formulas:>8} {t.answered:>8} {t.wrong:>5} {median:>9.4f} "
            f"{_percentile(t.seconds, 0.9):>8.4f} {small:>9.4f} {t.total:>8.1f}"
        )
        p = peer.get(exam)
        if args.peer and p is not None and p.seconds:
            pm = statistics.median(p.seconds)
            row += f" | {p.answered:>7} {p.wrong:>5} {pm:>9.4f} {median / pm:>9.2f}"
        print(row)
    every = [s for t in coral.values() for s in t.seconds]
    target_all = [s for t in coral.values() for s in t.target_seconds]
    target = (
        f" ({statistics.median(target_all):.4f} s on instances up to {TARGET_STATES:,} markings)"
        if target_all
        else ""
    )
    print(
        f"all: {len(every)} formulas, {sum(t.answered for t in coral.values())} answered, "
        f"{sum(t.wrong for t in coral.values())} wrong; median "
        f"{statistics.median(every) if every else float('nan'):.4f} s per formula{target};"
        f" total {time.perf_counter() - started:.1f} s"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
