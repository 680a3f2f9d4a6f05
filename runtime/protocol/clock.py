"""Clock sync: the paper's INIT offset between the controller's and the vehicle's clocks.

The handshake carries four times (`Hello.sent_at`, `HelloReply.received_at` and
``sent_at``, and the reply's arrival); `ClockSync` turns them into the offset the timeline
uses to merge the two event logs.
"""

from __future__ import annotations

from dataclasses import dataclass

from runtime.protocol.messages import Hello, HelloReply

__all__ = ["ClockSync", "clock_offset"]


def clock_offset(t0_cmc: float, t1_cmc: float, t0_rcs: float, t1_rcs: float) -> float:
    """The paper's INIT time offset: t_offset = (t1_cmc - t0_cmc)/2 - (t1_rcs - t0_rcs)/2.

    t0_cmc and t1_cmc are the controller (CMC) clock when it sent the `Hello` and when the
    `HelloReply` arrived; t0_rcs and t1_rcs the vehicle (RCS) clock when the Hello arrived
    and the reply left. The result is half the round trip minus the vehicle's turnaround:
    the estimated one-way delay, which is the offset between the two event logs when each
    is timed from its own INIT event (an RCS event at RCS log time t happened at CMC log
    time t + t_offset). It does not depend on how far apart the clocks are set.

    It assumes the delay is the same both ways. If the Hello took d_up and the reply
    d_down, the estimate is (d_up + d_down)/2 and its error is (d_down - d_up)/2, half
    the asymmetry; on the paper's Internet link, with one-way delays of about 7 s, that
    can be seconds. It also assumes neither clock drifts during the exchange.
    """
    return (t1_cmc - t0_cmc) / 2 - (t1_rcs - t0_rcs) / 2


@dataclass(frozen=True)
class ClockSync:
    """The four INIT times, and conversions between the two clocks built on them.

    Attributes:
        t0_cmc: controller clock when the `Hello` was sent (`Hello.sent_at`).
        t1_cmc: controller clock when the `HelloReply` arrived.
        t0_rcs: vehicle clock when the Hello arrived (`HelloReply.received_at`).
        t1_rcs: vehicle clock when the reply left (`HelloReply.sent_at`).
    """

    t0_cmc: float
    t1_cmc: float
    t0_rcs: float
    t1_rcs: float

    @classmethod
    def from_handshake(cls, hello: Hello, reply: HelloReply, received_at: float) -> ClockSync:
        """Build from the two handshake messages and the controller's arrival time."""
        return cls(hello.sent_at, received_at, reply.received_at, reply.sent_at)

    @property
    def delay(self) -> float:
        """The paper's t_offset, the estimated one-way delay (see `clock_offset`)."""
        return clock_offset(self.t0_cmc, self.t1_cmc, self.t0_rcs, self.t1_rcs)

    @property
    def vehicle_ahead(self) -> float:
        """How far the vehicle clock reads ahead of the controller's (same assumptions)."""
        return self.t0_rcs - (self.t0_cmc + self.delay)

    def to_controller(self, vehicle_time: float) -> float:
        """A vehicle-clock time on the controller's clock, to merge the event logs."""
        return vehicle_time - self.vehicle_ahead

    def to_vehicle(self, controller_time: float) -> float:
        """A controller-clock time on the vehicle's clock."""
        return controller_time + self.vehicle_ahead
