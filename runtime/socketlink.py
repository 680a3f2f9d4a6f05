"""A link to a vehicle over real sockets: TCP for the stream, UDP for telemetry.

With an emulator, the impairments are applied on the controller's side of the sockets:
outgoing bytes wait (serialisation, delay) before they are written to the socket,
incoming bytes and datagrams wait before the controller sees them, a reset or outage
aborts the socket, and an outage makes connecting fail. No proxy is needed, and none
could work: the ``Hello`` that announces the telemetry port is authenticated, so a proxy
could not rewrite it.

Which address telemetry arrives at: the vehicle sends its datagrams to the address its
controller's TCP connection comes from, at the port the ``Hello`` announces. So the UDP
socket binds to the controller's address *on the vehicle's network*, and the TCP
connection leaves from that same address: by default the address the system's routes
pick to reach the vehicle (what a socket connected to it would get), or
``telemetry_host`` when given (``coral-run --telemetry-host``). A wildcard
(``0.0.0.0``, ``::``) binds the UDP socket to every address and leaves the TCP source to
the system. Datagrams are authenticated with the session key whatever the address.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import ipaddress
import socket
from collections.abc import Callable

from runtime.emulator import LinkEmulator
from runtime.linkpipe import EmulatedConnection, EmulatedLink, LinkLog, quiet

__all__ = ["SocketLink", "local_address_towards"]


async def local_address_towards(host: str, port: int) -> str:
    """The local address this machine's routes use to reach ``host:port``.

    A UDP socket connected to the vehicle learns its source address from the routing
    table, and sends nothing. A TCP connection to the same place would get the same
    source: that is the address the vehicle sees its controller at.

    Raises:
        OSError: ``host`` cannot be resolved, or no route leads to it.
    """
    loop = asyncio.get_running_loop()
    infos = await loop.getaddrinfo(host, port, type=socket.SOCK_DGRAM)
    if not infos:
        raise OSError(f"cannot resolve {host}")
    family, kind, proto, _, address = infos[0]
    with socket.socket(family, kind, proto) as probe:
        probe.connect(address)
        return str(probe.getsockname()[0])


def _is_wildcard(host: str) -> bool:
    try:
        return ipaddress.ip_address(host).is_unspecified
    except ValueError:
        return False


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
        telemetry_host: the local address the UDP telemetry socket binds to and the TCP
            connection leaves from; None (the default): the one the routes pick to reach
            ``host`` (`local_address_towards`), so telemetry from a vehicle on another
            machine arrives. A wildcard binds UDP to every address.
        connect_timeout: seconds a TCP connect may take before it counts as failed.
    """

    def __init__(
        self,
        host: str,
        port: int,
        emulator: LinkEmulator | None = None,
        *,
        log: LinkLog = quiet,
        telemetry_host: str | None = None,
        connect_timeout: float = 10.0,
    ) -> None:
        super().__init__(emulator, log)
        self.host = host
        self.port = port
        self._telemetry_host = telemetry_host
        self._local_host: str | None = None
        """Where TCP connections leave from: the telemetry address, once it is bound."""
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
            local = None if self._local_host is None else (self._local_host, 0)
            try:
                reader, writer = await asyncio.wait_for(
                    asyncio.open_connection(self.host, self.port, local_addr=local),
                    self._connect_timeout,
                )
            except OSError as exc:
                if local is None or exc.errno != errno.EADDRNOTAVAIL:
                    raise
                # The telemetry address is gone (an interface went down, a new DHCP
                # lease): reaching the vehicle matters more than where telemetry lands.
                self._local_host = None
                self._log(
                    f"link: {local[0]} is no longer an address of this machine; connecting "
                    "from any address (telemetry may not arrive until the run is restarted)"
                )
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

        Without a ``telemetry_host``, the socket binds to the address the routes pick to
        reach the vehicle; if there is no route yet (the vehicle's network is down), to
        every address, so telemetry arrives once the route is back.

        Raises:
            OSError: the telemetry address cannot be bound.
        """
        if self._closed:
            raise RuntimeError("the link is closed (aclose() was called)")
        self._receive = receive
        if self._udp is None:
            host = self._telemetry_host
            if host is None:
                try:
                    host = await local_address_towards(self.host, self.port)
                except OSError as exc:
                    host = "0.0.0.0"
                    self._log(
                        f"no route to {self.host} yet ({exc}); telemetry socket on every address"
                    )
            loop = asyncio.get_running_loop()
            transport, _ = await loop.create_datagram_endpoint(
                lambda: _Telemetry(self), local_addr=(host, 0)
            )
            self._udp = transport
            self._udp_port = int(transport.get_extra_info("sockname")[1])
            if not _is_wildcard(host):
                self._local_host = str(transport.get_extra_info("sockname")[0])
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
