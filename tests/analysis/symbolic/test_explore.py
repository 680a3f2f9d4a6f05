"""The symbolic state space against the MCC oracle and against closed-form counts."""

from __future__ import annotations

import time
from typing import Any

import pytest
import yaml

from analysis.budget import Budget, resident_bytes
from analysis.symbolic import SymbolicLimits, explore_symbolic
from analysis.symbolic.explore import GRACE_SECONDS as GRACE
from coral_lang.net import Net, Place, Transition
from coral_lang.pnml.read import read_pnml
from tests.analysis.nets import replay_names
from tests.conftest import CONFORMANCE

# Instances the fixpoint finishes in about a second or less each on this machine.
FAST = [
    "Sudoku-PT-AN01",
    "ResAllocation-PT-R002C002",
    "ERK-PT-000001",
    "TwoPhaseLocking-PT-nC00004vD",
    "Eratosthenes-PT-010",
    "ShieldRVt-PT-001A",
    "CircadianClock-PT-000001",
    "DatabaseWithMutex-PT-02",
    "CircularTrains-PT-012",
    "Philosophers-PT-000005",
    "PhilosophersDyn-PT-03",
    "SimpleLoadBal-PT-02",
    "DrinkVendingMachine-PT-02",
    "Railroad-PT-005",
    "SharedMemory-PT-000005",
    "Eratosthenes-PT-020",
    "FMS-PT-00002",
    "Raft-PT-02",
    "Philosophers-PT-000010",
    "Referendum-PT-0010",
    "PGCD-PT-D02N005",  # weighted loops that change a count: the guard bug's witness
    "Dekker-PT-015",  # 278,528 states; not finished in 15 s before FORCE's order
]


def _oracle() -> dict[str, dict[str, Any]]:
    data = yaml.safe_load((CONFORMANCE / "oracle.yaml").read_text())
    return {m["model"]: m for m in data["models"]}


ORACLE = _oracle()


@pytest.mark.parametrize("model", FAST)
def test_conformance_numbers(model: str) -> None:
    entry = ORACLE[model]
    net = read_pnml(CONFORMANCE / entry["pnml"])
    result = explore_symbolic(net, SymbolicLimits(time_limit=30))
    assert result.complete, result.reason
    assert result.states == entry["states"]
    assert result.max_tokens_place == entry["max_tokens_place"]
    assert result.max_tokens_marking == entry["max_tokens_marking"]
    assert result.deadlock == entry["deadlock"]
    if result.deadlock:
        assert result.deadlock_marking is not None


def _cycles(n: int) -> Net:
    """n independent two-place cycles, one token each: exactly 2^n markings, no deadlock."""
    places = [Place(f"{s}{i}", initial=1 if s == "a" else 0) for i in range(n) for s in "ab"]
    transitions = [
        tr
        for i in range(n)
        for tr in (
            Transition(f"go{i}", inputs=((f"a{i}", 1),), outputs=((f"b{i}", 1),)),
            Transition(f"back{i}", inputs=((f"b{i}", 1),), outputs=((f"a{i}", 1),)),
        )
    ]
    return Net("cycles", tuple(places), tuple(transitions))


def _pool(n: int, k: int) -> Net:
    """k tokens moving among n places in a ring: C(n + k - 1, k) markings; counters of
    several bits, so widening is exercised."""
    places = [Place(f"p{i}", initial=k if i == 0 else 0) for i in range(n)]
    transitions = [
        Transition(f"t{i}", inputs=((f"p{i}", 1),), outputs=((f"p{(i + 1) % n}", 1),))
        for i in range(n)
    ]
    return Net("pool", tuple(places), tuple(transitions))


@pytest.mark.parametrize("n", [1, 7, 40, 64])
def test_independent_cycles_count_exactly(n: int) -> None:
    result = explore_symbolic(_cycles(n))
    assert result.complete
    assert result.states == 2**n  # 2^64 is past a double's exact range
    assert result.deadlock is False
    assert result.max_tokens_marking == n
    assert result.max_tokens_place == 1


@pytest.mark.parametrize(("n", "k"), [(3, 5), (6, 9), (16, 8)])
def test_token_ring_counts_and_bounds(n: int, k: int) -> None:
    from math import comb

    result = explore_symbolic(_pool(n, k))
    assert result.complete
    assert result.states == comb(n + k - 1, k)
    assert result.max_tokens_place == k
    assert result.max_tokens_marking == k
    assert all(bound == k for bound in result.place_bounds.values())


def test_unbounded_place_is_inconclusive_not_wrapped() -> None:
    net = Net(
        "pump",
        (Place("a", initial=1), Place("b")),
        (Transition("t", inputs=(("a", 1),), outputs=(("a", 1), ("b", 1))),),
    )
    result = explore_symbolic(net, SymbolicLimits(max_bits=6))
    assert not result.complete
    assert result.reason is not None and "unbounded" in result.reason and "b" in result.reason


def test_deadlock_witness_is_dead() -> None:
    net = _pool(4, 2)
    net = Net(net.name, net.places, net.transitions[:-1])  # the ring cut: tokens pile up
    result = explore_symbolic(net)
    assert result.deadlock is True
    assert result.deadlock_marking == {"p3": 2}


@pytest.mark.parametrize("model", ["Philosophers-PT-000005", "Railroad-PT-005", "ERK-PT-000001"])
def test_deadlock_trace_replays_to_the_witness(model: str) -> None:
    entry = ORACLE[model]
    net = read_pnml(CONFORMANCE / entry["pnml"])
    result = explore_symbolic(net, SymbolicLimits(time_limit=30))
    if not entry["deadlock"]:
        assert result.deadlock is False and result.deadlock_trace is None
        return
    assert result.deadlock_trace is not None
    final = replay_names(net, result.deadlock_trace)
    assert final == result.deadlock_marking
    enabled = [t for t in net.transitions if all(final.get(p, 0) >= w for p, w in t.inputs)]
    assert not enabled


def test_time_limit_bounds_the_whole_run() -> None:
    """A net far too large for 0.5 s stops within about twice the limit, saying why
    (Peterson-PT-3: saturation on nodes needs about 4 s)."""
    entry = ORACLE["Peterson-PT-3"]
    net = read_pnml(CONFORMANCE / entry["pnml"])
    started = time.monotonic()
    result = explore_symbolic(net, SymbolicLimits(time_limit=0.5))
    assert time.monotonic() - started < 1.0 + GRACE
    assert not result.complete
    assert result.reason is not None and "time limit" in result.reason
    assert result.deadlock is None


def test_command_budget_stops_the_run() -> None:
    entry = ORACLE["Peterson-PT-3"]
    net = read_pnml(CONFORMANCE / entry["pnml"])
    started = time.monotonic()
    result = explore_symbolic(net, SymbolicLimits(budget=Budget(0.5)))
    assert time.monotonic() - started < 1.0 + GRACE
    assert not result.complete and result.reason is not None
    assert "time limit of 0.5 s" in result.reason


def test_memory_limit_becomes_a_node_budget() -> None:
    """A memory limit barely above what the process uses leaves room for few nodes:
    the run stops inconclusive, naming the memory limit, never crashing (Peterson-PT-3's
    diagram holds 57,000 MDD nodes; Kanban-PT-00005's 1,700 now fit in 2 MB)."""
    entry = ORACLE["Peterson-PT-3"]
    net = read_pnml(CONFORMANCE / entry["pnml"])
    budget = Budget(memory=resident_bytes() + 2_000_000)
    result = explore_symbolic(net, SymbolicLimits(time_limit=20, budget=budget))
    assert not result.complete
    assert result.reason is not None and "memory limit" in result.reason
