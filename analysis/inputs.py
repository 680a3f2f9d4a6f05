"""Operator inputs in analysis: when the run stops, and traces that respect it.

A mission's operator inputs (``input abort_requested``, see ``docs/language.md``) are
INPUT transitions the operator may fire at most once each, but only while the run is
on: while some engine (plain, command) or reply transition is enabled. A marking where
none is enabled is *terminal*: the runtime has stopped there, so an input still armed
cannot fire, and a terminal marking that is not final is a deadlock.

The explorer stays a plain P/T explorer, because the rule changes no reachable
marking except when the initial marking itself is terminal (`analysis.statespace`
handles that case): if input ``i`` fires at a terminal ``M`` reached by a last
non-input step ``t`` from ``M'``, then ``i`` was enabled at ``M'`` (its armed place
is consumed by ``i`` alone) and ``t`` stays enabled after ``i`` (adding tokens never
disables, and ``t`` does not read the armed place), so ``M' -i-> -t-> M`` reaches the
same marking with ``i`` fired while the run was on. What changes is which markings
are dead (`terminal_rows`), which edges leave them (none: `analysis.stategraph`), and
the order of steps in a trace the P/T search found (`legal_trace` applies the swap
above until every input fires while the run is on).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from coral_lang.net import Net, Transition, TransitionKind

BoolArray = npt.NDArray[np.bool_]
IntArray = npt.NDArray[np.int64]


def input_flags(net: Net) -> BoolArray:
    """Per transition of ``net``, whether it is an operator input."""
    return np.array([t.kind is TransitionKind.INPUT for t in net.transitions], dtype=np.bool_)


def has_inputs(net: Net) -> bool:
    """Whether ``net`` has operator inputs (INPUT transitions; by kind, since a net built
    by hand may leave ``operator_input`` unset, where `Net.inputs` would miss them)."""
    return any(t.kind is TransitionKind.INPUT for t in net.transitions)


def _enabled_rows(net: Net, block: npt.NDArray[np.integer], t: Transition) -> BoolArray:
    """Which rows of ``block`` (markings, ``(n, places)``) enable ``t``."""
    ok = np.ones(int(block.shape[0]), dtype=np.bool_)
    for place, weight in t.inputs:
        ok &= block[:, net.place_index(place)] >= weight
    return ok


def terminal_rows(net: Net, block: npt.NDArray[np.integer]) -> BoolArray:
    """Which rows of ``block`` (markings, ``(n, places)``) are terminal: no transition
    other than an operator input is enabled there."""
    live = np.zeros(int(block.shape[0]), dtype=np.bool_)
    for t in net.transitions:
        if t.kind is not TransitionKind.INPUT:
            live |= _enabled_rows(net, block, t)
    return ~live


def input_edges_at(net: Net, block: npt.NDArray[np.integer], terminal: BoolArray) -> int:
    """How many (marking, enabled input) pairs of ``block`` sit at a ``terminal`` row:
    the P/T edges the run rule removes."""
    return sum(
        int((terminal & _enabled_rows(net, block, t)).sum())
        for t in net.transitions
        if t.kind is TransitionKind.INPUT
    )


def legal_trace(net: Net, trace: Sequence[int]) -> list[int] | None:
    """``trace`` (transition indices from the initial marking, fireable as a P/T
    sequence) reordered so that every operator input fires while the run is on; it
    reaches the same marking in the same number of steps. Each input fired at a
    terminal marking moves before the step that led there (see the module docstring),
    repeatedly. ``None`` when that is impossible: an input fires first and the initial
    marking is terminal (then no input can ever fire)."""
    steps = list(trace)
    if not has_inputs(net):
        return steps
    k = 0
    markings = [net.initial_marking()]
    while k < len(steps):
        transition = net.transitions[steps[k]]
        here = markings[k]
        if transition.kind is TransitionKind.INPUT and not net.runs_on(here):
            if k == 0:
                return None
            steps[k - 1], steps[k] = steps[k], steps[k - 1]
            del markings[k:]
            k -= 1
            continue
        markings.append(net.fire(here, transition))
        k += 1
    return steps
