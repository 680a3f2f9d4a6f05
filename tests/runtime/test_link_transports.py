"""MemoryLink and SocketLink against the real VehicleServer.

A minimal controller written here on `runtime.protocol` does the handshake, proves the
connection live with a heartbeat, sends commands and reads replies and telemetry over
the `Connection`/`Link` interface, the way the engine does. The in-memory tests run
under virtual time (a minute of the paper's link in a fraction of a real second); the
socket tests use 127.0.0.1 and a fast profile, and stay well under two seconds.
"""

from __future__ import annotations

import asyncio
import random
import socket
import time
from collections.abc import Awaitable
from dataclasses import dataclass, replace
from typing import TypeVar

import pytest

from romeo_sim.server import VehicleServer
from romeo_sim.vehicle import Vehicle
from runtime import socketlink
from runtime.link import (
    BUILTIN_PROFILES,
    Connection,
    Link,
    LinkEmulator,
    LinkProfile,
    LinkStats,
    MemoryLink,
    SocketLink,
)
from runtime.linkpipe import EmulatedConnection
from runtime.protocol import (
    Command,
    DatagramReceiver,
    Heartbeat,
    Hello,
    HelloReply,
    ParamValue,
    Rejected,
    Reply,
    ReplyAck,
    Role,
    StreamCodec,
    StreamMessage,
    TelemetryRecord,
)
from runtime.socketlink import local_address_towards
from runtime.vclock import run_virtual

PSK = bytes(range(32))
GENOA = BUILTIN_PROFILES["genoa-lisbon"]
T = TypeVar("T")


class MiniController:
    """Just enough of the engine's side of one connection for these tests."""

    def __init__(self, conn: Connection, nonce: bytes) -> None:
        self.conn = conn
        self.codec = StreamCodec(PSK, Role.CONTROLLER, nonce)
        self.inbox: list[StreamMessage | Rejected] = []
        self.hello_reply: HelloReply | None = None
        self.delay = 0.0
        self._beat: asyncio.Task[None] | None = None

    @classmethod
    async def start(
        cls,
        link: Link,
        *,
        nonce: bytes,
        telemetry_port: int = 0,
        mission_id: int = 7,
        resume: bool = False,
        last_reply_seq: int = 0,
    ) -> MiniController:
        """Connect, shake hands, send the verifying heartbeat, then keep beating."""
        loop = asyncio.get_running_loop()
        ctl = cls(await link.connect(), nonce)
        sent_at = loop.time()
        ctl.send(Hello(nonce, sent_at, mission_id, resume, last_reply_seq, telemetry_port))
        ctl.hello_reply = reply = await ctl.receive(HelloReply)
        ctl.delay = (loop.time() - sent_at) / 2 - (reply.sent_at - reply.received_at) / 2
        ctl.send(Heartbeat(loop.time()))
        ctl._beat = asyncio.create_task(ctl._heartbeats())
        return ctl

    async def _heartbeats(self) -> None:
        while not self.conn.closed:
            await asyncio.sleep(1.0)
            self.send(Heartbeat(asyncio.get_running_loop().time()))

    def send(self, msg: StreamMessage) -> None:
        self.conn.write(self.codec.encode(msg))

    def command(self, command_id: int, name: str, **params: ParamValue) -> None:
        self.send(Command(command_id, name, asyncio.get_running_loop().time(), dict(params)))

    async def receive(self, kind: type[T]) -> T:
        """The next message of type ``kind`` (others are kept in ``inbox``)."""
        while True:
            for i, item in enumerate(self.inbox):
                if isinstance(item, kind):
                    del self.inbox[i]
                    return item
            data = await self.conn.read()
            if not data:
                raise ConnectionError("the connection closed")
            self.inbox += self.codec.feed(data)

    async def reply(self, command_id: int, kind: str) -> Reply:
        """The next reply to ``command_id``, acknowledged; fails if it is not of ``kind``."""
        while True:
            reply = await self.receive(Reply)
            self.send(ReplyAck(reply.reply_seq))
            if reply.command_id == command_id:
                assert reply.kind == kind, reply
                return reply

    async def close(self) -> None:
        if self._beat is not None:
            self._beat.cancel()
            await asyncio.gather(self._beat, return_exceptions=True)
        self.conn.close()


def _server(loop: asyncio.AbstractEventLoop, log: list[str], seed: int = 0) -> VehicleServer:
    return VehicleServer(
        Vehicle(seed=seed),
        PSK,
        clock=loop.time,
        nonces=random.Random(seed).randbytes,
        log=log.append,
    )


