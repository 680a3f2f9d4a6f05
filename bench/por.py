"""Partial-order reduction against the full search on the MCC conformance models.

Run ``.venv/bin/python bench/por.py [--models M ...] [--min-states N] [--max-states N]
[--time-limit S]``. For each model: the full search's states and seconds, then the
stubborn-set reduced search's (``por=True``) states, seconds and whether the reduction
was switched off part-way, and both deadlock verdicts (they must agree). It imports
``analysis`` from ``PYTHONPATH``, so the same script measures an older checkout:
``PYTHONPATH=/path/to/old .venv/bin/python bench/por.py ...`` (run both in one window
and compare ratios; the machine's noise is in both).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parent.parent
CONFORMANCE = REPO.parent / "shared" / "conformance"


def _oracle() -> dict[str, dict[str, Any]]:
    import yaml

    with (CONFORMANCE / "oracle.yaml").open() as handle:
        models: list[dict[str, Any]] = yaml.safe_load(handle)["models"]
    return {m["model"]: m for m in models}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--models", nargs="*", help="models (default: by --min/--max-states)")
    parser.add_argument("--min-states", type=int, default=20_000)
    parser.add_argument("--max-states", type=int, default=300_000)
    parser.add_argument("--time-limit", type=float, default=30.0, help="seconds per search")
    args = parser.parse_args()

    from analysis.budget import Budget
    from analysis.encoding import CompactNet
    from analysis.statespace import explore
    from coral_lang.pnml import read_pnml

    oracle = _oracle()
    names = args.models or [
        name
        for name, m in sorted(oracle.items(), key=lambda kv: int(kv[1]["states"]))
        if args.min_states <= int(m["states"]) <= args.max_states
    ]
    print(f"{'model':<38} {'states':>10} {'full s':>8} {'POR states':>11} {'POR s':>8}  note")
    disagree = 0
    for name in names:
        cn = CompactNet.from_net(read_pnml(CONFORMANCE / "pnml" / f"{name}.pnml"))
        started = time.perf_counter()
        full = explore(cn, max_states=None, budget=Budget(seconds=args.time_limit))
        full_s = time.perf_counter() - started
        started = time.perf_counter()
        red = explore(cn, max_states=None, budget=Budget(seconds=args.time_limit), por=True)
        red_s = time.perf_counter() - started
        notes = []
        if not red.complete:
            notes.append(f"POR stopped: {red.stopped_reason}")
        if getattr(red, "reduction_note", None):
            notes.append("switched off part-way")
        if full.complete and red.complete and full.has_deadlock != red.has_deadlock:
            disagree += 1
            notes.append("DEADLOCK VERDICTS DIFFER")
        print(
            f"{name:<38} {full.states:>10,} {full_s:>8.2f} {red.states:>11,} {red_s:>8.2f}  "
            + "; ".join(notes),
            flush=True,
        )
    return 1 if disagree else 0


if __name__ == "__main__":
    raise SystemExit(main())
