"""A slow or hostile client never stalls the vehicle server (issue 17, items 2 and 6).

Real localhost sockets (127.0.0.1 only) and small limits: a handshake deadline of a few
tenths of a second, a handful of pending connections. Every await has a timeout and every
loop a bound; each test takes well under two seconds.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import random
import re
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any, TypeVar

import pytest

from romeo_sim.vehicle import Vehicle
from runtime.keys import write_key_file
from runtime.link import MemoryLink
from runtime.protocol import (
    MAX_FRAME,
    Command,
    Heartbeat,
    Hello,
    HelloReply,
    ParamValue,
    Rejected,
    Reply,
    Role,
    StreamCodec,
    StreamMessage,
)
from runtime.vclock import run_virtual
from runtime.vehicle import VehicleServer
from runtime.vehicle import server as server_module
from runtime.vehicle.server import DESCRIPTOR_RESERVE, _LogThrottle, spare_descriptors

PSK = bytes(range(32))
WAIT = 3.0  # seconds: the longest any single await may take
T = TypeVar("T")


async def within(awaitable: Awaitable[T], seconds: float = WAIT) -> T:
    return await asyncio.wait_for(awaitable, seconds)


async def until(condition: Callable[[], bool], seconds: float = WAIT) -> None:
    async with asyncio.timeout(seconds):
        while not condition():
            await asyncio.sleep(0.005)


def make_server(log: list[str], *, speed: float = 50.0, **limits: Any) -> VehicleServer[Vehicle]:
    return VehicleServer(
        Vehicle(seed=0),
        PSK,
        clock=time.monotonic,
        speed=speed,
        tick=0.01,
        nonces=random.Random(0).randbytes,
        log=log.append,
        **limits,
    )


class Controller:
    """The engine's side of one connection, just enough for these tests."""

    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.reader = reader
        self.writer = writer
        self.codec = StreamCodec(PSK, Role.CONTROLLER, b"c" * 16)
        self.inbox: list[StreamMessage | Rejected] = []

    @classmethod
    async def connect(cls, port: int) -> Controller:
        """Connect and send the Hello (not yet the verifying frame)."""
        reader, writer = await within(asyncio.open_connection("127.0.0.1", port))
        ctl = cls(reader, writer)
        await ctl.send(Hello(ctl.codec.nonce, 0.0, 7, False, 0, 0))
        return ctl

    async def send(self, msg: StreamMessage) -> None:
        self.writer.write(self.codec.encode(msg))
        await within(self.writer.drain())

    async def command(self, command_id: int, name: str, **params: ParamValue) -> None:
        await self.send(Command(command_id, name, 0.0, dict(params)))

    async def receive(self, kind: type[T]) -> T:
        async def next_one() -> T:
            while True:
                for i, item in enumerate(self.inbox):
                    if isinstance(item, kind):
                        del self.inbox[i]
                        return item
                data = await self.reader.read(4096)
                if not data:
                    raise ConnectionError("the vehicle closed the connection")
                self.inbox += self.codec.feed(data)

        return await within(next_one())

    async def close(self) -> None:
        self.writer.close()
        with contextlib.suppress(ConnectionError):
            await within(self.writer.wait_closed())


async def closed_by_peer(reader: asyncio.StreamReader, seconds: float = WAIT) -> bool:
    """True once the server closed the connection (EOF or reset) within ``seconds``."""
    try:
        async with asyncio.timeout(seconds):
            while await reader.read(4096):
                pass
    except ConnectionError:
        return True
    except TimeoutError:
        return False
    return True


@pytest.mark.slow
def test_a_trickling_client_is_closed_at_the_handshake_deadline() -> None:
    """One byte of a real Hello every 50 ms: each read is quick, the handshake never ends."""
    log: list[str] = []

    async def scenario() -> tuple[float, VehicleServer[Vehicle]]:
        async with make_server(log, handshake_timeout=0.3) as server:
            assert server.address is not None
            reader, writer = await within(asyncio.open_connection("127.0.0.1", server.address[1]))
            codec = StreamCodec(PSK, Role.CONTROLLER, b"t" * 16)
            hello = codec.encode(Hello(codec.nonce, 0.0, 7, False, 0, 0))
            started = time.monotonic()
            for byte in hello[:40]:  # 2 s of trickling at most
                writer.write(bytes([byte]))
                if await closed_by_peer(reader, 0.05):
                    break
            elapsed = time.monotonic() - started
            writer.close()
            return elapsed, server

    elapsed, server = asyncio.run(within(scenario(), 10.0))
    assert 0.25 <= elapsed < 1.0, elapsed
    assert server.stats.timed_out == 1 and server.stats.adopted == 0
    assert any("no verified frame in time" in line for line in log), log


