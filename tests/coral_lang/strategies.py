"""Hypothesis strategies for valid CORAL missions (as syntax trees).

Generated missions are valid against the bundled ROMEO profile: every place they name
is declared, every command exists with its parameters in range and every reply kind
mapped, so they must compile as well as round-trip through the printer.
"""

from __future__ import annotations

from hypothesis import strategies as st

from coral_lang import ast
from coral_lang.lexer import KEYWORDS
from coral_lang.profile import CommandSpec, load_bundled_profile

ROMEO = load_bundled_profile("ROMEO")

identifiers = st.from_regex(r"[a-z][a-z0-9_]{0,8}", fullmatch=True).filter(
    lambda s: s not in KEYWORDS
)


def _in_range(spec_min: float | None, spec_max: float | None) -> st.SearchStrategy[float]:
    low = -1e3 if spec_min is None else spec_min
    high = 1e3 if spec_max is None else spec_max
    return st.floats(low, high, allow_nan=False, allow_infinity=False)


@st.composite
def actions(draw: st.DrawFn, places: list[str]) -> ast.Action:
    """A valid ROMEO command with every reply mapped to a place (or ignored)."""
    spec: CommandSpec = draw(st.sampled_from(ROMEO.commands))
    positional = draw(st.booleans())
    args = []
    for param in spec.params:
        value = ast.Number(draw(_in_range(param.minimum, param.maximum)))
        args.append(ast.Arg(None if positional else param.name, value))
    replies = []
    for reply in spec.replies:
        if draw(st.integers(0, 5)) == 0:
            replies.append(ast.ReplyMap(reply, None))
        else:
            replies.append(ast.ReplyMap(reply, (ast.TokenRef(draw(st.sampled_from(places))),)))
    return ast.Action("ROMEO", spec.name, tuple(args), tuple(replies))


@st.composite
def token_sets(draw: st.DrawFn, places: list[str], min_size: int = 0) -> tuple[ast.TokenRef, ...]:
    """Distinct places, some with weights."""
    chosen = draw(st.lists(st.sampled_from(places), min_size=min_size, max_size=3, unique=True))
    return tuple(
        ast.TokenRef(p, draw(st.one_of(st.none(), st.integers(1, 3).map(ast.Number))))
        for p in chosen
    )


@st.composite
def missions(draw: st.DrawFn) -> ast.Mission:
    """A valid mission for ROMEO: places, constants, finals, transitions, assertions."""
    names = draw(st.lists(identifiers, min_size=2, max_size=12, unique=True))
    n_places = draw(st.integers(1, len(names) - 1))
    places, others = names[:n_places], names[n_places:]
    decls: list[ast.Declaration] = []
    groups = draw(st.lists(st.integers(1, 3), min_size=1, max_size=len(places)))
    index = 0
    for size in groups:
        chunk = places[index : index + size]
        index += size
        if chunk:
            decls.append(
                ast.Places(
                    tuple(
                        ast.PlaceDecl(
                            p,
                            draw(st.one_of(st.none(), st.integers(0, 3).map(ast.Number))),
                            draw(st.one_of(st.none(), st.integers(3, 5).map(ast.Number))),
                        )
                        for p in chunk
                    )
                )
            )
    if index < len(places):
        decls.append(ast.Places(tuple(ast.PlaceDecl(p) for p in places[index:])))
    if draw(st.booleans()):
        decls.append(ast.Const("LABEL", ast.String(draw(st.text(max_size=10)))))
    for transition_name in others:
        action = draw(st.one_of(st.none(), actions(places)))
        wait = draw(token_sets(places, min_size=1))
        signal = draw(token_sets(places))
        priority = draw(st.one_of(st.none(), st.integers(-3, 3).map(ast.Number)))
        decls.append(ast.TransitionDecl(transition_name, priority, wait, action, signal))
    for _ in range(draw(st.integers(0, 2))):
        decls.append(ast.Final(draw(token_sets(places, min_size=1))))
    if draw(st.booleans()):
        decls.append(ast.AssertDecl(ast.AssertKind.NEVER, draw(token_sets(places, min_size=1))))
    if draw(st.booleans()):
        target = (ast.TokenRef(draw(st.sampled_from(places))),)
        decls.append(
            ast.AssertDecl(ast.AssertKind.BOUND, target, ast.Number(draw(st.integers(0, 5))))
        )
    return ast.Mission(draw(identifiers), "ROMEO", tuple(decls))
