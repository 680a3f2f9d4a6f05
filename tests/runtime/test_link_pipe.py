"""runtime.linkpipe: bytes through an emulated connection, under virtual time.

The vehicle's end here is a recorder; `test_link_transports.py` plugs in the real
vehicle server and real sockets.
"""

from __future__ import annotations

import asyncio
from dataclasses import replace

from hypothesis import given
from hypothesis import strategies as st

from runtime.emulator import LinkEmulator
from runtime.linkpipe import EmulatedConnection, EmulatedLink, LinkStats, TimedQueue
from runtime.linkprofile import BUILTIN_PROFILES, LinkProfile
from runtime.vclock import run_virtual

GENOA = BUILTIN_PROFILES["genoa-lisbon"]
HOSTILE = BUILTIN_PROFILES["hostile"]
CALM = [
    replace(GENOA, reset_rate_per_s=0.0, outage_rate_per_s=0.0),
    replace(HOSTILE, reset_rate_per_s=0.0, outage_rate_per_s=0.0),
    BUILTIN_PROFILES["ideal"],
]


class Recorder:
    """A vehicle end that keeps what reaches it."""

    def __init__(self) -> None:
        self.data = bytearray()
        self.eof = False
        self.aborted: str | None = None

    def deliver(self, data: bytes) -> None:
        assert not self.eof and self.aborted is None
        self.data += data

    def deliver_eof(self) -> None:
        self.eof = True

    def abort(self, reason: str) -> None:
        self.aborted = reason


def _open(
    profile: LinkProfile | None, seed: int, log: list[str]
) -> tuple[EmulatedLink, EmulatedConnection, Recorder]:
    loop = asyncio.get_running_loop()
    emulator = None if profile is None else LinkEmulator(profile, seed)
    link = EmulatedLink(emulator, log.append)
    path = None if emulator is None else emulator.connect(loop.time()).path
    end = Recorder()
    return link, EmulatedConnection(loop, 1, path, end, link), end


async def _read_all(conn: EmulatedConnection) -> bytes:
    got = bytearray()
    while data := await conn.read():
        got += data
    return bytes(got)


chunks = st.lists(st.tuples(st.binary(min_size=1, max_size=200), st.floats(0.0, 1.0)), max_size=25)


@given(
    seed=st.integers(0, 2**32),
    profile=st.sampled_from([*CALM, None]),
    up=chunks,
    down=chunks,
)
def test_both_directions_deliver_every_byte_in_order_for_any_seed_and_chunking(
    seed: int,
    profile: LinkProfile | None,
    up: list[tuple[bytes, float]],
    down: list[tuple[bytes, float]],
) -> None:
    sent_up = b"".join(data for data, _ in up)
    sent_down = b"".join(data for data, _ in down)

    async def scenario() -> tuple[bytes, Recorder, LinkStats]:
        link, conn, end = _open(profile, seed, [])

        async def controller() -> bytes:
            for data, gap in up:
                await asyncio.sleep(gap)
                conn.write(data)
            received = bytearray()
            while len(received) < len(sent_down):
                received += await conn.read()
            return bytes(received)

        async def vehicle() -> None:
            for data, gap in down:
                await asyncio.sleep(gap)
                conn.from_vehicle(data)
            while len(end.data) < len(sent_up):
                await asyncio.sleep(0.1)

        received, _ = await asyncio.gather(controller(), vehicle())
        conn.close()
        while not end.eof:
            await asyncio.sleep(0.1)
        return received, end, link.stats

    received, end, stats = run_virtual(scenario(), timeout=3600)
    assert received == sent_down
    assert bytes(end.data) == sent_up
    assert end.aborted is None and stats.bytes_lost == 0
    assert stats.bytes_up == len(end.data) and stats.bytes_down == len(received)


