"""The reachability graph of a completely explored net, and what temporal checks need.

`analysis.statespace.explore` stores every reachable marking but not the edges between
them: counting and reachability questions never need them. Temporal properties do
(cycles, "a final marking stays reachable", fair runs, CTL fixpoints, LTL products), so
`build_graph` recovers them once, vectorised: for a block of stored markings it finds
the enabled transitions, adds each one's key delta to the marking's packed key and
looks the successor up in a hash set of all keys. The result is compressed sparse
rows (``indptr``, ``targets``, ``labels``), 12 bytes per edge, in which every
(marking, enabled transition) pair is one edge, as the MCC counts them, except that an
operator input has no edge out of a terminal marking (`analysis.inputs`: the run has
stopped there), so the graph's dead nodes are the terminal markings.

The algorithms below work on plain arrays so the LTL product graph can use them too:

* `scc_labels`: strongly connected components (scipy's C implementation);
* `backward_reach` / `forward_reach`: which nodes reach (are reached from) a set,
  through allowed nodes and edges;
* `shortest_path`: a shortest edge sequence from a set of nodes to another set;
* `fair_sccs` and `fair_lasso`: cycles that a run satisfying weak fairness can take
  forever (each *group* of edges that is enabled at every node of the cycle must occur
  on it), with a lasso as evidence.

Graphs of at most `SMALL_GRAPH` edges (every mission of a few hundred markings) are
searched in plain Python: loading scipy costs about 0.2 s, longer than searching them,
and every ``coral-check`` of a mission pays it otherwise. scipy is loaded on first use.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from analysis.budget import Budget, work_limit_reason
from analysis.encoding import KeyStore
from analysis.inputs import input_flags
from analysis.statespace import StateSpace

IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

if TYPE_CHECKING:
    import scipy.sparse as sp

GRAPH_CELLS = 1 << 22
"""Most (marking, preset entry) cells gathered at once while finding enabled edges."""
SMALL_GRAPH = 10_000
"""Graphs with at most this many nodes and edges are searched in Python, not scipy."""


class GraphError(Exception):
    """The graph cannot be built: the state space is incomplete or reduced, or the edge
    budget ran out. The message says which; callers turn it into an inconclusive
    verdict."""


@dataclass(frozen=True)
class StateGraph:
    """Every reachable marking of a net and every (marking, enabled transition) edge.

    Attributes:
        space: the complete, unreduced state space the nodes come from; node ``i`` is
            its state ``i`` (BFS order: ``space.trace_to(i)`` is a shortest trace).
        indptr: edges of node ``i`` are ``indptr[i]:indptr[i + 1]``.
        targets: successor node of each edge.
        labels: transition index of each edge.
        seconds: time spent building the edges.
    """

    space: StateSpace
    indptr: IntArray
    targets: IntArray
    labels: IntArray
    seconds: float

    @property
    def n_states(self) -> int:
        """Number of nodes."""
        return int(self.indptr.size - 1)

    @property
    def n_edges(self) -> int:
        """Number of edges."""
        return int(self.targets.size)

    @cached_property
    def sources(self) -> IntArray:
        """Source node of each edge."""
        return np.repeat(np.arange(self.n_states, dtype=np.int64), np.diff(self.indptr))

    @cached_property
    def dead(self) -> BoolArray:
        """Nodes with no enabled transition (terminal ones, on a net with inputs)."""
        flags: BoolArray = np.diff(self.indptr) == 0
        return flags

    def enabled(self, transitions: Sequence[int]) -> BoolArray:
        """Nodes where at least one of ``transitions`` is enabled."""
        out = np.zeros(self.n_states, dtype=np.bool_)
        if len(transitions):
            hit = np.isin(self.labels, np.asarray(transitions, dtype=np.int64))
            out[self.sources[hit]] = True
        return out

    def markings_where(self, predicate: Callable[[IntArray], BoolArray]) -> BoolArray:
        """Per node, ``predicate`` applied to blocks of markings (as in
        `StateSpace.find`)."""
        out = np.zeros(self.n_states, dtype=np.bool_)
        for start, block in self.space.iter_markings():
            out[start : start + block.shape[0]] = predicate(block)
        return out

    def edge_steps(self, edges: Sequence[int]) -> list[tuple[int, int, int]]:
        """``(source, transition, target)`` of each edge index."""
        return [(int(self.sources[e]), int(self.labels[e]), int(self.targets[e])) for e in edges]


def build_graph(
    space: StateSpace,
    *,
    max_edges: int | None = None,
    budget: Budget | None = None,
) -> StateGraph:
    """The edges of a complete, unreduced ``space``.

    Args:
        space: from `explore` with ``por=False``, ``complete``.
        max_edges: stop with `GraphError` past this many edges (12 bytes each).
        budget: its deadline stops the build with `GraphError` (None: no limit); its
            clock times it.

    Raises:
        GraphError: the space is incomplete or reduced, or a budget ran out.
    """
    if space.reduced:
        raise GraphError("the state space is stubborn-set reduced; temporal checks need all edges")
    if not space.complete:
        raise GraphError(f"the state space is incomplete ({space.stopped_reason})")
    if max_edges is not None and space.edges > max_edges:
        raise GraphError(_too_many_edges(space.edges, max_edges))
    budget = budget or Budget()
    start = budget.clock()
    from analysis.encoding import CompactNet

    cn = CompactNet.from_net(space.net)
    n, n_t = space.states, cn.n_transitions
    operator = np.flatnonzero(input_flags(space.net))
    engine = np.flatnonzero(~input_flags(space.net))
    keys = np.ascontiguousarray(space.keys[:n])
    store = KeyStore.of(keys, wide_index=n >= 1 << 31)
    delta = space.layout.key_deltas(cn.effects)
    per_marking = max(1, sum(int(g.places.size) for g in cn.groups) + n_t)
    chunk = max(1, GRAPH_CELLS // per_marking)
    counts = np.zeros(n, dtype=np.int64)
    targets: list[IntArray] = []
    labels: list[IntArray] = []
    for first, block in space.iter_markings(chunk):
        if budget.expired():
            done = sum(int(t.size) for t in targets)
            raise GraphError(f"building the edges: {budget.time_reason(done, 'edge')}")
        enabled = np.zeros((block.shape[0], n_t), dtype=np.bool_)
        for group in cn.groups:
            if group.places.shape[1] == 0:
                enabled[:, group.transitions] = True
                continue
            ok = (block[:, group.places] >= group.weights).all(axis=2)
            enabled[:, group.transitions] = ok
        if operator.size:
            # The run has stopped where no engine or reply transition is enabled: the
            # operator can no longer act there (analysis.inputs).
            stopped = ~enabled[:, engine].any(axis=1)
            enabled[np.ix_(stopped, operator)] = False
        rows, trans = np.nonzero(enabled)
        nodes = rows.astype(np.int64) + first
        succ_keys = keys[nodes] + delta[trans]
        found = store.find(succ_keys)
        if found.size and int(found.min()) < 0:
            raise GraphError("a successor marking is not in the state space (internal error)")
        np.add.at(counts, nodes, 1)
        targets.append(found)
        labels.append(trans.astype(np.int64))
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(counts, out=indptr[1:])
    all_targets = np.concatenate(targets) if targets else np.zeros(0, dtype=np.int64)
    all_labels = np.concatenate(labels) if labels else np.zeros(0, dtype=np.int64)
    if max_edges is not None and all_targets.size > max_edges:
        raise GraphError(_too_many_edges(all_targets.size, max_edges))
    return StateGraph(space, indptr, all_targets, all_labels, budget.clock() - start)


def _too_many_edges(edges: int, max_edges: int) -> str:
    return f"{work_limit_reason(max_edges, 'edge')}: the graph has {edges:,} edges"


# -- algorithms on arrays of edges --------------------------------------------------------


def _matrix(n: int, src: IntArray, dst: IntArray) -> sp.csr_matrix:
    import scipy.sparse as sp

    data = np.ones(src.size, dtype=np.int8)
    return sp.csr_matrix((data, (src, dst)), shape=(n, n))


def _small(n: int, src: IntArray) -> bool:
    return n <= SMALL_GRAPH and src.size <= SMALL_GRAPH


def _successors(n: int, src: IntArray, dst: IntArray) -> list[list[tuple[int, int]]]:
    """Per node, its ``(target, edge index)`` pairs in edge order."""
    out: list[list[tuple[int, int]]] = [[] for _ in range(n)]
    for e, (a, b) in enumerate(zip(src.tolist(), dst.tolist(), strict=True)):
        out[a].append((b, e))
    return out


def _scc_small(n: int, src: IntArray, dst: IntArray) -> IntArray:
    """`scc_labels` in Python: Tarjan's algorithm with an explicit stack."""
    succ = [[b for b, _ in edges] for edges in _successors(n, src, dst)]
    index, low, comp = [-1] * n, [0] * n, [-1] * n
    on_stack = [False] * n
    stack: list[int] = []
    counter = components = 0
    for root in range(n):
        if index[root] >= 0:
            continue
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack[root] = True
        work = [(root, 0)]
        while work:
            v, i = work[-1]
            if i < len(succ[v]):
                work[-1] = (v, i + 1)
                w = succ[v][i]
                if index[w] < 0:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on_stack[w] = True
                    work.append((w, 0))
                elif on_stack[w]:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                parent = work[-1][0]
                low[parent] = min(low[parent], low[v])
            if low[v] == index[v]:
                while True:
                    w = stack.pop()
                    on_stack[w] = False
                    comp[w] = components
                    if w == v:
                        break
                components += 1
    return np.asarray(comp, dtype=np.int64)


