"""Node-level saturation (`analysis.symbolic.mdd`): units found from P-invariants,
exact counts against a breadth-first search on small nets with and without units, the
cap that reports a possibly unbounded place, and the fallback to the set-level
schedule giving the same answers."""

from __future__ import annotations

from collections import deque

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import analysis.symbolic.explore as explore
from analysis.symbolic import SymbolicLimits, explore_symbolic
from analysis.symbolic.encoding import invariant_facts, level_order, place_order
from analysis.symbolic.mdd import MddSaturation, Unbounded
from coral_lang.net import Net
from coral_lang.pnml.read import read_pnml
from tests.analysis.nets import make_net, replay_names
from tests.analysis.symbolic.test_saturate import small_nets
from tests.conftest import CONFORMANCE


def _reachable(net: Net) -> set[tuple[int, ...]]:
    start = net.initial_marking()
    seen = {start}
    queue = deque([start])
    while queue:
        marking = queue.popleft()
        for t in net.transitions:
            if net.enabled(marking, t):
                after = net.fire(marking, t)
                if after not in seen:
                    seen.add(after)
                    queue.append(after)
    return seen


def _never(nodes: int) -> str | None:
    return None


def _go_on() -> None:
    return None


def _agrees(run: MddSaturation, root: int, net: Net) -> None:
    """Count, bounds, heaviest marking and dead markings equal the search's."""
    reachable = _reachable(net)
    assert run.count(root) == len(reachable)
    assert run.largest(root) == [max(m[p] for m in reachable) for p in range(len(net.places))]
    assert run.heaviest(root) == max(sum(m) for m in reachable)
    dead = [m for m in reachable if not any(net.enabled(m, t) for t in net.transitions)]
    hit = run.dead(root, _go_on)
    assert run.count(hit) == len(dead)
    if dead:
        assert tuple(run.pick(hit)) in dead


def _mutex(n: int) -> Net:
    """n processes idle -> waiting -> critical -> idle around one lock, each process a
    unit of three places, the lock a unit with the critical places."""
    places: dict[str, int] = {"lock": 1}
    transitions: dict[str, tuple[dict[str, int], dict[str, int]]] = {}
    for i in range(n):
        places |= {f"idle{i}": 1, f"wait{i}": 0, f"crit{i}": 0}
        transitions[f"ask{i}"] = ({f"idle{i}": 1}, {f"wait{i}": 1})
        transitions[f"enter{i}"] = ({f"wait{i}": 1, "lock": 1}, {f"crit{i}": 1})
        transitions[f"leave{i}"] = ({f"crit{i}": 1}, {f"idle{i}": 1, "lock": 1})
    return make_net("mutex", places, transitions)


@st.composite
def unit_nets(draw: st.DrawFn) -> Net:
    """Processes (units of 2-3 places, one token each) whose moves may test a place of
    another process and may take a token from or give one to a shared pool (paid from
    or into a budget place, so the pool stays bounded)."""
    sizes = draw(st.lists(st.integers(2, 3), min_size=1, max_size=3))
    places: dict[str, int] = {}
    for i, size in enumerate(sizes):
        start = draw(st.integers(0, size - 1))
        places |= {f"u{i}_{k}": int(k == start) for k in range(size)}
    places |= {"pool": draw(st.integers(0, 2)), "budget": draw(st.integers(0, 2))}
    transitions: dict[str, tuple[dict[str, int], dict[str, int]]] = {}
    for n in range(draw(st.integers(1, 7))):
        i = draw(st.integers(0, len(sizes) - 1))
        a, b = draw(st.integers(0, sizes[i] - 1)), draw(st.integers(0, sizes[i] - 1))
        ins, outs = {f"u{i}_{a}": 1}, {f"u{i}_{b}": 1}
        if draw(st.booleans()):  # test another process's place
            j = draw(st.integers(0, len(sizes) - 1))
            if j != i:
                c = f"u{j}_{draw(st.integers(0, sizes[j] - 1))}"
                ins[c], outs[c] = 1, 1
        pool = draw(st.sampled_from(["none", "take", "give"]))
        if pool == "take":
            ins["pool"], outs["budget"] = 1, 1
        elif pool == "give":
            ins["budget"], outs["pool"] = 1, 1
        transitions[f"t{n}"] = (ins, outs)
    return make_net("units", places, transitions)


@settings(max_examples=60, deadline=None, derandomize=True)
@given(unit_nets())
def test_processes_with_units_count_exactly(net: Net) -> None:
    """Units as levels, tests across units and a shared counter: the same markings,
    bounds, heaviest marking and dead markings as the search, through the whole run
    too (deadlock verdict and a trace that replays)."""
    bounds, units = invariant_facts(net, 5.0)  # a process some move touches is a unit
    levels = level_order(net, units, place_order(net))
    run = MddSaturation(net, levels, [b if b is not None else 15 for b in bounds], _never)
    _agrees(run, run.run(list(net.initial_marking())), net)
    result = explore_symbolic(net)
    reachable = _reachable(net)
    assert result.complete and result.states == len(reachable)
    if result.deadlock:
        assert result.deadlock_trace is not None
        assert replay_names(net, result.deadlock_trace) == result.deadlock_marking


