"""Benchmark of structural reductions on the deadlock question (MCC conformance models).

Run ``.venv/bin/python bench/reductions.py --help``. For each of the 47 instances:
places/transitions before and after `analysis.reduce.reduce_net`, markings explored on
the reduced net, seconds (reduction, random walks, siphon-trap check, search and witness
replay, in this process), the verdict against the oracle and what decided it; with
``--peer``, TAPAAL's verifypn with its default reductions on the same question, in the
same run. The last lines count the verdicts
decided under 0.1 s and any disagreement with the oracle (exit status 1 if one).

``--queries``: the ReachabilityCardinality, ReachabilityFireability and UpperBounds
formulas of each instance instead (``answers.yaml``), each answered on the net reduced
for what it observes (`analysis.reduce.query`): per instance the formulas decided, the
seconds, and any answer unequal to the consensus (exit status 1 if one).
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from analysis.budget import Budget  # noqa: E402
from analysis.reduce import Goal, decide_deadlock, reduce_net  # noqa: E402
from coral_lang.pnml import parse_pnml  # noqa: E402

SHARED = next(
    (d for d in (REPO.parent / "shared", Path("/work/shared")) if d.is_dir()), REPO.parent
)
"""The team's shared data folder (beside the checkout, or /work/shared from a worktree)."""
CONFORMANCE = SHARED / "conformance"
VERIFYPN = SHARED / "peers" / "verifypn"
FAST = 0.1
"""Seconds under which a verdict counts as "decided without exploring" in the summary."""

QUERY = """<?xml version="1.0"?>
<property-set xmlns="http://mcc.lip6.fr/">
  <property>
    <id>ReachabilityDeadlock</id>
    <description>deadlock</description>
    <formula><exists-path><finally><deadlock/></finally></exists-path></formula>
  </property>
</property-set>
"""


def _oracle() -> list[dict[str, Any]]:
    import yaml

    with (CONFORMANCE / "oracle.yaml").open() as handle:
        models: list[dict[str, Any]] = yaml.safe_load(handle)["models"]
    return sorted(models, key=lambda m: int(m["states"]))


def _peer(pnml: Path, query: Path, timeout: float) -> tuple[str, int | None, float]:
    """verifypn's verdict, explored states and wall seconds (verdict "timeout" if none)."""
    start = time.perf_counter()
    try:
        out = subprocess.run(
            [str(VERIFYPN), "-s", "BFS", "-q", "0", "-l", "0", "-x", "1", str(pnml), str(query)],
            capture_output=True,
            text=True,
            timeout=timeout,
        ).stdout
    except subprocess.TimeoutExpired:
        return "timeout", None, time.perf_counter() - start
    seconds = time.perf_counter() - start
    verdict = re.search(r"FORMULA ReachabilityDeadlock (TRUE|FALSE)", out)
    explored = re.search(r"explored states:\s+(\d+)", out)
    return (
        verdict.group(1).lower() if verdict else "?",
        int(explored.group(1)) if explored else 0,
        seconds,
    )


QUERY_EXAMINATIONS = ("ReachabilityCardinality", "ReachabilityFireability", "UpperBounds")


