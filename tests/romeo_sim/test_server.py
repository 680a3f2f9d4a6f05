"""`romeo-sim serve`: the simulated vehicle on real sockets (127.0.0.1 only).

Each test starts a `VehicleServer` on port 0 at 50x real time and talks to it with a
minimal controller written here on top of `runtime.protocol`, the way the engine will.
Every await has a timeout; each test takes well under a second.
"""

from __future__ import annotations

import asyncio
import itertools
import random
import socket
import time
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import TypeVar

import pytest

from romeo_sim.cli import main
from romeo_sim.server import VehicleServer
from romeo_sim.vehicle import Vehicle
from runtime.eventlog import EventLog
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

PSK = bytes(range(32))
WAIT = 3.0  # seconds: the longest any single await may take
T = TypeVar("T")


async def within(awaitable: Awaitable[T], seconds: float = WAIT) -> T:
    """``awaitable`` or TimeoutError after ``seconds``."""
    return await asyncio.wait_for(awaitable, seconds)


def make_server(log: list[str], seed: int = 0) -> VehicleServer:
    return VehicleServer(
        Vehicle(seed=seed),
        PSK,
        clock=time.monotonic,
        speed=50.0,
        tick=0.01,
        nonces=random.Random(seed).randbytes,
        log=log.append,
    )


class Controller:
    """Just enough of the engine's side of one connection for these tests."""

    def __init__(
        self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, nonce: bytes
    ) -> None:
        self.reader = reader
        self.writer = writer
        self.codec = StreamCodec(PSK, Role.CONTROLLER, nonce)
        self.inbox: list[StreamMessage | Rejected] = []
        self.hello_reply: HelloReply | None = None
        self._beat: asyncio.Task[None] | None = None

    @classmethod
    async def connect(
        cls,
        port: int,
        *,
        nonce: bytes,
        mission_id: int = 7,
        resume: bool = False,
        last_reply_seq: int = 0,
        telemetry_port: int = 0,
    ) -> Controller:
        """Connect, shake hands, send the verifying Heartbeat, then keep beating."""
        reader, writer = await within(asyncio.open_connection("127.0.0.1", port))
        ctl = cls(reader, writer, nonce)
        hello = Hello(nonce, 0.0, mission_id, resume, last_reply_seq, telemetry_port)
        await ctl.send(hello)
        ctl.hello_reply = await within(ctl.receive(HelloReply))
        await ctl.send(Heartbeat(0.0))
        ctl._beat = asyncio.create_task(ctl._heartbeats())
        return ctl

    async def _heartbeats(self) -> None:
        # The vehicle's watchdog is 30 s of vehicle time, 0.6 s of wall time at 50x.
        while True:
            await asyncio.sleep(0.05)
            await self.send(Heartbeat(0.0))

    async def send(self, msg: StreamMessage) -> None:
        self.writer.write(self.codec.encode(msg))
        await within(self.writer.drain())

    async def command(self, command_id: int, name: str, **params: ParamValue) -> None:
        await self.send(Command(command_id, name, 0.0, dict(params)))

    async def receive(self, kind: type[T]) -> T:
        """The next message of type ``kind`` (others are kept in ``inbox``)."""
        while True:
            for i, item in enumerate(self.inbox):
                if isinstance(item, kind):
                    del self.inbox[i]
                    return item
            data = await self.reader.read(4096)
            if not data:
                raise ConnectionError("the vehicle closed the connection")
            self.inbox += self.codec.feed(data)

    async def reply(self, command_id: int, kind: str) -> Reply:
        """The next reply to ``command_id``; fails if it is not of ``kind``."""
        while True:
            reply = await within(self.receive(Reply))
            if reply.command_id == command_id:
                assert reply.kind == kind, reply
                return reply

    async def close(self) -> None:
        if self._beat is not None:
            self._beat.cancel()
            await asyncio.gather(self._beat, return_exceptions=True)
        self.writer.close()
        await within(self.writer.wait_closed())


async def until(condition: Callable[[], bool], seconds: float = WAIT) -> None:
    """Poll ``condition`` until it holds, or TimeoutError."""
    async with asyncio.timeout(seconds):
        while not condition():
            await asyncio.sleep(0.005)


