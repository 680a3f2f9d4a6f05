"""A symbolic result in the report's terms: the state space figures, and the deadlock
verdict when the diagram decides it. Kept apart from the exploration so that `verify`
imports it without loading CUDD."""

from __future__ import annotations

from typing import TYPE_CHECKING

from analysis.report import Evidence, PropertyResult, StateSpaceFigures, Verdict, make_trace
from coral_lang.net import Net, TransitionKind

if TYPE_CHECKING:
    from analysis.symbolic.explore import SymbolicResult

SYMBOLIC = "symbolic state space (decision diagram)"

AUTO_SYMBOLIC_MIN_STATES = 100_000
"""`--method auto` (verify and query) tries decision diagrams after an incomplete
explicit search only when its state budget was at least this: a smaller one asks for
a small explicit search."""


def symbolic_applicable(net: Net) -> bool:
    """Whether the diagrams model `net` exactly: plain P/T firing only (mission INPUT
    transitions have an engine-specific rule, place capacities are not encoded)."""
    return not any(tr.kind is TransitionKind.INPUT for tr in net.transitions) and all(
        p.capacity is None for p in net.places
    )


def symbolic_figures(result: SymbolicResult) -> StateSpaceFigures:
    """The report's state space figures from a symbolic run: exact counts and bounds
    when complete; a lower bound (markings found so far) with the reason otherwise.
    A diagram has no edges and no per-state cost: both are 0."""
    return StateSpaceFigures(
        states=result.states,
        edges=0,
        max_tokens_place=result.max_tokens_place,
        max_tokens_marking=result.max_tokens_marking,
        place_bounds=dict(result.place_bounds),
        complete=result.complete,
        stopped_reason=result.reason,
        reduced=False,
        seconds=result.seconds,
        bytes_per_state=0.0,
        method="symbolic",
    )


def symbolic_deadlock(net: Net, result: SymbolicResult, title: str) -> PropertyResult | None:
    """The deadlock verdict of a complete symbolic run, or None when it does not decide:
    a net with declared final markings whose dead markings the diagram does not tell
    apart from final ones (the explicit methods decide those)."""
    if not result.deadlock:
        return PropertyResult(
            "deadlock",
            title,
            Verdict.PROVEN,
            SYMBOLIC,
            f"no dead marking among all {result.states} reachable states",
        )
    if net.finals or result.deadlock_marking is None:
        return None
    trace = result.deadlock_trace
    if trace is None:
        detail = "a marking in which no transition is enabled is reachable (no trace: its "
        detail += "search ran out of budget)"
        evidence = Evidence(marking=dict(result.deadlock_marking), note=detail)
    else:
        detail = f"a marking in which no transition is enabled is reachable in {len(trace)} "
        detail += "step(s); shortest trace below"
        by_name = {t.name: i for i, t in enumerate(net.transitions)}
        evidence = Evidence(
            trace=make_trace(net, [by_name[name] for name in trace]),
            marking=dict(result.deadlock_marking),
            note="found in the decision diagram; replayed on the net",
        )
    return PropertyResult("deadlock", title, Verdict.VIOLATED, SYMBOLIC, detail, evidence)
