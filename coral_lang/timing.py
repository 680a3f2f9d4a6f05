"""The timing assumptions timed analysis proves under, as plain data.

Untimed analysis lets every reply come at any time; timed analysis
(``coral-check verify --timed``, `analysis.timed`) bounds the two things that take time
in a mission: the vehicle's work (the profile: `ProfileTiming` and each command's work
interval) and the link (`LinkBounds`, from a link profile). Both live here, beside the
profile, because the compiler, analysis and runtime all read them and ``coral_lang``
imports nothing of ours.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = [
    "DEFAULT_REPLY_LATENCY_S",
    "DEFAULT_TOLERANCE",
    "LinkBounds",
    "ProfileTiming",
]

DEFAULT_TOLERANCE = 0.2
"""Relative spread of a command's work time around its nominal ``duration_s`` when the
profile gives no interval of its own: [0.8, 1.2] x nominal (the generic simulated
vehicle's default spread)."""

DEFAULT_REPLY_LATENCY_S = 0.1
"""How late a vehicle may send a reply after it fell due: its polling period (the
generic vehicle and `runtime.vehicle.handlers.HandlerVehicle` poll every 0.1 s)."""


@dataclass(frozen=True)
class ProfileTiming:
    """A profile's ``timing`` block.

    Attributes:
        tolerance: default relative spread of work times, in [0, 1).
        reply_latency_s: longest time between a reply falling due and the vehicle
            sending it, s (>= 0).
    """

    tolerance: float = DEFAULT_TOLERANCE
    reply_latency_s: float = DEFAULT_REPLY_LATENCY_S

    def __post_init__(self) -> None:
        if not (math.isfinite(self.tolerance) and 0.0 <= self.tolerance < 1.0):
            raise ValueError(f"timing.tolerance must be in [0, 1), got {self.tolerance!r}")
        if not (math.isfinite(self.reply_latency_s) and self.reply_latency_s >= 0.0):
            raise ValueError(f"timing.reply_latency_s must be >= 0, got {self.reply_latency_s!r}")


@dataclass(frozen=True)
class LinkBounds:
    """Bounds on the one-way delay of any message on the link, that analysis assumes.

    An emulated Internet link has a heavy-tailed jitter with no upper bound, so these
    are a *statement*: "analysis assumes no message takes longer than ``max_delay_s``"
    (the paper saw stalls of about 7 s). Runs whose link exceeded it are outside what
    analysis proved; the fuzz report counts them.

    Attributes:
        name: the link profile they come from (for reports).
        min_delay_s: shortest one-way delay, s (>= 0).
        max_delay_s: longest one-way delay, s (>= ``min_delay_s``).
    """

    name: str
    min_delay_s: float
    max_delay_s: float

    def __post_init__(self) -> None:
        low, high = self.min_delay_s, self.max_delay_s
        if not (math.isfinite(low) and math.isfinite(high) and 0.0 <= low <= high):
            raise ValueError(
                f"link bounds must satisfy 0 <= min_delay_s <= max_delay_s, "
                f"got {low!r} and {high!r}"
            )

    def to_json(self) -> dict[str, object]:
        """JSON-ready form (reports, certificates, schedule files)."""
        return {
            "name": self.name,
            "min_delay_s": self.min_delay_s,
            "max_delay_s": self.max_delay_s,
        }
