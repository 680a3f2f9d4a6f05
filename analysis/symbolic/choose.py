"""Which method `verify` should use for a net: explicit search or decision diagrams."""

from __future__ import annotations

from typing import Literal

from analysis.symbolic.report import symbolic_applicable
from coral_lang.net import Net

Method = Literal["explicit", "symbolic"]

EXPLICIT_BUDGET_STATES = 20_000_000
"""About what the explicit explorer stores in a few GiB at today's bytes per state."""


def state_estimate(net: Net) -> float:
    """A crude upper estimate of reachable markings: the product over places of
    (bound + 1), bounding each place by the total of the initial tokens when every
    transition conserves tokens, else infinity. Cheap and structural; only its order
    of magnitude is used."""
    total = sum(p.initial for p in net.places)
    for tr in net.transitions:
        if sum(w for _, w in tr.outputs) > sum(w for _, w in tr.inputs):
            return float("inf")
    estimate = 1.0
    for _ in net.places:
        estimate *= total + 1
        if estimate > 1e300:
            return float("inf")
    return estimate


def choose_method(net: Net, *, explicit_budget: int = EXPLICIT_BUDGET_STATES) -> Method:
    """Recommended rule: symbolic when the net is a plain P/T net (no mission INPUT
    transitions, whose engine-specific firing rule only the explicit explorer models)
    that conserves tokens and whose structural estimate exceeds what the explicit
    search can store; explicit otherwise (it gives shortest traces and every
    examination). `--method auto` keeps explicit today; this is the rule to switch to.
    """
    if not symbolic_applicable(net):
        return "explicit"
    estimate = state_estimate(net)
    if estimate != float("inf") and estimate > explicit_budget:
        return "symbolic"
    return "explicit"
