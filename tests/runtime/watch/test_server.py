"""The watch server on a real socket (127.0.0.1, port 0): replay, live following over SSE,
the token off loopback, the viewer limit, and a stalled viewer that costs no memory."""

from __future__ import annotations

import asyncio
import json
import socket
import threading
import tracemalloc
from collections.abc import AsyncIterator, Callable
from pathlib import Path

import aiohttp
import pytest

from runtime.eventlog import EventLog
from runtime.watch.main import log_info
from runtime.watch.server import Hub, Slot, Watch, WatchServer, needs_token
from runtime.watch.source import LogReader
from runtime.watch.state import snapshot_at
from tests.runtime.watch.conftest import NET, run, serving


def log_server(watch: Watch, **options: object) -> WatchServer:
    """A server of ``watch`` on a free loopback port, with its log's static info."""
    options.setdefault("info", log_info(watch.reader))
    return WatchServer(watch, port=0, **options)  # type: ignore[arg-type]


async def sse(response: aiohttp.ClientResponse) -> AsyncIterator[dict[str, object]]:
    """The documents of an SSE stream, one per ``data:`` line."""
    while line := await response.content.readline():
        if line.startswith(b"data: "):
            yield json.loads(line[len(b"data: ") :])


@pytest.mark.slow
def test_a_finished_log_is_replayed(pool_log: Path) -> None:
    reader = LogReader(pool_log)
    watch = Watch(reader)
    watch.poll()

    async def test() -> None:
        server = log_server(watch)
        async with serving(server):
            assert server.token is None  # loopback: no token
            base = server.url
            async with aiohttp.ClientSession() as client:
                async with client.get(base) as page:
                    assert page.status == 200
                    html = await page.text()
                assert "<script>" in html and "src=" not in html and "<link" not in html
                for t in (0.0, 30.0, 100.0):
                    async with client.get(f"{base}snapshot?t={t}") as reply:
                        doc = await reply.json()
                    expected = snapshot_at(reader.net_json, watch.events, watch.samples, t)
                    assert doc["snapshot"] == json.loads(json.dumps(expected.to_json()))
                    assert doc["live"] is False and doc["start"] == 0.0 and doc["end"] > 100
                for bad in ("nan", "inf", "x"):
                    async with client.get(f"{base}snapshot?t={bad}") as reply:
                        assert reply.status == 400
                async with client.get(f"{base}health") as reply:
                    assert (await reply.json())["ok"] is True
                async with client.get(f"{base}info") as reply:  # the log's static data
                    info = await reply.json()
                assert info["mission"] == reader.mission and "<svg" in info["net_svg"]
                assert server.payload() is server.payload()  # serialised once per version
                async with client.post(f"{base}snapshot", data=b"x" * 10_000) as reply:
                    assert reply.status in (405, 413)
                long_header = {"X-Padding": "x" * 6000}  # under aiohttp's 8190, over ours
                async with client.get(f"{base}health", headers=long_header) as reply:
                    assert reply.status == 400

    try:
        run(test)
    finally:
        reader.close()


def test_a_live_log_is_followed_until_mission_end(tmp_path: Path) -> None:
    path = tmp_path / "ctl.sqlite"
    writer = EventLog.create(path, role="controller", mission="n", meta={}, net_json=NET)
    writer.event(0.0, "mission-start", mission_id=1, marking={"a": 1})
    writer.commit()
    reader = LogReader(path)
    watch = Watch(reader)
    watch.poll()

    async def test() -> None:
        watch.poll_interval = 0.02
        server = log_server(watch)
        async with serving(server):
            async with (
                aiohttp.ClientSession() as client,
                client.get(f"{server.url}events") as stream,
            ):
                assert stream.headers["Content-Type"].startswith("text/event-stream")
                documents = sse(stream)
                first = await anext(documents)
                assert first["snapshot"]["marking"] == {"a": 1}  # type: ignore[index]
                assert first["live"] is True
                writer.event(1.0, "fire", transition="go", command_id=None)
                writer.commit()
                second = await anext(documents)
                assert second["snapshot"]["marking"] == {"b": 2}  # type: ignore[index]
                writer.event(2.0, "mission-end", end="final", final=True, marking={"b": 2})
                writer.commit()
                third = await anext(documents)
                assert third["live"] is False
            assert server._follower is not None
            await asyncio.wait_for(server._follower, 2)  # it stopped following by itself

    try:
        run(test)
    finally:
        writer.close()
        reader.close()


