"""The mutable net the rules rewrite, and what it remembers to map answers back.

Arcs are kept sparse (transition -> {place: weight} both ways, plus the reverse
indexes), so every rule costs what it touches, never places x transitions. Each
transition of the working net remembers the sequence of original transitions it
stands for: a firing sequence of the reduced net expands into one of the original.
"""

from __future__ import annotations

from collections import defaultdict

from analysis.reduce.goal import Goal, Kind
from coral_lang.net import Net, Place, Transition

Arcs = dict[str, dict[str, int]]


class WorkNet:
    """A place/transition net under reduction (names are the original ones)."""

    def __init__(self, net: Net, goal: Goal) -> None:
        self.name = net.name
        self.goal = goal
        self.initial: dict[str, int] = {p.name: p.initial for p in net.places}
        self.pre: Arcs = {t.name: dict(t.inputs) for t in net.transitions}
        self.post: Arcs = {t.name: dict(t.outputs) for t in net.transitions}
        self.expand: dict[str, tuple[str, ...]] = {t.name: (t.name,) for t in net.transitions}
        self.prefix: list[str] = []
        self.closers: list[tuple[str, ...]] = []
        """Original sequences a dead marking of the reduced net may still enable in the
        original (`pre_agglomerate`); a witness fires them while enabled, last first."""
        """Original transitions fired before any reduced one (the working net's initial
        marking is the one they reach in the original)."""
        self.consumers: defaultdict[str, set[str]] = defaultdict(set)
        self.producers: defaultdict[str, set[str]] = defaultdict(set)
        for t in net.transitions:
            for p, _ in t.inputs:
                self.consumers[p].add(t.name)
            for p, _ in t.outputs:
                self.producers[p].add(t.name)
        self.protected_places = set(goal.places)
        self.protected_transitions = set(goal.transitions)
        if goal.kind is Kind.REACHABILITY:
            for name in goal.transitions:
                self.protected_places.update(self.pre.get(name, {}))
        self.lp_deadline: float | None = None
        """`time.monotonic` past which the linear-programming rule tries no place."""
        self.lp_tried: set[str] = set()
        """Places the linear-programming rule has tried (each once per reduction)."""
        self.applied: defaultdict[str, int] = defaultdict(int)
        """How many times each rule fired, by rule name (for reports and the bench)."""

    # -- edits ---------------------------------------------------------------------------

    def remove_transition(self, t: str) -> None:
        """Drop ``t`` and its arcs."""
        for p in self.pre.pop(t):
            self.consumers[p].discard(t)
        for p in self.post.pop(t):
            self.producers[p].discard(t)
        del self.expand[t]

    def remove_place(self, p: str) -> None:
        """Drop ``p`` and every arc to or from it (the caller proved it irrelevant)."""
        for t in self.consumers.pop(p, set()):
            del self.pre[t][p]
        for t in self.producers.pop(p, set()):
            del self.post[t][p]
        del self.initial[p]

    def add_transition(
        self, name: str, pre: dict[str, int], post: dict[str, int], expand: tuple[str, ...]
    ) -> str:
        """Add a transition (renamed if ``name`` is taken) and return its name."""
        base, k = name, 1
        while name in self.pre:
            name, k = f"{base}#{k}", k + 1
        self.pre[name] = dict(pre)
        self.post[name] = dict(post)
        self.expand[name] = expand
        for p in pre:
            self.consumers[p].add(name)
        for p in post:
            self.producers[p].add(name)
        return name

    def set_post(self, t: str, p: str, weight: int) -> None:
        """Set the weight of arc ``t -> p`` (0 removes it)."""
        if weight:
            self.post[t][p] = weight
            self.producers[p].add(t)
        else:
            self.post[t].pop(p, None)
            self.producers[p].discard(t)

    # -- output --------------------------------------------------------------------------

    def to_net(self) -> Net:
        """The current net as a `Net` (places and transitions in a stable order)."""
        places = tuple(Place(name=p, initial=m) for p, m in self.initial.items())
        transitions = tuple(
            Transition(
                name=t,
                inputs=tuple(sorted(self.pre[t].items())),
                outputs=tuple(sorted(self.post[t].items())),
            )
            for t in self.pre
        )
        return Net(name=self.name, places=places, transitions=transitions)
