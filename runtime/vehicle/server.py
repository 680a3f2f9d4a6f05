"""Any `VehicleModel` served on the coral wire protocol: what puts a vehicle on the wire.

`VehicleServer` puts a model (ROMEO's simulator, the generic simulated vehicle, an
integrator's `runtime.vehicle.handlers.HandlerVehicle` on real hardware) behind a TCP
listener (handshake, commands, replies, reply acknowledgements, heartbeats) and sends its
telemetry by UDP, exactly as ``docs/protocol.md`` describes the vehicle's side. Written
once, here, so that every vehicle gets the same authentication, the same exactly-once
reply ledger and the same resume rules; a vehicle only has to be a model. It owns no clock
and no randomness of its own: the wall clock, the nonce source and the log are
parameters, so tests can drive it.

How it behaves:

* One controller at a time. A new connection is taken as the controller only once
  `StreamCodec.peer_verified` is True (its first session frame); then the previous
  connection, if any, is closed and the new one's ``Hello`` resume request is applied.
* Every command id runs once per mission (`ReplyLedger`); a repeat re-sends the replies
  still unacknowledged for it. Replies are kept until a `ReplyAck` (or a resuming
  ``Hello``'s ``last_reply_seq``) covers them, and re-sent after a resume.
* A ``MakeSafe`` request makes the vehicle safe at once (`VehicleModel.make_safe`), once
  per request id, and is acknowledged (``MakeSafeAck``) every time.
* The vehicle's command ids are the server's own, numbered 1, 2, 3... across missions, so a
  new mission may reuse the wire ids of an old one without the vehicle mistaking them for
  repeats.
* A stepping task advances the vehicle by the wall-clock time elapsed times ``speed``;
  every frame from the controller first brings the vehicle up to date, so a command is
  stamped with the right vehicle time. Telemetry samples are taken every
  ``1 / telemetry_hz`` seconds of *vehicle* time; a model whose `VehicleModel.telemetry`
  returns None at that moment gives neither a datagram nor a sample.
* Rejected input is counted and logged; the connection and the vehicle go on. The log
  is rate-limited (`_LogThrottle`): the first few lines of a kind from one host, then one
  summary line per period, so a flood of garbage cannot flood the log.
* A hostile or slow client cannot lock the controller out (``docs/protocol.md``, "Hostile
  clients"): a connection not adopted within ``handshake_timeout`` seconds of being
  accepted is closed however it trickles bytes, at most ``max_pending`` connections wait
  unadopted (a new one closes the oldest, preferring one that sent no ``Hello``), a
  pending connection sending more than ``max_pending_bytes`` is closed, and accept
  failures (out of descriptors) are counted, logged rate-limited and retried. The adopted
  controller is never counted against these limits. At `start`, ``max_pending`` is
  lowered to what the process's descriptor limit (soft ``RLIMIT_NOFILE``) leaves free
  after `DESCRIPTOR_RESERVE` (a warning says so): pending connections then never take the
  descriptor the controller's connection needs.
* The event log is given at construction (``event_log``) or created when the first
  controller is adopted (``open_event_log``): a served vehicle learns its mission only
  from that ``Hello``, so its log is named after the wire mission id.
* Without sockets (`start_detached` and `accept`), an in-memory link such as
  `runtime.memorylink.MemoryLink` hands the server its connections and receives the
  telemetry, so the same server runs under a virtual clock.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import os
import socket
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Generic

from runtime.eventlog import EventLog, EventLogError
from runtime.protocol import (
    MAX_DETAIL_BYTES,
    MAX_FRAME,
    MIN_KEY_SIZE,
    NONCE_SIZE,
    Command,
    Heartbeat,
    Hello,
    HelloReply,
    MakeSafe,
    MakeSafeAck,
    ProtocolError,
    Rejected,
    ReplyAck,
    ReplyLedger,
    Role,
    StreamCodec,
    StreamMessage,
    encode_datagram,
)
from runtime.telemetry import TelemetryRecord
from runtime.vehicle.model import Reply, VehicleModel
from runtime.vehicle.sigterm import Terminated, sigterm_raises

__all__ = ["ServerStats", "VehicleServer", "run_vehicle", "serve_vehicle"]

if TYPE_CHECKING:
    from typing_extensions import TypeVar

    M = TypeVar("M", bound=VehicleModel, covariant=True, default=VehicleModel)
else:  # the default is for type checkers only (typing.TypeVar takes it from 3.13)
    from typing import TypeVar

    M = TypeVar("M", bound=VehicleModel, covariant=True)
"""The model a server serves. ``VehicleServer(romeo)`` is a ``VehicleServer[Vehicle]``, so
``server.vehicle`` keeps ROMEO's own methods for its callers; a bare ``VehicleServer``
annotation means any model."""

Clock = Callable[[], float]
"""A monotonic clock in seconds (wall time in production, a fake one in tests)."""

DatagramSink = Callable[[bytes, tuple[str, int]], None]
"""Where an in-memory connection's telemetry goes: (datagram, (host, port))."""


DESCRIPTOR_RESERVE = 12
"""Descriptors `VehicleServer.start` keeps free beyond the pending connections: the
controller's connection and a reconnecting one, the event log (SQLite: database, journal
or WAL, shared memory), the resolver, and a margin."""


def _stderr(line: str) -> None:
    print(f"vehicle server: {line}", file=sys.stderr, flush=True)


