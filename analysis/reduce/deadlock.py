"""The deadlock question answered on the reduced net, with the witness mapped back.

The reduced net is explored (`analysis.statespace.explore`); a dead marking found
there yields a firing sequence that is expanded (`Reduction.expand_trace`) and
replayed on the original net before it is trusted, so a witness is always checked
on the net the user gave.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from analysis.budget import Budget
from analysis.reduce.driver import Reduction, reduce_net
from analysis.reduce.goal import Goal
from analysis.statespace import explore
from coral_lang.net import Net


@dataclass(frozen=True)
class DeadlockAnswer:
    """Verdict of `decide_deadlock`."""

    deadlock: bool | None
    """True/False when decided; None when the search on the reduced net stopped."""
    trace: list[str] | None
    """With ``deadlock``: a firing sequence of the original net reaching a dead marking."""
    reduction: Reduction
    states: int
    """Markings stored while exploring the reduced net."""
    stopped_reason: str | None = None


def replay(net: Net, trace: Sequence[str]) -> list[int] | None:
    """The marking ``trace`` reaches in ``net``, or None if some step is not enabled."""
    marking = [p.initial for p in net.places]
    for name in trace:
        t = net.transition(name)
        for p, w in t.inputs:
            i = net.place_index(p)
            if marking[i] < w:
                return None
            marking[i] -= w
        for p, w in t.outputs:
            marking[net.place_index(p)] += w
    return marking


def is_dead(net: Net, marking: Sequence[int]) -> bool:
    """Whether ``marking`` enables no transition of ``net``."""
    return not any(
        all(marking[net.place_index(p)] >= w for p, w in t.inputs) for t in net.transitions
    )


def decide_deadlock(
    net: Net,
    *,
    max_states: int | None = None,
    budget: Budget | None = None,
    reduction: Reduction | None = None,
) -> DeadlockAnswer:
    """Reduce ``net`` for the deadlock question, explore, and map the answer back."""
    red = reduction or reduce_net(net, Goal.deadlock())
    space = explore(red.net, max_states=max_states, budget=budget)
    if space.deadlocks.size:
        trace = red.expand_trace(space.trace_names(int(space.deadlocks[0])))
        reached = replay(net, trace)
        if reached is None or not is_dead(net, reached):
            raise AssertionError(f"reduced deadlock witness does not replay on {net.name}")
        return DeadlockAnswer(True, trace, red, space.states)
    if space.complete:
        return DeadlockAnswer(False, None, red, space.states)
    return DeadlockAnswer(None, None, red, space.states, space.stopped_reason)
