"""Options of timed analysis: the link bounds assumed, and the budget."""

from __future__ import annotations

from dataclasses import dataclass

from coral_lang.timing import LinkBounds

__all__ = ["DEFAULT_TIMED_STATES", "TimedOptions"]

DEFAULT_TIMED_STATES = 200_000
"""Symbolic states explored before timed analysis gives up (inconclusive)."""


@dataclass(frozen=True)
class TimedOptions:
    """How to run timed analysis.

    Attributes:
        link: bounds on the one-way delay of every message (from a link profile).
        max_states: symbolic states explored before giving up (inconclusive).
        time_limit_s: seconds before giving up (inconclusive); None: no limit.
        memory_limit: bytes of resident memory of the process past which it gives up
            (inconclusive, the command's ``--memory-limit``); None: no limit.
        method: ``auto`` (``events`` when the mission's commands fall into independent
            groups, else ``clock``), ``events`` (event times with partial-order
            reduction; falls back to ``clock`` for a net whose places can hold two
            tokens) or ``clock`` (one global clock, every interleaving: the reference,
            slow with parallel branches). All give the same answers.
    """

    link: LinkBounds
    max_states: int = DEFAULT_TIMED_STATES
    time_limit_s: float | None = 60.0
    method: str = "auto"
    memory_limit: int | None = None
