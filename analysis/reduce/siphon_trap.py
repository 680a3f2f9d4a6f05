"""Deadlock-freedom of the reduced net by the siphon-trap property, before any search.

Argument (Commoner's; see `analysis.siphons`): in an *ordinary* net (every arc weight 1)
the places empty at a dead marking form a siphon (every transition has an empty input,
so every transition feeding the set also takes from it). A trap that is marked stays
marked. So if every minimal siphon contains an initially marked trap, no reachable
marking is dead. On the reduced net this decides the original: the reduction preserves
whether a dead marking is reachable.

The enumeration of minimal siphons can be exponential, so it is tried with a small work
cap (larger on wide nets, whose searches are long anyway): it decides the nets where it
is cheap (Dekker's mutual exclusion: 20 minimal siphons, a few milliseconds, where the
search stores thousands of markings) and costs the others a few milliseconds before
their search.
"""

from __future__ import annotations

from analysis.budget import Budget
from analysis.siphons import siphon_trap_check
from coral_lang.net import Net

SIPHON_BRANCHES = 100
"""Partial sets the siphon enumeration may visit (its work cap)..."""
SIPHON_SECONDS = 0.05
"""...and its time cap."""
WIDE = 400
"""Reduced nets with at least this many transitions get ten times both caps: their
searches are long anyway (Dekker-PT-020, 440 transitions, needs about 300 partial sets
and has 1.2e9 edges)."""


def siphons_prove_deadlock_free(net: Net, budget: Budget | None = None) -> bool:
    """True when ``net`` is ordinary and every minimal siphon (all of them found within
    the caps) contains an initially marked trap: then no reachable marking is dead
    (`analysis.siphons.siphon_trap_check`, with small caps)."""
    if not net.transitions or any(
        w != 1 for t in net.transitions for _, w in (*t.inputs, *t.outputs)
    ):
        return False  # (checked first: a weighted net is not worth the enumeration)
    scale = 10 if len(net.transitions) >= WIDE else 1
    left = None if budget is None else budget.remaining()
    seconds = scale * SIPHON_SECONDS if left is None else min(scale * SIPHON_SECONDS, left / 4)
    check = siphon_trap_check(net, scale * SIPHON_BRANCHES, Budget(seconds))
    return check.proves_deadlock_free