def _telemetry(key: bytes | None, datagrams: list[bytes]) -> list[TelemetryRecord]:
    assert key is not None
    receiver = DatagramReceiver(key)
    return [t for t in map(receiver.accept, datagrams) if isinstance(t, TelemetryRecord)]


# ---------------------------------------------------------------------- in memory


@dataclass
class MissionRun:
    """What happened in `_mission`."""

    handshake_done: float
    delay: float
    replies: list[Reply]
    datagrams: int
    samples: list[TelemetryRecord]
    stats: LinkStats
    server: str
    server_log: list[str]
    link_log: list[str]
    end: float


async def _mission(profile: LinkProfile | None, seed: int) -> MissionRun:
    """Handshake, INIT and DEPTH over a MemoryLink, then 20 s of telemetry."""
    loop = asyncio.get_running_loop()
    server_log: list[str] = []
    link_log: list[str] = []
    server = _server(loop, server_log, seed)
    emulator = None if profile is None else LinkEmulator(profile, seed)
    link = MemoryLink(server, emulator, log=link_log.append)
    datagrams: list[bytes] = []
    port = await link.open_telemetry(datagrams.append)
    nonce = random.Random(seed).randbytes(16)
    ctl = await MiniController.start(link, nonce=nonce, telemetry_port=port)
    handshake_done = loop.time()
    ctl.command(1, "INIT")
    init = await ctl.reply(1, "done")
    ctl.command(2, "DEPTH", z=1.0)
    depth = await ctl.reply(2, "ack")
    await asyncio.sleep(20.0)
    samples = _telemetry(ctl.codec.session_key, datagrams)
    await ctl.close()
    await link.aclose()
    await server.stop()
    return MissionRun(
        handshake_done,
        ctl.delay,
        [init, depth],
        len(datagrams),
        samples,
        link.stats,
        server.stats.summary(),
        server_log,
        link_log,
        loop.time(),
    )


def test_a_mission_start_over_the_papers_link_in_virtual_time() -> None:
    started = time.perf_counter()
    run = run_virtual(_mission(GENOA, 0), timeout=600)
    assert time.perf_counter() - started < 2.0
    assert [(r.command_id, r.reply_seq, r.kind) for r in run.replies] == [
        (1, 1, "done"),
        (2, 2, "ack"),
    ]
    # The handshake crossed the 9600 bps line both ways: Hello 66 B and HelloReply 88 B,
    # plus TCP/IP headers and the round trip of the connect itself.
    line = (66 + 88 + 4 * 40) * 10 / 9600
    assert run.handshake_done > line + 4 * GENOA.delay_s
    assert run.delay > GENOA.delay_s
    # TelemetryRecord at 2 Hz for about 20 s, through 1 % loss: nearly all of it arrives.
    assert len(run.samples) >= 30
    assert run.samples[-1].z > run.samples[0].z + 0.3  # the vehicle dives
    stats = run.stats
    assert stats.connections == 1 and stats.resets == 0 and stats.connect_failures == 0
    assert stats.datagrams >= len(run.samples) and stats.bytes_down > 0 and stats.bytes_up > 0
    assert any("starts mission 7" in line for line in run.server_log)


def test_without_an_emulator_the_memory_link_is_instant() -> None:
    run = run_virtual(_mission(None, 1), timeout=600)
    assert run.handshake_done == 0.0 and run.delay == 0.0
    assert run.datagrams == len(run.samples) == run.stats.datagrams_delivered


def test_a_whole_run_is_the_same_every_time_with_the_same_seeds() -> None:
    first = run_virtual(_mission(GENOA, 2), timeout=600)
    again = run_virtual(_mission(GENOA, 2), timeout=600)
    other = run_virtual(_mission(GENOA, 3), timeout=600)
    assert first == again
    assert first.handshake_done != other.handshake_done


