"""The reachability graph's edges and the cycle/fairness algorithms on it."""

from __future__ import annotations

import numpy as np
import pytest

from analysis.stategraph import (
    GraphError,
    backward_reach,
    build_graph,
    fair_lasso,
    fair_sccs,
    shortest_path,
)
from analysis.statespace import explore
from coral_lang.net import Net, Place, Transition


def _ring(n: int) -> Net:
    """One token going round ``n`` places, plus a way out from place 0 to ``out``."""
    places = [Place(f"p{i}", 1 if i == 0 else 0) for i in range(n)] + [Place("out")]
    transitions = [
        Transition(f"t{i}", ((f"p{i}", 1),), ((f"p{(i + 1) % n}", 1),)) for i in range(n)
    ]
    transitions.append(Transition("leave", (("p0", 1),), (("out", 1),)))
    return Net("ring", tuple(places), tuple(transitions))


def test_edges_are_every_marking_transition_pair() -> None:
    space = explore(_ring(4))
    graph = build_graph(space)
    assert graph.n_states == space.states == 5
    assert graph.n_edges == space.edges == 5
    for s in range(graph.n_states):
        marking = space.marking(s)
        for e in range(int(graph.indptr[s]), int(graph.indptr[s + 1])):
            tr = space.net.transitions[int(graph.labels[e])]
            assert space.net.enabled(marking, tr)
            assert space.marking(int(graph.targets[e])) == space.net.fire(marking, tr)
    assert graph.dead.sum() == 1


def test_incomplete_space_is_refused() -> None:
    space = explore(_ring(6), max_states=2)
    with pytest.raises(GraphError, match="incomplete"):
        build_graph(space)


def test_reach_and_paths() -> None:
    graph = build_graph(explore(_ring(4)))
    n, src, dst = graph.n_states, graph.sources, graph.targets
    goal = graph.dead
    assert backward_reach(n, src, dst, goal).all()
    start = np.zeros(n, dtype=np.bool_)
    start[0] = True
    path = shortest_path(n, src, dst, start, goal)
    assert path is not None and [
        graph.space.net.transitions[int(graph.labels[e])].name for e in path
    ] == ["leave"]


def test_fairness_excludes_a_cycle_that_starves_an_enabled_group() -> None:
    graph = build_graph(explore(_ring(3)))
    n, src, dst = graph.n_states, graph.sources, graph.targets
    leave = graph.space.net.transition_index("leave")
    start = np.zeros(n, dtype=np.bool_)
    start[0] = True
    # Without fairness the ring is a cycle a run can take forever.
    comp, fair = fair_sccs(n, src, dst, [])
    lasso = fair_lasso(n, src, dst, start, comp, fair)
    assert lasso is not None and len(lasso.cycle) == 3
    # "leave" is not enabled at every node of the ring, so weak fairness allows it too.
    group = (graph.enabled([leave]), graph.labels == leave)
    comp, fair = fair_sccs(n, src, dst, [group])
    assert fair.any()
    # A group enabled everywhere on the ring and never taken inside it starves.
    everywhere = np.ones(n, dtype=np.bool_)
    comp, fair = fair_sccs(n, src, dst, [(everywhere, graph.labels == leave)])
    assert not fair.any()
