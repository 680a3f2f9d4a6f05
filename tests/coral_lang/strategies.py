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


_CMP = ("<", "<=", "==", "!=", ">=", ">")


@st.composite
def sums(draw: st.DrawFn, places: list[str]) -> ast.Sum:
    """``p + q*2`` (places only: a number goes on the other side)."""
    chosen = draw(st.lists(st.sampled_from(places), min_size=1, max_size=3))
    return ast.Sum(
        tuple(
            ast.TokenRef(q, draw(st.one_of(st.none(), st.integers(1, 3).map(ast.Number))))
            for q in chosen
        )
    )


@st.composite
def state_atoms(
    draw: st.DrawFn, places: list[str], transitions: list[str], commands: list[str], finals: bool
) -> ast.Expr:
    """A state atom naming only what the mission declares."""
    options: list[st.SearchStrategy[ast.Expr]] = [
        st.builds(ast.TokenRef, st.sampled_from(places)),
        st.builds(
            ast.Comparison,
            sums(places),
            st.sampled_from(_CMP),
            st.integers(0, 4).map(lambda k: ast.Sum((ast.Number(k),))),
        ),
        st.builds(ast.Comparison, sums(places), st.sampled_from(_CMP), sums(places)),
        st.sampled_from(["true", "false", "deadlock"] + (["final"] if finals else [])).map(
            ast.Word
        ),
    ]
    if transitions:
        refs = st.lists(st.sampled_from(transitions), min_size=1, max_size=2).map(
            lambda names: tuple(ast.TransitionRef(n) for n in names)
        )
        options.append(st.builds(ast.Call, st.just("fireable"), refs))
    if commands:
        refs = st.lists(st.sampled_from(commands), min_size=1, max_size=2).map(
            lambda names: tuple(ast.TransitionRef(n) for n in names)
        )
        options.append(st.builds(ast.Call, st.just("in_flight"), refs))
    return draw(st.one_of(options))


def expressions(atoms: st.SearchStrategy[ast.Expr], logic: str) -> st.SearchStrategy[ast.Expr]:
    """Property expressions of ``logic`` (``state``, ``ltl`` or ``ctl``) over ``atoms``."""
    unary = ["not"] + {
        "state": [],
        "ltl": ["X", "F", "G"],
        "ctl": ["AX", "AF", "AG", "EX", "EF", "EG"],
    }[logic]
    binary = ["->"] + (["U"] if logic == "ltl" else [])

    def extend(inner: st.SearchStrategy[ast.Expr]) -> st.SearchStrategy[ast.Expr]:
        options: list[st.SearchStrategy[ast.Expr]] = [
            st.builds(ast.Unary, st.sampled_from(unary), inner),
            st.builds(
                ast.Binary,
                st.sampled_from(["and", "or"]),
                st.lists(inner, min_size=2, max_size=3).map(tuple),
            ),
            st.builds(ast.Binary, st.sampled_from(binary), st.tuples(inner, inner)),
        ]
        if logic == "ctl":
            options.append(st.builds(ast.PathUntil, st.sampled_from(["A", "E"]), inner, inner))
        return st.one_of(options)

    return st.recursive(atoms, extend, max_leaves=6)


@st.composite
def temporal_asserts(
    draw: st.DrawFn, places: list[str], transitions: list[str], commands: list[str], finals: bool
) -> ast.TemporalAssert:
    """A valid ``assert always/eventually/leadsto/ltl/ctl``."""
    atoms = state_atoms(places, transitions, commands, finals)
    kind = draw(st.sampled_from(list(ast.TemporalKind)))
    if kind is ast.TemporalKind.LEADSTO:
        state = expressions(atoms, "state")
        return ast.TemporalAssert(kind, ast.Binary("leadsto", (draw(state), draw(state))))
    logic = {ast.TemporalKind.LTL: "ltl", ast.TemporalKind.CTL: "ctl"}.get(kind, "state")
    if logic == "ltl" and transitions:
        refs = st.lists(st.sampled_from(transitions), min_size=1, max_size=2).map(
            lambda names: tuple(ast.TransitionRef(n) for n in names)
        )
        atoms = st.one_of(atoms, st.builds(ast.Call, st.just("fires"), refs))
    return ast.TemporalAssert(kind, draw(expressions(atoms, logic)))


@st.composite
def missions(draw: st.DrawFn) -> ast.Mission:
    """A valid mission for ROMEO: places, constants, finals, transitions, assertions
    (temporal ones too), requirements, operator inputs (waited on, never signalled)."""
    names = draw(st.lists(identifiers, min_size=2, max_size=14, unique=True))
    n_inputs = draw(st.integers(0, min(2, len(names) - 2)))
    inputs, names = names[:n_inputs], names[n_inputs:]
    n_places = draw(st.integers(1, len(names) - 1))
    places, others = names[:n_places], names[n_places:]
    decls: list[ast.Declaration] = []
    if inputs:
        decls.append(ast.Inputs(tuple(ast.InputName(i) for i in inputs)))
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
    commands: list[str] = []
    replies: list[str] = []
    for transition_name in others:
        action = draw(st.one_of(st.none(), actions(places)))
        if action is not None:
            commands.append(transition_name)
            replies += [f"{transition_name}.{r.reply}" for r in action.replies]
        wait = draw(token_sets([*places, *inputs], min_size=1))
        signal = draw(token_sets(places))
        priority = draw(st.one_of(st.none(), st.integers(-3, 3).map(ast.Number)))
        decls.append(ast.TransitionDecl(transition_name, priority, wait, action, signal))
    n_finals = draw(st.integers(0, 2))
    for _ in range(n_finals):
        decls.append(ast.Final(draw(token_sets(places, min_size=1))))
    if draw(st.booleans()):
        decls.append(ast.AssertDecl(ast.AssertKind.NEVER, draw(token_sets(places, min_size=1))))
    if draw(st.booleans()):
        target = (ast.TokenRef(draw(st.sampled_from(places))),)
        decls.append(
            ast.AssertDecl(ast.AssertKind.BOUND, target, ast.Number(draw(st.integers(0, 5))))
        )
    for _ in range(draw(st.integers(0, 2))):
        decls.append(draw(temporal_asserts(places, [*others, *replies], commands, n_finals > 0)))
    if draw(st.booleans()):
        decls.append(ast.Require("termination"))
    return ast.Mission(draw(identifiers), "ROMEO", tuple(decls))
