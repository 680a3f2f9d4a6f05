"""``coral-run watch LOG [--watch [HOST:]PORT]``: serve a log's page until Ctrl-C.

The server of a running mission (``coral-run MISSION --watch``, with the operate right) is
`runtime.watch.live`; this one reads the log file, so it only views.

Why a separate process reading the log rather than a hook in the engine: the log is already
the mission's record (committed, WAL, readable while written), so a viewer that reads it can
never slow down or disturb the run, and the same page replays a finished mission.
"""

from __future__ import annotations

import asyncio
import sys
from pathlib import Path

from runtime.watch.server import DEFAULT_HOST, Watch, WatchError, WatchServer, static_info
from runtime.watch.source import LogReader

__all__ = ["WatchError", "log_info", "parse_address", "watch"]


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
        view = Watch(reader, poll_interval=poll_interval)
        view.poll()  # everything committed so far, before the first viewer arrives
        asyncio.run(_serve(view, host, port, log_info(reader)))
    except KeyboardInterrupt:
        print("coral-run watch: stopped", file=sys.stderr)
    finally:
        reader.close()
    return 0


def log_info(reader: LogReader) -> dict[str, object]:
    """The page's static data (`runtime.watch.info.page_info`) of a log's header."""
    return static_info(reader.net_json, {"mission": reader.mission, **reader.meta})


async def _serve(view: Watch, host: str, port: int, info: dict[str, object]) -> None:
    server = WatchServer(
        view,
        host=host,
        port=port,
        info=info,
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
    print("coral-run watch: a log's server cannot operate the mission (no operate right)")
    try:
        await asyncio.Event().wait()
    finally:
        await server.stop()