def test_commands_get_their_replies_and_acks_are_honoured() -> None:
    log: list[str] = []

    async def scenario() -> None:
        async with make_server(log) as server:
            assert server.address is not None
            host, port = server.address
            assert host == "127.0.0.1" and port > 0
            ctl = await Controller.connect(port, nonce=b"c" * 16, mission_id=42)
            reply = ctl.hello_reply
            assert reply is not None and not reply.resumed and reply.last_reply_seq == 0
            assert reply.silence_timeout == pytest.approx(30.0 / 50.0)
            await ctl.command(1, "INIT")
            init = await ctl.reply(1, "done")
            await ctl.command(2, "DEPTH", z=1.0)
            await ctl.command(3, "DEPTH?", z=1.0, time_out=60.0)
            depth = await ctl.reply(2, "ack")
            await ctl.send(ReplyAck(depth.reply_seq))
            done = await ctl.reply(3, "done")
            await ctl.send(ReplyAck(done.reply_seq))
            assert [init.reply_seq, depth.reply_seq, done.reply_seq] == [1, 2, 3]
            assert 1.0 < done.vehicle_time - depth.vehicle_time < 60.0
            assert server.ledger is not None and server.ledger.mission_id == 42
            await until(lambda: server.ledger is not None and server.ledger.acked_seq == 3)
            assert server.ledger.unacknowledged() == []
            assert server.stats.commands == 3 and server.stats.rejected == 0
            assert server.controller is not None
            await ctl.close()
        assert server.address is not None  # stop() keeps the address for the log

    asyncio.run(within(scenario(), 10.0))
    assert any("starts mission 42" in line for line in log), log


class _Datagrams(asyncio.DatagramProtocol):
    def __init__(self) -> None:
        self.queue: asyncio.Queue[bytes] = asyncio.Queue()

    def datagram_received(self, data: bytes, addr: tuple[str | int, ...]) -> None:
        self.queue.put_nowait(data)


def test_telemetry_goes_to_the_announced_port_under_the_session_key() -> None:
    log: list[str] = []

    async def scenario() -> list[TelemetryRecord]:
        loop = asyncio.get_running_loop()
        transport, inbox = await loop.create_datagram_endpoint(
            _Datagrams, local_addr=("127.0.0.1", 0)
        )
        udp_port = transport.get_extra_info("sockname")[1]
        try:
            async with make_server(log) as server:
                assert server.address is not None
                ctl = await Controller.connect(
                    server.address[1], nonce=b"t" * 16, telemetry_port=udp_port
                )
                assert ctl.codec.session_key is not None
                receiver = DatagramReceiver(ctl.codec.session_key)
                await ctl.command(1, "DEPTH", z=1.0)
                samples: list[TelemetryRecord] = []
                while not samples or samples[-1].z < 0.5:
                    result = receiver.accept(await within(inbox.queue.get()))
                    assert not isinstance(result, Rejected), result
                    samples.append(result)
                await ctl.close()
                assert server.stats.datagrams >= len(samples)
                return samples
        finally:
            transport.close()

    samples = asyncio.run(within(scenario(), 10.0))
    assert len(samples) >= 2
    assert [s.seq for s in samples] == list(range(1, len(samples) + 1))
    # 2 Hz of vehicle time: consecutive samples half a vehicle second apart.
    gaps = [b.vehicle_time - a.vehicle_time for a, b in itertools.pairwise(samples)]
    assert all(gap == pytest.approx(0.5, abs=0.06) for gap in gaps), gaps
    assert samples[-1].z > samples[0].z + 0.3
    assert samples[0].est_x is None  # no FIX_XY yet: NaN on the wire


def _forged_command(command_id: int) -> bytes:
    """A well-formed Command frame tagged under a key the vehicle does not know."""
    wrong = b"\x55" * 32
    forger = StreamCodec(wrong, Role.CONTROLLER, b"f" * 16)
    accomplice = StreamCodec(wrong, Role.VEHICLE, b"g" * 16)
    (hello,) = accomplice.feed(forger.encode(Hello(b"f" * 16, 0.0, 7)))
    assert isinstance(hello, Hello)
    forger.feed(accomplice.encode(HelloReply(b"f" * 16, b"g" * 16, 0.0, 0.0, False, 0, 30.0)))
    return forger.encode(Command(command_id, "DEPTH", 0.0, {"z": 3.0}))


def test_forged_and_replayed_frames_are_rejected_and_the_link_goes_on() -> None:
    log: list[str] = []

    async def scenario() -> VehicleServer:
        async with make_server(log) as server:
            assert server.address is not None
            ctl = await Controller.connect(server.address[1], nonce=b"x" * 16)
            ctl.writer.write(_forged_command(99))
            frame = ctl.codec.encode(Command(1, "INIT", 0.0))
            ctl.writer.write(frame)
            await within(ctl.writer.drain())
            await ctl.reply(1, "done")
            ctl.writer.write(frame)  # the same frame again: a replay
            await ctl.command(2, "DEPTH", z=1.0)
            await ctl.reply(2, "ack")
            await ctl.close()
            return server

    server = asyncio.run(within(scenario(), 10.0))
    assert server.stats.rejected == 2
    assert server.stats.commands == 2  # INIT and DEPTH; not the forged 99, nor the replay
    assert any("bad-tag" in line for line in log), log
    assert any("replay" in line for line in log), log


