"""The live terminal view (``--tui``): the watch page's snapshot, drawn in the terminal.

For an operator on a ship reaching the controller over SSH, where a browser is not at hand:
the same `runtime.watch.state.Snapshot` the page shows (``Snapshot.to_json()``), as a
header (mission, time, live, paused or ended and how), the last telemetry and its age, link
health, the last operator actions, the marking and the command status lines.

Why ``rich``: a well-kept library whose `rich.live.Live` redraws a block in place with
plain ANSI cursor moves (no curses, no terminfo database, so it works in any SSH session
and in tmux), and whose `Console` knows when its output is not a terminal.

Design choices:

* **No alternate screen** (``Live(screen=False)``): the block is redrawn below the run's own
  lines, and anything the run prints meanwhile (its progress and warnings, on stdout or
  stderr) is written *above* the block by rich's redirection, so the scrollback keeps the
  run's console lines and the last frame stays on screen when the view ends.
* **Redraw only on change**: a frame is drawn when the snapshot's ``seq`` or ``time`` (or
  its paused or ended state) changed, and otherwise once a second so the time-out
  countdowns and the telemetry's age move on. A frame is small whatever the mission's
  length (at most `MAX_COMMANDS` command lines, those still out first, then the newest, and
  `MAX_PLACES` places, each list ending in "... N more"; fewer commands on a short
  terminal) and its tables are laid out by hand (`_grid`), so drawing one takes a few
  milliseconds and never holds the event loop (or the engine beside it) for long.
* **Not a terminal** (``--tui`` with its output in a file or a pipe): no escape codes; one
  plain summary line when the snapshot changed, at most once a second, and the last state
  when the view ends.
* **Only reads the snapshot**, with ``.get`` and defaults throughout: the fields the engine
  adds when it knows them (``enabled``, ``paused``, a command's ``awaiting`` and
  ``timeout_at``, ``operator``...) are shown when present, and a log written before them
  still renders.

Place kinds are not in the snapshot; pending and armed places are told by their names
(``T.pending``: a command of ``T`` in flight; ``NAME.armed``: input ``NAME`` not given).

Times are shown from the log's start, as on the page: the mapping's ``start`` when the
caller adds it (the page's documents have it), else the first snapshot holding an event.

Between two events the controller's time is not in the snapshot; the countdowns use the
caller's ``clock`` when it has one (in-process), else the snapshot's time moved on at
``rate`` times real time since it last changed (1 for a real-time run; 0 for a log written
in virtual time, whose clock only moves with its events).
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import sys
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Final

from rich.console import Console, Group, RenderableType
from rich.live import Live
from rich.text import Text

from coral_lang.diagnostics import CoralError
from runtime.eventlog import EventLogError
from runtime.watch.source import LogReader
from runtime.watch.state import WatchState, clock_rate

__all__ = [
    "MAX_COMMANDS",
    "MAX_OPERATOR",
    "MAX_PLACES",
    "TerminalView",
    "render",
    "run_terminal_view",
    "summary_line",
    "watch_log_tui",
]

MAX_COMMANDS: Final = 30
"""Command status lines in a frame (commands still out first, then the newest)."""

MAX_PLACES: Final = 20
"""Marked places in a frame."""

MAX_OPERATOR: Final = 5
"""Latest operator actions in a frame."""

REDRAW_EVERY: Final = 1.0
"""Seconds between frames when nothing changed (countdowns), and between plain lines."""

Snapshotter = Callable[[], Mapping[str, object]]


# --- reading a snapshot defensively --------------------------------------------------------


def _num(value: object) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    try:
        number = float(value)
    except OverflowError:  # an integer beyond any float: not a time or a count we show
        return None
    return number if math.isfinite(number) else None


def _map(value: object) -> Mapping[str, object]:
    return value if isinstance(value, Mapping) else {}


def _seq(value: object) -> Sequence[object]:
    return value if isinstance(value, list | tuple) else ()


def _fmt(value: object) -> str:
    """A snapshot value as an operator reads it: numbers short, anything else as text."""
    if isinstance(value, bool):
        return "yes" if value else "no"
    number = _num(value)
    if number is not None:
        if abs(number) >= 1e9:
            return f"{number:.3g}"
        return str(int(number)) if number.is_integer() else f"{number:.2f}"
    if value is None:
        return "-"
    return str(value)


def _printable(text: str) -> str:
    """``text`` with every control character (escape, newline...) as "?": names and
    messages come from a log, and a log is data, never terminal commands (rich itself
    passes ESC through)."""
    if text.isprintable():
        return text
    return "".join(ch if ch.isprintable() else "?" for ch in text)


def _labelled(label: str, text: str) -> Text:
    return Text.assemble((f"{label:<11}", "bold"), _printable(text))


def _clip(text: str, width: int) -> str:
    return text if len(text) <= width else text[: width - 1] + "…"


def _place_note(place: str) -> str:
    if place.endswith(".pending"):
        return f"command in flight ({place.removesuffix('.pending')})"
    if place.endswith(".armed"):
        return f"input {place.removesuffix('.armed')} not given yet"
    return ""


def _state_word(snap: Mapping[str, object], origin: float = 0.0) -> str:
    """LIVE, PAUSED or how it ended: ``ENDED final at 166.6 s``."""
    end = snap.get("end")
    if isinstance(end, Mapping):
        how = _fmt(end.get("end", "?"))
        at = _num(end.get("time"))
        word = f"ENDED {how}" + (f" at {at - origin:.1f} s" if at is not None else "")
        extra = []
        if end.get("stopped_by"):
            extra.append(f"by {_fmt(end.get('stopped_by'))}")
        if "made_safe" in end:
            extra.append("made safe" if end.get("made_safe") else "NOT made safe")
        return word + (f" ({', '.join(extra)})" if extra else "")
    return "PAUSED" if snap.get("paused") is True else "LIVE"


def _out(command: Mapping[str, object]) -> bool:
    """Whether a command may still get a reply: its ``awaiting`` kinds when the snapshot
    has them, else whether nothing came back yet."""
    if "awaiting" in command:
        return bool(_seq(command.get("awaiting")))
    return not _seq(command.get("replies"))


def _countdown(command: Mapping[str, object], now: float) -> str:
    if not _out(command):
        return ""
    timeout_at = _num(command.get("timeout_at"))
    if timeout_at is None:
        return "none" if "timeout_at" in command else ""
    left = timeout_at - now
    return f"in {left:.0f} s" if left > 0 else "due"


def _describe(command: Mapping[str, object]) -> str:
    params = _map(command.get("params"))
    inner = ", ".join(f"{key}={_fmt(value)}" for key, value in params.items())
    return _clip(f"{_fmt(command.get('name', '?'))}({inner})", 40)


def _ordered(commands: Sequence[object]) -> list[Mapping[str, object]]:
    """Commands still out first, then the newest: what an operator looks for."""
    rows = [c for c in commands if isinstance(c, Mapping)]
    rows.sort(key=lambda c: (not _out(c), -(_num(c.get("command_id")) or 0.0)))
    return rows


def _telemetry_text(snap: Mapping[str, object], now: float) -> str:
    sample = snap.get("telemetry")
    if not isinstance(sample, Mapping):
        return "no telemetry yet"
    parts = []
    for label, key, unit, digits in (
        ("x", "x", " m", 2),
        ("y", "y", " m", 2),
        ("depth", "depth", " m", 2),
        ("heading", "heading", "°", 1),
    ):
        value = _num(sample.get(key))
        parts.append(f"{label} {'-' if value is None else f'{value:.{digits}f}'}{unit}")
    at = _num(sample.get("time"))
    if at is not None:
        parts.append(f"({max(0.0, now - at):.1f} s old)")
    return "  ".join(parts)


def _link_text(snap: Mapping[str, object]) -> str:
    link = _map(snap.get("link"))
    if not link:
        return "-"
    parts = []
    for key, value in link.items():
        seconds = key in _SECONDS and _num(value) is not None
        parts.append(f"{key.replace('_', ' ')} {_fmt(value)}{' s' if seconds else ''}")
    return "  ".join(parts)


_SECONDS: Final = frozenset({"round_trip", "reply_after", "outage_seconds"})
"""Link figures that are durations (the others are counts or flags)."""


def _names(value: object, limit: int = 10) -> str:
    names = [str(name) for name in _seq(value)]
    more = f" ... {len(names) - limit} more" if len(names) > limit else ""
    return ", ".join(names[:limit]) + more


def _marked(snap: Mapping[str, object]) -> list[tuple[str, int]]:
    marking = _map(snap.get("marking"))
    marked = []
    for place, tokens in marking.items():
        number = _num(tokens)
        if number:
            marked.append((str(place), int(number)))
    return marked


# --- a frame -------------------------------------------------------------------------------


def _origin(snap: Mapping[str, object], origin: float | None) -> float:
    """Where shown times count from: ``origin``, else the snapshot's ``start``, else 0."""
    if origin is not None:
        return origin
    return _num(snap.get("start")) or 0.0


