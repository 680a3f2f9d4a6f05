"""CTL checking (`analysis.ctl`): the deadlock convention, each operator on tiny nets,
and random nets and formulas against a reference of this file.

The reference (`reference_sat`) builds the reachability graph in Python with
`Net.enabled` / `Net.fire` and computes every operator as the textbook fixpoint over
*maximal* paths, with no strongly connected components:

* ``EX s``: some successor in ``s``; ``AX s``: every successor in ``s`` (true at a dead
  marking);
* ``EF b = μZ. b ∨ EX Z``; ``E[a U b] = μZ. b ∨ (a ∧ EX Z)``;
* ``EG a = νZ. a ∧ (dead ∨ EX Z)`` (a maximal path may end in a dead marking);
* ``AF b = μZ. b ∨ (¬dead ∧ AX Z)``; ``A[a U b] = μZ. b ∨ (a ∧ ¬dead ∧ AX Z)``;
* ``AG a = νZ. a ∧ AX Z``.
"""

from __future__ import annotations

import operator
from collections.abc import Callable

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from analysis.budget import Budget, BudgetExceeded
from analysis.ctl import CtlChecker, CtlError
from analysis.stategraph import build_graph
from analysis.statespace import explore
from coral_lang.formula import (
    All,
    And,
    Compare,
    Const,
    Deadlock,
    Exists,
    Finally,
    Fireable,
    Formula,
    Globally,
    IntConst,
    Next,
    Not,
    Or,
    Tokens,
    Until,
)
from coral_lang.net import Net
from tests.analysis.nets import make_net, mutex
from tests.analysis.strategies import small_nets

Marking = tuple[int, ...]

# -- the deadlock convention, as verifypn 4.4.2 answers it ------------------------------

# p0 --t0--> p1 (dead there); q --t1--> p0 never fires. The same net and formulas were
# run through TAPAAL's verifypn, one formula per run (docs/verify.md, "Model Checking
# Contest queries"); each expected value below is its answer.
DEAD = make_net(
    "dead",
    {"p0": 1, "p1": 0, "q": 0},
    {"t0": ({"p0": 1}, {"p1": 1}), "t1": ({"q": 1}, {"p0": 1})},
)
TRUE, FALSE = Const(True), Const(False)
P1 = Compare(IntConst(1), "<=", Tokens((("p1", 1),)))
P1_LE_5 = Compare(Tokens((("p1", 1),)), "<=", IntConst(5))
T0 = Fireable(("t0",))


def AX(f: Formula) -> Formula:
    return All(Next(f))


def EX(f: Formula) -> Formula:
    return Exists(Next(f))


VERIFYPN = [
    ("AX EX true", AX(EX(TRUE)), False),
    ("AX AX false", AX(AX(FALSE)), True),
    ("AX EX false", AX(EX(FALSE)), False),
    ("AX AX true", AX(AX(TRUE)), True),
    ("AX AX p1", AX(AX(P1)), True),
    ("AX EX p1", AX(EX(P1)), False),
    ("EG true", Exists(Globally(TRUE)), True),
    ("AX EG p1", AX(Exists(Globally(P1))), True),
    ("AX AG p1", AX(All(Globally(P1))), True),
    ("AF not fireable(t0)", All(Finally(Not(T0))), True),
    ("EG fireable(t0)", Exists(Globally(T0)), False),
    ("AX AF false", AX(All(Finally(FALSE))), False),
    ("AX E[true U false]", AX(Exists(Until(TRUE, FALSE))), False),
    ("AX A[p1 U false]", AX(All(Until(P1, FALSE))), False),
    ("AG EX true", All(Globally(EX(TRUE))), False),
    ("EF AX false", Exists(Finally(AX(FALSE))), True),
    ("EF not EX true", Exists(Finally(Not(EX(TRUE)))), True),
    ("AG EX p1 <= 5", All(Globally(EX(P1_LE_5))), False),
    ("EF AX not p1", Exists(Finally(AX(Not(P1)))), True),
    ("EF deadlock", Exists(Finally(Deadlock())), True),
    ("AG not deadlock", All(Globally(Not(Deadlock()))), False),
    ("EX EX p1 <= 5", EX(EX(P1_LE_5)), False),
]


def checker(net: Net) -> CtlChecker:
    space = explore(net, max_states=10_000)
    assert space.complete
    return CtlChecker(build_graph(space))


@pytest.mark.parametrize(
    ("formula", "expected"), [(f, e) for _, f, e in VERIFYPN], ids=[name for name, _, _ in VERIFYPN]
)
def test_dead_markings_follow_verifypn(formula: Formula, expected: bool) -> None:
    assert checker(DEAD).holds(formula) is expected


