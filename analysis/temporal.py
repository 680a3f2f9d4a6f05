"""Verdicts on a mission's temporal assertions: ``always``, ``eventually``, ``leadsto``,
``ltl`` and ``ctl`` (``docs/language.md``), for `analysis.verify`.

`check_temporal` turns one `Assertion` of kind LTL or CTL into a `PropertyResult`:

* **LTL** (``always P``, ``eventually P``, ``P leadsto Q``, ``ltl φ``) holds when every
  run of the net satisfies the formula, counting only the runs the runtime can
  produce: the *weakly fair* ones of `analysis.fairness` (the engine never leaves a
  transition enabled forever, the vehicle answers every command). A run that reaches a
  dead marking stays there forever (``analysis.ltl``).

  ``always P`` with ``P`` a state expression is a safety property: it fails exactly
  when a reachable marking violates ``P`` (weak fairness never hides a finite
  prefix), so it is decided on the explored markings without the edges, and a
  violation comes with a *shortest* trace, even when the state space is incomplete.
  Every other LTL formula goes to `analysis.ltl.check_ltl` on the reachability graph;
  a violation comes with a *lasso*: a trace, then a loop the run repeats forever (or
  the dead marking it stays in).
* **CTL** (``ctl φ``) holds when the initial marking satisfies ``φ``, over all runs
  (``analysis.ctl``). A property of the form ``EF P``, ``E [ P U Q ]``, ``EX P`` or
  ``EG P`` (alone or as a conjunct) that holds comes with a witness trace; a
  violated ``AG P``, ``AF P``, ``AX P`` or ``A [ P U Q ]`` with a counterexample.

The verdict is inconclusive, with the reason, when the state space is incomplete or
reduced, or the graph or the LTL product exceeds its budget.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from analysis.fairness import fairness_groups
from analysis.report import Evidence, PropertyResult, Verdict, make_trace, witness
from analysis.stategraph import (
    GraphError,
    StateGraph,
    fair_lasso,
    fair_sccs,
    node_mask,
    shortest_path,
)
from analysis.statespace import StateSpace
from coral_lang import formula as fm
from coral_lang.net import Assertion, AssertKind, Net

if TYPE_CHECKING:
    from analysis.ctl import CtlChecker

Markings = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]
GraphSource = Callable[[], StateGraph]
"""Returns the reachability graph, built once per verification, or raises
`GraphError` saying why there is none."""

EXPLICIT = "explicit state space"
LTL_METHOD = "LTL model checking (Spot), runs under the runtime's fairness"
CTL_METHOD = "CTL model checking on the reachability graph"


def check_temporal(
    net: Net,
    space: StateSpace,
    graph: GraphSource,
    assertion: Assertion,
    key: str,
) -> PropertyResult:
    """The verdict on one temporal assertion of ``net``.

    Args:
        net: the net the assertion belongs to.
        space: its explored state space (possibly incomplete or reduced).
        graph: the reachability graph of ``space``, built on the first call (and
            cached by the caller); raises `GraphError` when there can be none.
        assertion: of kind `AssertKind.LTL` or `AssertKind.CTL`.
        key: the property's key in the report (``assert:N``).
    """
    formula = assertion.formula
    if formula is None or not assertion.temporal:
        raise ValueError(f"not a temporal assertion: {assertion.describe()}")
    checker = _Temporal(net, space, graph, assertion, key)
    if assertion.kind is AssertKind.CTL:
        return checker.ctl(formula)
    body = fm.ltl_body(formula)
    assert body is not None, "the compiler only makes LTL assertions of LTL formulas"
    if isinstance(body, fm.Globally) and fm.is_state_formula(body.arg):
        return checker.invariant(body.arg)
    return checker.ltl(formula)


class _Temporal:
    def __init__(
        self, net: Net, space: StateSpace, graph: GraphSource, assertion: Assertion, key: str
    ) -> None:
        self.net = net
        self.space = space
        self.graph = graph
        self.assertion = assertion
        self.key = key
        self.title = assertion.describe()
        self.method = EXPLICIT + (" (stubborn-set reduced)" if space.reduced else "")

    def result(
        self, verdict: Verdict, method: str, detail: str, evidence: Evidence | None = None
    ) -> PropertyResult:
        return PropertyResult(
            self.key, self.title, verdict, method, detail, evidence, self.assertion.span
        )

    def inconclusive(self, method: str, reason: str) -> PropertyResult:
        return self.result(Verdict.INCONCLUSIVE, method, reason)

    def trace_to(self, state: int, note: str = "") -> Evidence:
        return witness(self.space, state, note)

    # -- LTL --------------------------------------------------------------------------

    def invariant(self, state: fm.Formula) -> PropertyResult:
        """``G P`` with ``P`` a state formula: no reachable marking violates ``P``."""
        from analysis.ctl import NetIndex, StateEvaluator

        index = NetIndex(self.net)

        def violated(block: Markings) -> BoolArray:
            return ~StateEvaluator(index, block).sat(state)

        hit = self.space.find(violated)
        if hit is not None:
            return self.result(
                Verdict.VIOLATED,
                self.method,
                f"a marking that violates it is reachable in {self.space.depth_of(hit)} "
                f"step(s); {'a' if self.space.reduced else 'shortest'} trace below",
                self.trace_to(hit),
            )
        if self.space.complete and not self.space.reduced:
            return self.result(
                Verdict.PROVEN,
                self.method,
                f"holds in all {self.space.states} reachable markings",
            )
        return self.inconclusive(self.method, f"not violated so far; {_incomplete(self.space)}")

    def ltl(self, formula: fm.Formula) -> PropertyResult:
        """Any other LTL formula, on the product with Spot's automaton."""
        from analysis.ltl import LtlError, check_ltl

        try:
            graph = self.graph()
            result = check_ltl(graph, formula, fairness=fairness_groups(graph))
        except GraphError as exc:
            return self.inconclusive(LTL_METHOD, str(exc))
        except LtlError as exc:
            return self.inconclusive(LTL_METHOD, f"cannot be checked: {exc}")
        figures = (
            f"{graph.n_states} markings, {result.product_states} product states, "
            f"{result.automaton_states} automaton states"
        )
        if result.holds:
            return self.result(
                Verdict.PROVEN, LTL_METHOD, f"every fair run satisfies it ({figures})"
            )
        evidence, shape = self.lasso(result.prefix, result.cycle)
        return self.result(
            Verdict.VIOLATED, LTL_METHOD, f"a fair run violates it: {shape} ({figures})", evidence
        )

    def lasso(
        self, prefix: list[tuple[int, int, int]], cycle: list[tuple[int, int, int]]
    ) -> tuple[Evidence, str]:
        """Evidence for the run ``prefix`` then ``cycle`` forever, and a phrase saying
        its shape. Stutter steps (transition -1, at a dead marking) are not firings:
        a cycle of them is the run staying in that dead marking."""
        lead = [t for _, t, _ in prefix if t >= 0]
        loop = [t for _, t, _ in cycle if t >= 0]
        entry = cycle[0][0] if cycle else (prefix[-1][2] if prefix else 0)
        marking = self.net.marking_dict(self.space.marking(entry))
        trace = make_trace(self.net, lead)
        if not loop:
            final = self.net.is_final(self.space.marking(entry))
            where = "a declared final marking" if final else "a dead marking (a deadlock)"
            note = f"the run ends in {where} and stays there forever"
            return (
                Evidence(trace=trace, marking=marking, note=note),
                f"{len(lead)} step(s) to {where}, where it stays",
            )
        evidence = Evidence(
            trace=trace,
            marking=marking,
            loop=make_trace(self.net, loop, start=len(lead) + 1),
            note="the loop starts from the marking shown and repeats forever; the run "
            "is fair: every engine transition and every command's replies get their turn",
        )
        return evidence, f"{len(lead)} step(s), then a loop of {len(loop)} step(s) forever"

    # -- CTL --------------------------------------------------------------------------

    def ctl(self, formula: fm.Formula) -> PropertyResult:
        """A CTL formula at the initial marking, over all maximal paths."""
        from analysis.ctl import CtlChecker, CtlError

        try:
            graph = self.graph()
            checker = CtlChecker(graph)
            holds = checker.holds(formula)
            evidence = _Explainer(self.net, graph, checker).explain(formula, holds)
        except GraphError as exc:
            return self.inconclusive(CTL_METHOD, str(exc))
        except CtlError as exc:
            return self.inconclusive(CTL_METHOD, f"cannot be checked: {exc}")
        if holds:
            detail = f"the initial marking satisfies it ({graph.n_states} markings)"
            return self.result(Verdict.PROVEN, CTL_METHOD, detail, evidence)
        detail = f"the initial marking does not satisfy it ({graph.n_states} markings)"
        if evidence is not None:
            detail += "; counterexample below"
        return self.result(Verdict.VIOLATED, CTL_METHOD, detail, evidence)