def _bfs_small(
    n: int, src: IntArray, dst: IntArray, start: BoolArray, goal: BoolArray | None
) -> tuple[list[int], list[int], int]:
    """Breadth-first search from every ``start`` node: ``(visited in order, edge that
    reached each node or -1, first goal node met or -1)``."""
    succ = _successors(n, src, dst)
    via = [-1] * n
    seen = start.tolist()
    order = [int(v) for v in np.flatnonzero(start)]
    queue = deque(order)
    wanted = goal.tolist() if goal is not None else None
    while queue:
        v = queue.popleft()
        if wanted is not None and wanted[v]:
            return order, via, v
        for w, e in succ[v]:
            if not seen[w]:
                seen[w] = True
                via[w] = e
                order.append(w)
                queue.append(w)
    return order, via, -1


def scc_labels(n: int, src: IntArray, dst: IntArray) -> IntArray:
    """Strongly connected component of each of ``n`` nodes under edges ``src -> dst``."""
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    if _small(n, src):
        return _scc_small(n, src, dst)
    from scipy.sparse import csgraph

    _, labels = csgraph.connected_components(
        _matrix(n, src, dst), directed=True, connection="strong"
    )
    return np.asarray(labels, dtype=np.int64)


def nontrivial(n: int, src: IntArray, dst: IntArray, comp: IntArray) -> BoolArray:
    """Per component of ``comp``, whether it holds a cycle (two nodes, or a self-loop)."""
    n_comp = int(comp.max(initial=-1)) + 1
    sizes = np.bincount(comp, minlength=n_comp)
    cyclic = sizes > 1
    loops = src[src == dst]
    cyclic[comp[loops]] = True
    return cyclic


