"""Saturation-style fixpoint: transitions grouped by the top level of their support,
the groups closed bottom-up, and every lower group closed again as soon as a higher
one adds markings.

Ciardo, Luettgen and Siminiceanu, "Saturation: an efficient iteration strategy for
symbolic state-space generation" (TACAS 2001) fire the events of each level to a local
fixpoint on the diagram's nodes, bottom level first, re-saturating the levels below
whenever a firing at a higher level creates new nodes. Here the same schedule runs on
whole sets with CUDD's relational product: the invariant is that the reached set is
closed under every group below the current one, so a group at the top only ever sees
markings whose lower parts are already saturated. A breadth-first or chained sweep
instead carries every partial marking through every level at once, and its frontiers
grow far beyond the final set (Dekker-PT-015: 323,000 nodes after two sweeps, no
fixpoint in 20 s).

Each group remembers the reached set it was last closed at, and only the markings
added since are its frontier, so returning to a group costs what is new to it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from analysis.symbolic.explore import SymbolicNet, _Transition

Bdd = Any


def groups_by_top(transitions: Sequence[_Transition]) -> list[list[_Transition]]:
    """The transitions grouped by their top level, the bottom-most group first."""
    by_top: dict[int, list[_Transition]] = {}
    for t in transitions:
        by_top.setdefault(t.top, []).append(t)
    return [by_top[top] for top in sorted(by_top, reverse=True)]


class Saturation:
    """One saturation run. `step(t, frontier)` is the caller's hook before each
    image (overflow detection, budgets): it returns a reason to stop, or None."""

    def __init__(
        self,
        sym: SymbolicNet,
        step: Callable[[_Transition, Bdd], str | None],
    ) -> None:
        self.sym = sym
        self.step = step
        self.groups = groups_by_top(sym.transitions)
        self.images = 0
        self.rounds = 0

    def run(self, initial: Bdd) -> tuple[Bdd, str | None]:
        """The markings reachable from `initial` (closed under every transition), or
        the markings found so far and the reason a budget stopped the run.

        After a group adds markings, the walk restarts at the lowest group whose
        support meets the places that group changes (saturation's event locality:
        the others cannot newly fire where nothing they read changed, so their turn
        can wait and take the new markings in one batch). Whatever the schedule, the
        run ends only when a full scan finds every group closed at the reached set."""
        false = self.sym.bdd.false
        reached = initial
        closed_at = [false] * len(self.groups)
        supports = [set().union(*(t.support for t in g)) for g in self.groups]
        changes = [set().union(*(t.changed for t in g)) for g in self.groups]
        i = 0
        while True:
            while i < len(self.groups):
                frontier = reached & ~closed_at[i]
                if frontier == false:
                    i += 1
                    continue
                self.rounds += 1
                before = reached
                reached, reason = self._close(self.groups[i], reached, frontier)
                closed_at[i] = reached
                if reason is not None:
                    return reached, reason
                if reached == before:
                    i += 1
                    continue
                touched = changes[i]
                i = next((j for j in range(i) if supports[j] & touched), i + 1)
            # the final scan: every group closed at the reached set
            i = next(
                (j for j in range(len(self.groups)) if (reached & ~closed_at[j]) != false),
                len(self.groups),
            )
            if i == len(self.groups):
                return reached, None

    def _close(
        self, group: list[_Transition], reached: Bdd, frontier: Bdd
    ) -> tuple[Bdd, str | None]:
        """Close `reached` under `group`, starting from the markings `frontier` the group
        has not yet been applied to; chained inside the group (what one transition adds
        is at once the frontier of the next)."""
        sym = self.sym
        false = sym.bdd.false
        while frontier != false:
            added = false
            for t in group:
                self.images += 1
                reason = self.step(t, frontier)
                if reason is not None:
                    return reached, reason
                new = sym.image(frontier, t) & ~reached
                if new != false:
                    reached |= new
                    frontier |= new
                    added |= new
            frontier = added
        return reached, None
