"""`VehicleServer` serves any `VehicleModel`, not just ROMEO; the serving helpers.

The protocol itself (forged frames, resumes, ids reused across missions) is tested with
ROMEO in ``tests/romeo_sim/test_server.py``; here the model is a `GenericVehicle` or a
bare `HandlerVehicle`, driven under virtual time through `MemoryLink` by a minimal
controller, and the helpers run on real localhost sockets.
"""

from __future__ import annotations

import asyncio
import random
import socket
import typing
from pathlib import Path
from typing import TypeVar

import pytest

from coral_lang.profile import VehicleProfile, load_profile
from romeo_sim.server import ServerStats as OldServerStats
from romeo_sim.server import VehicleServer as OldVehicleServer
from romeo_sim.vehicle import Reply as OldReply
from romeo_sim.vehicle import Vehicle
from runtime.eventlog import EventLog
from runtime.link import Connection, MemoryLink
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
from runtime.vclock import run_virtual
from runtime.vehicle import (
    HandlerVehicle,
    ServerStats,
    VehicleServer,
    run_vehicle,
    serve_vehicle,
)
from runtime.vehicle import Reply as ModelReply
from runtime.vehicle.generic import GenericVehicle
from tests.conftest import EXAMPLES

PSK = bytes(range(32))
T = TypeVar("T")


def minnow() -> VehicleProfile:
    return load_profile(EXAMPLES / "profiles" / "minnow.yaml")


class MiniController:
    """Just enough of the engine's side of one connection."""

    def __init__(self, conn: Connection) -> None:
        self.conn = conn
        self.codec = StreamCodec(PSK, Role.CONTROLLER, b"c" * 16)
        self.inbox: list[StreamMessage | Rejected] = []
        self.hello_reply: HelloReply | None = None

    @classmethod
    async def start(cls, link: MemoryLink, telemetry_port: int) -> MiniController:
        ctl = cls(await link.connect())
        ctl.send(Hello(ctl.codec.nonce, 0.0, 11, False, 0, telemetry_port))
        ctl.hello_reply = await ctl.receive(HelloReply)
        ctl.send(Heartbeat(0.0))
        return ctl

    def send(self, msg: StreamMessage) -> None:
        self.conn.write(self.codec.encode(msg))

    def command(self, command_id: int, name: str, **params: ParamValue) -> None:
        self.send(Command(command_id, name, 0.0, dict(params)))

    async def receive(self, kind: type[T]) -> T:
        while True:
            for i, item in enumerate(self.inbox):
                if isinstance(item, kind):
                    del self.inbox[i]
                    return item
            data = await self.conn.read()
            if not data:
                raise ConnectionError("closed")
            self.inbox += self.codec.feed(data)

    async def reply(self) -> Reply:
        """The next reply, acknowledged; the controller's heartbeat goes with it."""
        reply = await asyncio.wait_for(self.receive(Reply), 600.0)
        self.send(ReplyAck(reply.reply_seq))
        return reply


def test_the_old_import_paths_still_work() -> None:
    # romeo_sim.server's is the same server, specialised to ROMEO for type checkers.
    assert typing.get_origin(OldVehicleServer) is VehicleServer
    assert typing.get_args(OldVehicleServer) == (Vehicle,)
    server = OldVehicleServer(Vehicle(seed=0), PSK)
    assert isinstance(server, VehicleServer) and server.vehicle.events == ()
    assert OldServerStats is ServerStats and OldReply is ModelReply


