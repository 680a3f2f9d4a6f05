"""The reachability graph of a small net as a `networkx.MultiDiGraph`.

Nodes are state numbers (BFS order, 0 = initial marking) with a ``marking`` attribute
(tuple aligned with ``net.places``) and ``dead`` (enables nothing); there is one edge
per (marking, enabled transition) pair, keyed by the transition name, so parallel
firings to the same successor stay distinct and ``number_of_edges()`` equals the MCC
edge count. ``networkx.write_graphml`` and ``networkx.nx_pydot`` take it from there
(convert tuple attributes to strings first for GraphML).
"""

from __future__ import annotations

from typing import Any

import networkx as nx

from analysis.stategraph import build_graph
from analysis.statespace import StateSpace, explore
from coral_lang.net import Net

MAX_GRAPH_STATES = 100_000
"""Largest graph built by default: a networkx graph costs ~1 KB per node and edge."""


def to_networkx(source: StateSpace | Net, *, max_states: int = MAX_GRAPH_STATES) -> Any:
    """The reachability graph of ``source`` (a net, or a complete full `StateSpace`).

    Args:
        source: a net (explored here) or the result of `explore` without ``por``.
        max_states: refuse state spaces with more markings than this.

    Returns:
        A ``networkx.MultiDiGraph`` (typed ``Any``: networkx ships no type hints).

    Raises:
        ValueError: the state space is incomplete, reduced, or larger than
            ``max_states``; explore the net fully (or raise ``max_states``) first.
    """
    space = explore(source, max_states=max_states + 1) if isinstance(source, Net) else source
    if not space.complete:
        raise ValueError(
            f"state space of '{space.net.name}' is incomplete ({space.stopped_reason});"
            " only complete reachability graphs can be exported"
        )
    if space.reduced:
        raise ValueError("a partial-order reduced state space has no full graph; explore again")
    if space.states > max_states:
        raise ValueError(
            f"state space of '{space.net.name}' has {space.states} markings,"
            f" more than max_states={max_states}"
        )
    net = space.net
    edges = build_graph(space)
    graph = nx.MultiDiGraph(name=net.name)
    dead = set(space.deadlocks.tolist())
    for i, marking in enumerate(space.markings.tolist()):
        graph.add_node(i, marking=tuple(marking), dead=i in dead)
    names = [t.name for t in net.transitions]
    for source, t, target in zip(
        edges.sources.tolist(), edges.labels.tolist(), edges.targets.tolist(), strict=True
    ):
        graph.add_edge(source, target, key=names[t], transition=t)
    return graph
