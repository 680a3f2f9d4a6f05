"""Prove bad markings unreachable with the state equation, without exploring states.

Every reachable marking M satisfies the *state equation* M = M0 + C·x for some integer
firing-count vector x >= 0, with M >= 0. So if z3 shows that no (M, x) satisfies the
equation together with "M is bad", no bad marking is reachable: a proof. The converse
fails: a solution need not be reachable (the counts may not be firable in any order),
so a solution is only a `Candidate`, never a counterexample.

Two strengthenings cut spurious solutions:

* P-invariants: y·M = y·M0 (implied by the equation, kept because it can help z3).
* Traps: a trap marked in M0 stays marked forever, so sum over the trap of M >= 1.
  After each candidate, the largest trap among its empty places is computed; if that
  trap is initially marked, its constraint is added and z3 is asked again (the
  refinement of Esparza and Melzer). If not, no trap constraint can exclude the
  candidate and it is returned.

Bad sets are data (`BadMarkings`), never code strings: a conjunction of linear place
constraints, optionally "dead" (no transition enabled), optionally minus some markings
(the declared final ones).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar, Literal

from analysis.budget import Budget, BudgetExceeded, stage
from analysis.inputs import legal_trace
from analysis.invariants import InvariantBasis
from analysis.siphons import maximal_trap
from analysis.structural import DEFAULT_QUERY_SECONDS
from coral_lang.net import Net, Transition, TransitionKind

if TYPE_CHECKING:
    import z3  # imported where a query runs: it takes about 50 ms to load

Marking = tuple[int, ...]
Op = Literal[">=", "<=", "=="]

METHOD = "state equation"
DEFAULT_TIME_LIMIT = 60.0
"""Default time limit of `check_unreachable`, across its trap refinement rounds."""
METHOD_TRAPS = "state equation + traps"


# -- what is bad ------------------------------------------------------------------------


@dataclass(frozen=True)
class PlaceConstraint:
    """A linear constraint on a marking: ``sum(weight * M(place)) op bound``.

    Attributes:
        terms: ``(place name, weight)`` pairs; weights may be negative.
        op: ``">="``, ``"<="`` or ``"=="``.
        bound: The right-hand side.
    """

    terms: tuple[tuple[str, int], ...]
    op: Op
    bound: int

    def value(self, net: Net, marking: Sequence[int]) -> int:
        """The left-hand side in ``marking``."""
        return sum(w * marking[net.place_index(p)] for p, w in self.terms)

    def holds(self, net: Net, marking: Sequence[int]) -> bool:
        """Whether ``marking`` satisfies the constraint."""
        value = self.value(net, marking)
        if self.op == ">=":
            return value >= self.bound
        if self.op == "<=":
            return value <= self.bound
        return value == self.bound

    def describe(self) -> str:
        """E.g. ``M(a) + 2*M(b) >= 3``."""
        lhs = " + ".join(f"M({p})" if w == 1 else f"{w}*M({p})" for p, w in self.terms)
        return f"{lhs or '0'} {self.op} {self.bound}"


@dataclass(frozen=True)
class BadMarkings:
    """A set of markings that must not be reachable, as data.

    A marking is bad when it satisfies every constraint, is dead if ``dead`` is set,
    and is none of ``exclude``.

    ``exclude`` rows may be projections: a final marking leaves each armed place free
    (0 or 1), so listing finals as full markings costs 2**k rows (and z3 disjuncts) for
    k operator inputs, while one row per final on `Net.final_columns` says the same.

    Attributes:
        constraints: A conjunction of linear place constraints (empty: no restriction).
        dead: Also require that no transition is enabled (operator inputs aside: a
            marking where only inputs are enabled is terminal, hence dead).
        exclude: Markings that are not bad, e.g. the declared final markings when
            looking for unexpected deadlocks: full markings (aligned with
            `Net.places`), or their values on ``exclude_columns`` when that is set.
        exclude_columns: The place columns ``exclude`` rows give (``None``: all).
        exclude_armed: Columns an excluded marking holds at most 1 in (the armed
            places a final leaves free).
        label: How a report names this set, e.g. ``"a and b marked together"``.
    """

    constraints: tuple[PlaceConstraint, ...] = ()
    dead: bool = False
    exclude: tuple[Marking, ...] = ()
    label: str = ""
    exclude_columns: tuple[int, ...] | None = None
    exclude_armed: tuple[int, ...] = ()

    def excluded(self, marking: Marking) -> bool:
        """Whether ``marking`` is one of ``exclude`` (so not bad)."""
        if not self.exclude or any(marking[i] > 1 for i in self.exclude_armed):
            return False
        if self.exclude_columns is None:
            return tuple(marking) in set(self.exclude)
        return tuple(marking[i] for i in self.exclude_columns) in set(self.exclude)

    def matches(self, net: Net, marking: Marking) -> bool:
        """Whether ``marking`` is in the set (used to confirm candidates by search)."""
        if self.excluded(tuple(marking)):
            return False
        if not all(c.holds(net, marking) for c in self.constraints):
            return False
        return not (self.dead and any(net.enabled(marking, t) for t in _engine(net)))

    def describe(self) -> str:
        """The label, or the constraints spelled out."""
        if self.label:
            return self.label
        parts = [c.describe() for c in self.constraints]
        if self.dead:
            parts.append("no transition enabled")
        if self.exclude:
            parts.append(f"not one of {len(self.exclude)} final marking(s)")
        return " and ".join(parts) or "any marking"


def never_together(places: Iterable[str]) -> BadMarkings:
    """Markings where all ``places`` hold a token at once (``assert never {a, b}``)."""
    names = tuple(places)
    return BadMarkings(
        constraints=tuple(PlaceConstraint(((p, 1),), ">=", 1) for p in names),
        label=f"{', '.join(names)} marked together",
    )


def above_bound(places: Iterable[str], bound: int) -> BadMarkings:
    """Markings with more than ``bound`` tokens in total over ``places``."""
    names = tuple(places)
    return BadMarkings(
        constraints=(PlaceConstraint(tuple((p, 1) for p in names), ">=", bound + 1),),
        label=f"more than {bound} token(s) in {', '.join(names)}",
    )


def deadlocks(exclude: Iterable[Marking] = ()) -> BadMarkings:
    """Dead markings, except those in ``exclude``."""
    skip = tuple(tuple(m) for m in exclude)
    label = "a dead marking" + (" that is not a declared final marking" if skip else "")
    return BadMarkings(dead=True, exclude=skip, label=label)


def unexpected_deadlocks(net: Net) -> BadMarkings:
    """Dead markings other than the net's declared final markings (one projected row
    per final, see `BadMarkings`)."""
    patterns = tuple(net.final_patterns())
    if not patterns:
        return deadlocks()
    return BadMarkings(
        dead=True,
        exclude=patterns,
        label="a dead marking that is not a declared final marking",
        exclude_columns=net.final_columns(),
        exclude_armed=net.armed_columns(),
    )


# -- what the solver says -----------------------------------------------------------------


@dataclass(frozen=True)
class Proven:
    """No bad marking is reachable: the state equation (with ``traps``) has no solution.

    Attributes:
        bad: The set shown unreachable.
        method: ``"state equation"`` or ``"state equation + traps"``.
        traps: The trap constraints that were needed, as place-name tuples.
    """

    bad: BadMarkings
    method: str = METHOD
    traps: tuple[tuple[str, ...], ...] = ()

    def explain(self) -> str:
        """One line for a report."""
        why = f"no reachable marking is {self.bad.describe()}: the {self.method} has no solution"
        if self.traps:
            why += f" ({len(self.traps)} initially marked trap(s) stay marked)"
        return why


@dataclass(frozen=True)
class Candidate:
    """A solution of the state equation in the bad set. NOT a counterexample.

    The firing counts may not be firable in any order from M0, so the marking may be
    unreachable. The caller must confirm it by search (explore, or `realise` a firing
    order of the counts) before reporting a violation; otherwise the verdict is
    inconclusive.

    Attributes:
        bad: The set the marking belongs to.
        marking: M, aligned with `Net.places`.
        firing_counts: x, aligned with `Net.transitions`; M = M0 + C·x.
        places: Place names (for display).
        transitions: Transition names (for display).
        method: Which constraints the solution satisfies.
        traps: Trap constraints that were added before this solution was found.
    """

    bad: BadMarkings
    marking: Marking
    firing_counts: tuple[int, ...]
    places: tuple[str, ...]
    transitions: tuple[str, ...]
    method: str = METHOD
    traps: tuple[tuple[str, ...], ...] = ()
    is_counterexample: ClassVar[bool] = False

    def marking_dict(self) -> dict[str, int]:
        """Marked places of the candidate as ``{name: tokens}``."""
        return {p: m for p, m in zip(self.places, self.marking, strict=True) if m}

    def counts_dict(self) -> dict[str, int]:
        """Transitions with a non-zero firing count as ``{name: count}``."""
        return {t: x for t, x in zip(self.transitions, self.firing_counts, strict=True) if x}

    def explain(self) -> str:
        """One line saying what the solution is and what it is not."""
        return (
            f"the {self.method} admits {self.marking_dict()} with firing counts "
            f"{self.counts_dict()} ({self.bad.describe()}); not a counterexample until a "
            f"search confirms it is reachable"
        )


@dataclass(frozen=True)
class Unknown:
    """z3 gave up (timeout or resource limit); nothing is proven either way."""

    bad: BadMarkings
    reason: str
    method: str = METHOD

    def explain(self) -> str:
        """One line for a report."""
        return f"{self.method} inconclusive for {self.bad.describe()}: {self.reason}"


StateEquationResult = Proven | Candidate | Unknown


# -- the check ----------------------------------------------------------------------------


def check_unreachable(
    net: Net,
    bad: BadMarkings,
    *,
    invariants: InvariantBasis | None = None,
    use_traps: bool = True,
    max_trap_rounds: int = 50,
    query_seconds: float = DEFAULT_QUERY_SECONDS,
    budget: Budget | None = None,
) -> StateEquationResult:
    """Try to prove that no marking in ``bad`` is reachable.

    Args:
        net: The net.
        bad: The markings that must not be reachable.
        invariants: P-invariants to add as y·M = y·M0 (optional; implied anyway).
        use_traps: Refine candidates with trap constraints.
        max_trap_rounds: At most this many refinement rounds.
        query_seconds: Cap of each z3 query (also bounded by ``budget``).
        budget: Bounds all rounds together (default: `DEFAULT_TIME_LIMIT` seconds from
            now); a candidate found when it runs out is returned unrefined.

    Returns:
        `Proven` (unsat: no bad marking is reachable), `Candidate` (a solution that
        still needs confirming), or `Unknown` (z3 gave up or a limit was hit).
    """
    import z3

    if invariants is not None and invariants.kind != "P":
        raise ValueError("the state equation is strengthened with P-invariants only")
    budget = stage(budget, DEFAULT_TIME_LIMIT)
    try:
        solver, marking, counts = _equation(net, bad, invariants, budget)
    except BudgetExceeded as exc:
        return Unknown(bad=bad, reason=f"building the constraints: {exc.reason}")
    traps: list[tuple[str, ...]] = []
    rounds = 0
    while True:
        solver.set("timeout", budget.z3_timeout_ms(query_seconds))
        status = solver.check()
        method = METHOD_TRAPS if traps else METHOD
        if status == z3.unsat:
            return Proven(bad=bad, method=method, traps=tuple(traps))
        if status != z3.sat:
            return Unknown(bad=bad, reason=f"z3: {solver.reason_unknown()}", method=method)
        model = solver.model()
        m = tuple(model.eval(v, model_completion=True).as_long() for v in marking)
        x = tuple(model.eval(v, model_completion=True).as_long() for v in counts)
        trap = _violated_trap(net, m) if use_traps else None
        if trap is None or rounds >= max_trap_rounds or budget.expired():
            return Candidate(
                bad=bad,
                marking=m,
                firing_counts=x,
                places=net.place_names,
                transitions=tuple(t.name for t in net.transitions),
                method=method,
                traps=tuple(traps),
            )
        traps.append(trap)
        solver.add(z3.Sum([marking[net.place_index(p)] for p in trap]) >= 1)
        rounds += 1


def realise(net: Net, candidate: Candidate, max_nodes: int = 100_000) -> tuple[int, ...] | None:
    """Look for a firing order of the candidate's counts: a real counterexample.

    Depth-first over which transition to fire next, each at most its remaining count.
    The marking is determined by the counts still to fire (M = M0 + C·(x - remaining)),
    so a set of remaining-count vectors already tried is enough to avoid repeats.

    Args:
        net: The net the candidate came from.
        candidate: A solution of the state equation.
        max_nodes: Search budget (count vectors tried).

    Returns:
        Transition indices that, fired from M0 with `Net.fire`, reach
        ``candidate.marking`` (a bad marking: a genuine counterexample); None if no
        order was found within budget. None does **not** make the candidate spurious in
        general: another solution of the equation may be reachable.
    """
    start = net.initial_marking()
    total = tuple(candidate.firing_counts)
    tried: set[tuple[int, ...]] = set()
    # Each frame: (marking, remaining counts, sequence so far).
    stack: list[tuple[Marking, tuple[int, ...], tuple[int, ...]]] = [(start, total, ())]
    while stack and len(tried) < max_nodes:
        marking, remaining, sequence = stack.pop()
        if not any(remaining):
            # Operator inputs fire while the run is on (analysis.inputs).
            legal = legal_trace(net, sequence)
            return None if legal is None else tuple(legal)
        if remaining in tried:
            continue
        tried.add(remaining)
        for t in reversed(range(len(remaining))):
            tr = net.transitions[t]
            if remaining[t] and net.enabled(marking, tr):
                rest = (*remaining[:t], remaining[t] - 1, *remaining[t + 1 :])
                stack.append((net.fire(marking, tr), rest, (*sequence, t)))
    return None


def _sparse_rows(net: Net) -> list[dict[int, int]]:
    """Row p of the incidence matrix as ``{t: C[p, t]}`` from the arcs (Python ints,
    exact): the equation has one term per arc, so it never needs the dense places x
    transitions matrix, which past tens of millions of cells would not fit in memory."""
    rows: list[dict[int, int]] = [{} for _ in net.places]
    for t, tr in enumerate(net.transitions):
        for name, w in tr.inputs:
            row = rows[net.place_index(name)]
            row[t] = row.get(t, 0) - w
        for name, w in tr.outputs:
            row = rows[net.place_index(name)]
            row[t] = row.get(t, 0) + w
    return rows


EQUATION_CHECK_ROWS = 256
"""Rows of the equation built between two looks at the budget (z3's Python API takes
about 100 us an arc, so a wide net's constraints alone can outlast a time limit)."""


def _equation(
    net: Net, bad: BadMarkings, invariants: InvariantBasis | None, budget: Budget | None = None
) -> tuple[z3.Solver, list[z3.ArithRef], list[z3.ArithRef]]:
    """The solver with M = M0 + C x, x >= 0, M >= 0, invariants and the bad set; past
    ``budget`` (checked every `EQUATION_CHECK_ROWS` rows) `BudgetExceeded`."""
    import z3

    rows = _sparse_rows(net)
    m0 = net.initial_marking()
    counts = [z3.Int(f"x_{t}") for t in range(len(net.transitions))]
    marking = [z3.Int(f"m_{p}") for p in range(len(net.places))]
    solver = z3.Solver()
    solver.add(*[x >= 0 for x in counts], *[m >= 0 for m in marking])
    for p, row in enumerate(rows):
        if budget is not None and p % EQUATION_CHECK_ROWS == 0:
            budget.check()
        flow = [c * counts[t] for t, c in sorted(row.items()) if c]
        solver.add(marking[p] == m0[p] + z3.Sum(flow) if flow else marking[p] == m0[p])
    if invariants is not None:
        for inv in invariants.invariants:
            terms = [w * marking[p] for p, w in enumerate(inv.weights) if w]
            solver.add(z3.Sum(terms) == inv.value(m0))
    for c in bad.constraints:
        lhs = z3.Sum([w * marking[net.place_index(p)] for p, w in c.terms] or [z3.IntVal(0)])
        solver.add(
            lhs >= c.bound if c.op == ">=" else lhs <= c.bound if c.op == "<=" else lhs == c.bound
        )
    if bad.dead:
        for k, tr in enumerate(_engine(net)):
            if budget is not None and k % EQUATION_CHECK_ROWS == 0:
                budget.check()
            # Disabled: some input place holds fewer tokens than the arc needs. A
            # transition without inputs is always enabled, so Or([]) = False is right.
            solver.add(z3.Or([marking[net.place_index(p)] < w for p, w in tr.inputs]))
    columns = range(len(marking)) if bad.exclude_columns is None else bad.exclude_columns
    for final in bad.exclude:
        # Not this final: some constrained place differs, or some armed place holds 2+.
        differs = [marking[p] != k for p, k in zip(columns, final, strict=True)]
        solver.add(z3.Or(differs + [marking[p] > 1 for p in bad.exclude_armed]))
    return solver, marking, counts


def _engine(net: Net) -> list[Transition]:
    """The transitions whose being disabled makes a marking dead: all but operator
    inputs (a marking where only inputs are enabled is terminal, see
    `analysis.inputs`)."""
    return [t for t in net.transitions if t.kind is not TransitionKind.INPUT]


def _violated_trap(net: Net, marking: Marking) -> tuple[str, ...] | None:
    """An initially marked trap that is empty in ``marking``, or None.

    The maximal trap among the empty places contains every trap that is empty there;
    if it is not initially marked, no trap constraint can exclude this marking.
    """
    empty = [p.name for p, m in zip(net.places, marking, strict=True) if m == 0]
    trap = maximal_trap(net, empty)
    if any(net.place(p).initial for p in trap):
        return tuple(sorted(trap, key=net.place_index))
    return None


__all__ = [
    "METHOD",
    "METHOD_TRAPS",
    "BadMarkings",
    "Candidate",
    "Op",
    "PlaceConstraint",
    "Proven",
    "StateEquationResult",
    "Unknown",
    "above_bound",
    "check_unreachable",
    "deadlocks",
    "never_together",
    "realise",
    "unexpected_deadlocks",
]
