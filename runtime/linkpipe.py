"""What the two transports share: a connection with the emulator in the middle, and stats.

`EmulatedConnection` is the controller's end of one connection (it implements
`runtime.link.Connection`). The vehicle's end is whatever the transport plugs in as a
`VehicleEnd`: an asyncio stream protocol served by the in-memory `VehicleServer`, or a
real socket. Bytes each way wait in a `TimedQueue` until the time the emulator gave
them, and the connection dies at the emulator's reset or outage time, with whatever was
still in flight.

`EmulatedLink` is the part of a link that is not about the transport: asking the
emulator whether a connection attempt succeeds, scheduling datagrams, counters, log.
"""

from __future__ import annotations

import asyncio
import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, fields
from typing import Protocol

from runtime.emulator import Direction, LinkEmulator, Outage, StreamPath

__all__ = [
    "EmulatedConnection",
    "EmulatedLink",
    "LinkLog",
    "LinkStats",
    "TimedQueue",
    "VehicleEnd",
]

LinkLog = Callable[[str], None]
"""Receives one line per notable link event: each reset, each outage (once)."""


def quiet(_: str) -> None:
    """The default log: say nothing."""


@dataclass
class LinkStats:
    """Counters of one link, for the log, reports and tests.

    Attributes:
        connections: connections made.
        connect_failures: connection attempts that raised ConnectionError.
        resets: connections the emulator reset.
        outages: distinct outages that refused a connection, cut one or lost a datagram.
        bytes_up: stream bytes the controller wrote (on live connections).
        bytes_down: stream bytes delivered to the controller.
        chunks_up: writes by the controller.
        chunks_down: chunks delivered to the controller.
        bytes_lost: stream bytes lost in flight when a connection was cut.
        datagrams: datagrams the vehicle sent to the controller's telemetry port.
        datagrams_delivered: copies handed to the telemetry callback.
        datagrams_lost: datagrams lost (random loss or outage).
        datagrams_duplicated: datagrams delivered twice.
        datagrams_reordered: datagrams held back so that later ones could overtake them.
    """

    connections: int = 0
    connect_failures: int = 0
    resets: int = 0
    outages: int = 0
    bytes_up: int = 0
    bytes_down: int = 0
    chunks_up: int = 0
    chunks_down: int = 0
    bytes_lost: int = 0
    datagrams: int = 0
    datagrams_delivered: int = 0
    datagrams_lost: int = 0
    datagrams_duplicated: int = 0
    datagrams_reordered: int = 0

    def summary(self) -> str:
        """One line for the log: every non-zero counter."""
        parts = [f"{f.name}={getattr(self, f.name)}" for f in fields(self) if getattr(self, f.name)]
        return "link: " + (", ".join(parts) if parts else "no traffic")


class TimedQueue:
    """Items delivered in the order they were put, each at (or after) its time.

    Times put must not decrease (the emulator's stream arrivals never do); one timer per
    item, and each timer delivers the oldest item, so two items due at the same moment
    still come out in order.
    """

    def __init__(self, loop: asyncio.AbstractEventLoop, deliver: Callable[[bytes], None]) -> None:
        self._loop = loop
        self._deliver = deliver
        self._items: deque[bytes] = deque()
        self._timers: deque[asyncio.TimerHandle] = deque()
        self._generation = 0

    def __len__(self) -> int:
        return len(self._items)

    def put(self, at: float, item: bytes) -> None:
        """Deliver ``item`` at loop time ``at``, after every item put before it."""
        self._items.append(item)
        self._timers.append(self._loop.call_at(at, self._pop, self._generation))

    def _pop(self, generation: int) -> None:
        if generation != self._generation or not self._items:
            return  # cleared since this timer was set
        # Forget one timer: this one, or (same due time, fired out of order) one that is
        # about to fire; either way the generation check above keeps it harmless.
        self._timers.popleft()
        self._deliver(self._items.popleft())

    def clear(self) -> int:
        """Drop everything not yet delivered; returns how many bytes were dropped."""
        dropped = sum(len(item) for item in self._items)
        self._items.clear()
        for timer in self._timers:
            timer.cancel()
        self._timers.clear()
        self._generation += 1
        return dropped


class VehicleEnd(Protocol):
    """The vehicle's end of a connection, as the transport provides it."""

    def deliver(self, data: bytes) -> None:
        """Bytes from the controller arrive at the vehicle now."""

    def deliver_eof(self) -> None:
        """The controller's end of stream arrives: it closed the connection."""

    def abort(self, reason: str) -> None:
        """The connection is reset under the vehicle (emulated reset or outage)."""


