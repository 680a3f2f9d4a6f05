"""The watch server inside a running ``coral-run`` (``--watch [HOST:]PORT``), with the
operate right.

The same `WatchServer` as ``coral-run watch LOG`` (routes, tokens, one slot per viewer),
over a `LiveFeed` of the controller's own event log instead of a polled file, and with the
controller's ``operate`` so ``POST /operate`` can give an input, pause or resume. It runs
in the controller's event loop: nothing here may block or raise into it (every route's
failure is answered 500 and reported once), and a stalled viewer costs one slot.

The operate token is printed once and written to a token file (mode 0600, created with
``O_EXCL``) so ``coral-run operate`` on the same machine finds it without the console.
While the run serves, the file is held with an advisory lock (``flock``): a second run
in the same directory is refused by name, and a file left behind by a run killed with
``kill -9`` (nobody holds its lock) is taken over by the next one, e.g. ``--resume``. The
file is removed when the server stops.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import fcntl
import os
import stat
from collections.abc import AsyncIterator, Callable, Mapping
from pathlib import Path
from typing import Final

from runtime.operator import Operate
from runtime.watch.feed import LiveFeed
from runtime.watch.server import Watch, WatchError, WatchServer, document
from runtime.watch.source import LogReader
from runtime.watch.state import snapshot_at

__all__ = ["PUBLISH_SHARE", "LiveWatch", "TokenFile", "serve_live"]

PUBLISH_SHARE: Final = 50
"""Publishing waits at least this many times what the last publication took."""


class LiveWatch:
    """A `LiveFeed` as the server's `Source`: documents, and publication at most every
    ``feed.interval`` seconds (at once after a quiet spell, and at mission-end).

    The state at a past time (``/snapshot?t=``) is read from the run's log file, as
    ``coral-run watch`` reads it, for that request only: a `LogReader` opened, read whole,
    replayed up to t and closed (the server calls it off the loop, one at a time). Nothing
    of it is kept between requests: a long run's rows would otherwise stay in memory for
    the rest of the run after one scrub. It holds the committed rows: the few the run has
    not committed yet are not there.
    """

    def __init__(self, feed: LiveFeed) -> None:
        self.feed = feed
        self.mission = feed.mission

    @property
    def ended(self) -> bool:
        return self.feed.ended

    @property
    def seq(self) -> int:
        return self.feed.state.seq

    @property
    def version(self) -> int:
        return self.feed.version

    def document(self, t: float | None = None) -> dict[str, object]:
        if t is None:
            snapshot = self.feed.snapshot()
        else:
            history = Watch(LogReader(self.feed.path))
            try:
                history.poll()
                snapshot = snapshot_at(
                    self.feed.net_json, history.events, history.samples, t, history.state.rate
                )
            finally:
                history.reader.close()
        doc = document(self.mission, self.ended, self.feed.span(), snapshot)
        if self.feed.broken is not None:
            doc["broken"] = self.feed.broken
        return doc

    def close(self) -> None:
        """Nothing to release: the log is read per ``?t=`` request and closed at once."""

    async def follow(self, publish: Callable[[], None], on_error: Callable[[str], None]) -> None:
        """Publish each change, at most every ``feed.interval`` seconds, and no more often
        than keeps publishing (snapshot and serialisation, in the run's loop) under
        1/`PUBLISH_SHARE` of the loop's time: a big net's snapshot is published less
        often rather than slowing the engine."""
        loop = asyncio.get_running_loop()
        version = -1  # publish what is there at once, then each change
        while True:
            version = await self.feed.changed(version)
            started = loop.time()
            publish()
            if self.feed.ended:  # the final state is out: nothing more will change
                return
            cost = loop.time() - started
            await asyncio.sleep(max(self.feed.interval, cost * PUBLISH_SHARE))


class TokenFile:
    """The operate token in a file only its owner reads, held (``flock``) while serving."""

    def __init__(self, path: Path, token: str) -> None:
        self.path = path
        self._fd = self._claim(path)
        data = f"{token}\n".encode()
        try:
            # Write first, then cut to length: a reader (`coral-run operate`) of a stale
            # file being taken over never sees it empty (truncating first would open that
            # window). Tokens all have one length, so it sees the old token or the new one.
            written = os.pwrite(self._fd, data, 0)
            if written != len(data):
                raise OSError(0, "short write")
            os.ftruncate(self._fd, len(data))
        except OSError as error:
            self.close()
            raise WatchError(f"{path}: cannot write the operate token: {error.strerror}") from None

    @staticmethod
    def _claim(path: Path) -> int:
        # O_NONBLOCK: opening a FIFO for writing would otherwise wait for a reader (for
        # ever, hanging the run's start), and a device could do anything; the file's type
        # is checked before anything else is done with it.
        flags = os.O_WRONLY | os.O_NOFOLLOW | os.O_CLOEXEC | os.O_NONBLOCK
        try:
            fd = os.open(path, flags | os.O_CREAT | os.O_EXCL, 0o600)
        except FileExistsError:
            fd = -1
        except OSError as error:
            raise WatchError(f"{path}: cannot create the token file: {error.strerror}") from None
        if fd < 0:  # there already: a live run's (held) or a dead run's (free, ours)
            try:
                fd = os.open(path, flags)
            except OSError as error:
                if error.errno == errno.ENXIO:  # a FIFO nobody reads: not a token file
                    raise WatchError(
                        f"{path}: exists and is not a token file of this user's runs"
                    ) from None
                raise WatchError(
                    f"{path}: a token file is there and cannot be opened ({error.strerror}); "
                    "is another run serving from this directory?"
                ) from None
            info = os.fstat(fd)
            if not stat.S_ISREG(info.st_mode) or info.st_uid != os.getuid():
                os.close(fd)
                raise WatchError(f"{path}: exists and is not a token file of this user's runs")
            os.fchmod(fd, 0o600)
        os.set_blocking(fd, True)  # a regular file: back to plain writes
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            raise WatchError(
                f"{path}: another run is serving this mission's watch page (it holds the "
                "token file); give this run another --out directory"
            ) from None
        return fd

    def close(self) -> None:
        """Remove the file (if it is still the one written) and release it."""
        fd, self._fd = self._fd, -1
        if fd < 0:
            return
        with contextlib.suppress(OSError):
            if os.path.samestat(os.fstat(fd), os.stat(self.path, follow_symlinks=False)):
                os.unlink(self.path)
        os.close(fd)


@contextlib.asynccontextmanager
async def serve_live(
    feed: LiveFeed,
    *,
    host: str,
    port: int,
    operate: Operate | None,
    token_file: Path | None,
    console: Callable[[str], None],
    info: Mapping[str, object],
) -> AsyncIterator[str]:
    """Serve ``feed`` on ``host:port`` while the body runs; yields the view URL.

    Prints the view URL and the operate URL once through ``console``, writes the operate
    token to ``token_file`` when given (see the module) and removes it on exit. Raises
    `WatchError` (exit 2) when the address cannot be bound or the token file belongs to
    another run.
    """
    source = LiveWatch(feed)
    server = WatchServer(
        source,
        host=host,
        port=port,
        operate=operate,
        info=info,
        on_error=lambda line: console(f"watch: {line}"),
    )
    held: TokenFile | None = None
    try:
        if token_file is not None and server.operate_token is not None:
            held = TokenFile(token_file, server.operate_token)
        try:
            url = await server.start()
        except OSError as error:
            raise WatchError(f"cannot listen on {host}:{port}: {error.strerror or error}") from None
        view = " (the URL holds the view token)" if server.token is not None else ""
        console(f"watch: view the mission at {url}{view}")
        if server.operate_url is not None:
            where = f"; the token is also in {token_file} (mode 0600)" if held else ""
            console(
                f"watch: operate it at {server.operate_url} (shown once: this token can "
                f"pause, resume and give inputs{where})"
            )
        yield url
    finally:
        await server.stop()
        source.close()
        if held is not None:
            held.close()