def render(
    snap: Mapping[str, object],
    *,
    mission: str = "",
    now: float | None = None,
    origin: float | None = None,
    max_commands: int = MAX_COMMANDS,
    width: int = 100,
) -> RenderableType:
    """One frame of the view for a snapshot (``Snapshot.to_json()``); ``now`` is the
    controller's time for countdowns and ages (default: the snapshot's time). Times are
    shown from ``origin`` (default: the mapping's ``start``, as the page does)."""
    at = _num(snap.get("time")) or 0.0
    now = at if now is None else now
    origin = _origin(snap, origin)
    name = mission or _fmt(snap.get("mission", "mission"))
    header = Text()
    header.append(_printable(name), style="bold")
    header.append(f"  t {now - origin:.1f} s  seq {_fmt(snap.get('seq', 0))}  ")
    word = _state_word(snap, origin)
    style = "bold green" if word == "LIVE" else "bold yellow" if word == "PAUSED" else "bold"
    header.append(_printable(word), style=style)
    unknown = _num(snap.get("unknown_firings"))
    if unknown:
        header.append(f"  ({unknown:.0f} firings of unknown transitions)", style="red")

    parts: list[RenderableType] = [header]
    parts.append(_labelled("telemetry", _telemetry_text(snap, now)))
    parts.append(_labelled("link", _link_text(snap)))
    for key, label in (("enabled", "enabled"), ("offered", "inputs")):
        if _seq(snap.get(key)):
            parts.append(_labelled(label, _names(snap.get(key))))
    operator = [a for a in _seq(snap.get("operator")) if isinstance(a, Mapping)]
    for action in operator[-MAX_OPERATOR:]:
        parts.append(_labelled("operator", _operator_text(action, origin)))

    parts.append(_marking_table(snap, width))
    parts.append(_commands_table(snap, now, origin, max_commands, width))
    return Group(*parts)


