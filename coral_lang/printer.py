"""Print a mission tree back as CORAL text, in the canonical layout.

``parse(format_mission(tree))`` gives back ``tree`` (spans aside): the property tests
hold the parser and printer to that. The printer knows nothing of comments or blank
lines: `coral_lang.formatting` lays out whole files with it and puts those back.
"""

from __future__ import annotations

from coral_lang import ast

INDENT = "    "
MAX_WIDTH = 100
"""Longest line the layout aims at: an action longer than this on one line goes on two,
its reply map under the command (the layout the examples are written in)."""
_CONTINUATION = " " * len(f"{INDENT}action {{ ")


def format_mission(mission: ast.Mission) -> str:
    """The canonical text of ``mission``."""
    lines: list[str] = []
    if mission.name is not None:
        lines.append(f"mission {mission.name}")
    if mission.vehicle is not None:
        lines.append(f"vehicle {mission.vehicle}")
    for declaration in mission.declarations:
        if lines:
            lines.append("")
        lines.extend(format_declaration(declaration))
    return "\n".join(lines) + "\n"


def format_declaration(declaration: ast.Declaration) -> list[str]:
    """The lines of one declaration."""
    if isinstance(declaration, ast.Const):
        return [f"const {declaration.name} = {format_value(declaration.value)}"]
    if isinstance(declaration, ast.Places):
        return ["place " + ", ".join(_place(p) for p in declaration.places)]
    if isinstance(declaration, ast.Final):
        return [f"final {format_tokens(declaration.tokens)}"]
    if isinstance(declaration, ast.Include):
        return [f"include {format_string(declaration.path)}"]
    if isinstance(declaration, ast.TemporalAssert):
        return [format_temporal(declaration)]
    if isinstance(declaration, ast.Require):
        return [f"require {declaration.name}"]
    if isinstance(declaration, ast.Inputs):
        return ["input " + ", ".join(n.name for n in declaration.names)]
    if isinstance(declaration, ast.AssertDecl):
        if declaration.kind is ast.AssertKind.BOUND:
            assert declaration.bound is not None
            target = (
                format_token(declaration.tokens[0])
                if len(declaration.tokens) == 1
                else format_tokens(declaration.tokens)
            )
            return [f"assert bound {target} <= {format_value(declaration.bound)}"]
        if declaration.kind is ast.AssertKind.WITHIN:
            assert declaration.deadline is not None
            deadline = format_value(declaration.deadline)
            return [f"assert within {deadline} {format_tokens(declaration.tokens)}"]
        return [f"assert {declaration.kind.value} {format_tokens(declaration.tokens)}"]
    return _transition(declaration)


def format_temporal(declaration: ast.TemporalAssert) -> str:
    """``assert always P``, ``assert P leadsto Q``, ``assert ctl AG EF P``..."""
    formula = declaration.formula
    if declaration.kind is ast.TemporalKind.LEADSTO:
        return f"assert {format_expr(formula)}"
    return f"assert {declaration.kind.value} {format_expr(formula)}"


# Binding strength of each operator: a child binding more loosely than its position
# needs is parenthesised, so printing then parsing gives back the same tree.
_LEADSTO, _IMPLIES, _OR, _AND, _UNTIL, _UNARY, _ATOM = range(7)
_BINARY_LEVEL = {"leadsto": _LEADSTO, "->": _IMPLIES, "or": _OR, "and": _AND, "U": _UNTIL}


def format_expr(expr: ast.Expr | ast.Sum, level: int = _LEADSTO) -> str:
    """A property expression in canonical layout, parenthesised only where needed
    (and around every ``U`` below the top, which reads better)."""
    if isinstance(expr, ast.Sum):
        return " + ".join(
            format_token(t) if isinstance(t, ast.TokenRef) else format_value(t) for t in expr.terms
        )
    own, text = _expr(expr)
    if own < level or (own == _UNTIL and level > _LEADSTO):
        return f"({text})"
    return text


def _expr(expr: ast.Expr) -> tuple[int, str]:
    if isinstance(expr, ast.TokenRef):
        return _ATOM, format_token(expr)
    if isinstance(expr, ast.Comparison):
        return _ATOM, f"{format_expr(expr.left)} {expr.op} {format_expr(expr.right)}"
    if isinstance(expr, ast.Word):
        return _ATOM, expr.word
    if isinstance(expr, ast.Call):
        names = ", ".join(t.name for t in expr.transitions)
        return _ATOM, f"{expr.function}({names})"
    if isinstance(expr, ast.PathUntil):
        left = format_expr(expr.left, _IMPLIES)
        right = format_expr(expr.right, _IMPLIES)
        return _ATOM, f"{expr.quantifier} [ {left} U {right} ]"
    if isinstance(expr, ast.Unary):
        return _UNARY, f"{expr.op} {format_expr(expr.arg, _UNARY)}"
    own = _BINARY_LEVEL[expr.op]
    if expr.op in ("and", "or"):
        parts = [format_expr(a, own + 1) for a in expr.args]
    elif expr.op == "leadsto":
        parts = [format_expr(a, _IMPLIES) for a in expr.args]
    else:  # '->' and 'U' group to the right
        parts = [format_expr(expr.args[0], own + 1), format_expr(expr.args[1], own)]
    return own, f" {expr.op} ".join(parts)


