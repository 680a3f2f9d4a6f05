"""The deadlock question answered on the reduced net, with the witness mapped back.

Random walks on the reduced net try first (`walk`: a few hundred steps, often enough
when the net blocks quickly), then the siphon-trap property (`siphon_trap`: a cheap
proof that no dead marking is reachable, when the enumeration is small); otherwise the
reduced net is explored (`analysis.statespace.explore`). A dead marking found either way
yields a firing sequence that is expanded (`Reduction.expand_trace`) and replayed on the
original net before it is trusted, so a witness is always checked on the net the user
gave.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from analysis.budget import Budget
from analysis.reduce.driver import Reduction, reduce_net, reducible
from analysis.reduce.goal import Goal, Kind
from analysis.reduce.siphon_trap import siphons_prove_deadlock_free
from analysis.reduce.walk import walk_to_deadlock
from analysis.statespace import explore
from coral_lang.net import Net

WITNESS_FAILED = "the reduced net's deadlock witness does not replay on the original net"
"""``stopped_reason`` when a mapped-back witness fails its replay (a reduction bug: the
caller falls back to the unreduced search rather than trust the verdict)."""

SIPHON_PROOF = (
    "siphon-trap property of the reduced net: every minimal siphon of the ordinary net "
    "contains an initially marked trap"
)
"""`DeadlockAnswer.proof` when `siphons_prove_deadlock_free` decided."""

EARLY_STOP_TRANSITIONS = 2000
"""Nets with at most this many transitions stop at the first dead marking stored; the
check costs a numpy pass per transition and batch, more than it saves on wider nets."""


class _FirstDead:
    """A `explore` ``stop_when`` that stops at the first stored dead marking, so a net
    with a deadlock need not be explored in full (the witness is still shortest: states
    are stored in BFS order)."""

    def __init__(self, net: Net) -> None:
        self.presets = [
            (
                np.array([net.place_index(p) for p, _ in t.inputs], dtype=np.int64),
                np.array([w for _, w in t.inputs], dtype=np.int64),
            )
            for t in net.transitions
        ]
        self.found: int | None = None

    def __call__(self, first: int, markings: npt.NDArray[np.integer]) -> bool:
        # Only markings no transition so far enables are tested against the next one,
        # so the cost falls with every transition instead of staying rows x width.
        rows = np.arange(markings.shape[0])
        for cols, weights in self.presets:
            if not cols.size:
                return False  # a transition with no input is always enabled
            rows = rows[~(markings[np.ix_(rows, cols)] >= weights).all(axis=1)]
            if not rows.size:
                return False
        self.found = first + int(rows[0])
        return True


@dataclass(frozen=True)
class DeadlockAnswer:
    """Verdict of `decide_deadlock`."""

    deadlock: bool | None
    """True/False when decided; None when the search on the reduced net stopped."""
    trace: list[str] | None
    """With ``deadlock``: a firing sequence of the original net reaching a dead marking."""
    reduction: Reduction
    states: int
    """Markings stored while exploring the reduced net (0 when a random walk found the
    dead marking and no search ran)."""
    stopped_reason: str | None = None
    proof: str | None = None
    """When ``deadlock`` is False without a search (``states`` 0): what proved it."""
    by: str = "search"
    """What decided: ``"search"`` (the reduced net explored), ``"random walk"`` (a walk
    reached the dead marking) or ``"siphon-trap"`` (`proof`)."""


def replay(net: Net, trace: Sequence[str]) -> list[int] | None:
    """The marking ``trace`` reaches in ``net``, or None if some step is not enabled
    (the net's own firing rule: `Net.enabled`, `Net.fire`)."""
    marking = net.initial_marking()
    for name in trace:
        t = net.transition(name)
        if not net.enabled(marking, t):
            return None
        marking = net.fire(marking, t)
    return list(marking)


MAX_CLOSING_FIRINGS = 100_000
"""Closer firings at most when completing a witness (each only drains its private
inputs, so this is never reached on a net the rule applied to)."""


def dead_witness(net: Net, red: Reduction, reduced: Sequence[str]) -> list[str] | None:
    """The firing sequence of ``net`` for a dead marking the reduced net reaches by
    ``reduced``: expanded, replayed, then completed by firing the reduction's closers
    while enabled (last recorded first); None unless it ends in a dead marking of
    ``net`` (a rule would be wrong: the caller decides nothing)."""
    trace = red.expand_trace(reduced)
    reached = replay(net, trace)
    if reached is None:
        return None
    marking = tuple(reached)
    fired = 0
    for closer in reversed(red.closers):
        while fired < MAX_CLOSING_FIRINGS:
            after = marking
            for name in closer:
                t = net.transition(name)
                if not net.enabled(after, t):
                    break
                after = net.fire(after, t)
            else:
                marking, fired = after, fired + 1
                trace.extend(closer)
                continue
            break
    return trace if is_dead(net, marking) else None


def is_dead(net: Net, marking: Sequence[int]) -> bool:
    """Whether ``marking`` enables no transition of ``net``."""
    reached = tuple(marking)
    return not any(net.enabled(reached, t) for t in net.transitions)


def decide_deadlock(
    net: Net,
    *,
    max_states: int | None = None,
    budget: Budget | None = None,
    reduction: Reduction | None = None,
    accepted: Callable[[Sequence[int]], bool] | None = None,
) -> DeadlockAnswer:
    """Reduce ``net`` for the deadlock question, explore, and map the answer back.

    ``budget`` bounds the reduction and the search; a net with operator inputs is not
    reduced, and its dead states are found by `explore`'s own rule (terminal states).

    ``accepted`` (a predicate on markings of ``net``) names dead markings that are no
    deadlock, such as a mission's declared final markings: only a dead marking it
    rejects is a witness. It reads the original marking the replay reaches, so the
    caller must protect every place it reads (see `final_goal`): the rules then keep
    those places' values at every dead marking.
    """
    if accepted is not None:
        return _decide_unaccepted(net, accepted, max_states, budget, reduction)
    red = reduction or reduce_net(net, Goal.deadlock(), budget=budget)
    walked = walk_to_deadlock(red.net) if reducible(net) else None
    if walked is not None:
        trace = dead_witness(net, red, walked)
        if trace is not None:
            return DeadlockAnswer(True, trace, red, 0, by="random walk")
    if reducible(net) and siphons_prove_deadlock_free(red.net, budget):
        return DeadlockAnswer(False, None, red, 0, proof=SIPHON_PROOF, by="siphon-trap")
    early = reducible(net) and len(red.net.transitions) <= EARLY_STOP_TRANSITIONS
    first_dead = _FirstDead(red.net) if early else None
    space = explore(red.net, max_states=max_states, budget=budget, stop_when=first_dead)
    dead = first_dead.found if first_dead is not None else None
    if dead is None and space.deadlocks.size:
        dead = int(space.deadlocks[0])
    if dead is not None:
        trace = dead_witness(net, red, space.trace_names(dead))
        if trace is None:  # a rule is wrong: say so, decide nothing
            return DeadlockAnswer(None, None, red, space.states, WITNESS_FAILED)
        return DeadlockAnswer(True, trace, red, space.states)
    if space.complete:
        return DeadlockAnswer(False, None, red, space.states)
    return DeadlockAnswer(None, None, red, space.states, space.stopped_reason)


DEAD_REPLAYS = 10_000
"""Dead markings of the reduced net replayed at most when looking for one that is not
accepted (each replay costs the trace's length); past it the answer is undecided."""


def final_goal(net: Net) -> Goal:
    """The deadlock goal of a net whose declared final markings are no deadlock: a final
    constrains every place it does not leave free (`Net.final_test`), so all those are
    protected. The rules that drop a place whose value may differ between dead markings
    (implicit and sink places) then keep them; the series rules still apply, since the
    places they remove are empty in every dead marking of the original, so the replayed
    witness has the original's dead marking exactly and the predicate reads it there."""
    columns = net.final_test().columns if net.finals else ()
    return Goal(Kind.DEADLOCK, frozenset(net.places[i].name for i in columns))


def _decide_unaccepted(
    net: Net,
    accepted: Callable[[Sequence[int]], bool],
    max_states: int | None,
    budget: Budget | None,
    reduction: Reduction | None,
) -> DeadlockAnswer:
    """`decide_deadlock` where some dead markings are accepted: the whole reduced space
    is explored (the first dead marking may be an accepted one) and its dead markings
    replayed on ``net`` in BFS order until one is not accepted."""
    red = reduction or reduce_net(net, final_goal(net), budget=budget)
    space = explore(red.net, max_states=max_states, budget=budget)
    for replayed, state in enumerate(space.deadlocks):
        if replayed >= DEAD_REPLAYS:
            reason = f"more than {DEAD_REPLAYS} dead markings to replay"
            return DeadlockAnswer(None, None, red, space.states, reason)
        trace = dead_witness(net, red, space.trace_names(int(state)))
        reached = None if trace is None else replay(net, trace)
        if trace is None or reached is None:
            return DeadlockAnswer(None, None, red, space.states, WITNESS_FAILED)
        if not accepted(reached):
            return DeadlockAnswer(True, trace, red, space.states)
    if space.complete:
        return DeadlockAnswer(False, None, red, space.states)
    return DeadlockAnswer(None, None, red, space.states, space.stopped_reason)
