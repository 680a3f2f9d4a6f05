"""The time limit bounds the whole check of a wide net, reading the file included.

On a clock that only moves when the test says so (plus a little on every reading), a
file whose reading "takes" 4.5 s of a 5 s limit leaves the analysis half a second:
every stage takes its share of what is left, the ones that cannot be interrupted are
not started, and the verdicts say which limit stopped them. Virtual time, so the test
asserts what the code does, not how fast the machine is.
"""

from __future__ import annotations

import itertools
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import analysis.pipeline as pipeline
import analysis.statespace as statespace
import analysis.symbolic.explore as symbolic_explore
import analysis.verify as verify_module
from analysis.budget import Budget
from analysis.coverability import coverability, node_cap
from analysis.pipeline import CheckOptions, check_file
from analysis.report import Verdict
from analysis.statespace import StateSpace, explore
from analysis.symbolic.encoding import force
from analysis.symbolic.explore import SymbolicLimits, explore_symbolic
from analysis.verify import VerifyOptions, run_verification
from coral_lang.pnml import write_pnml
from tests.analysis.test_budget import FakeClock
from tests.analysis.wide_nets import rings

MARGIN_S = 0.2
"""Virtual seconds the check may read past its limit: the stages after the deadline
read the clock a few times each to find it spent (a reading moves it 10 ms)."""