def list_items(declaration: ast.Places | ast.Inputs) -> list[tuple[int, str]]:
    """The items of a ``place`` or ``input`` list, each with the source line it starts
    on: the formatter keeps a commented list's line breaks where the source had them."""
    if isinstance(declaration, ast.Places):
        return [(p.span.line, _place(p)) for p in declaration.places]
    return [(n.span.line, n.name) for n in declaration.names]


def _place(place: ast.PlaceDecl) -> str:
    text = place.name
    if place.initial is not None:
        text += f" = {format_value(place.initial)}"
    if place.capacity is not None:
        text += f" capacity {format_value(place.capacity)}"
    return text


def transition_fields(transition: ast.TransitionDecl) -> list[str] | None:
    """A transition without an action as the fields of one line (header, priority, wait,
    signal; "" where absent), or None when it has an action. The formatter keeps such a
    transition on one line when it was written on one, as a row of a table."""
    if transition.action is not None:
        return None
    priority = transition.priority
    return [
        f"transition {transition.name}",
        "" if priority is None else f"priority {format_value(priority)}",
        f"wait {format_tokens(transition.wait)}"
        if transition.wait or not transition.signal
        else "",
        f"signal {format_tokens(transition.signal)}" if transition.signal else "",
    ]


def _transition(transition: ast.TransitionDecl) -> list[str]:
    header = f"transition {transition.name}"
    if transition.priority is not None:
        header += f" priority {format_value(transition.priority)}"
    lines = [header]
    if transition.wait or (transition.action is None and not transition.signal):
        lines.append(f"{INDENT}wait   {format_tokens(transition.wait)}")
    if transition.action is not None:
        line = f"{INDENT}action {{ {format_action(transition.action)} }}"
        if len(line) <= MAX_WIDTH:
            lines.append(line)
        else:
            command, _ = _action_parts(transition.action)
            lines.append(f"{INDENT}action {{ {command}")
            lines.extend(_reply_lines(transition.action))
    if transition.signal:
        lines.append(f"{INDENT}signal {format_tokens(transition.signal)}")
    return lines


def _reply_lines(action: ast.Action) -> list[str]:
    """``-> { ack: a, error: b } }`` under the command, filled up to `MAX_WIDTH` and
    then continued under the first reply (a long reply map stays readable)."""
    replies = [_reply(r) for r in action.replies]
    first = f"{_CONTINUATION}-> {{ "
    under = " " * len(first)
    lines: list[str] = []
    current, fresh = first, True
    last = len(replies) - 1
    for number, reply in enumerate(replies):
        piece = reply + ("," if number < last else " } }")
        candidate = current + ("" if fresh else " ") + piece
        if not fresh and len(candidate) > MAX_WIDTH:
            lines.append(current)
            candidate = under + piece
        current, fresh = candidate, False
    lines.append(current if replies else current + "} }")
    return lines


def format_action(action: ast.Action) -> str:
    """``ROMEO(DEPTH, z = 2.0) -> { ack: a, error: b }``."""
    command, replies = _action_parts(action)
    return f"{command} -> {{ {replies} }}"


def _action_parts(action: ast.Action) -> tuple[str, str]:
    """``ROMEO(DEPTH, z = 2.0)`` and ``ack: a, error: b``: an action either side of ``->``."""
    args = "".join(", " + _arg(a) for a in action.args)
    replies = ", ".join(_reply(r) for r in action.replies)
    return f"{action.system}({action.command}{args})", replies


def _arg(arg: ast.Arg) -> str:
    value = format_value(arg.value)
    return value if arg.name is None else f"{arg.name} = {value}"


def _reply(reply: ast.ReplyMap) -> str:
    if reply.targets is None:
        return f"{reply.reply}: ignore"
    if len(reply.targets) == 1:
        return f"{reply.reply}: {format_token(reply.targets[0])}"
    return f"{reply.reply}: {format_tokens(reply.targets)}"


def format_tokens(tokens: tuple[ast.TokenRef, ...]) -> str:
    """``{ a, b*2 }`` (``{ }`` when empty)."""
    if not tokens:
        return "{ }"
    return "{ " + ", ".join(format_token(t) for t in tokens) + " }"


def format_token(token: ast.TokenRef) -> str:
    """``p`` or ``p*2``."""
    if token.weight is None:
        return token.place
    return f"{token.place}*{format_value(token.weight)}"


def format_value(value: ast.Value) -> str:
    """A literal or constant name as it is written in source."""
    if isinstance(value, ast.Name):
        return value.name
    if isinstance(value, ast.String):
        return format_string(value.value)
    number = repr(value.value)
    return number if value.unit is None else f"{number} {value.unit}"


def format_string(text: str) -> str:
    """A double-quoted string literal with the escapes the lexer reads back."""
    escaped = (
        text.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n").replace("\t", "\\t")
    )
    return f'"{escaped}"'
