"""Lower the temporal assertions of a mission to the shared formula tree.

``assert always P``, ``assert eventually P``, ``assert P leadsto Q`` and ``assert ltl
φ`` become LTL formulas ``A φ`` over the runs of the net; ``assert ctl φ`` a CTL
formula. ``docs/language.md`` gives the grammar and this table of atoms:

======================  ==============================================================
``p``, ``p*k``          ``p >= k`` (``k`` = 1 by default)
``p + q*2 <= 3``        `Compare` of `Tokens` with an `IntConst`; integer constants
                        are folded, so ``p + 1 <= N`` is ``p <= N - 1``
``in_flight(t, ...)``   the pending places of the commands summed ``>= 1``
``fires(t, ...)``       `Fires` (LTL only: an event, not a property of a marking)
``fireable(t, ...)``    `Fireable`
``final``               the marking is one of the declared final markings: each
                        place of a final holds exactly its tokens and every other
                        mission and pending place is empty (one `And`, an `Or` of
                        them when the mission declares several)
``deadlock``            `Deadlock`; ``true`` and ``false``: `Const`
``a -> b``              ``not a or b``
``P leadsto Q``         ``G (not P or F Q)``
======================  ==============================================================

Each operator is checked against the logic it is used in, with a diagnostic that says
how to write the property instead: a path quantifier in LTL, ``X F G U`` without one
in CTL, ``fires`` in CTL, a temporal operator in the state expression of ``always``,
``eventually`` or ``leadsto``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

from coral_lang import ast
from coral_lang import formula as fm
from coral_lang.diagnostics import Span, did_you_mean
from coral_lang.net import AssertKind

UNKNOWN = "CORAL002"
LOGIC = "CORAL008"

_TEMPORAL: dict[str, Callable[[fm.Formula], fm.Formula]] = {
    "X": fm.Next,
    "F": fm.Finally,
    "G": fm.Globally,
}

ErrorSink = Callable[..., None]
"""``error(code, message, span, *notes)``, as the compiler's."""

Counter = Callable[[ast.Number | ast.Name, str, int], int | None]
"""``count(value, what, minimum)``: a whole number from a literal or a constant, or
None after reporting why not (the compiler's ``_count``)."""


@dataclass(frozen=True)
class TransitionInfo:
    """What a property may say about one declared transition.

    Attributes:
        pending: its pending place when it sends a command (``t.pending``), else None.
        replies: the reply kinds of its command: each is a transition ``t.KIND``.
    """

    pending: str | None
    replies: tuple[str, ...]


@dataclass(frozen=True)
class Names:
    """The declarations a property is checked against.

    Attributes:
        places: the mission's places, in declaration order.
        constants: every declared constant's name.
        transitions: every declared transition.
        finals: the declared final markings.
        state_places: every place a final marking constrains (mission and pending).
    """

    places: Sequence[str]
    constants: frozenset[str]
    transitions: Mapping[str, TransitionInfo]
    finals: Sequence[tuple[tuple[str, int], ...]]
    state_places: Sequence[str]


class _Failed(Exception):
    """A sub-formula had an error (already reported); lowering goes on with siblings."""


