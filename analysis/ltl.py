"""LTL model checking on a completely explored net: Spot's automaton times the graph.

`check_ltl` decides whether every run (every weakly fair run, with ``fairness``) from
the initial marking satisfies an LTL formula of `coral_lang.formula` (``A φ`` or a
bare path formula ``φ``; see `ltl_body`). The mission language's temporal assertions
and the Model Checking Contest's LTLCardinality / LTLFireability files both land here.

Semantics
---------

* **Runs.** A run is an infinite sequence of *positions*. Position ``i`` is a pair
  ``(s_i, t_i)``: the marking ``s_i`` and the transition ``t_i`` fired from ``s_i`` to
  ``s_{i+1}``; ``s_0`` is the initial marking. A run that reaches a dead marking (no
  transition enabled) stays there forever: every later position is that marking with
  no transition (``t_i`` = *none*). This is the Model Checking Contest convention for
  LTL ("a run that reaches a deadlock is continued by repeating the dead marking
  forever"). So every maximal firing sequence is exactly one run, finite ones padded
  with the dead marking.
* **Atoms.** State atoms are read on ``s_i``: `Compare` compares two integer
  expressions (`Tokens`: a weighted sum of the token counts of named places;
  `IntConst`) with ``<=, <, >=, >, ==`` or ``!=``; `Fireable` holds when at least one
  of its transitions is enabled at ``s_i``; `Deadlock` when none is; `Const` is
  ``true``/``false``. The event atom `Fires` holds when ``t_i`` is one of its
  transitions; it is false at the stuttering positions of a dead marking.
* **Operators.** `Not`, `And`, `Or` as usual; ``X φ``: ``φ`` at position ``i + 1``
  (the real next position: at a dead marking that is the same marking again, no
  stutter-invariance is assumed, so ``X`` counts steps); ``F φ``: at some position
  ``j >= i``; ``G φ``: at every ``j >= i``; ``φ U ψ``: ``ψ`` at some ``j >= i`` and
  ``φ`` at every position from ``i`` to ``j - 1`` (strong until).
* **Verdict.** The formula *holds* when every run from the initial marking satisfies
  it at position 0. With ``fairness`` groups (see `analysis.fairness`), only runs that
  are weakly fair for every group count: a run is unfair for a group when from some
  position on the group is enabled at every position and none of its edges is ever
  taken again. A run that ends in a dead marking is fair (nothing is enabled there).
* **Counterexample.** When the formula does not hold, `LtlResult` gives a run that
  violates it (and is fair) as a lasso of graph steps: ``prefix`` from node 0, then
  ``cycle`` repeated forever. A step is ``(source, transition, target)``; transition
  ``-1`` is a stutter step at a dead marking (``source == target``).

Method
------

The negated formula goes to Spot (``spot.translate(¬φ, "TGBA")``): a transition-based
generalized Büchi automaton. TGBA rather than a state-based Büchi automaton ("BA")
because it is usually smaller (BA degeneralizes, multiplying states by the number of
acceptance sets), so the product is smaller, and the cycle search below takes several
acceptance sets in its stride. Atoms become atomic propositions named ``a0``, ``a1``,
... by the formula constructors of Spot (no string parsing, so no precedence or
quoting issue); an atom that is constant over the whole graph is replaced by
``true``/``false`` first, so Spot can simplify it away.

The graph (`analysis.stategraph.StateGraph`) gets one stutter self-loop ("no
transition") at each dead node, so every node has a successor and every run is an
infinite path whose edges are the positions. Each atomic proposition is evaluated
once: state atoms per node (all `Compare` atoms in one pass over the markings),
`Fires` per transition. Nodes are then classed by their state-atom values and
transitions by their `Fires` values, so the valuation of an edge is one integer,
(class of its source, class of its transition), found with a few array gathers per
edge. Each automaton edge guard (a BDD) is evaluated once per valuation, vectorised
over all of them (one `numpy.where` per BDD node).

The product has nodes ``(graph node, automaton state)`` and an edge
``(s, q) -> (s', q')`` for each graph edge ``s -> s'`` and automaton edge ``q -> q'``
whose guard holds on the graph edge's valuation; the product edge carries the
automaton edge's acceptance marks. Only the part reachable from ``(0, initial
state)`` is kept. Its size is known before it is built (edges per valuation times
guards), and it is built one of two ways:

* at most `EAGER_PRODUCT_EDGES` edges in the *whole* product (reachable or not): all
  of it, one array operation per automaton edge, then cut to its reachable part with
  `forward_reach`;
* otherwise breadth first from the initial node, one vectorised step per layer (each
  layer's nodes times their graph edges times their automaton state's edges), so an
  automaton state that is only reachable early in a run (``X X p``) costs nothing
  later. Any accepting fair cycle in a part built so far is one of the whole product,
  so the part is searched once it has `FIRST_CHECK` edges and again each time that
  doubles: a violated formula usually stops after a fraction of the product. After
  `DEEP_LAYERS` layers (a long thin graph, where per-layer overhead dominates) it
  gives way to the first way if the whole product fits the budget.

A run violating the formula (and fair) exists iff the reachable product has a cycle
that visits every acceptance set of the automaton and is weakly fair. Both conditions
are *groups* for `fair_sccs` / `fair_lasso`: acceptance set ``k`` is a group enabled
at every node whose edges are the product edges marked ``k``; a fairness group is
lifted to the product with ``enabled_at`` read on the graph node (false at dead
nodes) and its edges the product edges over its graph edges (never a stutter step).
A strongly connected component admits such a cycle iff it is not trivial and each
group is disabled at one of its nodes or has an edge inside it; `fair_lasso` gives
the shortest prefix into one and a cycle through it covering every group, mapped back
to graph steps. (The prefix may hold stutter steps: the automaton may need a few
positions at a dead marking before its cycle.) An automaton with an empty language
(the formula is valid) or a product without edges stops before the search.

Budget: past ``max_product_edges`` reachable product edges the check stops with
`ProductTooLarge` (a `GraphError`: an inconclusive verdict for callers), unless the
part built already holds a counterexample, which is then the answer. Product arrays
are int32 (four per edge: source, target, graph edge, automaton edge); with the
strongly connected components (scipy) and the lasso search on top, the measured peak
is about 50 to 70 bytes per product edge on MCC graphs (16.8 M edges: 0.8 GB; 33 M:
2.2 GB) and up to about 120 on graphs with few edges per marking, where per-marking
arrays count. The default `DEFAULT_MAX_PRODUCT_EDGES` = 20 million is thus about 1 to
1.5 GB.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any, cast, overload

import numpy as np
import numpy.typing as npt
import spot
from spot import buddy

from analysis.budget import Budget, work_limit_reason
from analysis.ctl import NetIndex, StateEvaluator
from analysis.fairness import Group
from analysis.stategraph import (
    GraphError,
    Lasso,
    StateGraph,
    fair_lasso,
    fair_sccs,
    forward_reach,
)
from coral_lang.formula import (
    And,
    Compare,
    Const,
    Deadlock,
    Finally,
    Fireable,
    Fires,
    Formula,
    Globally,
    Next,
    Not,
    Or,
    Tokens,
    Until,
    children,
    ltl_body,
    walk,
)

IntArray = npt.NDArray[np.int64]
Index = npt.NDArray[np.integer[Any]]
"""Product arrays and edge classes: int32 where that suffices (half the memory)."""
BoolArray = npt.NDArray[np.bool_]
Step = tuple[int, int, int]
"""``(source node, transition index or -1 for a stutter step, target node)``."""

STUTTER = -1
"""The transition index of a stutter step at a dead marking."""

DEFAULT_MAX_PRODUCT_EDGES = 20_000_000
"""Reachable product edges `check_ltl` builds at most by default: 1 to 1.5 GB at the
50 to 70 bytes per edge measured at peak (module docstring)."""

EAGER_PRODUCT_EDGES = 4_000_000
"""Up to this many edges in the *whole* product (reachable or not), it is generated in
one go and then cut to its reachable part; above, breadth first from the initial
node."""

_CHUNK = 1 << 21
"""Most (product node, graph edge, automaton edge) candidates expanded at once."""


class LtlError(ValueError):
    """The formula cannot be checked on this net (not LTL, or an unknown name)."""


class NotLtlError(LtlError):
    """The formula has a path quantifier below its root: it is not LTL."""


class ProductTooLarge(GraphError):
    """The product of the graph and the automaton exceeds ``max_product_edges``."""


@dataclass(frozen=True)
class LtlResult:
    """The verdict of `check_ltl`.

    Attributes:
        formula: the formula checked (as given).
        holds: whether every (fair) run from the initial marking satisfies it.
        prefix: when it does not hold, steps from node 0 to the start of ``cycle``.
        cycle: steps repeated forever; ``prefix + cycle^ω`` violates the formula.
        product_states: nodes of the reachable product searched.
        product_edges: edges of the reachable product searched.
        automaton_states: states of Spot's automaton for the negated formula.
        seconds: wall time of the whole check.
    """

    formula: Formula
    holds: bool
    prefix: list[Step] = field(default_factory=list)
    cycle: list[Step] = field(default_factory=list)
    product_states: int = 0
    product_edges: int = 0
    automaton_states: int = 0
    seconds: float = 0.0


def check_ltl(
    graph: StateGraph,
    formula: Formula,
    *,
    fairness: Sequence[Group] = (),
    max_product_edges: int | None = DEFAULT_MAX_PRODUCT_EDGES,
    budget: Budget | None = None,
) -> LtlResult:
    """Whether every (weakly fair) run of ``graph`` from node 0 satisfies ``formula``.

    See the module docstring for the semantics (runs stutter at dead markings) and
    the method.

    Args:
        graph: the complete reachability graph.
        formula: ``A φ`` or ``φ`` with ``φ`` free of path quantifiers.
        fairness: weak-fairness groups over ``graph`` (``(enabled_at per node,
            in_group per edge)``, e.g. `analysis.fairness.fairness_groups`); only runs
            fair for all of them count.
        max_product_edges: refuse past this many reachable product edges (unless a
            counterexample turned up within them); ``None`` for no limit.
        budget: its clock times the check (``LtlResult.seconds``); its deadline and
            memory limit are checked before the product is built and between the
            layers of a large one (None: no limit).

    Raises:
        NotLtlError: ``formula`` is not LTL.
        LtlError: it names a place or transition the net does not have.
        ProductTooLarge: the edge budget ran out.
        BudgetExceeded: the deadline of ``budget`` passed, or the process is (or would
            be, with the product) over its memory limit; the reason says which.
    """
    budget = budget or Budget()
    start = budget.clock()
    body = ltl_body(formula)
    if body is None:
        raise NotLtlError(f"not an LTL formula (a path quantifier below the root): {formula}")
    ext = _Extended.of(graph)
    atoms = _atoms(body)
    columns = _evaluate_atoms(graph, atoms)
    # An atom with one value on every edge of the graph is that constant: Spot
    # simplifies it away (often the whole formula) before the product exists.
    present = np.zeros(len(graph.space.net.transitions) + 1, dtype=np.bool_)
    present[graph.labels + 1] = True
    present[0] = bool(ext.dead.size)
    constant: dict[Formula, bool] = {}
    names: dict[Formula, str] = {}
    for atom, (on_labels, column) in zip(atoms, columns, strict=True):
        seen = column[present] if on_labels else column
        if seen.all() or not seen.any():
            constant[atom] = bool(seen.any())
        else:
            names[atom] = f"a{len(names)}"
    negated = spot.formula.Not(_to_spot(body, names, constant))
    aut = spot.translate(negated, "TGBA")
    if not aut.acc().is_generalized_buchi():  # not expected of "TGBA"; be safe
        aut = spot.to_generalized_buchi(aut)
    n_aut = int(aut.num_states())

    def result(product: _Product | None = None, lasso: Lasso | None = None) -> LtlResult:
        prefix: list[Step] = []
        cycle: list[Step] = []
        if product is not None and lasso is not None:
            prefix = [ext.step(int(product.gedge[e])) for e in lasso.prefix]
            cycle = [ext.step(int(product.gedge[e])) for e in lasso.cycle]
        return LtlResult(
            formula,
            lasso is None,
            prefix,
            cycle,
            product.n_nodes if product else 0,
            int(product.src.size) if product else 0,
            n_aut,
            budget.clock() - start,
        )

    if aut.is_empty():  # ¬φ has no model at all: φ is valid
        return result()
    automaton = _Automaton.of(aut)
    by_name = {name: columns[atoms.index(atom)] for atom, name in names.items()}
    inv, values = _valuations(ext, [by_name[name] for name in automaton.ap_names])
    table = automaton.guard_table(values)
    per_value = np.bincount(inv, minlength=values.shape[0]).astype(np.int64)
    full = int((table[automaton.guard] @ per_value).sum())  # edges of the whole product
    search = _Search(ext, automaton, fairness, graph.dead)
    # The command's budget before the product grows: its deadline and, for the edges
    # about to be built (at most ``full``), its memory limit.
    budget.check()
    budget.check_memory(min(full, max_product_edges or full) * PRODUCT_BYTES_PER_EDGE)
    # Breadth first pays per layer: past `DEEP_LAYERS` of them it gives way to the
    # whole product when that fits the budget (a long thin graph, e.g. a counter).
    fits = max_product_edges is None or full <= max_product_edges
    layers = DEEP_LAYERS if fits else None
    layered = None
    if full > EAGER_PRODUCT_EDGES:
        layered = _layered_product(
            ext, automaton, table, inv, search, max_product_edges, layers, budget
        )
    if layered is not None:
        return result(*layered)
    product = _eager_product(ext, automaton, table, inv, full)
    lasso = search(product)  # the budget only stops a search that found nothing
    if lasso is None and max_product_edges is not None and product.src.size > max_product_edges:
        raise _too_large(product.src.size, max_product_edges)
    return result(product, lasso)


PRODUCT_BYTES_PER_EDGE = 32
"""Upper bound of a product edge's cost (source, target, graph edge and automaton edge
arrays, int64 at worst), asked of the memory budget before the product is built."""


def _too_large(edges: int, budget: int) -> ProductTooLarge:
    return ProductTooLarge(
        f"LTL product {work_limit_reason(budget, 'edge')} ({edges:,} edges built) and no"
        " counterexample among them"
    )


# -- the graph with stutter steps -----------------------------------------------------------


@dataclass(frozen=True)
class _Extended:
    """The graph's edges ``0 .. m-1`` followed by one stutter self-loop per dead node
    (edge ``m + k`` at ``dead[k]``, label -1), without copying the graph's arrays.

    ``first[s]``/``degree[s]`` give the edges of node ``s`` as a contiguous range (a
    dead node's range is its stutter loop)."""

    graph: StateGraph
    dead: IntArray
    first: IntArray
    degree: IntArray

    @staticmethod
    def of(graph: StateGraph) -> _Extended:
        dead = np.flatnonzero(graph.dead).astype(np.int64)
        first = graph.indptr[:-1].copy()
        degree = np.diff(graph.indptr)
        first[dead] = graph.n_edges + np.arange(dead.size, dtype=np.int64)
        degree[dead] = 1
        return _Extended(graph, dead, first, degree)

    @property
    def n_nodes(self) -> int:
        return self.graph.n_states

    @property
    def m(self) -> int:
        """Edges of the graph proper."""
        return self.graph.n_edges

    @property
    def n_edges(self) -> int:
        return self.m + int(self.dead.size)

    def _pick(self, edges: IntArray, real: IntArray, stutter: IntArray) -> IntArray:
        """``real[e]`` for graph edges, ``stutter[e - m]`` for stutter edges."""
        if not self.dead.size:
            return real[edges]
        if not self.m:
            return stutter[edges]
        out: IntArray = real[np.minimum(edges, self.m - 1)]
        loops = edges >= self.m
        out[loops] = stutter[edges[loops] - self.m]
        return out

    def src(self, edges: IntArray) -> IntArray:
        return self._pick(edges, self.graph.sources, self.dead)

    def dst(self, edges: IntArray) -> IntArray:
        return self._pick(edges, self.graph.targets, self.dead)

    def label_code(self, edges: IntArray) -> IntArray:
        """``label + 1`` of each edge (0 for a stutter step)."""
        out = np.zeros(edges.size, dtype=np.int64)
        real = edges < self.m
        out[real] = self.graph.labels[edges[real]] + 1
        return out

    def step(self, edge: int) -> Step:
        if edge < self.m:
            g = self.graph
            return (int(g.sources[edge]), int(g.labels[edge]), int(g.targets[edge]))
        node = int(self.dead[edge - self.m])
        return (node, STUTTER, node)


# -- atoms ----------------------------------------------------------------------------------


def _atoms(body: Formula) -> list[Formula]:
    """The distinct non-constant atoms of ``body``, in order of first occurrence."""
    seen: dict[Formula, None] = {}
    for node in walk(body):
        if isinstance(node, Compare | Fireable | Deadlock | Fires):
            seen.setdefault(node, None)
        elif not isinstance(node, Const | Not | And | Or | Next | Finally | Globally | Until):
            raise NotLtlError(f"not an LTL formula: unexpected {type(node).__name__} in {body}")
    return list(seen)


def _transition_indices(graph: StateGraph, names: Sequence[str]) -> list[int]:
    net = graph.space.net
    known = {t.name: i for i, t in enumerate(net.transitions)}
    missing = [n for n in names if n not in known]
    if missing:
        raise LtlError(f"unknown transition(s) {', '.join(missing)} in the formula")
    return [known[n] for n in names]


Column = tuple[bool, BoolArray]
"""An atom's values: ``(False, per node)`` for a state atom, ``(True, per label + 1)``
for `Fires` (index 0: the stutter step)."""


def _evaluate_atoms(graph: StateGraph, atoms: list[Formula]) -> list[Column]:
    """The value of each atom on each node (state atoms) or transition (`Fires`)."""
    net = graph.space.net
    places = {p.name: i for i, p in enumerate(net.places)}
    compares = [a for a in atoms if isinstance(a, Compare)]
    for cmp in compares:
        for side in (cmp.left, cmp.right):
            if isinstance(side, Tokens):
                missing = [p for p, _ in side.places if p not in places]
                if missing:
                    raise LtlError(f"unknown place(s) {', '.join(missing)} in the formula")
    on_nodes: dict[Formula, BoolArray] = {}
    if compares:
        values = np.zeros((len(compares), graph.n_states), dtype=np.bool_)

        index = NetIndex(net)
        # One pass over the markings for all comparisons (decoding is the cost).
        for first, block in graph.space.iter_markings():
            evaluator = StateEvaluator(index, block)
            for i, cmp in enumerate(compares):
                values[i, first : first + block.shape[0]] = evaluator.atom(cmp)
        on_nodes.update(zip(compares, values, strict=True))
    columns: list[Column] = []
    for atom in atoms:
        if isinstance(atom, Fires):
            on_labels = np.zeros(len(net.transitions) + 1, dtype=np.bool_)
            on_labels[np.asarray(_transition_indices(graph, atom.transitions)) + 1] = True
            columns.append((True, on_labels))
        elif isinstance(atom, Fireable):
            columns.append((False, graph.enabled(_transition_indices(graph, atom.transitions))))
        elif isinstance(atom, Deadlock):
            columns.append((False, graph.dead))
        else:
            columns.append((False, on_nodes[atom]))
    return columns


def _to_spot(body: Formula, names: dict[Formula, str], constant: dict[Formula, bool]) -> Any:
    """``body`` as a Spot formula built with Spot's constructors (iteratively: the MCC
    files nest deeply). Atoms map to ``names`` or to their ``constant`` value."""
    done: dict[int, Any] = {}
    stack: list[tuple[Formula, bool]] = [(body, False)]
    f = spot.formula
    while stack:
        node, expanded = stack.pop()
        if id(node) in done:
            continue
        if isinstance(node, Const):
            done[id(node)] = f.tt() if node.value else f.ff()
            continue
        if isinstance(node, Compare | Fireable | Deadlock | Fires):
            if node in constant:
                done[id(node)] = f.tt() if constant[node] else f.ff()
            else:
                done[id(node)] = f.ap(names[node])
            continue
        subs = children(node)
        if not expanded:
            stack.append((node, True))
            stack.extend((c, False) for c in subs)
            continue
        args = [done[id(c)] for c in subs]
        if isinstance(node, Not):
            done[id(node)] = f.Not(args[0])
        elif isinstance(node, And):
            done[id(node)] = f.And(args)
        elif isinstance(node, Or):
            done[id(node)] = f.Or(args)
        elif isinstance(node, Next):
            done[id(node)] = f.X(args[0])
        elif isinstance(node, Finally):
            done[id(node)] = f.F(args[0])
        elif isinstance(node, Globally):
            done[id(node)] = f.G(args[0])
        elif isinstance(node, Until):
            done[id(node)] = f.U(args[0], args[1])
        else:  # pragma: no cover - `_atoms` rejected everything else
            raise NotLtlError(f"not an LTL formula: {node}")
    return done[id(body)]


_DENSE = 1 << 24
"""Codes below this are numbered with a counting array, not a sort."""


def _dense(code: IntArray, bound: int) -> tuple[IntArray, IntArray]:
    """``(inv, rep)``: distinct values of ``code`` (all ``< bound``) numbered 0, 1, ...
    (``inv`` per element) and an element holding each."""
    if bound <= _DENSE:
        present = np.bincount(code, minlength=bound) > 0
        number = np.cumsum(present) - 1
        inv: IntArray = number[code]
    else:
        _, inv = np.unique(code, return_inverse=True)
        inv = inv.astype(np.int64).reshape(-1)
    rep = np.zeros(int(inv.max(initial=-1)) + 1, dtype=np.int64)
    rep[inv] = np.arange(inv.size, dtype=np.int64)
    return inv, rep


def _dense_rows(columns: list[BoolArray], size: int) -> tuple[IntArray, IntArray]:
    """Number the distinct rows of ``columns`` (each ``size`` booleans): ``(inv,
    rep)`` as in `_dense`."""
    code = np.zeros(size, dtype=np.int64)
    bound = 1
    for column in columns:
        if bound > 1 << 61:  # renumber densely before the code overflows
            code, rep = _dense(code, bound)
            bound = int(rep.size)
        code = code * 2 + column
        bound *= 2
    return _dense(code, bound)


_ROWS = 1 << 20
"""Most valuation rows (state classes times transition classes) used without first
numbering the ones that occur."""


def _valuations(ext: _Extended, columns: list[Column]) -> tuple[Index, BoolArray]:
    """``(inv, values)``: valuations of the edges of ``ext`` as rows
    ``values[row, column]``, and the row of each edge (not every row need occur).

    State atoms are classified per node and `Fires` atoms per transition first; the
    row of an edge is (class of its source, class of its transition): a few gathers
    per edge."""
    node_cols = [c for on_labels, c in columns if not on_labels]
    label_cols = [c for on_labels, c in columns if on_labels]
    node_inv, node_rep = _dense_rows(node_cols, ext.n_nodes)
    label_inv, label_rep = _dense_rows(label_cols, len(ext.graph.space.net.transitions) + 1)
    n_label = int(label_rep.size)
    rows = int(node_rep.size) * n_label
    if rows < 1 << 31:  # so are the codes below: store them in half the bytes
        node_inv, label_inv = node_inv.astype(np.int32), label_inv.astype(np.int32)
    g = ext.graph
    code: Index
    if n_label == 1:
        code = np.concatenate([node_inv[g.sources], node_inv[ext.dead]])
    else:
        code = np.concatenate(
            [
                node_inv[g.sources] * n_label + label_inv[g.labels + 1],
                node_inv[ext.dead] * n_label + label_inv[0],
            ]
        )
    if rows <= _ROWS:
        nodes = np.repeat(node_rep, n_label)
        labels = np.tile(label_rep, int(node_rep.size))
        inv = code
    else:  # too many combinations: number those that occur
        inv, rep = _dense(code.astype(np.int64), rows)
        nodes, labels = ext.src(rep), ext.label_code(rep)
    values = np.zeros((nodes.size, len(columns)), dtype=np.bool_)
    for j, (on_labels, column) in enumerate(columns):
        values[:, j] = column[labels] if on_labels else column[nodes]
    return inv, values


# -- the automaton --------------------------------------------------------------------------


@dataclass(frozen=True)
class _Automaton:
    """Spot's automaton as arrays: edges sorted by source state."""

    n_states: int
    init: int
    n_sets: int
    src: IntArray
    dst: IntArray
    guard: IntArray  # index into `guards`
    marks: BoolArray  # (edges, n_sets)
    first: IntArray  # edges of state q: first[q] : first[q] + degree[q]
    degree: IntArray
    guards: list[Any]  # distinct guard BDDs
    ap_names: list[str]
    var_column: dict[int, int]  # BDD variable -> column of the valuations

    @staticmethod
    def of(aut: Any) -> _Automaton:
        bdict = aut.get_dict()
        ap_names = [str(ap) for ap in aut.ap()]
        var_column = {int(bdict.varnum(ap)): j for j, ap in enumerate(aut.ap())}
        n_sets = int(aut.num_sets())
        guard_index: dict[int, int] = {}
        guards: list[Any] = []
        rows: list[tuple[int, int, int, list[int]]] = []
        for e in aut.edges():
            key = int(e.cond.id())
            if key not in guard_index:
                guard_index[key] = len(guards)
                guards.append(e.cond)
            rows.append((int(e.src), int(e.dst), guard_index[key], list(e.acc.sets())))
        rows.sort(key=lambda r: r[0])
        n = int(aut.num_states())
        marks = np.zeros((len(rows), n_sets), dtype=np.bool_)
        for i, row in enumerate(rows):
            marks[i, row[3]] = True
        src = np.asarray([r[0] for r in rows], dtype=np.int64)
        degree = np.bincount(src, minlength=n).astype(np.int64)
        first = np.zeros(n, dtype=np.int64)
        np.cumsum(degree[:-1], out=first[1:])
        return _Automaton(
            n,
            int(aut.get_init_state_number()),
            n_sets,
            src,
            np.asarray([r[1] for r in rows], dtype=np.int64),
            np.asarray([r[2] for r in rows], dtype=np.int64),
            marks,
            first,
            degree,
            guards,
            ap_names,
            var_column,
        )

    def guard_table(self, values: BoolArray) -> BoolArray:
        """``table[g, v]``: whether guard ``g`` holds on valuation row ``v``, each BDD
        node evaluated once over all rows."""
        memo: dict[int, BoolArray] = {
            int(buddy.bddtrue.id()): np.ones(values.shape[0], dtype=np.bool_),
            int(buddy.bddfalse.id()): np.zeros(values.shape[0], dtype=np.bool_),
        }
        table = np.zeros((len(self.guards), values.shape[0]), dtype=np.bool_)
        for g, root in enumerate(self.guards):
            stack = [root]
            while stack:
                node = stack[-1]
                if int(node.id()) in memo:
                    stack.pop()
                    continue
                high, low = buddy.bdd_high(node), buddy.bdd_low(node)
                pending = [b for b in (high, low) if int(b.id()) not in memo]
                if pending:
                    stack.extend(pending)
                    continue
                stack.pop()
                column = values[:, self.var_column[int(buddy.bdd_var(node))]]
                memo[int(node.id())] = np.where(column, memo[int(high.id())], memo[int(low.id())])
            table[g] = memo[int(root.id())]
        return table


# -- the product ----------------------------------------------------------------------------


@dataclass(frozen=True)
class _Product:
    """A product graph reachable from its node ``start``: node ``i`` pairs graph node
    ``graph_node[i]`` with an automaton state; each edge knows its edge of `_Extended`
    (``gedge``) and its automaton edge (``aedge``)."""

    n_nodes: int
    graph_node: IntArray
    start: int
    src: Index
    dst: Index
    gedge: Index
    aedge: Index


def _ranges(first: IntArray, count: IntArray) -> tuple[IntArray, IntArray]:
    """For ranges ``first[i] : first[i] + count[i]``: the owner ``i`` of each element
    and the element, all ranges concatenated."""
    total = int(count.sum())
    owner = np.repeat(np.arange(count.size, dtype=np.int64), count)
    starts = np.zeros(count.size, dtype=np.int64)
    np.cumsum(count[:-1], out=starts[1:])
    element = first[owner] + (np.arange(total, dtype=np.int64) - starts[owner])
    return owner, element


def _eager_product(
    ext: _Extended, aut: _Automaton, table: BoolArray, inv: Index, full: int
) -> _Product:
    """The whole product (``full`` edges) in one go, one array operation per automaton
    edge, then its part reachable from the initial node."""
    q = aut.n_states
    n = ext.n_nodes * q
    wide = np.int64 if n >= 1 << 31 else np.int32
    src = np.empty(full, dtype=wide)
    dst = np.empty(full, dtype=wide)
    gedge = np.empty(full, dtype=np.int64 if ext.n_edges >= 1 << 31 else np.int32)
    aedge = np.empty(full, dtype=np.int32)
    at = 0
    for g in range(len(aut.guards)):
        users = np.flatnonzero(aut.guard == g)
        sel = np.flatnonzero(table[g][inv])
        tail, head = ext.src(sel) * q, ext.dst(sel) * q
        for a in users:
            end = at + sel.size
            src[at:end] = tail + aut.src[a]
            dst[at:end] = head + aut.dst[a]
            gedge[at:end] = sel
            aedge[at:end] = a
            at = end
    assert at == full
    start = np.zeros(n, dtype=np.bool_)
    start[aut.init] = True  # (graph node 0, initial state)
    reached = forward_reach(n, cast(IntArray, src), cast(IntArray, dst), start)
    keep = reached[src]
    nodes = np.flatnonzero(reached)
    number = np.cumsum(reached, dtype=wide) - 1
    return _Product(
        int(nodes.size),
        nodes // q,
        int(number[aut.init]),
        number[src[keep]],
        number[dst[keep]],
        gedge[keep],
        aedge[keep],
    )


def _concat(arrays: list[IntArray]) -> IntArray:
    return np.concatenate(arrays) if arrays else np.zeros(0, dtype=np.int64)


class _Growing:
    """Integer columns that grow by appended pieces (capacity grows by half, so
    appending costs amortized constant time per element and reading them back costs
    nothing)."""

    def __init__(self, width: int, dtype: type[np.integer[Any]] = np.int64) -> None:
        self._data: Index = np.zeros((width, 1 << 10), dtype=dtype)
        self.size = 0

    def append(self, *pieces: npt.NDArray[np.integer[Any]]) -> None:
        n = int(pieces[0].size)
        if self.size + n > self._data.shape[1]:
            capacity = max(self.size + n, self._data.shape[1] * 3 // 2)
            grown = np.zeros((self._data.shape[0], capacity), dtype=self._data.dtype)
            grown[:, : self.size] = self._data[:, : self.size]
            self._data = grown
        for i, piece in enumerate(pieces):
            self._data[i, self.size : self.size + n] = piece
        self.size += n

    def column(self, i: int) -> Index:
        return self._data[i, : self.size]


DEEP_LAYERS = 2000
"""Layers after which the breadth-first construction stops in favour of the whole
product, if that fits the budget."""

FIRST_CHECK = 1 << 20
"""The layered construction looks for a counterexample in what it has built once it
has this many edges, then each time their number doubles (and at the budget)."""


def _layered_product(
    ext: _Extended,
    aut: _Automaton,
    table: BoolArray,
    inv: Index,
    search: _Search,
    max_edges: int | None,
    max_layers: int | None,
    budget: Budget,
) -> tuple[_Product, Lasso | None] | None:
    """The reachable product, breadth first from the initial node: each layer expands
    its nodes' graph edges times their automaton state's edges in array operations.

    Any fair accepting cycle of a part built so far is one of the whole product, so
    the part is searched from time to time (`FIRST_CHECK`) and a counterexample stops
    the construction early; ``max_edges`` stops only a search that found none. ``None``
    after ``max_layers`` layers (nothing found). Past the deadline of ``budget`` (checked
    once a layer) it raises `BudgetExceeded`."""
    q = aut.n_states
    if ext.n_nodes * q >= 1 << 31:
        raise ProductTooLarge(f"{ext.n_nodes} markings times {q} automaton states: too many")
    # Product node (s, state) is s * q + state; `number` holds its dense index, or -1.
    number = np.full(ext.n_nodes * q, -1, dtype=np.int32)
    number[aut.init] = 0
    nodes = _Growing(1)
    nodes.append(np.asarray([aut.init], dtype=np.int64))
    # Source, target, graph edge, automaton edge: int32 unless the graph is huge.
    edges = _Growing(4, np.int32 if ext.n_edges < 1 << 31 else np.int64)
    check_at = FIRST_CHECK

    def assemble() -> _Product:
        src, dst, gedge, aedge = (edges.column(i) for i in range(4))
        graph_node = cast(IntArray, nodes.column(0) // q)
        return _Product(nodes.size, graph_node, 0, src, dst, gedge, aedge)

    frontier = cast(IntArray, nodes.column(0).copy())
    layers = 0
    while frontier.size:
        layers += 1
        if max_layers is not None and layers > max_layers:
            return None
        budget.check()
        fresh: list[IntArray] = []
        for chunk in _chunks(frontier, ext, aut, q):
            s, state = chunk // q, chunk % q
            owner, edge = _ranges(ext.first[s], ext.degree[s])
            owner2, a = _ranges(aut.first[state[owner]], aut.degree[state[owner]])
            edge = edge[owner2]
            ok = table[aut.guard[a], inv[edge]]
            edge, a, owner2 = edge[ok], a[ok], owner2[ok]
            dst = ext.dst(edge) * q + aut.dst[a]
            new = np.unique(dst[number[dst] < 0])
            number[new] = np.arange(nodes.size, nodes.size + new.size, dtype=np.int32)
            nodes.append(new)
            fresh.append(new)
            edges.append(number[chunk[owner[owner2]]], number[dst], edge, a)
            if max_edges is not None and edges.size > max_edges:
                product = assemble()
                lasso = search(product)
                if lasso is None:
                    raise _too_large(edges.size, max_edges)
                return product, lasso
        frontier = _concat(fresh)
        if edges.size >= check_at and frontier.size:
            product = assemble()
            lasso = search(product)
            if lasso is not None:
                return product, lasso
            check_at = 2 * edges.size
    product = assemble()
    return product, search(product)


def _chunks(frontier: IntArray, ext: _Extended, aut: _Automaton, q: int) -> Iterator[IntArray]:
    """``frontier`` in pieces of at most about `_CHUNK` candidate product edges."""
    work = ext.degree[frontier // q] * aut.degree[frontier % q]
    bounds = np.searchsorted(np.cumsum(work), np.arange(_CHUNK, int(work.sum()), _CHUNK))
    for piece in np.split(frontier, np.unique(bounds)):
        if piece.size:
            yield piece


class _Search:
    """Looks for a fair accepting cycle in a product: `fair_sccs` then `fair_lasso`."""

    def __init__(
        self, ext: _Extended, aut: _Automaton, fairness: Sequence[Group], dead: BoolArray
    ) -> None:
        self._ext, self._aut, self._fairness = ext, aut, fairness
        self._live = ~dead

    def __call__(self, product: _Product) -> Lasso | None:
        if not product.src.size:
            return None
        groups = _LiftedGroups(product, self._aut, self._ext, self._fairness, self._live)
        # The algorithms take any integer arrays; the product's are int32 to save room.
        src, dst = cast(IntArray, product.src), cast(IntArray, product.dst)
        comp, fair = fair_sccs(product.n_nodes, src, dst, groups)
        if not fair.any():
            return None
        start = np.zeros(product.n_nodes, dtype=np.bool_)
        start[product.start] = True
        lasso = fair_lasso(product.n_nodes, src, dst, start, comp, fair, groups)
        assert lasso is not None, "every product node is reachable from the start"
        return lasso


class _LiftedGroups(Sequence[Group]):
    """The groups `fair_sccs` needs on the product, built one at a time when asked for
    (a mission has a fairness group per transition): first one per acceptance set
    (enabled everywhere, owning the edges that carry the mark), then each fairness
    group lifted from the graph (enabled where its graph node is, owning the product
    edges over its graph edges)."""

    def __init__(
        self,
        product: _Product,
        aut: _Automaton,
        ext: _Extended,
        fairness: Sequence[Group],
        live: BoolArray,
    ) -> None:
        self._product = product
        self._aut = aut
        self._fairness = fairness
        self._live = live
        self._everywhere = np.ones(product.n_nodes, dtype=np.bool_)
        # Stutter steps belong to no group.
        self._real = product.gedge < ext.m
        self._clipped = np.minimum(product.gedge, max(ext.m - 1, 0))

    def __len__(self) -> int:
        return self._aut.n_sets + len(self._fairness)

    @overload
    def __getitem__(self, i: int) -> Group: ...

    @overload
    def __getitem__(self, i: slice) -> Sequence[Group]: ...

    def __getitem__(self, i: int | slice) -> Group | Sequence[Group]:
        if isinstance(i, slice):
            return [self[j] for j in range(len(self))[i]]
        if i < 0:
            i += len(self)
        if not 0 <= i < len(self):
            raise IndexError(i)
        p = self._product
        if i < self._aut.n_sets:
            return self._everywhere, self._aut.marks[p.aedge, i]
        enabled_at, in_group = self._fairness[i - self._aut.n_sets]
        # Nothing is enabled at a dead marking: a run stuttering there is fair.
        lifted_edges = in_group[self._clipped] & self._real if in_group.size else self._real & False
        return (enabled_at & self._live)[p.graph_node], lifted_edges

    def __iter__(self) -> Iterator[Group]:
        for i in range(len(self)):
            yield self[i]
