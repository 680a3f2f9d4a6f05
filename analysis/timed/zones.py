"""Difference-bound matrices over time stamps, in whole microseconds.

A zone is a convex set of valuations of a few time variables, each constraint of the
form ``x_i - x_j <= c``: exactly what timed automata tools (UPPAAL, Tina's state
classes) manipulate. Here the variables are *time stamps*: variable 0 is the mission's
start, variable 1 is ``now``, and every other one is the moment some timer started (a
command was sent, arrived, a reply fell due). Letting time pass moves ``now`` alone.

Times are integers (microseconds). Every constant of the model is an integer, so the
zones' vertices are integral and a strict constraint ``x - y < c`` is ``x - y <= c - 1``
without losing a run that matters: a non-empty half-open interval with integral ends
always holds an integer. Python integers are exact, so no rounding creeps into a bound.

The matrix is kept *canonical* (every entry the tightest bound implied by the others,
all-pairs shortest paths), so emptiness, inclusion and bounds are read off directly.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Protocol

__all__ = ["INF", "NOW", "START", "Zone", "ZoneLike"]

INF = 1 << 62
"""No bound."""
START = 0
"""The mission's start: the zero of time."""
NOW = 1
"""The current time."""


class ZoneLike(Protocol):
    """What the semantics needs of a zone: `Zone`, or the constraint log that
    `analysis.timed.witness` uses to give a whole run concrete times."""

    def constrain(self, i: int, j: int, c: int) -> ZoneLike | None:
        """``x_i - x_j <= c`` added (None: empty)."""
        ...

    def elapse(self) -> ZoneLike:
        """Time passes."""
        ...

    def stamp_now(self) -> tuple[ZoneLike, int]:
        """A new variable equal to ``now``."""
        ...

    def bound(self, i: int, j: int) -> int:
        """Upper bound of ``x_i - x_j``."""
        ...

    def fresh(self) -> tuple[ZoneLike, int]:
        """A new variable, only known to be at or after `START`."""
        ...


def _add(a: int, b: int) -> int:
    return INF if a >= INF or b >= INF else a + b