def test_a_reset_ends_the_connection_and_the_mission_resumes_on_a_new_one() -> None:
    profile = replace(GENOA, reset_rate_per_s=0.05, outage_rate_per_s=0.0)

    async def scenario() -> tuple[float, float, HelloReply, LinkStats, list[str], list[str]]:
        loop = asyncio.get_running_loop()
        server_log: list[str] = []
        link_log: list[str] = []
        server = _server(loop, server_log)
        link = MemoryLink(server, LinkEmulator(profile, 4), log=link_log.append)
        ctl = await MiniController.start(link, nonce=b"1" * 16, mission_id=9)
        conn = ctl.conn
        assert isinstance(conn, EmulatedConnection) and conn.path is not None
        ctl.command(1, "INIT")
        await ctl.reply(1, "done")
        with pytest.raises(ConnectionError):
            while True:  # heartbeats and replies until the link resets the connection
                await ctl.receive(Command)
        reset_seen = loop.time()
        assert conn.closed and await conn.read() == b""
        await ctl.close()
        again = await MiniController.start(
            link, nonce=b"2" * 16, mission_id=9, resume=True, last_reply_seq=1
        )
        assert again.hello_reply is not None
        again.command(2, "DEPTH", z=1.0)
        await again.reply(2, "ack")
        await again.close()
        await link.aclose()
        await server.stop()
        return conn.path.ends_at, reset_seen, again.hello_reply, link.stats, link_log, server_log

    ends_at, seen, reply, stats, link_log, server_log = run_virtual(scenario(), timeout=3600)
    assert seen == ends_at
    assert reply.resumed and reply.last_reply_seq == 1
    assert stats.resets == 1 and stats.connections == 2
    assert len(link_log) == 1, link_log
    assert link_log[0].startswith(f"link: connection 1 reset at t={ends_at:.1f} s, ")
    assert any("resumed mission 9" in line for line in server_log), server_log
    assert any("connection reset by the link emulator" in line for line in server_log), server_log


def test_an_outage_refuses_connections_until_it_ends() -> None:
    profile = replace(GENOA, reset_rate_per_s=0.0, outage_rate_per_s=0.01)

    async def scenario() -> tuple[list[float], float, float, LinkStats, list[str], bool]:
        loop = asyncio.get_running_loop()
        log: list[str] = []
        server = _server(loop, [])
        emulator = LinkEmulator(profile, 5)
        link = MemoryLink(server, emulator, log=log.append)
        ctl = await MiniController.start(link, nonce=b"o" * 16)
        outage = emulator.next_outage(loop.time())
        assert outage is not None and outage.start > loop.time()
        with pytest.raises(ConnectionError):
            while True:
                await ctl.receive(Command)
        cut = loop.time()
        await ctl.close()
        failures: list[float] = []
        while True:
            try:
                conn = await link.connect()
                break
            except ConnectionError as exc:
                assert "outage until" in str(exc)
                failures.append(loop.time())
                await asyncio.sleep(2.0)
        connected = loop.time()
        closed = conn.closed
        conn.close()
        await link.aclose()
        await server.stop()
        assert outage.start == cut
        return failures, outage.end, connected, link.stats, log, closed

    failures, end, connected, stats, log, closed = run_virtual(scenario(), timeout=7200)
    assert failures and all(t <= end + GENOA.delay_s * 2 for t in failures)
    assert connected >= end and not closed
    assert stats.outages == 1 and stats.connect_failures == len(failures)
    assert len(log) == 1, log  # one line per outage, however many attempts it refuses
    assert log[0].startswith("link: outage from t=") and "connection 1 cut" in log[0]


def test_telemetry_for_a_port_nobody_opened_is_dropped() -> None:
    async def scenario() -> LinkStats:
        loop = asyncio.get_running_loop()
        server = _server(loop, [])
        link = MemoryLink(server, None)
        ctl = await MiniController.start(link, nonce=b"p" * 16, telemetry_port=1234)
        await asyncio.sleep(5.0)
        await ctl.close()
        await link.aclose()
        await server.stop()
        return link.stats

    assert run_virtual(scenario(), timeout=60).datagrams == 0


# ---------------------------------------------------------------------- real sockets

FAST = LinkProfile(
    name="fast",
    bandwidth_bps=1e6,
    delay_s=0.005,
    jitter_scale_s=0.002,
    jitter_shape=1.5,
    jitter_cap_s=0.05,
    datagram_loss=0.1,
    datagram_duplicate=0.1,
    datagram_reorder=0.1,
    reorder_delay_s=0.05,
)


async def within(awaitable: Awaitable[T], seconds: float = 3.0) -> T:
    return await asyncio.wait_for(awaitable, seconds)


