"""The live server of a running ``coral-run`` (`serve_live`) on real sockets: rights of
each token, ``POST /operate`` and its answers, the token file, off-loopback viewing, and a
stalled viewer while the engine logs a burst."""

from __future__ import annotations

import asyncio
import fcntl
import json
import os
import socket
import stat
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import aiohttp
import pytest

from runtime.eventlog import EventLog
from runtime.operator import OperatorAction, OperatorOutcome
from runtime.watch.feed import LiveFeed
from runtime.watch.live import LiveWatch, TokenFile, serve_live
from runtime.watch.server import Watch, WatchError, WatchServer
from runtime.watch.source import LogReader
from tests.runtime.watch.conftest import NET, run, serving


class FakeRun:
    """A controller's ``operate``: records the actions, accepts gives of ``abort``."""

    def __init__(self) -> None:
        self.actions: list[OperatorAction] = []

    async def operate(self, action: OperatorAction) -> OperatorOutcome:
        self.actions.append(action)
        if action.action == "give" and action.input != "abort":
            return OperatorOutcome(False, f"no input named {action.input}")
        return OperatorOutcome(True, f"{action.describe()} done")


def _log(tmp_path: Path) -> EventLog:
    log = EventLog.create(
        tmp_path / "c.sqlite", role="controller", mission="n", meta={}, net_json=NET
    )
    log.event(0.0, "mission-start", mission_id=1, marking={"a": 1})
    return log


def _token_of(lines: list[str]) -> str:
    [line] = [line for line in lines if "operate it at" in line]
    return line.split("?token=")[1].split()[0]


async def _post(
    client: aiohttp.ClientSession, url: str, body: object, token: str | None, **headers: str
) -> tuple[int, Any]:
    if token is not None:
        headers["Authorization"] = f"Bearer {token}"
    data = body if isinstance(body, bytes) else json.dumps(body).encode()
    async with client.post(f"{url}operate", data=data, headers=headers) as reply:
        text = await reply.text()
        return reply.status, (json.loads(text) if reply.status == 200 else text)


def test_rights_and_operate_on_loopback(tmp_path: Path) -> None:
    log = _log(tmp_path)
    feed = LiveFeed(log, NET)
    fake = FakeRun()
    lines: list[str] = []
    token_file = tmp_path / "watch.token"

    async def test() -> None:
        async with serve_live(
            feed,
            host="127.0.0.1",
            port=0,
            operate=fake.operate,
            token_file=token_file,
            console=lines.append,
            info={"mission": "n", "inputs": ["abort"]},
        ) as url:
            operate = _token_of(lines)
            assert token_file.read_text() == f"{operate}\n"
            assert stat.S_IMODE(token_file.stat().st_mode) == 0o600
            assert url.endswith("/") and "token" not in url  # loopback: viewing is free
            async with aiohttp.ClientSession() as client:
                for query, rights in (
                    ("", {"view": True, "operate": False}),
                    ("?token=wrong", {"view": True, "operate": False}),
                    (f"?token={operate}", {"view": True, "operate": True}),
                ):
                    async with client.get(f"{url}rights{query}") as reply:
                        assert await reply.json() == rights
                async with client.get(f"{url}info") as reply:
                    assert (await reply.json())["inputs"] == ["abort"]
                log.event(5.0, "fire", transition="go", command_id=None)
                log.commit()
                async with client.get(f"{url}snapshot") as reply:
                    assert (await reply.json())["snapshot"]["marking"] == {"b": 2}
                async with client.get(f"{url}snapshot?t=1") as reply:  # read from the file
                    doc = await reply.json()
                    assert doc["snapshot"]["marking"] == {"a": 1} and doc["end"] == 5.0
                good = {"action": "give", "input": "abort"}
                assert (await _post(client, url, good, None))[0] == 401
                assert (await _post(client, url, good, "wrong"))[0] == 401
                # A token in the query is not enough to act (it ends up in logs, histories).
                async with client.post(f"{url}operate?token={operate}", json=good) as reply:
                    assert reply.status == 401
                for body, field in (
                    (b"{", "body"),
                    ([1], "body"),
                    ({"action": "stop"}, "action"),
                    ({"action": "give"}, "input"),
                    ({"action": "give", "input": 3}, "input"),
                    ({"action": "pause", "input": "abort"}, "input"),
                    ({"action": "pause", "extra": 1}, "extra"),
                ):
                    status, text = await _post(client, url, body, operate)
                    assert status == 400 and text.startswith(f"{field}:"), (body, text)
                status, text = await _post(client, url, good, operate, **{"X-Coral-Client": "x"})
                assert status == 400 and "X-Coral-Client" in text
                assert (await _post(client, url, b"x" * 5000, operate))[0] == 413
                assert fake.actions == []  # nothing bad reached the run
                status, answer = await _post(
                    client, url, good, operate, **{"X-Coral-Client": "cli"}
                )
                assert status == 200 and answer == {"accepted": True, "message": "give abort done"}
                status, answer = await _post(
                    client, url, {"action": "give", "input": "nope"}, operate
                )
                assert status == 200 and answer["accepted"] is False
                status, answer = await _post(
                    client, url, {"action": "pause", "input": None}, operate
                )
                assert status == 200 and answer["accepted"] is True
            [first, second, third] = fake.actions
            port = url.rsplit(":", 1)[1].rstrip("/")
            assert first.action == "give" and first.input == "abort"
            assert (
                first.origin.startswith("cli 127.0.0.1:")
                and first.origin != f"cli 127.0.0.1:{port}"
            )
            assert second.origin.startswith("http 127.0.0.1:")
            assert third == OperatorAction("pause", third.origin, None)
        assert not token_file.exists()

    try:
        run(test)
    finally:
        feed.close()
        log.close()
    assert sum("operate it at" in line for line in lines) == 1  # printed once
    assert any("view the mission at" in line for line in lines)


