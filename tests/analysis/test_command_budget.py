"""``time_limit`` bounds the whole verify command, not only the explicit search.

A wide generated net makes every later stage (state equation, invariants, z3
structural boundedness, siphons) slow: before, a 1 s limit gave a run of tens of
seconds. Now the run ends within a small multiple of the limit, and each stage that
did not run says which limit stopped it.
"""

from __future__ import annotations

import time

from analysis.budget import Budget
from analysis.report import Verdict
from analysis.verify import STRUCTURE_FACTS, VerifyOptions, run_verification
from coral_lang.net import Net, Place, Transition


def _wide(processes: int, choices: int) -> Net:
    """``processes`` two-place cycles, each with ``choices`` parallel transitions a->b
    and one back b->a: bounded, deadlock-free, with many transitions."""
    places: list[Place] = []
    transitions: list[Transition] = []
    for i in range(processes):
        places += [Place(f"a{i}", 1), Place(f"b{i}", 0)]
        for j in range(choices):
            transitions.append(Transition(f"t{i}_{j}", ((f"a{i}", 1),), ((f"b{i}", 1),)))
        transitions.append(Transition(f"r{i}", ((f"b{i}", 1),), ((f"a{i}", 1),)))
    return Net("wide", tuple(places), tuple(transitions))


def test_a_spent_budget_stops_every_later_stage_with_its_reason() -> None:
    net = _wide(300, 20)
    started = time.perf_counter()
    report = run_verification(net, VerifyOptions(time_limit=1.0)).report
    took = time.perf_counter() - started
    # Before: 20 s and more (the state equation and structure ran past the limit).
    assert took < 10.0, f"a 1 s limit took {took:.1f} s"
    assert not report.statespace.complete
    # The search's own share of the limit, or the limit itself, stopped it.
    assert "time limit of" in str(report.statespace.stopped_reason)
    deadlock = next(p for p in report.properties if p.key == "deadlock")
    assert deadlock.verdict is Verdict.INCONCLUSIVE
    assert "time limit of 1 s reached" in deadlock.detail
    for key in STRUCTURE_FACTS:
        fact = report.structure[key]
        assert isinstance(fact, dict)
        assert "time limit of 1 s reached" in str(fact["summary"]), key


def test_an_expired_caller_budget_skips_the_structure_section() -> None:
    ticks = iter(range(0, 10**6, 5))  # every reading of the clock moves 5 s on

    budget = Budget(seconds=None, clock=lambda: float(next(ticks)))
    net = _wide(2, 2)
    report = run_verification(net, VerifyOptions(time_limit=20.0), budget=budget).report
    summaries = [str(report.structure[key]) for key in STRUCTURE_FACTS]
    assert any("time limit of 20 s reached" in s for s in summaries)
    assert report.structure["class"] == [
        "ORDINARY",
        "STATE_MACHINE",
        "SIMPLE_FREE_CHOICE",
        "EXTENDED_FREE_CHOICE",
        "CONSERVATIVE",
        "SUBCONSERVATIVE",
    ]


def test_a_generous_limit_changes_nothing() -> None:
    net = _wide(3, 2)
    report = run_verification(net, VerifyOptions(time_limit=60.0)).report
    assert report.statespace.complete
    assert report.statespace.states == 8
    for key in STRUCTURE_FACTS:
        assert "not computed" not in str(report.structure[key])


def test_proofs_after_a_stopped_search_still_run_within_the_limit() -> None:
    """The search takes only a share of the limit (`SEARCH_SHARE`): a search stopped by
    its state cap leaves the state equation time to prove the net deadlock-free."""
    report = run_verification(_wide(12, 1), VerifyOptions(max_states=100, time_limit=60.0))
    assert not report.report.statespace.complete
    assert report.report.property("deadlock").verdict is Verdict.PROVEN