def test_a_slow_read_leaves_the_analysis_only_the_rest_of_the_limit(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    file = tmp_path / "rings.pnml"
    write_pnml(rings(200, 10), file)
    clock = FakeClock(0.01)
    load = pipeline.load_net_file  # type: ignore[attr-defined]

    def slow_load(*args: object, **kwargs: object) -> object:
        clock.now += 4.5  # reading a very large net
        return load(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(pipeline, "load_net_file", slow_load)
    options = CheckOptions(verify=VerifyOptions(time_limit=5.0, max_states=20_000))
    outcome = check_file(file, options, budget=Budget(clock=clock))
    report = outcome.report
    assert report is not None
    # the analysis ran in what the read left, on the command's clock
    assert report.seconds <= 0.5 + MARGIN_S
    assert clock.now <= 5.0 + MARGIN_S
    # (the explorer reads the clock once a chunk: its state cap may come first)
    stopped = report.statespace.stopped_reason or ""
    assert stopped.startswith(("time limit of 5 s reached after", "state budget of 20,000")), (
        stopped
    )
    deadlock = report.property("deadlock")
    assert deadlock.verdict is Verdict.INCONCLUSIVE
    assert "not run: time limit of 5 s reached before the state equation" in deadlock.detail
    bounded = report.property("bounded")
    assert "structural boundedness not run: time limit of 5 s reached" in bounded.detail
    for key in ("invariants", "structural_boundedness", "siphons_traps"):
        assert "not computed: time limit of 5 s reached" in str(report.structure[key]), key


def test_the_time_limit_is_counted_from_before_the_read(tmp_path: Path) -> None:
    """Without a caller's budget, `check_file` starts its own before reading: a limit
    of 0 s ends the search at once, whatever the file."""
    file = tmp_path / "rings.pnml"
    write_pnml(rings(20, 10), file)
    outcome = check_file(file, CheckOptions(verify=VerifyOptions(time_limit=0.0)))
    assert outcome.report is not None
    assert outcome.report.statespace.stopped_reason == "time limit of 0 s reached after 1 state"


def test_decision_diagrams_are_not_started_without_time_to_set_them_up(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A search that used its 80% of the time left (here: the clock moved on and a
    small state cap stopped it) leaves 0.1 s, half the rest, which cannot set up
    diagrams on 3,000 places and arcs (`SYMBOLIC_SETUP_SECONDS_PER_ARC`)."""
    clock = FakeClock(0.0)
    search = verify_module.explore  # type: ignore[attr-defined]

    def used_its_share(*args: Any, **kwargs: Any) -> StateSpace:
        clock.now += 0.8
        return search(*args, **{**kwargs, "max_states": 1_000})

    monkeypatch.setattr(verify_module, "explore", used_its_share)
    options = VerifyOptions(time_limit=1.0, structural=False)
    report = run_verification(rings(100, 10), options, budget=Budget(clock=clock)).report
    assert not report.statespace.complete
    detail = report.property("dead_transitions").detail
    assert "decision diagrams not run:" in detail and "3,000 places and arcs" in detail


SETUP_STAGES = [
    "one_hot_components",
    "invariant_place_bounds",
    "FieldNet",
    "_EnablingIndex",
    "_EnablingBits",
    "_set_layout",
    "SleepSets",
]
"""The explorer's set-up in the order it runs them (on `rings` with spare places, all
of them run); the budget is read between them."""


def _timed_stages(
    monkeypatch: pytest.MonkeyPatch, clock: FakeClock, slow: str, seconds: float
) -> tuple[list[str], list[float]]:
    """Wrap every set-up stage so that it records its name, and ``slow`` moves the
    clock on by ``seconds`` (its "work"); the list of stages started, and the clock
    when ``slow`` returned."""
    started: list[str] = []
    done: list[float] = []
    for name in SETUP_STAGES:
        owner: Any = statespace._Explorer if name == "_set_layout" else statespace
        stage = getattr(owner, name)

        def timed(*args: Any, _stage: Any = stage, _name: str = name, **kwargs: Any) -> Any:
            started.append(_name)
            if _name != slow:
                return _stage(*args, **kwargs)
            clock.now += seconds
            result = _stage(*args, **kwargs)
            done.append(clock.now)
            return result

        monkeypatch.setattr(owner, name, timed)
    return started, done


@pytest.mark.parametrize("slow", SETUP_STAGES)
def test_the_explorer_set_up_stops_when_the_budget_is_spent(
    slow: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A set-up stage that "takes" 2 s of a 1 s budget is the last one started: the
    search is not started either, and the state space is the initial marking, stored
    but not expanded, with the limit as its reason (the shape of every stopped
    search), never an exception."""
    clock = FakeClock(0.001)
    started, done = _timed_stages(monkeypatch, clock, slow, 2.0)
    net = rings(20, 10, spare_places=3)
    space = explore(net, budget=Budget(1.0, clock=clock))
    assert started == SETUP_STAGES[: SETUP_STAGES.index(slow) + 1]
    assert not space.complete and space.states == 1 and space.edges == 0
    assert space.stopped_reason == "time limit of 1 s reached after 1 state"
    assert space.marking(0) == tuple(net.initial_marking())
    assert space.place_bounds.tolist() == list(net.initial_marking())
    assert space.trace_to(0) == [] and not space.deadlocks.size
    assert clock.now - done[0] <= MARGIN_S  # a few readings after the slow stage


def test_a_whole_check_whose_explorer_set_up_outlasts_the_limit_says_so(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The command on a net whose components "take" 6 s of a 5 s limit: no search, no
    traceback, every verdict inconclusive and naming the limit."""
    file = tmp_path / "rings.pnml"
    write_pnml(rings(200, 10), file)
    clock = FakeClock(0.001)
    _, done = _timed_stages(monkeypatch, clock, "one_hot_components", 6.0)
    options = CheckOptions(verify=VerifyOptions(time_limit=5.0))
    report = check_file(file, options, budget=Budget(clock=clock)).report
    assert report is not None
    assert report.statespace.stopped_reason == "time limit of 5 s reached after 1 state"
    assert clock.now - done[0] <= MARGIN_S
    for result in report.properties:
        assert result.verdict is Verdict.INCONCLUSIVE, result
        assert "time limit of 5 s reached" in result.detail, result


SYMBOLIC_STAGES = {
    "invariant_facts": "ordering the places",
    "place_order": "ordering the levels",
    "level_order": "the transitions' steps",
    "MddSaturation": "the transitions' steps",
}
"""The decision diagrams' set-up in order, and the stage the budget stops when the one
named "takes" longer than the budget (its reason says which)."""


@pytest.mark.parametrize("slow", list(SYMBOLIC_STAGES))
def test_the_decision_diagrams_set_up_stops_when_the_budget_is_spent(
    slow: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """As for the explorer: a stage of the diagrams' set-up that "takes" 2 s of a 1 s
    budget is the last one started (`place_order` once), and the result is incomplete
    with the limit and the stage as its reason, not an exception."""
    clock = FakeClock(0.001)
    started: list[str] = []
    done: list[float] = []
    for name in SYMBOLIC_STAGES:
        stage = getattr(symbolic_explore, name)

        def timed(*args: Any, _stage: Any = stage, _name: str = name, **kwargs: Any) -> Any:
            started.append(_name)
            if _name == slow:
                clock.now += 2.0
            result = _stage(*args, **kwargs)
            if _name == slow:
                done.append(clock.now)
            return result

        monkeypatch.setattr(symbolic_explore, name, timed)
    result = explore_symbolic(rings(20, 10), SymbolicLimits(budget=Budget(1.0, clock=clock)))
    names = list(SYMBOLIC_STAGES)
    assert started == names[: names.index(slow) + 1]
    assert not result.complete and result.states == 0
    assert result.reason == f"time limit of 1 s reached (setting up: {SYMBOLIC_STAGES[slow]})"
    assert clock.now - done[0] <= MARGIN_S


def test_a_verdict_says_which_limit_stopped_the_decision_diagrams(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """``--method symbolic`` on a clock where the invariants "take" 6 s of a 5 s limit:
    the verdicts the diagrams would have decided name the command's limit (not the
    diagrams' share of it) and where their set-up stopped."""
    clock = FakeClock(0.001)
    facts = symbolic_explore.invariant_facts  # type: ignore[attr-defined]

    def slow(*args: Any, **kwargs: Any) -> Any:
        clock.now += 6.0
        return facts(*args, **kwargs)

    monkeypatch.setattr(symbolic_explore, "invariant_facts", slow)
    options = VerifyOptions(time_limit=5.0, method="symbolic", structural=False)
    report = run_verification(rings(20, 10), options, budget=Budget(clock=clock)).report
    detail = report.property("bounded").detail
    stopped = (
        "decision diagrams stopped: time limit of 5 s reached (setting up: ordering the places)"
    )
    assert stopped in detail, detail


def test_the_decision_diagrams_order_the_places_once(monkeypatch: pytest.MonkeyPatch) -> None:
    """Node saturation hands over at once here (every net counts as testing too many
    levels), and the set-level schedule takes over with the same order of places:
    `place_order` runs once (it ran for each)."""
    calls: list[int] = []
    order = symbolic_explore.place_order  # type: ignore[attr-defined]

    def counted(net: Any) -> list[int]:
        calls.append(1)
        return order(net)

    monkeypatch.setattr(symbolic_explore, "place_order", counted)
    monkeypatch.setattr(symbolic_explore, "WIDE_TESTS", 0)
    result = explore_symbolic(rings(3, 4))
    assert result.complete and result.states == 4**3
    assert len(calls) == 1


def test_a_wide_node_reads_the_budget_between_its_children() -> None:
    """The root of 300 rings has 300 children: the tree stops among them at its
    deadline instead of making them all first."""
    ticks = itertools.count()
    result = coverability(rings(300, 10), budget=Budget(2.5, clock=lambda: float(next(ticks))))
    assert result.bounded is None
    assert result.reason.startswith("time limit of 2.5 s reached after")
    assert 1 < result.nodes < 300


def test_the_node_cap_keeps_a_wide_tree_small() -> None:
    net = rings(2000, 10)
    assert node_cap(2_000, net, 2_000_000) == 100
    assert node_cap(2_000, rings(10, 10), 2_000_000) == 2_000
    result = coverability(net, max_nodes=node_cap(2_000, net, 2_000_000))
    assert result.nodes == 100 and result.reason == "node budget of 100 reached"


def _force_reference(
    size: int, supports: list[list[int]], start: list[int], rounds: int
) -> list[int]:
    """FORCE as plain Python loops (the implementation `force` replaced)."""
    if not supports:
        return list(start)

    def span(order: list[int]) -> int:
        position = {p: i for i, p in enumerate(order)}
        return sum(max(position[p] for p in s) - min(position[p] for p in s) for s in supports)

    touching: list[list[int]] = [[] for _ in range(size)]
    for k, support in enumerate(supports):
        for p in support:
            touching[p].append(k)
    order = list(start)
    best, best_cost = list(order), span(order)
    for _ in range(rounds):
        position = {p: i for i, p in enumerate(order)}
        centre = [sum(position[p] for p in s) / len(s) for s in supports]
        target = {
            p: sum(centre[k] for k in touching[p]) / len(touching[p])
            if touching[p]
            else position[p]
            for p in order
        }
        order = sorted(order, key=lambda p: (target[p], position[p]))
        cost = span(order)
        if cost < best_cost:
            best, best_cost = list(order), cost
    return best


@settings(max_examples=200, deadline=None)
@given(st.data())
def test_force_in_numpy_finds_the_order_the_loops_found(data: st.DataObject) -> None:
    size = data.draw(st.integers(1, 25))
    item = st.integers(0, size - 1)
    supports = data.draw(st.lists(st.sets(item, min_size=1, max_size=5).map(sorted), max_size=30))
    start = data.draw(st.permutations(list(range(size))))
    rounds = data.draw(st.sampled_from([1, 3, 40]))
    assert force(size, supports, list(start), rounds) == _force_reference(
        size, supports, list(start), rounds
    )