def test_a_command_resent_after_a_reconnect_is_carried_out_once() -> None:
    log: list[str] = []

    async def scenario() -> tuple[VehicleServer, list[Reply]]:
        async with make_server(log) as server:
            assert server.address is not None
            port = server.address[1]
            first = await Controller.connect(port, nonce=b"1" * 16, mission_id=9)
            await first.command(1, "INIT")
            init = await first.reply(1, "done")
            await first.send(ReplyAck(init.reply_seq))
            await first.command(2, "DEPTH", z=1.0)
            await first.close()  # dropped before the DEPTH reply was read
            await until(lambda: server.controller is None)

            second = await Controller.connect(
                port, nonce=b"2" * 16, mission_id=9, resume=True, last_reply_seq=1
            )
            hello_reply = second.hello_reply
            assert hello_reply is not None
            assert hello_reply.resumed and hello_reply.last_reply_seq == 2
            await second.command(2, "DEPTH", z=1.0)  # same id: the engine cannot know
            replies = [await second.reply(2, "ack"), await second.reply(2, "ack")]
            await second.send(ReplyAck(2))
            await second.command(3, "DEPTH?", z=1.0, time_out=60.0)
            replies.append(await second.reply(3, "done"))
            await second.close()
            return server, replies

    server, replies = asyncio.run(within(scenario(), 10.0))
    # One re-send for the resume, one for the repeated id: the same reply, seq 2, both times.
    assert [r.reply_seq for r in replies] == [2, 2, 3]
    assert replies[0] == replies[1]
    assert server.stats.commands == 3 and server.stats.repeats == 1
    assert server.stats.resent == 2 and server.stats.adopted == 2
    # The vehicle saw DEPTH once: its own ids 1 (INIT), 2 (DEPTH), 3 (DEPTH?).
    assert [r.kind for r in server.vehicle.replies_for(2)] == ["ack"]
    assert server.vehicle.replies_for(4) == ()
    assert any("resumed mission 9" in line for line in log), log


def test_a_new_mission_may_reuse_command_ids() -> None:
    log: list[str] = []

    async def scenario() -> list[Reply]:
        async with make_server(log) as server:
            assert server.address is not None
            port = server.address[1]
            first = await Controller.connect(port, nonce=b"a" * 16, mission_id=1)
            await first.command(1, "DEPTH", z=1.0)
            await first.reply(1, "ack")
            await first.close()
            # An unknown mission cannot be resumed; the vehicle says so and starts afresh.
            second = await Controller.connect(port, nonce=b"b" * 16, mission_id=2, resume=True)
            assert second.hello_reply is not None and not second.hello_reply.resumed
            await second.command(1, "HEADING", psi=90.0)
            replies = [await second.reply(1, "ack")]
            await second.close()
            return replies

    (reply,) = asyncio.run(within(scenario(), 10.0))
    assert reply.reply_seq == 1  # numbered afresh in the new mission
    assert any("could not resume mission 2" in line for line in log), log


def test_cli_help_names_the_key_options(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["serve", "--help"]) == 0
    out = capsys.readouterr().out
    assert "--key-file" in out and "--key-hex" in out and "--speed" in out


@pytest.mark.parametrize(
    ("args", "message"),
    [
        ([], "serve needs a pre-shared key"),
        (["--key-hex", "00112233"], "4 bytes, too short"),
        (["--key-hex", "not hex at all, not at all"], "is not hex"),
    ],
)
def test_cli_refuses_to_serve_without_a_good_key(
    args: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["serve", *args]) == 2
    err = capsys.readouterr().err
    assert message in err and "--key-file FILE" in err


