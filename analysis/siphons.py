"""Siphons, traps and the siphon-trap (Commoner) property.

A *siphon* S is a set of places with •S ⊆ S•: every transition that puts tokens into S
also takes from S, so once S is empty it stays empty. A *trap* Q has Q• ⊆ •Q: every
transition that takes from Q puts back into Q, so once Q is marked it stays marked.

The siphon-trap property (every minimal siphon contains a trap that is marked
initially) proves deadlock-freedom for *ordinary* nets: at a dead marking of an
ordinary net the empty places form a siphon, and that siphon would contain a trap that
can never be emptied. For free-choice nets it is Commoner's theorem and proves liveness.
For weighted nets it is no proof at all: a transition can be dead while all its input
places hold tokens (too few). `siphon_trap_check` says which case applies.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from collections.abc import Set as AbstractSet
from dataclasses import dataclass

from analysis.budget import Budget, stage, work_limit_reason
from analysis.structural import classify
from coral_lang.net import Net

DEFAULT_MAX_BRANCHES = 100_000
DEFAULT_TIME_LIMIT = 10.0


class _Arcs:
    """Index sets of a net: input/output places of each transition and vice versa."""

    def __init__(self, net: Net) -> None:
        self.n_places = len(net.places)
        self.t_in = [frozenset(net.place_index(p) for p, _ in t.inputs) for t in net.transitions]
        self.t_out = [frozenset(net.place_index(p) for p, _ in t.outputs) for t in net.transitions]
        producers: list[set[int]] = [set() for _ in net.places]
        consumers: list[set[int]] = [set() for _ in net.places]
        for t, (ins, outs) in enumerate(zip(self.t_in, self.t_out, strict=True)):
            for p in ins:
                consumers[p].add(t)
            for p in outs:
                producers[p].add(t)
        self.producers = [frozenset(s) for s in producers]  # •p
        self.consumers = [frozenset(s) for s in consumers]  # p•


def is_siphon(net: Net, places: Iterable[str]) -> bool:
    """Whether ``places`` is a siphon (•S ⊆ S•). The empty set counts as one."""
    arcs = _Arcs(net)
    s = {net.place_index(p) for p in places}
    return all(arcs.t_in[t] & s for p in s for t in arcs.producers[p])


def is_trap(net: Net, places: Iterable[str]) -> bool:
    """Whether ``places`` is a trap (Q• ⊆ •Q). The empty set counts as one."""
    arcs = _Arcs(net)
    q = {net.place_index(p) for p in places}
    return all(arcs.t_out[t] & q for p in q for t in arcs.consumers[p])


def _max_trap(arcs: _Arcs, places: Iterable[int]) -> frozenset[int]:
    trap = set(places)
    _prune_trap(arcs, trap, list(trap))
    return frozenset(trap)


def _max_siphon(arcs: _Arcs, places: Iterable[int]) -> frozenset[int]:
    siphon = set(places)
    _prune_siphon(arcs, siphon, list(siphon))
    return frozenset(siphon)


def _prune_trap(arcs: _Arcs, trap: set[int], suspects: list[int]) -> None:
    """Shrink ``trap`` in place to the largest trap inside it, given that only the
    places in ``suspects`` may violate the trap condition now.

    A worklist rather than repeated sweeps: dropping p can only break the places that
    feed a transition putting into p, so only those are looked at again. The cost is
    the arcs around what is dropped, not places x sweeps (a 5,000-place chain took
    minutes of sweeps)."""
    _largest_inside(trap, suspects, arcs.consumers, arcs.t_out, arcs.producers, arcs.t_in)


def _prune_siphon(arcs: _Arcs, siphon: set[int], suspects: list[int]) -> None:
    """The dual of `_prune_trap`: shrink ``siphon`` in place to the largest siphon
    inside it; dropping p can only break the outputs of transitions taking from p."""
    _largest_inside(siphon, suspects, arcs.producers, arcs.t_in, arcs.consumers, arcs.t_out)


def _largest_inside(
    kept: set[int],
    suspects: list[int],
    guards: Sequence[Iterable[int]],
    guard_side: Sequence[AbstractSet[int]],
    feeders: Sequence[Iterable[int]],
    feeder_side: Sequence[AbstractSet[int]],
) -> None:
    """The worklist both prunings share: a place p stays while every transition of
    ``guards[p]`` has a place of ``guard_side[t]`` kept; dropping it puts the kept
    places of ``feeder_side[t]``, for each ``t`` of ``feeders[p]``, back on the list.
    For traps the guards are p's consumers and their outputs; for siphons, p's
    producers and their inputs."""
    while suspects:
        p = suspects.pop()
        if p not in kept:
            continue
        if any(guard_side[t].isdisjoint(kept) for t in guards[p]):
            kept.discard(p)
            for t in feeders[p]:
                suspects.extend(feeder_side[t] & kept)


def maximal_trap(net: Net, places: Iterable[str]) -> frozenset[str]:
    """The largest trap inside ``places`` (possibly empty).

    Fixpoint: drop a place if some transition takes from it without putting back into
    the remaining set. Traps are closed under union, so the result contains every trap
    inside ``places``.

    Args:
        net: The net.
        places: Candidate place names.

    Returns:
        The names of the maximal trap.
    """
    arcs = _Arcs(net)
    trap = _max_trap(arcs, (net.place_index(p) for p in places))
    return frozenset(net.places[i].name for i in trap)


def maximal_siphon(net: Net, places: Iterable[str]) -> frozenset[str]:
    """The largest siphon inside ``places`` (possibly empty), by the dual fixpoint."""
    arcs = _Arcs(net)
    siphon = _max_siphon(arcs, (net.place_index(p) for p in places))
    return frozenset(net.places[i].name for i in siphon)


@dataclass(frozen=True)
class SiphonEnumeration:
    """Minimal siphons found by a bounded search.

    Attributes:
        siphons: Minimal siphons as sorted tuples of place names, deterministic order.
        complete: True if the search finished: the list is every minimal siphon.
        reason: Why it stopped early, empty when complete.
    """

    siphons: tuple[tuple[str, ...], ...]
    complete: bool
    reason: str = ""
    method: str = "minimal siphons (branching search)"

    def explain(self) -> str:
        """One line: how many, and whether the list is complete."""
        tail = "" if self.complete else f" (incomplete: {self.reason})"
        return f"{len(self.siphons)} minimal siphon(s){tail}"


def minimal_siphons(
    net: Net,
    max_branches: int = DEFAULT_MAX_BRANCHES,
    budget: Budget | None = None,
) -> SiphonEnumeration:
    """Enumerate the minimal siphons of ``net``.

    For each place p, grow a set from {p}: pick a transition that feeds the set without
    taking from it, and branch over which of its input places joins the set, using only
    places after p in net order. Every minimal siphon is reached from its first place by
    one branch (it must contain an input of each transition feeding it), so the search is
    exhaustive when it finishes. Siphons found are shrunk to minimal ones and
    deduplicated.

    Args:
        net: The net.
        max_branches: Stop after exploring this many partial sets.
        budget: Bounds the time (default: `DEFAULT_TIME_LIMIT` seconds from now).

    Returns:
        A `SiphonEnumeration`; ``complete`` says whether the list is exhaustive.
    """
    arcs = _Arcs(net)
    budget = stage(budget, DEFAULT_TIME_LIMIT)
    found: set[frozenset[int]] = set()
    seen: set[frozenset[int]] = set()
    branches = 0
    complete, reason = True, ""
    # Any siphon made of places from ``start`` on lies inside their maximal siphon,
    # ``allowed``; it is shrunk from one start to the next rather than recomputed (the
    # largest siphon inside a subset lies inside the largest one of the set), so all
    # starts together cost about the arcs once, not places x arcs.
    allowed = set(range(arcs.n_places))
    _prune_siphon(arcs, allowed, list(allowed))
    for start in range(arcs.n_places):
        if start:
            allowed.discard(start - 1)
            _prune_siphon(
                arcs, allowed, [q for t in arcs.consumers[start - 1] for q in arcs.t_out[t]]
            )
        if budget.expired():
            complete, reason = False, budget.time_reason(branches, "partial set")
            break
        if start not in allowed:
            continue
        stack = [frozenset([start])]
        while stack:
            current = stack.pop()
            if current in seen or any(f <= current for f in found):
                continue
            seen.add(current)
            branches += 1
            if branches > max_branches:
                complete, reason = False, work_limit_reason(max_branches, "partial set")
                break
            if branches % 256 == 0 and budget.expired():
                complete, reason = False, budget.time_reason(branches, "partial set")
                break
            choices = _branching(arcs, current, allowed)
            if choices is None:
                found.add(_shrink(arcs, current))
                continue
            for p in sorted(choices, reverse=True):
                stack.append(current | {p})
        if not complete:
            break
    minimal = [s for s in found if not any(o < s for o in found)]
    names = sorted(tuple(sorted(net.places[i].name for i in s)) for s in minimal)
    return SiphonEnumeration(siphons=tuple(names), complete=complete, reason=reason)


def _branching(
    arcs: _Arcs, current: frozenset[int], allowed: AbstractSet[int]
) -> frozenset[int] | None:
    """The places to branch on: the allowed inputs of the transition that feeds
    ``current`` without taking from it and has the fewest of them. None if no transition
    feeds ``current`` that way (it is a siphon); empty if one has no allowed input (no
    siphon within ``allowed`` extends ``current``; siphons with places before the
    search's start were found from those places)."""
    best: frozenset[int] | None = None
    for p in sorted(current):
        for t in sorted(arcs.producers[p]):
            if arcs.t_in[t] & current:
                continue
            options = arcs.t_in[t] & allowed
            if best is None or len(options) < len(best):
                best = options
                if not best:
                    return best
    return best


def _shrink(arcs: _Arcs, siphon: frozenset[int]) -> frozenset[int]:
    """A minimal siphon inside ``siphon``: drop places while a siphon remains."""
    current = siphon
    shrunk = True
    while shrunk:
        shrunk = False
        for p in sorted(current):
            inner = _max_siphon(arcs, current - {p})
            if inner:
                current = inner
                shrunk = True
                break
    return current


@dataclass(frozen=True)
class SiphonTrapCheck:
    """The siphon-trap property and what it proves for this net.

    Attributes:
        holds: True if every minimal siphon contains an initially marked trap; False if
            some minimal siphon does not (``failing`` names it); None if the siphon
            enumeration was cut off before a failure was found.
        failing: A minimal siphon with no initially marked trap inside, if any.
        proves_deadlock_free: True only when ``holds`` and the net is ordinary (and has
            transitions): then no reachable marking is dead.
        proves_live: True only when ``holds`` and the net is (extended) free-choice
            (Commoner's theorem).
        scope: The sentence a report should print about what was proven.
        siphons: The enumeration the check used.
    """

    holds: bool | None
    failing: tuple[str, ...] | None
    proves_deadlock_free: bool
    proves_live: bool
    scope: str
    siphons: SiphonEnumeration
    method: str = "siphon-trap property (Commoner)"

    def explain(self) -> str:
        """One line a reviewer can check."""
        if self.holds:
            return f"every minimal siphon contains an initially marked trap: {self.scope}"
        if self.holds is False and self.failing is not None:
            return (
                f"siphon {{{', '.join(self.failing)}}} contains no initially marked trap: "
                f"{self.scope}"
            )
        return f"siphon-trap property undecided ({self.siphons.reason})"


def siphon_trap_check(
    net: Net,
    max_branches: int = DEFAULT_MAX_BRANCHES,
    budget: Budget | None = None,
) -> SiphonTrapCheck:
    """Check the siphon-trap property and state honestly what it proves.

    Args:
        net: The net.
        max_branches: Work bound for the siphon enumeration.
        budget: Bounds the time of the enumeration (see `minimal_siphons`).

    Returns:
        A `SiphonTrapCheck`.
    """
    enumeration = minimal_siphons(net, max_branches, budget)
    arcs = _Arcs(net)
    m0 = net.initial_marking()
    failing: tuple[str, ...] | None = None
    for names in enumeration.siphons:
        trap = _max_trap(arcs, (net.place_index(n) for n in names))
        if not any(m0[i] for i in trap):
            failing = names
            break
    holds: bool | None = False
    if failing is None:
        holds = True if enumeration.complete else None
    kind = classify(net)
    has_transitions = bool(net.transitions)
    deadlock_free = bool(holds) and kind.ordinary and has_transitions
    # Commoner's theorem holds for extended free-choice nets (which include free-choice).
    live = deadlock_free and kind.extended_free_choice
    if holds is False:
        scope = "no conclusion (the property is sufficient, not necessary, for deadlock-freedom)"
        if kind.extended_free_choice:
            scope = "the free-choice net is not live (Commoner), deadlock-freedom not decided"
    elif not holds:
        scope = "no conclusion"
    elif live:
        scope = "free-choice net: live, hence deadlock-free (Commoner's theorem)"
    elif deadlock_free:
        scope = "ordinary net: deadlock-free (liveness not implied: not free-choice)"
    elif not has_transitions:
        scope = "no conclusion: the net has no transitions, so every marking is dead"
    else:
        scope = (
            "weighted net: only a partial argument, not a proof of deadlock-freedom "
            "(a transition can be dead with tokens on all its input places)"
        )
    return SiphonTrapCheck(
        holds=holds,
        failing=failing,
        proves_deadlock_free=deadlock_free,
        proves_live=live,
        scope=scope,
        siphons=enumeration,
    )


__all__ = [
    "SiphonEnumeration",
    "SiphonTrapCheck",
    "is_siphon",
    "is_trap",
    "maximal_siphon",
    "maximal_trap",
    "minimal_siphons",
    "siphon_trap_check",
]
