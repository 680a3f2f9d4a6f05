"""What the vehicle side of the wire protocol drives: a `VehicleModel`.

The protocol side (handshake, authentication, the reply ledger, heartbeats, telemetry
datagrams: `runtime.vehicle.server.VehicleServer`) is written once. Behind it sits a
model of the vehicle that never reads a clock: the server moves its time forward with
`VehicleModel.advance_to` and hands it each command once. ROMEO's physics simulator, the
generic simulated vehicle for any profile, a fault injector wrapped around either, and an
integrator's adapter to real hardware (`runtime.vehicle.handlers`) all are models.

This module is the contract between those parts; it imports nothing of the controller's
side of ``runtime`` (engine, controller, links), so a vehicle can be built on it alone.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

from runtime.telemetry import TelemetryRecord

__all__ = [
    "Params",
    "Reply",
    "TelemetryRecord",
    "VehicleModel",
]

Params = Mapping[str, float | int | str]
"""A command's parameters as they come off the wire."""


@dataclass(frozen=True)
class Reply:
    """One reply of the vehicle to a command.

    Attributes:
        command_id: the vehicle-side id of the command it answers (the one given to
            `VehicleModel.command`).
        command: that command's name.
        kind: a reply kind of the profile (``ack``, ``done``, ``timeout``, ``error``...).
        time: vehicle time when it was produced, s.
        detail: free text for people and logs.
    """

    command_id: int
    command: str
    kind: str
    time: float
    detail: str = ""


@runtime_checkable
class VehicleModel(Protocol):
    """A vehicle as the vehicle-side server drives it. Time is injected, never read.

    Rules every model keeps (the server relies on them):

    * `command` is called once per command (the server's ledger filters repeats) with a
      fresh ``command_id``; it returns the replies due at once (``ack``, ``error`` for a
      refused command...), and later replies come from `advance_to`.
    * `advance_to` never moves the clock back; it returns every reply that fell due up to
      ``t``, in time order, each stamped with its own vehicle time.
    * A model never raises for bad input from the wire (an unknown command, a missing or
      out-of-range parameter): it replies ``error`` with a detail.
    * `make_safe` does at once what the watchdog does after ``watchdog_s`` of silence.
    """

    @property
    def time(self) -> float:
        """The vehicle clock, s."""
        ...

    @property
    def watchdog_s(self) -> float:
        """Vehicle seconds without a word from the controller after which the vehicle
        makes itself safe (stops its tasks, surfaces); reported to the controller."""
        ...

    def advance_to(self, t: float) -> list[Reply]:
        """Move the clock to ``t``; return the replies that fell due meanwhile."""
        ...

    def command(self, command_id: int, name: str, params: Params) -> list[Reply]:
        """Start carrying out one command; return its immediate replies."""
        ...

    def heard_from_controller(self) -> None:
        """The controller is alive: reset the watchdog."""
        ...

    def make_safe(self, reason: str) -> list[Reply]:
        """The controller asks the vehicle to make itself safe now (``MakeSafe`` frame).

        The effect is the watchdog's, at once: every task stops, every pending query
        replies ``timeout`` and every running action ``error``, and the vehicle does
        what its watchdog does to be safe (surface, stop the thrusters). Returns the
        replies due now, those included, like `command`; the server numbers them in
        the mission's ledger, so a resumed controller consumes them and the mission
        takes its error paths. Calling it again with nothing running is harmless.
        ``reason`` is for the vehicle's own log.
        """
        ...

    def telemetry(self) -> TelemetryRecord | None:
        """A snapshot to send as telemetry, or None when the vehicle has none to give.

        Its ``seq`` is left 0: the server numbers each sample it sends.
        """
        ...
