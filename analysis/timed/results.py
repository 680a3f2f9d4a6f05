"""What timed analysis found: mission time bounds, time-out adequacy, deadlines.

`TimedReport` is the answer of `analysis.timed.analyse_timed`. `analysis.verify` turns
it into ordinary `analysis.report.PropertyResult` entries (so text, JSON, SARIF, HTML
and certificates show them like every other verdict) and keeps it whole in
`analysis.report.Report.timed` for the figures and schedules.
"""

from __future__ import annotations

from dataclasses import dataclass

from analysis.report import Verdict
from analysis.timed.schedule import TimedSchedule
from coral_lang.diagnostics import Span
from coral_lang.net import format_tokens
from coral_lang.timing import LinkBounds

__all__ = [
    "DeadlineResult",
    "FinalTiming",
    "QueryAdequacy",
    "TimedReport",
]


@dataclass(frozen=True)
class FinalTiming:
    """Best and worst mission time to one declared final marking.

    Attributes:
        final: the final marking's tokens, as declared (place -> count).
        best_s: shortest engine time from the mission's start to reaching it.
        worst_s: longest.
        best: a run that takes ``best_s``.
        worst: a run that takes ``worst_s``.
    """

    final: dict[str, int]
    best_s: float
    worst_s: float
    best: TimedSchedule
    worst: TimedSchedule

    def describe(self) -> str:
        """E.g. ``final { mission_complete }: 160.2 s to 402.7 s``."""
        return (
            f"final {format_tokens(sorted(self.final.items()))}: "
            f"{self.best_s:.1f} s to {self.worst_s:.1f} s"
        )

    def to_json(self) -> dict[str, object]:
        """JSON-ready form (schedules included)."""
        return {
            "final": self.final,
            "best_s": self.best_s,
            "worst_s": self.worst_s,
            "best": self.best.to_json(),
            "worst": self.worst.to_json(),
        }


@dataclass(frozen=True)
class QueryAdequacy:
    """Whether one query's time-out is adequate: it cannot time out while the vehicle
    works within the profile's bounds and the link stays within its bound.

    Attributes:
        transition: the COMMAND transition that sends the query.
        command: the query's name (``DEPTH?``).
        time_out_s: its ``time_out`` parameter.
        verdict: proven (never times out), violated (``counterexample`` times it out)
            or inconclusive (``detail`` says why).
        detail: one sentence for people.
        counterexample: a run in which it times out.
        span: where the transition is written.
        margin_s: when proven, the least slack between the reply falling due and the
            time-out over all runs (how much longer the link or the vehicle could take).
    """

    transition: str
    command: str
    time_out_s: float
    verdict: Verdict
    detail: str
    counterexample: TimedSchedule | None = None
    span: Span | None = None
    margin_s: float | None = None

    def to_json(self) -> dict[str, object]:
        """JSON-ready form."""
        return {
            "transition": self.transition,
            "command": self.command,
            "time_out_s": self.time_out_s,
            "verdict": self.verdict.value,
            "detail": self.detail,
            "margin_s": self.margin_s,
            "counterexample": None
            if self.counterexample is None
            else self.counterexample.to_json(),
        }


@dataclass(frozen=True)
class DeadlineResult:
    """The verdict on one ``assert within T s { places }`` of the mission.

    Attributes:
        index: the assertion's position among the mission's assertions, from 1 (its
            property key is ``assert:INDEX``).
        places: the places it names, with their token counts.
        deadline_s: T.
        verdict: proven, violated (``counterexample`` misses it) or inconclusive.
        detail: one sentence for people.
        counterexample: a run that does not mark the places by the deadline.
        latest_s: when proven, the latest time over all runs at which they are marked.
    """

    index: int
    places: dict[str, int]
    deadline_s: float
    verdict: Verdict
    detail: str
    counterexample: TimedSchedule | None = None
    latest_s: float | None = None

    def to_json(self) -> dict[str, object]:
        """JSON-ready form."""
        return {
            "index": self.index,
            "places": self.places,
            "deadline_s": self.deadline_s,
            "verdict": self.verdict.value,
            "detail": self.detail,
            "latest_s": self.latest_s,
            "counterexample": None
            if self.counterexample is None
            else self.counterexample.to_json(),
        }


@dataclass(frozen=True)
class TimedReport:
    """Everything timed analysis found about one net.

    Attributes:
        complete: whether the exploration finished. When it did not, ``reason`` says
            why, bounds are absent and nothing is proven.
        reason: why it is incomplete (budget, time limit, a cycle, an operator input).
        link: the link bounds assumed.
        states: symbolic states explored.
        seconds: how long it took.
        finals: timing per reachable declared final marking, in declaration order.
        queries: adequacy per query transition, in net order.
        deadlines: verdict per ``within`` assertion.
        unbounded: when the mission can run forever under the timing (a reachable
            cycle of firings), its description; then no worst time exists.
        stuck: markings, not declared final, in which some run ends under the timing
            (untimed analysis reports deadlocks; this is for the record).
    """

    complete: bool
    reason: str
    link: LinkBounds
    states: int
    seconds: float
    finals: tuple[FinalTiming, ...] = ()
    queries: tuple[QueryAdequacy, ...] = ()
    deadlines: tuple[DeadlineResult, ...] = ()
    unbounded: str = ""
    stuck: tuple[dict[str, int], ...] = ()

    @property
    def best_s(self) -> float | None:
        """Shortest time to any final marking (None when none is reached)."""
        return min((f.best_s for f in self.finals), default=None)

    @property
    def worst_s(self) -> float | None:
        """Longest time to any final marking (None when none is reached or unbounded)."""
        if self.unbounded or not self.complete:
            return None
        return max((f.worst_s for f in self.finals), default=None)

    def to_json(self) -> dict[str, object]:
        """The ``timed`` member of a report's JSON (``docs/json.md``)."""
        return {
            "complete": self.complete,
            "reason": self.reason,
            "link": self.link.to_json(),
            "states": self.states,
            "seconds": round(self.seconds, 6),
            "best_s": self.best_s,
            "worst_s": self.worst_s,
            "unbounded": self.unbounded,
            "stuck": list(self.stuck),
            "finals": [f.to_json() for f in self.finals],
            "queries": [q.to_json() for q in self.queries],
            "deadlines": [d.to_json() for d in self.deadlines],
        }