def test_units_are_the_one_token_invariants() -> None:
    net = _mutex(3)
    names = [p.name for p in net.places]
    _, units = invariant_facts(net, 5.0)
    found = {frozenset(names[p] for p in unit) for unit in units}
    # the largest first: the lock with every critical section, then what is left
    assert frozenset({"lock", "crit0", "crit1", "crit2"}) in found
    taken = [p for unit in units for p in unit]
    assert len(taken) == len(set(taken))  # disjoint


def test_a_dead_end_is_found() -> None:
    """Two processes each taking two locks in opposite orders: the classic deadlock."""
    net = make_net(
        "locks",
        {"a0": 1, "a1": 0, "a2": 0, "b0": 1, "b1": 0, "b2": 0, "x": 1, "y": 1},
        {
            "a_x": ({"a0": 1, "x": 1}, {"a1": 1}),
            "a_y": ({"a1": 1, "y": 1}, {"a2": 1}),
            "a_done": ({"a2": 1}, {"a0": 1, "x": 1, "y": 1}),
            "b_y": ({"b0": 1, "y": 1}, {"b1": 1}),
            "b_x": ({"b1": 1, "x": 1}, {"b2": 1}),
            "b_done": ({"b2": 1}, {"b0": 1, "x": 1, "y": 1}),
        },
    )
    _, units = invariant_facts(net, 5.0)
    run = MddSaturation(net, level_order(net, units, place_order(net)), [1] * 8, _never)
    root = run.run(list(net.initial_marking()))
    _agrees(run, root, net)
    assert run.count(run.dead(root, _go_on)) == 1
    result = explore_symbolic(net)
    assert result.deadlock and result.deadlock_trace is not None
    assert sorted(result.deadlock_trace) == ["a_x", "b_y"]


@pytest.mark.parametrize("n", [1, 2, 4])
def test_units_count_exactly(n: int) -> None:
    net = _mutex(n)
    bounds, units = invariant_facts(net, 5.0)
    levels = level_order(net, units, place_order(net))
    assert sorted(p for level in levels for p in level) == list(range(len(net.places)))
    assert any(len(level) > 1 for level in levels)
    run = MddSaturation(net, levels, [b or 7 for b in bounds], _never)
    _agrees(run, run.run(list(net.initial_marking())), net)


@settings(max_examples=40, deadline=None, derandomize=True)
@given(small_nets())
def test_counters_count_exactly(net: Net) -> None:
    """One level per place (no units): the reachable markings of small random nets."""
    levels = [[p] for p in range(len(net.places))]
    run = MddSaturation(net, levels, [63] * len(net.places), _never)
    _agrees(run, run.run(list(net.initial_marking())), net)


def test_a_place_past_its_cap_is_reported() -> None:
    net = make_net("pump", {"a": 1, "b": 0}, {"t": ({"a": 1}, {"a": 1, "b": 1})})
    run = MddSaturation(net, [[0], [1]], [1, 5], _never)
    with pytest.raises(Unbounded) as caught:
        run.run([1, 0])
    assert caught.value.place == 1
    result = explore_symbolic(net, SymbolicLimits(max_bits=4))
    assert not result.complete and result.reason is not None and "b" in result.reason


def test_giving_up_falls_back_to_sets(monkeypatch: pytest.MonkeyPatch) -> None:
    """With no node images allowed the set-level schedule answers, the same answers."""
    net = _mutex(3)
    nodes = explore_symbolic(net)
    monkeypatch.setattr(explore, "MDD_MAX_CALLS", -1)
    monkeypatch.setattr("analysis.symbolic.mdd.CHECK_EVERY", 1)
    sets = explore_symbolic(net)
    assert nodes.complete and sets.complete
    assert nodes.states == sets.states == len(_reachable(net))
    assert nodes.iterations != sets.iterations  # a different schedule ran
    assert (nodes.deadlock, nodes.max_tokens_place) == (sets.deadlock, sets.max_tokens_place)


def test_a_level_that_is_not_a_unit_is_refused() -> None:
    """Two places grouped as a unit that a transition empties: refused, never a wrong
    step (the caller then keeps to the set-level schedule)."""
    net = make_net("leak", {"a": 1, "b": 0}, {"t": ({"a": 1}, {})})
    with pytest.raises(ValueError, match="not a unit"):
        MddSaturation(net, [[0, 1]], [1, 1], _never)


@pytest.mark.parametrize(("model", "tested"), [("Dekker-PT-010", 9), ("Peterson-PT-2", 1)])
def test_widest_test_counts_levels_read_and_left_unchanged(model: str, tested: int) -> None:
    """Dekker's `enter_i` tests the flag of each of the 9 other processes (the rule
    `WIDE_TESTS` sends such nets to the set-level schedule); Peterson's moves test one
    other place at most."""
    net = read_pnml(CONFORMANCE / "pnml" / f"{model}.pnml")
    bounds, units = invariant_facts(net, 5.0)
    levels = level_order(net, units, place_order(net))
    run = MddSaturation(net, levels, [b if b is not None else 15 for b in bounds], _never)
    assert run.widest_test() == tested
    assert (tested >= explore.WIDE_TESTS) == (model == "Dekker-PT-010")
