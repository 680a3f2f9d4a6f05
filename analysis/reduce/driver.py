"""Apply the reduction rules to a fixpoint and map answers back to the original net.

`reduce_net` runs the rule families (`dead`, `redundant`, `implicit`, `agglomerate`,
`fusion`)
until none applies, the round limit is hit or the budget's deadline passes (each rule is
sound on its own, so stopping between two rules is always safe). The `Reduction` it
returns expands a reduced firing sequence into an original one (`expand_trace`): a
deadlock witness of the reduced net becomes a replayable witness of the original.
Observed places keep their names and values, so bounds and predicates over them read
the same on both nets.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from analysis.budget import Budget
from analysis.inputs import has_inputs
from analysis.reduce.agglomerate import agglomerate_series, post_agglomerate, pre_agglomerate
from analysis.reduce.dead import (
    remove_dead_transitions,
    remove_neutral_transitions,
    remove_sink_places,
)
from analysis.reduce.fusion import fuse_series_places
from analysis.reduce.goal import Goal
from analysis.reduce.implicit import remove_implicit_places
from analysis.reduce.implicit_lp import remove_lp_implicit_places
from analysis.reduce.redundant import (
    collapse_live,
    remove_dominated_self_loops,
    remove_duplicate_transitions,
)
from analysis.reduce.work import WorkNet
from coral_lang.net import Net

Rule = Callable[[WorkNet], bool]

RULES: tuple[Rule, ...] = (
    remove_dead_transitions,
    remove_sink_places,
    remove_neutral_transitions,
    remove_duplicate_transitions,
    remove_dominated_self_loops,
    collapse_live,
    remove_implicit_places,
    agglomerate_series,
    post_agglomerate,
    pre_agglomerate,
    fuse_series_places,
)
"""The rule families in the order one round applies them (cheap removals first)."""

LP_RULES: tuple[Rule, ...] = (*RULES, remove_lp_implicit_places)
"""With the linear-programming implicit-place rule last. Not the default: on the 47
conformance instances it removed places on one only (HouseConstruction-PT-00002) while
its LP calls doubled the time of the small reductions (bench/reductions.py, docs)."""


@dataclass(frozen=True)
class Reduction:
    """A reduced net and how to read its answers on the original."""

    original: Net
    net: Net
    goal: Goal
    expansion: dict[str, tuple[str, ...]]
    """Reduced transition name -> the original transitions it fires, in order."""
    applied: dict[str, int] = field(default_factory=dict)
    """How many times each rule applied."""
    seconds: float = 0.0
    prefix: tuple[str, ...] = ()
    """Original transitions fired before any reduced one: the reduced net's initial
    marking is the one they reach (a rule may fire a transition eagerly at the start,
    see `fusion`)."""

    closers: tuple[tuple[str, ...], ...] = ()
    """Original sequences that a dead marking of the reduced net may still enable in the
    original (`agglomerate.pre_agglomerate`): a deadlock witness fires them while they
    are enabled, the last recorded first, to reach a dead marking of the original."""

    def expand_trace(self, trace: Sequence[str]) -> list[str]:
        """A firing sequence of the reduced net as one of the original net."""
        return [*self.prefix, *(name for t in trace for name in self.expansion[t])]

    def summary(self) -> str:
        """One line: sizes before and after, and the rules used."""
        rules = ", ".join(f"{k} x{v}" for k, v in sorted(self.applied.items())) or "none"
        return (
            f"{len(self.original.places)}/{len(self.original.transitions)} -> "
            f"{len(self.net.places)}/{len(self.net.transitions)} places/transitions "
            f"({rules})"
        )


def reducible(net: Net) -> bool:
    """Only plain P/T semantics: operator inputs, capacities and priorities change
    what is enabled, and the rules' arguments do not cover them."""
    return not (
        has_inputs(net)
        or any(p.capacity is not None for p in net.places)
        or any(t.priority for t in net.transitions)
    )


def _expired(budget: Budget | None) -> bool:
    left = None if budget is None else budget.remaining()
    return left is not None and left <= 0


def reduce_net(
    net: Net,
    goal: Goal,
    *,
    budget: Budget | None = None,
    max_rounds: int = 100,
    lp_seconds: float = 0.0,
) -> Reduction:
    """Reduce ``net`` preserving ``goal``.

    Args:
        net: the original net (unchanged).
        goal: the property to preserve and what it observes.
        budget: once its deadline passes no further rule is started (the net reduced
            so far is returned: every rule is sound on its own).
        max_rounds: rounds of all rules at most.
        lp_seconds: above 0, the linear-programming implicit-place rule runs too, for
            at most this long in all (less when the budget has less left).
    """
    start = time.monotonic()
    if not reducible(net):
        ident: dict[str, tuple[str, ...]] = {t.name: (t.name,) for t in net.transitions}
        return Reduction(net, net, goal, ident, {}, time.monotonic() - start)
    w = WorkNet(net, goal)
    left = None if budget is None else budget.remaining()
    w.lp_deadline = start + (lp_seconds if left is None else min(lp_seconds, left / 4))
    rules = LP_RULES if lp_seconds > 0 else RULES
    for _ in range(max_rounds):
        changed = False
        for rule in rules:
            if _expired(budget):
                break
            changed = rule(w) or changed
        if not changed or _expired(budget):
            break
    seconds = time.monotonic() - start
    return Reduction(
        net,
        w.to_net(),
        goal,
        dict(w.expand),
        dict(w.applied),
        seconds,
        tuple(w.prefix),
        tuple(w.closers),
    )