def test_off_loopback_viewing_needs_the_view_token(tmp_path: Path) -> None:
    log = _log(tmp_path)
    feed = LiveFeed(log, NET)
    fake = FakeRun()
    lines: list[str] = []

    async def test() -> None:
        async with serve_live(
            feed,
            host="127.0.0.2",
            port=0,
            operate=fake.operate,
            token_file=None,
            console=lines.append,
            info={},
        ) as url:
            view = url.split("?token=")[1]
            operate = _token_of(lines)
            base = url.split("?")[0]
            assert view != operate and len(view) >= 40 and len(operate) >= 40
            async with aiohttp.ClientSession() as client:
                async with client.get(f"{base}snapshot") as reply:
                    assert reply.status == 401
                for token in (view, operate):  # the operate token grants view too
                    async with client.get(f"{base}snapshot?token={token}") as reply:
                        assert reply.status == 200
                        assert (await reply.json())["snapshot"]["marking"] == {"a": 1}
                async with client.get(f"{base}rights") as reply:
                    assert await reply.json() == {"view": False, "operate": False}
                async with client.get(f"{base}rights?token={view}") as reply:
                    assert await reply.json() == {"view": True, "operate": False}
                pause = {"action": "pause"}
                assert (await _post(client, base, pause, view))[0] == 403
                status, answer = await _post(
                    client, base, pause, operate, **{"X-Coral-Client": "page"}
                )
                assert status == 200 and answer["accepted"] is True
            assert fake.actions[0].origin.startswith("page 127.0.0.1:")

    try:
        run(test)
    finally:
        feed.close()
        log.close()


def test_a_token_file_held_by_another_run_refuses_to_start(tmp_path: Path) -> None:
    path = tmp_path / "watch.token"
    other = TokenFile(path, "theirs")
    log = _log(tmp_path)
    feed = LiveFeed(log, NET)

    async def test() -> None:
        with pytest.raises(WatchError, match="another run is serving"):
            async with serve_live(
                feed,
                host="127.0.0.1",
                port=0,
                operate=FakeRun().operate,
                token_file=path,
                console=lambda line: None,
                info={},
            ):
                raise AssertionError("started")

    try:
        run(test)
        assert path.read_text() == "theirs\n"  # left alone
        other.close()
        assert not path.exists()
        # A file left by a run killed with -9 (nobody holds it) is taken over, 0600.
        fd = os.open(path, os.O_CREAT | os.O_WRONLY, 0o644)
        os.write(fd, b"stale-token\n")
        os.close(fd)
        mine = TokenFile(path, "fresh")
        assert path.read_text() == "fresh\n" and stat.S_IMODE(path.stat().st_mode) == 0o600
        with open(path) as probe, pytest.raises(BlockingIOError):
            fcntl.flock(probe, fcntl.LOCK_EX | fcntl.LOCK_NB)
        mine.close()
        assert not path.exists()
        path.symlink_to(tmp_path / "elsewhere")
        with pytest.raises(WatchError):
            TokenFile(path, "x")
    finally:
        feed.close()
        log.close()


def test_a_log_server_cannot_operate(tmp_path: Path) -> None:
    log = _log(tmp_path)
    log.commit()
    reader = LogReader(tmp_path / "c.sqlite")

    async def test() -> None:
        server = WatchServer(Watch(reader), port=0)
        async with serving(server) as url, aiohttp.ClientSession() as client:
            async with client.get(f"{url}rights") as reply:
                assert await reply.json() == {"view": True, "operate": False}
            status, text = await _post(client, url, {"action": "pause"}, "anything")
            assert status == 404 and "operate from the run's own --watch server" in text

    try:
        run(test)
    finally:
        reader.close()
        log.close()


