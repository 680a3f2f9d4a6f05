"""The link emulator: the fate of every byte and datagram, decided from one seed.

`LinkEmulator` is pure bookkeeping, no I/O and no clock: the transports
(`runtime.memorylink`, `runtime.socketlink`) ask it, with the current time, when a
stream chunk arrives, what happens to a datagram, whether a connection attempt succeeds
and when a connection will be cut, and carry out the answer. The same emulator therefore
works in memory under virtual time and over real sockets in real time.

Randomness: every decision comes from generators derived from the seed, one per purpose
(each direction's stream, each direction's datagrams, connections, outages), so the
fate of telemetry does not change when a command is added, and outages fall at the same
times whatever the traffic. Same profile, seed and calls: same fates.

The model, per direction (``UP`` controller to vehicle, ``DOWN`` vehicle to controller):

* The line carries one byte after another at ``bandwidth_bps``: a chunk or datagram
  starts when the line is free, takes ``(size + overhead) * bits_per_byte /
  bandwidth_bps`` seconds, and the next waits for it.
* Then each travels ``delay_s`` plus a heavy-tailed jitter sample, plus, with
  ``stall_probability``, a stall of ``stall_min_s``..``stall_max_s``.
* Stream chunks of one connection arrive in order: a chunk never arrives before the
  one sent ahead of it (head-of-line blocking, as in TCP).
* Datagrams may be lost, duplicated (the copy with its own delay) or held back.
* Outages come at random times (a Poisson process from the emulator's first use) and
  last ``outage_min_s``..``outage_max_s``; a connection is cut at its reset time or the
  start of the next outage, whichever comes first.
"""

from __future__ import annotations

import bisect
import enum
import math
import random
from dataclasses import dataclass
from typing import Generic, TypeVar

from coral_lang.linkprofile import LinkProfile

__all__ = [
    "ConnectAttempt",
    "DatagramFate",
    "Direction",
    "LinkEmulator",
    "Outage",
    "StreamPath",
]


class Direction(enum.Enum):
    """Which way bytes go."""

    UP = "controller->vehicle"
    DOWN = "vehicle->controller"


Instant = TypeVar("Instant", int, float)
"""The clock an outage is measured on: a schedule's integer milliseconds (exact, for
replays and shrinking) or the emulator's seconds."""


@dataclass(frozen=True)
class Outage(Generic[Instant]):
    """The link is down from ``start`` for ``length``, on the caller's clock.

    One class for both users: the link emulator draws outages in float seconds
    (``Outage[float]``), a `runtime.schedule.Schedule` lists them in integer milliseconds
    (``Outage[int]``); the arithmetic is the same, and so is the meaning of ``end``.

    Raises:
        ValueError: a negative ``start`` or ``length``.
    """

    start: Instant
    length: Instant

    def __post_init__(self) -> None:
        if min(self.start, self.length) < 0:
            raise ValueError(f"an outage needs start and length >= 0, got {self}")

    @property
    def end(self) -> Instant:
        """When the link is back."""
        return self.start + self.length

    def covers(self, t: Instant) -> bool:
        """True if the link is down at ``t``."""
        return self.start <= t < self.end

    def overlaps(self, t0: Instant, t1: Instant) -> bool:
        """True if the link is down at any time in ``[t0, t1]``."""
        return self.start <= t1 and t0 < self.end


@dataclass(frozen=True)
class DatagramFate:
    """What happens to one datagram.

    Attributes:
        sent_at: when it was sent.
        arrivals: when copies arrive, in no particular order; empty if it is lost, two
            if it is duplicated.
        lost_to: ``"loss"`` (random loss) or ``"outage"``; None if it arrives.
        reordered: it was held back so that later datagrams may overtake it.
        outage: the outage that lost it, if that is why.
    """

    sent_at: float
    arrivals: tuple[float, ...]
    lost_to: str | None = None
    reordered: bool = False
    outage: Outage[float] | None = None

    @property
    def lost(self) -> bool:
        """True if no copy arrives."""
        return not self.arrivals

    @property
    def duplicated(self) -> bool:
        """True if more than one copy arrives."""
        return len(self.arrivals) > 1