def _operator_text(action: Mapping[str, object], origin: float) -> str:
    what = _fmt(action.get("action", "?"))
    if action.get("input"):
        what += f" {_fmt(action.get('input'))}"
    verdict = "accepted" if action.get("accepted") is True else "refused"
    at = _num(action.get("time"))
    when = f"{at - origin:.1f} s " if at is not None else ""
    message = _fmt(action.get("message", ""))
    return f"{when}{what} from {_fmt(action.get('origin', '?'))}: {verdict}; {message}"


Cell = tuple[str, str]
"""A table cell: its text and its rich style ("" for none)."""


def _grid(
    title: str,
    header: Sequence[str],
    rows: Sequence[Sequence[Cell]],
    *,
    right: frozenset[int],
    shrink: Sequence[int],
    width: int,
) -> Text:
    """A table as one `Text`: a title, a header and one line per row, columns padded by
    hand. Why not `rich.table.Table`: it measures and wraps every cell on every frame, ten
    times the cost of this for the same lines; here no cell wraps (the ``shrink`` columns,
    in that order, are cut with an ellipsis to fit ``width``), so a frame's height is its
    row count."""
    widths = [len(name) for name in header]
    for row in rows:
        for i, (cell, _) in enumerate(row):
            widths[i] = max(widths[i], len(cell))
    excess = sum(widths) + 2 * (len(widths) - 1) - width
    for i in shrink:
        if excess <= 0:
            break
        cut = min(excess, max(0, widths[i] - 8))
        widths[i] -= cut
        excess -= cut
    text = Text(no_wrap=True, overflow="crop")
    text.append(title, style="bold italic")
    text.append("\n")

    def line(cells: Sequence[Cell], bold: bool) -> None:
        for i, (cell, style) in enumerate(cells):
            shown = _clip(cell, widths[i]) if widths[i] else ""
            shown = shown.rjust(widths[i]) if i in right else shown.ljust(widths[i])
            text.append(_printable(shown), style="bold" if bold else style)
            text.append("  " if i < len(cells) - 1 else "\n")

    line([(name, "") for name in header], True)
    for row in rows:
        line(row, False)
    text.rstrip()
    return text