class _Explainer:
    """Finite evidence for the value of a CTL formula at the initial marking: a path
    that an existential property holds along (a witness), or that a universal one
    fails along (a counterexample, the witness of its dual)."""

    def __init__(self, net: Net, graph: StateGraph, checker: CtlChecker) -> None:
        self.net = net
        self.graph = graph
        self.checker = checker
        self.n = graph.n_states
        self.src = graph.sources
        self.dst = graph.targets

    def explain(self, f: fm.Formula, value: bool) -> Evidence | None:
        """Evidence that ``f`` has ``value`` at node 0, when a path shows it."""
        if isinstance(f, fm.Not):
            return self.explain(f.arg, not value)
        if isinstance(f, fm.Or) and not value:
            return None  # every part fails: one path cannot show that
        if isinstance(f, fm.And) and value:
            # every part holds: the first with a witness stands for them
            for arg in f.args:
                evidence = self.explain(arg, value)
                if evidence is not None:
                    return evidence
            return None
        if isinstance(f, fm.And | fm.Or):
            # a conjunction fails (a disjunction holds) by one part: show that one
            for arg in f.args:
                if self.checker.holds(arg) == value:
                    return self.explain(arg, value)
            return None
        if isinstance(f, fm.Exists) and value:
            return self.witness(f.path, universal_dual=False)
        if isinstance(f, fm.All) and not value:
            return self.witness(f.path, universal_dual=True)
        return None

    def witness(self, path: fm.Formula, universal_dual: bool) -> Evidence | None:
        """A path from node 0 for ``E path`` or, with ``universal_dual``, against
        ``A path`` (the path of ``E`` of its negation)."""
        sat = self.checker.sat
        if isinstance(path, fm.Next):
            goal = ~sat(path.arg) if universal_dual else sat(path.arg)
            first, last = int(self.graph.indptr[0]), int(self.graph.indptr[1])
            edges = [e for e in range(first, last) if goal[self.dst[e]]]
            return self.evidence(edges[:1]) if edges else None
        if isinstance(path, fm.Finally):
            if universal_dual:  # not AF b: EG not b
                return self.stay_within(~sat(path.arg))
            return self.reach(None, sat(path.arg))
        if isinstance(path, fm.Globally):
            if universal_dual:  # not AG a: EF not a
                return self.reach(None, ~sat(path.arg))
            return self.stay_within(sat(path.arg))
        assert isinstance(path, fm.Until)
        a, b = sat(path.left), sat(path.right)
        if not universal_dual:
            return self.reach(a, b)
        # not A[a U b]: E[not b U (not a and not b)] or EG not b
        found = self.reach(~b, ~a & ~b)
        return found if found is not None else self.stay_within(~b)

    def reach(self, through: BoolArray | None, goal: BoolArray) -> Evidence | None:
        """A shortest path from node 0 to ``goal``, every node before it in
        ``through``."""
        keep = np.ones(self.src.size, dtype=np.bool_) if through is None else through[self.src]
        idx = np.flatnonzero(keep)
        start = np.zeros(self.n, dtype=np.bool_)
        start[0] = True
        path = shortest_path(self.n, self.src[idx], self.dst[idx], start, goal)
        if path is None:
            return None
        return self.evidence([int(idx[e]) for e in path])

    def stay_within(self, inside: BoolArray) -> Evidence | None:
        """A maximal path from node 0 that never leaves ``inside``: into a dead
        marking, or a cycle repeated forever."""
        if not inside[0]:
            return None
        keep = inside[self.src] & inside[self.dst]
        idx = np.flatnonzero(keep)
        src, dst = self.src[idx], self.dst[idx]
        comp, cyclic = fair_sccs(self.n, src, dst, (), within=inside)
        in_cycle = (comp >= 0) & cyclic[np.maximum(comp, 0)]
        goal = inside & (self.graph.dead | in_cycle)
        start = np.zeros(self.n, dtype=np.bool_)
        start[0] = True
        prefix = shortest_path(self.n, src, dst, start, goal)
        if prefix is None:
            return None
        end = int(dst[prefix[-1]]) if prefix else 0
        lead = [int(idx[e]) for e in prefix]
        if self.graph.dead[end]:
            return self.evidence(lead, "the path ends in this dead marking (nothing can fire)")
        lasso = fair_lasso(self.n, src, dst, node_mask(self.n, end), comp, cyclic)
        assert lasso is not None
        loop = [int(idx[e]) for e in lasso.cycle]
        return Evidence(
            trace=make_trace(self.net, [int(self.graph.labels[e]) for e in lead]),
            marking=self.net.marking_dict(self.graph.space.marking(end)),
            loop=make_trace(
                self.net, [int(self.graph.labels[e]) for e in loop], start=len(lead) + 1
            ),
            note="the loop starts from the marking shown and repeats forever",
        )

    def evidence(self, edges: list[int], note: str = "") -> Evidence:
        """The firing sequence of ``edges`` from node 0 and the marking it ends in."""
        end = int(self.dst[edges[-1]]) if edges else 0
        return Evidence(
            trace=make_trace(self.net, [int(self.graph.labels[e]) for e in edges]),
            marking=self.net.marking_dict(self.graph.space.marking(end)),
            note=note or ("" if edges else "the initial marking itself shows it"),
        )


def _incomplete(space: StateSpace) -> str:
    if space.reduced:
        return "the state space is stubborn-set reduced, which keeps no temporal property"
    return f"the state space is incomplete ({space.stopped_reason})"