class EmulatedConnection:
    """The controller's end of one connection; the emulator decides when bytes arrive.

    Implements `runtime.link.Connection`. The transport calls `from_vehicle` with each
    chunk its vehicle end sends and `vehicle_closed` when that end closes.

    Args:
        loop: the running loop (virtual or real time).
        number: the link's connection number (for the log).
        path: the emulator's plan for this connection; None: no emulator, every byte
            arrives on the next loop iteration and the connection lives until closed.
        vehicle: the vehicle's end.
        link: the link, for counters and log lines.
    """

    def __init__(
        self,
        loop: asyncio.AbstractEventLoop,
        number: int,
        path: StreamPath | None,
        vehicle: VehicleEnd,
        link: EmulatedLink,
    ) -> None:
        self.number = number
        self.path = path
        self._loop = loop
        self._vehicle = vehicle
        self._link = link
        self._inbox = bytearray()
        self._readable = asyncio.Event()
        self._ended = False  # the controller's side is finished: read() returns b""
        self._closed_by_us = False
        self._vehicle_gone = False  # the vehicle's side got its end of stream or reset
        self._up = TimedQueue(loop, self._arrive_at_vehicle)
        self._down = TimedQueue(loop, self._arrive_at_controller)
        self._ends_at = math.inf if path is None else path.ends_at
        self._cut_timer: asyncio.TimerHandle | None = None
        if math.isfinite(self._ends_at):
            self._cut_timer = loop.call_at(self._ends_at, self._cut)

    # ------------------------------------------------------------------ the controller's side

    async def read(self) -> bytes:
        """The bytes that have arrived, waiting for some; b"" once closed or reset.

        Safe to cancel (``asyncio.wait_for``): nothing is lost.
        """
        while not self._inbox and not self._ended:
            self._readable.clear()
            await self._readable.wait()
        if not self._inbox:
            return b""
        data = bytes(self._inbox)
        self._inbox.clear()
        return data

    def write(self, data: bytes) -> None:
        """Send ``data``; never blocks. Ignored once the connection is closed or reset."""
        if self.closed or not data:
            return
        stats = self._link.stats
        stats.bytes_up += len(data)
        stats.chunks_up += 1
        self._send(Direction.UP, bytes(data), self._up)

    def close(self) -> None:
        """Close our end: drop what has not been read, send the end of stream."""
        if self._closed_by_us:
            return
        self._closed_by_us = True
        self._finish_controller_side()
        self._down.clear()
        if not self._vehicle_gone:
            self._send(Direction.UP, b"", self._up)
        self._settle()

    @property
    def closed(self) -> bool:
        """True once closed by us, by the vehicle (end of stream received) or reset."""
        return self._ended or self._closed_by_us

    def shutdown(self) -> None:
        """Close at once, both ends, without waiting for the emulated link (tear-down)."""
        self.close()
        self._up.clear()
        self._down.clear()
        self._cancel_cut()
        if not self._vehicle_gone:
            self._vehicle_gone = True
            self._vehicle.deliver_eof()

    # ------------------------------------------------------------------ the vehicle's side

    def from_vehicle(self, data: bytes) -> None:
        """The vehicle's end sent ``data`` now."""
        if self._vehicle_gone or self._closed_by_us or not data:
            return  # nobody is listening any more
        self._send(Direction.DOWN, bytes(data), self._down)

    def vehicle_closed(self) -> None:
        """The vehicle's end closed the connection now (end of stream to the controller)."""
        if self._vehicle_gone:
            return
        self._vehicle_gone = True
        if not self._closed_by_us:
            self._send(Direction.DOWN, b"", self._down)
        self._settle()

    # ------------------------------------------------------------------ delivery

    def _send(self, direction: Direction, data: bytes, queue: TimedQueue) -> None:
        now = self._loop.time()
        if self.path is None:
            at = now
        elif data:
            at = self.path.chunk(direction, len(data), now)
        else:
            at = self.path.close_arrival(direction, now)
        if at >= self._ends_at:
            self._link.stats.bytes_lost += len(data)  # cut before it arrives
            return
        queue.put(at, data)

    def _arrive_at_vehicle(self, data: bytes) -> None:
        if self._vehicle_gone:
            return
        if data:
            self._vehicle.deliver(data)
            return
        self._vehicle_gone = True
        self._vehicle.deliver_eof()
        self._settle()

    def _arrive_at_controller(self, data: bytes) -> None:
        if self.closed:
            return
        if data:
            self._inbox += data
            self._link.stats.bytes_down += len(data)
            self._link.stats.chunks_down += 1
            self._readable.set()
            return
        self._finish_controller_side()
        self._settle()

    def _finish_controller_side(self) -> None:
        self._ended = True
        self._readable.set()

    def _settle(self) -> None:
        """Once both sides are finished, the emulator's cut no longer matters."""
        if self.closed and self._vehicle_gone:
            self._cancel_cut()
            self._link._forget(self)

    def _cancel_cut(self) -> None:
        if self._cut_timer is not None:
            self._cut_timer.cancel()
            self._cut_timer = None

    def _cut(self) -> None:
        """The emulator's reset or outage: the connection dies with the bytes in flight."""
        self._cut_timer = None
        lost = self._up.clear() + self._down.clear()
        self._link.stats.bytes_lost += lost
        if not self.closed:  # what already arrived stays readable
            self._finish_controller_side()
            self._link._on_cut(self, lost)
        if not self._vehicle_gone:
            self._vehicle_gone = True
            cause = "an outage" if self.path is not None and self.path.outage else "a reset"
            self._vehicle.abort(f"connection reset by the link emulator ({cause})")
        self._link._forget(self)