def _marking_table(snap: Mapping[str, object], width: int) -> Text:
    marked = _marked(snap)
    rows: list[list[Cell]] = [
        [(place, ""), (str(tokens), ""), (_place_note(place), "cyan")]
        for place, tokens in marked[:MAX_PLACES]
    ]
    if len(marked) > MAX_PLACES:
        rows.append([(f"... {len(marked) - MAX_PLACES} more", ""), ("", ""), ("", "")])
    if not marked:
        rows.append([("(no token)", ""), ("", ""), ("", "")])
    header = ("place", "tokens", "")
    return _grid("marking", header, rows, right=frozenset({1}), shrink=(2, 0), width=width)


def _reply_text(command: Mapping[str, object], origin: float) -> str:
    """The last reply's kind and time (from the log's start); the ``status`` line when the
    replies are not listed."""
    replies = [r for r in _seq(command.get("replies")) if isinstance(r, Mapping)]
    if not replies:
        return "" if _out(command) else _fmt(command.get("status", ""))
    last = replies[-1]
    at = _num(last.get("time"))
    return f"{_fmt(last.get('kind', '?'))}" + (f" at {at - origin:.1f} s" if at is not None else "")


def _commands_table(
    snap: Mapping[str, object], now: float, origin: float, limit: int, width: int
) -> Text:
    commands = _ordered(_seq(snap.get("commands")))
    rows: list[list[Cell]] = []
    for command in commands[:limit]:
        out = _out(command)
        sent = _num(command.get("sent_at"))
        sends = _num(command.get("sends")) or 1
        sent_text = "-" if sent is None else f"{sent - origin:.1f} s"
        if sends > 1:
            sent_text += f" (x{sends:.0f})"
        if "awaiting" in command:
            awaiting = ", ".join(str(kind) for kind in _seq(command.get("awaiting")))
        else:
            awaiting = "reply" if out else ""
        flag = "yellow" if out else ""
        # After the end, a command still out waits for nothing: no countdown.
        countdown = "" if snap.get("end") is not None else _countdown(command, now)
        rows.append(
            [
                (_fmt(command.get("command_id")), ""),
                (_describe(command), ""),
                (sent_text, ""),
                (_clip(awaiting, 24), flag),
                (countdown, flag),
                (_reply_text(command, origin), ""),
            ]
        )
    total = _num(snap.get("commands_total"))
    hidden = max(len(commands), int(total or 0)) - min(limit, len(commands))
    if hidden > 0:
        rows.append([("", ""), (f"... {hidden} more", ""), *[("", "")] * 4])
    if not commands:
        rows.append([("", ""), ("(none sent yet)", ""), *[("", "")] * 4])
    # The command and its reply give way first when the terminal is narrow.
    header = ("id", "command", "sent", "awaiting", "time-out", "reply")
    right = frozenset({0, 2, 4})
    return _grid("commands", header, rows, right=right, shrink=(1, 5, 3), width=width)


