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
* `Budget.z3_timeout_ms` is the one place where seconds become z3's milliseconds;
* an optional memory limit (bytes of resident memory of the whole process): once the
  process is over it, `Budget.expired` says so (the budget is spent, as by a deadline)
  and `Budget.time_reason` gives the memory reason instead, so every search that stops
  at its deadline also stops, with an honest reason, at the memory limit; a search that
  is about to grow a table asks `Budget.check_memory` first. See `default_memory_limit`
  for the default and `memory_ceiling` for the hard safety net.

Typical use::

    budget = Budget(seconds=60.0)
    space = explore(net, budget=budget.child(seconds=20.0))
    solver.set("timeout", budget.z3_timeout_ms(10.0))
"""

from __future__ import annotations

import contextlib
import math
import os
import resource
import time
from collections.abc import Callable, Iterator
from pathlib import Path

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


MEMORY_SHARE = 0.8
"""Share of the memory available to the process taken as the default memory limit:
the rest is left to the system, page cache and the operator's other programs."""
MEMORY_CHECK_SECONDS = 0.05
"""`Budget.expired` reads the resident memory at most this often (about 10 us a read)."""
CEILING_SLACK = 4 << 30
"""Address space `memory_ceiling` allows beyond the budget and its margin."""
_UNITS = {"": 1, "B": 1, "K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40}


def parse_bytes(text: str) -> int:
    """``200M``, ``1.5G``, ``512k``, ``1048576``: bytes (binary units, K = 1024).

    Raises:
        ValueError: with a message naming the text, for anything else.
    """
    value = text.strip().upper().removesuffix("IB").removesuffix("B")
    unit = value[-1:] if value[-1:] in _UNITS else ""
    number = value[: len(value) - len(unit)]
    try:
        amount = float(number)
    except ValueError:
        amount = math.nan
    if not math.isfinite(amount) or amount <= 0:
        raise ValueError(
            f"'{text}' is not an amount of memory: a positive number of bytes with an "
            "optional K, M, G or T suffix (e.g. 200M, 1.5G)"
        )
    return int(amount * _UNITS[unit])


def bytes_text(amount: int) -> str:
    """``200 MiB``, ``1.5 GiB``: the short form used in reasons."""
    for unit, size in (("GiB", 1 << 30), ("MiB", 1 << 20), ("KiB", 1 << 10)):
        if amount >= size:
            return f"{amount / size:.4g} {unit}"
    return f"{amount} B"


def resident_bytes() -> int:
    """The process's resident memory now (Linux ``/proc/self/statm``; elsewhere the peak
    from getrusage, an upper bound)."""
    try:
        pages = int(Path("/proc/self/statm").read_text().split()[1])
        return pages * os.sysconf("SC_PAGE_SIZE")
    except (OSError, ValueError, IndexError):
        return peak_resident_bytes()


def peak_resident_bytes() -> int:
    """The process's peak resident memory so far (getrusage: KiB on Linux)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def _cgroup_limit() -> int | None:
    """The memory limit of the process's cgroup (v2 ``memory.max``, v1
    ``memory.limit_in_bytes``), None when there is none."""
    for path in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        with contextlib.suppress(OSError, ValueError):
            text = Path(path).read_text().strip()
            if text != "max" and int(text) < 1 << 60:  # v1 writes a huge number for none
                return int(text)
    return None


def _meminfo(field: str) -> int | None:
    with contextlib.suppress(OSError, ValueError):
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith(field + ":"):
                return int(line.split()[1]) * 1024
    return None


def default_memory_limit() -> int | None:
    """The memory limit when the user sets none: `MEMORY_SHARE` of the cgroup's limit
    when the process has one (a container: going over it calls the OOM killer), else of
    the memory available now (MemAvailable: what can be had without swapping), else of
    MemTotal; None where none of these can be read (no limit)."""
    for amount in (_cgroup_limit(), _meminfo("MemAvailable"), _meminfo("MemTotal")):
        if amount:
            return int(amount * MEMORY_SHARE)
    return None


def _data_bytes() -> int:
    """The data segment's size now (VmData), or the resident memory where unknown."""
    return _status_field("VmData") or resident_bytes()


def _status_field(field: str) -> int | None:
    with contextlib.suppress(OSError, ValueError):
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith(field + ":"):
                return int(line.split()[1]) * 1024
    return None


def memory_limit_reason(limit: int | None, done: int | None = None, unit: str = "state") -> str:
    """``memory limit of 200 MiB reached after 1,234,567 states``; without a limit (an
    allocation failed anyway) ``out of memory after ...``."""
    text = "out of memory" if limit is None else f"memory limit of {bytes_text(limit)} reached"
    if done is not None:
        text += f" after {_count_text(done, unit)}"
    return text