@given(seed=st.integers(0, 2**32), up=chunks)
def test_a_cut_connection_delivers_a_prefix_and_then_ends_both_sides(
    seed: int, up: list[tuple[bytes, float]]
) -> None:
    profile = replace(HOSTILE, reset_rate_per_s=1.0, outage_rate_per_s=0.0)

    async def scenario() -> tuple[Recorder, LinkStats, list[str], bool]:
        log: list[str] = []
        link, conn, end = _open(profile, seed, log)
        for data, gap in up:
            await asyncio.sleep(gap / 10)
            conn.write(data)
        tail = await _read_all(conn)  # returns b"" once reset: no deadlock
        assert tail == b""
        return end, link.stats, log, conn.closed

    end, stats, log, closed = run_virtual(scenario(), timeout=3600)
    sent = b"".join(data for data, _ in up)
    assert sent.startswith(bytes(end.data))
    assert closed and end.aborted is not None and "reset" in end.aborted
    assert stats.resets == 1 and len(log) == 1 and "connection 1 reset at t=" in log[0]
    # Every byte written before the reset either arrived or was lost in flight.
    assert stats.bytes_up <= len(sent)
    assert len(end.data) + stats.bytes_lost == stats.bytes_up


def test_what_arrived_before_a_reset_can_still_be_read() -> None:
    profile = LinkProfile(name="resets", delay_s=0.1, reset_rate_per_s=0.5)

    async def scenario() -> list[bytes]:
        _, conn, _ = _open(profile, 3, [])
        assert conn.path is not None
        await asyncio.sleep(max(0.0, conn.path.ends_at - 0.05 - asyncio.get_running_loop().time()))
        conn.from_vehicle(b"too late")  # due after the reset: lost
        await asyncio.sleep(0.2)
        return [await conn.read(), await conn.read()]

    assert run_virtual(scenario()) == [b"", b""]


def test_reading_is_safe_to_cancel() -> None:
    async def scenario() -> bytes:
        _, conn, _ = _open(GENOA, 4, [])
        loop = asyncio.get_running_loop()
        loop.call_later(1.0, conn.from_vehicle, b"hello")
        for _ in range(3):
            try:
                return await asyncio.wait_for(conn.read(), 0.3)
            except TimeoutError:
                pass
        return await conn.read()

    assert run_virtual(scenario()) == b"hello"


def test_the_vehicle_closing_ends_the_stream_after_the_bytes_in_flight() -> None:
    async def scenario() -> tuple[list[bytes], bool]:
        _, conn, end = _open(GENOA, 5, [])
        conn.from_vehicle(b"last words")
        conn.vehicle_closed()
        conn.from_vehicle(b"after the end")  # a closed end sends nothing
        assert not conn.closed
        reads = [await conn.read(), await conn.read()]
        conn.write(b"to nobody")
        conn.close()
        await asyncio.sleep(10)
        return reads, end.eof or bool(end.data)

    reads, vehicle_heard = run_virtual(scenario())
    assert reads == [b"last words", b""]
    assert not vehicle_heard


def test_writes_after_close_go_nowhere_and_read_returns_end_of_stream() -> None:
    async def scenario() -> tuple[bytes, Recorder, LinkStats]:
        link, conn, end = _open(None, 0, [])
        conn.write(b"one")
        conn.close()
        conn.write(b"two")
        await asyncio.sleep(0.1)
        return await conn.read(), end, link.stats

    data, end, stats = run_virtual(scenario())
    assert data == b"" and bytes(end.data) == b"one" and end.eof
    assert stats.bytes_up == 3 and stats.chunks_up == 1


def test_a_timed_queue_keeps_order_among_items_due_at_the_same_moment() -> None:
    async def scenario() -> list[bytes]:
        loop = asyncio.get_running_loop()
        got: list[bytes] = []
        queue = TimedQueue(loop, got.append)
        for i in range(50):
            queue.put(1.0 + (i // 10), bytes([i]))  # five groups of ten, same time each
        await asyncio.sleep(2.5)
        assert queue.clear() == 30 and len(queue) == 0
        queue.put(3.0, b"after")
        await asyncio.sleep(5)
        return got

    got = run_virtual(scenario())
    assert got == [bytes([i]) for i in range(20)] + [b"after"]


def test_the_stats_summary_names_what_happened() -> None:
    assert LinkStats().summary() == "link: no traffic"
    assert LinkStats(resets=2, bytes_up=10).summary() == "link: resets=2, bytes_up=10"
