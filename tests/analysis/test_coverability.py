"""Karp-Miller coverability: hand nets, pumping traces replayed, random nets vs reference."""

from __future__ import annotations

import itertools
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import given, settings

from analysis.budget import Budget
from analysis.coverability import coverability
from coral_lang.net import Net
from coral_lang.pnml import read_pnml
from tests.analysis.nets import Arcs, make_net
from tests.analysis.reference import explore_reference
from tests.analysis.strategies import small_nets
from tests.conftest import CONFORMANCE


def _replay_grows(net: Net, prefix: tuple[str, ...], loop: tuple[str, ...], place: str) -> bool:
    """Fire prefix, then loop twice, with Net.fire; the place must grow each round and
    no place may shrink over a round."""
    marking = net.initial_marking()
    seen = []
    for name in prefix:
        tr = net.transition(name)
        assert net.enabled(marking, tr), name
        marking = net.fire(marking, tr)
    seen.append(marking)
    for _ in range(2):
        for name in loop:
            tr = net.transition(name)
            assert net.enabled(marking, tr), name
            marking = net.fire(marking, tr)
        seen.append(marking)
    i = net.place_index(place)
    return all(
        after[i] > before[i] and all(a >= b for a, b in zip(after, before, strict=True))
        for before, after in itertools.pairwise(seen)
    )


def test_pump_is_unbounded_with_a_replayable_trace() -> None:
    net = make_net("pump", {"a": 1, "b": 0}, {"t": ({"a": 1}, {"a": 1, "b": 1})})
    result = coverability(net)
    assert result.bounded is False and result.complete
    assert result.unbounded == ("b",) and result.bounds == {"a": 1}
    trace = result.pumps["b"]
    assert trace.prefix_names == () and trace.loop_names == ("t",)
    assert _replay_grows(net, trace.prefix_names, trace.loop_names, "b")
    assert "'b' is unbounded" in trace.explain() and "unbounded: b" in result.explain()


def test_unbounded_buffer_between_producer_and_consumer() -> None:
    net = make_net(
        "prodcons",
        {"ready": 1, "made": 0, "buffer": 0, "want": 1, "got": 0},
        {
            "produce": ({"ready": 1}, {"made": 1}),
            "deposit": ({"made": 1}, {"ready": 1, "buffer": 1}),
            "take": ({"buffer": 1, "want": 1}, {"got": 1}),
            "consume": ({"got": 1}, {"want": 1}),
        },
    )
    result = coverability(net)
    assert result.bounded is False and result.unbounded == ("buffer",)
    trace = result.pumps["buffer"]
    assert _replay_grows(net, trace.prefix_names, trace.loop_names, "buffer")
    assert result.bounds == {"ready": 1, "made": 1, "want": 1, "got": 1}


def test_nested_pump_feeds_a_second_one() -> None:
    # q grows by t; u turns a q into a p. The tree's own loop for p (just u) drains q, so
    # the trace must include repetitions of t.
    net = make_net(
        "nested",
        {"a": 1, "b": 1, "q": 0, "p": 0},
        {"t": ({"a": 1}, {"a": 1, "q": 1}), "u": ({"b": 1, "q": 1}, {"b": 1, "p": 1})},
    )
    result = coverability(net)
    assert result.unbounded == ("q", "p") and result.missing_pumps == ()
    for place in ("q", "p"):
        trace = result.pumps[place]
        assert _replay_grows(net, trace.prefix_names, trace.loop_names, place)


def test_weighted_pump_needs_a_run_up() -> None:
    # Two tokens must collect in x before the pump can fire at all.
    net = make_net(
        "runup",
        {"s": 2, "x": 0, "y": 0},
        {"load": ({"s": 1}, {"x": 1}), "grow": ({"x": 2}, {"x": 2, "y": 3})},
    )
    result = coverability(net)
    trace = result.pumps["y"]
    assert trace.prefix_names == ("load", "load") and trace.loop_names == ("grow",)
    assert trace.after[2] - trace.start[2] == 3


def test_bounded_net_gives_exact_bounds() -> None:
    net = make_net(
        "mutex",
        {"idle1": 1, "cs1": 0, "idle2": 1, "cs2": 0, "lock": 1},
        {
            "enter1": ({"idle1": 1, "lock": 1}, {"cs1": 1}),
            "exit1": ({"cs1": 1}, {"idle1": 1, "lock": 1}),
            "enter2": ({"idle2": 1, "lock": 1}, {"cs2": 1}),
            "exit2": ({"cs2": 1}, {"idle2": 1, "lock": 1}),
        },
    )
    result = coverability(net)
    assert result.bounded is True and result.complete and result.nodes == 3
    assert result.bounds == {p.name: 1 for p in net.places}
    assert result.pumps == {} and "bounded" in result.explain()


def test_sibling_branches_are_not_compared() -> None:
    # From s, "one" gives (0, 1) and "two" gives (0, 2). (0, 2) strictly covers (0, 1),
    # but they are siblings: comparing them would wrongly make c unbounded.
    net = make_net(
        "siblings",
        {"s": 1, "c": 0},
        {"one": ({"s": 1}, {"c": 1}), "two": ({"s": 1}, {"c": 2})},
    )
    result = coverability(net)
    assert result.bounded is True and result.bounds == {"s": 1, "c": 2}