class PropertyLowering:
    """Turns `ast.TemporalAssert` nodes into formulas, reporting every error."""

    def __init__(self, names: Names, count: Counter, error: ErrorSink) -> None:
        self.names = names
        self.count = count
        self.error = error
        self.place_set = frozenset(names.places)

    def lower(self, declaration: ast.TemporalAssert) -> tuple[AssertKind, fm.Formula] | None:
        """The logic and the formula of ``declaration``; None when it has errors."""
        kind = declaration.kind
        body = declaration.formula
        try:
            if kind is ast.TemporalKind.CTL:
                return AssertKind.CTL, self._lower(body, "ctl", "assert ctl")
            if kind is ast.TemporalKind.LTL:
                return AssertKind.LTL, fm.All(self._lower(body, "ltl", "assert ltl"))
            if kind is ast.TemporalKind.LEADSTO:
                assert isinstance(body, ast.Binary) and body.op == "leadsto"
                premise, goal = self._lower_all(body.args, "state", "leadsto")
                return AssertKind.LTL, fm.All(_leadsto(premise, goal))
            state = self._lower(body, "state", f"assert {kind.value}")
        except _Failed:
            return None
        if kind is ast.TemporalKind.ALWAYS:
            return AssertKind.LTL, fm.All(fm.Globally(state))
        return AssertKind.LTL, fm.All(fm.Finally(state))

    # -- the walk ---------------------------------------------------------------------

    def _lower_all(self, exprs: Sequence[ast.Expr], mode: str, where: str) -> list[fm.Formula]:
        """Every one of ``exprs``, reporting the errors of all before failing."""
        out: list[fm.Formula] = []
        failed = False
        for expr in exprs:
            try:
                out.append(self._lower(expr, mode, where))
            except _Failed:
                failed = True
        if failed:
            raise _Failed
        return out

    def _fail(self, code: str, message: str, span: Span, *notes: str) -> _Failed:
        self.error(code, message, span, *notes)
        return _Failed()

    def _lower(self, expr: ast.Expr, mode: str, where: str) -> fm.Formula:
        """``mode``: ``state`` (no temporal operator), ``ltl`` or ``ctl``."""
        if isinstance(expr, ast.TokenRef):
            self._place(expr)
            weight = 1
            if expr.weight is not None:
                counted = self.count(expr.weight, f"weight of '{expr.place}'", 1)
                if counted is None:
                    raise _Failed
                weight = counted
            return fm.Compare(fm.Tokens(((expr.place, 1),)), ">=", fm.IntConst(weight))
        if isinstance(expr, ast.Comparison):
            return self._comparison(expr)
        if isinstance(expr, ast.Word):
            return self._word(expr)
        if isinstance(expr, ast.Call):
            return self._call(expr, mode)
        if isinstance(expr, ast.Unary):
            return self._unary(expr, mode, where)
        if isinstance(expr, ast.PathUntil):
            if mode != "ctl":
                raise self._quantifier_outside_ctl(
                    f"{expr.quantifier} [ .. U .. ]", expr.span, mode, where
                )
            left, right = self._lower_all((expr.left, expr.right), mode, where)
            until = fm.Until(left, right)
            return fm.All(until) if expr.quantifier == "A" else fm.Exists(until)
        return self._binary(expr, mode, where)

    def _unary(self, expr: ast.Unary, mode: str, where: str) -> fm.Formula:
        op = expr.op
        if op == "not":
            return fm.Not(self._lower(expr.arg, mode, where))
        if op in _TEMPORAL:
            if mode == "state":
                raise self._temporal_in_state(op, expr.op_span, where)
            if mode == "ctl":
                raise self._fail(
                    LOGIC,
                    f"in CTL, '{op}' needs a path quantifier: write 'A{op}' (on every run) "
                    f"or 'E{op}' (on some run)",
                    expr.op_span,
                )
            return _TEMPORAL[op](self._lower(expr.arg, mode, where))
        if mode != "ctl":
            raise self._quantifier_outside_ctl(op, expr.op_span, mode, where)
        inner = _TEMPORAL[op[1]](self._lower(expr.arg, mode, where))
        return fm.All(inner) if op[0] == "A" else fm.Exists(inner)

    def _binary(self, expr: ast.Binary, mode: str, where: str) -> fm.Formula:
        op = expr.op
        if op in ("U", "leadsto") and mode == "state":
            raise self._temporal_in_state(op, expr.op_span, where)
        if op == "U" and mode == "ctl":
            raise self._fail(
                LOGIC,
                "in CTL, 'U' needs a path quantifier: write 'A [ P U Q ]' (on every run) "
                "or 'E [ P U Q ]' (on some run)",
                expr.op_span,
            )
        if op == "leadsto" and mode == "ctl":
            raise self._fail(
                LOGIC,
                "'leadsto' is LTL: in CTL write 'AG (P -> AF Q)'",
                expr.op_span,
                "or write the property as 'assert P leadsto Q'",
            )
        args = self._lower_all(expr.args, mode, where)
        if op == "and":
            return fm.And(tuple(args))
        if op == "or":
            return fm.Or(tuple(args))
        if op == "->":
            return fm.Or((fm.Not(args[0]), args[1]))
        if op == "U":
            return fm.Until(args[0], args[1])
        return _leadsto(args[0], args[1])

    def _temporal_in_state(self, op: str, span: Span, where: str) -> _Failed:
        if where == "leadsto":
            context = "the two sides of 'leadsto' are state expressions"
        else:
            context = f"'{where}' takes a state expression"
        hint = "write the whole property as 'assert ltl ...' (or 'assert ctl ...')"
        if op == "leadsto":
            hint = "'leadsto' is a form of its own: 'assert P leadsto Q'; or use 'assert ltl ...'"
        return self._fail(LOGIC, f"'{op}' is a temporal operator, but {context}", span, hint)

    def _quantifier_outside_ctl(self, op: str, span: Span, mode: str, where: str) -> _Failed:
        if mode == "state":
            return self._temporal_in_state(op, span, where)
        plain = f"'{op[1:]} ...'" if len(op) == 2 else "'P U Q'"
        return self._fail(
            LOGIC,
            f"'{op}' is a CTL path quantifier; an LTL formula already speaks of every run",
            span,
            f"write {plain} in LTL, or the property as 'assert ctl ...'",
        )

    # -- atoms ------------------------------------------------------------------------

    def _place(self, ref: ast.TokenRef) -> None:
        if ref.place in self.place_set:
            return
        if ref.place in self.names.constants:
            raise self._fail(
                LOGIC,
                f"'{ref.place}' is a constant, not a place: compare a place with it, "
                f"e.g. 'p >= {ref.place}'",
                ref.span,
            )
        raise self._fail(
            UNKNOWN,
            f"unknown place '{ref.place}'{did_you_mean(ref.place, self.names.places)}",
            ref.span,
        )

    def _sum(self, total: ast.Sum) -> tuple[dict[str, int], int]:
        """The places of ``total`` with their weights, and its constant part."""
        places: dict[str, int] = {}
        constant = 0
        failed = False
        for term in total.terms:
            if isinstance(term, ast.Number):
                constant += int(term.value)
                continue
            if term.place not in self.place_set and term.place in self.names.constants:
                if term.weight is not None:
                    self.error(LOGIC, f"constant '{term.place}' cannot take a weight", term.span)
                    failed = True
                    continue
                value = self.count(ast.Name(term.place, term.span), f"constant '{term.place}'", 0)
                if value is None:
                    failed = True
                else:
                    constant += value
                continue
            try:
                self._place(term)
            except _Failed:
                failed = True
                continue
            weight = 1
            if term.weight is not None:
                counted = self.count(term.weight, f"weight of '{term.place}'", 1)
                if counted is None:
                    failed = True
                    continue
                weight = counted
            places[term.place] = places.get(term.place, 0) + weight
        if failed:
            raise _Failed
        return places, constant

    def _comparison(self, expr: ast.Comparison) -> fm.Formula:
        try:
            left, left_const = self._sum(expr.left)
        except _Failed:
            self._sum(expr.right)  # report its errors too
            raise
        right, right_const = self._sum(expr.right)
        op = expr.op
        if not right:
            lhs: fm.IntExpr = _tokens(left) if left else fm.IntConst(left_const)
            return fm.Compare(lhs, op, fm.IntConst(right_const - (left_const if left else 0)))
        if not left:
            return fm.Compare(fm.IntConst(left_const - right_const), op, _tokens(right))
        if left_const != right_const:
            raise self._fail(
                LOGIC,
                "a comparison of places with places cannot also add numbers",
                expr.span,
                "compare each side with a number, or the places alone ('p <= q + r')",
            )
        return fm.Compare(_tokens(left), op, _tokens(right))

    def _word(self, expr: ast.Word) -> fm.Formula:
        if expr.word in ("true", "false"):
            return fm.Const(expr.word == "true")
        if expr.word == "deadlock":
            return fm.Deadlock()
        finals = self.names.finals
        if not finals:
            raise self._fail(
                LOGIC,
                "'final' means a declared final marking, and this mission declares none",
                expr.span,
                "declare the proper ends with 'final { ... }'",
            )
        options = [self._final(tokens) for tokens in finals]
        return options[0] if len(options) == 1 else fm.Or(tuple(options))

    def _final(self, tokens: tuple[tuple[str, int], ...]) -> fm.Formula:
        named = dict(tokens)
        parts: list[fm.Formula] = [
            fm.Compare(fm.Tokens(((p, 1),)), "==", fm.IntConst(k)) for p, k in tokens
        ]
        rest = tuple((p, 1) for p in self.names.state_places if p not in named)
        if rest:
            parts.append(fm.Compare(fm.Tokens(rest), "==", fm.IntConst(0)))
        return parts[0] if len(parts) == 1 else fm.And(tuple(parts))

    def _call(self, expr: ast.Call, mode: str) -> fm.Formula:
        function = expr.function
        if function == "fires" and mode == "ctl":
            raise self._fail(
                LOGIC,
                "'fires' is an event of a run, which CTL cannot see: CTL speaks of markings",
                expr.span,
                "use 'fireable(...)' (the transition is enabled), or write the property "
                "as 'assert ltl ...'",
            )
        names: list[str] = []
        failed = False
        for ref in expr.transitions:
            name = self._transition(ref, function)
            if name is None:
                failed = True
            else:
                names.append(name)
        if failed:
            raise _Failed
        if function == "in_flight":
            pending = []
            for name in dict.fromkeys(names):
                place = self.names.transitions[name].pending
                assert place is not None
                pending.append((place, 1))
            return fm.Compare(fm.Tokens(tuple(pending)), ">=", fm.IntConst(1))
        unique = tuple(dict.fromkeys(names))
        return fm.Fires(unique) if function == "fires" else fm.Fireable(unique)

    def _transition(self, ref: ast.TransitionRef, function: str) -> str | None:
        """The net's name for ``ref`` after checking it, or None (reported)."""
        transitions = self.names.transitions
        base, _, reply = ref.name.partition(".")
        info = transitions.get(base)
        if info is None:
            known = list(transitions)
            if reply:
                known += [f"{t}.{r}" for t, i in transitions.items() for r in i.replies]
            self.error(
                UNKNOWN,
                f"unknown transition '{ref.name}'{did_you_mean(ref.name, known)}",
                ref.span,
            )
            return None
        if function == "in_flight":
            if reply:
                self.error(
                    LOGIC,
                    f"in_flight takes the transition that sends a command, "
                    f"'in_flight({base})', not one of its replies",
                    ref.span,
                )
                return None
            if info.pending is None:
                self.error(
                    LOGIC,
                    f"transition '{base}' sends no command, so nothing of it is ever in flight",
                    ref.span,
                    "in_flight takes a transition with an 'action'",
                )
                return None
            return base
        if reply and reply not in info.replies:
            if info.pending is None:
                self.error(
                    UNKNOWN,
                    f"transition '{base}' sends no command, so it has no reply '{reply}'",
                    ref.span,
                )
            else:
                self.error(
                    UNKNOWN,
                    f"transition '{base}' has no reply '{reply}'"
                    f"{did_you_mean(reply, info.replies)}",
                    ref.span,
                    f"its replies: {', '.join(info.replies)}",
                )
            return None
        return ref.name


def _tokens(places: dict[str, int]) -> fm.Tokens:
    return fm.Tokens(tuple(places.items()))


def _leadsto(premise: fm.Formula, goal: fm.Formula) -> fm.Formula:
    """``G (P -> F Q)``."""
    return fm.Globally(fm.Or((fm.Not(premise), fm.Finally(goal))))
