"""One budget object for every analysis that can run out of time or work.

Why one: the searches (explicit state space, reachability graph, Karp-Miller tree,
invariants, siphons, z3 queries, CTL labelling) used to carry their own clock alias,
their own "stop" exception and their own way of saying that a limit was hit, some in
seconds and some in milliseconds. A verdict left inconclusive by a budget should read
the same whichever search ran out, and a test should be able to drive any of them to
its deadline with a fake clock. So:

* `Budget` holds a clock (injectable; `time.perf_counter` by default), an optional
  deadline (seconds from its creation) and an optional work cap (states, edges, rows:
  whatever its user counts, named by ``unit``);
* `BudgetExceeded` is the one exception a search raises when its budget runs out; it
  carries the reason;
* `time_limit_reason` and `work_limit_reason` build that reason, always in the same
  shape: ``time limit of 120 s reached after 1,234,567 states`` and
  ``state budget of 2,000,000 reached``;
* `Budget.child` gives a stage its own slice, never outliving its parent's deadline;
* `Budget.z3_timeout_ms` is the one place where seconds become z3's milliseconds.

Typical use::

    budget = Budget(seconds=60.0)
    space = explore(net, budget=budget.child(seconds=20.0))
    solver.set("timeout", budget.z3_timeout_ms(10.0))
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

Clock = Callable[[], float]
"""A seconds counter: `time.perf_counter` in use, a fake one in tests."""

Z3_NO_TIMEOUT_MS = 2**32 - 1
"""What z3 reads as "no time-out" (its ``timeout`` parameter is an unsigned int)."""


class BudgetExceeded(Exception):
    """A search ran out of its budget; ``reason`` says which limit and how far it got."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


def _seconds_text(seconds: float) -> str:
    return f"{seconds:g}"


def _count_text(count: int, unit: str) -> str:
    return f"{count:,} {unit if count == 1 else unit + 's'}"


def time_limit_reason(seconds: float, done: int | None = None, unit: str = "state") -> str:
    """The reason text of a time limit: ``time limit of 120 s reached`` and, when the
    caller knows how far it got, ``after 1,234,567 states``.

    Args:
        seconds: the limit that passed.
        done: how many ``unit`` were done by then (None: not said).
        unit: what ``done`` counts, singular ("state", "edge", "row").
    """
    text = f"time limit of {_seconds_text(seconds)} s reached"
    if done is not None:
        text += f" after {_count_text(done, unit)}"
    return text


def work_limit_reason(limit: int, unit: str = "state") -> str:
    """The reason text of a work cap: ``state budget of 2,000,000 reached``.

    Args:
        limit: the cap.
        unit: what it counts, singular ("state", "edge", "node", "row").
    """
    return f"{unit} budget of {limit:,} reached"


class Budget:
    """A clock, an optional deadline and an optional work cap (see the module docstring).

    Args:
        seconds: the time limit, from now (None: no limit).
        work: the work cap (None: no cap); ``unit`` names what it counts.
        unit: singular noun for the work ("state", "edge", ...), used in reasons.
        clock: seconds counter; tests pass a fake one.

    A budget is cheap; make one per run (or per stage with `child`). Its ``started``
    is the clock's reading at creation, so `elapsed` measures the run it bounds.
    """

    def __init__(
        self,
        seconds: float | None = None,
        work: int | None = None,
        *,
        unit: str = "state",
        clock: Clock = time.perf_counter,
    ) -> None:
        if seconds is not None and (math.isnan(seconds) or seconds < 0):
            raise ValueError(f"a time limit must be a number of seconds >= 0, not {seconds}")
        if work is not None and work < 0:
            raise ValueError(f"a work cap must be >= 0, not {work}")
        self.clock = clock
        self.work = work
        self.unit = unit
        self.started = clock()
        self.deadline: float | None = None if seconds is None else self.started + seconds
        # The limit quoted when the deadline passes: this budget's own seconds, or the
        # ancestor's when a child's slice was cut short by it (see `child`).
        self.limit: float | None = seconds

    # -- time ----------------------------------------------------------------------------

    def elapsed(self) -> float:
        """Seconds since the budget was made, on its clock."""
        return self.clock() - self.started

    def remaining(self) -> float | None:
        """Seconds left before the deadline (never negative); None without one."""
        if self.deadline is None:
            return None
        return max(0.0, self.deadline - self.clock())

    def expired(self) -> bool:
        """Whether the deadline has passed."""
        return self.deadline is not None and self.clock() > self.deadline

    def time_reason(self, done: int | None = None, unit: str | None = None) -> str:
        """`time_limit_reason` for this budget's limit (see there)."""
        return time_limit_reason(self.limit or 0.0, done, unit or self.unit)

    def work_reason(self, unit: str | None = None) -> str:
        """`work_limit_reason` for this budget's cap (see there)."""
        return work_limit_reason(self.work or 0, unit or self.unit)

    def check(self, done: int | None = None) -> None:
        """Raise `BudgetExceeded` when the deadline has passed, or when ``done`` (the
        work so far, in ``unit``) has reached the work cap.

        Args:
            done: the work done so far; quoted in the time reason too.
        """
        if self.work is not None and done is not None and done >= self.work:
            raise BudgetExceeded(self.work_reason())
        if self.expired():
            raise BudgetExceeded(self.time_reason(done))

    # -- slices --------------------------------------------------------------------------

    def child(
        self, seconds: float | None = None, work: int | None = None, unit: str | None = None
    ) -> Budget:
        """A budget for one stage: ``seconds`` from now, but never past this budget's
        deadline; its own work cap (work counts differ between stages: states, then
        edges), in ``unit`` (this budget's unit by default); the same clock.

        When this budget's deadline comes first, the child quotes this budget's limit in
        its reason, since that is the limit the user set.
        """
        sub = Budget(seconds, work, unit=unit or self.unit, clock=self.clock)
        if self.deadline is not None and (sub.deadline is None or self.deadline < sub.deadline):
            sub.deadline = self.deadline
            sub.limit = self.limit
        return sub

    def z3_timeout_ms(self, cap_s: float | None = None) -> int:
        """z3's ``timeout`` parameter (milliseconds, at least 1) for one query: ``cap_s``
        seconds, or what is left of the budget if that is less.

        Args:
            cap_s: the query's own cap in seconds (None: only the budget bounds it).
        """
        seconds = cap_s
        left = self.remaining()
        if left is not None:
            seconds = left if seconds is None else min(seconds, left)
        if seconds is None:
            return Z3_NO_TIMEOUT_MS
        return max(1, min(Z3_NO_TIMEOUT_MS, math.ceil(seconds * 1000)))


def stage(budget: Budget | None, seconds: float | None, work: int | None = None) -> Budget:
    """A function's own budget: a child of ``budget`` (the caller's) or, without one, a
    fresh budget of ``seconds`` on the real clock. Keeps the "None means the default
    limit" rule in one place.

    Args:
        budget: the caller's budget, if any.
        seconds: the default limit, used only when ``budget`` is None.
        work: the work cap of the new budget.
    """
    if budget is None:
        return Budget(seconds, work)
    return budget.child(work=work)


__all__ = [
    "Z3_NO_TIMEOUT_MS",
    "Budget",
    "BudgetExceeded",
    "Clock",
    "stage",
    "time_limit_reason",
    "work_limit_reason",
]
