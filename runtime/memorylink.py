"""An in-memory link to a vehicle server in the same process, for virtual-time runs.

`MemoryLink` joins the controller to a `VehicleServer` without sockets: each
connection hands the server a real ``asyncio.StreamReader``/``StreamWriter`` pair, so
the server's own connection handler serves it, and the server's telemetry reaches the
controller's callback. Every byte and datagram goes through the link emulator. Under
`runtime.vclock.VirtualTimeLoop` a whole mission over the paper's link runs in seconds,
the same way each time.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Any, Protocol

from runtime.emulator import LinkEmulator
from runtime.linkpipe import EmulatedConnection, EmulatedLink, LinkLog, quiet

__all__ = ["InMemoryServer", "MemoryLink"]

DatagramSink = Callable[[bytes, tuple[str, int]], None]


class InMemoryServer(Protocol):
    """What `MemoryLink` needs of the vehicle (`romeo_sim.server.VehicleServer` has it)."""

    async def start_detached(self) -> None:
        """Run the vehicle without sockets (does nothing if it already runs)."""

    async def accept(
        self,
        reader: asyncio.StreamReader,
        writer: asyncio.StreamWriter,
        *,
        peer: tuple[str, int],
        datagram_sink: DatagramSink | None = None,
    ) -> None:
        """Serve one connection until it closes; its telemetry goes to ``datagram_sink``."""


class _ServerEnd:
    """The vehicle's end of one in-memory connection: a stream protocol and its transport."""

    def __init__(self, protocol: asyncio.StreamReaderProtocol) -> None:
        self.protocol = protocol
        self._lost = False

    def deliver(self, data: bytes) -> None:
        if not self._lost:
            self.protocol.data_received(data)

    def deliver_eof(self) -> None:
        if not self._lost:
            self.protocol.eof_received()

    def abort(self, reason: str) -> None:
        self.lose(ConnectionResetError(reason))

    def lose(self, exc: Exception | None) -> None:
        if not self._lost:
            self._lost = True
            self.protocol.connection_lost(exc)


class _MemoryTransport(asyncio.Transport):
    """The transport under the server's StreamWriter: writes go into the emulated link."""

    def __init__(self, end: _ServerEnd, conn: EmulatedConnection, extra: dict[str, Any]) -> None:
        super().__init__(extra)
        self._end = end
        self._conn = conn
        self._closing = False

    def write(self, data: bytes | bytearray | memoryview) -> None:
        if not self._closing:
            self._conn.from_vehicle(bytes(data))

    def close(self) -> None:
        if self._closing:
            return
        self._closing = True
        self._conn.vehicle_closed()
        asyncio.get_running_loop().call_soon(self._end.lose, None)

    def abort(self) -> None:
        self.close()

    def is_closing(self) -> bool:
        return self._closing

    def can_write_eof(self) -> bool:
        return False

    def get_write_buffer_size(self) -> int:
        return 0

    def get_write_buffer_limits(self) -> tuple[int, int]:
        return (0, 0)

    def set_write_buffer_limits(self, high: int | None = None, low: int | None = None) -> None:
        pass  # nothing is buffered here: the emulator holds the bytes

    def is_reading(self) -> bool:
        return True

    def pause_reading(self) -> None:
        pass  # the server reads whenever it likes; the emulator paces the bytes

    def resume_reading(self) -> None:
        pass


class MemoryLink(EmulatedLink):
    """A link to a vehicle server in this process, through the emulator (implements `Link`).

    The server is started with ``start_detached()`` on first use unless it already runs;
    stopping it stays with its owner.

    Args:
        server: the vehicle, e.g. `romeo_sim.server.VehicleServer` built with
            ``clock=loop.time``.
        emulator: decides delays and losses; None: a perfect link.
        log: one line per reset and per outage (failed attempts are only counted).
        telemetry_port: the port announced in ``Hello`` (any number but 0 will do).
    """

    def __init__(
        self,
        server: InMemoryServer,
        emulator: LinkEmulator | None = None,
        *,
        log: LinkLog = quiet,
        telemetry_port: int = 40000,
    ) -> None:
        super().__init__(emulator, log)
        if not 0 < telemetry_port < 65536:
            raise ValueError(f"telemetry_port must be 1..65535, got {telemetry_port}")
        self._server = server
        self._telemetry_port = telemetry_port
        self._receive: Callable[[bytes], None] | None = None
        self._started = False
        self._tasks: set[asyncio.Task[None]] = set()

    async def connect(self) -> EmulatedConnection:
        """A new connection to the vehicle.

        Raises:
            ConnectionError: the emulator refused it (an outage).
        """
        if not self._started:
            self._started = True
            await self._server.start_detached()
        path = await self._attempt()
        loop = asyncio.get_running_loop()
        number = self._next_number()
        peer = ("memory", 50000 + number)
        reader = asyncio.StreamReader()
        protocol = asyncio.StreamReaderProtocol(reader)
        end = _ServerEnd(protocol)
        conn = EmulatedConnection(loop, number, path, end, self)
        transport = _MemoryTransport(end, conn, {"peername": peer, "sockname": ("vehicle", 0)})
        protocol.connection_made(transport)
        writer = asyncio.StreamWriter(transport, protocol, reader, loop)
        self._register(conn)
        task = loop.create_task(
            self._server.accept(reader, writer, peer=peer, datagram_sink=self._on_datagram),
            name=f"vehicle side of memory connection {number}",
        )
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)
        return conn

    async def open_telemetry(self, receive: Callable[[bytes], None]) -> int:
        """Deliver the vehicle's telemetry datagrams to ``receive``; the port to announce."""
        self._receive = receive
        return self._telemetry_port

    async def aclose(self) -> None:
        """Close every connection at once and stop delivering telemetry."""
        self._receive = None
        self._shutdown_all()
        await asyncio.sleep(0)  # let the server see the ends of stream

    def _on_datagram(self, data: bytes, address: tuple[str, int]) -> None:
        receive = self._receive
        if receive is None or address[1] != self._telemetry_port:
            return  # nobody listens on that port
        self._datagram(data, receive)
