"""CTL model checking on a complete reachability graph, one satisfaction set per
sub-formula.

`CtlChecker` labels every node of a `StateGraph` with every sub-formula of a CTL
formula, bottom up (the classic algorithm of Clarke, Emerson and Sistla): a
satisfaction set is a numpy boolean array over the nodes, and each operator is a few
array operations or one graph search in C (scipy):

* atoms (`Compare`, `Fireable`, `Deadlock`, `Const`) on a compact table of all markings
  (`StateEvaluator`); ``not``/``and``/``or`` element-wise;
* ``EX s``: the sources of the edges whose target is in ``s``; ``AX s = not EX not s``;
* ``E[a U b]``, ``EF b``: backward breadth-first search from ``b`` through the nodes of
  ``a`` (a reversed copy of the edges, filtered, with one extra root row);
* ``EG a``: the strongly connected components of the graph restricted to ``a``; the
  nodes of ``a`` that reach, inside ``a``, a component with a cycle or a dead node;
* ``AF``, ``AG``, ``A[a U b]`` by the dualities
  ``AF b = not EG not b``, ``AG a = not EF not a``,
  ``A[a U b] = not (E[not b U (not a and not b)] or EG not b)``.

Dead markings (no transition enabled) follow the MCC consensus for CTL, checked
against TAPAAL's verifypn and the contest's answers (``docs/verify.md``, "Model
Checking Contest queries"): paths are *maximal*, so a path may end in a dead marking
and is not extended there. Hence at a dead marking ``EX s`` is false and ``AX s`` is
true for every ``s`` (there is no next state), ``EG a`` holds where ``a`` does (the
path that stops there stays in ``a``), and ``AF b`` needs ``b`` before the path ends.
(LTL is different: there a run that reaches a dead marking repeats it forever.)

Sub-formulas are interned structurally (iteratively: no recursion however deeply a
formula nests), so a sub-formula that occurs twice, in one formula or in several
formulas checked with the same `CtlChecker`, is computed once.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import numpy.typing as npt
import scipy.sparse as sp
from scipy.sparse import csgraph

from analysis.budget import Budget, BudgetExceeded
from analysis.stategraph import StateGraph
from analysis.statespace import StateSpace
from coral_lang.formula import (
    ATOMS,
    All,
    And,
    Compare,
    Const,
    Deadlock,
    Exists,
    Finally,
    Fireable,
    Fires,
    Formula,
    Globally,
    IntConst,
    Next,
    Not,
    Or,
    Tokens,
    Until,
    children,
    is_ctl,
)
from coral_lang.net import Net, TransitionKind

__all__ = [
    "CtlChecker",
    "CtlError",
    "NetIndex",
    "StateEvaluator",
    "marking_table",
]

BoolArray = npt.NDArray[np.bool_]
IntArray = npt.NDArray[np.int64]

CACHE_CELLS = 1 << 28
"""Most booleans the sub-formula cache of a `CtlChecker` keeps (256 MB); past it, it
starts afresh with the next formula."""


class CtlError(ValueError):
    """The formula is not CTL, or names a place or transition the net lacks."""


class NetIndex:
    """Place and transition numbers and presets of a net, for evaluating atoms."""

    def __init__(self, net: Net) -> None:
        self.net = net
        self.place = {p.name: i for i, p in enumerate(net.places)}
        self.transition = {t.name: i for i, t in enumerate(net.transitions)}
        self.operator = [t.kind is TransitionKind.INPUT for t in net.transitions]
        self.presets: list[tuple[IntArray, IntArray]] = []
        for t in net.transitions:
            cols = np.asarray([self.place[p] for p, _ in t.inputs], dtype=np.int64)
            weights = np.asarray([w for _, w in t.inputs], dtype=np.int64)
            self.presets.append((cols, weights))

    def places_of(self, expr: Tokens) -> tuple[IntArray, IntArray]:
        """Columns and weights of a `Tokens` sum."""
        try:
            cols = [self.place[p] for p, _ in expr.places]
        except KeyError as exc:
            raise CtlError(f"unknown place {exc.args[0]!r}") from None
        weights = [w for _, w in expr.places]
        return np.asarray(cols, dtype=np.int64), np.asarray(weights, dtype=np.int64)

    def transitions_of(self, names: Sequence[str]) -> list[int]:
        """Transition numbers of ``names``."""
        try:
            return [self.transition[t] for t in names]
        except KeyError as exc:
            raise CtlError(f"unknown transition {exc.args[0]!r}") from None


def marking_table(space: StateSpace) -> npt.NDArray[np.integer]:
    """Every stored marking as a ``(states, places)`` matrix of the narrowest unsigned
    type that holds the largest count (one byte per place on safe nets)."""
    top = int(space.place_bounds.max(initial=0))
    dtype: type[np.integer]
    for dtype in (np.uint8, np.uint16, np.uint32):
        if top <= np.iinfo(dtype).max:
            break
    else:
        dtype = np.int64
    table = np.empty((space.states, len(space.net.places)), dtype=dtype)
    for start, block in space.iter_markings():
        table[start : start + block.shape[0]] = block
    return table


class StateEvaluator:
    """Truth of state formulas (no temporal operator) on a block of markings.

    Args:
        index: the net's `NetIndex`.
        markings: ``(n, places)`` token counts.
        dead: which of the ``n`` markings enable no transition, if known (else
            computed from the presets when a `Deadlock` atom asks).
    """

    def __init__(
        self,
        index: NetIndex,
        markings: npt.NDArray[np.integer],
        dead: BoolArray | None = None,
    ) -> None:
        self.index = index
        self.markings = markings
        self.n = int(markings.shape[0])
        self._dead = dead
        self._enabled: dict[int, BoolArray] = {}
        self._atoms: dict[Formula, BoolArray] = {}

    def enabled(self, t: int) -> BoolArray:
        """Markings where transition ``t`` may fire: its preset is covered (and, for an
        operator input, the run is on there: the marking is not dead)."""
        hit = self._preset_holds(t)
        if self.index.operator[t]:
            hit = hit & ~self.dead
        return hit

    def _preset_holds(self, t: int) -> BoolArray:
        """Markings that cover the preset of transition ``t``."""
        hit = self._enabled.get(t)
        if hit is None:
            cols, weights = self.index.presets[t]
            hit = np.ones(self.n, dtype=np.bool_)
            for c, w in zip(cols.tolist(), weights.tolist(), strict=True):
                hit &= self.markings[:, c] >= w
            self._enabled[t] = hit
        return hit

    @property
    def dead(self) -> BoolArray:
        """Markings that enable no transition (on a net with operator inputs: no
        transition but inputs, see `analysis.inputs`)."""
        if self._dead is None:
            live = np.zeros(self.n, dtype=np.bool_)
            for t in range(len(self.index.presets)):
                if not self.index.operator[t]:
                    live |= self._preset_holds(t)
            self._dead = ~live
        return self._dead

    def integer(self, expr: Tokens | IntConst) -> IntArray | int:
        """Value of an integer expression per marking (a constant stays a scalar)."""
        if isinstance(expr, IntConst):
            return expr.value
        cols, weights = self.index.places_of(expr)
        if cols.size == 1 and weights[0] == 1:
            return self.markings[:, int(cols[0])].astype(np.int64)
        block = self.markings[:, cols].astype(np.int64)
        total: IntArray = block @ weights if cols.size else np.zeros(self.n, dtype=np.int64)
        return total

    def atom(self, f: Formula) -> BoolArray:
        """Satisfaction set of an atom."""
        hit = self._atoms.get(f)
        if hit is not None:
            return hit
        if isinstance(f, Const):
            hit = np.full(self.n, f.value, dtype=np.bool_)
        elif isinstance(f, Compare):
            hit = _compare(self.integer(f.left), f.op, self.integer(f.right), self.n)
        elif isinstance(f, Fireable):
            hit = np.zeros(self.n, dtype=np.bool_)
            for t in self.index.transitions_of(f.transitions):
                hit |= self.enabled(t)
        elif isinstance(f, Deadlock):
            hit = self.dead
        else:
            raise CtlError(f"{type(f).__name__} is not a state atom")
        self._atoms[f] = hit
        return hit

    def sat(self, f: Formula) -> BoolArray:
        """Satisfaction set of a state formula (iterative; atoms cached)."""
        values: dict[int, BoolArray] = {}
        for node, kids in _postorder(f):
            values[id(node)] = self._combine(node, [values[k] for k in kids])
        return values[id(f)]

    def _combine(self, node: Formula, args: list[BoolArray]) -> BoolArray:
        if isinstance(node, ATOMS):
            return self.atom(node)
        if isinstance(node, Not):
            return ~args[0]
        if isinstance(node, And):
            return _fold(np.logical_and, args, True, self.n)
        if isinstance(node, Or):
            return _fold(np.logical_or, args, False, self.n)
        raise CtlError(f"{type(node).__name__} is not a state-formula operator")


def _postorder(f: Formula) -> list[tuple[Formula, list[int]]]:
    """Each node of ``f`` once (by identity), children first, with its children's
    ``id``s."""
    out: list[tuple[Formula, list[int]]] = []
    seen: set[int] = set()
    stack: list[tuple[Formula, bool]] = [(f, False)]
    while stack:
        node, ready = stack.pop()
        if id(node) in seen:
            continue
        kids = children(node)
        if not ready:
            stack.append((node, True))
            stack.extend((c, False) for c in reversed(kids) if id(c) not in seen)
            continue
        seen.add(id(node))
        out.append((node, [id(c) for c in kids]))
    return out


_COMPARE: dict[str, np.ufunc] = {
    "<=": np.less_equal,
    "<": np.less,
    ">=": np.greater_equal,
    ">": np.greater,
    "==": np.equal,
    "!=": np.not_equal,
}


def _compare(left: IntArray | int, op: str, right: IntArray | int, n: int) -> BoolArray:
    result = np.asarray(_COMPARE[op](left, right), dtype=np.bool_)
    if result.ndim == 0:
        return np.full(n, bool(result), dtype=np.bool_)
    return result


def _fold(op: np.ufunc, args: list[BoolArray], empty: bool, n: int) -> BoolArray:
    if not args:
        return np.full(n, empty, dtype=np.bool_)
    out = args[0].copy()
    for a in args[1:]:
        op(out, a, out=out)
    return out


@dataclass
class _Node:
    formula: Formula
    kids: tuple[int, ...]


class CtlChecker:
    """Labels the nodes of a complete `StateGraph` with CTL formulas.

    Args:
        graph: the reachability graph (node 0 is the initial marking).
        markings: the `marking_table` of ``graph.space``, if already built.
        index: the net's `NetIndex`, if already built.
        budget: its deadline stops labelling with `analysis.budget.BudgetExceeded` (the
            formula stays undecided); None: no limit.
    """

    def __init__(
        self,
        graph: StateGraph,
        *,
        markings: npt.NDArray[np.integer] | None = None,
        index: NetIndex | None = None,
        budget: Budget | None = None,
    ) -> None:
        self.graph = graph
        self.n = graph.n_states
        self.index = index or NetIndex(graph.space.net)
        table = marking_table(graph.space) if markings is None else markings
        self.states = StateEvaluator(self.index, table, graph.dead)
        self.budget = budget
        self._keys: dict[object, int] = {}
        self._nodes: list[_Node] = []
        self._values: list[BoolArray | None] = []

    # -- graph arrays, built on first use ---------------------------------------------
    #
    # Every operator works on the *distinct* (source, target) pairs: parallel edges
    # (two transitions with one effect) change no satisfaction set, and scipy's strongly
    # connected components slow down badly on rows with repeated entries (Dekker-PT-015:
    # 16.8 million edges, 4.2 million distinct pairs; minutes instead of 0.1 s).

    @cached_property
    def _index_type(self) -> type[np.signedinteger]:
        """scipy's graph routines take ``int32`` indices; anything else is copied."""
        small = self.graph.n_edges + self.n + 1 < np.iinfo(np.int32).max
        return np.int32 if small else np.int64

    @cached_property
    def _edges(self) -> tuple[IntArray, npt.NDArray[np.signedinteger], IntArray]:
        """``(src, dst, indptr)``: the distinct edges, by source then target, with the
        row pointers of the forward adjacency."""
        graph, it = self.graph, self._index_type
        matrix = sp.csr_matrix(
            (np.ones(graph.n_edges, dtype=np.int8), graph.targets.astype(it), graph.indptr),
            shape=(self.n, self.n),
        )
        matrix.sum_duplicates()
        indptr = matrix.indptr.astype(np.int64)
        src = np.repeat(np.arange(self.n, dtype=np.int64), np.diff(indptr))
        return src, matrix.indices.astype(it, copy=False), indptr

    @cached_property
    def _ones(self) -> npt.NDArray[np.float64]:
        """Edge weights for scipy (which works in ``float64``), sliced per matrix."""
        return np.ones(self._edges[0].size + self.n + 1, dtype=np.float64)

    @cached_property
    def _reverse(self) -> tuple[IntArray, npt.NDArray[np.signedinteger]]:
        """Predecessor lists: ``indices[indptr[t]:indptr[t + 1]]`` are the sources of
        the edges into ``t``."""
        src, dst, _ = self._edges
        order = np.argsort(dst, kind="stable")
        indptr = np.zeros(self.n + 1, dtype=np.int64)
        np.cumsum(np.bincount(dst, minlength=self.n), out=indptr[1:])
        return indptr, src[order].astype(self._index_type)

    def _matrix(
        self, indptr: IntArray, indices: npt.NDArray[np.signedinteger], rows: int
    ) -> sp.csr_matrix:
        """A ``rows`` x ``rows`` CSR matrix over the given arrays, built without copies."""
        return sp.csr_matrix(
            (self._ones[: indices.size], indices, indptr.astype(self._index_type)),
            shape=(rows, rows),
            copy=False,
        )

    @cached_property
    def _loops(self) -> IntArray:
        """Nodes with a self-loop edge (a firing that changes nothing)."""
        src, dst, _ = self._edges
        loops: IntArray = src[src == dst]
        return loops

    # -- public ----------------------------------------------------------------------

    def holds(self, f: Formula) -> bool:
        """Whether the initial marking satisfies ``f``."""
        return bool(self.sat(f)[0])

    def sat(self, f: Formula) -> BoolArray:
        """The nodes that satisfy the CTL formula ``f``.

        Raises:
            CtlError: ``f`` is not CTL, or names an unknown place or transition.
            BudgetExceeded: the budget's deadline passed.
        """
        if not is_ctl(f):
            raise CtlError("not a CTL formula: a temporal operator is not directly under A or E")
        if len(self._values) * self.n > CACHE_CELLS:
            self._keys.clear()
            self._nodes.clear()
            self._values.clear()
        order = self._intern(f)
        for k in order:
            if self._values[k] is None and not isinstance(
                self._nodes[k].formula, Next | Finally | Globally | Until
            ):
                self._values[k] = self._label(self._nodes[k])
                self._check_time()
        value = self._values[order[-1]]
        assert value is not None
        return value

    # -- interning -------------------------------------------------------------------

    def _intern(self, f: Formula) -> list[int]:
        """Number every distinct sub-formula of ``f``; their numbers, children first
        (``f`` last)."""
        ids: dict[int, int] = {}
        order: list[int] = []
        stack: list[tuple[Formula, bool]] = [(f, False)]
        while stack:
            node, ready = stack.pop()
            if id(node) in ids:
                continue
            kids = children(node)
            if not ready:
                stack.append((node, True))
                stack.extend((c, False) for c in reversed(kids) if id(c) not in ids)
                continue
            numbers = tuple(ids[id(c)] for c in kids)
            key: object = node if isinstance(node, ATOMS) else (type(node), numbers)
            number = self._keys.get(key)
            if number is None:
                number = len(self._nodes)
                self._keys[key] = number
                self._nodes.append(_Node(node, numbers))
                self._values.append(None)
            ids[id(node)] = number
            order.append(number)
        return order

    def _check_time(self) -> None:
        if self.budget is not None and self.budget.expired():
            raise BudgetExceeded(f"labelling stopped: {self.budget.time_reason()}")

    # -- labelling -------------------------------------------------------------------

    def _value(self, k: int) -> BoolArray:
        value = self._values[k]
        assert value is not None
        return value

    def _label(self, node: _Node) -> BoolArray:
        f = node.formula
        if isinstance(f, Fires):
            raise CtlError("fires(...) is an LTL event atom, not a CTL state formula")
        if isinstance(f, ATOMS):
            return self.states.atom(f)
        args = [self._value(k) for k in node.kids] if not isinstance(f, All | Exists) else []
        if isinstance(f, Not):
            return ~args[0]
        if isinstance(f, And):
            return _fold(np.logical_and, args, True, self.n)
        if isinstance(f, Or):
            return _fold(np.logical_or, args, False, self.n)
        assert isinstance(f, All | Exists)
        path = self._nodes[node.kids[0]]
        ops = [self._value(k) for k in path.kids]
        universal = isinstance(f, All)
        p = path.formula
        if isinstance(p, Next):
            return ~self.ex(~ops[0]) if universal else self.ex(ops[0])
        if isinstance(p, Finally):
            return ~self.eg(~ops[0]) if universal else self.eu(None, ops[0])
        if isinstance(p, Globally):
            return ~self.eu(None, ~ops[0]) if universal else self.eg(ops[0])
        assert isinstance(p, Until)
        a, b = ops
        if not universal:
            return self.eu(a, b)
        not_b = ~b
        return ~(self.eu(not_b, ~a & not_b) | self.eg(not_b))

    # -- the three primitive operators -----------------------------------------------

    def ex(self, s: BoolArray) -> BoolArray:
        """Nodes with a successor in ``s`` (none for a dead node)."""
        src, dst, _ = self._edges
        out = np.zeros(self.n, dtype=np.bool_)
        out[src[s[dst]]] = True
        return out

    def eu(self, a: BoolArray | None, b: BoolArray) -> BoolArray:
        """``E[a U b]``: nodes with a path through ``a`` into ``b`` (``a`` ``None``:
        any path, i.e. ``EF b``)."""
        if not b.any() or b.all():
            return b.copy()
        if a is not None and not (a & ~b).any():
            return b.copy()
        indptr, indices = self._reverse
        if a is not None:
            keep = a[indices]
            kept = np.zeros(indices.size + 1, dtype=np.int64)
            np.cumsum(keep, out=kept[1:])
            indptr = kept[indptr]
            indices = indices[keep]
        return self._reach(indptr, indices, b)

    def eg(self, a: BoolArray) -> BoolArray:
        """``EG a``: nodes of ``a`` with a maximal path inside ``a``: one that reaches a
        cycle of ``a`` nodes, or a dead node of ``a``."""
        if not a.any():
            return a.copy()
        src, dst, indptr = self._edges
        keep = a[src] & a[dst]
        kept = np.zeros(keep.size + 1, dtype=np.int64)
        np.cumsum(keep, out=kept[1:])
        sub = self._matrix(kept[indptr], dst[keep], self.n)
        _, comp = csgraph.connected_components(sub, directed=True, connection="strong")
        sizes = np.bincount(comp, minlength=int(comp.max(initial=-1)) + 1)
        cyclic = sizes > 1
        loops = self._loops[a[self._loops]]
        cyclic[comp[loops]] = True
        goal = a & (cyclic[comp] | self.graph.dead)
        return self.eu(a, goal)

    def _reach(
        self, indptr: IntArray, indices: npt.NDArray[np.signedinteger], goal: BoolArray
    ) -> BoolArray:
        """Nodes from which ``goal`` is reached along the (reversed) rows given: one
        breadth-first search from an extra root whose row lists the goal nodes."""
        seeds = np.flatnonzero(goal).astype(indices.dtype)
        full_indptr = np.append(indptr, indptr[-1] + seeds.size)
        full_indices = np.concatenate([indices, seeds])
        matrix = self._matrix(full_indptr, full_indices, self.n + 1)
        order = csgraph.breadth_first_order(
            matrix, self.n, directed=True, return_predecessors=False
        )
        out = np.zeros(self.n, dtype=np.bool_)
        out[order[order < self.n]] = True
        return out