def spare_descriptors() -> tuple[int, int] | None:
    """(descriptors this process may still open, its soft limit); None if unknown.

    Unknown: no ``resource`` module (Windows), no unlimited-or-finite soft limit to fit,
    or no folder listing the open descriptors (``/proc/self/fd``, ``/dev/fd``).
    """
    try:
        import resource
    except ImportError:
        return None
    soft, _ = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft == resource.RLIM_INFINITY:
        return None
    for folder in ("/proc/self/fd", "/dev/fd"):
        try:
            in_use = len(os.listdir(folder))  # counts the listing's own descriptor: safe
        except OSError:
            continue
        return max(0, soft - in_use), soft
    return None


@dataclass
class ServerStats:
    """Counters of one server run, for the log and the tests.

    Attributes:
        connections: TCP connections accepted.
        adopted: connections that became the controller (after their first session frame).
        commands: commands carried out (each command id of a mission once).
        repeats: commands received again with an id already carried out.
        replies: replies issued (not counting re-sends).
        resent: replies sent again (after a resume or a repeated command).
        rejected: frames the codec rejected (bad tag, replay, malformed...), all connections
            (each connection's own count is its codec's ``rejected``).
        datagrams: telemetry datagrams sent.
        timed_out: connections closed for not being adopted within ``handshake_timeout``.
        evicted: pending connections closed to make room for a newer one (``max_pending``).
        overflowed: pending connections closed for sending more than ``max_pending_bytes``.
        accept_errors: failed accepts on the listening socket (e.g. out of descriptors).
    """

    connections: int = 0
    adopted: int = 0
    commands: int = 0
    repeats: int = 0
    replies: int = 0
    resent: int = 0
    rejected: int = 0
    datagrams: int = 0
    timed_out: int = 0
    evicted: int = 0
    overflowed: int = 0
    accept_errors: int = 0

    def summary(self) -> str:
        """One line for the log (the hostile-client counters only when any is non-zero)."""
        line = (
            f"{self.connections} connections ({self.adopted} adopted), {self.commands} "
            f"commands ({self.repeats} repeats), {self.replies} replies ({self.resent} re-sent), "
            f"{self.datagrams} telemetry datagrams, {self.rejected} frames rejected"
        )
        if self.timed_out or self.evicted or self.overflowed or self.accept_errors:
            line += (
                f"; closed unadopted: {self.timed_out} timed out, {self.evicted} evicted, "
                f"{self.overflowed} over the byte limit; {self.accept_errors} accept errors"
            )
        return line


@dataclass
class _Burst:
    """One kind of log line from one source within the current period."""

    started: float
    shown: int = 0
    suppressed: int = 0


class _LogThrottle:
    """The first ``burst`` lines of each kind per ``period`` go to the log; the rest are counted.

    Why: the server logs events a peer causes (rejected frames, connections). Unthrottled,
    a client sending garbage writes a line per two bytes it sends, and a connection flood
    a line per attempt: the log becomes the attack. Each kind (e.g. "frames rejected from
    10.0.0.5") gets ``burst`` lines per period; what was held back is reported as one
    summary line, "N more frames rejected from 10.0.0.5 in the last S s", when the period
    ends (`flush`, called by the server's stepping task, or the next line of that kind).
    """

    MAX_KINDS = 256
    """Kinds tracked at once; beyond (a flood from many hosts), lines share one kind."""

    def __init__(
        self, log: Callable[[str], None], clock: Clock, burst: int = 3, period: float = 10.0
    ) -> None:
        self._log = log
        self._clock = clock
        self._burst = burst
        self._period = period
        self._kinds: dict[str, _Burst] = {}

    def __call__(self, kind: str, line: str) -> None:
        """Log ``line`` unless ``kind`` already had its ``burst`` lines this period."""
        now = self._clock()
        if kind not in self._kinds and len(self._kinds) >= self.MAX_KINDS:
            kind = "log lines from other hosts"
        burst = self._kinds.get(kind)
        if burst is not None and now - burst.started >= self._period:
            self._summarise(kind, burst, now)
            burst = None
        if burst is None:
            burst = self._kinds[kind] = _Burst(now)
        if burst.shown < self._burst:
            burst.shown += 1
            self._log(line)
        else:
            burst.suppressed += 1

    @property
    def pending(self) -> bool:
        """Whether a later `flush` may log a line (some kind had lines held back).

        Forgetting a kind whose period is over logs nothing when none was held back,
        and a kind's next line forgets an expired period by itself: so when this is
        False, a `flush` may be skipped without changing what is logged.
        """
        return any(burst.suppressed for burst in self._kinds.values())

    def flush(self, *, force: bool = False) -> None:
        """Summarise and forget every kind whose period is over (all of them if ``force``)."""
        now = self._clock()
        for kind, burst in list(self._kinds.items()):
            if force or now - burst.started >= self._period:
                self._summarise(kind, burst, now)
                del self._kinds[kind]

    def _summarise(self, kind: str, burst: _Burst, now: float) -> None:
        if burst.suppressed:
            self._log(f"{burst.suppressed} more {kind} in the last {now - burst.started:.0f} s")


@dataclass(eq=False)
class _Connection:
    """One accepted TCP connection and its codec."""

    codec: StreamCodec
    writer: asyncio.StreamWriter
    peer: str
    peer_host: str
    deadline: float = math.inf
    """Loop time by which the connection must be adopted."""
    received: int = 0
    """Bytes received (counted while the connection is pending)."""
    hello: Hello | None = None
    announced_resume: bool = False
    adopted: bool = False
    last_sent: float = 0.0
    telemetry_seq: int = 0
    closed: bool = field(default=False)
    sink: DatagramSink | None = None

    def send(self, msg: StreamMessage, now: float) -> None:
        if self.closed or self.writer.is_closing():
            return
        self.writer.write(self.codec.encode(msg))
        self.last_sent = now

    def close(self) -> None:
        self.closed = True
        if not self.writer.is_closing():
            self.writer.close()