def test_at_a_dead_marking_ex_is_false_and_ax_true() -> None:
    ck = checker(DEAD)
    dead = ck.graph.dead
    assert dead.tolist() == [False, True]
    for s in (np.zeros(2, dtype=np.bool_), np.ones(2, dtype=np.bool_)):
        assert not ck.ex(s)[1]
        assert ck.sat(AX(TRUE))[1] and ck.sat(AX(FALSE))[1]
    assert ck.eg(np.array([False, True])).tolist() == [False, True]


# -- operators on a cycle --------------------------------------------------------------


def test_operators_on_mutex() -> None:
    ck = checker(mutex())
    cs1 = Compare(Tokens((("cs1", 1),)), ">=", IntConst(1))
    cs2 = Compare(Tokens((("cs2", 1),)), ">=", IntConst(1))
    assert ck.holds(All(Globally(Not(And((cs1, cs2))))))
    assert ck.holds(Exists(Finally(cs1)))
    assert not ck.holds(All(Finally(cs1)))  # process 2 may take the lock forever
    assert ck.holds(Exists(Globally(Not(cs1))))
    assert ck.holds(All(Globally(Exists(Finally(cs1)))))
    assert ck.holds(All(Next(Or((cs1, cs2)))))
    assert not ck.holds(Exists(Until(Not(cs2), And((cs1, cs2)))))
    assert ck.holds(Exists(Until(Not(cs2), cs1)))
    assert not ck.holds(All(Until(Not(cs2), cs1)))


def test_self_loops_are_infinite_paths() -> None:
    net = make_net("loop", {"p": 1}, {"stay": ({"p": 1}, {"p": 1})})
    ck = checker(net)
    assert ck.holds(Exists(Globally(TRUE)))
    assert not ck.holds(All(Finally(FALSE)))
    assert ck.holds(All(Next(TRUE)))


def test_shared_sub_formulas_are_labelled_once() -> None:
    ck = checker(mutex())
    cs1 = Compare(Tokens((("cs1", 1),)), ">=", IntConst(1))
    inner = Exists(Finally(cs1))
    ck.holds(And((All(Globally(inner)), Not(inner))))
    nodes = len(ck._nodes)
    ck.holds(Or((inner, All(Globally(inner)))))
    assert len(ck._nodes) == nodes + 1  # only the new Or


def test_deeply_nested_formulas() -> None:
    f: Formula = Deadlock()
    for _ in range(3_000):
        f = Not(EX(f))
    ck = checker(DEAD)
    ck.holds(f)  # no RecursionError
    g: Formula = TRUE
    for _ in range(3_000):
        g = AX(g)
    assert ck.holds(g)


def test_errors_and_timeout() -> None:
    ck = checker(mutex())
    with pytest.raises(CtlError, match="not a CTL formula"):
        ck.sat(All(Globally(Finally(TRUE))))
    with pytest.raises(CtlError, match="unknown place 'nope'"):
        ck.sat(Compare(Tokens((("nope", 1),)), "<=", IntConst(1)))
    with pytest.raises(CtlError, match="unknown transition 'nope'"):
        ck.sat(Fireable(("nope",)))
    ticks = iter(range(100))
    late = CtlChecker(ck.graph, budget=Budget(0.5, clock=lambda: float(next(ticks))))
    with pytest.raises(BudgetExceeded, match=r"^labelling stopped: time limit of 0\.5 s reached$"):
        late.sat(Exists(Finally(Fireable(("enter1",)))))


# -- random nets and formulas against the fixpoint reference -------------------------------

_OPS: dict[str, Callable[[int, int], bool]] = {
    "<=": operator.le,
    "<": operator.lt,
    ">=": operator.ge,
    ">": operator.gt,
    "==": operator.eq,
    "!=": operator.ne,
}


def _graph(net: Net, limit: int = 300) -> tuple[list[Marking], list[list[int]]] | None:
    """States (BFS order) and successor lists, or None past ``limit`` states."""
    start = net.initial_marking()
    index = {start: 0}
    states, succ = [start], []
    k = 0
    while k < len(states):
        m = states[k]
        out = []
        for t in net.transitions:
            if net.enabled(m, t):
                n = net.fire(m, t)
                if n not in index:
                    if len(states) >= limit:
                        return None
                    index[n] = len(states)
                    states.append(n)
                out.append(index[n])
        succ.append(out)
        k += 1
    return states, succ


