"""``coral-run operate`` against a tiny fake of the live server, and the run's options."""

from __future__ import annotations

import asyncio
import contextlib
import socket
import threading
from collections.abc import AsyncIterator, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest
from aiohttp import web

from runtime.cli import main

TOKEN = "op-secret"


@dataclass
class Fake:
    """What the fake server saw, and what it answers."""

    port: int = 0
    status: int = 200
    answer: dict[str, object] = field(default_factory=lambda: {"accepted": True, "message": "ok"})
    requests: list[tuple[dict[str, object], dict[str, str]]] = field(default_factory=list)


@contextlib.contextmanager
def fake_server() -> Iterator[Fake]:
    """An aiohttp server on a free port in its own thread, answering ``POST /operate``."""
    fake = Fake()
    ready = threading.Event()
    loop = asyncio.new_event_loop()

    async def operate(request: web.Request) -> web.Response:
        fake.requests.append((await request.json(), dict(request.headers)))
        if request.headers.get("Authorization") != f"Bearer {TOKEN}":
            return web.json_response({"message": "bad token"}, status=401)
        return web.json_response(fake.answer, status=fake.status)

    async def start() -> web.AppRunner:
        app = web.Application()
        app.router.add_post("/operate", operate)
        runner = web.AppRunner(app)
        await runner.setup()
        site = web.TCPSite(runner, "127.0.0.1", 0)
        await site.start()
        server = site._server
        assert isinstance(server, asyncio.Server)
        fake.port = server.sockets[0].getsockname()[1]
        return runner

    def serve() -> None:
        asyncio.set_event_loop(loop)
        runner = loop.run_until_complete(start())
        ready.set()
        loop.run_forever()
        loop.run_until_complete(runner.cleanup())
        loop.close()

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    assert ready.wait(10)
    try:
        yield fake
    finally:
        loop.call_soon_threadsafe(loop.stop)
        thread.join(10)


@pytest.fixture
def server() -> Iterator[Fake]:
    with fake_server() as fake:
        yield fake


def token_file(tmp_path: Path, text: str = TOKEN) -> Path:
    path = tmp_path / "operate.token"
    path.write_text(text + "\n")
    path.chmod(0o600)
    return path


