"""The controller's make-safe request, vehicle side: every model, and the server.

`VehicleModel.make_safe` must do at once what the watchdog does after its silence (stop
every command with the watchdog's reply kinds, run the integrator's make-safe), and a
repeated or replayed request must be harmless. The server carries out each request id
once per mission and acknowledges every time.
"""

from __future__ import annotations

import asyncio
import random
from typing import cast

from hypothesis import given, settings
from hypothesis import strategies as st

from runtime.faultplan import parse_fault_rules
from runtime.link import MemoryLink
from runtime.protocol import (
    NONCE_SIZE,
    Command,
    Heartbeat,
    Hello,
    HelloReply,
    MakeSafe,
    MakeSafeAck,
    Rejected,
    Role,
    StreamCodec,
    StreamMessage,
)
from runtime.protocol import Reply as WireReply
from runtime.vclock import run_virtual
from runtime.vehicle import HandlerVehicle, Reply, VehicleModel
from runtime.vehicle.faults import FaultInjector
from runtime.vehicle.generic import GenericVehicle
from runtime.vehicle.server import VehicleServer
from tests.runtime.vehicle.test_generic import minnow
from tests.runtime.vehicle.test_handlers import Bot, kinds, profile

PSK = bytes(range(32))


def test_make_safe_stops_everything_at_once_with_the_watchdogs_replies() -> None:
    bot = Bot()
    vehicle = bot.vehicle(watchdog_s=10.0)
    vehicle.command(1, "DIVE", {"z": 3.0})
    vehicle.command(2, "FIX", {})
    vehicle.command(3, "LINE_END?", {"time_out": 1.0})
    assert vehicle.advance_to(0.55) == []
    replies = vehicle.make_safe("SIGTERM")
    assert kinds(replies) == [(2, "error"), (3, "timeout")]
    assert {r.time for r in replies} == {0.55}
    assert all("make itself safe" in r.detail for r in replies)
    assert bot.safe == 1 and vehicle.holders == {}
    assert bot.calls[-2:] == ["stop DIVE at 0.55", "stop FIX at 0.55"]
    assert vehicle.events[0].text == "make-safe requested by the controller (SIGTERM)"
    # The watchdog has nothing left to do: it does not make the vehicle safe again.
    assert vehicle.advance_to(100.0) == [] and bot.safe == 1
    # A repeat is harmless: nothing runs, nothing replies twice.
    assert vehicle.make_safe("SIGTERM") == [] and vehicle.holders == {}


COMMANDS: list[tuple[str, dict[str, float | int | str]]] = [
    ("DIVE", {"z": 3.0}),
    ("FIX", {}),
    ("LINE", {"x": 1.0, "y": 2.0}),
    ("LINE_END?", {"time_out": 5.0}),
    ("DEPTH?", {"z": 3.0, "time_out": 500.0}),
    ("SAMPLE", {"n": 2, "label": "a"}),
]


@settings(max_examples=60, deadline=None)
@given(
    chosen=st.lists(st.sampled_from(range(len(COMMANDS))), max_size=6),
    ticks=st.integers(1, 50),
)
def test_make_safe_replies_as_the_watchdog_would_at_the_same_moment(
    chosen: list[int], ticks: int
) -> None:
    """Same commands, same moment (between two polls): the request and the watchdog give
    the same replies (command, kind, time) and the same stops."""
    moment = ticks * 0.1 + 0.05
    asked, silent = Bot(), Bot()
    by_request = asked.vehicle(watchdog_s=1000.0)
    by_watchdog = silent.vehicle(watchdog_s=moment)
    by_request.heard_from_controller()
    by_watchdog.heard_from_controller()  # armed even when no command comes
    for n, index in enumerate(chosen, start=1):
        name, params = COMMANDS[index]
        assert kinds(by_request.command(n, name, params)) == kinds(
            by_watchdog.command(n, name, params)
        )
    got = by_request.advance_to(moment) + by_request.make_safe("test")
    want = by_watchdog.advance_to(moment)
    assert [(r.command_id, r.kind, r.time) for r in got] == [
        (r.command_id, r.kind, r.time) for r in want
    ]
    assert asked.safe == silent.safe == 1
    assert asked.calls == silent.calls


def test_the_generic_vehicle_heads_for_the_surface() -> None:
    vehicle = GenericVehicle(minnow(), seed=1, watchdog_s=1e6)
    assert vehicle.command(1, "DIVE", {"z": 10.0}) == []  # it acks after its work time
    vehicle.command(2, "DEPTH?", {"z": 10.0, "time_out": 600.0})
    assert kinds(vehicle.advance_to(20.0)) == [(1, "ack")]
    snapshot = vehicle.telemetry()
    assert snapshot is not None and snapshot.z > 5.0
    assert kinds(vehicle.make_safe("SIGINT")) == [(2, "timeout")]
    vehicle.advance_to(60.0)
    surfaced = vehicle.telemetry()
    assert surfaced is not None and surfaced.z < snapshot.z


