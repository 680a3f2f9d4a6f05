"""A link to a vehicle over real sockets: TCP for the stream, UDP for telemetry.

With an emulator, the impairments are applied on the controller's side of the sockets:
outgoing bytes wait (serialisation, delay) before they are written to the socket,
incoming bytes and datagrams wait before the controller sees them, a reset or outage
aborts the socket, and an outage makes connecting fail. No proxy is needed, and none
could work: the ``Hello`` that announces the telemetry port is authenticated, so a proxy
could not rewrite it.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable

from runtime.emulator import LinkEmulator
from runtime.linkpipe import EmulatedConnection, EmulatedLink, LinkLog, quiet

__all__ = ["SocketLink"]


class _SocketEnd:
    """The vehicle's end as seen from here: the TCP socket to it."""

    def __init__(self, writer: asyncio.StreamWriter) -> None:
        self.writer = writer

    def deliver(self, data: bytes) -> None:
        if not self.writer.is_closing():
            self.writer.write(data)

    def deliver_eof(self) -> None:
        self.writer.close()  # after the bytes already written

    def abort(self, reason: str) -> None:
        self.writer.transport.abort()


class _Telemetry(asyncio.DatagramProtocol):
    def __init__(self, link: SocketLink) -> None:
        self._link = link

    def datagram_received(self, data: bytes, addr: tuple[str | int, ...]) -> None:
        self._link._on_datagram(data)


class SocketLink(EmulatedLink):
    """A link to a vehicle at ``host:port`` over real sockets (implements `Link`).

    Args:
        host: the vehicle's address.
        port: its TCP port.
        emulator: impairments applied on this side; None: the network as it is.
        log: one line per reset and per outage (failed attempts are only counted).
        telemetry_host: local address the UDP telemetry socket binds to.
        connect_timeout: seconds a TCP connect may take before it counts as failed.
    """

    def __init__(
        self,
        host: str,
        port: int,
        emulator: LinkEmulator | None = None,
        *,
        log: LinkLog = quiet,
        telemetry_host: str = "127.0.0.1",
        connect_timeout: float = 10.0,
    ) -> None:
        super().__init__(emulator, log)
        self.host = host
        self.port = port
        self._telemetry_host = telemetry_host
        self._connect_timeout = connect_timeout
        self._udp: asyncio.DatagramTransport | None = None
        self._udp_port = 0
        self._receive: Callable[[bytes], None] | None = None
        self._pumps: set[asyncio.Task[None]] = set()
        self._writers: list[asyncio.StreamWriter] = []

    async def connect(self) -> EmulatedConnection:
        """A new TCP connection to the vehicle.

        Raises:
            ConnectionError: refused, unreachable, timed out, or an emulated outage.
        """
        path = await self._attempt()
        try:
            reader, writer = await asyncio.wait_for(
                asyncio.open_connection(self.host, self.port), self._connect_timeout
            )
        except TimeoutError:
            raise self._failed(
                f"cannot connect to {self.host}:{self.port}: no answer in "
                f"{self._connect_timeout:g} s"
            ) from None
        except OSError as exc:
            reason = exc.strerror or str(exc)
            raise self._failed(f"cannot connect to {self.host}:{self.port}: {reason}") from exc
        loop = asyncio.get_running_loop()
        conn = EmulatedConnection(loop, self._next_number(), path, _SocketEnd(writer), self)
        self._register(conn)
        self._writers = [w for w in self._writers if not w.transport.is_closing()]
        self._writers.append(writer)
        pump = loop.create_task(self._pump(reader, conn), name=f"socket link {conn.number}")
        self._pumps.add(pump)
        pump.add_done_callback(self._pumps.discard)
        return conn

    async def _pump(self, reader: asyncio.StreamReader, conn: EmulatedConnection) -> None:
        """Hand what the socket receives to the emulated connection."""
        try:
            while data := await reader.read(65536):
                conn.from_vehicle(data)
        except (ConnectionError, OSError):
            pass  # reset by the vehicle (or by us): an end of stream all the same
        finally:
            conn.vehicle_closed()

    async def open_telemetry(self, receive: Callable[[bytes], None]) -> int:
        """Open the UDP socket (once) and deliver datagrams to ``receive``; its port.

        Raises:
            OSError: the telemetry address cannot be bound.
        """
        if self._closed:
            raise RuntimeError("the link is closed (aclose() was called)")
        self._receive = receive
        if self._udp is None:
            loop = asyncio.get_running_loop()
            transport, _ = await loop.create_datagram_endpoint(
                lambda: _Telemetry(self), local_addr=(self._telemetry_host, 0)
            )
            self._udp = transport
            self._udp_port = int(transport.get_extra_info("sockname")[1])
        return self._udp_port

    def _on_datagram(self, data: bytes) -> None:
        if self._receive is not None:
            self._datagram(data, self._receive)

    async def aclose(self) -> None:
        """Close every connection and the telemetry socket at once."""
        self._receive = None
        self._shutdown_all()
        for writer in self._writers:
            writer.close()
        for writer in self._writers:
            with contextlib.suppress(ConnectionError, OSError, TimeoutError):
                await asyncio.wait_for(writer.wait_closed(), 1.0)
        self._writers.clear()
        if self._pumps:
            await asyncio.wait(list(self._pumps), timeout=1.0)
        if self._udp is not None:
            self._udp.close()
            self._udp = None