@contextlib.contextmanager
def memory_ceiling(limit: int | None, margin: float = 1.0) -> Iterator[None]:
    """The hard safety net under the memory budget: the soft ``RLIMIT_DATA`` set, for
    the ``with`` block, to the data segment already in use plus ``limit``, ``margin`` of
    it and `CEILING_SLACK`, so an allocation far past the budget fails as
    ``MemoryError`` (which the commands turn into an inconclusive verdict) instead of
    waking the kernel's OOM killer. Only the soft limit changes, and it is put back
    afterwards. None: nothing is set."""
    if limit is None or not hasattr(resource, "RLIMIT_DATA"):
        yield
        return
    soft, hard = resource.getrlimit(resource.RLIMIT_DATA)
    # RLIMIT_DATA counts address space (reserved tables, thread arenas), not resident
    # pages: start from the data segment in use and leave a wide margin, or threads
    # (z3's) fail to start long before the budget is reached.
    ceiling = _data_bytes() + int(limit * (1 + margin)) + CEILING_SLACK
    if hard != resource.RLIM_INFINITY:
        ceiling = min(ceiling, hard)
    if soft != resource.RLIM_INFINITY:
        ceiling = min(ceiling, soft)
    try:
        resource.setrlimit(resource.RLIMIT_DATA, (ceiling, hard))
    except (ValueError, OSError):
        yield
        return
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_DATA, (soft, hard))


class Budget:
    """A clock, an optional deadline and an optional work cap (see the module docstring).

    Args:
        seconds: the time limit, from now (None: no limit).
        work: the work cap (None: no cap); ``unit`` names what it counts.
        unit: singular noun for the work ("state", "edge", ...), used in reasons.
        clock: seconds counter; tests pass a fake one.
        memory: the memory limit, bytes of the process's resident memory (None: none).

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
        memory: int | None = None,
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
        self.memory = memory
        # Set once the process was seen over ``memory``: the budget is then spent.
        self.memory_spent = False
        self._memory_read_at = -math.inf

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
        """Whether the budget is spent: the deadline has passed, or the process is over
        the memory limit (read at most every `MEMORY_CHECK_SECONDS`)."""
        if self.deadline is not None and self.clock() > self.deadline:
            return True
        if self.memory is None:
            return False
        if not self.memory_spent:
            now = time.perf_counter()
            if now - self._memory_read_at >= MEMORY_CHECK_SECONDS:
                self._memory_read_at = now
                self.memory_spent = resident_bytes() > self.memory
        return self.memory_spent

    def check_memory(self, extra_bytes: int = 0) -> None:
        """Raise `BudgetExceeded` (memory reason) when the process's resident memory plus
        ``extra_bytes`` (what the caller is about to allocate, e.g. a table it grows)
        would pass the memory limit. The hook a search calls before it grows."""
        if self.memory is None:
            return
        if self.memory_spent or not self.would_fit(extra_bytes):
            self.memory_spent = True
            raise BudgetExceeded(memory_limit_reason(self.memory))

    def would_fit(self, extra_bytes: int) -> bool:
        """Whether ``extra_bytes`` more would keep the process's resident memory within
        the memory limit (always, without one); `check_memory` without the raise, for a
        search that has a cheaper way out than stopping."""
        return self.memory is None or resident_bytes() + extra_bytes <= self.memory

    def time_reason(self, done: int | None = None, unit: str | None = None) -> str:
        """Why `expired` said so: `time_limit_reason` for this budget's limit, or
        `memory_limit_reason` when it was the memory limit (see there)."""
        if self.memory_spent and self.memory is not None:
            return memory_limit_reason(self.memory, done, unit or self.unit)
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
        self,
        seconds: float | None = None,
        work: int | None = None,
        unit: str | None = None,
        *,
        share: bool = False,
    ) -> Budget:
        """A budget for one stage: ``seconds`` from now, but never past this budget's
        deadline; its own work cap (work counts differ between stages: states, then
        edges), in ``unit`` (this budget's unit by default); the same clock.

        When this budget's deadline comes first, the child quotes this budget's limit in
        its reason, since that is the limit the user set; with ``share`` (``seconds``
        are a share of this budget's time left) it always does.
        """
        sub = Budget(seconds, work, unit=unit or self.unit, clock=self.clock, memory=self.memory)
        sub.memory_spent = self.memory_spent
        if self.deadline is not None and (sub.deadline is None or self.deadline < sub.deadline):
            sub.deadline = self.deadline
            sub.limit = self.limit
        if share:
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
    "MEMORY_SHARE",
    "Z3_NO_TIMEOUT_MS",
    "Budget",
    "BudgetExceeded",
    "Clock",
    "bytes_text",
    "default_memory_limit",
    "memory_ceiling",
    "memory_limit_reason",
    "parse_bytes",
    "peak_resident_bytes",
    "resident_bytes",
    "stage",
    "time_limit_reason",
    "work_limit_reason",
]