def summary_line(
    snap: Mapping[str, object],
    *,
    mission: str = "",
    now: float | None = None,
    origin: float | None = None,
) -> str:
    """The snapshot on one plain line (no escape codes): for output that is not a terminal."""
    at = _num(snap.get("time")) or 0.0
    now = at if now is None else now
    origin = _origin(snap, origin)
    name = mission or _fmt(snap.get("mission", "mission"))
    marked = _marked(snap)
    marking = " ".join(f"{place}={tokens}" for place, tokens in marked[:8])
    if len(marked) > 8:
        marking += f" ... {len(marked) - 8} more"
    commands = [c for c in _seq(snap.get("commands")) if isinstance(c, Mapping)]
    out = sum(_out(c) for c in commands)
    total = max(len(commands), int(_num(snap.get("commands_total")) or 0))
    line = (
        f"{name} t {now - origin:.1f} s {_state_word(snap, origin)}"
        f" | marking {marking or '(no token)'}"
        f" | commands {total} ({out} out) | {_telemetry_text(snap, now)}"
        f" | link {_link_text(snap)}"
    )
    return _printable(" ".join(line.split()))  # one line whatever the names hold


# --- the view ------------------------------------------------------------------------------


class TerminalView:
    """Decides when to draw and draws: `tick` is called with the wall time (monotonic
    seconds) every refresh; the tests drive it with virtual times."""

    def __init__(
        self,
        snapshot: Snapshotter,
        console: Console,
        *,
        mission: str = "",
        clock: Callable[[], float] | None = None,
        rate: float = 1.0,
    ) -> None:
        self.snapshot = snapshot
        self.console = console
        self.mission = mission
        self.clock = clock
        self.rate = rate
        self.terminal = console.is_terminal
        self.frames = 0
        """Frames drawn (terminal) or lines printed (not a terminal)."""
        self._live: Live | None = None
        self._key: tuple[object, ...] | None = None
        self._drawn_at = -math.inf
        self._changed_at = 0.0
        self._printed: str | None = None
        self._origin: float | None = None

    def start(self) -> None:
        if self.terminal:
            self._live = Live(
                Text(""),
                console=self.console,
                auto_refresh=False,
                transient=False,
                screen=False,
                redirect_stdout=True,
                redirect_stderr=True,
                vertical_overflow="ellipsis",
            )
            self._live.start()

    def now(self, snap: Mapping[str, object], wall: float) -> float:
        """The controller's time for countdowns (see the module)."""
        if self.clock is not None:
            return self.clock()
        at = _num(snap.get("time")) or 0.0
        if snap.get("end") is not None:
            return at
        return at + max(0.0, wall - self._changed_at) * self.rate

    def origin(self, snap: Mapping[str, object]) -> float:
        """Where shown times count from: the snapshot's ``start`` (the log's first event,
        as on the page) when the caller put it there; else the earliest time of the first
        snapshot that holds an event, kept from then on."""
        start = _num(snap.get("start"))
        if start is not None:
            return start
        if self._origin is None and (_num(snap.get("seq")) or 0) > 0:
            times = [_num(snap.get("time"))]
            times += [_num(_map(c).get("sent_at")) for c in _seq(snap.get("commands"))]
            self._origin = min((t for t in times if t is not None), default=0.0)
        return self._origin or 0.0

    def tick(self, wall: float, *, force: bool = False) -> bool:
        """Draw if the snapshot changed or a second went by (or ``force``); whether it drew."""
        snap = self.snapshot()
        key = (snap.get("seq"), snap.get("time"), snap.get("paused"), snap.get("end") is None)
        changed = key != self._key
        if changed:
            self._key = key
            self._changed_at = wall
        now = self.now(snap, wall)
        origin = self.origin(snap)
        if self.terminal:
            if not (changed or force or wall - self._drawn_at >= REDRAW_EVERY):
                return False
            self._draw(snap, now, origin)
        else:
            # The log's own time, not an estimate: a line says what the log holds.
            line = summary_line(snap, mission=self.mission, origin=origin)
            if line == self._printed or not (force or wall - self._drawn_at >= REDRAW_EVERY):
                return False
            self.console.print(Text(line), soft_wrap=True, highlight=False)
            self._printed = line
        self._drawn_at = wall
        self.frames += 1
        return True

    def _draw(self, snap: Mapping[str, object], now: float, origin: float) -> None:
        height = self.console.size.height
        fixed = 12 + min(MAX_PLACES, max(1, len(_marked(snap)))) + len(_seq(snap.get("operator")))
        limit = max(3, min(MAX_COMMANDS, height - fixed))
        frame = render(
            snap,
            mission=self.mission,
            now=now,
            origin=origin,
            max_commands=limit,
            width=self.console.width,
        )
        if self._live is not None:
            self._live.update(frame, refresh=True)
        else:
            self.console.print(frame)

    def stop(self, wall: float) -> None:
        """Draw the last state (once more if it changed) and leave it on the screen."""
        try:
            self.tick(wall, force=True)
        finally:
            if self._live is not None:
                self._live.stop()
                self._live = None