def test_binding_off_loopback_needs_the_token(pool_log: Path) -> None:
    assert not needs_token("127.0.0.1") and not needs_token("::1")
    assert not needs_token("localhost")
    assert needs_token("127.0.0.2") and needs_token("0.0.0.0") and needs_token("10.1.2.3")
    reader = LogReader(pool_log)
    watch = Watch(reader)

    async def test() -> None:
        server = WatchServer(watch, host="127.0.0.2", port=0)
        async with serving(server):
            token = server.token
            assert token is not None and len(token) >= 40 and f"?token={token}" in server.url
            base = f"http://127.0.0.2:{server.port}"
            async with aiohttp.ClientSession() as client:
                for url, headers in (
                    (f"{base}/health", {}),
                    (f"{base}/snapshot?token=wrong", {}),
                    (f"{base}/events?token={token[:-1]}", {}),
                    (f"{base}/", {"Authorization": "Bearer nope"}),
                ):
                    async with client.get(url, headers=headers) as reply:
                        assert reply.status == 401, url
                async with client.get(f"{base}/health?token={token}") as reply:
                    assert reply.status == 200
                auth = {"Authorization": f"Bearer {token}"}
                async with client.get(f"{base}/snapshot", headers=auth) as reply:
                    assert reply.status == 200

    try:
        run(test)
    finally:
        reader.close()


def test_viewers_beyond_the_limit_get_503(pool_log: Path) -> None:
    reader = LogReader(pool_log)
    watch = Watch(reader)

    async def test() -> None:
        server = log_server(watch, max_viewers=1)
        async with (
            serving(server),
            aiohttp.ClientSession() as client,
            client.get(f"{server.url}events") as one,
        ):
            await anext(sse(one))
            async with client.get(f"{server.url}events") as two:
                assert two.status == 503
            async with client.get(f"{server.url}health") as health:
                assert (await health.json())["viewers"] == 1

    try:
        run(test)
    finally:
        reader.close()


def test_a_slot_holds_only_the_newest_payload() -> None:
    async def test() -> None:
        slot = Slot()
        for n in range(1000):
            slot.put(str(n).encode())
        assert slot.pending == b"999"
        assert await slot.take() == b"999"
        assert slot.pending is None
        slot.close()
        assert await slot.take() is None
        hub = Hub(max_viewers=2)
        assert hub.join() is not None and hub.join() is not None and hub.join() is None

    run(test)


def test_a_stalled_viewer_does_not_grow_memory(pool_log: Path) -> None:
    """A client that never reads while 1,000 snapshots of 100 kB are published: if they
    queued that would be 100 MB; the slot holds one, the socket buffers a bounded amount."""
    reader = LogReader(pool_log)
    watch = Watch(reader)

    async def test() -> None:
        server = log_server(watch)
        await server.start()
        stalled = socket.socket()
        stalled.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        stalled.setblocking(False)
        try:
            await asyncio.get_running_loop().sock_connect(stalled, ("127.0.0.1", server.port))
            request = b"GET /events HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n"
            await asyncio.get_running_loop().sock_sendall(stalled, request)
            for _ in range(100):  # the handler has joined the hub
                if server.hub.viewers:
                    break
                await asyncio.sleep(0.01)
            assert server.hub.viewers == 1
            tracemalloc.start()
            before = tracemalloc.get_traced_memory()[0]
            for n in range(1000):
                server.hub.publish(n.to_bytes(4, "big") * 25_000)
                await asyncio.sleep(0)
            await asyncio.sleep(0.05)
            grown = tracemalloc.get_traced_memory()[0] - before
            tracemalloc.stop()
            assert grown < 5_000_000, grown
            [waiting] = server.hub.pending()
            assert waiting is None or waiting[:4] == (999).to_bytes(4, "big")
        finally:
            stalled.close()
            await server.stop()

    try:
        run(test)
    finally:
        reader.close()


class CountingSource:
    """A `Source` that counts its documents, and whose replays wait for ``release``."""

    mission = "m"
    ended = False
    seq = 0

    def __init__(self) -> None:
        self.version = 0
        self.newest = 0
        self.replays: list[str] = []
        self.release = threading.Event()

    def document(self, t: float | None = None) -> dict[str, object]:
        if t is None:
            self.newest += 1
            return {"mission": self.mission, "version": self.version}
        self.replays.append(threading.current_thread().name)
        assert self.release.wait(5)
        return {"mission": self.mission, "t": t}

    async def follow(self, publish: Callable[[], None], on_error: Callable[[str], None]) -> None:
        return None