def test_node_budget_stops_the_tree() -> None:
    n = 12
    places = {f"p{i}": 1 if i == 0 else 0 for i in range(n)} | {"count": 0}
    transitions: dict[str, tuple[Arcs, Arcs]] = {
        f"t{i}": ({f"p{i}": 1}, {f"p{i + 1}": 1}) for i in range(n - 1)
    }
    transitions |= {f"s{i}": ({f"p{i}": 1}, {f"p{i}": 1, "count": 1}) for i in range(1)}
    net = make_net("budget", places, transitions)
    result = coverability(net, max_nodes=3)
    assert not result.complete and "node budget" in result.reason
    full = coverability(net)
    assert full.bounded is False and full.unbounded == ("count",)


def test_time_limit_with_an_injected_clock() -> None:
    n = 6
    net = make_net(
        "line",
        {f"p{i}": 1 if i == 0 else 0 for i in range(n)},
        {f"t{i}": ({f"p{i}": 1}, {f"p{i + 1}": 1}) for i in range(n - 1)},
    )
    ticks = itertools.count()
    result = coverability(net, budget=Budget(2.5, clock=lambda: float(next(ticks))))
    assert not result.complete and result.bounded is None
    assert result.reason == "time limit of 2.5 s reached after 2 nodes"
    assert "undecided" in result.explain()


# -- random nets against the reference explorer -------------------------------------------


@pytest.mark.slow
@settings(max_examples=300)
@given(small_nets())
def test_karp_miller_agrees_with_the_reference(net: Net) -> None:
    result = coverability(net, max_nodes=50_000, budget=Budget(20.0))
    assert result.complete  # small nets: the tree always finishes within budget
    if result.bounded:
        # A bounded net has finitely many markings: the reference finishes, with the
        # same bound per place.
        reference = explore_reference(net, max_states=200_000)
        assert reference.complete
        for i, place in enumerate(net.places):
            assert result.bounds[place.name] == max(m[i] for m in reference.states)
    else:
        assert result.unbounded and result.missing_pumps == ()
        for name, trace in result.pumps.items():
            assert _replay_grows(net, trace.prefix_names, trace.loop_names, name)
        # Places never ω are bounded, and the tree's bound holds on what search sees.
        reference = explore_reference(net, max_states=2_000)
        assert not reference.complete
        for i, place in enumerate(net.places):
            if place.name in result.bounds:
                assert max(m[i] for m in reference.states) <= result.bounds[place.name]


# -- conformance: bounded MCC models -------------------------------------------------------


def _oracle_models() -> list[dict[str, Any]]:
    path = CONFORMANCE / "oracle.yaml"
    if not path.exists():
        return []
    models: list[dict[str, Any]] = yaml.safe_load(path.read_text())["models"]
    return models


def _param(model: dict[str, Any]) -> Any:
    marks = [pytest.mark.slow] if model["states"] > 2_500 else []
    return pytest.param(model, id=str(model["model"]), marks=marks)


@pytest.mark.parametrize(
    "model", [_param(m) for m in _oracle_models() if m.get("states") and m["states"] <= 11_000]
)
def test_karp_miller_matches_the_mcc_state_space(model: dict[str, Any]) -> None:
    """All MCC models are bounded: the tree has one node per reachable marking, and its
    per-place maxima are the oracle's bounds."""
    net: Net = read_pnml(Path(CONFORMANCE) / model["pnml"])
    result = coverability(net, budget=Budget(60.0))
    assert result.bounded is True and result.complete
    assert result.nodes == model["states"]
    assert max(result.bounds.values()) == model["max_tokens_place"]
    for query in model.get("upper_bounds") or []:
        if len(query["places"]) == 1 and query["bound"] is not None:
            assert result.bounds[query["places"][0]] == query["bound"], query["id"]


def test_the_tree_summary_matches_a_plain_loop() -> None:
    """`_summarise` (numpy, block by block) gives the first omega node and the largest
    finite count per place that a loop over every node and place gives."""
    import random

    from analysis.coverability import OMEGA, SUMMARY_BLOCK, _Node, _numeric, _summarise

    rng = random.Random(7)
    n_places = 6
    nodes = [
        _Node(
            tuple(
                rng.choice([OMEGA, 0, 1, 2, 5]) if rng.random() < 0.3 else rng.randrange(4)
                for _ in range(n_places)
            ),
            -1,
            -1,
        )
        for _ in range(2 * SUMMARY_BLOCK + 37)
    ]
    first: dict[int, int] = {}
    top = [0] * n_places
    for index, node in enumerate(nodes):
        for p, v in enumerate(node.marking):
            if v == OMEGA:
                first.setdefault(p, index)
            else:
                top[p] = max(top[p], v)
    assert _summarise(nodes, n_places) == (first, top)
    rows = [_numeric([node.marking])[0] for node in nodes]
    assert _summarise(nodes, n_places, rows) == (first, top)  # the tree's own rows


@given(small_nets())
@settings(max_examples=150, deadline=None)
def test_a_node_looks_only_at_the_consumers_of_its_marked_places(net: Net) -> None:
    """The tree built from each node's candidates (consumers of its marked places and
    transitions without inputs) is the tree a scan of every transition builds: the
    same nodes, in the same order."""
    from analysis.coverability import _Tree

    fast = _Tree(net)
    fast_done = fast.build(400, Budget(seconds=30.0))

    class _Scan(_Tree):
        def _candidates(self, index: int) -> list[int]:
            return list(range(len(self.inputs)))

    scan = _Scan(net)
    assert scan.build(400, Budget(seconds=30.0)) == fast_done
    assert [n.marking for n in fast.nodes] == [n.marking for n in scan.nodes]
    assert [(n.parent, n.transition) for n in fast.nodes] == [
        (n.parent, n.transition) for n in scan.nodes
    ]