class EmulatedLink:
    """The transport-independent half of a link: emulator, counters, log, datagrams.

    Args:
        emulator: decides the link's impairments; None: a perfect link.
        log: one line per reset and per outage (failed attempts are only counted).
    """

    def __init__(self, emulator: LinkEmulator | None, log: LinkLog) -> None:
        self.emulator = emulator
        self.stats = LinkStats()
        self._log = log
        self._seen_outages: set[Outage[float]] = set()
        # Insertion-ordered (not a set), so tear-down happens in the same order every run.
        self._live: dict[EmulatedConnection, None] = {}
        self._numbers = 0
        self._closed = False
        # The loop's clock when the link was first used: log lines give times since then,
        # as the controller's console does (a real-time loop's clock is the raw monotonic
        # one, e.g. t=1682.6, which tells an operator nothing).
        self._t0: float | None = None

    def _mission_time(self, t: float) -> float:
        """``t`` on the loop's clock, as seconds since the link was first used."""
        return t - (self._t0 if self._t0 is not None else 0.0)

    # ------------------------------------------------------------------ connections

    async def _attempt(self) -> StreamPath | None:
        """Ask the emulator for a connection; wait its latency; ConnectionError if it fails."""
        if self._closed:
            raise RuntimeError("the link is closed (aclose() was called)")
        if self.emulator is None:
            return None
        loop = asyncio.get_running_loop()
        if self._t0 is None:
            self._t0 = loop.time()
        attempt = self.emulator.connect(loop.time())
        if attempt.latency > 0.0:
            await asyncio.sleep(attempt.latency)
        if attempt.path is not None:
            return attempt.path
        self.stats.connect_failures += 1
        outage = attempt.outage
        assert outage is not None
        self._note_outage(outage, "connection attempts fail")
        raise ConnectionError(
            "the vehicle cannot be reached: link outage until "
            f"t={self._mission_time(outage.end):.1f} s"
        )

    def _failed(self, reason: str) -> ConnectionError:
        """Count a failed attempt; the error to raise."""
        self.stats.connect_failures += 1
        return ConnectionError(reason)

    def _register(self, conn: EmulatedConnection) -> None:
        self.stats.connections += 1
        self._live[conn] = None

    def _next_number(self) -> int:
        self._numbers += 1
        return self._numbers

    def _forget(self, conn: EmulatedConnection) -> None:
        """``conn`` is finished at both ends."""
        self._live.pop(conn, None)

    def _on_cut(self, conn: EmulatedConnection, lost: int) -> None:
        path = conn.path
        assert path is not None
        in_flight = f"{lost} bytes in flight lost"
        if path.outage is not None:
            self._note_outage(path.outage, f"connection {conn.number} cut, {in_flight}")
        else:
            self.stats.resets += 1
            now = asyncio.get_running_loop().time()
            self._log(
                f"link: connection {conn.number} reset at t={self._mission_time(now):.1f} s, "
                f"{in_flight}"
            )

    def _note_outage(self, outage: Outage[float], what: str) -> None:
        """Count and log an outage the first time it shows (later effects are counted)."""
        if outage in self._seen_outages:
            return
        self._seen_outages.add(outage)
        self.stats.outages += 1
        self._log(
            f"link: outage from t={self._mission_time(outage.start):.1f} s "
            f"to t={self._mission_time(outage.end):.1f} s "
            f"({outage.length:.1f} s): {what}"
        )

    def _shutdown_all(self) -> None:
        self._closed = True
        for conn in list(self._live):
            conn.shutdown()
        self._live.clear()

    # ------------------------------------------------------------------ datagrams

    def _datagram(self, data: bytes, receive: Callable[[bytes], None]) -> None:
        """A datagram from the vehicle reached the link now: deliver it as the emulator says."""
        self.stats.datagrams += 1
        loop = asyncio.get_running_loop()
        if self.emulator is None:  # a perfect link: hand it over now, nothing in flight
            self._deliver_datagram(receive, data)
            return
        fate = self.emulator.datagram(Direction.DOWN, len(data), loop.time())
        if fate.lost:
            self.stats.datagrams_lost += 1
            if fate.outage is not None:
                self._note_outage(fate.outage, "datagrams lost")
            return
        self.stats.datagrams_duplicated += fate.duplicated
        self.stats.datagrams_reordered += fate.reordered
        for at in fate.arrivals:
            loop.call_at(at, self._deliver_datagram, receive, data)

    def _deliver_datagram(self, receive: Callable[[bytes], None], data: bytes) -> None:
        if self._closed:
            return
        self.stats.datagrams_delivered += 1
        receive(data)
