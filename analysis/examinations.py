"""Model Checking Contest examinations on one P/T net, with exact answers or none.

A `QuerySession` holds one net and everything computed about it (the state space,
the table of markings, the reachability graph, the CTL labels), so the formulas of a
run share them: each is computed at most once, and only when some formula needs it.
How a formula is decided:

* a formula without temporal operator: on the initial marking (``INITIAL_STATE``);
* ``AG φ`` / ``EF φ`` (also negated) with ``φ`` a state formula: a breadth-first
  search that stops as soon as every pending formula of the run has met a marking
  deciding it (`analysis.statespace.explore` with ``stop_when``); the first such
  marking has a shortest trace, given as witness or counterexample. With a complete
  state space already built, a scan of its markings;
* any other CTL formula: `analysis.ctl.CtlChecker` on the reachability graph;
* LTL (``A φ``, ``φ`` without path quantifier): `analysis.ltl.check_ltl`;
* UpperBounds: the largest sum over the stored markings, exact on a complete state
  space; on an incomplete one, exact only when it meets a bound proven by a
  P-invariant (``TOPOLOGICAL``);
* the global examinations (`GLOBAL_EXAMINATIONS`): ReachabilityDeadlock (the
  full search, then, if its budget stops it, a deadlock-preserving stubborn-set one),
  QuasiLiveness (every transition enabled somewhere), Liveness (every transition
  enabled somewhere in every bottom strongly connected component of the graph: from
  every reachable marking it can fire again), OneSafe (no place above one token, or
  every place bounded by one by a P-invariant), StableMarking (some place keeps one
  count in every reachable marking).

Limits (`QueryLimits`): states, seconds for the whole session (one
`analysis.budget.Budget`), graph edges and LTL product edges. When one runs out, the
formulas it leaves undecided get ``value=None`` (``CANNOT_COMPUTE``); an answer is never
guessed. Partial results are used only
where they are proofs: a marking found in an incomplete search decides ``EF``/``AG``;
a deadlock found proves ReachabilityDeadlock and refutes Liveness.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from analysis import budget as budgets
from analysis.budget import BudgetExceeded, Clock, memory_limit_reason
from analysis.ctl import CtlChecker, CtlError, NetIndex, StateEvaluator, marking_table
from analysis.mccxml import MccProperty, PlaceBound
from analysis.stategraph import GraphError, StateGraph, build_graph, scc_labels
from analysis.statespace import STOPPED_BY_REQUEST, StateSpace, explore
from analysis.symbolic.report import AUTO_SYMBOLIC_MIN_STATES, symbolic_applicable
from coral_lang.formula import (
    All,
    Exists,
    Finally,
    Formula,
    Globally,
    Not,
    is_ctl,
    is_state_formula,
    ltl_body,
    places_of,
    transitions_of,
)
from coral_lang.net import Net

if TYPE_CHECKING:
    from analysis.symbolic.explore import SymbolicResult

__all__ = [
    "EXAMINATIONS",
    "GLOBAL_EXAMINATIONS",
    "QUERY_EXAMINATIONS",
    "Answer",
    "QueryLimits",
    "QuerySession",
    "examination_of",
]

QUERY_EXAMINATIONS = (
    "ReachabilityCardinality",
    "ReachabilityFireability",
    "CTLCardinality",
    "CTLFireability",
    "LTLCardinality",
    "LTLFireability",
    "UpperBounds",
)
GLOBAL_EXAMINATIONS = (
    "ReachabilityDeadlock",
    "QuasiLiveness",
    "Liveness",
    "OneSafe",
    "StableMarking",
)
EXAMINATIONS = QUERY_EXAMINATIONS + GLOBAL_EXAMINATIONS

EXPLICIT = ("EXPLICIT", "STATE_COMPRESSION")
REDUCED = ("STRUCTURAL_REDUCTION", *EXPLICIT)
"""Techniques of an answer read on the structurally reduced net (`analysis.reduce`)."""
SYMBOLIC = ("DECISION_DIAGRAMS",)

STATE_EQUATION_SECONDS = 60.0
"""Most seconds the z3 proof of deadlock freedom may take when a search gave up."""

INVARIANT_SECONDS = 10.0
"""Most seconds the P-invariants behind OneSafe and UpperBounds may take."""

STATE_EQUATION_SECONDS_PER_ARC = 2e-4
"""What building the state equation costs per arc, with a margin (z3's Python API:
about 100 us an arc measured on generated rings of 4,000-20,000 arcs): the proof is
not tried when this times the arcs exceeds the time left."""
"""Technique words (the MCC's) of answers read off the explicit state space."""

DEFAULT_MAX_STATES = 5_000_000
DEFAULT_MAX_EDGES = 50_000_000
"""Graph edges allowed (12 bytes each in the graph, about 28 more for CTL's arrays)."""
DEFAULT_MAX_PRODUCT_EDGES = 25_000_000
TABLE_CELLS = 1 << 27
"""Largest ``states x places`` kept as a table of markings (one byte per cell on most
nets); larger state spaces are read block by block from their packed keys."""

BoolArray = npt.NDArray[np.bool_]


def examination_of(prop: MccProperty) -> str | None:
    """The examination a property belongs to: the file name (``<Examination>.xml`` as
    the MCC lays it out, or ``<Instance>.<Examination>.xml``), else its id."""
    stem = prop.file.replace("\\", "/").rsplit("/", 1)[-1]
    parts = stem.split(".")
    for name in QUERY_EXAMINATIONS:
        if name in parts[:-1] or f"-{name}-" in prop.id:
            return name
    return None


@dataclass(frozen=True)
class QueryLimits:
    """Limits of one session; ``None`` is no limit (the session turns them into one
    `analysis.budget.Budget`, shared by every search and formula).

    Attributes:
        max_states: markings stored by a search.
        time_limit: seconds for the whole session (searches, graph, every formula).
        max_edges: edges of the reachability graph (CTL, LTL, Liveness).
        max_product_edges: reachable edges of one LTL product.
        reductions: whether ReachabilityDeadlock is tried on the structurally reduced
            net first, and reachability and bounds formulas the full search leaves
            undecided after it (`analysis.reduce`).
        memory_limit: bytes of resident memory the process may use (checked by every
            search, the graph, the LTL product and CTL labelling through the budget).
        method: "explicit", "symbolic" (ReachabilityDeadlock and the state count from a
            decision diagram, `analysis.symbolic`) or "auto" (explicit, then symbolic
            when the explicit searches stop before deciding).
    """

    max_states: int | None = DEFAULT_MAX_STATES
    time_limit: float | None = None
    max_edges: int | None = DEFAULT_MAX_EDGES
    max_product_edges: int | None = DEFAULT_MAX_PRODUCT_EDGES
    reductions: bool = True
    memory_limit: int | None = None
    method: str = "auto"


@dataclass(frozen=True)
class Answer:
    """The answer to one formula (or one global examination).

    Attributes:
        id: the formula id (for a global examination, its name).
        value: ``True``/``False``, an integer for UpperBounds, ``None`` when it could
            not be computed (``reason`` says why).
        techniques: MCC technique words.
        seconds: time spent on this formula alone (shared work such as the state
            space is in `QuerySession.shared_seconds`).
        method: how it was decided (``initial``, ``reachability``, ``ctl``, ``ltl``,
            ``bound``, ``global``).
        trace: transition names from the initial marking: a witness when the answer
            is TRUE (or the bound), a counterexample when it is FALSE; ``None`` if
            there is none.
        cycle: for an LTL counterexample, transitions repeated forever after
            ``trace`` (empty: the run ends in a dead marking and stays there).
        reason: why there is no value, or a detail of the answer.
        examination: the examination, when known.
    """

    id: str
    value: bool | int | None
    techniques: tuple[str, ...] = ()
    seconds: float = 0.0
    method: str = ""
    trace: tuple[str, ...] | None = None
    cycle: tuple[str, ...] | None = None
    reason: str | None = None
    examination: str | None = None

    @property
    def computed(self) -> bool:
        """Whether there is a value."""
        return self.value is not None

    @property
    def trace_kind(self) -> str | None:
        """``witness`` or ``counterexample`` (``None`` without a trace)."""
        if self.trace is None:
            return None
        return "counterexample" if self.value is False else "witness"

    def mcc_line(self) -> str:
        """``FORMULA <id> TRUE|FALSE|<n> TECHNIQUES ...`` or ``... CANNOT_COMPUTE``."""
        if self.value is None:
            return f"FORMULA {self.id} CANNOT_COMPUTE"
        if isinstance(self.value, bool):
            text = "TRUE" if self.value else "FALSE"
        else:
            text = str(self.value)
        return f"FORMULA {self.id} {text} TECHNIQUES {' '.join(self.techniques)}".rstrip()

    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly form."""
        return {
            "id": self.id,
            "examination": self.examination,
            "answer": self.value,
            "status": "answered" if self.computed else "cannot_compute",
            "techniques": list(self.techniques),
            "method": self.method,
            "seconds": round(self.seconds, 6),
            "trace_kind": self.trace_kind,
            "trace": None if self.trace is None else list(self.trace),
            "cycle": None if self.cycle is None else list(self.cycle),
            "reason": self.reason,
        }


@dataclass
class _Reach:
    """A reachability formula: ``neg`` times negated ``EF target`` (``universal``:
    ``AG φ`` = not ``EF not φ``, so ``target`` is ``not φ``)."""

    target: Formula
    negated: bool  # the answer is "not EF target"
    hit: int | None = None  # first state satisfying target


def _peel(f: Formula) -> tuple[bool, Formula]:
    negated = False
    while isinstance(f, Not):
        negated = not negated
        f = f.arg
    return negated, f


def _reachability(f: Formula) -> _Reach | None:
    """``f`` as ``[not] EF target`` when it is an ``EF``/``AG`` of a state formula."""
    negated, core = _peel(f)
    finally_ = isinstance(core, Exists) and isinstance(core.path, Finally)
    globally = isinstance(core, All) and isinstance(core.path, Globally)
    if not (finally_ or globally):
        return None
    assert isinstance(core, Exists | All) and isinstance(core.path, Finally | Globally)
    target = core.path.arg
    if not is_state_formula(target):
        return None
    return _Reach(target, negated) if finally_ else _Reach(Not(target), not negated)


@dataclass
class QuerySession:
    """One net, its budgets, and what has been computed about it so far.

    Args:
        net: the net.
        limits: the limits.
        clock: seconds counter of the session's budget (tests pass a fake one).
    """

    net: Net
    limits: QueryLimits = field(default_factory=QueryLimits)
    clock: Clock = time.perf_counter
    shared_seconds: float = 0.0
    space: StateSpace | None = None
    graph: StateGraph | None = None
    graph_error: str | None = None

    def __post_init__(self) -> None:
        self.index = NetIndex(self.net)
        self.budget = budgets.Budget(
            self.limits.time_limit, clock=self.clock, memory=self.limits.memory_limit
        )
        # Set when an allocation failed (MemoryError): every later formula is then
        # "not computed" with this reason instead of trying (and failing) again.
        self._failed: str | None = None
        self._table: npt.NDArray[np.integer] | None = None
        self._ctl: CtlChecker | None = None
        self._reduced: StateSpace | None = None
        self._invariants: list[tuple[int, ...]] | None = None
        self.symbolic: SymbolicResult | None = None

    # -- budgets and shared work ---------------------------------------------------------

    def remaining(self) -> float | None:
        """Seconds left of the session's time limit (``None``: no limit)."""
        return self.budget.remaining()

    def out_of_time(self) -> bool:
        """Whether the session's budget is spent: its deadline passed, the process is
        over the memory limit, or an allocation already failed."""
        return self._failed is not None or self.budget.expired()

    def spent_reason(self) -> str:
        """Why the budget is spent (`out_of_time`), in `analysis.budget`'s words."""
        return self._failed or self.budget.time_reason()

    def not_computed(self, ident: str, method: str = "") -> Answer:
        """The answer to a formula the session's budget did not reach."""
        return Answer(ident, None, method=method, reason=f"not computed: {self.spent_reason()}")

    def _out_of_memory(self) -> str:
        """Record a failed allocation (the session is spent from now on); its reason."""
        done = None if self.space is None else self.space.states
        self._table = None
        self._ctl = None
        self._failed = memory_limit_reason(self.limits.memory_limit, done)
        return self._failed

    def full_space(self) -> StateSpace:
        """The (unreduced) state space, explored once within the budgets; it may be
        incomplete."""
        if self.space is None:
            start = self.clock()
            self.space = explore(
                self.net,
                max_states=self.limits.max_states,
                budget=self.budget,
            )
            self.shared_seconds += self.clock() - start
        return self.space

    def table(self) -> npt.NDArray[np.integer]:
        """`marking_table` of `full_space`."""
        if self._table is None:
            start = self.clock()
            self._table = marking_table(self.full_space())
            self.shared_seconds += self.clock() - start
        return self._table

    def blocks(self) -> Iterator[tuple[int, npt.NDArray[np.integer]]]:
        """``(first_state, markings)`` over `full_space`: the whole table when it is
        small enough to keep, else decoded blocks."""
        space = self.full_space()
        if self._table is not None or space.states * len(self.net.places) <= TABLE_CELLS:
            yield 0, self.table()
        else:
            yield from space.iter_markings()

    def full_graph(self) -> StateGraph | None:
        """The reachability graph (``None`` with ``graph_error`` set when the space is
        incomplete or a budget ran out)."""
        if self.graph is None and self.graph_error is None:
            space = self.full_space()
            start = self.clock()
            try:
                self.graph = build_graph(
                    space,
                    max_edges=self.limits.max_edges,
                    budget=self.budget,
                )
            except GraphError as exc:
                self.graph_error = str(exc)
            self.shared_seconds += self.clock() - start
        return self.graph

    def _names(self, transitions: Sequence[int]) -> tuple[str, ...]:
        return tuple(self.net.transitions[t].name for t in transitions)

    def _trace(self, space: StateSpace, state: int) -> tuple[str, ...]:
        return tuple(space.trace_names(state))

    # -- formulas ------------------------------------------------------------------------

    def check(self, props: Sequence[MccProperty]) -> list[Answer]:
        """Answer every property, in order."""
        answers: dict[int, Answer] = {}
        reach: dict[int, _Reach] = {}
        for k, prop in enumerate(props):
            unknown = self._unknown_names(prop.query)
            if unknown:
                answers[k] = Answer(
                    prop.id,
                    None,
                    method="error",
                    reason=f"cannot check: the net has no {unknown}",
                    examination=examination_of(prop),
                )
            elif not isinstance(prop.query, PlaceBound):
                r = _reachability(prop.query)
                if r is not None:
                    reach[k] = r
        needs_space = any(
            k not in reach and k not in answers and not _initial_only(p.query)
            for k, p in enumerate(props)
        )
        if reach and not needs_space and self.space is None and not self.out_of_time():
            self._shared(lambda: self._search(props, reach, answers))
        scanned = [
            k
            for k, p in enumerate(props)
            if k not in answers and (k in reach or isinstance(p.query, PlaceBound))
        ]
        if len(scanned) > 1 and not self.out_of_time():
            self._shared(lambda: self._batch(props, scanned, reach, answers))
        for k, prop in enumerate(props):
            if k in answers:
                continue
            start = self.clock()
            try:
                answer = self._answer(prop, reach.get(k))
            except (CtlError, ValueError) as exc:
                answer = Answer(prop.id, None, reason=f"cannot check: {exc}", method="error")
            except BudgetExceeded as exc:
                answer = Answer(prop.id, None, reason=exc.reason)
            except MemoryError:
                answer = Answer(prop.id, None, reason=self._out_of_memory())
            elapsed = self.clock() - start
            answers[k] = _with(answer, seconds=elapsed, examination=examination_of(prop))
        return [answers[k] for k in range(len(props))]

    def _shared(self, work: Callable[[], None]) -> None:
        """Run work shared by several formulas; a budget or allocation failure in it
        leaves their answers to the per-formula pass, which then reports the reason."""
        try:
            work()
        except BudgetExceeded:
            pass  # the budget is spent: `out_of_time` says so to every later formula
        except MemoryError:
            self._out_of_memory()

    def _unknown_names(self, q: Formula | PlaceBound) -> str | None:
        """The first place or transition ``q`` names that the net lacks, described."""
        places = set(q.places) if isinstance(q, PlaceBound) else places_of(q)
        for p in sorted(places):
            if p not in self.index.place:
                return f"place '{p}'"
        if not isinstance(q, PlaceBound):
            for t in sorted(transitions_of(q)):
                if t not in self.index.transition:
                    return f"transition '{t}'"
        return None

    def _answer(self, prop: MccProperty, reach: _Reach | None) -> Answer:
        q = prop.query
        if isinstance(q, PlaceBound):
            return self._bound(prop.id, q)
        if _initial_only(q):
            return self._initial(prop.id, q)  # needs no search: answered at any budget
        if self.out_of_time():
            return self.not_computed(prop.id)
        if reach is not None:
            self._scan({0: reach}, {})
            return self._reach_answer(prop.id, reach, self.full_space())
        if is_ctl(q):
            return self._ctl_formula(prop.id, q)
        if ltl_body(q) is not None:
            return self._ltl_formula(prop.id, q)
        return Answer(prop.id, None, reason="neither CTL nor LTL (CTL* is not supported)")

    def _initial(self, ident: str, q: Formula) -> Answer:
        initial = np.asarray([self.net.initial_marking()], dtype=np.int64)
        value = bool(StateEvaluator(self.index, initial).sat(q)[0])
        return Answer(ident, value, ("INITIAL_STATE",), method="initial")

    def _search(
        self, props: Sequence[MccProperty], reach: dict[int, _Reach], answers: dict[int, Answer]
    ) -> None:
        """One breadth-first search for all the reachability formulas, stopping when
        each has met a marking that decides it."""
        pending = dict(reach)
        start = self.clock()
        per_formula = dict.fromkeys(reach, 0.0)

        def stop_when(first: int, markings: npt.NDArray[np.int64]) -> bool:
            evaluator = StateEvaluator(self.index, markings)
            for k in list(pending):
                tick = self.clock()
                hits = np.flatnonzero(evaluator.sat(pending[k].target))
                if hits.size:
                    pending[k].hit = first + int(hits[0])
                    del pending[k]
                per_formula[k] += self.clock() - tick
            return not pending

        space = explore(
            self.net,
            max_states=self.limits.max_states,
            budget=self.budget,
            stop_when=stop_when,
        )
        if space.stopped_reason != STOPPED_BY_REQUEST:
            self.space = space  # what `full_space` would explore: reuse it
        total = self.clock() - start
        own = sum(per_formula.values())
        self.shared_seconds += max(0.0, total - own)
        for k, r in reach.items():
            answer = self._reach_answer(props[k].id, r, space)
            answers[k] = _with(answer, seconds=per_formula[k], examination=examination_of(props[k]))

    def _batch(
        self,
        props: Sequence[MccProperty],
        ks: list[int],
        reach: dict[int, _Reach],
        answers: dict[int, Answer],
    ) -> None:
        """Reachability and UpperBounds formulas answered from one pass over the
        markings (their time shared evenly)."""
        bounds = {}
        for k in ks:
            q = props[k].query
            if isinstance(q, PlaceBound):
                bounds[k] = [self.index.place[p] for p in q.places]
        space = self.full_space()
        start = self.clock()
        found = self._scan({k: reach[k] for k in ks if k in reach}, bounds)
        share = (self.clock() - start) / len(ks)
        for k in ks:
            if k in bounds:
                state, value = found[k]
                answer = self._bound_answer(props[k].id, bounds[k], state, value)
            else:
                answer = self._reach_answer(props[k].id, reach[k], space)
            answers[k] = _with(answer, seconds=share, examination=examination_of(props[k]))

    def _scan(
        self, reach: dict[int, _Reach], bounds: dict[int, list[int]]
    ) -> dict[int, tuple[int, int]]:
        """One pass over the markings of `full_space`: the first state satisfying each
        reachability target (into ``hit``) and, per bound, ``(state, largest sum)``."""
        space = self.full_space()
        dead = None
        if space.complete:
            dead = np.zeros(space.states, dtype=np.bool_)
            dead[space.deadlocks] = True
        for r in reach.values():
            r.hit = None
        pending = dict(reach)
        best = dict.fromkeys(bounds, (0, -1))
        for start, block in self.blocks():
            part = None if dead is None else dead[start : start + block.shape[0]]
            evaluator = StateEvaluator(self.index, block, part)
            for k in list(pending):
                hits = np.flatnonzero(evaluator.sat(pending[k].target))
                if hits.size:
                    pending.pop(k).hit = start + int(hits[0])
            for k, cols in bounds.items():
                sums = block[:, cols].sum(axis=1, dtype=np.int64)
                j = int(np.argmax(sums))
                if int(sums[j]) > best[k][1]:
                    best[k] = (start + j, int(sums[j]))
            if not pending and not bounds:
                break
        return best

    def _reach_answer(self, ident: str, r: _Reach, space: StateSpace) -> Answer:
        if r.hit is not None:
            return Answer(
                ident,
                not r.negated,
                EXPLICIT,
                method="reachability",
                trace=self._trace(space, r.hit),
            )
        if space.complete:
            return Answer(ident, r.negated, EXPLICIT, method="reachability")
        reduced = self._reach_by_reduction(ident, r)
        if reduced is not None:
            return reduced
        return Answer(
            ident,
            None,
            method="reachability",
            reason=f"state space incomplete: {space.stopped_reason}",
        )

    def _reduced_budget(self) -> budgets.Budget:
        """Half of what is left: the reduced search must leave time to the others."""
        left = self.remaining()
        return self.budget.child(seconds=None if left is None else left / 2)

    def _reach_by_reduction(self, ident: str, r: _Reach) -> Answer | None:
        """The formula decided on the net reduced for what it observes (`analysis.reduce`),
        a witness replayed on this net; ``None`` when that does not decide either."""
        from analysis.reduce.query import reach_by_reduction

        if self.out_of_time() or not self.limits.reductions:
            return None
        start = self.clock()
        found = reach_by_reduction(
            self.net, r.target, max_states=self.limits.max_states, budget=self._reduced_budget()
        )
        self.shared_seconds += self.clock() - start
        if found is None:
            return None
        value = bool(found.value) != r.negated
        return Answer(ident, value, REDUCED, method="reachability", trace=found.trace)

    def _ctl_formula(self, ident: str, q: Formula) -> Answer:
        graph = self.full_graph()
        if graph is None:
            return Answer(ident, None, method="ctl", reason=self._why_no_graph())
        if self._ctl is None:
            self._ctl = CtlChecker(
                graph, markings=self.table(), index=self.index, budget=self.budget
            )
        try:
            value = self._ctl.holds(q)
        except BudgetExceeded as exc:
            return Answer(ident, None, method="ctl", reason=exc.reason)
        trace = self._ctl_trace(q, value)
        return Answer(ident, value, EXPLICIT, method="ctl", trace=trace)

    def _ctl_trace(self, q: Formula, value: bool) -> tuple[str, ...] | None:
        """For ``[not] EF φ`` / ``[not] AG φ``, a shortest trace to a marking that
        decides it (nodes are numbered breadth first)."""
        assert self._ctl is not None and self.space is not None
        negated, core = _peel(q)
        if isinstance(core, Exists) and isinstance(core.path, Finally):
            target, found = core.path.arg, value != negated  # EF φ holds
        elif isinstance(core, All) and isinstance(core.path, Globally):
            target, found = core.path.arg, value == negated  # AG φ fails
        else:
            return None
        if not found:
            return None
        sat = self._ctl.sat(target)
        nodes = np.flatnonzero(sat if isinstance(core, Exists) else ~sat)
        return self._trace(self.space, int(nodes[0])) if nodes.size else None

    def _why_no_graph(self) -> str:
        space = self.full_space()
        if not space.complete:
            return f"state space incomplete: {space.stopped_reason}"
        return self.graph_error or "no reachability graph"

    def _ltl_formula(self, ident: str, q: Formula) -> Answer:
        try:
            from analysis.ltl import LtlError, check_ltl
        except ImportError as exc:  # pragma: no cover - the module ships with coral
            return Answer(ident, None, method="ltl", reason=f"LTL checker unavailable: {exc}")
        graph = self.full_graph()
        if graph is None:
            return Answer(ident, None, method="ltl", reason=self._why_no_graph())
        try:
            result = check_ltl(
                graph, q, max_product_edges=self.limits.max_product_edges, budget=self.budget
            )
        except BudgetExceeded as exc:
            return Answer(ident, None, method="ltl", reason=exc.reason)
        except GraphError as exc:
            return Answer(ident, None, method="ltl", reason=str(exc))
        except LtlError as exc:
            return Answer(ident, None, method="ltl", reason=f"cannot check: {exc}")
        if self.out_of_time():
            return self.not_computed(ident, "ltl")
        if result.holds:
            return Answer(ident, True, EXPLICIT, method="ltl")
        prefix = tuple(self.net.transitions[t].name for _, t, _ in result.prefix if t >= 0)
        cycle = tuple(self.net.transitions[t].name for _, t, _ in result.cycle if t >= 0)
        return Answer(ident, False, EXPLICIT, method="ltl", trace=prefix, cycle=cycle)

    # -- UpperBounds -----------------------------------------------------------------------

    def _bound(self, ident: str, q: PlaceBound) -> Answer:
        if self.out_of_time() and self.space is None:
            return self.not_computed(ident, "bound")
        cols = [self.index.place[p] for p in q.places]
        best, found = self._scan({}, {0: cols})[0]
        return self._bound_answer(ident, cols, best, found)

    def _bound_answer(self, ident: str, cols: list[int], best: int, found: int) -> Answer:
        space = self.full_space()
        trace = self._trace(space, best)
        if space.complete:
            return Answer(ident, found, EXPLICIT, method="bound", trace=trace)
        proven = self._invariant_bound(cols)
        if proven is not None and proven == found:
            return Answer(
                ident,
                found,
                (*EXPLICIT, "TOPOLOGICAL"),
                method="bound",
                trace=trace,
                reason="the bound reached equals the one a P-invariant proves",
            )
        reduced = self._bound_by_reduction(ident, cols)
        if reduced is not None:
            return reduced
        return Answer(
            ident,
            None,
            method="bound",
            reason=f"state space incomplete ({space.stopped_reason}); {found} tokens reached"
            + (f", at most {proven} by P-invariants" if proven is not None else ""),
        )

    def _bound_by_reduction(self, ident: str, cols: list[int]) -> Answer | None:
        """The bound from a complete search of the net reduced for these places
        (`analysis.reduce`); ``None`` when that search does not complete either."""
        from analysis.reduce.query import bound_by_reduction

        if self.out_of_time() or not self.limits.reductions:
            return None
        start = self.clock()
        places = [self.net.places[c].name for c in cols]
        found = bound_by_reduction(
            self.net, places, max_states=self.limits.max_states, budget=self._reduced_budget()
        )
        self.shared_seconds += self.clock() - start
        if found is None:
            return None
        return Answer(ident, int(found.value), REDUCED, method="bound", trace=found.trace)

    def _invariant_bound(self, cols: Sequence[int]) -> int | None:
        """The least ``floor(y·M0 / min y(S))`` over the P-invariants ``y`` covering all
        of ``cols`` (``None`` if none does): since ``y·M = y·M0`` in every reachable
        marking, ``sum M(S) <= y·M / min y(S)``."""
        invariants = self._p_invariants()
        m0 = self.net.initial_marking()
        best: int | None = None
        for weights in invariants:
            low = min(weights[c] for c in cols)
            if low <= 0:
                continue
            total = sum(w * m for w, m in zip(weights, m0, strict=True))
            bound = total // low
            best = bound if best is None else min(best, bound)
        return best

    def _p_invariants(self) -> list[tuple[int, ...]]:
        if self._invariants is None:
            from analysis.invariants import p_invariants

            basis = p_invariants(self.net, budget=self.budget.child(seconds=INVARIANT_SECONDS))
            self._invariants = [inv.weights for inv in basis.invariants]
        return self._invariants

    # -- global examinations -----------------------------------------------------------------

    def check_global(self, examination: str) -> Answer:
        """Answer a global examination (one of `GLOBAL_EXAMINATIONS`)."""
        if examination not in GLOBAL_EXAMINATIONS:
            raise ValueError(f"unknown global examination {examination!r}")
        start = self.clock()
        run: dict[str, Callable[[], Answer]] = {
            "ReachabilityDeadlock": self._deadlock,
            "QuasiLiveness": self._quasi_liveness,
            "Liveness": self._liveness,
            "OneSafe": self._one_safe,
            "StableMarking": self._stable_marking,
        }
        if self.out_of_time() and self.space is None:
            answer = self.not_computed("", "global")
        else:
            try:
                answer = run[examination]()
            except BudgetExceeded as exc:
                answer = Answer("", None, method="global", reason=exc.reason)
            except MemoryError:
                answer = Answer("", None, method="global", reason=self._out_of_memory())
        return _with(answer, id=examination, seconds=self.clock() - start, examination=examination)

    def _incomplete(self, space: StateSpace) -> Answer:
        return Answer(
            "", None, method="global", reason=f"state space incomplete: {space.stopped_reason}"
        )

    def symbolic_space(self, share: float = 1.0) -> SymbolicResult:
        """The reachable markings as a decision diagram (`analysis.symbolic`), built once
        with ``share`` of the time left."""
        if self.symbolic is None:
            from analysis.symbolic.explore import SymbolicLimits, explore_symbolic

            left = self.remaining()
            budget = self.budget.child(seconds=None if left is None else left * share)
            start = self.clock()
            self.symbolic = explore_symbolic(self.net, SymbolicLimits(budget=budget))
            self.shared_seconds += self.clock() - start
        return self.symbolic

    def _symbolic_deadlock(self, share: float) -> Answer:
        """ReachabilityDeadlock from the decision diagram: TRUE with a shortest trace to
        a dead marking, FALSE when the complete diagram holds none."""
        result = self.symbolic_space(share)
        if result.deadlock is True:
            trace = None if result.deadlock_trace is None else tuple(result.deadlock_trace)
            return Answer("", True, SYMBOLIC, method="global", trace=trace)
        if result.complete:
            return Answer("", False, SYMBOLIC, method="global")
        return Answer("", None, method="global", reason=f"symbolic: {result.reason}")

    def _deadlock(self) -> Answer:
        """With ``method="symbolic"``, the decision diagram alone; else the full search
        first (the fastest explorer, shared with the other
        examinations); when its budget stops it, a z3 proof that no dead marking is
        reachable (state equation and traps: answers FALSE without exploring), then a
        deadlock-preserving stubborn-set search, which often stores far fewer markings;
        with ``method="auto"``, the decision diagram last."""
        if self.limits.method == "symbolic":
            return self._symbolic_deadlock(1.0)
        answer = self._deadlock_explicit()
        if (
            answer.value is None
            and self.limits.method == "auto"
            and (self.limits.max_states or AUTO_SYMBOLIC_MIN_STATES) >= AUTO_SYMBOLIC_MIN_STATES
            and not self.out_of_time()
            and symbolic_applicable(self.net)
        ):
            return self._symbolic_deadlock(1.0)
        return answer

    def _deadlock_explicit(self) -> Answer:
        if self.space is None and not self.out_of_time():
            by_reduction = self._deadlock_by_reduction()
            if by_reduction is not None:
                return by_reduction
        space = self.full_space()
        techniques: tuple[str, ...] = EXPLICIT
        if not space.complete and not space.has_deadlock and not self.out_of_time():
            proof = self._deadlock_free_by_state_equation()
            if proof is not None:
                return proof
            if self._reduced is None:
                start = self.clock()
                self._reduced = explore(
                    self.net, max_states=self.limits.max_states, budget=self.budget, por=True
                )
                self.shared_seconds += self.clock() - start
            space, techniques = self._reduced, (*EXPLICIT, "STUBBORN_SETS")
        if space.has_deadlock:
            trace = self._trace(space, int(space.deadlocks[0]))
            return Answer("", True, techniques, method="global", trace=trace)
        if space.complete:
            return Answer("", False, techniques, method="global")
        return self._incomplete(space)

    def _deadlock_by_reduction(self) -> Answer | None:
        """Structural reductions first (`analysis.reduce`): the reduced net is searched
        within half of what is left of the budget, its witness replayed on this net;
        ``None`` when that does not decide (the unreduced searches follow)."""
        from analysis.reduce import decide_deadlock
        from analysis.reduce.driver import reducible

        if not reducible(self.net) or not self.limits.reductions:
            return None
        left = self.remaining()
        answer = decide_deadlock(
            self.net,
            max_states=self.limits.max_states,
            budget=self.budget.child(seconds=None if left is None else left / 2),
        )
        if answer.deadlock is None:
            return None
        trace = tuple(answer.trace) if answer.trace is not None else None
        techniques = {
            "random walk": ("STRUCTURAL_REDUCTION", "RANDOM_WALK"),
            "siphon-trap": ("STRUCTURAL_REDUCTION", "TOPOLOGICAL"),
        }.get(answer.by, ("STRUCTURAL_REDUCTION", *EXPLICIT))
        return Answer("", answer.deadlock, techniques, method="global", trace=trace)

    def _deadlock_free_by_state_equation(self) -> Answer | None:
        """FALSE when the state equation with trap constraints proves that no dead
        marking is reachable; ``None`` when it cannot (a solution of the equation is
        not a deadlock, so it never gives TRUE), or the time left would not build its
        constraints (`STATE_EQUATION_SECONDS_PER_ARC`; building checks the budget too)."""
        arcs = self.net.arc_count
        left = self.remaining()
        if self.out_of_time() or (
            left is not None and arcs * STATE_EQUATION_SECONDS_PER_ARC > left
        ):
            return None
        from analysis import stateeq  # z3 and the invariants: only when a search gave up

        start = self.clock()
        result = stateeq.check_unreachable(
            self.net,
            stateeq.deadlocks(),
            query_seconds=STATE_EQUATION_SECONDS,
            budget=self.budget.child(seconds=STATE_EQUATION_SECONDS),
        )
        self.shared_seconds += self.clock() - start
        if not isinstance(result, stateeq.Proven):
            return None
        return Answer("", False, ("STATE_EQUATION",), method="global", reason=result.explain())

    def _quasi_liveness(self) -> Answer:
        space = self.full_space()
        dead = space.dead_transitions
        if not dead.size:
            return Answer("", True, EXPLICIT, method="global")
        if space.complete:
            names = ", ".join(self._names(dead[:5].tolist()))
            more = f" and {dead.size - 5} more" if dead.size > 5 else ""
            return Answer(
                "", False, EXPLICIT, method="global", reason=f"never enabled: {names}{more}"
            )
        return self._incomplete(space)

    def _liveness(self) -> Answer:
        space = self.full_space()
        if not self.net.transitions:
            return Answer("", True, EXPLICIT, method="global", reason="the net has no transition")
        if space.has_deadlock:
            trace = self._trace(space, int(space.deadlocks[0]))
            return Answer(
                "",
                False,
                EXPLICIT,
                method="global",
                trace=trace,
                reason="a dead marking is reachable",
            )
        if not space.complete:
            return self._incomplete(space)
        dead = space.dead_transitions
        if dead.size:
            return Answer(
                "",
                False,
                EXPLICIT,
                method="global",
                reason=f"transition {self.net.transitions[int(dead[0])].name} is never enabled",
            )
        graph = self.full_graph()
        if graph is None:
            return Answer("", None, method="global", reason=self._why_no_graph())
        return self._bottom_components(graph)

    def _bottom_components(self, graph: StateGraph) -> Answer:
        """Live iff every bottom strongly connected component enables every transition
        at one of its nodes: every reachable marking reaches such a component, and
        inside one every node reaches every other."""
        n, src, dst, labels = graph.n_states, graph.sources, graph.targets, graph.labels
        comp = scc_labels(n, src, dst)
        n_comp = int(comp.max(initial=-1)) + 1
        exits = np.zeros(n_comp, dtype=np.bool_)
        exits[comp[src][comp[src] != comp[dst]]] = True
        bottom = ~exits
        n_t = len(self.net.transitions)
        inner = bottom[comp[src]]
        pairs = np.unique(comp[src][inner] * n_t + labels[inner])
        counts = np.bincount(pairs // n_t, minlength=n_comp)
        lacking = np.flatnonzero(bottom & (counts < n_t))
        if not lacking.size:
            return Answer("", True, EXPLICIT, method="global")
        members = np.isin(comp, lacking)
        node = int(np.flatnonzero(members)[0])  # lowest number: a shortest trace
        c = int(comp[node])
        present = np.zeros(n_t, dtype=np.bool_)
        present[labels[inner & (comp[src] == c)]] = True
        missing = self.net.transitions[int(np.flatnonzero(~present)[0])].name
        return Answer(
            "",
            False,
            EXPLICIT,
            method="global",
            trace=self._trace(graph.space, node),
            reason=f"after this trace, {missing} can never fire again",
        )

    def _one_safe(self) -> Answer:
        space = self.full_space()
        if space.max_tokens_place > 1:
            node = next(
                start + int(hit[0])
                for start, block in self.blocks()
                if (hit := np.flatnonzero((block > 1).any(axis=1))).size
            )
            return Answer("", False, EXPLICIT, method="global", trace=self._trace(space, node))
        if space.complete:
            return Answer("", True, EXPLICIT, method="global")
        bounds = self._invariant_place_bounds()
        if bounds is not None and all(b <= 1 for b in bounds):
            return Answer(
                "",
                True,
                ("TOPOLOGICAL",),
                method="global",
                reason="every place is bounded by one by a P-invariant",
            )
        return self._incomplete(space)

    def _invariant_place_bounds(self) -> list[int] | None:
        """Per place, a bound from P-invariants (``None`` unless every place has one)."""
        m0 = self.net.initial_marking()
        if any(m > 1 for m in m0):
            return None
        best: list[int | None] = [None] * len(self.net.places)
        for weights in self._p_invariants():
            total = sum(w * m for w, m in zip(weights, m0, strict=True))
            for p, w in enumerate(weights):
                if w > 0:
                    bound = total // w
                    current = best[p]
                    best[p] = bound if current is None else min(current, bound)
        if any(b is None for b in best):
            return None
        return [b for b in best if b is not None]

    def _stable_marking(self) -> Answer:
        space = self.full_space()
        initial = np.asarray(self.net.initial_marking(), dtype=np.int64)
        stable = np.ones(initial.size, dtype=np.bool_)
        for _, block in self.blocks():
            stable &= (block == initial.astype(block.dtype)).all(axis=0)
            if not stable.any():
                break
        if not stable.any():
            return Answer("", False, EXPLICIT, method="global")
        if space.complete:
            place = self.net.places[int(np.flatnonzero(stable)[0])].name
            return Answer(
                "", True, EXPLICIT, method="global", reason=f"place {place} never changes"
            )
        return self._incomplete(space)


def _initial_only(q: Formula | PlaceBound) -> bool:
    return not isinstance(q, PlaceBound) and is_state_formula(q)


def _with(answer: Answer, **changes: Any) -> Answer:
    from dataclasses import replace

    return replace(answer, **changes)