class Zone:
    """A canonical difference-bound matrix; ``bound(i, j)`` bounds ``x_i - x_j``.

    Zones are values: every operation returns a new zone (or None when the result is
    empty) and leaves its operand unchanged, so states can share them freely.
    """

    __slots__ = ("_m", "n")

    def __init__(self, n: int, matrix: list[list[int]]) -> None:
        self.n = n
        self._m = matrix

    @classmethod
    def initial(cls) -> Zone:
        """``START = NOW = 0``: the mission has just started."""
        return cls(2, [[0, 0], [0, 0]])

    def bound(self, i: int, j: int) -> int:
        """The tightest upper bound of ``x_i - x_j`` (`INF`: none)."""
        return self._m[i][j]

    def key(self) -> tuple[tuple[int, ...], ...]:
        """A hashable value equal for equal zones (over the same variable order)."""
        return tuple(tuple(row) for row in self._m)

    # ------------------------------------------------------------------ constraints

    def constrain(self, i: int, j: int, c: int) -> Zone | None:
        """The zone with ``x_i - x_j <= c`` added, or None if that leaves it empty."""
        m = self._m
        if c >= m[i][j]:
            return self
        if _add(m[j][i], c) < 0:
            return None
        n = self.n
        out = [row[:] for row in m]
        out[i][j] = c
        # Incremental closure: only paths through the new edge i -> j can shorten.
        col_i = [out[k][i] for k in range(n)]
        row_j = out[j]
        for k in range(n):
            ki = col_i[k]
            if ki >= INF:
                continue
            via = ki + c
            row_k = out[k]
            for col in range(n):
                jl = row_j[col]
                if jl < INF and via + jl < row_k[col]:
                    row_k[col] = via + jl
        for k in range(n):
            if out[k][k] < 0:
                return None
        return Zone(n, out)

    def constrain_all(self, constraints: Iterable[tuple[int, int, int]]) -> Zone | None:
        """Every ``(i, j, c)`` meaning ``x_i - x_j <= c`` added, or None if empty."""
        zone: Zone | None = self
        for i, j, c in constraints:
            assert zone is not None
            zone = zone.constrain(i, j, c)
            if zone is None:
                return None
        return zone

    def between(self, i: int, j: int, low: int, high: int) -> Zone | None:
        """``low <= x_i - x_j <= high`` added (``high`` may be `INF`)."""
        zone = self.constrain(j, i, -low)
        if zone is None or high >= INF:
            return zone
        return zone.constrain(i, j, high)

    # ------------------------------------------------------------------ time and variables

    def elapse(self) -> Zone:
        """Let any amount of time pass: ``now`` loses its upper bounds (the zone's
        other stamps are fixed moments of the past, so their differences stay)."""
        out = [row[:] for row in self._m]
        row = out[NOW]
        for j in range(self.n):
            if j != NOW:
                row[j] = INF
        return Zone(self.n, out)

    def stamp_now(self) -> tuple[Zone, int]:
        """A new variable equal to ``now``: a timer starting at this moment."""
        n = self.n
        out = [[*row, row[NOW]] for row in self._m]
        new_row = out[NOW][:]
        new_row[n] = 0
        out.append(new_row)
        out[NOW][n] = 0
        return Zone(n + 1, out), n

    def fresh(self) -> tuple[Zone, int]:
        """A new variable, only known to be at or after `START` (an event not yet
        placed in time)."""
        n = self.n
        out = [[*row, INF] for row in self._m]
        new_row = [INF] * (n + 1)
        new_row[n] = 0
        out.append(new_row)
        for i in range(n):  # x_new - x_i <= INF; x_i - x_new <= x_i - START
            out[i][n] = self._m[i][START]
        new_row[START] = INF
        out[START][n] = 0
        return Zone(n + 1, out), n

    def keep(self, variables: Sequence[int]) -> Zone:
        """The zone projected onto ``variables``, in that order (they become 0, 1, ...).

        Projection of a canonical matrix is deleting rows and columns: every bound was
        already the tightest, so nothing needs recomputing.
        """
        m = self._m
        return Zone(len(variables), [[m[i][j] for j in variables] for i in variables])

    def merge(self, other: Zone) -> Zone | None:
        """The union of the two zones when it is itself a zone, else None.

        The smallest zone holding both is their hull (the larger bound, entry by
        entry, of two canonical matrices is canonical). The union is that hull exactly
        when every point of the hull outside this zone lies in ``other``: the points
        outside this zone are those breaking one of its bounds tighter than the hull's,
        so each such bound, broken, is tried against ``other`` (in integers, breaking
        ``x_i - x_j <= c`` is ``x_j - x_i <= -c - 1``).
        """
        n = self.n
        hull = [
            [max(a, b) for a, b in zip(mine, theirs, strict=True)]
            for mine, theirs in zip(self._m, other._m, strict=True)
        ]
        merged = Zone(n, hull)
        for first, second in ((self, other), (other, self)):
            for i in range(n):
                row = first._m[i]
                for j in range(n):
                    c = row[j]
                    if i == j or c >= hull[i][j]:
                        continue
                    outside = merged.constrain(j, i, -c - 1)
                    if outside is not None and not second.includes(outside):
                        return None
        return merged

    def contains(self, point: Sequence[int]) -> bool:
        """Whether the valuation ``point`` (one value per variable) lies in the zone."""
        m = self._m
        return all(point[i] - point[j] <= m[i][j] for i in range(self.n) for j in range(self.n))

    def includes(self, other: Zone) -> bool:
        """Whether ``other`` (over the same variables) lies inside this zone."""
        for mine, theirs in zip(self._m, other._m, strict=True):
            for a, b in zip(mine, theirs, strict=True):
                if b > a:
                    return False
        return True

    def point(self, order: Sequence[int], prefer_high: Sequence[bool]) -> list[int]:
        """A valuation in the zone: the variables in ``order`` are fixed one by one,
        each to its highest value if ``prefer_high`` says so, else its lowest (given
        those fixed before); the rest follow. Value of ``START`` is 0.

        Used to turn a symbolic run into concrete times: fixing the end time first at
        its maximum yields a run that attains the worst case.
        """
        zone: Zone | None = self.constrain(START, START, 0)
        assert zone is not None
        values = [0] * self.n
        fixed = {START}
        sequence = list(order) + [v for v in range(self.n) if v not in order]
        for index, var in enumerate(sequence):
            if var in fixed:
                continue
            assert zone is not None
            high = zone.bound(var, START)
            low = -zone.bound(START, var)
            want_high = index < len(prefer_high) and prefer_high[index]
            value = high if want_high and high < INF else low
            zone = zone.between(var, START, value, value)
            if zone is None:  # pragma: no cover - canonical zones always admit it
                raise AssertionError("zone point extraction failed")
            values[var] = value
            fixed.add(var)
        return values
