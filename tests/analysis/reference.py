"""A plain, obviously-correct reachability explorer: the oracle for the fast ones.

Breadth-first over `Net.enabled`/`Net.fire` with a dict of markings. Slow on purpose:
every line can be checked by eye, so the vectorised explorer, coverability and the z3
state equation are tested against it on small nets.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

from coral_lang.net import Net

Marking = tuple[int, ...]


@dataclass
class ReferenceResult:
    """Everything the reference explorer learns about a small, bounded net."""

    states: list[Marking]
    edges: int  # (marking, enabled transition) pairs, as the MCC counts them
    dead: list[Marking]
    parent: dict[Marking, tuple[Marking, int] | None]
    complete: bool

    def trace_to(self, marking: Marking) -> list[int]:
        """Transition indices of the BFS (shortest) path from the initial marking."""
        path: list[int] = []
        step = self.parent[marking]
        while step is not None:
            previous, t = step
            path.append(t)
            step = self.parent[previous]
        return path[::-1]


def explore_reference(net: Net, max_states: int = 100_000) -> ReferenceResult:
    """Every reachable marking of ``net`` (up to ``max_states``), breadth first."""
    start = net.initial_marking()
    parent: dict[Marking, tuple[Marking, int] | None] = {start: None}
    order = [start]
    queue = deque([start])
    edges = 0
    dead: list[Marking] = []
    complete = True
    while queue:
        marking = queue.popleft()
        fired = False
        for t, transition in enumerate(net.transitions):
            if not net.enabled(marking, transition):
                continue
            fired = True
            edges += 1
            successor = net.fire(marking, transition)
            if successor not in parent:
                if len(parent) >= max_states:
                    complete = False
                    continue
                parent[successor] = (marking, t)
                order.append(successor)
                queue.append(successor)
        if not fired:
            dead.append(marking)
    return ReferenceResult(states=order, edges=edges, dead=dead, parent=parent, complete=complete)