async def _socket_mission(
    profile: LinkProfile | None,
    *,
    vehicle_host: str = "127.0.0.1",
    telemetry_host: str | None = None,
    peers: list[str] | None = None,
) -> tuple[list[Reply], list[TelemetryRecord], LinkStats]:
    """INIT and DEPTH over a SocketLink to a real server, then telemetry; ``peers``
    receives the address the vehicle saw its controller at."""
    loop = asyncio.get_running_loop()
    server = VehicleServer(
        Vehicle(seed=0),
        PSK,
        host=vehicle_host,
        speed=50.0,
        tick=0.01,
        nonces=random.Random(0).randbytes,
        log=lambda _: None,
    )
    host, port = await server.start()
    emulator = None if profile is None else LinkEmulator(profile, 6)
    link = SocketLink(host, port, emulator, telemetry_host=telemetry_host)
    try:
        datagrams: list[bytes] = []
        udp_port = await link.open_telemetry(datagrams.append)
        assert udp_port > 0
        ctl = await within(MiniController.start(link, nonce=b"s" * 16, telemetry_port=udp_port))
        ctl.command(1, "INIT")
        replies = [await within(ctl.reply(1, "done"))]
        ctl.command(2, "DEPTH", z=1.0)
        replies.append(await within(ctl.reply(2, "ack")))
        started = loop.time()
        while len(_telemetry(ctl.codec.session_key, datagrams)) < 8 and loop.time() < started + 2:
            await asyncio.sleep(0.02)
        samples = _telemetry(ctl.codec.session_key, datagrams)
        if peers is not None and server.controller is not None:
            peers.append(server.controller)
        await ctl.close()
        return replies, samples, link.stats
    finally:
        await link.aclose()
        await server.stop()


@pytest.mark.parametrize("profile", [None, FAST], ids=["plain", "emulated"])
def test_the_socket_link_talks_to_a_real_server(profile: LinkProfile | None) -> None:
    started = time.perf_counter()
    replies, samples, stats = asyncio.run(within(_socket_mission(profile), 10.0))
    assert time.perf_counter() - started < 2.0
    assert [r.reply_seq for r in replies] == [1, 2]
    assert len(samples) >= 8
    assert [s.seq for s in samples] == sorted(s.seq for s in samples)
    assert stats.connections == 1 and stats.bytes_up > 0 and stats.bytes_down > 0
    if profile is None:
        assert stats.datagrams_lost == 0 and stats.datagrams_delivered == stats.datagrams


@pytest.mark.slow
def test_the_socket_link_resets_under_the_emulator_and_reconnects() -> None:
    # Seed 12: the connections live 0.65 s and 0.54 s, ample for a handshake on localhost.
    profile = replace(FAST, reset_rate_per_s=2.0)

    async def scenario() -> tuple[LinkStats, list[str], HelloReply | None]:
        log: list[str] = []
        server = VehicleServer(Vehicle(seed=0), PSK, speed=50.0, tick=0.01, log=lambda _: None)
        host, port = await server.start()
        link = SocketLink(host, port, LinkEmulator(profile, 12), log=log.append)
        try:
            ctl = await within(MiniController.start(link, nonce=b"r" * 16, mission_id=3))
            with pytest.raises(ConnectionError):
                await within(ctl.receive(Command))
            assert ctl.conn.closed and await ctl.conn.read() == b""
            await ctl.close()
            again = await within(
                MiniController.start(link, nonce=b"R" * 16, mission_id=3, resume=True)
            )
            await again.close()
            return link.stats, log, again.hello_reply
        finally:
            await link.aclose()
            await server.stop()

    stats, log, reply = asyncio.run(within(scenario(), 10.0))
    assert stats.resets >= 1 and stats.connections == 2
    assert log and "reset at t=" in log[0]
    assert reply is not None and reply.resumed


def test_connecting_where_nobody_listens_is_a_connection_error() -> None:
    async def scenario() -> LinkStats:
        probe = await asyncio.start_server(lambda r, w: None, "127.0.0.1", 0)
        port = probe.sockets[0].getsockname()[1]
        probe.close()
        await probe.wait_closed()
        link = SocketLink("127.0.0.1", port)
        with pytest.raises(ConnectionError, match=f"cannot connect to 127.0.0.1:{port}"):
            await link.connect()
        await link.aclose()
        return link.stats

    assert asyncio.run(within(scenario())).connect_failures == 1


# ---------------------------------------------------------------------- telemetry address


def _can_bind(host: str) -> bool:
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            probe.bind((host, 0))
    except OSError:
        return False
    return True