def test_the_handshake_deadline_holds_on_the_in_memory_path_in_virtual_time() -> None:
    """The same bound through `VehicleServer.accept`, exactly, on the loop's (virtual) clock:
    one byte a second, a 5-s deadline, the connection ends 5 s after it was accepted."""
    log: list[str] = []

    async def scenario() -> tuple[float, int, VehicleServer[Vehicle]]:
        loop = asyncio.get_running_loop()
        server = VehicleServer(
            Vehicle(seed=0),
            PSK,
            clock=loop.time,
            handshake_timeout=5.0,
            nonces=random.Random(0).randbytes,
            log=log.append,
        )
        link = MemoryLink(server)
        conn = await link.connect()
        started = loop.time()
        sent = 0
        for _ in range(60):  # at most a minute of virtual time
            conn.write(b"\xc5")
            sent += 1
            with contextlib.suppress(TimeoutError):
                if await asyncio.wait_for(conn.read(), 1.0) == b"":
                    break
        ended = loop.time() - started
        await link.aclose()
        await server.stop()
        return ended, sent, server

    ended, sent, server = run_virtual(scenario(), timeout=120)
    assert ended == pytest.approx(5.0, abs=1e-6) and sent == 6
    assert server.stats.timed_out == 1


def test_a_flood_of_pending_connections_does_not_lock_the_controller_out() -> None:
    log: list[str] = []

    async def scenario() -> tuple[Reply, int, VehicleServer[Vehicle]]:
        async with make_server(log, max_pending=4) as server:
            assert server.address is not None
            port = server.address[1]
            junk: list[tuple[asyncio.StreamReader, asyncio.StreamWriter]] = []
            for _ in range(6):  # more junk than may wait: the oldest two are closed
                junk.append(await within(asyncio.open_connection("127.0.0.1", port)))
            await until(lambda: server.stats.connections == 6)
            ctl = await Controller.connect(port)
            reply = await ctl.receive(HelloReply)
            assert reply.controller_nonce == ctl.codec.nonce
            # More junk between the HelloReply and the verifying frame: the controller
            # sent a Hello, so junk that sent none is evicted before it.
            for _ in range(8):
                junk.append(await within(asyncio.open_connection("127.0.0.1", port)))
            await until(lambda: server.stats.connections == 15)
            await ctl.send(Heartbeat(0.0))
            await ctl.command(1, "DEPTH", z=1.0)
            ack = await ctl.receive(Reply)
            assert server.controller is not None
            closed = sum([await closed_by_peer(r, 0.01) for r, _ in junk])
            for _, writer in junk:
                writer.close()
            await ctl.close()
            return ack, closed, server

    ack, closed, server = asyncio.run(within(scenario(), 10.0))
    assert (ack.command_id, ack.kind) == (1, "ack")
    assert server.stats.evicted == 15 - 4 == closed
    assert server.stats.adopted == 1 and server.stats.commands == 1
    # Fifteen connections from one host: three lines, the rest held for a summary.
    assert sum("connection from" in line for line in log) == 3, log
    assert sum("closed unadopted to make room" in line for line in log) == 3, log
    assert any("12 more connections from 127.0.0.1" in line for line in log), log


def test_garbage_is_counted_but_logged_only_a_few_times() -> None:
    """10,000 bytes that make ~5,000 rejected frames, to the controller and to a pending
    connection: a handful of log lines, every rejection counted, the link goes on."""
    log: list[str] = []
    garbage = b"\xc5\x01" * 5_000  # a frame start every 2 bytes, each failing its check

    async def scenario() -> tuple[Reply, VehicleServer[Vehicle]]:
        async with make_server(log) as server:
            assert server.address is not None
            port = server.address[1]
            ctl = await Controller.connect(port)
            await ctl.receive(HelloReply)
            await ctl.send(Heartbeat(0.0))
            ctl.writer.write(garbage)
            await ctl.command(1, "DEPTH", z=1.0)
            ack = await ctl.receive(Reply)

            reader, writer = await within(asyncio.open_connection("127.0.0.1", port))
            writer.write(garbage)
            with contextlib.suppress(ConnectionError):
                await within(writer.drain())
            assert await closed_by_peer(reader)  # more than max_pending_bytes unverified
            writer.close()
            await ctl.close()
            return ack, server

    ack, server = asyncio.run(within(scenario(), 10.0))
    assert (ack.command_id, ack.kind) == (1, "ack")
    stats = server.stats
    assert stats.rejected >= 4_990 + 2_000, stats  # ~5,000, and ~2,000 before the cut
    assert stats.overflowed == 1 and stats.commands == 1
    assert sum(line.startswith("rejected from") for line in log) == 3, log
    summary = [line for line in log if "more frames rejected from 127.0.0.1" in line]
    assert len(summary) == 1 and int(summary[0].split()[0]) == stats.rejected - 3, log
    assert len(log) <= 12, log


