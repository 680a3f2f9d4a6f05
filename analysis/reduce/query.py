"""Reachability formulas and place bounds answered on the reduced net.

`coral-check query` asks these when its full search stopped undecided. The reduced net
keeps every observed place (by name, with the same values: see `Goal`) and every
observed transition with its preset, so a state formula over them reads the same on
both nets. A marking found on the reduced net is trusted only once its firing
sequence, expanded, replays on the original net and the formula (or the bound) holds
there too; otherwise the answer is undecided and the caller keeps its own.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from analysis.budget import Budget
from analysis.ctl import NetIndex, StateEvaluator
from analysis.reduce.deadlock import replay
from analysis.reduce.driver import Reduction, reduce_net, reducible
from analysis.reduce.goal import Goal
from analysis.statespace import explore
from coral_lang.formula import Deadlock, Formula, places_of, transitions_of, walk
from coral_lang.net import Net


@dataclass(frozen=True)
class ReducedAnswer:
    """A decided answer from the reduced net.

    Attributes:
        value: for reachability, whether a marking satisfying the target is reachable;
            for a bound, the largest sum reachable.
        trace: a firing sequence of the original net reaching the witness marking
            (for reachability, only when ``value`` is True).
        reduction: the reduction used (sizes and rules, for reports).
        states: markings stored while exploring the reduced net.
    """

    value: int | bool
    trace: tuple[str, ...] | None
    reduction: Reduction
    states: int


def _marking(net: Net, trace: Sequence[str]) -> npt.NDArray[np.int64] | None:
    reached = replay(net, trace)
    return None if reached is None else np.asarray([reached], dtype=np.int64)


def reach_by_reduction(
    net: Net, target: Formula, *, max_states: int | None = None, budget: Budget | None = None
) -> ReducedAnswer | None:
    """Whether some reachable marking of ``net`` satisfies the state formula ``target``,
    decided on the net reduced for it; None when undecided (not reducible, a deadlock
    atom, which every rule may change, or the reduced search stopped)."""
    if not reducible(net) or any(isinstance(f, Deadlock) for f in walk(target)):
        return None
    red = reduce_net(
        net, Goal.reachability(places_of(target), transitions_of(target)), budget=budget
    )
    index = NetIndex(red.net)
    hit: list[int] = []

    def stop_when(first: int, markings: npt.NDArray[np.int64]) -> bool:
        rows = np.flatnonzero(StateEvaluator(index, markings).sat(target))
        if rows.size:
            hit.append(first + int(rows[0]))
        return bool(rows.size)

    space = explore(red.net, max_states=max_states, budget=budget, stop_when=stop_when)
    if hit:
        trace = red.expand_trace(space.trace_names(hit[0]))
        marking = _marking(net, trace)
        if marking is None or not StateEvaluator(NetIndex(net), marking).sat(target)[0]:
            return None  # a rule is wrong for this formula: decide nothing
        return ReducedAnswer(True, tuple(trace), red, space.states)
    if space.complete:
        return ReducedAnswer(False, None, red, space.states)
    return None


def bound_by_reduction(
    net: Net, places: Sequence[str], *, max_states: int | None = None, budget: Budget | None = None
) -> ReducedAnswer | None:
    """The largest number of tokens ``places`` hold together in a reachable marking of
    ``net``, from the net reduced for their bounds; None unless the reduced search
    completes (and the marking reaching it replays with that sum)."""
    if not reducible(net):
        return None
    red = reduce_net(net, Goal.bounds(places), budget=budget)
    space = explore(red.net, max_states=max_states, budget=budget)
    if not space.complete:
        return None
    cols = [red.net.place_index(p) for p in places]
    best, state = -1, 0
    for first, block in space.iter_markings():
        sums = block[:, cols].sum(axis=1, dtype=np.int64)
        j = int(np.argmax(sums))
        if int(sums[j]) > best:
            best, state = int(sums[j]), first + j
    trace = red.expand_trace(space.trace_names(state))
    marking = _marking(net, trace)
    if marking is None:
        return None
    originals = [net.place_index(p) for p in places]
    if int(marking[0, originals].sum()) != best:
        return None
    return ReducedAnswer(best, tuple(trace), red, space.states)