def test_the_fault_injector_passes_make_safe_to_the_vehicle() -> None:
    plan = parse_fault_rules(["GPS_FIX?=timeout"])
    injector = FaultInjector(
        GenericVehicle(minnow(), seed=1, watchdog_s=1e6), minnow(), plan, seed=0
    )
    assert isinstance(injector, VehicleModel)
    injector.command(1, "DIVE", {"z": 10.0})
    injector.command(2, "DEPTH?", {"z": 10.0, "time_out": 600.0})
    injector.command(3, "GPS_FIX?", {"max_hdop": 2.0, "time_out": 5.0})  # forced at 5 s
    injector.advance_to(1.0)
    assert kinds(injector.make_safe("SIGTERM")) == [(2, "timeout")]
    # The forced reply keeps its time: the wrapped vehicle never heard of that command.
    assert kinds(injector.advance_to(10.0)) == [(3, "timeout")]


class Counting(HandlerVehicle):
    """A handler vehicle that counts the make-safe requests it carries out."""

    requests: list[str]

    def make_safe(self, reason: str) -> list[Reply]:
        self.requests.append(reason)
        return super().make_safe(reason)


def test_the_server_makes_safe_once_per_request_id_and_acks_every_time() -> None:
    bot = Bot()
    vehicle = Counting(profile(), on_watchdog=bot.make_safe, watchdog_s=1000.0)
    vehicle.requests = []
    vehicle.on("FIX", poll=lambda job: None)

    async def main() -> list[StreamMessage]:
        loop = asyncio.get_running_loop()
        server = VehicleServer(vehicle, PSK, clock=loop.time, log=lambda line: None)
        link = MemoryLink(server, None)
        conn = await link.connect()
        codec = StreamCodec(PSK, Role.CONTROLLER, random.Random(3).randbytes(NONCE_SIZE))
        got: list[StreamMessage] = []

        async def read() -> None:
            got.extend(m for m in codec.feed(await conn.read()) if not isinstance(m, Rejected))

        async def until(kind: type[object]) -> None:
            while not any(isinstance(m, kind) for m in got):
                await read()

        try:
            conn.write(codec.encode(Hello(codec.nonce, loop.time(), 5, False, 0, 0)))
            await until(HelloReply)
            conn.write(codec.encode(Heartbeat(loop.time())))
            conn.write(codec.encode(Command(1, "FIX", loop.time())))
            await asyncio.sleep(0.5)
            for request_id in (11, 11, 12):
                conn.write(codec.encode(MakeSafe(request_id, loop.time(), "SIGTERM")))
                await asyncio.sleep(0.1)
            await asyncio.sleep(0.5)
            while len([m for m in got if isinstance(m, MakeSafeAck)]) < 3:
                await read()
            return got
        finally:
            conn.close()
            await link.aclose()
            await server.stop()

    got = run_virtual(main())
    acks = [m for m in got if isinstance(m, MakeSafeAck)]
    assert [(a.request_id, a.first) for a in acks] == [(11, True), (11, False), (12, True)]
    assert vehicle.requests == ["SIGTERM", "SIGTERM"]  # the repeat of 11 did nothing
    # FIX, stopped by the first request, replied error through the ledger, before its ack.
    replies = [m for m in got if isinstance(m, WireReply)]
    assert [(r.command_id, r.kind) for r in replies] == [(1, "error")]
    assert got.index(replies[0]) < got.index(acks[0])


class OldModel(HandlerVehicle):
    """A plugin model written before make_safe joined the VehicleModel contract."""

    make_safe = None  # type: ignore[assignment]


def test_a_model_without_make_safe_is_not_acknowledged_and_the_server_goes_on() -> None:
    vehicle = OldModel(profile(), watchdog_s=1000.0)
    lines: list[str] = []

    async def main() -> list[StreamMessage | Rejected]:
        loop = asyncio.get_running_loop()
        model = cast(HandlerVehicle, vehicle)  # what a plugin's model looks like to the typer
        server = VehicleServer(model, PSK, clock=loop.time, log=lines.append)
        link = MemoryLink(server, None)
        conn = await link.connect()
        codec = StreamCodec(PSK, Role.CONTROLLER, random.Random(4).randbytes(NONCE_SIZE))
        got: list[StreamMessage | Rejected] = []
        try:
            conn.write(codec.encode(Hello(codec.nonce, loop.time(), 5, False, 0, 0)))
            while not any(isinstance(m, HelloReply) for m in got):
                got.extend(codec.feed(await conn.read()))
            conn.write(codec.encode(MakeSafe(21, loop.time(), "SIGTERM")))
            conn.write(codec.encode(Heartbeat(loop.time())))
            await asyncio.sleep(1.0)
            while not any(isinstance(m, Heartbeat) for m in got):  # the server still serves
                got.extend(codec.feed(await conn.read()))
            return got
        finally:
            conn.close()
            await link.aclose()
            await server.stop()

    got = run_virtual(main())
    assert not any(isinstance(m, MakeSafeAck) for m in got)
    assert any("has no make_safe(); not acknowledged" in line for line in lines)