@pytest.mark.slow
def test_a_quiet_adopted_controller_outlives_the_handshake_deadline() -> None:
    log: list[str] = []

    async def scenario() -> tuple[Reply, VehicleServer[Vehicle]]:
        # Real time: the vehicle's watchdog is 30 s, so a second of silence is fine.
        async with make_server(
            log, speed=1.0, handshake_timeout=0.2, heartbeat_interval=0.2
        ) as server:
            assert server.address is not None
            ctl = await Controller.connect(server.address[1])
            await ctl.receive(HelloReply)
            await ctl.send(Heartbeat(0.0))
            await until(lambda: server.controller is not None)
            await asyncio.sleep(1.0)  # five handshake deadlines of silence
            await ctl.command(1, "DEPTH", z=1.0)
            ack = await ctl.receive(Reply)
            assert isinstance(await ctl.receive(Heartbeat), Heartbeat)  # the server's own
            await ctl.close()
            return ack, server

    ack, server = asyncio.run(within(scenario(), 10.0))
    assert (ack.command_id, ack.kind) == (1, "ack")
    assert server.stats.timed_out == 0 and server.stats.adopted == 1


def test_accept_errors_are_counted_logged_rarely_and_free_a_descriptor(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Out of descriptors: no traceback per attempt, a pending connection is given up, and
    the controller gets in once accept works again."""
    log: list[str] = []

    async def scenario() -> VehicleServer[Vehicle]:
        loop = asyncio.get_running_loop()
        real_accept = loop.sock_accept
        calls = 0

        async def flaky_accept(sock: socket.socket) -> tuple[socket.socket, Any]:
            nonlocal calls
            calls += 1
            if 2 <= calls <= 31:  # after the first connection: 30 failures
                raise OSError(errno.EMFILE, "Too many open files")
            return await real_accept(sock)

        monkeypatch.setattr(loop, "sock_accept", flaky_accept)
        server = make_server(log)
        server.accept_retry_delay = 0.001
        async with server:
            assert server.address is not None
            port = server.address[1]
            reader, writer = await within(asyncio.open_connection("127.0.0.1", port))
            assert await closed_by_peer(reader)  # given up to free a descriptor
            writer.close()
            ctl = await Controller.connect(port)
            await ctl.receive(HelloReply)
            await ctl.send(Heartbeat(0.0))
            await ctl.command(1, "DEPTH", z=1.0)
            await ctl.receive(Reply)
            await ctl.close()
        return server

    server = asyncio.run(within(scenario(), 10.0))
    assert server.stats.accept_errors == 30 and server.stats.evicted == 1
    assert server.stats.adopted == 1
    assert sum("accept failed" in line for line in log) == 3, log
    assert any(line.startswith("27 more accept errors") for line in log), log


def test_the_log_throttle_summarises_each_period() -> None:
    now = [0.0]
    lines: list[str] = []
    throttle = _LogThrottle(lines.append, lambda: now[0], burst=2, period=10.0)
    for _ in range(50):
        throttle("frames rejected from h", "rejected from h:1")
    throttle("connections from h", "connection from h:2")
    assert lines == ["rejected from h:1"] * 2 + ["connection from h:2"]
    now[0] = 9.0
    throttle.flush()
    assert len(lines) == 3  # the period is not over yet
    now[0] = 12.5
    throttle("frames rejected from h", "rejected from h:1")  # a new period begins
    assert lines[3:] == ["48 more frames rejected from h in the last 12 s", "rejected from h:1"]
    now[0] = 30.0
    throttle.flush()
    assert len(lines) == 5 and not throttle._kinds  # nothing held back, nothing kept


@pytest.mark.parametrize(
    ("limits", "message"),
    [
        ({"max_pending": 0}, "max_pending must be at least 1"),
        ({"max_pending_bytes": 100}, f"max_pending_bytes must be at least {MAX_FRAME}"),
        ({"handshake_timeout": 0.0}, "handshake_timeout must be a positive"),
    ],
)
def test_limits_are_checked(limits: dict[str, Any], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        make_server([], **limits)


# ---------------------------------------------------------------------- descriptor limit


def test_max_pending_is_fitted_to_the_descriptors_left(monkeypatch: pytest.MonkeyPatch) -> None:
    """Few descriptors left: the cap is lowered at start, with one warning; many: kept."""
    outcomes: list[tuple[int, list[str]]] = []
    for spare in [(DESCRIPTOR_RESERVE + 5, 64), (DESCRIPTOR_RESERVE - 3, 20), (5000, 8192)]:
        monkeypatch.setattr(server_module, "spare_descriptors", lambda spare=spare: spare)
        log: list[str] = []

        async def scenario(log: list[str] = log) -> int:
            async with make_server(log) as server:
                return server.max_pending

        outcomes.append((asyncio.run(within(scenario())), log))
    (fitted, warned), (floor, _), (kept, quiet) = outcomes
    assert fitted == 5 and floor == 1 and kept == 16
    assert [line for line in warned if "pending connections" in line] == [
        "at most 5 pending connections, not 16: the descriptor limit (64, ulimit -n) leaves "
        f"{DESCRIPTOR_RESERVE + 5} free; raise it for more"
    ]
    assert not any("pending connections" in line for line in quiet), quiet


def test_spare_descriptors_counts_what_this_process_holds() -> None:
    spare = spare_descriptors()
    if spare is None:
        pytest.skip("no descriptor limit to fit on this system")
    free, soft = spare
    with socket.socket() as one, socket.socket() as two:
        assert (one.fileno(), two.fileno()) and spare_descriptors() == (free - 2, soft)


LIMITED_SOFT = 28
"""The served vehicle's soft descriptor limit in the next test: about 11 are open once it
listens, so the cap of 16 pending connections would run it out of descriptors."""


@pytest.mark.slow
@pytest.mark.skipif(sys.platform != "linux", reason="counts descriptors in /proc (Linux)")
def test_under_a_low_descriptor_limit_the_controller_gets_through_a_flood(
    tmp_path: Path,
) -> None:
    """A real ``romeo-sim serve`` whose soft RLIMIT_NOFILE is lowered (setrlimit, then
    exec): the cap is lowered at start, no accept ever fails for lack of a descriptor
    while 40 hostile connections come and hold on, and the controller is adopted."""
    key = tmp_path / "psk.hex"
    write_key_file(key, PSK)
    limit = (
        "import os, resource, sys\n"
        "_, hard = resource.getrlimit(resource.RLIMIT_NOFILE)\n"
        f"resource.setrlimit(resource.RLIMIT_NOFILE, ({LIMITED_SOFT}, hard))\n"
        "os.execv(sys.argv[1], sys.argv[1:])\n"
    )
    romeo = Path(sys.executable).parent / "romeo-sim"
    serve = [str(romeo), "serve", "--key-file", str(key), "--speed", "20", "--duration", "8"]
    vehicle = subprocess.Popen(
        [sys.executable, "-c", limit, *serve],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert vehicle.stdout is not None
        line = vehicle.stdout.readline()
        assert line.startswith("listening on 127.0.0.1:"), (line, vehicle.stderr)
        port = int(line.rsplit(":", 1)[1])

        async def scenario() -> Reply:
            hostile: list[asyncio.StreamWriter] = []
            for _ in range(20):
                hostile.append((await within(asyncio.open_connection("127.0.0.1", port)))[1])
            await asyncio.sleep(0.3)  # let the vehicle accept them
            ctl = await Controller.connect(port)
            await ctl.receive(HelloReply)
            for _ in range(20):  # more while the controller is pending: it sent a Hello
                hostile.append((await within(asyncio.open_connection("127.0.0.1", port)))[1])
            await ctl.send(Heartbeat(0.0))
            await ctl.command(1, "DEPTH", z=1.0)
            ack = await ctl.receive(Reply)
            for writer in hostile:
                writer.close()
            await ctl.close()
            return ack

        ack = asyncio.run(within(scenario(), 10.0))
    finally:
        vehicle.send_signal(signal.SIGINT)
        _, err = vehicle.communicate(timeout=15)
    assert (ack.command_id, ack.kind) == (1, "ack")
    match = re.search(r"at most (\d+) pending connections, not 16", err)
    assert match and 1 <= int(match.group(1)) < 16, err
    assert "accept failed" not in err and "; 0 accept errors" in err, err
    assert "1 adopted" in err and "Traceback" not in err, err
