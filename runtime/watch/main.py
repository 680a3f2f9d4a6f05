"""``coral-run watch LOG [--watch [HOST:]PORT]``: serve a log's page until Ctrl-C.

Why a separate process reading the log rather than a hook in the engine: the log is already
the mission's record (committed, WAL, readable while written), so a viewer that reads it can
never slow down or disturb the run, and the same page replays a finished mission.
"""

from __future__ import annotations

import asyncio
import sys
from pathlib import Path

from coral_lang.diagnostics import CoralError
from runtime.watch.server import DEFAULT_HOST, Watch, WatchServer
from runtime.watch.source import LogReader

__all__ = ["WatchError", "parse_address", "watch"]


class WatchError(CoralError):
    """The server cannot start (the address is taken, or not this machine's): bad usage."""


def parse_address(text: str) -> tuple[str, int]:
    """``PORT``, ``HOST:PORT`` or ``[IPv6]:PORT``; a bare port binds to 127.0.0.1.

    Raises ValueError with a message naming what was expected.
    """
    host, sep, port = text.rpartition(":")
    if not sep:
        host = DEFAULT_HOST
    host = host.removeprefix("[").removesuffix("]")
    if not host or not (port.isascii() and port.isdigit()) or not 0 <= int(port) < 65536:
        raise ValueError(f"expected [HOST:]PORT with a port from 0 to 65535, got {text!r}")
    return host, int(port)


def watch(log: Path, host: str, port: int, *, poll_interval: float = 0.5) -> int:
    """Serve ``log`` on ``host:port`` until Ctrl-C (exit 0). A bad log raises
    `EventLogError` (a `CoralError`) before anything listens."""
    reader = LogReader(log)
    try:
        view = Watch(reader)
        view.poll()  # everything committed so far, before the first viewer arrives
        asyncio.run(_serve(view, host, port, poll_interval))
    except KeyboardInterrupt:
        print("coral-run watch: stopped", file=sys.stderr)
    finally:
        reader.close()
    return 0


async def _serve(view: Watch, host: str, port: int, poll_interval: float) -> None:
    server = WatchServer(
        view,
        host=host,
        port=port,
        poll_interval=poll_interval,
        on_error=lambda line: print(f"coral-run watch: {line}", file=sys.stderr),
    )
    try:
        url = await server.start()
    except OSError as error:
        raise WatchError(f"cannot listen on {host}:{port}: {error.strerror or error}") from None
    state = "live: following the log until mission-end" if not view.ended else "replay"
    print(f"coral-run watch: {view.reader.path} ({state}) at {url}", flush=True)
    if server.token is not None:
        print("coral-run watch: the URL holds the access token (view right); it is shown once")
    try:
        await asyncio.Event().wait()
    finally:
        await server.stop()
