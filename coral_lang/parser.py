"""Recursive-descent parser for CORAL missions, with error recovery.

A syntax error is recorded and the parser skips to the next statement keyword, so
one run reports every error of a file. The grammar is in ``docs/language.md``.
"""

from __future__ import annotations

from coral_lang import ast, units
from coral_lang.diagnostics import Diagnostic, Severity, Span, did_you_mean
from coral_lang.gcpause import cyclic_gc_paused
from coral_lang.lexer import KEYWORDS, STATEMENT_KEYWORDS, Kind, Token, tokenize


class _SyntaxError(Exception):
    """Internal: unwinds to the statement loop, which resynchronises."""


def parse(text: str, file: str = "<mission>") -> tuple[ast.Mission, list[Diagnostic]]:
    """Parse mission ``text``; returns the tree (possibly partial) and all diagnostics."""
    with cyclic_gc_paused():
        tokens, diagnostics = tokenize(text, file)
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
            if token.text in ("wait", "action", "signal", "priority"):
                raise self.error(
                    f"'{token.text}' must belong to a transition; start one with 'transition NAME'"
                )
        raise self.error(
            f"expected a declaration (const, place, final, transition, include, assert), "
            f"found {token.describe()}"
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

    def number(self, context: str) -> ast.Number:
        minus = self.accept(Kind.MINUS)
        if not (self.at(Kind.INT) or self.at(Kind.FLOAT)):
            raise self.error(f"expected a number {context}, found {self.tok.describe()}")
        token = self.advance()
        value: int | float = int(token.text) if token.kind is Kind.INT else float(token.text)
        if minus is not None:
            value = -value
        start = minus.span if minus is not None else token.span
        unit = self.unit(token)
        return ast.Number(value, unit, _join(start, self.previous))

    def unit(self, number: Token) -> str | None:
        """A unit written right after a number on the same line (``2.0 m``, ``0.5 m/s``)."""
        token = self.tok
        if (
            token.kind is not Kind.IDENT
            or token.span.line != number.span.line
            or token.text in KEYWORDS
        ):
            return None
        name = token.text
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

    def count(self, context: str) -> ast.Number | ast.Name:
        """A token count, weight or bound: a number or a constant's name."""
        if self.tok.kind is Kind.IDENT and self.tok.text not in KEYWORDS:
            token = self.advance()
            return ast.Name(token.text, token.span)
        return self.number(context)

    def places(self) -> ast.Places:
        keyword = self.advance()
        decls = [self.place_decl()]
        while self.accept(Kind.COMMA):
            decls.append(self.place_decl())
        return ast.Places(tuple(decls), _join(keyword, self.previous))

    def place_decl(self) -> ast.PlaceDecl:
        name = self.ident("a place name")
        initial = capacity = None
        if self.accept(Kind.EQUALS):
            initial = self.count(f"as the initial tokens of '{name.text}'")
        if self.accept(Kind.IDENT, "capacity"):
            capacity = self.count(f"as the capacity of '{name.text}'")
        return ast.PlaceDecl(name.text, initial, capacity, _join(name, self.previous))

    def token_set(self, context: str) -> tuple[ast.TokenRef, ...]:
        """``{ p, q*2 }`` (possibly empty)."""
        self.expect(Kind.LBRACE, context)
        refs: list[ast.TokenRef] = []
        if self.tok.kind is not Kind.RBRACE:
            refs.append(self.token_ref())
            while self.tok.kind is Kind.COMMA:
                self.advance()
                refs.append(self.token_ref())
        self.expect(Kind.RBRACE, "to close the place set (places are separated by ',')")
        return tuple(refs)

    def token_ref(self) -> ast.TokenRef:
        name = self.tok
        if name.kind is Kind.IDENT and name.text not in KEYWORDS and name.text[-1] != "?":
            self.advance()  # the common case, without ident()'s checks and messages
        else:
            name = self.ident("a place name")
        weight = None
        if self.tok.kind is Kind.STAR:
            self.advance()
            weight = self.count(f"as the weight of '{name.text}'")
        return ast.TokenRef(name.text, weight, _join(name, self.previous))

    def final(self) -> ast.Final:
        keyword = self.advance()
        tokens = self.token_set("after 'final'")
        return ast.Final(tokens, _join(keyword, self.previous))

    def include(self) -> ast.Include:
        keyword = self.advance()
        path = self.expect(Kind.STRING, "after 'include' (a file name in double quotes)")
        return ast.Include(path.text, _join(keyword, path))

    def assertion(self) -> ast.AssertDecl:
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
        raise self.error(
            f"expected 'never', 'reachable' or 'bound' after 'assert', "
            f"found {kind_token.describe()}"
        )

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
        while self.accept(Kind.COMMA):
            args.append(self.arg())
        self.expect(Kind.RPAREN, "to close the command's arguments")
        self.expect(Kind.ARROW, "after the command: map its replies with '-> { reply: place }'")
        self.expect(Kind.LBRACE, "after '->'")
        replies: list[ast.ReplyMap] = []
        if not self.at(Kind.RBRACE):
            replies.append(self.reply_map())
            while self.accept(Kind.COMMA):
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
        value = self.value("as an argument")
        return ast.Arg(name, value, _join(start, self.previous))

    def value(self, context: str) -> ast.Value:
        if self.at(Kind.STRING):
            token = self.advance()
            return ast.String(token.text, token.span)
        if self.tok.kind is Kind.IDENT and self.tok.text not in KEYWORDS:
            token = self.ident("a constant name")
            return ast.Name(token.text, token.span)
        return self.number(context)

    def reply_map(self) -> ast.ReplyMap:
        reply = self.ident("a reply kind, e.g. done")
        self.expect(Kind.COLON, f"after reply kind '{reply.text}'")
        targets: tuple[ast.TokenRef, ...] | None
        if self.accept(Kind.IDENT, "ignore"):
            targets = None
        elif self.at(Kind.LBRACE):
            targets = self.token_set(f"after '{reply.text}:'")
        else:
            targets = (self.token_ref(),)
        return ast.ReplyMap(reply.text, targets, _join(reply, self.previous))