async def run_terminal_view(
    snapshot: Snapshotter,
    *,
    stop: asyncio.Event,
    refresh: float = 0.25,
    console: Console | None = None,
    mission: str = "",
    clock: Callable[[], float] | None = None,
    rate: float = 1.0,
) -> None:
    """Show ``snapshot()`` (a ``Snapshot.to_json()`` mapping) until ``stop`` is set, then
    draw the last state and return. Looks at the snapshot every ``refresh`` seconds and
    draws only when it changed, or once a second (see `TerminalView`). ``mission`` names
    the header (else the snapshot's ``mission``); ``clock`` gives the controller's time
    for the countdowns, else the snapshot's time moves on at ``rate`` (see the module)."""
    view = TerminalView(snapshot, console or Console(), mission=mission, clock=clock, rate=rate)
    loop = asyncio.get_running_loop()
    view.start()
    try:
        while not stop.is_set():
            view.tick(loop.time())
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(stop.wait(), refresh)
    except Exception as error:  # the view is a viewer: it never takes the run down
        print(f"terminal view stopped: {type(error).__name__}: {error}", file=sys.stderr)
        await stop.wait()
        return
    finally:
        with contextlib.suppress(Exception):
            view.stop(loop.time())


# --- coral-run watch LOG --tui ----------------------------------------------------------------


def watch_log_tui(log: Path, *, poll_interval: float = 0.5, console: Console | None = None) -> int:
    """Follow a controller log in the terminal until its ``mission-end`` (the last frame
    stays) or Ctrl-C; exit 0. A bad log raises `EventLogError` (a `CoralError`: exit 2)
    before anything is drawn."""
    reader = LogReader(log)
    try:
        state = WatchState(reader.net_json, clock_rate(reader.meta))
        events, samples = reader.read()
        state.advance(events, samples)
        start = events[0].time if events else None
        meta = reader.meta
        # A real-time run's controller clock is the wall clock (``--speed`` scales only
        # the simulator's); a virtual-time one moves only with its events.
        rate = 1.0 if meta.get("realtime") is True else 0.0
        asyncio.run(_follow(reader, state, start, poll_interval, console or Console(), rate))
    except KeyboardInterrupt:
        print("coral-run watch: stopped", file=sys.stderr)
    finally:
        reader.close()
    return 0


async def _follow(
    reader: LogReader,
    state: WatchState,
    start: float | None,
    poll_interval: float,
    console: Console,
    rate: float,
) -> None:
    def document() -> dict[str, object]:
        # Built once per change, not per frame; ``start`` as the page has it.
        return {**state.snapshot().to_json(), "start": start}

    current = document()
    stop = asyncio.Event()
    failures = 0

    async def poll() -> None:
        nonlocal current, failures, start
        while state.end is None:
            await asyncio.sleep(poll_interval)
            try:
                events, samples = await asyncio.to_thread(reader.read)
            except EventLogError as error:  # busy or a damaged row: say so once, go on
                failures += 1
                if failures == 1:
                    console.print(Text(f"coral-run watch: {error}"), style="red")
                continue
            if events or samples:
                if start is None and events:
                    start = events[0].time
                state.advance(events, samples)
                current = document()
        stop.set()

    if state.end is not None:
        stop.set()
        poller = None
    else:
        poller = asyncio.create_task(poll())
    try:
        await run_terminal_view(
            lambda: current, stop=stop, console=console, mission=reader.mission, rate=rate
        )
    finally:
        if poller is not None:
            poller.cancel()
            with contextlib.suppress(asyncio.CancelledError, CoralError):
                await poller
