"""The watch server: one page, a snapshot at any time, and a live stream of the newest one.

Routes (all GET):

* ``/`` the page (`runtime.watch.page`: one self-contained HTML file, no external asset);
* ``/snapshot?t=SECONDS`` the mission at time t of the log (replay scrubbing); without t,
  the newest;
* ``/events`` Server-Sent Events: the newest snapshot each time the log grows;
* ``/health`` ``{"ok": true, ...}``: whether the server is up and how far it has read.

Why a slot per viewer and not a queue: a viewer on a slow link, or a browser tab in the
background, must never hold memory or time of the server, let alone of the engine whose log
it reads. Each viewer has one `Slot` holding only the newest snapshot; publishing replaces
it, so a stalled viewer costs one snapshot however many are published, and when it reads
again it gets the present, not a backlog.

Why a token off loopback: on 127.0.0.1, ::1 or ``localhost`` only this machine's users reach
the server (the default). Bound to any other address (127.0.0.2 included: we do not guess
which other loopback addresses a machine routes where) anyone on that network could, so
every request must carry the random token printed at start, as ``?token=`` or
``Authorization: Bearer``; without it, 401. The token grants the *view* right only:
operating the mission (operator actions) will come with a separate operate right.
"""

from __future__ import annotations

import asyncio
import contextlib
import hmac
import json
import math
import secrets
from collections.abc import Awaitable, Callable
from typing import Final

from aiohttp import web

from coral_lang.diagnostics import CoralError
from runtime.eventlog import Event, TelemetrySample
from runtime.watch.page import PAGE
from runtime.watch.source import LogReader
from runtime.watch.state import WatchState, snapshot_at

__all__ = [
    "DEFAULT_HOST",
    "DEFAULT_PORT",
    "LOOPBACK_HOSTS",
    "MAX_VIEWERS",
    "RIGHTS",
    "Hub",
    "Slot",
    "Watch",
    "WatchServer",
    "needs_token",
]

DEFAULT_HOST: Final = "127.0.0.1"
DEFAULT_PORT: Final = 8765
LOOPBACK_HOSTS: Final = frozenset({"127.0.0.1", "::1", "localhost"})
"""The addresses served without a token; any other needs one (see the module)."""

MAX_VIEWERS: Final = 64
"""Live viewers at once; one more gets 503 (each holds a connection and a slot)."""

RIGHTS: Final = ("view",)
"""What a token grants now. Operator actions will add an ``operate`` right with a token of
its own, so a shared view link never lets anyone act on the mission."""

_MAX_BODY: Final = 4096
_MAX_LINE: Final = 4096
"""Requests are small GETs: bodies and header lines beyond these are refused by aiohttp."""

Payload = bytes


def needs_token(host: str) -> bool:
    """Whether binding to ``host`` requires the access token (anything not plain loopback)."""
    return host not in LOOPBACK_HOSTS


class Slot:
    """One viewer's mailbox: at most the newest payload, never a queue."""

    def __init__(self) -> None:
        self._payload: Payload | None = None
        self._ready = asyncio.Event()
        self.closed = False

    @property
    def pending(self) -> Payload | None:
        """The payload waiting to be sent, if any (one at most, by construction)."""
        return self._payload

    def put(self, payload: Payload) -> None:
        """Replace whatever was waiting: a viewer that fell behind skips to the present."""
        self._payload = payload
        self._ready.set()

    def close(self) -> None:
        self.closed = True
        self._ready.set()

    async def take(self) -> Payload | None:
        """The next payload to send, waiting for one; None once the slot is closed."""
        while True:
            await self._ready.wait()
            self._ready.clear()
            if self.closed:
                return None
            payload, self._payload = self._payload, None
            if payload is not None:
                return payload


class Hub:
    """The viewers' slots: publishing is O(viewers) and never waits for any of them."""

    def __init__(self, max_viewers: int = MAX_VIEWERS) -> None:
        self.max_viewers = max_viewers
        self._slots: set[Slot] = set()

    @property
    def viewers(self) -> int:
        return len(self._slots)

    def join(self) -> Slot | None:
        """A new viewer's slot, or None when `max_viewers` are already watching."""
        if len(self._slots) >= self.max_viewers:
            return None
        slot = Slot()
        self._slots.add(slot)
        return slot

    def pending(self) -> list[Payload | None]:
        """What waits in each viewer's slot: one payload at most per viewer."""
        return [slot.pending for slot in self._slots]

    def leave(self, slot: Slot) -> None:
        self._slots.discard(slot)

    def publish(self, payload: Payload) -> None:
        for slot in self._slots:
            slot.put(payload)

    def close(self) -> None:
        for slot in self._slots:
            slot.close()


