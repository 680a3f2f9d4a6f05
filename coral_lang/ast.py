"""The syntax tree of a CORAL mission. Every node keeps the span of the text that made it.

Spans are excluded from equality, so two trees compare equal when they say the same
thing, wherever it was written: the printer's round-trip test relies on that. Nodes
are slotted, not frozen: a large mission has a hundred thousand of them, and frozen
dataclasses cost three times as much to build. Nothing mutates a tree once parsed.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

from coral_lang.diagnostics import Span

_NOWHERE = Span("<generated>", 0, 0, 0, 0)


@dataclass(slots=True)
class Number:
    """A numeric literal, possibly with a unit: ``2.0``, ``250 cm``, ``-3``."""

    value: int | float
    unit: str | None = None
    span: Span = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(slots=True)
class String:
    """A string literal."""

    value: str
    span: Span = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(slots=True)
class Name:
    """A reference to a constant by name."""

    name: str
    span: Span = field(default=_NOWHERE, compare=False, repr=False)


Value = Number | String | Name


@dataclass(slots=True)
class TokenRef:
    """A place with an optional arc weight or token count: ``p`` or ``p*2``."""

    place: str
    weight: Number | Name | None = None
    span: Span = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(slots=True)
class Const:
    """``const NAME = value``."""

    name: str
    value: Number | String
    span: Span = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(slots=True)
class PlaceDecl:
    """One place of a ``place`` statement: ``name [= tokens] [capacity k]``."""

    name: str
    initial: Number | Name | None = None
    capacity: Number | Name | None = None
    span: Span = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(slots=True)
class Places:
    """``place a, b = 2, c capacity 3``."""

    places: tuple[PlaceDecl, ...]
    span: Span = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(slots=True)
class Final:
    """``final { p, q*2 }``: a proper end of the mission."""

    tokens: tuple[TokenRef, ...]
    span: Span = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(slots=True)
class Arg:
    """A command argument, positional (``name`` None) or named."""

    name: str | None
    value: Value
    span: Span = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(slots=True)
class ReplyMap:
    """``reply: place``, ``reply: { a, b }`` or ``reply: ignore`` (``targets`` None)."""

    reply: str
    targets: tuple[TokenRef, ...] | None
    span: Span = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(slots=True)
class Action:
    """``SYSTEM(COMMAND, args...) -> { reply: place, ... }``."""

    system: str
    command: str
    args: tuple[Arg, ...]
    replies: tuple[ReplyMap, ...]
    span: Span = field(default=_NOWHERE, compare=False, repr=False)
    command_span: Span = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(slots=True)
class TransitionDecl:
    """``transition NAME [priority N]`` with ``wait``, optional ``action``, ``signal``."""

    name: str
    priority: Number | Name | None = None
    wait: tuple[TokenRef, ...] = ()
    action: Action | None = None
    signal: tuple[TokenRef, ...] = ()
    span: Span = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(slots=True)
class Include:
    """``include "other.coral"``."""

    path: str
    span: Span = field(default=_NOWHERE, compare=False, repr=False)


class AssertKind(enum.Enum):
    """Which property an ``assert`` states."""

    NEVER = "never"
    REACHABLE = "reachable"
    BOUND = "bound"
    WITHIN = "within"


@dataclass(slots=True)
class AssertDecl:
    """``assert never {a, b}``, ``assert reachable {p}``, ``assert bound p <= k``,
    ``assert within 600 s {p}``.

    ``deadline`` (a time, or a constant's name) is set for ``within`` only; it comes
    last so that the positional form of the other kinds stays as it was.
    """

    kind: AssertKind
    tokens: tuple[TokenRef, ...]
    bound: Number | Name | None = None
    span: Span = field(default=_NOWHERE, compare=False, repr=False)
    deadline: Number | Name | None = None


# -- temporal properties -------------------------------------------------------------------
# The expressions of ``assert always/eventually/leadsto/ltl/ctl``: one tree for the three
# logics; the compiler checks that each operator belongs to the logic it is used in and
# lowers the tree to `coral_lang.formula`.


@dataclass(slots=True)
class Sum:
    """``p + q*2 + 1``: places (with weights) and whole numbers or integer constants. A
    `TokenRef` term may name a constant: the compiler decides, knowing the places."""

    terms: tuple[TokenRef | Number, ...]
    span: Span = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(slots=True)
class Comparison:
    """``left op right`` with ``op`` one of ``< <= == != >= >``."""

    left: Sum
    op: str
    right: Sum
    span: Span = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(slots=True)
class Word:
    """``true``, ``false``, ``deadlock`` or ``final``."""

    word: str
    span: Span = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(slots=True)
class TransitionRef:
    """A transition named in a property: ``check_depth``, or one of its replies,
    ``check_depth.timeout``."""

    name: str
    span: Span = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(slots=True)
class Call:
    """``in_flight(t, ...)``, ``fires(t, ...)`` or ``fireable(t, ...)``."""

    function: str
    transitions: tuple[TransitionRef, ...]
    span: Span = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(slots=True)
class Unary:
    """A prefix operator: ``not``, the LTL ``X F G``, the CTL ``AX AF AG EX EF EG``."""

    op: str
    arg: Expr
    span: Span = field(default=_NOWHERE, compare=False, repr=False)
    op_span: Span = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(slots=True)
class Binary:
    """An infix operator: ``and``, ``or`` (two or more ``args``), ``->``, ``U`` and
    ``leadsto`` (exactly two)."""

    op: str
    args: tuple[Expr, ...]
    span: Span = field(default=_NOWHERE, compare=False, repr=False)
    op_span: Span = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(slots=True)
class PathUntil:
    """The CTL ``A [ left U right ]`` or ``E [ left U right ]``."""

    quantifier: str
    left: Expr
    right: Expr
    span: Span = field(default=_NOWHERE, compare=False, repr=False)


Expr = TokenRef | Comparison | Word | Call | Unary | Binary | PathUntil
"""A property expression. A bare `TokenRef` ``p*k`` means "``p`` holds at least ``k``
tokens"."""


class TemporalKind(enum.Enum):
    """Which form a temporal ``assert`` has."""

    ALWAYS = "always"
    EVENTUALLY = "eventually"
    LEADSTO = "leadsto"
    LTL = "ltl"
    CTL = "ctl"


@dataclass(slots=True)
class TemporalAssert:
    """``assert always P``, ``assert eventually P``, ``assert P leadsto Q`` (``formula``
    is then the `Binary` ``leadsto``), ``assert ltl φ``, ``assert ctl φ``."""

    kind: TemporalKind
    formula: Expr
    span: Span = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(slots=True)
class Require:
    """``require termination``: what the mission demands of verification."""

    name: str
    span: Span = field(default=_NOWHERE, compare=False, repr=False)
    name_span: Span = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(slots=True)
class InputName:
    """One name of an ``input`` statement."""

    name: str
    span: Span = field(default=_NOWHERE, compare=False, repr=False)


@dataclass(slots=True)
class Inputs:
    """``input abort_requested, surface_now``: places only the operator marks, each at
    most once per run (see ``docs/language.md``, "Operator inputs")."""

    names: tuple[InputName, ...]
    span: Span = field(default=_NOWHERE, compare=False, repr=False)


Declaration = (
    Const
    | Places
    | Final
    | TransitionDecl
    | Include
    | AssertDecl
    | TemporalAssert
    | Require
    | Inputs
)


@dataclass(slots=True)
class Mission:
    """One source file: an optional header and its declarations."""

    name: str | None
    vehicle: str | None
    declarations: tuple[Declaration, ...]
    file: str = field(default="<mission>", compare=False)
    name_span: Span = field(default=_NOWHERE, compare=False, repr=False)
    vehicle_span: Span = field(default=_NOWHERE, compare=False, repr=False)
