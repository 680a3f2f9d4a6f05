"""Temporal formulas over the runs of a net: one tree for every property language.

The mission language (``assert always ...``, ``assert ... leadsto ...``, CTL) and the
Model Checking Contest's XML property files both build these nodes, so one set of
checkers in `analysis` decides them all.

A formula is CTL* shaped, as the MCC files are: path quantifiers (`All`, `Exists`)
wrap path formulas built from `Next`, `Finally`, `Globally` and `Until`. The
checkers accept two fragments of it:

* **CTL**: every temporal operator sits directly under a path quantifier
  (``AG φ`` is ``All(Globally(φ))``); see `is_ctl`.
* **LTL**: one `All` at the root (or none) above a path formula free of quantifiers;
  see `ltl_body`.

State atoms: `Compare` of two integer expressions (`Tokens`: the sum of the tokens of
some places, with weights; `IntConst`), `Fireable` (at least one of some transitions
is enabled), `Deadlock` (no transition is enabled) and `Const`. `Fires` is an event
atom, true at a position of a run when the transition taken there is one of the
named ones; it is meaningful in LTL only (a run is a sequence of markings *and* the
transitions between them, see ``docs/verify.md``).

Nodes are frozen dataclasses, hashable and compared by value, so a checker can cache
the satisfaction set of a sub-formula that occurs twice.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

# -- integer expressions ------------------------------------------------------------------


@dataclass(frozen=True)
class Tokens:
    """``sum(weight * tokens(place))`` over ``places`` (weight 1 in the MCC files)."""

    places: tuple[tuple[str, int], ...]

    def __str__(self) -> str:
        terms = [p if w == 1 else f"{p}*{w}" for p, w in self.places]
        if len(terms) == 1:
            return terms[0]
        return "(" + " + ".join(terms) + ")" if terms else "0"


@dataclass(frozen=True)
class IntConst:
    """An integer constant."""

    value: int

    def __str__(self) -> str:
        return str(self.value)


IntExpr = Tokens | IntConst

COMPARISONS = ("<=", "<", ">=", ">", "==", "!=")
"""The comparison operators of `Compare` (the MCC files use ``<=`` only)."""


# -- state formulas -----------------------------------------------------------------------


@dataclass(frozen=True)
class Const:
    """``true`` or ``false``."""

    value: bool

    def __str__(self) -> str:
        return "true" if self.value else "false"


@dataclass(frozen=True)
class Compare:
    """``left op right`` with ``op`` one of `COMPARISONS`."""

    left: IntExpr
    op: str
    right: IntExpr

    def __post_init__(self) -> None:
        if self.op not in COMPARISONS:
            raise ValueError(f"unknown comparison {self.op!r}; expected one of {COMPARISONS}")

    def __str__(self) -> str:
        return f"{self.left} {self.op} {self.right}"


@dataclass(frozen=True)
class Fireable:
    """At least one of ``transitions`` is enabled in the marking."""

    transitions: tuple[str, ...]

    def __str__(self) -> str:
        return f"fireable({', '.join(self.transitions)})"


@dataclass(frozen=True)
class Deadlock:
    """No transition is enabled in the marking."""

    def __str__(self) -> str:
        return "deadlock"


@dataclass(frozen=True)
class Fires:
    """Event atom: the transition taken at this position of the run is one of
    ``transitions`` (false where the run stutters in a dead marking)."""

    transitions: tuple[str, ...]

    def __str__(self) -> str:
        return f"fires({', '.join(self.transitions)})"


@dataclass(frozen=True)
class Not:
    """Negation."""

    arg: Formula

    def __str__(self) -> str:
        return f"not {_wrap(self.arg)}"


@dataclass(frozen=True)
class And:
    """Conjunction of two or more formulas (an empty one is ``true``)."""

    args: tuple[Formula, ...]

    def __str__(self) -> str:
        return " and ".join(_wrap(a) for a in self.args) if self.args else "true"


@dataclass(frozen=True)
class Or:
    """Disjunction of two or more formulas (an empty one is ``false``)."""

    args: tuple[Formula, ...]

    def __str__(self) -> str:
        return " or ".join(_wrap(a) for a in self.args) if self.args else "false"


# -- path quantifiers and temporal operators -----------------------------------------------


@dataclass(frozen=True)
class All:
    """``A``: the path formula holds on every run from the marking."""

    path: Formula

    def __str__(self) -> str:
        return f"A {_wrap(self.path)}"


@dataclass(frozen=True)
class Exists:
    """``E``: the path formula holds on some run from the marking."""

    path: Formula

    def __str__(self) -> str:
        return f"E {_wrap(self.path)}"


@dataclass(frozen=True)
class Next:
    """``X``: holds at the next position (at a dead marking the run stutters, so the
    next position is the same marking: see ``docs/verify.md``)."""

    arg: Formula

    def __str__(self) -> str:
        return f"X {_wrap(self.arg)}"


@dataclass(frozen=True)
class Finally:
    """``F``: holds at some position from now on."""

    arg: Formula

    def __str__(self) -> str:
        return f"F {_wrap(self.arg)}"


@dataclass(frozen=True)
class Globally:
    """``G``: holds at every position from now on."""

    arg: Formula

    def __str__(self) -> str:
        return f"G {_wrap(self.arg)}"


@dataclass(frozen=True)
class Until:
    """``U``: ``right`` holds at some position, and ``left`` at every one before it."""

    left: Formula
    right: Formula

    def __str__(self) -> str:
        return f"{_wrap(self.left)} U {_wrap(self.right)}"


Formula = (
    Const
    | Compare
    | Fireable
    | Deadlock
    | Fires
    | Not
    | And
    | Or
    | All
    | Exists
    | Next
    | Finally
    | Globally
    | Until
)

ATOMS = (Const, Compare, Fireable, Deadlock, Fires)
TEMPORAL = (Next, Finally, Globally, Until)
QUANTIFIERS = (All, Exists)


def _wrap(f: Formula) -> str:
    return str(f) if isinstance(f, ATOMS) else f"({f})"


def children(f: Formula) -> tuple[Formula, ...]:
    """The direct sub-formulas of ``f``."""
    if isinstance(f, Not | All | Exists | Next | Finally | Globally):
        return (f.path,) if isinstance(f, All | Exists) else (f.arg,)
    if isinstance(f, And | Or):
        return f.args
    if isinstance(f, Until):
        return (f.left, f.right)
    return ()


def walk(f: Formula) -> Iterator[Formula]:
    """``f`` and every sub-formula, parents before children (iterative: the MCC files
    nest deeply)."""
    stack = [f]
    while stack:
        node = stack.pop()
        yield node
        stack.extend(reversed(children(node)))


def places_of(f: Formula) -> set[str]:
    """Every place a `Tokens` atom of ``f`` reads."""
    found: set[str] = set()
    for node in walk(f):
        if isinstance(node, Compare):
            for side in (node.left, node.right):
                if isinstance(side, Tokens):
                    found.update(p for p, _ in side.places)
    return found


def transitions_of(f: Formula) -> set[str]:
    """Every transition a `Fireable` or `Fires` atom of ``f`` names."""
    found: set[str] = set()
    for node in walk(f):
        if isinstance(node, Fireable | Fires):
            found.update(node.transitions)
    return found


def is_state_formula(f: Formula) -> bool:
    """Whether ``f`` has no temporal operator, quantifier or event atom."""
    return not any(isinstance(n, (*TEMPORAL, *QUANTIFIERS, Fires)) for n in walk(f))


def is_ctl(f: Formula) -> bool:
    """Whether ``f`` is CTL: each temporal operator directly under `All`/`Exists`, each
    quantifier directly above one, and no `Fires` atom."""
    stack: list[Formula] = [f]
    while stack:
        node = stack.pop()
        if isinstance(node, Fires | Next | Finally | Globally | Until):
            return False
        if isinstance(node, All | Exists):
            path = node.path
            if not isinstance(path, TEMPORAL):
                return False
            stack.extend(children(path))
        else:
            stack.extend(children(node))
    return True


def ltl_body(f: Formula) -> Formula | None:
    """The path formula of an LTL property ``A φ`` (or of a bare path formula ``φ``):
    ``φ`` when no quantifier occurs inside it, else ``None``."""
    body = f.path if isinstance(f, All) else f
    if any(isinstance(n, QUANTIFIERS) for n in walk(body)):
        return None
    return body
