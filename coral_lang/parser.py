"""Recursive-descent parser for CORAL missions, with error recovery.

A syntax error is recorded and the parser skips to the next statement keyword, so
one run reports every error of a file. A ',' missing after a number in a list is the
exception: it is recorded and the list goes on (`_Parser.missing_comma`), so what
follows is not lost and the compiler reports nothing more about it. The grammar is in
``docs/language.md``.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from coral_lang import ast, units
from coral_lang.diagnostics import Diagnostic, Severity, Span, did_you_mean
from coral_lang.gcpause import cyclic_gc_paused
from coral_lang.lexer import KEYWORDS, STATEMENT_KEYWORDS, Kind, Token, tokenize
from coral_lang.printer import format_expr

MAX_WHOLE = 2**63 - 1
"""Largest whole number a mission may write: counts and weights are 64-bit integers in
the engines and in PNML exports, and larger ones are never meant."""

MAX_ERRORS = 99
"""Diagnostics after which the parser gives up on a file: a file with that many syntax
errors is not a mission, and going on only costs time and memory. One below the 100
diagnostics `render_all` shows per file, so the "stopped" note is always shown."""

_TEMPORAL_KINDS = ("always", "eventually", "ltl", "ctl")
_ASSERT_KINDS = ("never", "reachable", "bound", "within", *_TEMPORAL_KINDS)
_PREFIX_OPERATORS = frozenset({"X", "F", "G", "AX", "AF", "AG", "EX", "EF", "EG"})
_FUNCTIONS = ("in_flight", "fires", "fireable")
_COMPARISONS = {
    Kind.LT: "<",
    Kind.LE: "<=",
    Kind.EQEQ: "==",
    Kind.NE: "!=",
    Kind.GE: ">=",
    Kind.GT: ">",
}
# The comma-separated lists a missing ',' is recognised in, each with the token that
# must follow a name for it to start the next item (None: the name alone does).
_LIST_FOLLOW: dict[str, Kind | None] = {
    "places": None,
    "arguments": Kind.EQUALS,
    "replies": Kind.COLON,
}
_UNIT_HINT = " (or a unit after the number: s, min, ...)"
# Tokens that can follow a place name inside a state expression.
_CONTINUES_TERM = frozenset(
    {*_COMPARISONS, Kind.STAR, Kind.PLUS, Kind.ARROW, Kind.EQUALS, Kind.DOT}
)


class _SyntaxError(Exception):
    """Internal: unwinds to the statement loop, which resynchronises."""


def parse(text: str, file: str = "<mission>") -> tuple[ast.Mission, list[Diagnostic]]:
    """Parse mission ``text``; returns the tree (possibly partial) and all diagnostics."""
    with cyclic_gc_paused():
        tokens, diagnostics = tokenize(text, file)
        return parse_tokens(tokens, file, diagnostics)


def parse_tokens(
    tokens: list[Token], file: str, diagnostics: list[Diagnostic]
) -> tuple[ast.Mission, list[Diagnostic]]:
    """Parse tokens `tokenize` made (``diagnostics`` are its own, extended in place).

    For callers that lex for themselves: the formatter lexes once, keeping comments.
    """
    parser = _Parser(tokens, file, diagnostics)
    return parser.mission(), parser.diagnostics


def _join(a: Span | Token, b: Span | Token) -> Span:
    """The span from the start of ``a`` to the end of ``b`` (tokens or spans)."""
    # tuple.__new__: a named tuple's own constructor costs twice as much, per tree node
    return tuple.__new__(Span, (a.file, a.line, a.col, b.end_line, b.end_col))


class _Parser:
    def __init__(self, tokens: list[Token], file: str, diagnostics: list[Diagnostic]) -> None:
        self.tokens = tokens
        self.pos = 0
        self.file = file
        self.diagnostics = diagnostics
        # The current and previous token are plain attributes, not properties: they are
        # read several times per token, and that dominated parsing of large missions.
        self.tok: Token = tokens[0]
        self.previous: Token = tokens[0]
        # Where the property expression being parsed stands, for errors ("" outside one).
        self._context = ""
        # The position just after the last number (and unit) read, for `missing_comma`.
        self._number_end = -1

    # -- token helpers ----------------------------------------------------------------

    def advance(self) -> Token:
        token = self.tok
        if token.kind is not Kind.EOF:
            self.pos += 1
            self.previous = token
            self.tok = self.tokens[self.pos]
        return token

    def at(self, kind: Kind, text: str | None = None) -> bool:
        token = self.tok
        return token.kind is kind and (text is None or token.text == text)

    def at_keyword(self, word: str) -> bool:
        return self.at(Kind.IDENT, word)

    def accept(self, kind: Kind, text: str | None = None) -> Token | None:
        token = self.tok
        if token.kind is kind and (text is None or token.text == text):
            # advance() inlined: this runs for most tokens (never with kind EOF)
            self.pos += 1
            self.previous = token
            self.tok = self.tokens[self.pos]
            return token
        return None

    def error(
        self, message: str, span: Span | None = None, notes: tuple[str, ...] = ()
    ) -> _SyntaxError:
        if self.tok.kind is Kind.ERROR and span is None:
            return _SyntaxError()  # the lexer reported this spot already
        self.diagnostics.append(
            Diagnostic(Severity.ERROR, "CORAL001", message, span or self.tok.span, notes)
        )
        return _SyntaxError()

    def expect(self, kind: Kind, context: str) -> Token:
        token = self.tok
        if token.kind is kind:
            # advance() inlined: this runs for most tokens (never with kind EOF)
            self.pos += 1
            self.previous = token
            self.tok = self.tokens[self.pos]
            return token
        raise self.error(f"expected {kind.value} {context}, found {token.describe()}")

    def ident(self, what: str, *, allow_query: bool = False) -> Token:
        token = self.tok
        if token.kind is not Kind.IDENT:
            raise self.error(f"expected {what}, found {token.describe()}")
        if token.text in KEYWORDS:
            raise self.error(
                f"expected {what}, found keyword '{token.text}' (keywords are reserved)"
            )
        if token.text.endswith("?") and not allow_query:
            raise self.error(
                f"'?' is only allowed at the end of a command name, not in {what} '{token.text}'"
            )
        return self.advance()

    def missing_comma(self, items: str, *, same_line: bool = True, unit_hint: bool = True) -> bool:
        """Whether a list of ``items`` goes on after a missing ','; reports it if so.

        ``place start = 1 done`` means two places: read as a unit, ``done`` gave
        "unknown unit" and, the whole statement lost, an "unknown place" at every use
        of ``start`` and ``done``. A name that can start the next item, right after a
        number (and its unit) that ended an item, on the same line unless the list is in
        braces, is one error at the name, and the list goes on as if the comma were
        there, so nothing after it is lost. A name after a name stays the error it was:
        nothing says which of the two is the mistake. A constant's name as a count
        (``place start = N done``) ends an item as a number does. ``unit_hint`` False:
        the number was a weight, which never takes a unit, so the hint would mislead.
        """
        token = self.tok
        if (
            self._number_end != self.pos
            or token.kind is not Kind.IDENT
            or token.text in KEYWORDS
            or (same_line and token.line != self.previous.end_line)
        ):
            return False
        follow = _LIST_FOLLOW[items]
        if follow is not None and self.tokens[self.pos + 1].kind is not follow:
            return False
        numeric = self.previous.kind in (Kind.INT, Kind.FLOAT)
        hint = _UNIT_HINT if unit_hint and numeric else ""
        self.diagnostics.append(
            Diagnostic(
                Severity.ERROR, "CORAL001", f"expected ',' between {items}{hint}", token.span
            )
        )
        return True

    def synchronise(self, start: int) -> None:
        """Skip to the next statement keyword (or end of file) after position ``start``."""
        if self.pos == start:
            self.advance()
        while not self.at(Kind.EOF) and not (
            self.tok.kind is Kind.IDENT and self.tok.text in STATEMENT_KEYWORDS
        ):
            self.advance()

    # -- grammar ------------------------------------------------------------------------

    def mission(self) -> ast.Mission:
        name: str | None = None
        vehicle: str | None = None
        name_span = vehicle_span = Span(self.file, 1, 1, 1, 1)
        declarations: list[ast.Declaration] = []
        while not self.at(Kind.EOF):
            if len(self.diagnostics) >= MAX_ERRORS:
                self.diagnostics.append(
                    Diagnostic(
                        Severity.ERROR,
                        "CORAL001",
                        f"{len(self.diagnostics)} errors: stopped reading the file here",
                        self.tok.span,
                    )
                )
                break
            start = self.pos
            try:
                if self.at_keyword("mission"):
                    keyword = self.advance()
                    token = self.ident("a mission name")
                    if name is not None or declarations:
                        self.diagnostics.append(
                            Diagnostic(
                                Severity.ERROR,
                                "CORAL001",
                                "'mission' must come first, once per file",
                                keyword.span,
                            )
                        )
                    name, name_span = token.text, _join(keyword, token)
                elif self.at_keyword("vehicle"):
                    keyword = self.advance()
                    token = self.ident("a vehicle name")
                    if vehicle is not None:
                        self.diagnostics.append(
                            Diagnostic(
                                Severity.ERROR, "CORAL001", "'vehicle' given twice", keyword.span
                            )
                        )
                    vehicle, vehicle_span = token.text, _join(keyword, token)
                else:
                    declarations.append(self.declaration())
            except _SyntaxError:
                self.synchronise(start)
            if self.pos == start:  # no progress: never loop forever on bad input
                self.advance()
        return ast.Mission(
            name=name,
            vehicle=vehicle,
            declarations=tuple(declarations),
            file=self.file,
            name_span=name_span,
            vehicle_span=vehicle_span,
        )

    def declaration(self) -> ast.Declaration:
        token = self.tok
        if token.kind is Kind.IDENT:
            word = token.text
            if word == "const":
                return self.const()
            if word == "place":
                return self.places()
            if word == "final":
                return self.final()
            if word == "transition":
                return self.transition()
            if word == "include":
                return self.include()
            if word == "assert":
                return self.assertion()
            if word == "require":
                return self.require()
            if word == "input":
                return self.inputs()
            if token.text in ("wait", "action", "signal", "priority"):
                raise self.error(
                    f"'{token.text}' must belong to a transition; start one with 'transition NAME'"
                )
        raise self.error(
            "expected a declaration (const, place, final, transition, include, assert, "
            f"require, input), found {token.describe()}"
        )

    def const(self) -> ast.Const:
        keyword = self.advance()
        name = self.ident("a constant name")
        self.expect(Kind.EQUALS, f"after 'const {name.text}'")
        value: ast.Number | ast.String
        if self.at(Kind.STRING):
            token = self.advance()
            value = ast.String(token.text, token.span)
        else:
            value = self.number(f"as the value of '{name.text}'")
        return ast.Const(name.text, value, _join(keyword, self.previous))

    def number(self, context: str, items: str = "") -> ast.Number:
        minus = self.accept(Kind.MINUS)
        if not (self.at(Kind.INT) or self.at(Kind.FLOAT)):
            raise self.error(f"expected a number {context}, found {self.tok.describe()}")
        token = self.tok
        value = self.numeric(token)
        self.advance()
        if minus is not None:
            value = -value
        start = minus.span if minus is not None else token.span
        unit = self.unit(token, items)
        self._number_end = self.pos
        return ast.Number(value, unit, _join(start, self.previous))

    def numeric(self, token: Token) -> int | float:
        """The value of number ``token``, refused (at the token) when out of range.

        Whole numbers are token counts, weights, priorities or parameters, all stored as
        64-bit integers by the engines and in PNML; a float that overflows to infinity
        (``1e400``) would silently compare larger than any bound.
        """
        if token.kind is Kind.INT:
            whole = int(token.text)  # the lexer caps the length, so this is cheap
            if whole > MAX_WHOLE:
                raise self.error(
                    f"number too large: {token.text} (at most {MAX_WHOLE})", token.span
                )
            return whole
        real = float(token.text)
        if not math.isfinite(real):
            raise self.error(f"number out of range: {token.text}", token.span)
        return real

    def unit(self, number: Token, items: str = "") -> str | None:
        """A unit written right after a number on the same line (``2.0 m``, ``0.5 m/s``).

        Inside a list of ``items``, a name that is no unit but can start the next item
        is left for `missing_comma` to report.
        """
        token = self.tok
        if (
            token.kind is not Kind.IDENT
            or token.line != number.line
            or token.text in KEYWORDS
            or self._context  # token counts in a property have no unit: 'p*2 U q'
        ):
            return None
        name = token.text
        if items and not units.is_unit(name):
            follow = self.tokens[self.pos + 1].kind
            wanted = _LIST_FOLLOW[items]
            if follow is not Kind.SLASH and (wanted is None or follow is wanted):
                return None
        self.advance()
        if self.at(Kind.SLASH):
            self.advance()
            name += "/" + self.ident("a unit after '/'").text
        if not units.is_unit(name):
            raise self.error(
                f"unknown unit '{name}'{did_you_mean(name, units.UNITS)}",
                _join(token, self.previous),
                (f"known units: {', '.join(units.UNITS)}",),
            )
        return name

    def count(self, context: str, items: str = "") -> ast.Number | ast.Name:
        """A token count, weight or bound: a number or a constant's name."""
        if self.tok.kind is Kind.IDENT and self.tok.text not in KEYWORDS:
            token = self.advance()
            self._number_end = self.pos  # a name ends an item as a number does
            return ast.Name(token.text, token.span)
        return self.number(context, items)

    def places(self) -> ast.Places:
        keyword = self.advance()
        decls = [self.place_decl()]
        while self.accept(Kind.COMMA) or self.missing_comma("places"):
            decls.append(self.place_decl())
        return ast.Places(tuple(decls), _join(keyword, self.previous))

    def inputs(self) -> ast.Inputs:
        keyword = self.advance()
        names = [self._input_name()]
        while self.accept(Kind.COMMA):
            names.append(self._input_name())
        return ast.Inputs(tuple(names), _join(keyword, self.previous))

    def _input_name(self) -> ast.InputName:
        token = self.ident("an operator input name, e.g. 'input abort_requested'")
        return ast.InputName(token.text, token.span)

    def place_decl(self) -> ast.PlaceDecl:
        name = self.ident("a place name")
        initial = capacity = None
        if self.accept(Kind.EQUALS):
            initial = self.count(f"as the initial tokens of '{name.text}'", "places")
        if self.accept(Kind.IDENT, "capacity"):
            capacity = self.count(f"as the capacity of '{name.text}'", "places")
        return ast.PlaceDecl(name.text, initial, capacity, _join(name, self.previous))

    def token_set(self, context: str) -> tuple[ast.TokenRef, ...]:
        """``{ p, q*2 }`` (possibly empty)."""
        self.expect(Kind.LBRACE, context)
        refs: list[ast.TokenRef] = []
        if self.tok.kind is not Kind.RBRACE:
            refs.append(self.token_ref("places"))
            while self.tok.kind is Kind.COMMA or (
                self.tok.kind is Kind.IDENT
                and self.missing_comma("places", same_line=False, unit_hint=False)
            ):
                self.accept(Kind.COMMA)
                refs.append(self.token_ref("places"))
        self.expect(Kind.RBRACE, "to close the place set (places are separated by ',')")
        return tuple(refs)

    def token_ref(self, items: str = "") -> ast.TokenRef:
        name = self.tok
        if name.kind is Kind.IDENT and name.text not in KEYWORDS and name.text[-1] != "?":
            self.advance()  # the common case, without ident()'s checks and messages
        else:
            name = self.ident("a place name")
        weight = None
        if self.tok.kind is Kind.STAR:
            self.advance()
            weight = self.count(f"as the weight of '{name.text}'", items)
        return ast.TokenRef(name.text, weight, _join(name, self.previous))

    def final(self) -> ast.Final:
        keyword = self.advance()
        tokens = self.token_set("after 'final'")
        return ast.Final(tokens, _join(keyword, self.previous))

    def include(self) -> ast.Include:
        keyword = self.advance()
        path = self.expect(Kind.STRING, "after 'include' (a file name in double quotes)")
        return ast.Include(path.text, _join(keyword, path))

    def assertion(self) -> ast.AssertDecl | ast.TemporalAssert:
        keyword = self.advance()
        kind_token = self.tok
        if self.at_keyword("never") or self.at_keyword("reachable"):
            self.advance()
            tokens = self.token_set(f"after 'assert {kind_token.text}'")
            return ast.AssertDecl(
                ast.AssertKind(kind_token.text),
                tokens,
                None,
                _join(keyword, self.previous),
            )
        if self.at_keyword("bound"):
            self.advance()
            if self.at(Kind.LBRACE):
                tokens = self.token_set("after 'assert bound'")
            else:
                tokens = (self.token_ref(),)
            self.expect(Kind.LE, "in 'assert bound PLACE <= N'")
            bound = self.count("as the bound")
            return ast.AssertDecl(
                ast.AssertKind.BOUND, tokens, bound, _join(keyword, self.previous)
            )
        if self.at_keyword("within") and self._starts_within():
            return self.within(keyword)
        if kind_token.kind is Kind.IDENT and kind_token.text in _TEMPORAL_KINDS:
            self.advance()
            formula = self.expression(f"after 'assert {kind_token.text}'")
            return ast.TemporalAssert(
                ast.TemporalKind(kind_token.text), formula, _join(keyword, self.previous)
            )
        if self._starts_leadsto():
            formula = self.expression("after 'assert'")
            if isinstance(formula, ast.Binary) and formula.op == "leadsto":
                return ast.TemporalAssert(
                    ast.TemporalKind.LEADSTO, formula, _join(keyword, self.previous)
                )
            raise self.error(
                f"expected 'leadsto' after 'assert {format_expr(formula)}', found "
                f"{self.tok.describe()}",
                None,
                (
                    "a state expression alone is no property: write 'assert always P', "
                    "'assert eventually P' or 'assert P leadsto Q'",
                ),
            )
        hint = ""
        if kind_token.kind is Kind.IDENT:
            hint = did_you_mean(kind_token.text, _ASSERT_KINDS)
        raise self.error(
            "expected 'never', 'reachable', 'bound', 'within', 'always', 'eventually', 'ltl', "
            f"'ctl' or 'P leadsto Q' after 'assert', found {kind_token.describe()}{hint}"
        )

    def _starts_within(self) -> bool:
        """Whether ``within`` after ``assert`` starts a deadline (``assert within 600 s
        { done }``) rather than name a place in ``assert within leadsto done``.

        ``within`` is not reserved (a mission may have a place of that name, and did
        before the deadline existed), so the token after it decides: one that continues
        a state expression makes it a place; anything else (a number, a constant's
        name, ``{``, the end) makes it a deadline, and a missing duration is reported
        as such rather than as a bad property.
        """
        follow = self.tokens[self.pos + 1]
        if follow.kind is Kind.IDENT:
            return follow.text not in ("leadsto", "and", "or")
        return follow.kind not in _CONTINUES_TERM and follow.kind is not Kind.LPAREN

    def within(self, keyword: Token) -> ast.AssertDecl:
        """``assert within DURATION { p, q*2 }``: the deadline is a time with its unit,
        or a constant's name; the compiler checks it is a positive time."""
        self.advance()  # 'within'
        token = self.tok
        if (
            token.kind is Kind.LBRACE
            or token.kind is Kind.EOF
            or (token.kind is Kind.IDENT and token.text in STATEMENT_KEYWORDS)
        ):
            raise self.error(
                f"expected a duration after 'assert within', found {token.describe()}",
                None,
                ("write the deadline before the places, e.g. 'assert within 600 s { done }'",),
            )
        deadline = self.count("as the deadline of 'assert within' (a time, e.g. 600 s)")
        tokens = self.token_set("after the deadline of 'assert within'")
        return ast.AssertDecl(
            ast.AssertKind.WITHIN, tokens, None, _join(keyword, self.previous), deadline
        )

    def _starts_leadsto(self) -> bool:
        """Whether the tokens after ``assert`` read as the start of ``P leadsto Q``
        rather than a misspelt assertion kind (``assert sometimes { a }``)."""
        token = self.tok
        if token.kind is Kind.LPAREN or token.kind is Kind.INT:
            return True
        if token.kind is not Kind.IDENT:
            return False
        if token.text in ("not", "true", "false", "deadlock", "final"):
            return True
        if token.text in KEYWORDS:
            return False
        follow = self.tokens[self.pos + 1]
        if follow.kind is Kind.IDENT:
            return follow.text in ("leadsto", "and", "or")
        return follow.kind in _CONTINUES_TERM or follow.kind is Kind.LPAREN

    def require(self) -> ast.Require:
        keyword = self.advance()
        name = self.ident("a requirement, e.g. 'require termination'")
        return ast.Require(name.text, _join(keyword, name), name.span)

    # -- property expressions (see docs/language.md for the precedence) ---------------------

    def expression(self, context: str) -> ast.Expr:
        """``implication [ "leadsto" implication ]``."""
        outer, self._context = self._context, context
        try:
            return self._leadsto()
        finally:
            self._context = outer

    def _leadsto(self) -> ast.Expr:
        left = self.implication()
        if self.at_keyword("leadsto"):
            op = self.advance()
            right = self.implication()
            if self.at_keyword("leadsto"):
                raise self.error("'leadsto' does not chain: parenthesise one side")
            return ast.Binary("leadsto", (left, right), _join(left.span, right.span), op.span)
        return left

    def implication(self, in_brackets: bool = False) -> ast.Expr:
        """``disjunction [ "->" implication ]`` (right-associative)."""
        left = self.disjunction(in_brackets)
        if self.tok.kind is Kind.ARROW:
            op = self.advance()
            right = self.implication(in_brackets)
            return ast.Binary("->", (left, right), _join(left.span, right.span), op.span)
        return left

    def disjunction(self, in_brackets: bool) -> ast.Expr:
        return self._chain("or", self.conjunction, in_brackets)

    def conjunction(self, in_brackets: bool) -> ast.Expr:
        return self._chain("and", self.until, in_brackets)

    def _chain(self, word: str, operand: Callable[[bool], ast.Expr], in_brackets: bool) -> ast.Expr:
        first = operand(in_brackets)
        args = [first]
        op_span = first.span
        while self.at_keyword(word):
            token = self.advance()
            if len(args) == 1:
                op_span = token.span
            args.append(operand(in_brackets))
        if len(args) == 1:
            return first
        return ast.Binary(word, tuple(args), _join(first.span, args[-1].span), op_span)

    def until(self, in_brackets: bool) -> ast.Expr:
        """``unary [ "U" until ]`` (right-associative); inside ``A [ .. ]`` the ``U`` at
        the bracket's own level separates the two sides instead."""
        left = self.unary()
        if not in_brackets and self.at_keyword("U"):
            op = self.advance()
            right = self.until(False)
            return ast.Binary("U", (left, right), _join(left.span, right.span), op.span)
        return left

    def unary(self) -> ast.Expr:
        token = self.tok
        if token.kind is Kind.IDENT:
            text = token.text
            if text == "not" or text in _PREFIX_OPERATORS:
                self.advance()
                arg = self.unary()
                return ast.Unary(text, arg, _join(token, arg.span), token.span)
            if text in ("A", "E"):
                follow = self.tokens[self.pos + 1]
                if follow.kind is Kind.IDENT and follow.text in ("X", "F", "G"):
                    self.advance()
                    self.advance()
                    arg = self.unary()
                    return ast.Unary(
                        text + follow.text, arg, _join(token, arg.span), _join(token, follow)
                    )
                if follow.kind is Kind.LBRACKET:
                    return self.path_until()
        return self.primary()

    def path_until(self) -> ast.PathUntil:
        quantifier = self.advance()
        self.advance()  # '['
        left = self.implication(in_brackets=True)
        if not self.at_keyword("U"):
            raise self.error(
                f"expected 'U' in '{quantifier.text} [ P U Q ]', found {self.tok.describe()}"
            )
        self.advance()
        right = self.implication()
        close = self.expect(Kind.RBRACKET, f"to close '{quantifier.text} [ P U Q'")
        return ast.PathUntil(quantifier.text, left, right, _join(quantifier, close))

    def primary(self) -> ast.Expr:
        token = self.tok
        if token.kind is Kind.LPAREN:
            self.advance()
            inner = self.expression(self._context)
            self.expect(Kind.RPAREN, "to close '('")
            return inner
        if token.kind is Kind.IDENT:
            text = token.text
            follow = self.tokens[self.pos + 1]
            if text in ("true", "false", "deadlock") or (
                text == "final" and follow.kind is not Kind.LBRACE
            ):
                self.advance()
                return ast.Word(text, token.span)
            if follow.kind is Kind.LPAREN and text not in KEYWORDS:
                return self.call()
        if (token.kind is Kind.IDENT and token.text not in KEYWORDS) or token.kind is Kind.INT:
            return self.comparison()
        raise self.error(f"expected a state expression {self._context}, found {token.describe()}")

    def call(self) -> ast.Call:
        name = self.advance()
        if name.text not in _FUNCTIONS:
            raise self.error(
                f"unknown function '{name.text}'{did_you_mean(name.text, _FUNCTIONS)}",
                name.span,
                (f"functions: {', '.join(_FUNCTIONS)}",),
            )
        self.advance()  # '('
        refs = [self.transition_ref(name.text)]
        while self.accept(Kind.COMMA):
            refs.append(self.transition_ref(name.text))
        close = self.expect(Kind.RPAREN, f"to close '{name.text}('")
        return ast.Call(name.text, tuple(refs), _join(name, close))

    def transition_ref(self, function: str) -> ast.TransitionRef:
        first = self.ident(f"a transition name in '{function}(...)'")
        text = first.text
        if self.accept(Kind.DOT):
            reply = self.ident(f"a reply kind after '{text}.'")
            text += "." + reply.text
        return ast.TransitionRef(text, _join(first, self.previous))

    def comparison(self) -> ast.Expr:
        left = self.sum()
        op = self.tok
        if op.kind in _COMPARISONS:
            self.advance()
            right = self.sum()
            return ast.Comparison(left, _COMPARISONS[op.kind], right, _join(left.span, right.span))
        if op.kind is Kind.EQUALS:
            raise self.error("'=' declares; write '==' to compare")
        if len(left.terms) == 1 and isinstance(left.terms[0], ast.TokenRef):
            return left.terms[0]
        raise self.error(
            f"expected a comparison ('<', '<=', '==', '!=', '>=', '>') after "
            f"'{format_expr(left)}', found {op.describe()}",
            None,
            ("a number or a sum is no property: compare it, e.g. 'p + q <= 3'",),
        )

    def sum(self) -> ast.Sum:
        terms = [self.term()]
        while self.accept(Kind.PLUS):
            terms.append(self.term())
        return ast.Sum(tuple(terms), _join(terms[0].span, terms[-1].span))

    def term(self) -> ast.TokenRef | ast.Number:
        token = self.tok
        if token.kind is Kind.INT:
            value = self.numeric(token)
            self.advance()
            return ast.Number(value, None, token.span)
        if token.kind is Kind.FLOAT or token.kind is Kind.MINUS:
            raise self.error(
                f"token counts are whole numbers of at least 0, found {token.describe()}"
            )
        ref = self.token_ref()
        if self.tok.kind is Kind.DOT and self.tokens[self.pos + 1].kind is Kind.IDENT:
            suffix = self.tokens[self.pos + 1]
            name = f"{ref.place}.{suffix.text}"
            if suffix.text == "pending":
                hint = f"write 'in_flight({ref.place})': its command awaits a reply"
            elif suffix.text == "free":
                hint = f"compare '{ref.place}' with its capacity instead"
            else:
                hint = f"a reply is an event: write 'fires({name})' or 'fireable({name})'"
            raise self.error(
                f"'{name}' is not a place a property can read; {hint}", _join(ref.span, suffix)
            )
        return ref

    def transition(self) -> ast.TransitionDecl:
        keyword = self.advance()
        name = self.ident("a transition name")
        header = _join(keyword, name)
        priority = None
        if self.accept(Kind.IDENT, "priority"):
            priority = self.count(f"as the priority of '{name.text}'")
        wait: tuple[ast.TokenRef, ...] | None = None
        signal: tuple[ast.TokenRef, ...] | None = None
        action: ast.Action | None = None
        while self.tok.kind is Kind.IDENT and self.tok.text in ("wait", "action", "signal"):
            clause = self.advance()
            if clause.text == "wait":
                if wait is not None:
                    raise self.error(
                        f"transition '{name.text}' has two 'wait' clauses; merge them", clause.span
                    )
                wait = self.token_set("after 'wait'")
            elif clause.text == "signal":
                if signal is not None:
                    raise self.error(
                        f"transition '{name.text}' has two 'signal' clauses; merge them",
                        clause.span,
                    )
                signal = self.token_set("after 'signal'")
            else:
                if action is not None:
                    raise self.error(
                        f"transition '{name.text}' has two actions; a transition sends one command",
                        clause.span,
                        (
                            "split it into two transitions, "
                            "or signal a place that starts the second",
                        ),
                    )
                action = self.action()
        if self.tok.kind is Kind.IDENT and self.tok.text == "priority":
            raise self.error(
                "'priority' is not a clause: it goes on the transition's line, "
                f"'transition {name.text} priority N'"
            )
        if self.tok.kind is Kind.IDENT and self.tok.text not in STATEMENT_KEYWORDS:
            clause_hint = did_you_mean(self.tok.text, ("wait", "action", "signal", "priority"))
            if clause_hint:
                raise self.error(f"unknown clause '{self.tok.text}'{clause_hint}")
        if wait is None and signal is None and action is None:
            raise self.error(
                f"transition '{name.text}' has no 'wait', 'action' or 'signal' clause",
                self.tok.span if self.tok.kind is not Kind.EOF else header,
            )
        return ast.TransitionDecl(name.text, priority, wait or (), action, signal or (), header)

    def action(self) -> ast.Action:
        open_brace = self.expect(Kind.LBRACE, "after 'action'")
        system = self.ident("a system name, e.g. ROMEO")
        self.expect(Kind.LPAREN, f"after '{system.text}'")
        command = self.ident("a command name", allow_query=True)
        args: list[ast.Arg] = []
        while self.accept(Kind.COMMA) or self.missing_comma("arguments"):
            args.append(self.arg())
        self.expect(Kind.RPAREN, "to close the command's arguments")
        self.expect(Kind.ARROW, "after the command: map its replies with '-> { reply: place }'")
        self.expect(Kind.LBRACE, "after '->'")
        replies: list[ast.ReplyMap] = []
        if not self.at(Kind.RBRACE):
            replies.append(self.reply_map())
            while self.accept(Kind.COMMA) or self.missing_comma(
                "replies", same_line=False, unit_hint=False
            ):
                replies.append(self.reply_map())
        self.expect(Kind.RBRACE, "to close the reply map")
        close = self.expect(Kind.RBRACE, "to close 'action {'")
        return ast.Action(
            system.text,
            command.text,
            tuple(args),
            tuple(replies),
            _join(open_brace, close),
            command.span,
        )

    def arg(self) -> ast.Arg:
        start = self.tok
        name: str | None = None
        if (
            self.tok.kind is Kind.IDENT
            and self.tokens[self.pos + 1].kind is Kind.EQUALS
            and self.tok.text not in KEYWORDS
        ):
            name = self.advance().text
            self.advance()
        value = self.value("as an argument", "arguments")
        return ast.Arg(name, value, _join(start, self.previous))

    def value(self, context: str, items: str = "") -> ast.Value:
        if self.at(Kind.STRING):
            token = self.advance()
            return ast.String(token.text, token.span)
        if self.tok.kind is Kind.IDENT and self.tok.text not in KEYWORDS:
            token = self.ident("a constant name")
            return ast.Name(token.text, token.span)
        return self.number(context, items)

    def reply_map(self) -> ast.ReplyMap:
        reply = self.ident("a reply kind, e.g. done")
        self.expect(Kind.COLON, f"after reply kind '{reply.text}'")
        targets: tuple[ast.TokenRef, ...] | None
        if self.accept(Kind.IDENT, "ignore"):
            targets = None
        elif self.at(Kind.LBRACE):
            targets = self.token_set(f"after '{reply.text}:'")
        else:
            targets = (self.token_ref("replies"),)
        return ast.ReplyMap(reply.text, targets, _join(reply, self.previous))