def forward_reach(n: int, src: IntArray, dst: IntArray, start: BoolArray) -> BoolArray:
    """Nodes reachable from ``start`` (included) along edges ``src -> dst``."""
    if not start.any():
        return start.copy()
    if _small(n, src):
        out = np.zeros(n, dtype=np.bool_)
        out[_bfs_small(n, src, dst, start, None)[0]] = True
        return out
    from scipy.sparse import csgraph

    # One extra node feeding every start node turns a multi-source search into one BFS.
    root = n
    seeds = np.flatnonzero(start)
    s = np.concatenate([src, np.full(seeds.size, root, dtype=np.int64)])
    d = np.concatenate([dst, seeds])
    order = csgraph.breadth_first_order(
        _matrix(n + 1, s, d), root, directed=True, return_predecessors=False
    )
    out = np.zeros(n, dtype=np.bool_)
    out[order[order < n]] = True
    return out


def backward_reach(n: int, src: IntArray, dst: IntArray, goal: BoolArray) -> BoolArray:
    """Nodes from which ``goal`` is reachable (goal included) along edges
    ``src -> dst``."""
    return forward_reach(n, dst, src, goal)


def shortest_path(
    n: int, src: IntArray, dst: IntArray, start: BoolArray, goal: BoolArray
) -> list[int] | None:
    """Indices (into ``src``/``dst``) of a shortest edge sequence from some ``start``
    node to some ``goal`` node; ``[]`` if a start node is a goal, ``None`` if none is
    reachable."""
    if (start & goal).any():
        return []
    if not start.any() or not goal.any():
        return None
    if _small(n, src):
        _, via, node = _bfs_small(n, src, dst, start, goal)
        if node < 0:
            return None
        path: list[int] = []
        while via[node] >= 0:
            path.append(via[node])
            node = int(src[via[node]])
        return path[::-1]
    from scipy.sparse import csgraph

    root = n
    seeds = np.flatnonzero(start)
    s = np.concatenate([src, np.full(seeds.size, root, dtype=np.int64)])
    d = np.concatenate([dst, seeds])
    order, pred = csgraph.breadth_first_order(
        _matrix(n + 1, s, d), root, directed=True, return_predecessors=True
    )
    reached = order[(order < n)]
    hits = reached[goal[reached]]
    if not hits.size:
        return None
    # BFS order is by distance, so the first goal met is a nearest one.
    node = int(hits[0])
    nodes = [node]
    while True:
        parent = int(pred[node])
        if parent == root or parent < 0:
            break
        nodes.append(parent)
        node = parent
    nodes.reverse()
    # Recover the edges: for each step (pred -> node) take the first matching edge.
    return _first_edges(n, src, dst, nodes[:-1], nodes[1:])


