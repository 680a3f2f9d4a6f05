"""How the CORAL Engine chooses among enabled transitions (`Policy`).

Its own module so that command lines can offer the choice without importing the engine.
"""

from __future__ import annotations

import enum

__all__ = ["Policy"]


class Policy(enum.Enum):
    """How the engine chooses among enabled transitions.

    ``PRIORITY``: the highest ``priority`` first, then the earliest in source order (the
    order of the net's transitions): deterministic, what runs on the vehicle.
    ``RANDOM``: uniformly among the enabled transitions of the highest priority, from a
    seeded generator: for tests that must see every order analysis allowed.
    """

    PRIORITY = "priority"
    RANDOM = "random"