other_loopback = pytest.mark.skipif(
    not (_can_bind("127.0.0.2") and _can_bind("127.0.0.3")),
    reason="needs 127.0.0.2 and 127.0.0.3 on the loopback interface (Linux routes 127/8 there)",
)


@other_loopback
@pytest.mark.parametrize(
    ("telemetry_host", "seen_from"),
    [(None, None), ("127.0.0.3", "127.0.0.3"), ("0.0.0.0", None)],
    ids=["route", "given", "wildcard"],
)
def test_telemetry_arrives_from_a_vehicle_on_another_address(
    telemetry_host: str | None, seen_from: str | None
) -> None:
    """The vehicle sends telemetry to the address its controller connects from: the link
    binds its UDP socket there, and connects from the given address when told one."""
    peers: list[str] = []
    replies, samples, _ = asyncio.run(
        within(
            _socket_mission(
                None, vehicle_host="127.0.0.2", telemetry_host=telemetry_host, peers=peers
            ),
            10.0,
        )
    )
    assert [r.reply_seq for r in replies] == [1, 2]
    assert len(samples) >= 8
    (peer,) = peers
    if seen_from is not None:
        assert peer.startswith(f"{seen_from}:"), peer


def _non_loopback_address() -> str | None:
    """This machine's address towards the rest of the world, if it has one."""
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            probe.connect(("198.51.100.1", 9))  # TEST-NET-2: a route lookup, nothing sent
            address = str(probe.getsockname()[0])
    except OSError:
        return None
    return None if address.startswith("127.") else address


@pytest.mark.skipif(_non_loopback_address() is None, reason="no non-loopback address")
def test_telemetry_arrives_from_a_vehicle_on_a_non_loopback_address() -> None:
    """The reported bug: a socket bound to 127.0.0.1 never hears a vehicle that sees its
    controller at the machine's network address. The default binds to that address."""
    address = _non_loopback_address()
    assert address is not None
    peers: list[str] = []
    _, samples, _ = asyncio.run(
        within(_socket_mission(None, vehicle_host=address, peers=peers), 10.0)
    )
    assert len(samples) >= 8
    assert peers and peers[0].startswith(f"{address}:")


def test_the_route_address_is_the_source_of_a_connection_to_the_vehicle() -> None:
    async def scenario() -> tuple[str, str]:
        server = await asyncio.start_server(lambda r, w: w.close(), "127.0.0.1", 0)
        port = server.sockets[0].getsockname()[1]
        try:
            chosen = await local_address_towards("127.0.0.1", port)
            _, writer = await asyncio.open_connection("127.0.0.1", port)
            source = writer.get_extra_info("sockname")[0]
            writer.close()
            return chosen, source
        finally:
            server.close()
            await server.wait_closed()

    chosen, source = asyncio.run(within(scenario()))
    assert chosen == source == "127.0.0.1"


def test_with_no_route_to_the_vehicle_telemetry_listens_on_every_address(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    async def no_route(host: str, port: int) -> str:
        raise OSError(101, "Network is unreachable")

    monkeypatch.setattr(socketlink, "local_address_towards", no_route)

    async def scenario() -> tuple[str, list[str]]:
        log: list[str] = []
        link = SocketLink("10.99.0.1", 9, log=log.append)
        await link.open_telemetry(lambda _: None)
        assert link._udp is not None
        bound = str(link._udp.get_extra_info("sockname")[0])
        await link.aclose()
        return bound, log

    bound, log = asyncio.run(within(scenario()))
    assert bound == "0.0.0.0"
    assert log and "no route to 10.99.0.1" in log[0], log


def test_a_telemetry_address_that_went_away_does_not_stop_reconnects() -> None:
    """The review: connections leave from the telemetry address; when that address is no
    longer this machine's (an interface went down), every reconnect used to fail with
    "cannot assign requested address" and the vehicle was never reached again."""

    async def scenario() -> tuple[str, list[str]]:
        server = await asyncio.start_server(lambda r, w: None, "127.0.0.1", 0)
        port = server.sockets[0].getsockname()[1]
        log: list[str] = []
        link = SocketLink("127.0.0.1", port, log=log.append)
        link._local_host = "192.0.2.77"  # TEST-NET-1: never an address of this machine
        try:
            conn = await link.connect()
            conn.close()
            return str(link._local_host), log
        finally:
            await link.aclose()
            server.close()
            await server.wait_closed()

    local, log = asyncio.run(within(scenario()))
    assert local == "None"
    assert any("192.0.2.77 is no longer an address of this machine" in line for line in log)
