"""The watch server: one page, a snapshot at any time, a live stream of the newest one, and
(inside a running ``coral-run``) the operator's actions.

Routes:

* ``GET /`` the page (`runtime.watch.page`: one self-contained HTML file, no external asset);
* ``GET /info`` the mission's static data (net drawing, inputs, workspace: `runtime.watch.info`);
* ``GET /snapshot?t=SECONDS`` the mission at time t (replay scrubbing); without t, the newest;
* ``GET /events`` Server-Sent Events: the newest snapshot each time the mission changes;
* ``GET /health`` ``{"ok": true, ...}``: whether the server is up and how far it has read;
* ``GET /rights`` ``{"view": bool, "operate": bool}`` for the token presented;
* ``POST /operate`` an operator action (`runtime.operator`), only on the server of a
  running mission (``coral-run MISSION --watch``); a log's server answers 404.

Two sources, one server: `Watch` follows a log file by polling it (``coral-run watch LOG``:
a separate process that can never disturb the run, and the replay of a finished one);
`runtime.watch.live.LiveWatch` is fed by the running controller's own event log
(`runtime.watch.feed`). Both give the same documents; only how they learn of new rows
differs.

Why a slot per viewer and not a queue: a viewer on a slow link, or a browser tab in the
background, must never hold memory or time of the server, let alone of the engine whose log
it reads. Each viewer has one `Slot` holding only the newest snapshot; publishing replaces
it, so a stalled viewer costs one snapshot however many are published, and when it reads
again it gets the present, not a backlog. A snapshot is serialised once per publication
for all viewers, and not at all when nobody watches.

Rights. *View*: on 127.0.0.1, ::1 or ``localhost`` only this machine's users reach the
server (the default) and viewing needs no token. Bound to any other address (127.0.0.2
included: we do not guess which other loopback addresses a machine routes where) anyone on
that network could, so every request must carry the random view token printed at start,
as ``?token=`` or ``Authorization: Bearer``; without it, 401. *Operate*: a second random
token, always required (on loopback too: every action on a mission is authenticated and
logged with its origin), as ``Authorization: Bearer`` on ``POST /operate``; it grants the
view right as well, so one link serves the operator. A view token presented to
``/operate`` gets 403, so a shared view link never lets anyone act on the mission.
Without a view token, a request must also name this machine in its ``Host`` header
(127.0.0.1, localhost, [::1] or the bound host; 421 otherwise): a page elsewhere whose
name is rebound to 127.0.0.1 (DNS rebinding) must not read the mission through a local
browser. Of the viewer slots, `OPERATOR_SLOTS` are kept for the operate token.

Cost per request: ``/snapshot`` (the newest) is the SSE payload's bytes, serialised once
per version; ``/info`` is serialised once; ``/snapshot?t=`` replays the log, so it runs
on a thread of the server's own, one at a time (503 meanwhile), never on the loop's
default executor, which the loop needs for its own work (name resolution).
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import hmac
import json
import math
import secrets
from collections.abc import Awaitable, Callable, Mapping
from typing import Final, Protocol

from aiohttp import web

from coral_lang.diagnostics import CoralError
from runtime.eventlog import Event, TelemetryRecord
from runtime.operator import ACTIONS, Operate, OperatorAction
from runtime.watch.page import PAGE
from runtime.watch.source import LogReader
from runtime.watch.state import Snapshot, WatchState, clock_rate, snapshot_at

__all__ = [
    "DEFAULT_HOST",
    "DEFAULT_PORT",
    "LOOPBACK_HOSTS",
    "MAX_VIEWERS",
    "OPERATE_RATE",
    "OPERATE_TIMEOUT",
    "OPERATOR_SLOTS",
    "RIGHTS",
    "Hub",
    "Slot",
    "Source",
    "Watch",
    "WatchError",
    "WatchServer",
    "document",
    "needs_token",
    "new_token",
    "parse_action",
    "static_info",
]

DEFAULT_HOST: Final = "127.0.0.1"
DEFAULT_PORT: Final = 8765
LOOPBACK_HOSTS: Final = frozenset({"127.0.0.1", "::1", "localhost"})
"""The addresses served without a token; any other needs one (see the module)."""

MAX_VIEWERS: Final = 64
"""Live viewers at once; one more gets 503 (each holds a connection and a slot)."""

OPERATOR_SLOTS: Final = 8
"""Of `MAX_VIEWERS`, the slots only a request presenting the operate token may take: on
loopback any local process can view without a token, and must not be able to take every
slot and lock the operator out of their own run (a cap per peer address would not do: on
loopback every local process has the same one)."""

RIGHTS: Final = ("view", "operate")
"""What a token grants: the view token ``view``; the operate token both (see the module)."""

OPERATE_TIMEOUT: Final = 5.0
"""Seconds the run has to answer an operator action before the request gets 504."""

OPERATE_RATE: Final = 10.0
"""Operator requests per second and peer address; more get 429 (a script looping on
``/operate`` must not flood the mission's log)."""

_MAX_BODY: Final = 4096
_MAX_LINE: Final = 4096
"""Bodies and header lines beyond these are refused (413, 400): requests are small."""

_MAX_NAME: Final = 200
_OWN_AUTH: Final = frozenset({"/rights", "/operate"})
"""Routes that check tokens themselves: ``/rights`` answers for any token (it reveals
nothing), ``/operate`` needs the operate token and says 401 or 403."""
_CLIENTS: Final = ("page", "cli", "http")


class WatchError(CoralError):
    """The server cannot start (the address is taken, or not this machine's; the token
    file is another run's): bad usage, exit 2."""


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
        """The next payload to send, waiting for one; None once the slot is closed and
        empty (the last payload put before closing is still given: the final state)."""
        while True:
            payload, self._payload = self._payload, None
            if payload is not None:
                return payload
            if self.closed:
                return None
            await self._ready.wait()
            self._ready.clear()


class Hub:
    """The viewers' slots: publishing is O(viewers) and never waits for any of them.

    ``reserved`` of the ``max_viewers`` slots are kept for operators (`OPERATOR_SLOTS`).
    """

    def __init__(self, max_viewers: int = MAX_VIEWERS, reserved: int = 0) -> None:
        self.max_viewers = max_viewers
        self.reserved = min(max(reserved, 0), max_viewers)
        self._slots: set[Slot] = set()

    @property
    def viewers(self) -> int:
        return len(self._slots)

    def join(self, operator: bool = False) -> Slot | None:
        """A new viewer's slot, or None when the slots it may take are all taken: all
        `max_viewers` for an ``operator``, all but the `reserved` ones for anyone else."""
        limit = self.max_viewers if operator else self.max_viewers - self.reserved
        if len(self._slots) >= limit:
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


class Source(Protocol):
    """What the server serves: a mission's documents, and a way to learn of changes."""

    mission: str

    @property
    def ended(self) -> bool:
        """Whether the mission has ended (nothing more will change)."""

    @property
    def seq(self) -> int:
        """The last event taken in."""

    @property
    def version(self) -> int:
        """Grows with every row taken in: the newest document changes only with it."""

    def document(self, t: float | None = None) -> dict[str, object]:
        """The snapshot (newest, or at ``t``) with the mission, liveness and span. With
        ``t`` it is called on the server's replay thread, one call at a time (it may read
        and replay the whole log)."""

    async def follow(self, publish: Callable[[], None], on_error: Callable[[str], None]) -> None:
        """Call ``publish`` after changes (throttled by the source) until the mission ends."""


def document(
    mission: str, ended: bool, span: tuple[float, float], snapshot: Snapshot
) -> dict[str, object]:
    """What the page receives, from either source: the snapshot and the replay's span."""
    start, end = span
    return {
        "mission": mission,
        "live": not ended,
        "start": start,
        "end": end,
        "snapshot": snapshot.to_json(),
    }


class Watch:
    """A log file's rows read so far, its live state, and its replay: the `Source` of
    ``coral-run watch LOG``, which polls the file every ``poll_interval`` seconds."""

    def __init__(self, reader: LogReader, *, poll_interval: float = 0.5) -> None:
        self.reader = reader
        self.mission = reader.mission
        self.poll_interval = poll_interval
        self.state = WatchState(reader.net_json, clock_rate(reader.meta))
        self.events: list[Event] = []
        self.samples: list[TelemetryRecord] = []

    @property
    def ended(self) -> bool:
        return self.state.end is not None

    @property
    def seq(self) -> int:
        return self.state.seq

    @property
    def version(self) -> int:
        return len(self.events) + len(self.samples)

    def ingest(self, events: list[Event], samples: list[TelemetryRecord]) -> bool:
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
        if t is None:
            snapshot = self.state.snapshot()
        else:
            snapshot = snapshot_at(
                self.reader.net_json, self.events, self.samples, t, self.state.rate
            )
        return document(self.mission, self.ended, self.span(), snapshot)

    async def follow(self, publish: Callable[[], None], on_error: Callable[[str], None]) -> None:
        """Poll the log for new rows until the mission ends; publish each change."""
        while not self.ended:
            await asyncio.sleep(self.poll_interval)
            try:
                events, samples = await asyncio.to_thread(self.reader.read)
            except CoralError as error:  # busy or damaged: say so, try again next time
                on_error(str(error))
                continue
            if self.ingest(events, samples):
                publish()


def _presented(request: web.Request, *, query: bool = True) -> str:
    """The token a request carries: ``Authorization: Bearer`` or (if allowed) ``?token=``."""
    header = request.headers.get("Authorization", "")
    if header.startswith("Bearer "):
        return header[len("Bearer ") :].strip()
    return request.query.get("token", "") if query else ""


def _matches(given: str, token: str | None) -> bool:
    return token is not None and hmac.compare_digest(given.encode(), token.encode())


class _RateLimit:
    """A token bucket per peer address: ``rate`` requests per second, bursts of ``rate``."""

    def __init__(self, rate: float) -> None:
        self.rate = rate
        self._buckets: dict[str, tuple[float, float]] = {}

    def allow(self, peer: str, now: float) -> bool:
        if len(self._buckets) > 1024:  # forget idle peers rather than grow
            self._buckets.clear()
        tokens, last = self._buckets.get(peer, (self.rate, now))
        tokens = min(self.rate, tokens + (now - last) * self.rate)
        if tokens < 1:
            self._buckets[peer] = (tokens, now)
            return False
        self._buckets[peer] = (tokens - 1, now)
        return True


def parse_action(body: bytes, client: str, peer: str) -> OperatorAction:
    """The action a ``POST /operate`` body asks for; `web.HTTPBadRequest` naming the field
    that is wrong otherwise. The body is ``{"action": "give"|"pause"|"resume", "input":
    NAME|null}``; ``input`` is a name for ``give`` and absent or null otherwise."""
    try:
        data = json.loads(body)
    except (ValueError, RecursionError):
        raise web.HTTPBadRequest(text="body: not JSON") from None
    if not isinstance(data, dict):
        raise web.HTTPBadRequest(text='body: expected a JSON object {"action": ..., "input": ...}')
    unknown = sorted(set(data) - {"action", "input"})
    if unknown:
        raise web.HTTPBadRequest(text=f"{str(unknown[0])[:40]}: unknown field")
    action = data.get("action")
    if action not in ACTIONS:
        raise web.HTTPBadRequest(text=f"action: expected one of {', '.join(ACTIONS)}")
    name = data.get("input")
    if action == "give":
        if not isinstance(name, str) or not name or len(name) > _MAX_NAME:
            raise web.HTTPBadRequest(text="input: give needs the name of a declared input")
    elif name is not None:
        raise web.HTTPBadRequest(text=f"input: {action} takes no input (null or absent)")
    return OperatorAction(action, f"{client} {peer}", name)


class WatchServer:
    """The aiohttp application over a `Source`, and the task that follows it.

    ``token`` is the view token (None on loopback, made up when needed); ``operate`` is the
    running controller's, None for a log's server (no operate right at all); its token is
    ``operate_token`` (made up when None).
    """

    def __init__(
        self,
        source: Source,
        *,
        host: str = DEFAULT_HOST,
        port: int = DEFAULT_PORT,
        token: str | None = None,
        operate: Operate | None = None,
        operate_token: str | None = None,
        info: Mapping[str, object] | None = None,
        max_viewers: int = MAX_VIEWERS,
        operate_timeout: float = OPERATE_TIMEOUT,
        operate_rate: float = OPERATE_RATE,
        on_error: Callable[[str], None] = lambda line: None,
    ) -> None:
        self.source = source
        self.host = host
        self.port = port
        self.token = token if token is not None or not needs_token(host) else new_token()
        self.operate = operate
        self.operate_token = None if operate is None else operate_token or new_token()
        self.info = dict(info) if info is not None else {"mission": source.mission}
        # Slots are reserved for operators only where there is an operate token to show.
        self.hub = Hub(max_viewers, 0 if operate is None else min(OPERATOR_SLOTS, max_viewers // 2))
        self.operate_timeout = operate_timeout
        self.on_error = on_error
        self.app = self._make_app()
        self._limit = _RateLimit(operate_rate)
        self._reported: set[str] = set()
        self._payload: tuple[tuple[int, bool], Payload] | None = None
        self._info_body: bytes | None = None
        # ``/snapshot?t=`` replays the log: one at a time, on a thread of its own (the
        # loop's default executor is left to what the loop needs, e.g. getaddrinfo).
        self._replayer: concurrent.futures.ThreadPoolExecutor | None = None
        self._replay: concurrent.futures.Future[bytes] | None = None
        self._runner: web.AppRunner | None = None
        self._follower: asyncio.Task[None] | None = None

    # --- rights -----------------------------------------------------------------------------

    def rights(self, request: web.Request) -> tuple[bool, bool]:
        """(view, operate) for the token ``request`` presents."""
        given = _presented(request)
        operate = _matches(given, self.operate_token)
        return operate or self.token is None or _matches(given, self.token), operate

    def _make_app(self) -> web.Application:
        @web.middleware
        async def guard(
            request: web.Request, handler: Callable[[web.Request], Awaitable[web.StreamResponse]]
        ) -> web.StreamResponse:
            """No route's failure reaches the loop (the engine's, in a live run): 500."""
            try:
                return await handler(request)
            except (web.HTTPException, asyncio.CancelledError):
                raise
            except Exception as error:
                line = f"{request.method} {request.path}: {type(error).__name__}: {error}"
                self._report(line)
                return web.Response(status=500, text=f"watch server error: {line}"[:300])

        @web.middleware
        async def auth(
            request: web.Request, handler: Callable[[web.Request], Awaitable[web.StreamResponse]]
        ) -> web.StreamResponse:
            if self.token is None and not self._host_allowed(request.headers.get("Host")):
                # Served without a token, only this machine may ask: a page elsewhere whose
                # name was rebound to 127.0.0.1 (DNS rebinding) sends its own name as Host.
                raise web.HTTPMisdirectedRequest(
                    text="this watch server answers only requests for 127.0.0.1, localhost, "
                    "[::1] or its own address (Host header)"
                )
            if request.path not in _OWN_AUTH and not self.rights(request)[0]:
                raise web.HTTPUnauthorized(
                    text="this watch server needs its access token (?token= or "
                    "Authorization: Bearer)",
                    headers={"WWW-Authenticate": "Bearer"},
                )
            return await handler(request)

        app = web.Application(
            middlewares=[guard, auth],
            client_max_size=_MAX_BODY,
            handler_args={"max_line_size": _MAX_LINE, "max_field_size": _MAX_LINE},
        )
        app.router.add_get("/", self._page)
        app.router.add_get("/info", self._info)
        app.router.add_get("/snapshot", self._snapshot)
        app.router.add_get("/events", self._events)
        app.router.add_get("/health", self._health)
        app.router.add_get("/rights", self._rights)
        app.router.add_post("/operate", self._operate)
        return app

    def _host_allowed(self, host: str | None) -> bool:
        """Whether a token-less request's ``Host`` names this server: a loopback name or
        the bound host, with no port or the server's."""
        if host is None:
            return False
        host = host.strip().lower()
        name, colon, port = host.rpartition(":")
        if not colon or name.endswith(":") or (host.startswith("[") and not name.endswith("]")):
            name, port = host, ""  # no port (``::1`` unbracketed is not a valid Host)
        elif port != str(self.port):
            return False
        bound = self.host.lower()
        names = {"127.0.0.1", "localhost", "[::1]", f"[{bound}]" if ":" in bound else bound}
        return name in names

    def _report(self, line: str) -> None:
        """Tell ``on_error`` of a failure once (a broken route must not flood the console)."""
        if line not in self._reported and len(self._reported) < 100:
            self._reported.add(line)
            self.on_error(line)

    # --- routes -----------------------------------------------------------------------------

    async def _page(self, request: web.Request) -> web.Response:
        return web.Response(
            text=PAGE,
            content_type="text/html",
            headers={"Content-Security-Policy": "default-src 'self' 'unsafe-inline'"},
        )

    async def _info(self, request: web.Request) -> web.Response:
        """The static data, serialised once (it never changes while serving)."""
        if self._info_body is None:
            self._info_body = json.dumps(self.info).encode()
        return web.Response(body=self._info_body, content_type="application/json")

    def _replay_bytes(self, t: float) -> bytes:
        """The document at ``t``, serialised (in the replay thread, off the loop)."""
        return json.dumps(self.source.document(t), separators=(",", ":")).encode()

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
            # A replay at t reads and replays the log's rows: off the loop (a live run's),
            # one at a time (each may read the whole log), on the replay thread.
            if self._replay is not None and not self._replay.done():
                raise web.HTTPServiceUnavailable(
                    text="a replay is already being computed; try again"
                )
            if self._replayer is None:
                self._replayer = concurrent.futures.ThreadPoolExecutor(
                    max_workers=1, thread_name_prefix="coral-watch-replay"
                )
            self._replay = self._replayer.submit(self._replay_bytes, t)
            body = await asyncio.wrap_future(self._replay)
            return web.Response(body=body, content_type="application/json")
        # The newest: the same bytes as the SSE payload, serialised once per version.
        return web.Response(body=self.payload(), content_type="application/json")

    async def _health(self, request: web.Request) -> web.Response:
        return web.json_response(
            {
                "ok": True,
                "live": not self.source.ended,
                "seq": self.source.seq,
                "viewers": self.hub.viewers,
            }
        )

    async def _rights(self, request: web.Request) -> web.Response:
        view, operate = self.rights(request)
        return web.json_response({"view": view, "operate": operate})

    async def _events(self, request: web.Request) -> web.StreamResponse:
        slot = self.hub.join(operator=self.rights(request)[1])
        if slot is None:
            raise web.HTTPServiceUnavailable(text="too many viewers; try again later")
        response = web.StreamResponse(
            headers={"Content-Type": "text/event-stream", "Cache-Control": "no-cache"}
        )
        try:
            await response.prepare(request)
            slot.put(self._first_payload())
            while (payload := await slot.take()) is not None:
                await response.write(b"data: " + payload + b"\n\n")
        except ConnectionError:  # the viewer went away: nothing to say
            pass
        except Exception as error:
            if not response.prepared:
                raise  # answered 500 by the guard
            self._report(f"GET /events: {type(error).__name__}: {error}")  # stream ends
        finally:
            self.hub.leave(slot)
        return response

    async def _operate(self, request: web.Request) -> web.Response:
        if self.operate is None:
            raise web.HTTPNotFound(
                text="this server watches a log; operate from the run's own --watch server"
            )
        if request.content_length is not None and request.content_length > _MAX_BODY:
            raise web.HTTPRequestEntityTooLarge(
                max_size=_MAX_BODY, actual_size=request.content_length
            )
        given = _presented(request, query=False)
        if not given:
            raise web.HTTPUnauthorized(
                text="operating needs the operate token (Authorization: Bearer)",
                headers={"WWW-Authenticate": "Bearer"},
            )
        if not _matches(given, self.operate_token):
            if _matches(given, self.token):
                raise web.HTTPForbidden(text="this token grants the view right only")
            raise web.HTTPUnauthorized(
                text="wrong operate token", headers={"WWW-Authenticate": "Bearer"}
            )
        peername = request.transport.get_extra_info("peername") if request.transport else None
        host, port = (str(peername[0]), int(peername[1])) if peername else ("?", 0)
        client = request.headers.get("X-Coral-Client", "http")
        if client not in _CLIENTS:
            raise web.HTTPBadRequest(text=f"X-Coral-Client: expected one of {', '.join(_CLIENTS)}")
        peer = f"[{host}]:{port}" if ":" in host else f"{host}:{port}"
        action = parse_action(await request.read(), client, peer)
        # Only actions that would reach the run count: each is logged by the controller.
        if not self._limit.allow(host, asyncio.get_running_loop().time()):
            raise web.HTTPTooManyRequests(text="too many operator requests; slow down")
        try:
            outcome = await asyncio.wait_for(self.operate(action), self.operate_timeout)
        except TimeoutError:
            raise web.HTTPGatewayTimeout(
                text=f"the run did not answer {action.describe()} within "
                f"{self.operate_timeout:g} s; it may still be taken: check the mission's state"
            ) from None
        return web.json_response(outcome.to_json())

    # --- publishing -------------------------------------------------------------------------

    def payload(self) -> Payload:
        """The newest document as one SSE payload (JSON on one line), serialised once per
        version of the source however many viewers join or are published to."""
        version = (self.source.version, self.source.ended)
        if self._payload is None or self._payload[0] != version:
            text = json.dumps(self.source.document(), separators=(",", ":"))
            self._payload = (version, text.encode())
        return self._payload[1]

    def _publish(self) -> None:
        """Give the viewers the newest document: serialised once for all, not at all for
        none."""
        try:
            if self.hub.viewers:
                self.hub.publish(self.payload())
            else:  # nobody got the newest: a viewer joining now must not get an older one
                self._payload = None
        except Exception as error:  # this publication is lost; the next one may do
            self._payload = None
            self._report(f"publishing the state failed: {type(error).__name__}: {error}")

    def _first_payload(self) -> Payload:
        """What a joining viewer gets first: the last document published, if the
        viewers have it (anything newer is published to every slot within the source's
        interval), else the newest. So a crowd joining a busy run costs one
        serialisation, not one each."""
        return self._payload[1] if self._payload is not None else self.payload()

    async def _follow(self) -> None:
        try:
            await self.source.follow(self._publish, self.on_error)
        except Exception as error:  # the stream stops; the server and the run go on
            self._report(f"following the mission failed: {type(error).__name__}: {error}")

    async def start(self) -> str:
        """Listen and start following; the view URL (with the view token, if any).

        Raises OSError when the address cannot be bound."""
        self._runner = web.AppRunner(self.app, access_log=None, shutdown_timeout=0.5)
        await self._runner.setup()
        site = web.TCPSite(self._runner, self.host, self.port)
        try:
            await site.start()
        except BaseException:
            await self._runner.cleanup()
            self._runner = None
            raise
        self.port = int(self._runner.addresses[0][1])
        self._follower = asyncio.create_task(self._follow())
        return self.url

    def _base(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/"

    @property
    def url(self) -> str:
        """The view URL (with the view token when one is needed)."""
        return self._base() + ("" if self.token is None else f"?token={self.token}")

    @property
    def operate_url(self) -> str | None:
        """The page with the operate token (view and operate rights); None without operate."""
        return None if self.operate_token is None else f"{self._base()}?token={self.operate_token}"

    async def stop(self) -> None:
        """Stop following, give every viewer the state as it stands (a run that just
        ended: its end, which the follower may not have published yet), and close; a
        viewer that does not take it within the shutdown timeout (0.5 s) is cut off."""
        if self._follower is not None:
            self._follower.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._follower
            self._follower = None
            self._publish()
        self.hub.close()
        if self._runner is not None:
            await self._runner.cleanup()
            self._runner = None
        replayer, self._replayer = self._replayer, None
        if replayer is not None:  # a replay still running ends on its own; nobody waits
            replayer.shutdown(wait=False, cancel_futures=True)


def static_info(net_json: str | None, meta: Mapping[str, object]) -> dict[str, object]:
    """``GET /info``'s data: `runtime.watch.info.page_info`, or the mission's name alone
    if that cannot be had (the page then draws no net; viewing goes on)."""
    try:
        from runtime.watch.info import page_info  # draws the net: loaded when served

        return dict(page_info(net_json, meta))
    except Exception as error:  # static extras must never stop the server
        return {
            "mission": str(meta.get("mission", "")),
            "error": f"{type(error).__name__}: {error}",
        }


def new_token() -> str:
    """A fresh access token (256 random bits, URL-safe)."""
    return secrets.token_urlsafe(32)