def _queries(models: list[dict[str, Any]], time_limit: float) -> int:
    """The ``--queries`` table; the exit status (1 if some answer is wrong)."""
    import yaml

    from analysis.examinations import _reachability
    from analysis.mccxml import PlaceBound, parse_properties
    from analysis.reduce.query import bound_by_reduction, reach_by_reduction

    with (CONFORMANCE / "answers.yaml").open() as handle:
        answers = {m["model"]: m for m in yaml.safe_load(handle)["models"]}
    print(f"{'model':38} {'formulas':>8} {'decided':>7} {'s':>8} {'max s':>7} wrong", flush=True)
    total = decided = wrong = 0
    for model in models:
        name = model["model"]
        path = CONFORMANCE / "pnml" / f"{name}.pnml"
        net = parse_pnml(path.read_bytes(), path.name)
        n = ok = bad = 0
        spent = worst = 0.0
        for exam in QUERY_EXAMINATIONS:
            entry = answers[name]["examinations"].get(exam)
            if not entry or not entry.get("queries"):
                continue
            file = CONFORMANCE / entry["queries"]
            expected = {f["id"]: f["expected"] for f in entry["formulas"]}
            for prop in parse_properties(file.read_bytes(), file.name, net):
                n += 1
                start = time.perf_counter()
                budget = Budget(time_limit)
                value: int | bool | None = None
                if isinstance(prop.query, PlaceBound):
                    found = bound_by_reduction(net, prop.query.places, budget=budget)
                    value = None if found is None else found.value
                else:
                    reach = _reachability(prop.query)
                    if reach is not None:
                        hit = reach_by_reduction(net, reach.target, budget=budget)
                        value = None if hit is None else bool(hit.value) != reach.negated
                seconds = time.perf_counter() - start
                spent, worst = spent + seconds, max(worst, seconds)
                if value is None:
                    continue
                ok += 1
                if expected[prop.id] is not None and value != expected[prop.id]:
                    bad += 1
                    print(f"  WRONG {prop.id}: {value} (consensus {expected[prop.id]})")
        total, decided, wrong = total + n, decided + ok, wrong + bad
        print(f"{name:38} {n:>8} {ok:>7} {spent:>8.2f} {worst:>7.2f} {bad}", flush=True)
    print(f"formulas: {total}; decided: {decided}; wrong: {wrong}")
    return 1 if wrong else 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--max-states", type=int, default=300_000, help="skip larger models")
    parser.add_argument("--time-limit", type=float, default=300.0, help="seconds per model")
    parser.add_argument("--peer", action="store_true", help="also run verifypn (defaults)")
    parser.add_argument("--only", nargs="*", help="these models only")
    parser.add_argument(
        "--queries", action="store_true", help="reachability and bounds formulas instead"
    )
    parser.add_argument(
        "--lp", type=float, default=0.0, help="seconds for the LP implicit-place rule (0: off)"
    )
    args = parser.parse_args()
    if args.queries:
        chosen = [m for m in _oracle() if m["states"] <= args.max_states]
        if args.only:
            chosen = [m for m in chosen if m["model"] in args.only]
        return _queries(chosen, args.time_limit)
    header = f"{'model':38} {'P/T before':>11} {'P/T after':>11} {'explored':>9} {'s':>7} verdict"
    if args.peer:
        header += f"  | {'peer':>6} {'explored':>9} {'s':>7} ratio"
    print(header, flush=True)
    fast = decided = wrong = peer_fast = 0
    with tempfile.TemporaryDirectory() as tmp:
        query = Path(tmp) / "ReachabilityDeadlock.xml"
        query.write_text(QUERY)
        models = [m for m in _oracle() if m["states"] <= args.max_states]
        if args.only:
            models = [m for m in models if m["model"] in args.only]
        for model in models:
            name = model["model"]
            path = CONFORMANCE / "pnml" / f"{name}.pnml"
            net = parse_pnml(path.read_bytes(), path.name)
            start = time.perf_counter()
            budget = Budget(args.time_limit)
            reduction = reduce_net(net, Goal.deadlock(), budget=budget, lp_seconds=args.lp)
            answer = decide_deadlock(net, budget=budget, reduction=reduction)
            seconds = time.perf_counter() - start
            red = answer.reduction.net
            if answer.deadlock is None:
                verdict = f"stopped ({answer.stopped_reason})"
            else:
                decided += 1
                ok = answer.deadlock == model["deadlock"]
                wrong += not ok
                fast += seconds < FAST
                verdict = f"{str(answer.deadlock).lower()} {'ok' if ok else 'WRONG'} ({answer.by})"
            line = (
                f"{name:38} {len(net.places):>5}/{len(net.transitions):<5} "
                f"{len(red.places):>5}/{len(red.transitions):<5} {answer.states:>9} "
                f"{seconds:>7.3f} {verdict}"
            )
            if args.peer:
                pv, pexplored, ps = _peer(path, query, args.time_limit)
                peer_fast += ps < FAST and pv in ("true", "false")
                line += f"  | {pv:>6} {pexplored!s:>9} {ps:>7.3f} {seconds / ps:5.2f}"
            print(line, flush=True)
    print(f"decided: {decided}/{len(models)}; under {FAST} s: {fast}; wrong: {wrong}")
    if args.peer:
        print(f"verifypn decided under {FAST} s: {peer_fast}")
    return 1 if wrong else 0


if __name__ == "__main__":
    sys.exit(main())
