"""Generated wide nets: many transitions, small state spaces.

Wide nets are where the cost of a method tracks places x transitions rather than the
states: a matrix or an enabling test over every transition. These nets make that cost
visible at sizes a test can afford, and `bench/wide.py` reuses them at bench sizes.
"""

from __future__ import annotations

from coral_lang.net import Net, Place, Transition


def rings(n_rings: int, length: int, spare_places: int = 0, idle: int = 0) -> Net:
    """``n_rings`` independent cycles of ``length`` places, one token each, plus
    ``spare_places`` unmarked places read by nothing and ``idle`` transitions that
    never fire (each takes from one of the ring places and from one empty place).

    Reachable markings: ``length ** n_rings``; every marking enables ``n_rings``
    transitions (``n_rings * length ** n_rings`` edges) and none is dead. The net has
    ``n_rings * length`` transitions, so enabling by scanning every transition costs
    ``length`` times what changes.
    """
    places: list[Place] = []
    transitions: list[Transition] = []
    for r in range(n_rings):
        places += [Place(f"r{r}p{k}", 1 if k == 0 else 0) for k in range(length)]
        transitions += [
            Transition(f"r{r}t{k}", ((f"r{r}p{k}", 1),), ((f"r{r}p{(k + 1) % length}", 1),))
            for k in range(length)
        ]
    places += [Place(f"spare{k}") for k in range(spare_places)]
    if idle:
        places.append(Place("empty"))
    transitions += [
        Transition(
            f"idle{k}",
            ((f"r{k % n_rings}p{k % length}", 1), ("empty", 1)),
            ((f"r{k % n_rings}p{(k + 1) % length}", 1),),
        )
        for k in range(idle)
    ]
    return Net(
        name=f"rings{n_rings}x{length}", places=tuple(places), transitions=tuple(transitions)
    )


def chain(length: int, spare_places: int = 0) -> Net:
    """One token along ``length`` transitions, ending in a dead marking, plus
    ``spare_places`` unmarked places read by nothing: ``length + 1`` markings,
    ``length`` edges, one deadlock (after firing every transition), every place
    bounded by 1."""
    places = [Place(f"p{k}", 1 if k == 0 else 0) for k in range(length + 1)]
    places += [Place(f"spare{k}") for k in range(spare_places)]
    transitions = [Transition(f"t{k}", ((f"p{k}", 1),), ((f"p{k + 1}", 1),)) for k in range(length)]
    return Net(name=f"chain{length}", places=tuple(places), transitions=tuple(transitions))


def parallel_rings(n_rings: int, length: int, copies: int) -> Net:
    """`rings` where each step of a ring is ``copies`` parallel transitions (the same
    arcs, different names): ``length ** n_rings`` markings, ``n_rings * length * copies``
    transitions, and every marking enables ``n_rings * copies`` of them."""
    places: list[Place] = []
    transitions: list[Transition] = []
    for r in range(n_rings):
        places += [Place(f"r{r}p{k}", 1 if k == 0 else 0) for k in range(length)]
        for k in range(length):
            arcs = ((f"r{r}p{k}", 1),), ((f"r{r}p{(k + 1) % length}", 1),)
            transitions += [Transition(f"r{r}t{k}c{c}", *arcs) for c in range(copies)]
    return Net(
        name=f"rings{n_rings}x{length}x{copies}",
        places=tuple(places),
        transitions=tuple(transitions),
    )


def count_rings(n_rings: int, length: int, tokens: int, idle: int = 0) -> Net:
    """`rings` with ``tokens`` tokens starting in the first place of each ring: the
    places are counts, not one-hot components, so enabling cannot be looked up by a
    component's value. ``idle`` transitions each take from a ring place and from an
    empty place, so they never fire.

    Reachable markings: ``C(length + tokens - 1, tokens) ** n_rings`` (the ways to put
    ``tokens`` tokens on ``length`` places, per ring); a marking enables one transition
    per marked ring place and none is dead.
    """
    places: list[Place] = []
    transitions: list[Transition] = []
    for r in range(n_rings):
        places += [Place(f"r{r}p{k}", tokens if k == 0 else 0) for k in range(length)]
        transitions += [
            Transition(f"r{r}t{k}", ((f"r{r}p{k}", 1),), ((f"r{r}p{(k + 1) % length}", 1),))
            for k in range(length)
        ]
    if idle:
        places.append(Place("empty"))
    transitions += [
        Transition(
            f"idle{k}",
            ((f"r{k % n_rings}p{(k // n_rings) % length}", 1), ("empty", 1)),
            ((f"r{k % n_rings}p{(k // n_rings + 1) % length}", 1),),
        )
        for k in range(idle)
    ]
    return Net(
        name=f"countrings{n_rings}x{length}x{tokens}",
        places=tuple(places),
        transitions=tuple(transitions),
    )