class Watch:
    """A log's rows read so far, its live state, and its replay."""

    def __init__(self, reader: LogReader) -> None:
        self.reader = reader
        self.state = WatchState(reader.net_json)
        self.events: list[Event] = []
        self.samples: list[TelemetrySample] = []

    @property
    def ended(self) -> bool:
        return self.state.end is not None

    def ingest(self, events: list[Event], samples: list[TelemetrySample]) -> bool:
        """Take newly read rows; whether there were any."""
        self.events.extend(events)
        self.samples.extend(samples)
        self.state.advance(events, samples)
        return bool(events or samples)

    def poll(self) -> bool:
        """Read and take the rows committed since the last poll (blocking: SQLite)."""
        return self.ingest(*self.reader.read())

    def span(self) -> tuple[float, float]:
        """The replay's range: first event to the end (or the newest event so far)."""
        if not self.events:
            return 0.0, 0.0
        return self.events[0].time, self.state.time

    def document(self, t: float | None = None) -> dict[str, object]:
        """What the page receives: the snapshot (newest, or at ``t``) and the span."""
        if t is None:
            snapshot = self.state.snapshot()
        else:
            snapshot = snapshot_at(self.reader.net_json, self.events, self.samples, t)
        start, end = self.span()
        return {
            "mission": self.reader.mission,
            "live": not self.ended,
            "start": start,
            "end": end,
            "snapshot": snapshot.to_json(),
        }

    def payload(self) -> Payload:
        return json.dumps(self.document(), separators=(",", ":")).encode()


def _authorised(request: web.Request, token: str) -> bool:
    given = request.query.get("token", "")
    header = request.headers.get("Authorization", "")
    if not given and header.startswith("Bearer "):
        given = header[len("Bearer ") :].strip()
    return hmac.compare_digest(given.encode(), token.encode())


class WatchServer:
    """The aiohttp application over a `Watch`, and the task that follows a live log."""

    def __init__(
        self,
        watch: Watch,
        *,
        host: str = DEFAULT_HOST,
        port: int = DEFAULT_PORT,
        token: str | None = None,
        max_viewers: int = MAX_VIEWERS,
        poll_interval: float = 0.5,
        on_error: Callable[[str], None] = lambda line: None,
    ) -> None:
        self.watch = watch
        self.host = host
        self.port = port
        self.token = token if token is not None or not needs_token(host) else _new_token()
        self.hub = Hub(max_viewers)
        self.poll_interval = poll_interval
        self.on_error = on_error
        self.app = self._make_app()
        self._runner: web.AppRunner | None = None
        self._follower: asyncio.Task[None] | None = None

    def _make_app(self) -> web.Application:
        token = self.token

        @web.middleware
        async def auth(
            request: web.Request, handler: Callable[[web.Request], Awaitable[web.StreamResponse]]
        ) -> web.StreamResponse:
            if token is not None and not _authorised(request, token):
                raise web.HTTPUnauthorized(
                    text="this watch server needs its access token (?token= or "
                    "Authorization: Bearer)",
                    headers={"WWW-Authenticate": "Bearer"},
                )
            return await handler(request)

        app = web.Application(
            middlewares=[auth],
            client_max_size=_MAX_BODY,
            handler_args={"max_line_size": _MAX_LINE, "max_field_size": _MAX_LINE},
        )
        app.router.add_get("/", self._page)
        app.router.add_get("/snapshot", self._snapshot)
        app.router.add_get("/events", self._events)
        app.router.add_get("/health", self._health)
        return app

    async def _page(self, request: web.Request) -> web.Response:
        return web.Response(
            text=PAGE,
            content_type="text/html",
            headers={"Content-Security-Policy": "default-src 'self' 'unsafe-inline'"},
        )

    async def _snapshot(self, request: web.Request) -> web.Response:
        text = request.query.get("t")
        t = None
        if text is not None:
            try:
                t = float(text)
            except ValueError:
                t = math.nan
            if not math.isfinite(t):
                raise web.HTTPBadRequest(text=f"t must be a number of seconds, got {text[:40]!r}")
        return web.json_response(self.watch.document(t))

    async def _health(self, request: web.Request) -> web.Response:
        return web.json_response(
            {
                "ok": True,
                "live": not self.watch.ended,
                "seq": self.watch.state.seq,
                "viewers": self.hub.viewers,
            }
        )

    async def _events(self, request: web.Request) -> web.StreamResponse:
        slot = self.hub.join()
        if slot is None:
            raise web.HTTPServiceUnavailable(text="too many viewers; try again later")
        try:
            response = web.StreamResponse(
                headers={"Content-Type": "text/event-stream", "Cache-Control": "no-cache"}
            )
            await response.prepare(request)
            slot.put(self.watch.payload())
            while (payload := await slot.take()) is not None:
                await response.write(b"data: " + payload + b"\n\n")
        finally:
            self.hub.leave(slot)
        return response

    async def _follow(self) -> None:
        """Poll the log for new rows until the mission ends; publish each change."""
        while not self.watch.ended:
            await asyncio.sleep(self.poll_interval)
            try:
                events, samples = await asyncio.to_thread(self.watch.reader.read)
            except CoralError as error:  # busy or damaged: say so, try again next time
                self.on_error(str(error))
                continue
            if self.watch.ingest(events, samples):
                self.hub.publish(self.watch.payload())

    async def start(self) -> str:
        """Listen and start following; the URL to open (with the token, if any)."""
        self._runner = web.AppRunner(self.app, access_log=None, shutdown_timeout=0.5)
        await self._runner.setup()
        site = web.TCPSite(self._runner, self.host, self.port)
        await site.start()
        self.port = int(self._runner.addresses[0][1])
        self._follower = asyncio.create_task(self._follow())
        return self.url

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        query = "" if self.token is None else f"?token={self.token}"
        return f"http://{host}:{self.port}/{query}"

    async def stop(self) -> None:
        if self._follower is not None:
            self._follower.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._follower
        self.hub.close()
        if self._runner is not None:
            await self._runner.cleanup()


def _new_token() -> str:
    return secrets.token_urlsafe(32)
