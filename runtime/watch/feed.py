"""The state of a running mission, fed by its own event log as the engine writes it.

`coral-run MISSION --watch` serves the page from inside the run: no polling of the file,
every row reaches the state the moment it is logged (`EventLog.add_listener`). The
listener runs in the engine's path, so it does the least that keeps the state right: one
`WatchState.advance` on one row and a version bump, both O(1). The rows logged before
the feed is attached are taken in first (the listener's ``replay``), so a feed made after
`Controller.start_new` or on a resumed run is whole.

Serialising snapshots for viewers is the server's business, throttled: `changed` wakes its
waiter at most once per burst (one thread-safe wake-up, then nothing until the
waiter has looked), and the server waits `interval` between publications, so 1,000 events
in a burst cost the engine 1,000 small calls and the server a few snapshots per second,
plus one at mission-end.

Why the feed keeps no rows: the log is the mission's record, already on disk, so a page
scrubbing back in time (``/snapshot?t=``) reads it (`runtime.watch.live.LiveWatch`, off the
loop, only when asked); keeping every row here would cost the run memory, and collector
time, for a feature most runs never use.
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Final

from runtime.eventlog import Event, EventLog
from runtime.telemetry import TelemetryRecord
from runtime.watch.state import Snapshot, WatchState, clock_rate

__all__ = ["PUBLISH_INTERVAL", "LiveFeed"]

PUBLISH_INTERVAL: Final = 0.5
"""Seconds between two publications to viewers at most (mission-end comes at once)."""


class LiveFeed:
    """A running mission's `WatchState`, advanced by a listener on its `EventLog`.

    Rows may be logged from any thread (the listener takes a small lock); `changed` and
    the snapshots are for the event loop that serves the viewers.
    """

    def __init__(
        self, log: EventLog, net_json: str | None, *, interval: float = PUBLISH_INTERVAL
    ) -> None:
        self.mission = log.mission
        self.path: Path = log.path
        self.net_json = net_json
        self.meta = dict(log.meta)
        self.interval = interval
        self.state = WatchState(net_json, clock_rate(self.meta))
        self.version = 0
        self.first_time: float | None = None
        """The first event's time: where the replay's span starts."""
        self.closed = False
        self.broken: str | None = None
        """Why the feed stopped hearing the log (its listener raised and was dropped), or
        None: the state is then frozen, and the page must say so rather than show LIVE."""
        self._lock = threading.Lock()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._wake: asyncio.Event | None = None
        self._wake_sent = False
        # replay: the rows logged before the feed was attached (mission-start, a resumed
        # run's history) come first, so the state is the whole mission's.
        self._remove: Callable[[], None] | None = log.add_listener(
            self._on_row, replay=True, on_drop=self._on_drop
        )

    # --- the engine's side (keep it tiny) ---------------------------------------------------

    def _on_row(self, row: Event | TelemetryRecord) -> None:
        with self._lock:
            if isinstance(row, Event):
                if self.first_time is None:
                    self.first_time = row.time
                self.state.advance((row,))
            else:
                self.state.advance(samples=(row,))
            self.version += 1
            if self._wake_sent or self._loop is None:
                return
            self._wake_sent = True
        self._signal()

    def _on_drop(self, error: BaseException) -> None:
        """The log dropped our listener (it raised): mark the feed broken and wake the
        server once, so viewers get a last document saying the live view is lost."""
        with self._lock:
            self.broken = f"{type(error).__name__}: {error}"[:300]
            self.version += 1
            self._remove = None  # already removed by the log
            if self._loop is None:
                return
            self._wake_sent = True
        self._signal()

    def _signal(self) -> None:
        loop, wake = self._loop, self._wake
        if loop is None or wake is None or loop.is_closed():
            return
        try:
            running = asyncio.get_running_loop()
        except RuntimeError:
            running = None
        if running is loop:
            wake.set()
        else:  # logged from a worker thread: wake the loop safely
            with contextlib.suppress(RuntimeError):
                loop.call_soon_threadsafe(wake.set)

    # --- the server's side ------------------------------------------------------------------

    @property
    def ended(self) -> bool:
        """Whether nothing more will change: the mission-end event was logged, the feed
        was closed, or it broke (`broken`)."""
        return self.closed or self.broken is not None or self.state.end is not None

    def snapshot(self) -> Snapshot:
        """The state now, as a value the caller may keep."""
        with self._lock:
            return self.state.snapshot()

    def span(self) -> tuple[float, float]:
        """First event's time to the newest's: the range the page can scrub."""
        with self._lock:
            if self.first_time is None:
                return 0.0, 0.0
            return self.first_time, self.state.time

    async def changed(self, after: int) -> int:
        """Wait until `version` is above ``after`` (or the feed is closed); the version."""
        if self._wake is None:
            self._loop = asyncio.get_running_loop()
            self._wake = asyncio.Event()
        while True:
            with self._lock:
                if self.version > after or self.closed or self.broken is not None:
                    self._wake_sent = False
                    self._wake.clear()
                    return self.version
                self._wake_sent = False
                self._wake.clear()
            await self._wake.wait()

    def close(self) -> None:
        """Stop listening to the log and release `changed`'s waiter."""
        remove, self._remove = self._remove, None
        if remove is not None:
            remove()
        with self._lock:
            self.closed = True
        if self._wake is not None:
            self._signal()