def test_the_server_serves_a_generic_vehicle(tmp_path: Path) -> None:
    """Handshake, replies from a non-ROMEO model (at once, later, caused by another
    command), telemetry datagrams and the vehicle's event log."""

    async def scenario() -> tuple[
        list[Reply], list[TelemetryRecord], HelloReply | None, ServerStats
    ]:
        loop = asyncio.get_running_loop()
        log = EventLog.create(tmp_path / "vehicle.sqlite", role="vehicle", mission="t", meta={})
        server = VehicleServer(
            GenericVehicle(minnow(), seed=5),
            PSK,
            clock=loop.time,
            speed=2.0,
            nonces=random.Random(0).randbytes,
            log=lambda _: None,
            event_log=log,
        )
        link = MemoryLink(server)
        datagrams: list[bytes] = []
        port = await link.open_telemetry(datagrams.append)
        ctl = await MiniController.start(link, port)
        replies: list[Reply] = []
        ctl.command(1, "INIT")
        replies.append(await ctl.reply())
        ctl.command(2, "DIVE", z=12.0)
        replies.append(await ctl.reply())
        await asyncio.sleep(5.0)  # 10 s of vehicle time: the pose goes 3 m down
        ctl.command(3, "DEPTH?", z=12.0, time_out=300.0)
        ctl.command(4, "SURFACE")
        replies += [await ctl.reply(), await ctl.reply()]
        ctl.command(5, "NOPE")
        replies.append(await ctl.reply())
        assert ctl.codec.session_key is not None
        receiver = DatagramReceiver(ctl.codec.session_key)
        samples = [t for t in map(receiver.accept, datagrams) if isinstance(t, TelemetryRecord)]
        ctl.conn.close()
        await link.aclose()
        await server.stop()
        log.close()
        return replies, samples, ctl.hello_reply, server.stats

    replies, samples, hello, stats = run_virtual(scenario(), timeout=600)
    assert hello is not None and hello.silence_timeout == 15.0  # 30 vehicle s at 2x
    assert [(r.command_id, r.reply_seq, r.kind) for r in replies] == [
        (1, 1, "done"),
        (2, 2, "ack"),
        (3, 3, "timeout"),  # at once, when SURFACE takes DIVE's depth
        (4, 4, "ack"),  # SURFACE acks after its work time: 1 s +/- 20 %
        (5, 5, "error"),
    ]
    assert 4.0 <= replies[0].vehicle_time <= 6.1  # INIT: 5 s +/- 20 %
    assert replies[2].detail == "its task DIVE was replaced by SURFACE"
    assert 0.8 - 1e-9 <= replies[3].vehicle_time - replies[2].vehicle_time <= 1.3 + 1e-9
    assert replies[4].detail == "unknown command 'NOPE'"
    assert stats.commands == 5 and stats.replies == 5
    assert len(samples) >= 8 and stats.datagrams == len(samples)
    # 0.3 m/s down from DIVE's arrival: its ack (about 1 s) and then the 10 s slept.
    assert max(s.z for s in samples) == pytest.approx(3.3, abs=0.2)
    with EventLog.open(tmp_path / "vehicle.sqlite") as log:
        assert len(list(log.samples())) >= len(samples)
        assert log.count("reply-issued") == 5


def test_a_model_without_telemetry_sends_no_datagram_and_records_no_sample(
    tmp_path: Path,
) -> None:
    async def scenario() -> tuple[list[Reply], list[bytes], ServerStats]:
        loop = asyncio.get_running_loop()
        vehicle = HandlerVehicle(minnow())
        vehicle.on("INIT", poll=lambda job: "done" if job.elapsed >= 3.0 else None)
        log = EventLog.create(tmp_path / "v.sqlite", role="vehicle", mission="t", meta={})
        server = VehicleServer(
            vehicle,
            PSK,
            clock=loop.time,
            nonces=random.Random(1).randbytes,
            log=lambda _: None,
            event_log=log,
        )
        link = MemoryLink(server)
        datagrams: list[bytes] = []
        ctl = await MiniController.start(link, await link.open_telemetry(datagrams.append))
        ctl.command(1, "INIT")
        ctl.command(2, "DIVE", z=3.0)
        replies = [await ctl.reply(), await ctl.reply()]
        await asyncio.sleep(5.0)
        ctl.conn.close()
        await link.aclose()
        await server.stop()
        log.close()
        return replies, datagrams, server.stats

    replies, datagrams, stats = run_virtual(scenario(), timeout=600)
    assert [(r.command_id, r.kind) for r in replies] == [(2, "error"), (1, "done")]
    assert replies[0].detail == "DIVE is not implemented on this vehicle"
    assert replies[1].vehicle_time == pytest.approx(3.0)
    assert datagrams == [] and stats.datagrams == 0
    with EventLog.open(tmp_path / "v.sqlite") as log:
        assert list(log.samples()) == []


def test_serve_vehicle_listens_on_localhost_and_says_where(
    capsys: pytest.CaptureFixture[str],
) -> None:
    lines: list[str] = []

    async def scenario() -> ServerStats:
        return await serve_vehicle(
            GenericVehicle(minnow()), PSK, duration=0.05, speed=10.0, log=lines.append
        )

    stats = asyncio.run(asyncio.wait_for(scenario(), 5.0))
    out = capsys.readouterr().out
    assert out.startswith("listening on 127.0.0.1:") and int(out.split(":")[-1]) > 0
    assert stats.connections == 0
    assert lines and lines[-1].startswith("stopped at vehicle time 0.")


def test_run_vehicle_reports_bad_input_as_an_exit_code() -> None:
    lines: list[str] = []
    assert run_vehicle(GenericVehicle(minnow()), b"short", log=lines.append) == 2
    assert "at least 16 bytes" in lines[-1]
    assert run_vehicle(GenericVehicle(minnow()), PSK, speed=0.0, log=lines.append) == 2
    assert "speed must be a positive finite number" in lines[-1]
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        assert run_vehicle(GenericVehicle(minnow()), PSK, port=port, log=lines.append) == 1
    assert lines[-1].startswith(f"cannot listen on 127.0.0.1:{port}")
    assert run_vehicle(GenericVehicle(minnow()), PSK, duration=0.01, log=lines.append) == 0