class VehicleServer(Generic[M]):
    """A `VehicleModel` served on the coral wire protocol: TCP for the stream, UDP for telemetry.

    Args:
        vehicle: the vehicle model (simulated, or an adapter to real hardware); the server
            is the only thing that should drive it while it runs.
        psk: the pre-shared key, at least `MIN_KEY_SIZE` bytes.
        host: address to listen on (TCP) and send telemetry from (UDP).
        port: TCP port; 0 picks a free one (`start` returns it).
        clock: monotonic wall clock in seconds; ``time.monotonic`` in production.
        speed: vehicle seconds per wall second (1.0: real time; 50.0: fifty times faster).
        telemetry_hz: telemetry samples per second of vehicle time.
        tick: wall seconds between steps of the stepping task.
        heartbeat_interval: wall seconds of silence towards the controller after which the
            server sends a `Heartbeat`.
        handshake_timeout: wall seconds, from accept, a new connection has to prove it is
            live (its first session frame) before it is closed, however it trickles bytes.
            Measured on the event loop's clock (``loop.time()``). The default allows the
            paper's link, which stalled up to 7 s each way: Hello, HelloReply and the
            verifying frame may take three such stalls.
        max_pending: connections that may wait unadopted at once; a new one beyond closes
            the oldest (one that sent no ``Hello`` first). The controller is not counted.
            `start` lowers it to fit the descriptor limit (`max_pending` tells the result).
        max_pending_bytes: bytes a pending connection may send without being adopted
            (at least `MAX_FRAME`); a handshake takes about a hundred.
        nonces: source of random bytes for the handshake nonces; ``os.urandom`` by default.
        log: receives one line per notable event (rejections, connections); stderr by
            default.
        event_log: the vehicle's side of the run's record (``docs/eventlog.md``): every
            command received, reply issued and telemetry sample, on the vehicle clock;
            committed about once a second and at `stop`. None: no record.
        open_event_log: with no ``event_log``, called once with the wire mission id when
            the first controller is adopted, to create the log then (the caller closes
            it); a failure is logged and the vehicle goes on without a record.

    Raises:
        ValueError: a key shorter than `MIN_KEY_SIZE`, or a speed, rate or interval that is
            not a positive finite number, or a limit out of range.
    """

    accept_retry_delay: float = 0.1
    """Seconds to wait after a failed accept (e.g. no descriptor left) before the next."""

    def __init__(
        self,
        vehicle: M,
        psk: bytes,
        *,
        host: str = "127.0.0.1",
        port: int = 0,
        clock: Clock = time.monotonic,
        speed: float = 1.0,
        telemetry_hz: float = 2.0,
        tick: float = 0.05,
        heartbeat_interval: float = 1.0,
        handshake_timeout: float = 30.0,
        max_pending: int = 16,
        max_pending_bytes: int = 4 * MAX_FRAME,
        nonces: Callable[[int], bytes] = os.urandom,
        log: Callable[[str], None] = _stderr,
        event_log: EventLog | None = None,
        open_event_log: Callable[[int], EventLog] | None = None,
    ) -> None:
        if not isinstance(psk, bytes | bytearray) or len(psk) < MIN_KEY_SIZE:
            raise ValueError(
                f"the pre-shared key must be at least {MIN_KEY_SIZE} bytes "
                "(use 32 random bytes, e.g. secrets.token_hex(32))"
            )
        for name, value in (
            ("speed", speed),
            ("telemetry_hz", telemetry_hz),
            ("tick", tick),
            ("heartbeat_interval", heartbeat_interval),
            ("handshake_timeout", handshake_timeout),
        ):
            if not math.isfinite(value) or value <= 0.0:
                raise ValueError(f"{name} must be a positive finite number, got {value!r}")
        if max_pending < 1:
            raise ValueError(f"max_pending must be at least 1, got {max_pending!r}")
        if max_pending_bytes < MAX_FRAME:
            raise ValueError(
                f"max_pending_bytes must be at least {MAX_FRAME}, got {max_pending_bytes!r}"
            )
        self.vehicle = vehicle
        self._psk = bytes(psk)
        self._host = host
        self._port = port
        self._clock = clock
        self.speed = float(speed)
        self._telemetry_period = 1.0 / telemetry_hz
        self._tick = tick
        self._heartbeat_interval = heartbeat_interval
        self._handshake_timeout = handshake_timeout
        self._max_pending = max_pending
        self._max_pending_bytes = max_pending_bytes
        self._nonces = nonces
        self._log = log
        self._throttled = _LogThrottle(log, clock)
        self._events = event_log
        self._open_events = None if event_log is not None else open_event_log
        self._samples = 0
        self._last_commit = 0.0
        self.stats = ServerStats()
        self.ledger: ReplyLedger | None = None
        """The current mission's ledger; None until a controller's Hello is adopted."""
        self._active: _Connection | None = None
        self._connections: set[_Connection] = set()
        # Connections not adopted yet, oldest first (a dict keeps the order).
        self._pending: dict[_Connection, None] = {}
        # Sockets accepted whose connection is not registered yet (counted as pending).
        self._accepting = 0
        self._handlers: set[asyncio.Task[None]] = set()
        # Vehicle-side command id -> (the ledger it belongs to, the wire command id).
        self._origin: dict[int, tuple[ReplyLedger, int]] = {}
        # Make-safe request ids carried out for the current mission (a repeat is acked only).
        self._made_safe: set[int] = set()
        self._next_vehicle_id = 1
        self._listener: socket.socket | None = None
        self._acceptor: asyncio.Task[None] | None = None
        self._udp: asyncio.DatagramTransport | None = None
        self._stepper: asyncio.Task[None] | None = None
        self._held: list[Reply] = []
        """Replies of a tick taken ahead of the loop's clock, sent when it gets there."""
        self._last_wall = 0.0
        self._next_sample = vehicle.time
        self._address: tuple[str, int] | None = None

    # ------------------------------------------------------------------ lifecycle

    @property
    def address(self) -> tuple[str, int] | None:
        """The bound TCP (host, port) once started, else None."""
        return self._address

    @property
    def max_pending(self) -> int:
        """Connections that may wait unadopted (after `start`, fitted to the descriptors)."""
        return self._max_pending

    @property
    def event_log(self) -> EventLog | None:
        """The vehicle's event log: given, or created at the first adoption; else None."""
        return self._events

    @property
    def silence_timeout(self) -> float:
        """The vehicle's watchdog in wall seconds (reported in `HelloReply`).

        The watchdog counts vehicle seconds; the controller counts wall seconds, so at
        ``speed`` 50 a 30-s watchdog is 0.6 s for the controller.
        """
        return self.vehicle.watchdog_s / self.speed

    @property
    def controller(self) -> str | None:
        """The address of the current controller connection, None if there is none."""
        return None if self._active is None else self._active.peer

    async def start(self) -> tuple[str, int]:
        """Listen, open the telemetry socket and start stepping the vehicle.

        Returns:
            The bound TCP (host, port); with ``port=0``, the port the system picked.

        Raises:
            RuntimeError: the server was already started.
            OSError: the address cannot be bound.
        """
        if self._listener is not None or self._stepper is not None:
            raise RuntimeError("VehicleServer.start() called twice")
        loop = asyncio.get_running_loop()
        # Our own accept loop rather than asyncio.start_server: asyncio logs a traceback
        # for every failed accept (up to 100 a second when out of descriptors); here a
        # failure is counted, logged rate-limited and retried after a pause.
        infos = await loop.getaddrinfo(
            self._host, self._port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE
        )
        family, _, _, _, address = infos[0]
        listener = socket.create_server(address[:2], family=family, backlog=100)
        listener.setblocking(False)
        self._listener = listener
        bound = listener.getsockname()
        self._address = (str(bound[0]), int(bound[1]))
        try:
            udp, _ = await loop.create_datagram_endpoint(
                asyncio.DatagramProtocol, local_addr=(self._host, 0)
            )
        except OSError:
            self._listener = None
            listener.close()
            raise
        self._udp = udp
        self._fit_to_descriptors()
        self._acceptor = asyncio.create_task(self._accept_loop(listener), name="vehicle accept")
        self._start_stepping()
        return self._address

    def _fit_to_descriptors(self) -> None:
        """Lower ``max_pending`` to what the descriptor limit leaves free; warn once.

        Why: each pending connection holds a descriptor. Under a flood, pending connections
        up to a cap above the limit would make every accept fail (EMFILE) until one is
        evicted; fitted, the controller's connection always finds a descriptor. Measured
        after the sockets are open, so they are counted.
        """
        spare = spare_descriptors()
        if spare is None:
            return
        free, soft = spare
        cap = max(1, free - DESCRIPTOR_RESERVE)
        if cap < self._max_pending:
            self._log(
                f"at most {cap} pending connections, not {self._max_pending}: the descriptor "
                f"limit ({soft}, ulimit -n) leaves {free} free; raise it for more"
            )
            self._max_pending = cap

    def _open_record(self, mission_id: int) -> None:
        """Create the event log (``open_event_log``) at the first adoption, once."""
        opener, self._open_events = self._open_events, None
        if opener is None or self._events is not None:
            return
        try:
            self._events = opener(mission_id)
        except (EventLogError, OSError) as exc:
            self._log(f"no event log: {exc}")

    async def _accept_loop(self, listener: socket.socket) -> None:
        loop = asyncio.get_running_loop()
        while True:
            try:
                sock, peer = await loop.sock_accept(listener)
            except OSError as exc:
                self.stats.accept_errors += 1
                self._throttled("accept errors", f"accept failed: {exc}; retrying")
                if self._pending:  # out of descriptors: give up a pending connection's
                    self._evict("to free a descriptor")
                await asyncio.sleep(self.accept_retry_delay)
                continue
            await self._make_room()
            self._accepting += 1
            task = asyncio.create_task(self._on_socket(sock, peer), name=f"vehicle conn {peer}")
            self._handlers.add(task)
            task.add_done_callback(self._handlers.discard)
            # An accept that finds a connection waiting does not yield: without this, a
            # flood is accepted in one burst, before any eviction has released its socket.
            await asyncio.sleep(0)

    async def _make_room(self) -> None:
        """Keep pending connections, the one just accepted included, within ``max_pending``.

        Evicting here, before the next accept, rather than when the connection registers,
        bounds the descriptors a flood holds at any moment (``max_pending`` plus the one
        just accepted): with ``max_pending`` fitted to the descriptor limit, no accept
        fails for lack of one.
        """
        while len(self._pending) + self._accepting >= self._max_pending:
            if self._pending:
                self._evict(f"to make room (at most {self._max_pending} pending)")
            else:  # accepted ones still registering: let them
                await asyncio.sleep(0)

    async def _on_socket(self, sock: socket.socket, peer: object) -> None:
        try:
            reader, writer = await asyncio.open_connection(sock=sock)
        except OSError as exc:
            sock.close()
            self._throttled("accept errors", f"connection {peer}: {exc}")
            return
        finally:
            self._accepting -= 1  # registered at once below, with no await in between
        await self._serve_connection(reader, writer, peer, None)

    async def start_detached(self) -> None:
        """Start stepping the vehicle without opening any socket.

        For in-memory links (a virtual-time run has no sockets): connections come through
        `accept`, and each one's telemetry goes to the sink given there. Does nothing if
        the server already runs (`start` or `start_detached`); `stop` stops it.
        """
        if self._stepper is None:
            self._start_stepping()

    def _start_stepping(self) -> None:
        self._last_wall = self._clock()
        self._next_sample = self.vehicle.time
        self._stepper = asyncio.create_task(self._step_loop(), name="vehicle server stepper")

    async def stop(self) -> None:
        """Close every connection, stop stepping, release the sockets. Safe to call twice."""
        if self._stepper is not None:
            self._stepper.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._stepper
            self._stepper = None
        if self._acceptor is not None:
            self._acceptor.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._acceptor
            self._acceptor = None
        if self._listener is not None:
            self._listener.close()
            self._listener = None
        for conn in list(self._connections):
            conn.close()
        for task in list(self._handlers):
            task.cancel()
        if self._handlers:
            await asyncio.gather(*self._handlers, return_exceptions=True)
        self._commit_record(force=True)
        self._throttled.flush(force=True)
        if self._udp is not None:
            self._udp.close()
            self._udp = None
        self._active = None

    async def __aenter__(self) -> VehicleServer[M]:
        await self.start()
        return self

    async def __aexit__(self, *exc: object) -> None:
        await self.stop()

    # ------------------------------------------------------------------ vehicle time

    def catch_up(self) -> None:
        """Advance the vehicle to the present (wall time elapsed x speed); send what fell due.

        Telemetry samples are taken on the way, every ``1 / telemetry_hz`` vehicle seconds.
        """
        now = self._clock()
        target = self._target(now)
        self._last_wall = now
        replies: list[Reply] = []
        while self._next_sample <= target:
            replies += self.vehicle.advance_to(max(self._next_sample, self.vehicle.time))
            snapshot = self.vehicle.telemetry()
            if snapshot is not None and not isinstance(snapshot, TelemetryRecord):
                raise TypeError(
                    f"{type(self.vehicle).__name__}.telemetry() returned "
                    f"{type(snapshot).__name__}; a vehicle model returns a "
                    "runtime.telemetry.TelemetryRecord (or None)"
                )
            if snapshot is not None:
                self._record_sample(snapshot)
                self._send_telemetry(snapshot)
            self._next_sample += self._telemetry_period
        replies += self.vehicle.advance_to(target)
        self._issue(replies)

    async def _step_loop(self) -> None:
        loop = asyncio.get_running_loop()
        quiet_until: Callable[[], float | None] | None = getattr(loop, "quiet_until", None)
        if self._clock != loop.time:
            quiet_until = None  # ticks on another clock than the loop's: no look-ahead
        while True:
            if self._held:
                held, self._held = self._held, []
                self._issue(held)  # the vehicle is already at this tick (`_quiet_ticks`)
            else:
                self.catch_up()
            active = self._active
            if active is not None and not active.closed:
                now = self._clock()
                if now - active.last_sent >= self._heartbeat_interval:
                    active.send(Heartbeat(self.vehicle.time), now)
            self._commit_record()
            self._throttled.flush()
            horizon = None if quiet_until is None else quiet_until()
            if horizon is None or not await self._quiet_ticks(loop, horizon):
                await asyncio.sleep(self._tick)

    async def _quiet_ticks(self, loop: asyncio.AbstractEventLoop, horizon: float) -> bool:
        """Do now the ticks before ``horizon`` that nobody would see; wake for the next.

        Under virtual time (`runtime.vclock.VirtualTimeLoop.quiet_until`) no other code
        runs before ``horizon``, so a tick that only steps the vehicle (no telemetry
        sample, heartbeat, log commit or log line due) changes nothing anyone could see
        before then: it is done at once, on the clock reading it would have had. That
        reading is the event loop's own arithmetic for a sleep of one tick,
        ``t + ((t + tick) - t)``, and a tick is taken ahead only if the loop's clock can
        land on the reading of the tick after it exactly, from the present reading (the
        loop moves its clock by ``when - now``). Replies a quiet tick produced are held
        (`_held`) and sent when the loop reaches that tick, as they would have been. A
        fuzz run thus makes about three trips through the event loop a second instead of
        twenty, and does exactly what it did (``tests/runtime/fuzz/test_golden.py``).

        Returns False, having done nothing, when not even the next tick can be taken
        (the caller sleeps one tick as usual); else True once the loop reached the tick
        after the last one taken (or the one whose replies are held).
        """
        now = self._clock()
        tick = self._tick
        t = now
        when = t + tick
        taken = 0
        while taken < _QUIET_MAX_TICKS:
            at = t + (when - t)  # the clock's reading at the tick due at ``when``
            after = at + tick
            if when >= horizon - _QUIET_MARGIN or now + (after - now) != at + (after - at):
                break  # another timer first, or the loop could not land on the tick after
            target = self._quiet_target(at)
            if target is None:
                break
            self._last_wall = at
            self._held = self.vehicle.advance_to(target)
            taken += 1
            if self._held:
                break  # wake at this tick to send them
            t, when = at, after
        if taken == 0:
            return False
        future: asyncio.Future[None] = loop.create_future()
        handle = loop.call_at(when, _wake, future)
        try:
            await future
        finally:
            handle.cancel()
        return True

    def _target(self, now: float) -> float:
        """The vehicle time a tick at clock reading ``now`` advances the vehicle to."""
        return self.vehicle.time + max(0.0, now - self._last_wall) * self.speed

    def _quiet_target(self, at: float) -> float | None:
        """`_target` of a tick at clock reading ``at``, if that tick would only step the
        vehicle (no telemetry sample, log line, heartbeat or log commit due); else None."""
        target = self._target(at)
        if self._next_sample <= target or self._throttled.pending:
            return None
        active = self._active
        if (
            active is not None
            and not active.closed
            and at - active.last_sent >= self._heartbeat_interval
        ):
            return None
        if self._events is not None and at - self._last_commit >= 1.0:
            return None
        return target

    def _record_sample(self, t: TelemetryRecord) -> None:
        if self._events is None:
            return
        self._samples += 1
        self._events.telemetry(t.numbered(self._samples))

    def _record(self, what: str, /, **data: object) -> None:
        if self._events is not None:
            self._events.event(self.vehicle.time, what, **data)

    def _commit_record(self, *, force: bool = False) -> None:
        now = self._clock()
        if self._events is not None and (force or now - self._last_commit >= 1.0):
            self._last_commit = now
            self._events.commit()

    def _send_telemetry(self, t: TelemetryRecord) -> None:
        conn = self._active
        if conn is None or conn.closed or conn.hello is None:
            return
        if conn.sink is None and self._udp is None:
            return
        port = conn.hello.telemetry_port
        key = conn.codec.session_key
        if port == 0 or key is None:
            return
        conn.telemetry_seq += 1
        try:
            datagram = encode_datagram(key, t.numbered(conn.telemetry_seq))
        except ProtocolError as exc:  # a non-finite state: a bug in the model
            self._log(f"telemetry not sent: {exc}")
            return
        if conn.sink is not None:
            conn.sink(datagram, (conn.peer_host, port))
        elif self._udp is not None:
            self._udp.sendto(datagram, (conn.peer_host, port))
        self.stats.datagrams += 1

    # ------------------------------------------------------------------ replies

    def _issue(self, replies: list[Reply]) -> None:
        """Number the vehicle's replies in the mission's ledger and send them."""
        for reply in replies:
            origin = self._origin.get(reply.command_id)
            if origin is None or origin[0] is not self.ledger:
                continue  # the vehicle's own (watchdog) or an abandoned mission's command
            ledger, wire_id = origin
            wire = ledger.issue(wire_id, reply.kind, reply.time, _clip(reply.detail))
            self.stats.replies += 1
            self._record(
                "reply-issued",
                command_id=wire_id,
                reply_seq=wire.reply_seq,
                kind=wire.kind,
                detail=wire.detail,
            )
            self._send_to_controller(wire)

    def _send_to_controller(self, msg: StreamMessage) -> None:
        conn = self._active
        if conn is not None and not conn.closed:
            conn.send(msg, self._clock())

    # ------------------------------------------------------------------ connections

    async def accept(
        self,
        reader: asyncio.StreamReader,
        writer: asyncio.StreamWriter,
        *,
        peer: tuple[str, int],
        datagram_sink: DatagramSink | None = None,
    ) -> None:
        """Serve one connection that did not come through the TCP listener; return when it ends.

        For in-memory links: ``reader`` and ``writer`` are the connection's two streams,
        ``peer`` names the controller in the log, and the connection's telemetry goes to
        ``datagram_sink(datagram, (peer host, announced port))`` (to the UDP socket, if
        the server has one, when None).
        """
        await self._serve_connection(reader, writer, peer, datagram_sink)

    async def _serve_connection(
        self,
        reader: asyncio.StreamReader,
        writer: asyncio.StreamWriter,
        peer: object,
        sink: DatagramSink | None,
    ) -> None:
        task = asyncio.current_task()
        if task is not None:
            self._handlers.add(task)
        conn = _Connection(
            StreamCodec(self._psk, Role.VEHICLE, self._nonces(NONCE_SIZE)),
            writer,
            f"{peer[0]}:{peer[1]}" if isinstance(peer, tuple) else str(peer),
            str(peer[0]) if isinstance(peer, tuple) else self._host,
            deadline=asyncio.get_running_loop().time() + self._handshake_timeout,
            sink=sink,
        )
        while len(self._pending) >= self._max_pending:
            self._evict(f"to make room (at most {self._max_pending} pending)")
        self._connections.add(conn)
        self._pending[conn] = None
        self.stats.connections += 1
        self._throttled(f"connections from {conn.peer_host}", f"connection from {conn.peer}")
        try:
            await self._serve(conn, reader)
        except (ConnectionError, OSError) as exc:
            self._closing(conn, f"connection {conn.peer}: {exc}")
        finally:
            conn.close()
            self._connections.discard(conn)
            self._pending.pop(conn, None)
            if self._active is conn:
                self._active = None
                self._log(f"controller {conn.peer} disconnected; replies kept until resumed")
            if task is not None:
                self._handlers.discard(task)

    def _closing(self, conn: _Connection, line: str) -> None:
        """Log why a connection closes: rate-limited per host, unless it was the controller."""
        if conn.adopted:
            self._log(line)
        else:
            self._throttled(f"connections from {conn.peer_host} closed", line)

    def _evict(self, why: str) -> None:
        """Close the oldest pending connection, preferring one that has not sent a Hello.

        Why that preference: a real controller sends its Hello at once, so under a flood of
        connections that send nothing (or junk) it is never the one evicted.
        """
        victim = next((c for c in self._pending if c.hello is None), None)
        if victim is None:
            victim = next(iter(self._pending))
        del self._pending[victim]
        self.stats.evicted += 1
        self._closing(victim, f"connection {victim.peer}: closed unadopted {why}")
        victim.close()

    async def _serve(self, conn: _Connection, reader: asyncio.StreamReader) -> None:
        try:
            # The whole handshake, however the bytes trickle in, within the deadline.
            async with asyncio.timeout_at(conn.deadline) as deadline:
                while not conn.adopted:
                    if not await self._receive(conn, reader):
                        return
                deadline.reschedule(None)
        except TimeoutError:
            if not conn.adopted:  # else only a drain after the adopting frame was cut
                self.stats.timed_out += 1
                self._closing(conn, f"connection {conn.peer}: no verified frame in time; closing")
                return
        while await self._receive(conn, reader):
            pass

    async def _receive(self, conn: _Connection, reader: asyncio.StreamReader) -> bool:
        """Read and handle one chunk; False once the connection is over."""
        data = await reader.read(4096)
        if not data or conn.closed:
            return False
        self.catch_up()
        pending = not conn.adopted
        for item in conn.codec.feed(data):
            if conn.closed:
                return False
            if isinstance(item, Rejected):
                self.stats.rejected += 1
                self._throttled(
                    f"frames rejected from {conn.peer_host}",
                    f"rejected from {conn.peer}: {item.reason.value}: {item.detail}",
                )
            elif isinstance(item, Hello):
                self._on_hello(conn, item)
            # The first session frame proves the connection live (even an authentic
            # frame that fails later checks): only then is it the controller.
            if not conn.adopted and conn.hello is not None and conn.codec.peer_verified:
                self._adopt(conn)
            if conn.adopted and not isinstance(item, Rejected | Hello):
                self._on_session(conn, item)
        if pending and not conn.adopted:
            conn.received += len(data)
            if conn.received > self._max_pending_bytes:
                self.stats.overflowed += 1
                self._closing(
                    conn, f"connection {conn.peer}: {conn.received} bytes unverified; closing"
                )
                return False
        with contextlib.suppress(ConnectionError):
            await conn.writer.drain()
        return not conn.closed

    def _on_hello(self, conn: _Connection, hello: Hello) -> None:
        received_at = self.vehicle.time
        resumed = self._can_resume(hello)
        last = self.ledger.last_reply_seq if resumed and self.ledger is not None else 0
        conn.hello = hello
        conn.announced_resume = resumed
        conn.send(
            HelloReply(
                hello.nonce,
                conn.codec.nonce,
                received_at,
                self.vehicle.time,
                resumed,
                last,
                self.silence_timeout,
            ),
            self._clock(),
        )

    def _can_resume(self, hello: Hello) -> bool:
        return (
            hello.resume and self.ledger is not None and self.ledger.mission_id == hello.mission_id
        )

    def _adopt(self, conn: _Connection) -> None:
        """Make a verified connection the controller and apply its Hello."""
        hello = conn.hello
        assert hello is not None
        if self._can_resume(hello) != conn.announced_resume:
            # Another controller changed the mission between this Hello and now.
            self._log(f"connection {conn.peer}: mission changed during the handshake; closing")
            conn.close()
            return
        self._pending.pop(conn, None)
        old = self._active
        if old is not None and old is not conn:
            self._log(f"controller {old.peer} replaced by {conn.peer}")
            old.close()
        self._active = conn
        conn.adopted = True
        self.stats.adopted += 1
        self._open_record(hello.mission_id)
        self._record(
            "adopt", peer=conn.peer, mission_id=hello.mission_id, resumed=conn.announced_resume
        )
        self.vehicle.heard_from_controller()
        if conn.announced_resume:
            assert self.ledger is not None
            self.ledger.acknowledge(hello.last_reply_seq)
            pending = self.ledger.unacknowledged(hello.last_reply_seq)
            self._log(
                f"controller {conn.peer} resumed mission {hello.mission_id}; "
                f"re-sending {len(pending)} replies"
            )
            for reply in pending:
                self.stats.resent += 1
                conn.send(reply, self._clock())
        else:
            self.ledger = ReplyLedger(hello.mission_id)
            self._origin.clear()
            self._made_safe.clear()
            what = "could not resume" if hello.resume else "starts"
            self._log(f"controller {conn.peer} {what} mission {hello.mission_id}")

    def _on_session(self, conn: _Connection, msg: StreamMessage) -> None:
        if conn is not self._active or self.ledger is None:
            return
        self.vehicle.heard_from_controller()
        if isinstance(msg, Command):
            self._on_command(conn, msg)
        elif isinstance(msg, ReplyAck):
            self.ledger.acknowledge(msg.reply_seq)
        elif isinstance(msg, MakeSafe):
            self._on_make_safe(conn, msg)
        # Heartbeat: hearing from the controller is all it does.

    def _on_make_safe(self, conn: _Connection, msg: MakeSafe) -> None:
        """Make the vehicle safe once per request id; acknowledge every time.

        Why once: a request id seen again (a controller that retries with the same id)
        must not stop the vehicle's recovery a second time. The replies the stopped commands
        give go into the ledger before the acknowledgement, so they reach the controller
        (now, or on resume) like any other reply.
        """
        make_safe = getattr(self.vehicle, "make_safe", None)
        if make_safe is None:
            # A plugin model written before make_safe joined VehicleModel: say so, and
            # do not acknowledge what was not done (its watchdog still acts on silence).
            self._record("make-safe", request_id=msg.request_id, reason=msg.reason, done=False)
            self._log(
                f"controller {conn.peer} asked the vehicle to make itself safe, but "
                f"{type(self.vehicle).__name__} has no make_safe(); not acknowledged"
            )
            return
        first = msg.request_id not in self._made_safe
        self._made_safe.add(msg.request_id)
        self._record("make-safe", request_id=msg.request_id, reason=msg.reason, repeat=not first)
        if first:
            self._log(
                f"controller {conn.peer} asked the vehicle to make itself safe "
                f"({msg.reason or 'no reason given'}); stopping every command"
            )
            self._issue(make_safe(msg.reason))
            self._commit_record(force=True)
        conn.send(MakeSafeAck(msg.request_id, self.vehicle.time, first), self._clock())

    def _on_command(self, conn: _Connection, cmd: Command) -> None:
        ledger = self.ledger
        assert ledger is not None
        first = ledger.first_time(cmd.command_id)
        self._record(
            "command-received",
            command_id=cmd.command_id,
            name=cmd.name,
            params=dict(cmd.params),
            repeat=not first,
        )
        if not first:
            self.stats.repeats += 1
            for reply in ledger.replies_for(cmd.command_id):
                self.stats.resent += 1
                conn.send(reply, self._clock())
            return
        vehicle_id = self._next_vehicle_id
        self._next_vehicle_id += 1
        self._origin[vehicle_id] = (ledger, cmd.command_id)
        self.stats.commands += 1
        self._issue(self.vehicle.command(vehicle_id, cmd.name, cmd.params))
        # Replies this command caused for other commands (a replaced task's queries): the
        # model hands them out from its next advance, stamped with this command's time.
        self._issue(self.vehicle.advance_to(self.vehicle.time))


