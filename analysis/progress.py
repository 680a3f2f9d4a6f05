"""Live progress of long explorations: the data passed to callbacks, and a printer.

`explore` calls its ``progress`` callback after every chunk of the frontier with a
`ProgressInfo`. `ProgressPrinter` is the callback for terminals: one line, rewritten in
place, at most every ``interval`` seconds, on stderr, and only when stderr is a
terminal unless ``force`` is set (so logs and CI output stay clean).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TextIO

from analysis.budget import Clock


@dataclass(frozen=True)
class ProgressInfo:
    """A snapshot of a running exploration.

    Attributes:
        states: markings stored so far.
        edges: (marking, transition) pairs fired so far.
        frontier: markings waiting to be expanded.
        depth: BFS layers reached.
        seconds: time since exploration started.
    """

    states: int
    edges: int
    frontier: int
    depth: int
    seconds: float

    @property
    def rate(self) -> float:
        """States per second so far."""
        return self.states / self.seconds if self.seconds > 0 else 0.0

    def line(self) -> str:
        """The snapshot as one short status line."""
        return (
            f"{self.states:>12,} states  {self.edges:>14,} edges  "
            f"{self.rate:>11,.0f} states/s  frontier {self.frontier:,}  "
            f"depth {self.depth}  {self.seconds:.1f} s"
        )


ProgressCallback = Callable[[ProgressInfo], None]


class ProgressPrinter:
    """A progress callback that rewrites one status line on a terminal.

    Args:
        stream: where to write (default: ``sys.stderr``).
        interval: least seconds between two lines.
        force: print even when ``stream`` is not a terminal.
        clock: seconds counter (tests pass a fake one).
    """

    def __init__(
        self,
        stream: TextIO | None = None,
        interval: float = 0.5,
        force: bool = False,
        clock: Clock = time.perf_counter,
    ) -> None:
        self.stream = stream if stream is not None else sys.stderr
        self.interval = interval
        self.enabled = force or self.stream.isatty()
        self.clock = clock
        self._last: float | None = None
        self._printed = False

    def __call__(self, info: ProgressInfo) -> None:
        """Print ``info`` if enough time passed since the last line."""
        if not self.enabled:
            return
        now = self.clock()
        if self._last is not None and now - self._last < self.interval:
            return
        self._last = now
        self.stream.write("\r" + info.line())
        self.stream.flush()
        self._printed = True

    def close(self) -> None:
        """End the status line (call once exploration is over)."""
        if self._printed:
            self.stream.write("\n")
            self.stream.flush()
            self._printed = False