class StreamPath:
    """One connection's two byte streams through the emulator.

    Made by `LinkEmulator.connect`. Arrival times of each direction never decrease, so
    the bytes come out in the order they went in.

    Attributes:
        number: 1 for the emulator's first connection, 2 for the next...
        established_at: when the connection was made.
        ends_at: when the emulator cuts it (``math.inf``: never).
        end_cause: ``"reset"`` or ``"outage"`` (None when it never ends).
        outage: the outage that cuts it, if that is the cause.
    """

    def __init__(
        self,
        emulator: LinkEmulator,
        number: int,
        established_at: float,
        ends_at: float,
        end_cause: str | None,
        outage: Outage[float] | None,
    ) -> None:
        self._emulator = emulator
        self.number = number
        self.established_at = established_at
        self.ends_at = ends_at
        self.end_cause = end_cause
        self.outage = outage
        self._last = {Direction.UP: -math.inf, Direction.DOWN: -math.inf}

    def chunk(self, direction: Direction, size: int, now: float) -> float:
        """When a chunk of ``size`` bytes written at ``now`` arrives at the other end.

        It may be after `ends_at`: the chunk is then lost with the connection.
        """
        arrival = self._emulator._stream_arrival(direction, size, now)
        arrival = max(arrival, self._last[direction])
        self._last[direction] = arrival
        return arrival

    def close_arrival(self, direction: Direction, now: float) -> float:
        """When the end of the stream (FIN), sent at ``now``, reaches the other end."""
        return self.chunk(direction, 0, now)


@dataclass(frozen=True)
class ConnectAttempt:
    """The outcome of one connection attempt.

    Attributes:
        latency: how long the attempt takes before it succeeds or fails (seconds).
        path: the new connection's streams; None if the attempt fails.
        outage: the outage that makes it fail, if any.
    """

    latency: float
    path: StreamPath | None
    outage: Outage[float] | None = None

    @property
    def ok(self) -> bool:
        """True if the connection is made."""
        return self.path is not None


