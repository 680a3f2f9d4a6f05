"""Structure of a net, independent of any marking: matrices, classes, boundedness.

Everything here looks at arcs only (plus the initial marking for the derived bounds),
so it is cheap and never explores a state. Three jobs:

* `incidence`: the pre, post and incidence matrices every other method builds on.
* `classify`: ordinary / state machine / marked graph / (extended) free choice /
  conservative, with the definitions the Model Checking Contest uses.
* `structural_boundedness`: a z3 linear program that proves places bounded for the
  given initial marking (and, when a strictly positive weighting exists, for every one).

Results carry a ``method`` and an ``explain()`` line so the verify layer can turn them
into verdicts with evidence (see ``docs/analysis-methods.md``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from fractions import Fraction
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from analysis.budget import Budget, BudgetExceeded, stage
from coral_lang.net import Net

if TYPE_CHECKING:
    import z3  # imported where a query runs: it takes about 50 ms to load

IntMatrix = npt.NDArray[np.int64]

DEFAULT_QUERY_SECONDS = 10.0
"""Cap of one z3 query, in seconds (`analysis.budget.Budget.z3_timeout_ms` converts)."""
PER_PLACE_SECONDS = 30.0
BUILD_CHECK_COLUMNS = 256
"""Columns of ``y^T C <= 0`` built between two looks at the budget."""
"""Default time limit of `structural_boundedness` (the per-place LPs take most of it)."""
MAX_DENSE_CELLS = 25_000_000
"""Places x transitions `incidence` builds: three int64 matrices of this many cells
take 600 MB. ``analysis.verify`` stops at the same size before calling anything here;
a direct call on a larger net gets `TooLargeForStructure` instead of exhausting memory."""


class TooLargeForStructure(ValueError):
    """The net is too large for the dense matrices of the structural method.

    Callers turn it into an inconclusive answer that says so (``str(exc)`` is the
    reason: "too large for the structural method (...)").
    """

    def __init__(self, places: int, transitions: int, limit: int) -> None:
        self.places = places
        self.transitions = transitions
        super().__init__(
            f"too large for the structural method ({places:,} places x {transitions:,} "
            f"transitions = {places * transitions:,} cells, over the {limit:,}-cell limit "
            "of its dense matrices)"
        )


@dataclass(frozen=True, eq=False)
class Incidence:
    """The matrices of a net: rows are places (marking order), columns transitions.

    Attributes:
        places: Place names, the row order.
        transitions: Transition names, the column order.
        pre: ``pre[p, t]`` tokens ``t`` takes from ``p``.
        post: ``post[p, t]`` tokens ``t`` puts into ``p``.
        matrix: ``post - pre``, the incidence matrix C: firing ``t`` adds column ``t``.
    """

    places: tuple[str, ...]
    transitions: tuple[str, ...]
    pre: IntMatrix
    post: IntMatrix
    matrix: IntMatrix

    def rows(self) -> list[list[int]]:
        """C as nested Python ints, for exact arithmetic that must never overflow."""
        return [[int(v) for v in row] for row in self.matrix]


def incidence(net: Net, max_cells: int = MAX_DENSE_CELLS) -> Incidence:
    """Build the pre, post and incidence matrices of ``net`` (numpy int64).

    Args:
        net: Any net; transitions without arcs give zero columns.
        max_cells: The largest places x transitions built (see `MAX_DENSE_CELLS`).

    Returns:
        The `Incidence` with rows in `Net.places` order and columns in
        `Net.transitions` order.

    Raises:
        TooLargeForStructure: places x transitions exceeds ``max_cells``; raised before
            anything is allocated.
    """
    n_p, n_t = len(net.places), len(net.transitions)
    if n_p * n_t > max_cells:
        raise TooLargeForStructure(n_p, n_t, max_cells)
    pre = np.zeros((n_p, n_t), dtype=np.int64)
    post = np.zeros((n_p, n_t), dtype=np.int64)
    for t, tr in enumerate(net.transitions):
        for name, w in tr.inputs:
            pre[net.place_index(name), t] += w
        for name, w in tr.outputs:
            post[net.place_index(name), t] += w
    return Incidence(
        places=net.place_names,
        transitions=tuple(t.name for t in net.transitions),
        pre=pre,
        post=post,
        matrix=post - pre,
    )


def incidence_columns(net: Net) -> list[dict[int, int]]:
    """Column ``t`` of the incidence matrix C as place index -> non-zero change: built
    from the arcs, so its size follows them, never places x transitions."""
    return _effects(net)


def incidence_rows(net: Net) -> list[dict[int, int]]:
    """Row ``p`` of the incidence matrix C as transition index -> non-zero change
    (the transpose of `incidence_columns`)."""
    rows: list[dict[int, int]] = [{} for _ in net.places]
    for t, column in enumerate(_effects(net)):
        for p, change in column.items():
            rows[p][t] = change
    return rows


# -- classification ---------------------------------------------------------------------


@dataclass(frozen=True)
class NetClass:
    """Syntactic classes of a net (Murata 1989; the MCC "structural" properties).

    Attributes:
        ordinary: Every arc has weight 1.
        state_machine: Ordinary, every transition has exactly one input and one output
            place (tokens move, never fork or join).
        marked_graph: Ordinary, every place has exactly one input and one output
            transition (no choice, no merge).
        free_choice: Ordinary, and a place with several output transitions is their only
            input place (the MCC's SIMPLE_FREE_CHOICE).
        extended_free_choice: Ordinary, and two transitions sharing an input place have
            the same input places.
        conservative: Every transition puts back as many tokens as it takes (weighted),
            i.e. the all-ones vector is a P-invariant: the token count never changes.
        subconservative: No transition produces more tokens than it takes.
    """

    ordinary: bool
    state_machine: bool
    marked_graph: bool
    free_choice: bool
    extended_free_choice: bool
    conservative: bool
    subconservative: bool
    method: str = "structure (arcs only)"

    def names(self) -> tuple[str, ...]:
        """The classes that hold, in MCC spelling (e.g. ``("ORDINARY", "CONSERVATIVE")``)."""
        flags = {
            "ORDINARY": self.ordinary,
            "STATE_MACHINE": self.state_machine,
            "MARKED_GRAPH": self.marked_graph,
            "SIMPLE_FREE_CHOICE": self.free_choice,
            "EXTENDED_FREE_CHOICE": self.extended_free_choice,
            "CONSERVATIVE": self.conservative,
            "SUBCONSERVATIVE": self.subconservative,
        }
        return tuple(name for name, holds in flags.items() if holds)

    def explain(self) -> str:
        """One line naming the classes that hold."""
        held = ", ".join(n.lower().replace("_", " ") for n in self.names()) or "no special class"
        return f"net class: {held}"


def classify(net: Net) -> NetClass:
    """Classify ``net`` syntactically.

    The free-choice and graph classes require an ordinary net, as in the MCC's
    definitions; a weighted net is none of them.

    Args:
        net: The net to classify.

    Returns:
        The `NetClass` flags.
    """
    # From the arcs, never from |P| x |T| matrices: a net of 10^5 places has 10^10 cells.
    pre = [_weights(t.inputs) for t in net.transitions]
    post = [_weights(t.outputs) for t in net.transitions]
    ordinary = all(w <= 1 for arcs in (*pre, *post) for w in arcs.values())
    consumers: dict[str, list[int]] = {p: [] for p in net.place_names}
    place_in = dict.fromkeys(net.place_names, 0)
    for t, (ins, outs) in enumerate(zip(pre, post, strict=True)):
        for p in ins:
            consumers[p].append(t)
        for p in outs:
            place_in[p] += 1
    inputs = [ins.keys() for ins in pre]
    state_machine = ordinary and all(
        len(ins) == 1 and len(outs) == 1 for ins, outs in zip(pre, post, strict=True)
    )
    marked_graph = ordinary and all(
        place_in[p] == 1 and len(ts) == 1 for p, ts in consumers.items()
    )
    free_choice = ordinary and all(
        len(ts) <= 1 or all(inputs[t] == {p} for t in ts) for p, ts in consumers.items()
    )
    extended = ordinary and all(
        all(inputs[t] == inputs[ts[0]] for t in ts) for ts in consumers.values()
    )
    column_sums = [
        sum(outs.values()) - sum(ins.values()) for ins, outs in zip(pre, post, strict=True)
    ]
    return NetClass(
        ordinary=ordinary,
        state_machine=state_machine,
        marked_graph=marked_graph,
        free_choice=free_choice,
        extended_free_choice=extended,
        conservative=all(c == 0 for c in column_sums),
        subconservative=all(c <= 0 for c in column_sums),
    )


def _weights(arcs: tuple[tuple[str, int], ...]) -> dict[str, int]:
    """Place -> total arc weight (parallel arcs add up, as in `incidence`)."""
    total: dict[str, int] = {}
    for place, w in arcs:
        total[place] = total.get(place, 0) + w
    return total


def _effects(net: Net) -> list[dict[int, int]]:
    """Column ``t`` of the incidence matrix as place index -> non-zero change."""
    columns = []
    for tr in net.transitions:
        change: dict[int, int] = {}
        for name, w in tr.outputs:
            change[net.place_index(name)] = change.get(net.place_index(name), 0) + w
        for name, w in tr.inputs:
            change[net.place_index(name)] = change.get(net.place_index(name), 0) - w
        columns.append({p: c for p, c in change.items() if c})
    return columns


# -- structural boundedness ---------------------------------------------------------------


@dataclass(frozen=True)
class StructuralBoundedness:
    """What linear programming over the incidence matrix proves about place bounds.

    Attributes:
        structurally_bounded: True if a weighting y >= 1 with y^T C <= 0 exists (every
            place bounded for *every* initial marking); False if z3 showed none exists;
            None if z3 gave up (timeout).
        weights: Such a weighting (exact rationals) when one was found.
        bounds: Place -> proven upper bound for this net's initial marking. Only places
            proven bounded appear; a missing place is *not* shown unbounded.
        unproven: Places for which no bound was proven (the LP is unbounded for them or
            z3 gave up).
        reason: Why something is missing (timeouts), empty when nothing is.
    """

    structurally_bounded: bool | None
    weights: dict[str, Fraction] | None
    bounds: dict[str, int]
    unproven: tuple[str, ...]
    reason: str = ""
    method: str = "structural boundedness (z3 linear programming over y^T C <= 0)"

    def explain(self) -> str:
        """One line a reviewer can check."""
        if self.structurally_bounded:
            head = "structurally bounded: a positive weighting y with y^T C <= 0 exists"
        elif self.structurally_bounded is False:
            head = "not structurally bounded: no positive weighting y with y^T C <= 0"
        else:
            head = "structural boundedness undecided"
        tail = f"; {len(self.bounds)} place(s) bounded for the initial marking"
        if self.unproven:
            tail += f", {len(self.unproven)} without a structural bound"
        return head + tail + (f" ({self.reason})" if self.reason else "")


def _to_fraction(value: z3.ExprRef) -> Fraction:
    """An exact rational from a z3 model value (reals are rational in LRA)."""
    import z3

    simplified = z3.simplify(value)
    if z3.is_rational_value(simplified):
        return Fraction(simplified.numerator_as_long(), simplified.denominator_as_long())
    if z3.is_int_value(simplified):
        return Fraction(simplified.as_long())
    raise ValueError(f"z3 returned a non-rational value {simplified}")


def structural_boundedness(
    net: Net,
    query_seconds: float = DEFAULT_QUERY_SECONDS,
    per_place: bool = True,
    budget: Budget | None = None,
) -> StructuralBoundedness:
    """Decide structural boundedness and derive per-place bounds by linear programming.

    Why it is sound: if y >= 0 and y^T C <= 0 then y·M <= y·M0 for every reachable M
    (M = M0 + C x with x >= 0), so ``M(p) <= y·M0 / y(p)`` whenever y(p) > 0. The
    per-place bound minimises y·M0 with y(p) = 1: the best bound any such y gives (the
    LP dual of maximising M(p) over the real relaxation of the state equation).

    Args:
        net: The net.
        query_seconds: Cap of each z3 query (also bounded by ``budget``).
        per_place: Also solve one small LP per place for the tightest bound (about 0.1 s
            per place on nets of a few hundred places). Without it bounds come from the
            single global weighting only.
        budget: Bounds the whole computation (default: `PER_PLACE_SECONDS` from now);
            places left when it runs out keep the global bound (or none).

    Returns:
        A `StructuralBoundedness`; ``structurally_bounded`` is None on timeout.
    """
    import z3

    budget = stage(budget, PER_PLACE_SECONDS)
    effects = _effects(net)
    names = net.place_names
    m0 = net.initial_marking()
    unit = _unit_weighting(effects)
    # One z3 variable a place: only when an LP will be built (about 40 us each).
    y = [z3.Real(f"y_{i}") for i in range(len(names))] if per_place or not unit else []
    reasons: list[str] = []

    def column_constraints() -> list[z3.BoolRef]:
        built = []
        for k, column in enumerate(effects):
            if k % BUILD_CHECK_COLUMNS == 0:
                budget.check()  # z3's Python API: about 100 us an arc
            built.append(
                z3.Sum([c * y[p] for p, c in sorted(column.items())] or [z3.RealVal(0)]) <= 0
            )
        return built

    weights: dict[str, Fraction] | None = None
    decided: bool | None
    if unit:
        # y = 1 everywhere already satisfies y^T C <= 0: no transition makes tokens.
        weights = dict.fromkeys(names, Fraction(1))
        decided = True
    else:
        solver = z3.Solver()
        try:
            solver.add(*[v >= 1 for v in y], *column_constraints())
        except BudgetExceeded as exc:
            return StructuralBoundedness(None, None, {}, names, f"global LP: {exc.reason}")
        solver.set("timeout", budget.z3_timeout_ms(query_seconds))
        status = solver.check()
        if status == z3.sat:
            model = solver.model()
            weights = {
                names[i]: _to_fraction(model.eval(y[i], model_completion=True))
                for i in range(len(names))
            }
            decided = True
        elif status == z3.unsat:
            decided = False
        else:
            decided = None
            reasons.append(f"global LP: {solver.reason_unknown()}")

    bounds: dict[str, int] = {}
    if weights is not None:
        total = sum((weights[n] * m0[i] for i, n in enumerate(names)), Fraction(0))
        for name in names:
            bounds[name] = math.floor(total / weights[name])
    if per_place:
        for i, name in enumerate(names):
            if budget.expired():
                reasons.append(f"per-place bounds stopped: {budget.time_reason(i, 'place')}")
                break
            try:
                columns = column_constraints()
            except BudgetExceeded as exc:
                reasons.append(f"per-place bounds stopped: {exc.reason}")
                break
            timeout_ms = budget.z3_timeout_ms(query_seconds)
            best = _place_bound(y, i, m0, columns, timeout_ms)
            if isinstance(best, str):
                reasons.append(f"{name}: {best}")
            elif best is not None:
                bounds[name] = min(best, bounds.get(name, best))
    unproven = tuple(n for n in names if n not in bounds)
    return StructuralBoundedness(
        structurally_bounded=decided,
        weights=weights,
        bounds=bounds,
        unproven=unproven,
        reason="; ".join(reasons),
    )


def _unit_weighting(effects: Sequence[Mapping[int, int]]) -> bool:
    """Whether no transition puts out more tokens than it takes (every column of C sums
    to at most 0): then y = 1 is a weighting with y^T C <= 0, found in one pass over
    the arcs instead of an LP (true of most MCC nets, which conserve their tokens)."""
    return all(sum(column.values()) <= 0 for column in effects)


def _place_bound(
    y: list[z3.ArithRef],
    place: int,
    m0: tuple[int, ...],
    columns: list[z3.BoolRef],
    timeout_ms: int,
) -> int | str | None:
    """floor(min y·M0 s.t. y >= 0, y(place) = 1, y^T C <= 0); None if infeasible,
    a reason string if z3 gave up."""
    import z3

    opt = z3.Optimize()
    opt.set("timeout", timeout_ms)
    opt.add(*[v >= 0 for v in y], y[place] == 1, *columns)
    objective = z3.Sum([m0[i] * y[i] for i in range(len(y)) if m0[i]] or [z3.RealVal(0)])
    handle = opt.minimize(objective)
    status = opt.check()
    if status == z3.unsat:
        return None
    if status != z3.sat:
        return f"z3 gave up ({opt.reason_unknown()})"
    value = opt.lower(handle)
    if not (z3.is_rational_value(value) or z3.is_int_value(value)):
        return "objective not attained"
    return math.floor(_to_fraction(value))


__all__ = [
    "DEFAULT_QUERY_SECONDS",
    "MAX_DENSE_CELLS",
    "Incidence",
    "NetClass",
    "StructuralBoundedness",
    "TooLargeForStructure",
    "classify",
    "incidence",
    "incidence_columns",
    "incidence_rows",
    "structural_boundedness",
]