def test_snapshot_and_info_are_serialised_once_per_version() -> None:
    source = CountingSource()

    async def test() -> None:
        server = WatchServer(source, port=0, info={"mission": "m", "net_svg": "<svg/>"})
        async with serving(server) as url, aiohttp.ClientSession() as client:
            for _ in range(20):
                async with client.get(f"{url}snapshot") as reply:
                    assert await reply.json() == {"mission": "m", "version": 0}
            assert source.newest == 1  # one serialisation for twenty requests
            source.version = 1
            async with client.get(f"{url}snapshot") as reply:
                assert (await reply.json())["version"] == 1
            assert source.newest == 2
            async with client.get(f"{url}info") as reply:
                first = await reply.read()
            server.info["mission"] = "changed"  # served bytes are the first ones
            async with client.get(f"{url}info") as reply:
                assert await reply.read() == first
                assert reply.content_type == "application/json"

    run(test)


def test_one_replay_at_a_time_on_its_own_thread() -> None:
    source = CountingSource()

    async def test() -> None:
        server = WatchServer(source, port=0)
        url = await server.start()
        try:
            async with aiohttp.ClientSession() as client:
                first = asyncio.create_task(client.get(f"{url}snapshot?t=1"))
                for _ in range(200):  # the first replay is running
                    if source.replays:
                        break
                    await asyncio.sleep(0.01)
                async with client.get(f"{url}snapshot?t=2") as second:
                    assert second.status == 503
                    assert "already being computed" in await second.text()
                async with client.get(f"{url}snapshot") as newest:  # not a replay: served
                    assert newest.status == 200
                source.release.set()
                reply = await first
                assert reply.status == 200 and (await reply.json())["t"] == 1.0
                reply.release()
                async with client.get(f"{url}snapshot?t=3") as third:
                    assert (await third.json())["t"] == 3.0
            assert len(source.replays) == 2
            assert all(name.startswith("coral-watch-replay") for name in source.replays)
        finally:
            source.release.set()
            await server.stop()

    run(test)


def test_without_a_token_only_requests_for_this_machine_are_answered() -> None:
    """DNS rebinding: a page of evil.example whose name now resolves to 127.0.0.1 sends
    ``Host: evil.example``; served without a token, only local names are answered."""

    async def test() -> None:
        server = WatchServer(CountingSource(), port=0)
        async with serving(server) as url:
            port = server.port
            async with aiohttp.ClientSession() as client:
                for host in (
                    "evil.example",
                    f"evil.example:{port}",
                    f"127.0.0.1:{port + 1}",
                    "127.0.0.1.evil.example",
                    f"[::2]:{port}",
                    "::1",
                    "",
                ):
                    async with client.get(f"{url}health", headers={"Host": host}) as reply:
                        assert reply.status == 421, host
                        assert "Host header" in await reply.text()
                for host in (
                    f"127.0.0.1:{port}",
                    "127.0.0.1",
                    f"localhost:{port}",
                    "LocalHost",
                    f"[::1]:{port}",
                    "[::1]",
                ):
                    async with client.get(f"{url}health", headers={"Host": host}) as reply:
                        assert reply.status == 200, host
                async with client.get(f"{url}health") as reply:  # aiohttp's own Host
                    assert reply.status == 200

    run(test)


def test_with_a_token_any_host_name_may_be_used() -> None:
    async def test() -> None:
        server = WatchServer(CountingSource(), host="127.0.0.2", port=0)
        async with serving(server):
            base = f"http://127.0.0.2:{server.port}/"
            async with aiohttp.ClientSession() as client:
                headers = {"Host": "watch.example", "Authorization": f"Bearer {server.token}"}
                async with client.get(f"{base}health", headers=headers) as reply:
                    assert reply.status == 200

    run(test)


def test_reserved_slots_are_for_operators_only() -> None:
    hub = Hub(max_viewers=4, reserved=2)
    assert hub.join() is not None and hub.join() is not None
    assert hub.join() is None  # the rest is reserved
    assert hub.join(operator=True) is not None and hub.join(operator=True) is not None
    assert hub.join(operator=True) is None and hub.viewers == 4