def test_slow_failing_and_flooding_operators(tmp_path: Path) -> None:
    log = _log(tmp_path)
    feed = LiveFeed(log, NET)
    errors: list[str] = []

    async def slow(action: OperatorAction) -> OperatorOutcome:
        if action.action == "pause":
            await asyncio.sleep(5)
        if action.action == "resume":
            raise RuntimeError("controller bug")
        return OperatorOutcome(True, "ok")

    async def test() -> None:
        server = WatchServer(
            LiveWatch(feed),
            port=0,
            operate=slow,
            operate_timeout=0.05,
            operate_rate=3,
            on_error=errors.append,
        )
        async with serving(server) as url:
            token = server.operate_token
            async with aiohttp.ClientSession() as client:
                status, text = await _post(client, url, {"action": "pause"}, token)
                assert status == 504 and "did not answer pause" in text
                for _ in range(2):
                    status, text = await _post(client, url, {"action": "resume"}, token)
                    assert status == 500 and "controller bug" in text
                status, _ = await _post(client, url, {"action": "give", "input": "a"}, token)
                assert status == 429  # 3 per second
            assert errors == [errors[0]] and "controller bug" in errors[0]  # reported once

    try:
        run(test)
    finally:
        feed.close()
        log.close()


@pytest.mark.slow
def test_a_stalled_viewer_while_the_engine_logs_a_burst(tmp_path: Path) -> None:
    """One viewer never reads, another reads: 1,000 rows logged in a burst reach the state
    at once, the server publishes a few snapshots, and no slot holds more than one."""
    log = _log(tmp_path)
    feed = LiveFeed(log, NET, interval=0.05)

    async def test() -> None:
        server = WatchServer(LiveWatch(feed), port=0, operate=FakeRun().operate)
        await server.start()
        published = 0
        publish = server.hub.publish

        def counting(payload: bytes) -> None:
            nonlocal published
            published += 1
            publish(payload)

        server.hub.publish = counting  # type: ignore[method-assign]
        loop = asyncio.get_running_loop()
        stalled = socket.socket()
        stalled.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        stalled.setblocking(False)
        try:
            await loop.sock_connect(stalled, ("127.0.0.1", server.port))
            await loop.sock_sendall(stalled, b"GET /events HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
            async with aiohttp.ClientSession() as client, client.get(f"{server.url}events") as live:
                for _ in range(100):
                    if server.hub.viewers == 2:
                        break
                    await asyncio.sleep(0.01)
                assert server.hub.viewers == 2
                for n in range(1000):
                    log.event(1.0 + n / 1000, "fire", transition="go", pad="x" * 500)
                    if n % 100 == 0:
                        assert all(p is None or len(p) > 0 for p in server.hub.pending())
                        await asyncio.sleep(0)
                assert feed.state.seq == 1001  # every row reached the state in the burst
                log.event(3.0, "mission-end", end="final", final=True, marking={"b": 2})
                last = None
                while line := await live.content.readline():
                    if line.startswith(b"data: "):
                        last = json.loads(line[6:])
                        if not last["live"]:
                            break
                assert last is not None and last["snapshot"]["seq"] == 1002
                assert len(server.hub.pending()) == 2  # one slot each, holding one at most
            assert 1 <= published <= 20, published
        finally:
            stalled.close()
            await server.stop()

    try:
        run(test)
    finally:
        feed.close()
        log.close()


class BrokenSource:
    """A source whose documents fail: every route must answer, never raise."""

    mission = "broken"
    ended = False
    seq = 0
    version = 0

    def document(self, t: float | None = None) -> dict[str, object]:
        raise KeyError("no such place")

    async def follow(self, publish: Callable[[], None], on_error: Callable[[str], None]) -> None:
        for _ in range(3):
            publish()  # nobody watches: nothing is serialised, nothing fails
            await asyncio.sleep(0.01)


def test_a_failing_source_is_answered_500_and_reported_once() -> None:
    errors: list[str] = []

    async def test() -> None:
        server = WatchServer(BrokenSource(), port=0, on_error=errors.append)
        async with serving(server) as url:
            async with aiohttp.ClientSession() as client:
                for _ in range(2):
                    async with client.get(f"{url}snapshot") as reply:
                        assert reply.status == 500 and "no such place" in await reply.text()
                async with client.get(f"{url}events") as stream:
                    assert stream.status == 200
                    assert await stream.content.read() == b""  # ended, not hung
                async with client.get(f"{url}health") as reply:
                    assert reply.status == 200
            assert server._follower is not None
            await asyncio.wait_for(server._follower, 1)

    run(test)
    # snapshot and events; publishing to nobody serialised nothing, so it did not fail
    assert len(errors) == len(set(errors)) == 2, errors


def test_the_end_reaches_viewers_when_the_run_stops_at_once(tmp_path: Path) -> None:
    """The run ends and leaves `serve_live` at once, before the follower's next
    publication: stopping still gives every viewer the final state."""
    log = _log(tmp_path)
    feed = LiveFeed(log, NET, interval=5.0)  # the follower would wait 5 s
    documents: list[dict[str, Any]] = []

    async def test() -> None:
        async with aiohttp.ClientSession() as client:
            async with serve_live(
                feed,
                host="127.0.0.1",
                port=0,
                operate=FakeRun().operate,
                token_file=None,
                console=lambda line: None,
                info={},
            ) as url:
                stream = await client.get(f"{url}events")
                first = await stream.content.readline()
                documents.append(json.loads(first[len(b"data: ") :]))
                log.event(1.0, "fire", transition="go", command_id=None)
                log.event(2.0, "mission-end", end="final", final=True, marking={"b": 2})
            async for line in stream.content:  # the server has stopped; the stream ends
                if line.startswith(b"data: "):
                    documents.append(json.loads(line[len(b"data: ") :]))
            stream.close()

    try:
        run(test)
    finally:
        feed.close()
        log.close()
    assert documents[0]["live"] is True
    assert documents[-1]["live"] is False
    assert documents[-1]["snapshot"]["marking"] == {"b": 2}


def test_anonymous_viewers_cannot_take_the_operators_slots(tmp_path: Path) -> None:
    """On loopback any local process views without a token: it must not be able to take
    every slot and lock the operator out of the run."""
    log = _log(tmp_path)
    feed = LiveFeed(log, NET)

    async def test() -> None:
        server = WatchServer(LiveWatch(feed), port=0, operate=FakeRun().operate, max_viewers=4)
        async with serving(server) as url:
            operator = f"{url}events?token={server.operate_token}"
            streams: list[aiohttp.ClientResponse] = []
            async with aiohttp.ClientSession() as client:
                for _ in range(2):
                    streams.append(await client.get(f"{url}events"))
                    assert streams[-1].status == 200
                async with client.get(f"{url}events") as refused:
                    assert refused.status == 503
                for _ in range(2):
                    streams.append(await client.get(operator))
                    assert streams[-1].status == 200
                async with client.get(operator) as full:
                    assert full.status == 503
                for stream in streams:
                    stream.close()

    try:
        run(test)
    finally:
        feed.close()
        log.close()


def test_a_fifo_at_the_token_path_is_refused_at_once(tmp_path: Path) -> None:
    """Opening a FIFO for writing waits for a reader: the run's start must not hang."""
    path = tmp_path / "operate.token"
    os.mkfifo(path, 0o600)
    outcome: list[BaseException | None] = []

    def claim() -> None:
        try:
            TokenFile(path, "x").close()
            outcome.append(None)
        except BaseException as error:  # reported by the assertion below
            outcome.append(error)

    worker = threading.Thread(target=claim, daemon=True)
    worker.start()
    worker.join(2)
    if worker.is_alive():  # release the blocked open before failing
        os.close(os.open(path, os.O_RDONLY | os.O_NONBLOCK))
        worker.join(2)
        raise AssertionError("TokenFile blocked on a FIFO")
    [error] = outcome
    assert isinstance(error, WatchError) and "not a token file" in str(error)
    assert stat.S_ISFIFO(path.lstat().st_mode)  # left alone


def test_taking_over_a_token_file_never_shows_it_empty(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A reader (``coral-run operate``) may read the file at any moment while a new run
    takes a stale one over: after each write to it, the file must hold a whole token."""
    path = tmp_path / "operate.token"
    path.write_bytes(b"stale-token-left-by-a-killed-run\n")
    seen: list[bytes] = []
    for name in ("write", "pwrite", "ftruncate"):
        original = getattr(os, name)

        def spying(*args: Any, _original: Any = original) -> Any:
            result = _original(*args)
            seen.append(path.read_bytes())
            return result

        monkeypatch.setattr(os, name, spying)
    token = "fresh-token"
    held = TokenFile(path, token)
    monkeypatch.undo()
    try:
        assert seen and b"" not in seen, seen
        assert path.read_bytes() == f"{token}\n".encode()
    finally:
        held.close()


def test_a_replay_on_a_live_run_keeps_no_rows(tmp_path: Path) -> None:
    log = _log(tmp_path)
    log.event(1.0, "fire", transition="go", command_id=None)
    log.commit()
    feed = LiveFeed(log, NET)
    live = LiveWatch(feed)
    try:
        assert live.document(0.5)["snapshot"]["marking"] == {"a": 1}  # type: ignore[index]
        assert live.document(1.5)["snapshot"]["marking"] == {"b": 2}  # type: ignore[index]
        kept = [value for value in vars(live).values() if isinstance(value, Watch | list)]
        assert kept == []  # read for the request, then let go
    finally:
        feed.close()
        log.close()