def test_an_accepted_action_exits_0_and_sends_the_token_and_client(
    server: Fake, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    server.answer = {"accepted": True, "message": "input abort_requested given"}
    token_file(tmp_path)  # the run's --out folder holds its token
    code = main(["operate", str(server.port), "give", "abort_requested", "--out", str(tmp_path)])
    assert code == 0
    assert "input abort_requested given" in capsys.readouterr().out
    body, headers = server.requests[0]
    assert body == {"action": "give", "input": "abort_requested"}
    assert headers["X-Coral-Client"] == "cli"


def test_a_refused_action_exits_1_with_the_runs_reason(
    server: Fake, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    server.answer = {"accepted": False, "message": "already paused"}
    path = token_file(tmp_path)
    assert main(["operate", f"127.0.0.1:{server.port}", "pause", "--token-file", str(path)]) == 1
    assert "refused: already paused" in capsys.readouterr().err
    assert server.requests[0][0] == {"action": "pause", "input": None}


def test_a_wrong_token_exits_2_naming_the_address(
    server: Fake, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = token_file(tmp_path, "wrong")
    assert main(["operate", str(server.port), "resume", "--token-file", str(path)]) == 2
    err = capsys.readouterr().err
    assert f"127.0.0.1:{server.port}" in err and "the operate token was refused" in err


@pytest.mark.parametrize(
    ("status", "meaning"),
    [(403, "view right only"), (404, "no operator actions"), (400, "HTTP 400")],
)
def test_other_refusals_of_the_server_exit_2(
    server: Fake, tmp_path: Path, capsys: pytest.CaptureFixture[str], status: int, meaning: str
) -> None:
    server.status = status
    server.answer = {"message": "field 'action'"}
    path = token_file(tmp_path)
    assert main(["operate", str(server.port), "pause", "--token-file", str(path)]) == 2
    assert meaning in capsys.readouterr().err


def test_the_token_comes_from_the_environment_last(
    server: Fake, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("CORAL_OPERATE_TOKEN", TOKEN)
    assert main(["operate", str(server.port), "pause", "--out", str(tmp_path / "none")]) == 0
    # A token file in --out comes before the environment.
    token_file(tmp_path, "from-file")
    assert main(["operate", str(server.port), "pause", "--out", str(tmp_path)]) == 2
    assert server.requests[-1][1]["Authorization"] == "Bearer from-file"


def test_no_token_bad_usage_and_no_server_exit_2(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.delenv("CORAL_OPERATE_TOKEN", raising=False)
    assert main(["operate", "9", "pause", "--out", str(tmp_path)]) == 2
    assert "no operate token" in capsys.readouterr().err
    path = token_file(tmp_path)
    assert main(["operate", "9", "give", "--token-file", str(path)]) == 2
    assert "give needs the NAME" in capsys.readouterr().err
    assert main(["operate", "9", "pause", "now", "--token-file", str(path)]) == 2
    with contextlib.closing(socket.socket()) as probe:
        probe.bind(("127.0.0.1", 0))
        free = probe.getsockname()[1]  # bound, not listening: refused
        assert main(["operate", str(free), "pause", "--token-file", str(path)]) == 2
    assert f"cannot reach 127.0.0.1:{free}" in capsys.readouterr().err
    assert main(["operate", "9", "stop", "--token-file", str(path)]) == 2


@pytest.mark.parametrize("flag", [["--watch", "0"], ["--tui"]])
def test_watching_a_run_needs_real_time(
    flag: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code = main(["mission.coral", *flag, "--out", str(tmp_path)])
    assert code == 2
    assert f"{flag[0]} needs a run in real time: add --realtime (or --vehicle)" in (
        capsys.readouterr().err
    )
    assert not any(tmp_path.iterdir())


def test_watch_log_tui_calls_the_terminal_view(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import runtime.tui

    seen: list[Path] = []

    def fake_view(log: Path) -> int:
        seen.append(log)
        return 0

    monkeypatch.setattr(runtime.tui, "watch_log_tui", fake_view)
    assert main(["watch", str(tmp_path / "c.sqlite"), "--tui"]) == 0
    assert seen == [tmp_path / "c.sqlite"]
    assert main(["watch", str(tmp_path / "c.sqlite"), "--tui", "--watch", "0"]) == 2


QUICK = """
mission quick_stop
vehicle ROMEO
input stop
place start = 1
place at_a, done, failed, stopped
final { done }
final { stopped }
final { failed }
transition go_a
    wait { start }
    action { ROMEO(DEPTH?, z = 0.0, time_out = 60.0) -> { done: at_a, timeout: failed } }
transition finish
    wait { at_a }
    signal { done }
transition stop_at_a priority 1
    wait { at_a, stop }
    signal { stopped }
transition stop_after_failure
    wait { failed, stop }
    signal { failed }
transition stop_too_late
    wait { done, stop }
    signal { done }
"""


@pytest.mark.slow
def test_operate_drives_a_real_run_served_with_watch(tmp_path: Path) -> None:
    """End to end in real time: the run's live server, its 0600 token file, the client.

    The pause lands while the first query is out (5 s of simulator time at speed 2), so
    the reply is consumed while paused, and the input then resumes the engine and takes
    the mission's stop path."""
    import re

    from analysis.signing import TrustStore
    from runtime.cli import OPERATE_TOKEN_FILE, live_companion
    from runtime.controller import Controller, RunEnd
    from runtime.eventlog import EventLog
    from runtime.gate import approve_mission
    from runtime.run import RunConfig, run_mission

    mission_file = tmp_path / "quick_stop.coral"
    mission_file.write_text(QUICK)
    approved = approve_mission(mission_file, issue=True, trusted=TrustStore())
    out = tmp_path / "run"
    lines: list[str] = []
    codes: list[int] = []
    modes: list[int] = []

    @contextlib.asynccontextmanager
    async def operator(controller: Controller) -> AsyncIterator[None]:
        port = next(m[1] for line in lines if (m := re.search(r"127\.0\.0\.1:(\d+)/", line)))
        modes.append((out / OPERATE_TOKEN_FILE).stat().st_mode & 0o777)

        async def act() -> None:
            for argv in (["pause"], ["give", "stop"], ["give", "stop"]):
                codes.append(
                    await asyncio.to_thread(main, ["operate", port, *argv, "--out", str(out)])
                )
                await asyncio.sleep(0.3 if argv == ["pause"] else 0.0)

        task = asyncio.create_task(act())
        try:
            yield
        finally:
            await task

    config = RunConfig(
        out_dir=out,
        psk=bytes(32),
        realtime=True,
        speed=2.0,
        console=lines.append,
        log_key_ephemeral=True,
        companions=(
            live_companion(
                watch=("127.0.0.1", 0),
                tui=False,
                token_file=out / OPERATE_TOKEN_FILE,
                console=lines.append,
            ),
            operator,
        ),
    )
    result = run_mission(approved, config)
    assert modes == [0o600]
    assert not (out / OPERATE_TOKEN_FILE).exists()  # removed with the server
    assert result.end is RunEnd.FINAL and result.marking == {"stopped": 1}
    assert codes[:2] == [0, 0]
    with EventLog.open(out / "controller.sqlite") as log:
        actions = [e.data for e in log.events("operator")]
    assert [(a["action"], a["accepted"]) for a in actions][:2] == [("pause", True), ("give", True)]
    assert all(str(a["origin"]).startswith("cli 127.0.0.1:") for a in actions)


def _answering(raw: bytes) -> tuple[int, threading.Thread, socket.socket]:
    """A server on 127.0.0.1 that answers one connection with ``raw`` and hangs up.

    It reads until the client closes before closing itself: closing with part of the
    request still unread (headers and body can come in separate segments) makes the
    kernel reset the connection, and the client then sees a reset, not ``raw``."""
    listener = socket.create_server(("127.0.0.1", 0))

    def serve() -> None:
        connection, _ = listener.accept()
        with connection:
            connection.settimeout(10)
            connection.recv(65536)
            connection.sendall(raw)
            connection.shutdown(socket.SHUT_WR)
            with contextlib.suppress(OSError):
                while connection.recv(65536):
                    pass

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    return int(listener.getsockname()[1]), thread, listener


@pytest.mark.parametrize(
    ("raw", "said"),
    [
        (b"SSH-2.0-OpenSSH_9.6\r\n", "is not a coral watch server"),
        (b"HTTP/1.1 200 OK\r\nContent-Length: 100\r\n\r\n{", "not JSON"),
        (b"HTTP/1.1 200 OK\r\nContent-Length: 9000\r\n\r\n" + b"[" * 9000, "not JSON"),
    ],
    ids=["not-http", "truncated", "deeply-nested"],
)
def test_a_server_that_is_not_coral_exits_2_without_a_traceback(
    raw: bytes, said: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    port, thread, listener = _answering(raw)
    with listener:
        code = main(["operate", str(port), "pause", "--token-file", str(token_file(tmp_path))])
        thread.join(timeout=10)
    assert code == 2
    assert said in capsys.readouterr().err


def test_bad_addresses_and_tokens_exit_2_with_a_message(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = token_file(tmp_path)
    assert main(["operate", "a b:80", "pause", "--token-file", str(path)]) == 2
    assert "a b:80" in capsys.readouterr().err
    odd = tmp_path / "odd.token"
    odd.write_text("tok\u20ac\n", encoding="utf-8")
    assert main(["operate", "9", "pause", "--token-file", str(odd)]) == 2
    assert "characters no token has" in capsys.readouterr().err