class LinkEmulator:
    """Decides, reproducibly from ``seed``, what the link does to each byte and datagram.

    Args:
        profile: the impairments (`coral_lang.linkprofile.LinkProfile`).
        seed: any integer; the same seed and the same calls give the same fates.
    """

    def __init__(self, profile: LinkProfile, seed: int) -> None:
        self.profile = profile
        self.seed = seed

        def child(purpose: str) -> random.Random:
            return random.Random(f"coral-link/{seed}/{purpose}")

        self._stream_rng = {d: child(f"stream/{d.name}") for d in Direction}
        self._datagram_rng = {d: child(f"datagram/{d.name}") for d in Direction}
        self._connection_rng = child("connection")
        self._outage_rng = child("outage")
        self._sample_rng = child("samples")
        self._line_free = {d: -math.inf for d in Direction}
        self._outages: list[Outage[float]] = []
        self._outage_starts: list[float] = []
        self._outage_ends: list[float] = []
        self._outage_origin: float | None = None
        self._connections = 0

    # ------------------------------------------------------------------ delays

    def _line(self, direction: Direction, size: int, now: float) -> float:
        """Queue ``size`` bytes behind the direction's earlier bytes; when the last is sent."""
        start = max(now, self._line_free[direction])
        done = start + self.profile.serialisation_time(size)
        self._line_free[direction] = done
        return done

    def _travel(self, rng: random.Random) -> float:
        """One sample of the delay after the line: base + jitter (+ a stall)."""
        p = self.profile
        delay = p.delay_s
        if p.jitter_scale_s > 0.0:
            u = 1.0 - rng.random()  # in (0, 1]
            delay += min(p.jitter_cap_s, p.jitter_scale_s * (u ** (-1.0 / p.jitter_shape) - 1.0))
        if p.stall_probability > 0.0 and rng.random() < p.stall_probability:
            delay += rng.uniform(p.stall_min_s, p.stall_max_s)
        return delay

    def _stream_arrival(self, direction: Direction, size: int, now: float) -> float:
        sent = self._line(direction, size + self.profile.stream_overhead_bytes, now)
        return sent + self._travel(self._stream_rng[direction])

    def sample_delay(self) -> float:
        """A sample of the one-way delay after the line (base, jitter, stall).

        For statistics and documentation; it draws from a generator of its own, so
        sampling changes no other fate.
        """
        return self._travel(self._sample_rng)

    # ------------------------------------------------------------------ datagrams

    def datagram(self, direction: Direction, size: int, now: float) -> DatagramFate:
        """The fate of a datagram of ``size`` bytes sent at ``now``."""
        p = self.profile
        rng = self._datagram_rng[direction]
        outage = self.outage_at(now)
        if outage is not None:
            return DatagramFate(now, (), "outage", outage=outage)
        sent = self._line(direction, size + p.datagram_overhead_bytes, now)
        if p.datagram_loss > 0.0 and rng.random() < p.datagram_loss:
            return DatagramFate(now, (), "loss")
        arrival = sent + self._travel(rng)
        reordered = p.datagram_reorder > 0.0 and rng.random() < p.datagram_reorder
        if reordered:
            arrival += rng.uniform(0.0, p.reorder_delay_s)
        arrivals = [arrival]
        if p.datagram_duplicate > 0.0 and rng.random() < p.datagram_duplicate:
            arrivals.append(sent + self._travel(rng))
        outage = self.outage_between(now, max(arrivals))
        if outage is not None:
            arrivals = [t for t in arrivals if not outage.overlaps(now, t)]
        if not arrivals:
            return DatagramFate(now, (), "outage", reordered, outage)
        return DatagramFate(now, tuple(arrivals), None, reordered)

    # ------------------------------------------------------------------ connections

    def connect(self, now: float) -> ConnectAttempt:
        """Try to open a connection at ``now``.

        A successful attempt takes one round trip (SYN up, SYN-ACK down). During an
        outage it fails after one base round trip (as if refused or unreachable), and an
        outage that starts before the round trip completes also makes it fail.
        """
        p = self.profile
        outage = self.outage_at(now)
        if outage is not None:
            return ConnectAttempt(2.0 * p.delay_s, None, outage)
        rng = self._connection_rng
        syn = self._line(Direction.UP, p.stream_overhead_bytes, now) + self._travel(rng)
        ack = self._line(Direction.DOWN, p.stream_overhead_bytes, syn) + self._travel(rng)
        outage = self.outage_between(now, ack)
        if outage is not None:
            return ConnectAttempt(max(0.0, outage.start - now), None, outage)
        ends_at, cause = math.inf, None
        if p.reset_rate_per_s > 0.0:
            ends_at, cause = ack + rng.expovariate(p.reset_rate_per_s), "reset"
        nxt = self.next_outage(ack)
        if nxt is not None and nxt.start < ends_at:
            ends_at, cause = nxt.start, "outage"
        else:
            nxt = None
        self._connections += 1
        path = StreamPath(self, self._connections, ack, ends_at, cause, nxt)
        return ConnectAttempt(ack - now, path)

    # ------------------------------------------------------------------ outages

    def outage_at(self, t: float) -> Outage[float] | None:
        """The outage in progress at ``t``, if any."""
        outage = self.outage_between(t, t)
        return outage if outage is not None and outage.covers(t) else None

    def outage_between(self, t0: float, t1: float) -> Outage[float] | None:
        """The first outage that overlaps ``[t0, t1]``, if any."""
        self._extend(t0, t1)
        # Outages never overlap, so their ends increase: find the first to end after t0.
        i = bisect.bisect_right(self._outage_ends, t0)
        if i < len(self._outages) and self._outages[i].overlaps(t0, t1):
            return self._outages[i]
        return None

    def next_outage(self, after: float) -> Outage[float] | None:
        """The first outage starting at or after ``after`` (None if outages never happen)."""
        if self.profile.outage_rate_per_s <= 0.0:
            return None
        self._extend(after, after)  # now the last outage starts after ``after``
        i = bisect.bisect_left(self._outage_starts, after)
        return self._outages[i]

    def _extend(self, now: float, until: float) -> None:
        """Draw the outage timeline until an outage starts after ``until``.

        The timeline starts at the first time the emulator is asked about (``now``).
        """
        p = self.profile
        if p.outage_rate_per_s <= 0.0:
            return
        if self._outage_origin is None:
            self._outage_origin = now
        rng = self._outage_rng
        t = self._outages[-1].end if self._outages else self._outage_origin
        while not self._outages or self._outages[-1].start <= until:
            start = t + rng.expovariate(p.outage_rate_per_s)
            outage = Outage(start, rng.uniform(p.outage_min_s, p.outage_max_s))
            t = outage.end
            self._outages.append(outage)
            self._outage_starts.append(start)
            self._outage_ends.append(t)
