"""Minimal P- and T-invariants (semiflows) with exact integer arithmetic.

A P-invariant is y >= 0, y != 0, with y^T C = 0: the weighted token sum y·M is the
same in every reachable marking. A T-invariant is x >= 0, x != 0, with C x = 0: firing
every transition t exactly x(t) times (in some firable order, if there is one) returns
to the starting marking.

The algorithm is the Farkas / Fourier-Motzkin elimination of Martinez and Silva (1982):
start from the identity, cancel one column of the matrix at a time by positive
combinations of rows of opposite sign, drop rows whose support contains another row's,
and divide every row by the gcd of its entries. What remains are the minimal-support
invariants, each the smallest integer vector on its support. Rows are Python ints, so
nothing overflows. The number of rows can explode exponentially; ``max_rows`` and
a `Budget` bound the work, and the result then says ``complete=False`` and keeps
only rows that are already invariants (each still a genuine invariant).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Literal

from analysis.budget import Budget, BudgetExceeded, stage, work_limit_reason
from analysis.structural import classify, incidence_columns, incidence_rows
from coral_lang.net import Net

DEFAULT_MAX_ROWS = 20_000
DEFAULT_TIME_LIMIT = 20.0
DEFAULT_MAX_CELLS = 20_000_000
"""Size budget: the elimination's working rows are sparse (their non-zero weights and
residuals), and start with one weight per variable plus the incidence entries. A net
with more than this many is not attempted: the basis is empty and incomplete, with the
reason "too large for the structural method (N places)"."""

OUTPUT_CELLS = 2_000_000
"""Most weights listed for the invariants found by elimination: each lists one per
variable (16 MB of tuples at most)."""
TRIVIAL_CELLS = 100_000
"""The same for the unit invariants of places no transition touches: a net of 100,000
such places would otherwise list 10^10 weights."""

# A working row: (weights over the variables, residual over the columns, both as their
# non-zero entries; support bitmask).
_Row = tuple[dict[int, int], dict[int, int], int]


@dataclass(frozen=True)
class Invariant:
    """One minimal-support invariant.

    Attributes:
        weights: One non-negative weight per place (P) or transition (T), in net order.
        names: The place or transition names, aligned with ``weights``.
    """

    weights: tuple[int, ...]
    names: tuple[str, ...]

    @property
    def support(self) -> frozenset[int]:
        """Indices with a non-zero weight."""
        return frozenset(i for i, w in enumerate(self.weights) if w)

    def support_names(self) -> tuple[str, ...]:
        """Names of the elements with a non-zero weight, in net order."""
        return tuple(n for n, w in zip(self.names, self.weights, strict=True) if w)

    def value(self, vector: Sequence[int]) -> int:
        """The weighted sum ``weights · vector`` (y·M for a P-invariant)."""
        return sum(w * v for w, v in zip(self.weights, vector, strict=True))

    def describe(self) -> str:
        """The invariant as a sum, e.g. ``idle + 2*busy``."""
        terms = [
            n if w == 1 else f"{w}*{n}" for n, w in zip(self.names, self.weights, strict=True) if w
        ]
        return " + ".join(terms)


@dataclass(frozen=True)
class InvariantBasis:
    """The minimal-support invariants of one kind, and whether the search finished.

    Attributes:
        kind: ``"P"`` (place weights, y^T C = 0) or ``"T"`` (firing counts, C x = 0).
        names: The places (P) or transitions (T) the weights refer to.
        invariants: Minimal-support invariants found, in a deterministic order.
        complete: True when the elimination finished: every minimal-support invariant is
            listed. False when a limit stopped it: the listed ones are genuine invariants
            but others may exist.
        reason: Why the search stopped early, empty when complete.
    """

    kind: Literal["P", "T"]
    names: tuple[str, ...]
    invariants: tuple[Invariant, ...]
    complete: bool
    reason: str = ""
    method: str = "Farkas algorithm (exact integers, minimal supports)"

    def covered_elements(self) -> frozenset[int]:
        """Indices in the support of some listed invariant."""
        covered: set[int] = set()
        for inv in self.invariants:
            covered |= inv.support
        return frozenset(covered)

    def uncovered(self) -> tuple[str, ...]:
        """Names not in the support of any listed invariant."""
        covered = self.covered_elements()
        return tuple(n for i, n in enumerate(self.names) if i not in covered)

    def covered(self) -> bool | None:
        """Whether every element is in some invariant's support; None if the search
        stopped early and the listed invariants do not cover everything."""
        if not self.uncovered():
            return True
        return False if self.complete else None

    def explain(self) -> str:
        """One line: how many invariants, whether the search finished."""
        what = "P-invariants" if self.kind == "P" else "T-invariants"
        head = f"{len(self.invariants)} minimal {what}"
        if not self.complete:
            head += f" (incomplete: {self.reason})"
        return head


def semiflows(
    rows: Sequence[Sequence[int]],
    max_rows: int = DEFAULT_MAX_ROWS,
    budget: Budget | None = None,
) -> tuple[list[tuple[int, ...]], bool, str]:
    """Minimal-support non-negative integer vectors v with ``sum_i v[i] * rows[i] = 0``.

    Args:
        rows: One row per variable (a place for P-invariants: the rows of C).
        max_rows: Stop when the working set exceeds this many rows.
        budget: Stop at its deadline (default: `DEFAULT_TIME_LIMIT` seconds from now).

    Returns:
        ``(vectors, complete, reason)``: the vectors are sorted; when ``complete`` is
        False they are only the rows that were already semiflows when the limit hit.
    """
    sparse = [{j: int(v) for j, v in enumerate(row) if v} for row in rows]
    return sparse_semiflows(sparse, max_rows, budget)


def sparse_semiflows(
    rows: Sequence[Mapping[int, int]],
    max_rows: int = DEFAULT_MAX_ROWS,
    budget: Budget | None = None,
) -> tuple[list[tuple[int, ...]], bool, str]:
    """`semiflows` of rows given by their non-zero entries (column -> value).

    Working rows are sparse too (weights and residual as dicts), so the cost follows
    the arcs and the rows' supports, never variables x columns: nets of thousands of
    places and transitions are in reach within a time slice.
    """
    n = len(rows)
    budget = stage(budget, DEFAULT_TIME_LIMIT)
    # A zero row (a place no transition touches) is an invariant alone and never
    # combines with another: set aside, so that such places cost nothing.
    work: list[_Row] = [
        ({i: 1}, residual, 1 << i)
        for i, row in enumerate(rows)
        if (residual := {j: int(v) for j, v in row.items() if v})
    ]
    trivial = [[(i, 1)] for i, row in enumerate(rows) if not any(row.values())]
    signs = _Signs(work)
    complete, reason = True, ""
    try:
        if len(work) > max_rows:
            raise _too_many_rows(max_rows)
        while signs.pending:
            column = signs.cheapest()
            work = _eliminate(work, column, max_rows, budget, signs)
    except BudgetExceeded as stop:
        complete, reason = False, stop.reason
    found = sorted(sorted(r[0].items()) for r in work if not r[1])
    # the others first, then the untouched places' unit invariants (a smaller share)
    done = found[: max(1, OUTPUT_CELLS // max(1, n))]
    done += trivial[: max(1, TRIVIAL_CELLS // max(1, n))]
    if len(done) < len(found) + len(trivial):
        complete = False
        reason = (reason + "; " if reason else "") + (
            f"{len(found) + len(trivial):,} invariants found, {len(done):,} listed (each is "
            f"{n:,} weights)"
        )
    vectors = sorted({_dense(dict(r), n) for r in done})
    return vectors, complete, reason


def _dense(weights: dict[int, int], n: int) -> tuple[int, ...]:
    out = [0] * n
    for i, w in weights.items():
        out[i] = w
    return tuple(out)


class _Signs:
    """Per column, how many working rows are positive and negative there, kept up to
    date as rows come and go: choosing the next column costs the pending columns, not
    a pass over every row."""

    def __init__(self, work: list[_Row]) -> None:
        self.pos: dict[int, int] = {}
        self.neg: dict[int, int] = {}
        for row in work:
            self.add(row, 1)
        self.pending = set(self.pos) | set(self.neg)

    def add(self, row: _Row, step: int) -> None:
        for c, v in row[1].items():
            counts = self.pos if v > 0 else self.neg
            counts[c] = counts.get(c, 0) + step

    def cheapest(self) -> int:
        """The pending column whose elimination adds the fewest rows (the growth
        heuristic: rows added minus rows removed), lowest index on ties."""

        def growth(c: int) -> tuple[int, int]:
            pos, neg = self.pos.get(c, 0), self.neg.get(c, 0)
            return pos * neg - pos - neg, c

        column = min(self.pending, key=growth)
        self.pending.discard(column)
        return column


def _too_many_rows(max_rows: int) -> BudgetExceeded:
    return BudgetExceeded(work_limit_reason(max_rows, "intermediate row"))


def _eliminate(
    work: list[_Row], column: int, max_rows: int, budget: Budget, signs: _Signs
) -> list[_Row]:
    """One Fourier-Motzkin step: cancel ``column`` with positive combinations; raises
    `BudgetExceeded` (the working set before this step is still valid) when the rows
    would pass ``max_rows`` or the deadline passes.

    The rows that do not touch ``column`` form an antichain of supports already, so
    only the combined rows are checked against everything, and those rows only
    against the combined rows kept (the same set as a full minimality pass)."""
    budget.check()
    zero = [r for r in work if column not in r[1]]
    positive = [r for r in work if r[1].get(column, 0) > 0]
    negative = [r for r in work if r[1].get(column, 0) < 0]
    if len(zero) + len(positive) * len(negative) > 8 * max_rows:
        raise _too_many_rows(max_rows)
    combined: list[_Row] = []
    for a in positive:
        budget.check()
        for b in negative:
            fa, fb = -b[1][column], a[1][column]
            weights = _combine(a[0], b[0], fa, fb)
            residual = _combine(a[1], b[1], fa, fb)
            combined.append(_normalised(weights, residual, a[2] | b[2]))
    fresh = _minimal_supports(combined, [r[2] for r in zero], budget)
    masks = [r[2] for r in fresh]
    kept = [r for r in zero if not any(k & ~r[2] == 0 for k in masks)] if fresh else zero
    result = kept + fresh
    if len(result) > max_rows:
        raise _too_many_rows(max_rows)
    for row in positive + negative:
        signs.add(row, -1)
    if len(kept) < len(zero):
        dropped = {id(r) for r in zero} - {id(r) for r in kept}
        for row in zero:
            if id(row) in dropped:
                signs.add(row, -1)
    for row in fresh:
        signs.add(row, 1)
    return result


def _combine(a: dict[int, int], b: dict[int, int], fa: int, fb: int) -> dict[int, int]:
    """``fa * a + fb * b`` without its zero entries."""
    out = {k: fa * v for k, v in a.items()}
    for k, v in b.items():
        total = out.get(k, 0) + fb * v
        if total:
            out[k] = total
        else:
            out.pop(k, None)
    return out


def _normalised(weights: dict[int, int], residual: dict[int, int], support: int) -> _Row:
    g = 0
    for v in (*weights.values(), *residual.values()):
        g = math.gcd(g, v)
    if g > 1:
        weights = {k: v // g for k, v in weights.items()}
        residual = {k: v // g for k, v in residual.items()}
    return weights, residual, support


def _minimal_supports(rows: list[_Row], others: list[int], budget: Budget) -> list[_Row]:
    """Keep rows whose support contains neither another kept row's support nor one
    of ``others``.

    Two rows with equal support are proportional once all are minimal (the residual
    is linear in the weights), so keeping the first one loses nothing.
    """
    ordered = sorted(rows, key=lambda r: (r[2].bit_count(), sorted(r[0].items())))
    kept: list[_Row] = []
    masks: list[int] = list(others)
    for count, row in enumerate(ordered):
        if count % 512 == 0:
            budget.check()
        mask = row[2]
        if any(k & ~mask == 0 for k in masks):
            continue
        kept.append(row)
        masks.append(mask)
    return kept


def p_invariants(
    net: Net,
    max_rows: int = DEFAULT_MAX_ROWS,
    budget: Budget | None = None,
    max_cells: int = DEFAULT_MAX_CELLS,
) -> InvariantBasis:
    """Minimal-support P-invariants of ``net`` (y >= 0, y^T C = 0).

    Args:
        net: The net.
        max_rows: Work bound, see `semiflows`.
        budget: Time limit, see `semiflows`.
        max_cells: Size budget, see `DEFAULT_MAX_CELLS`.

    Returns:
        An `InvariantBasis` of kind ``"P"``.
    """
    rows = incidence_rows(net)
    if len(rows) + sum(len(r) for r in rows) > max_cells:
        return _basis("P", net.place_names, [], False, _too_large(len(rows), "places"))
    vectors, complete, reason = sparse_semiflows(rows, max_rows, budget)
    return _basis("P", net.place_names, vectors, complete, reason)


def t_invariants(
    net: Net,
    max_rows: int = DEFAULT_MAX_ROWS,
    budget: Budget | None = None,
    max_cells: int = DEFAULT_MAX_CELLS,
) -> InvariantBasis:
    """Minimal-support T-invariants of ``net`` (x >= 0, C x = 0).

    Args:
        net: The net.
        max_rows: Work bound, see `semiflows`.
        budget: Time limit, see `semiflows`.
        max_cells: Size budget, see `DEFAULT_MAX_CELLS`.

    Returns:
        An `InvariantBasis` of kind ``"T"``.
    """
    names = tuple(t.name for t in net.transitions)
    columns = incidence_columns(net)
    if len(columns) + sum(len(c) for c in columns) > max_cells:
        return _basis("T", names, [], False, _too_large(len(columns), "transitions"))
    vectors, complete, reason = sparse_semiflows(columns, max_rows, budget)
    return _basis("T", names, vectors, complete, reason)


def _too_large(size: int, what: str) -> str:
    return f"too large for the structural method ({size} {what})"


def _basis(
    kind: Literal["P", "T"],
    names: tuple[str, ...],
    vectors: list[tuple[int, ...]],
    complete: bool,
    reason: str,
) -> InvariantBasis:
    return InvariantBasis(
        kind=kind,
        names=names,
        invariants=tuple(Invariant(v, names) for v in vectors),
        complete=complete,
        reason=reason,
    )


def invariant_bounds(net: Net, basis: InvariantBasis) -> dict[str, int]:
    """Upper bounds on places from P-invariants: ``M(p) <= floor(y·M0 / y(p))``.

    Sound for every reachable marking because y·M = y·M0 and all terms are
    non-negative. Only places in the support of some invariant get a bound.

    Args:
        net: The net the invariants belong to.
        basis: Its P-invariants (complete or not; each one is genuine).

    Returns:
        Place name -> the smallest bound any listed invariant gives.
    """
    if basis.kind != "P":
        raise ValueError("place bounds need P-invariants")
    m0 = net.initial_marking()
    bounds: dict[str, int] = {}
    for inv in basis.invariants:
        total = inv.value(m0)
        for i in inv.support:
            bound = total // inv.weights[i]
            name = net.places[i].name
            bounds[name] = min(bound, bounds.get(name, bound))
    return {name: bounds[name] for name in net.place_names if name in bounds}


@dataclass(frozen=True)
class InvariantReport:
    """What the invariants prove about a net.

    Attributes:
        p: The P-invariants.
        t: The T-invariants.
        conservative: The all-ones vector is a P-invariant (token count constant).
        covered_by_p: Every place is in some P-invariant: the net is structurally
            bounded (bounded for every initial marking). None if undecided.
        consistent: Every transition is in some T-invariant (a firing-count vector
            using every transition returns to the start). None if undecided. A
            bounded live net must be consistent (and covered by P-invariants).
        bounds: Place -> bound from P-invariants for this initial marking.
    """

    p: InvariantBasis
    t: InvariantBasis
    conservative: bool
    covered_by_p: bool | None
    consistent: bool | None
    bounds: dict[str, int]
    method: str = "P/T-invariants (Farkas algorithm)"

    def explain(self) -> str:
        """One line summary for reports."""

        def word(flag: bool | None, yes: str, no: str) -> str:
            return yes if flag else (no if flag is False else f"{yes}: undecided")

        parts = [
            self.p.explain(),
            self.t.explain(),
            word(self.covered_by_p, "covered by P-invariants", "not covered by P-invariants"),
            word(self.consistent, "consistent", "not consistent"),
        ]
        if self.conservative:
            parts.append("conservative")
        return "; ".join(parts)


def invariant_report(
    net: Net,
    max_rows: int = DEFAULT_MAX_ROWS,
    budget: Budget | None = None,
    max_cells: int = DEFAULT_MAX_CELLS,
) -> InvariantReport:
    """Compute P- and T-invariants and what they prove (coverage, bounds, classes).

    Args:
        net: The net.
        max_rows: Work bound for each elimination.
        budget: Time limit of each elimination (a child of it each; default
            `DEFAULT_TIME_LIMIT` seconds each).
        max_cells: Size budget for each elimination, see `DEFAULT_MAX_CELLS`.

    Returns:
        The `InvariantReport`.
    """
    p = p_invariants(net, max_rows, budget, max_cells)
    t = t_invariants(net, max_rows, budget, max_cells)
    return InvariantReport(
        p=p,
        t=t,
        conservative=classify(net).conservative,
        covered_by_p=p.covered(),
        consistent=t.covered(),
        bounds=invariant_bounds(net, p),
    )


__all__ = [
    "DEFAULT_MAX_ROWS",
    "DEFAULT_TIME_LIMIT",
    "Invariant",
    "InvariantBasis",
    "InvariantReport",
    "invariant_bounds",
    "invariant_report",
    "p_invariants",
    "semiflows",
    "sparse_semiflows",
    "t_invariants",
]
