"""What a reduction must preserve: the property kind and what the property observes.

A rule may only touch what the property cannot see. `Goal` names the kind of question
(deadlock, reachability of a predicate, bounds of places) and the places and
transitions the question reads; those are *protected*: never removed, merged or fused.
"""

from __future__ import annotations

import enum
from collections.abc import Iterable
from dataclasses import dataclass


class Kind(enum.Enum):
    """The property a reduced net must answer exactly as the original."""

    DEADLOCK = "deadlock"
    """Whether some reachable marking enables no transition."""
    REACHABILITY = "reachability"
    """Whether some reachable marking satisfies a predicate over the protected places
    and the enabledness of the protected transitions (EF / AG questions)."""
    BOUNDS = "bounds"
    """The most tokens the protected places hold (sum over any subset of them)."""


@dataclass(frozen=True)
class Goal:
    """A property kind plus what it observes (names in the original net).

    For reachability, a protected transition's preset is protected too (see
    `observed_places`): its enabledness is then a function of protected places, which
    every rule keeps exactly.
    """

    kind: Kind
    places: frozenset[str] = frozenset()
    transitions: frozenset[str] = frozenset()

    @staticmethod
    def deadlock() -> Goal:
        """The deadlock question; it observes no place (deadness is global)."""
        return Goal(Kind.DEADLOCK)

    @staticmethod
    def reachability(places: Iterable[str] = (), transitions: Iterable[str] = ()) -> Goal:
        """A reachability question over ``places`` and the fireability of ``transitions``."""
        return Goal(Kind.REACHABILITY, frozenset(places), frozenset(transitions))

    @staticmethod
    def bounds(places: Iterable[str]) -> Goal:
        """Upper bounds of (sums over) ``places``."""
        return Goal(Kind.BOUNDS, frozenset(places))