def _first_edges(
    n: int, src: IntArray, dst: IntArray, heads: Sequence[int], tails: Sequence[int]
) -> list[int]:
    """For each ``(heads[i], tails[i])`` pair, the first edge index from one to the other
    (each pair must have an edge): one sort of the edges, then a binary search per
    pair, so long paths in large graphs stay cheap."""
    if not len(heads):
        return []
    keys = src.astype(np.int64) * (n + 1) + dst
    order = np.argsort(keys, kind="stable")
    wanted = np.asarray(heads, dtype=np.int64) * (n + 1) + np.asarray(tails, dtype=np.int64)
    found = order[np.searchsorted(keys[order], wanted)]
    return [int(e) for e in found]


def fair_sccs(
    n: int,
    src: IntArray,
    dst: IntArray,
    groups: Sequence[tuple[BoolArray, BoolArray]],
    within: BoolArray | None = None,
) -> tuple[IntArray, BoolArray]:
    """Components whose cycles a weakly fair run can take forever.

    A run is weakly fair for a group when the group is not enabled at every position
    from some point on without one of its edges being taken. A run that stays in a
    strongly connected component ``C`` forever and takes every edge of ``C`` infinitely
    often is the fairest one possible there: it violates a group exactly when the group
    is enabled at every node of ``C`` and none of the group's edges lies inside ``C``.
    So ``C`` (with a cycle) admits a fair run iff no group is in that position.

    Args:
        n: number of nodes.
        src, dst: the edges.
        groups: per fairness group, ``(enabled_at, edge_in_group)``: the nodes where
            the group is enabled and which edges belong to it.
        within: only nodes where this is true (and edges between them) count; ``None``
            for all.

    Returns:
        ``(comp, fair)``: the component of each node (``-1`` outside ``within``) and,
        per component, whether it has a cycle and admits a fair run.
    """
    keep = np.ones(src.size, dtype=np.bool_)
    if within is not None:
        keep = within[src] & within[dst]
    s, d = src[keep], dst[keep]
    comp = scc_labels(n, s, d)
    if within is not None:
        comp = np.where(within, comp, -1)
    n_comp = int(comp.max(initial=-1)) + 1
    # Nodes outside `within` get the spare index n_comp, dropped from the result.
    fair = nontrivial(n, s, d, np.where(comp < 0, n_comp, comp))[:n_comp]
    members = comp >= 0
    for enabled_at, in_group in groups:
        # Components in which the group is enabled at every node ...
        disabled_somewhere = np.zeros(n_comp, dtype=np.bool_)
        disabled_somewhere[comp[members & ~enabled_at]] = True
        # ... and none of its edges stays inside the component.
        inner = keep & in_group
        inner_edges = np.zeros(n_comp, dtype=np.bool_)
        if inner.any():
            a, b = comp[src[inner]], comp[dst[inner]]
            same = (a == b) & (a >= 0)
            inner_edges[a[same]] = True
        fair &= disabled_somewhere | inner_edges
    return comp, fair