_QUIET_MARGIN = 1e-6
"""Seconds before another's timer within which no tick is taken ahead: a tick due at the
same reading as another timer runs in the loop's own order, not ours."""

_QUIET_MAX_TICKS = 1000
"""Ticks taken ahead at most at once (the vehicle's time runs at most this far ahead)."""


def _wake(future: asyncio.Future[None]) -> None:
    if not future.done():
        future.set_result(None)


def _clip(detail: str) -> str:
    """``detail`` cut to what a Reply frame carries (whole UTF-8 characters)."""
    raw = detail.encode("utf-8")
    if len(raw) <= MAX_DETAIL_BYTES:
        return detail
    return raw[: MAX_DETAIL_BYTES - 3].decode("utf-8", errors="ignore") + "..."


async def serve_vehicle(
    model: VehicleModel,
    psk: bytes,
    *,
    host: str = "127.0.0.1",
    port: int = 0,
    speed: float = 1.0,
    duration: float | None = None,
    event_log: EventLog | None = None,
    open_event_log: Callable[[int], EventLog] | None = None,
    log: Callable[[str], None] = _stderr,
) -> ServerStats:
    """Serve ``model`` on ``host:port`` until cancelled or ``duration`` wall seconds pass.

    Prints ``listening on HOST:PORT`` to stdout once the socket is bound (with ``port=0``,
    the port the system picked), so a script or a test can connect. Listens on localhost
    unless told otherwise: a vehicle is exposed to the network only on purpose.

    Returns:
        The server's counters.

    Raises:
        ValueError: a key shorter than `MIN_KEY_SIZE` or a bad ``speed``.
        OSError: the address cannot be bound.
    """
    server = VehicleServer(
        model,
        psk,
        host=host,
        port=port,
        clock=time.monotonic,
        speed=speed,
        log=log,
        event_log=event_log,
        open_event_log=open_event_log,
    )
    try:
        bound_host, bound_port = await server.start()
    except OSError:
        await server.stop()
        raise
    print(f"listening on {bound_host}:{bound_port}", flush=True)
    try:
        if duration is None:
            await asyncio.Event().wait()
        else:
            await asyncio.sleep(duration)
    finally:
        await server.stop()
        log(f"stopped at vehicle time {model.time:.1f} s; {server.stats.summary()}")
    return server.stats


def run_vehicle(
    model: VehicleModel,
    psk: bytes,
    *,
    host: str = "127.0.0.1",
    port: int = 0,
    speed: float = 1.0,
    duration: float | None = None,
    event_log: EventLog | None = None,
    open_event_log: Callable[[int], EventLog] | None = None,
    log: Callable[[str], None] = _stderr,
) -> int:
    """`serve_vehicle` from an integrator's ``main``: blocks until Ctrl-C or ``duration``.

    Returns:
        An exit code: 0 after a clean stop (Ctrl-C included), 1 when the address cannot be
        bound, 2 for a bad key or speed; the reason goes to ``log``, never a traceback.
    """
    try:
        with sigterm_raises():
            asyncio.run(
                serve_vehicle(
                    model,
                    psk,
                    host=host,
                    port=port,
                    speed=speed,
                    duration=duration,
                    event_log=event_log,
                    open_event_log=open_event_log,
                    log=log,
                )
            )
    except Terminated:
        log("stopped (SIGTERM)")
    except KeyboardInterrupt:
        log("stopped (Ctrl-C)")
    except ValueError as exc:
        log(str(exc))
        return 2
    except OSError as exc:
        log(f"cannot listen on {host}:{port}: {exc}")
        return 1
    return 0