def test_cli_serves_for_the_given_duration(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    key = tmp_path / "psk.hex"
    key.write_text(PSK.hex() + "\n")
    key.chmod(0o600)  # a key file others can read is refused
    args = ["serve", "--key-file", str(key), "--speed", "20", "--duration", "0.2"]
    assert main(args) == 0
    captured = capsys.readouterr()
    assert captured.out.startswith("listening on 127.0.0.1:")
    assert "stopped at vehicle time" in captured.err


def test_a_detached_server_opens_no_socket_and_serves_handed_connections() -> None:
    """start_detached/accept: what runtime.memorylink builds on (tested in depth there)."""
    log: list[str] = []

    async def scenario() -> tuple[VehicleServer, list[tuple[bytes, tuple[str, int]]]]:
        server = make_server(log)
        await server.start_detached()
        await server.start_detached()  # already running: nothing happens
        assert server.address is None
        with pytest.raises(RuntimeError, match="called twice"):
            await server.start()
        ours, theirs = socket.socketpair()
        reader, writer = await asyncio.open_connection(sock=theirs)
        sent: list[tuple[bytes, tuple[str, int]]] = []
        serving = asyncio.create_task(
            server.accept(
                reader,
                writer,
                peer=("handed", 1),
                datagram_sink=lambda data, address: sent.append((data, address)),
            )
        )
        ctl_reader, ctl_writer = await asyncio.open_connection(sock=ours)
        ctl = Controller(ctl_reader, ctl_writer, b"d" * 16)
        await ctl.send(Hello(b"d" * 16, 0.0, 5, False, 0, 4321))
        ctl.hello_reply = await within(ctl.receive(HelloReply))
        await ctl.send(Heartbeat(0.0))
        await ctl.command(1, "DEPTH", z=1.0)
        await ctl.reply(1, "ack")
        await until(lambda: len(sent) >= 2)
        await ctl.close()
        await within(serving)
        await server.stop()
        return server, sent

    server, sent = asyncio.run(within(scenario(), 10.0))
    assert {address for _, address in sent} == {("handed", 4321)}
    assert server.stats.datagrams == len(sent) and server.stats.commands == 1
    assert any("connection from handed:1" in line for line in log), log


def test_the_event_log_is_created_at_the_first_adoption_named_by_the_mission_id(
    tmp_path: Path,
) -> None:
    """A served vehicle learns its mission from the first Hello: `open_event_log` is called
    then, once, with the wire mission id; a later mission goes on in the same log."""
    log: list[str] = []
    opened: list[int] = []

    def open_log(mission_id: int) -> EventLog:
        opened.append(mission_id)
        return EventLog.create(
            tmp_path / "vehicle.sqlite", role="vehicle", mission=str(mission_id), meta={}
        )

    async def scenario() -> VehicleServer:
        server = VehicleServer(
            Vehicle(seed=0),
            PSK,
            speed=50.0,
            tick=0.01,
            nonces=random.Random(0).randbytes,
            log=log.append,
            open_event_log=open_log,
        )
        async with server:
            assert server.address is not None and server.event_log is None
            await asyncio.sleep(0.1)  # telemetry before any controller: nowhere to go
            for mission_id in (41, 42):
                ctl = await Controller.connect(
                    server.address[1], nonce=bytes([mission_id]) * 16, mission_id=mission_id
                )
                await ctl.command(1, "DEPTH", z=1.0)
                await ctl.reply(1, "ack")
                await ctl.close()
        return server

    server = asyncio.run(within(scenario(), 10.0))
    assert opened == [41]
    assert server.event_log is not None
    server.event_log.close()
    with EventLog.open(tmp_path / "vehicle.sqlite") as vehicle_log:
        assert vehicle_log.mission == "41" and vehicle_log.role == "vehicle"
        adopted = [e.data["mission_id"] for e in vehicle_log.events(["adopt"])]
        commands = list(vehicle_log.events(["command-received"]))
    assert adopted == [41, 42] and len(commands) == 2


def test_a_log_that_cannot_be_created_is_reported_and_the_vehicle_goes_on(
    tmp_path: Path,
) -> None:
    existing = tmp_path / "vehicle.sqlite"
    existing.write_bytes(b"evidence")
    log: list[str] = []

    async def scenario() -> VehicleServer:
        server = VehicleServer(
            Vehicle(seed=0),
            PSK,
            speed=50.0,
            tick=0.01,
            nonces=random.Random(0).randbytes,
            log=log.append,
            open_event_log=lambda mission_id: EventLog.create(
                existing, role="vehicle", mission=str(mission_id), meta={}
            ),
        )
        async with server:
            assert server.address is not None
            ctl = await Controller.connect(server.address[1], nonce=b"e" * 16)
            await ctl.command(1, "DEPTH", z=1.0)
            await ctl.reply(1, "ack")
            await ctl.close()
        return server

    server = asyncio.run(within(scenario(), 10.0))
    assert server.event_log is None and server.stats.commands == 1
    assert existing.read_bytes() == b"evidence"
    assert any(line.startswith("no event log:") and "already exists" in line for line in log), log
