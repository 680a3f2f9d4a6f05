"""The one telemetry record: a vehicle's pose at one instant of its own clock.

A vehicle model produces it, the vehicle server numbers it and sends it as a datagram
(`runtime.protocol.encode_datagram`), the controller decodes it back into the same record
(`runtime.protocol.DatagramReceiver`), both sides store it in their event logs
(`runtime.eventlog.EventLog.telemetry`), and the timeline and the live view read it from
there. One class with one set of field names, so nothing is renamed on the way (the three
records this replaces said ``time`` or ``vehicle_time``, ``x_est`` or ``est_x``).

Import rule: a module both sides share (like `runtime.protocol`): it imports nothing of
ours, so a vehicle and the controller can both build on it.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["TelemetryRecord"]


@dataclass(frozen=True)
class TelemetryRecord:
    """One telemetry sample, timed by the *vehicle's* clock.

    Positions in metres, ``z`` is depth (down positive), ``psi`` the heading in degrees
    clockwise from north, as in the ROMEO profile. The field order lets a vehicle model
    write ``TelemetryRecord(now, x, y, z, psi)``; ``seq`` comes last because only the
    sender knows it.

    Attributes:
        vehicle_time: the vehicle's clock at the sample, s. Always the vehicle's, even in
            the controller's log, so every sample is mapped onto the controller's clock
            the same way (`runtime.timeline`).
        x: north position the vehicle reports (a simulator reports its true position).
        y: east position.
        z: depth.
        psi: heading.
        est_x: the navigation filter's estimate of x; None before it is initialised
            (ROMEO's FIX_XY) or when the vehicle has none.
        est_y: likewise for y.
        seq: the datagram's sequence number, 1, 2, 3... per connection; 0 for a sample
            not (yet) numbered, as a vehicle model produces it.
    """

    vehicle_time: float
    x: float
    y: float
    z: float
    psi: float
    est_x: float | None = None
    est_y: float | None = None
    seq: int = 0

    def numbered(self, seq: int) -> TelemetryRecord:
        """This sample as sent: numbered ``seq``, and only the fields the wire carries.

        A richer snapshot (ROMEO's, with speeds and thrusts) comes back as a plain
        record, so what is logged is exactly what the datagram holds.
        """
        return TelemetryRecord(
            self.vehicle_time, self.x, self.y, self.z, self.psi, self.est_x, self.est_y, seq
        )