@dataclass(frozen=True)
class Lasso:
    """An infinite run as evidence: edges from a start node to a cycle, then the cycle
    (edge indices into the arrays it was found in)."""

    prefix: tuple[int, ...]
    cycle: tuple[int, ...]


def fair_lasso(
    n: int,
    src: IntArray,
    dst: IntArray,
    start: BoolArray,
    comp: IntArray,
    fair: BoolArray,
    groups: Sequence[tuple[BoolArray, BoolArray]] = (),
) -> Lasso | None:
    """A shortest prefix from ``start`` into a fair component, then a cycle inside it
    that satisfies every group (takes one of its edges, or passes a node where it is
    disabled). ``None`` when no fair component is reachable."""
    if not fair.any():
        return None
    target = (comp >= 0) & fair[np.maximum(comp, 0)]
    prefix = shortest_path(n, src, dst, start, target)
    if prefix is None:
        return None
    entry = int(dst[prefix[-1]]) if prefix else int(np.flatnonzero(start & target)[0])
    c = int(comp[entry])
    inside = (comp[src] == c) & (comp[dst] == c)
    cycle = _covering_cycle(n, src, dst, inside, entry, comp == c, groups)
    return Lasso(tuple(prefix), tuple(cycle))


def _covering_cycle(
    n: int,
    src: IntArray,
    dst: IntArray,
    inside: BoolArray,
    entry: int,
    members: BoolArray,
    groups: Sequence[tuple[BoolArray, BoolArray]],
) -> list[int]:
    """A cycle from ``entry`` back to it, within the component, that visits for each
    group an edge of it (or a node where it is disabled): a chain of shortest paths."""
    idx = np.flatnonzero(inside)
    s, d = src[idx], dst[idx]
    cycle: list[int] = []
    here = entry
    for enabled_at, in_group in groups:
        if (members & ~enabled_at).any():
            goal_nodes = members & ~enabled_at
            if not goal_nodes[here]:
                step = shortest_path(n, s, d, node_mask(n, here), goal_nodes)
                assert step is not None
                cycle += [int(idx[e]) for e in step]
                here = int(d[step[-1]]) if step else here
            continue
        group_edges = np.flatnonzero(in_group[idx])
        assert group_edges.size, "a fair component has an inner edge of every enabled group"
        heads = np.zeros(n, dtype=np.bool_)
        heads[s[group_edges]] = True
        step = shortest_path(n, s, d, node_mask(n, here), heads)
        assert step is not None
        cycle += [int(idx[e]) for e in step]
        here = int(d[step[-1]]) if step else here
        take = group_edges[s[group_edges] == here][0]
        cycle.append(int(idx[take]))
        here = int(d[take])
    # Close the cycle; a cycle must take at least one edge.
    if here == entry and cycle:
        return cycle
    if here == entry:
        loops = np.flatnonzero(s == entry)
        first = loops[0]
        cycle.append(int(idx[first]))
        here = int(d[first])
        if here == entry:
            return cycle
    back = shortest_path(n, s, d, node_mask(n, here), node_mask(n, entry))
    assert back is not None
    return cycle + [int(idx[e]) for e in back]


def node_mask(n: int, node: int) -> BoolArray:
    """A boolean array over ``n`` nodes, true at ``node`` only."""
    out = np.zeros(n, dtype=np.bool_)
    out[node] = True
    return out