def reference_sat(net: Net, states: list[Marking], succ: list[list[int]], f: Formula) -> set[int]:
    nodes = set(range(len(states)))
    dead = {i for i in nodes if not succ[i]}

    def ex(s: set[int]) -> set[int]:
        return {i for i in nodes if any(j in s for j in succ[i])}

    def ax(s: set[int]) -> set[int]:
        return {i for i in nodes if all(j in s for j in succ[i])}

    def lfp(step: Callable[[set[int]], set[int]]) -> set[int]:
        z: set[int] = set()
        while (n := step(z)) != z:
            z = n
        return z

    def gfp(step: Callable[[set[int]], set[int]]) -> set[int]:
        z = set(nodes)
        while (n := step(z)) != z:
            z = n
        return z

    def value(m: Marking, e: Tokens | IntConst) -> int:
        if isinstance(e, IntConst):
            return e.value
        return sum(w * m[net.place_index(p)] for p, w in e.places)

    def sat(g: Formula) -> set[int]:
        if isinstance(g, Const):
            return set(nodes) if g.value else set()
        if isinstance(g, Compare):
            return {
                i for i in nodes if _OPS[g.op](value(states[i], g.left), value(states[i], g.right))
            }
        if isinstance(g, Fireable):
            ts = [net.transition(t) for t in g.transitions]
            return {i for i in nodes if any(net.enabled(states[i], t) for t in ts)}
        if isinstance(g, Deadlock):
            return set(dead)
        if isinstance(g, Not):
            return nodes - sat(g.arg)
        if isinstance(g, And):
            out = set(nodes)
            for arg in g.args:
                out &= sat(arg)
            return out
        if isinstance(g, Or):
            out = set()
            for arg in g.args:
                out |= sat(arg)
            return out
        assert isinstance(g, All | Exists)
        p = g.path
        live = nodes - dead
        if isinstance(p, Next):
            s = sat(p.arg)
            return ax(s) if isinstance(g, All) else ex(s)
        if isinstance(p, Finally):
            b = sat(p.arg)
            if isinstance(g, All):
                return lfp(lambda z: b | (live & ax(z)))
            return lfp(lambda z: b | ex(z))
        if isinstance(p, Globally):
            a = sat(p.arg)
            if isinstance(g, All):
                return gfp(lambda z: a & ax(z))
            return gfp(lambda z: a & (dead | ex(z)))
        assert isinstance(p, Until)
        a, b = sat(p.left), sat(p.right)
        if isinstance(g, All):
            return lfp(lambda z: b | (a & live & ax(z)))
        return lfp(lambda z: b | (a & ex(z)))

    return sat(f)


def _atoms(net: Net) -> st.SearchStrategy[Formula]:
    places = [p.name for p in net.places]
    transitions = [t.name for t in net.transitions]
    compare = st.builds(
        Compare,
        st.builds(
            Tokens,
            st.lists(st.sampled_from(places), min_size=1, max_size=2, unique=True).map(
                lambda ps: tuple((p, 1) for p in ps)
            ),
        ),
        st.sampled_from(sorted(_OPS)),
        st.builds(IntConst, st.integers(0, 3)),
    )
    fire = st.lists(st.sampled_from(transitions), min_size=1, max_size=2, unique=True).map(
        lambda ts: Fireable(tuple(ts))
    )
    return st.one_of(compare, fire, st.just(Deadlock()), st.builds(Const, st.booleans()))


def _ctl(net: Net) -> st.SearchStrategy[Formula]:
    def extend(inner: st.SearchStrategy[Formula]) -> st.SearchStrategy[Formula]:
        quant = st.sampled_from([All, Exists])
        unary = st.sampled_from([Next, Finally, Globally])
        return st.one_of(
            st.builds(Not, inner),
            st.builds(lambda a, b: And((a, b)), inner, inner),
            st.builds(lambda a, b: Or((a, b)), inner, inner),
            st.builds(lambda q, u, a: q(u(a)), quant, unary, inner),
            st.builds(lambda q, a, b: q(Until(a, b)), quant, inner, inner),
        )

    return st.recursive(_atoms(net), extend, max_leaves=6)


@pytest.mark.slow
@settings(max_examples=200, suppress_health_check=[HealthCheck.too_slow], deadline=None)
@given(data=st.data(), net=small_nets(max_places=4, max_transitions=4, max_initial=2))
def test_random_formulas_match_the_fixpoint_reference(data: st.DataObject, net: Net) -> None:
    built = _graph(net)
    assume(built is not None)
    assert built is not None
    states, succ = built
    space = explore(net, max_states=1_000)
    assert space.complete and space.states == len(states)
    # Map the explorer's numbering to the reference's by marking.
    order = [states.index(space.marking(i)) for i in range(space.states)]
    ck = CtlChecker(build_graph(space))
    for _ in range(4):
        f = data.draw(_ctl(net))
        expected = reference_sat(net, states, succ, f)
        got = {order[i] for i in np.flatnonzero(ck.sat(f)).tolist()}
        assert got == expected, f
