"""LTL checking (`analysis.ltl`): examples, error cases, and random nets and formulas
against two references of this file.

* `holds_on_lasso` evaluates an LTL formula on an ultimately periodic word (a least
  fixpoint per `Until` over the finitely many positions); it needs no automaton.
  `assert_counterexample` replays a counterexample on the net with `Net.enabled` /
  `Net.fire` and checks, with it, that the lasso violates the formula and is fair.
* `reference_holds` builds the product with Spot's *state-based Büchi* automaton
  ("BA", from a formula *string*, not the constructors `check_ltl` uses) explicitly, one
  Python step per edge, with atoms read on `Net` markings and guards decided by BuDDy
  on one letter at a time, then looks for an accepting fair strongly connected
  component with networkx.
* `bounded_violation` enumerates every lasso of the graph up to a length and evaluates
  the formula on it: evidence for "holds" that does not rest on Spot at all.
"""

from __future__ import annotations

import operator
from collections.abc import Callable, Sequence
from unittest import mock

import networkx as nx
import pytest
import spot
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from spot import buddy

import analysis.ltl as ltl
from analysis.fairness import Group, fairness_groups
from analysis.ltl import LtlError, LtlResult, NotLtlError, ProductTooLarge, Step, check_ltl
from analysis.stategraph import StateGraph, build_graph
from analysis.statespace import explore
from coral_lang.formula import (
    COMPARISONS,
    All,
    And,
    Compare,
    Const,
    Deadlock,
    Exists,
    Finally,
    Fireable,
    Fires,
    Formula,
    Globally,
    IntConst,
    IntExpr,
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
Letter = tuple[Marking, str | None]
"""A position of a run: the marking and the transition fired there (None: stutter)."""

_OPS: dict[str, Callable[[int, int], bool]] = {
    "<=": operator.le,
    "<": operator.lt,
    ">=": operator.ge,
    ">": operator.gt,
    "==": operator.eq,
    "!=": operator.ne,
}


# -- the reference evaluator on lasso words -------------------------------------------------


def _int_value(net: Net, marking: Marking, e: IntExpr) -> int:
    if isinstance(e, IntConst):
        return e.value
    return sum(w * marking[net.place_index(p)] for p, w in e.places)


def atom_holds(net: Net, atom: Formula, letter: Letter) -> bool:
    """An atom at one position, straight from the net."""
    marking, fired = letter
    if isinstance(atom, Const):
        return atom.value
    if isinstance(atom, Compare):
        return _OPS[atom.op](
            _int_value(net, marking, atom.left), _int_value(net, marking, atom.right)
        )
    if isinstance(atom, Fireable):
        return any(net.enabled(marking, net.transition(t)) for t in atom.transitions)
    if isinstance(atom, Deadlock):
        return not any(net.enabled(marking, t) for t in net.transitions)
    if isinstance(atom, Fires):
        return fired is not None and fired in atom.transitions
    raise AssertionError(f"not an atom: {atom}")


def holds_on_lasso(net: Net, f: Formula, prefix: list[Letter], cycle: list[Letter]) -> bool:
    """Whether ``prefix cycle^ω`` satisfies the LTL path formula ``f`` at position 0."""
    word = prefix + cycle
    n, loop = len(word), len(prefix)
    assert cycle
    succ = [i + 1 if i + 1 < n else loop for i in range(n)]

    def ev(g: Formula) -> list[bool]:
        if isinstance(g, All):
            return ev(g.path)
        if isinstance(g, Not):
            return [not v for v in ev(g.arg)]
        if isinstance(g, And):
            parts = [ev(a) for a in g.args]
            return [all(p[i] for p in parts) for i in range(n)]
        if isinstance(g, Or):
            parts = [ev(a) for a in g.args]
            return [any(p[i] for p in parts) for i in range(n)]
        if isinstance(g, Next):
            inner = ev(g.arg)
            return [inner[succ[i]] for i in range(n)]
        if isinstance(g, Finally):
            return ev(Until(Const(True), g.arg))
        if isinstance(g, Globally):
            return ev(Not(Finally(Not(g.arg))))
        if isinstance(g, Until):
            left, right = ev(g.left), ev(g.right)
            # Least fixpoint of  u = right or (left and X u)  on the finite lasso.
            u = list(right)
            changed = True
            while changed:
                changed = False
                for i in range(n):
                    if not u[i] and left[i] and u[succ[i]]:
                        u[i] = changed = True
            return u
        return [atom_holds(net, g, letter) for letter in word]

    return ev(f)[0]


def _markings(graph: StateGraph) -> list[Marking]:
    return [tuple(int(v) for v in row) for row in graph.space.markings]


def _letters(graph: StateGraph, steps: Sequence[Step], markings: list[Marking]) -> list[Letter]:
    net = graph.space.net
    return [(markings[s], None if t < 0 else net.transitions[t].name) for s, t, _ in steps]


def _edge_of(graph: StateGraph, step: Step) -> int | None:
    """The graph edge of a step (None for a stutter step)."""
    s, t, _ = step
    if t < 0:
        return None
    for e in range(int(graph.indptr[s]), int(graph.indptr[s + 1])):
        if int(graph.labels[e]) == t:
            return e
    raise AssertionError(f"no edge for step {step}")


def assert_counterexample(
    graph: StateGraph, formula: Formula, result: LtlResult, groups: Sequence[Group] = ()
) -> None:
    """``result``'s lasso is a run of the net (replayed with `Net.fire`), closes, is
    weakly fair for ``groups`` and violates ``formula``."""
    net, space = graph.space.net, graph.space
    assert not result.holds
    assert result.cycle, "a counterexample has a non-empty cycle"
    marking, node = net.initial_marking(), 0
    for s, t, d in [*result.prefix, *result.cycle]:
        assert s == node, "steps are consecutive"
        assert space.marking(s) == marking
        if t < 0:
            assert not any(net.enabled(marking, tr) for tr in net.transitions), "stutter: dead"
            assert d == s
        else:
            assert net.enabled(marking, net.transitions[t])
            marking = net.fire(marking, net.transitions[t])
            assert space.marking(d) == marking
        node = d
    assert node == result.cycle[0][0], "the cycle closes"
    cycle_nodes = [s for s, _, _ in result.cycle]
    cycle_edges = {_edge_of(graph, step) for step in result.cycle}
    for enabled_at, in_group in groups:
        if all(enabled_at[s] for s in cycle_nodes):
            assert any(e is not None and in_group[e] for e in cycle_edges), "the cycle is fair"
    markings = _markings(graph)
    prefix = _letters(graph, result.prefix, markings)
    cycle = _letters(graph, result.cycle, markings)
    assert not holds_on_lasso(net, formula, prefix, cycle), "the lasso violates the formula"


# -- the reference product --------------------------------------------------------------------


def _spot_text(f: Formula, names: dict[Formula, str]) -> str:
    """``f`` in Spot's syntax, fully parenthesized, atoms as quoted propositions."""
    if isinstance(f, All):
        return _spot_text(f.path, names)
    if isinstance(f, Const):
        return "1" if f.value else "0"
    if isinstance(f, Compare | Fireable | Deadlock | Fires):
        names.setdefault(f, f"atom {len(names)}")
        return f'"{names[f]}"'
    if isinstance(f, Not):
        return f"(!{_spot_text(f.arg, names)})"
    if isinstance(f, And | Or):
        if not f.args:
            return "1" if isinstance(f, And) else "0"
        joiner = " & " if isinstance(f, And) else " | "
        return "(" + joiner.join(_spot_text(a, names) for a in f.args) + ")"
    if isinstance(f, Next | Finally | Globally):
        op = {Next: "X", Finally: "F", Globally: "G"}[type(f)]
        return f"({op} {_spot_text(f.arg, names)})"
    if isinstance(f, Until):
        return f"({_spot_text(f.left, names)} U {_spot_text(f.right, names)})"
    raise AssertionError(f)


def _net_groups(net: Net, markings: list[Marking]) -> list[tuple[set[int], str]]:
    """Plain weak fairness, from the net: per transition, the nodes enabling it."""
    return [
        ({i for i, m in enumerate(markings) if net.enabled(m, tr)}, tr.name)
        for tr in net.transitions
    ]


def reference_holds(graph: StateGraph, formula: Formula, fair: bool) -> bool:
    """Explicit product with Spot's state-based Büchi automaton of the negation."""
    net = graph.space.net
    names: dict[Formula, str] = {}
    text = f"!({_spot_text(formula, names)})"
    aut = spot.translate(spot.formula(text), "BA")
    bdict = aut.get_dict()
    var = {ap.ap_name(): bdict.varnum(ap) for ap in aut.ap()}
    markings = _markings(graph)
    steps: dict[int, list[tuple[str | None, int]]] = {}
    for s, m in enumerate(markings):
        moves: list[tuple[str | None, int]] = [
            (tr.name, markings.index(net.fire(m, tr)))
            for tr in net.transitions
            if net.enabled(m, tr)
        ]
        steps[s] = moves or [(None, s)]  # a dead marking stutters

    def letter_bdd(letter: Letter) -> object:
        cube = buddy.bddtrue
        for atom, name in names.items():
            if name in var:
                v = var[name]
                lit = buddy.bdd_ithvar(v) if atom_holds(net, atom, letter) else buddy.bdd_nithvar(v)
                cube = cube & lit
        return cube

    init = (0, aut.get_init_state_number())
    edges: list[tuple[tuple[int, int], tuple[int, int], str | None, frozenset[int]]] = []
    seen, todo = {init}, [init]
    while todo:
        s, q = todo.pop()
        for fired, d in steps[s]:
            letter = letter_bdd((markings[s], fired))
            for e in aut.out(q):
                if (e.cond & letter) == buddy.bddfalse:
                    continue
                target = (d, int(e.dst))
                edges.append(((s, q), target, fired, frozenset(e.acc.sets())))
                if target not in seen:
                    seen.add(target)
                    todo.append(target)
    g = nx.DiGraph()
    g.add_nodes_from(seen)
    g.add_edges_from((a, b) for a, b, _, _ in edges)
    groups = _net_groups(net, markings) if fair else []
    for comp in nx.strongly_connected_components(g):
        inner = [(a, f, acc) for a, b, f, acc in edges if a in comp and b in comp]
        if not inner:
            continue
        if any(all(k not in acc for _, _, acc in inner) for k in range(aut.num_sets())):
            continue
        nodes = {s for s, _ in comp}
        if all(
            not nodes <= enabled or any(f == name for _, f, _ in inner) for enabled, name in groups
        ):
            return False
    return True


def bounded_violation(
    graph: StateGraph, formula: Formula, fair: bool, max_length: int, max_paths: int = 3000
) -> list[Step] | None:
    """Some lasso with at most ``max_length`` steps that violates ``formula`` (and is
    weakly fair when ``fair``), or None; every path is tried, up to ``max_paths``."""
    net = graph.space.net
    markings = _markings(graph)
    succ: dict[int, list[Step]] = {}
    for s, m in enumerate(markings):
        out = [
            (s, t, markings.index(net.fire(m, tr)))
            for t, tr in enumerate(net.transitions)
            if net.enabled(m, tr)
        ]
        succ[s] = out or [(s, -1, s)]
    groups = _net_groups(net, markings) if fair else []
    paths: list[list[Step]] = [[]]
    for _ in range(max_length):
        longer = []
        for path in paths:
            here = path[-1][2] if path else 0
            longer += [[*path, step] for step in succ[here]]
        if len(longer) > max_paths:
            break
        paths = longer
        for path in paths:
            nodes = [0] + [d for _, _, d in path]
            for j in range(len(path)):
                if nodes[j] != nodes[-1]:
                    continue
                prefix, cycle = path[:j], path[j:]
                names = {None if t < 0 else net.transitions[t].name for _, t, _ in cycle}
                visited = {s for s, _, _ in cycle}
                if any(visited <= enabled and name not in names for enabled, name in groups):
                    continue
                words = _letters(graph, prefix, markings), _letters(graph, cycle, markings)
                if not holds_on_lasso(net, formula, *words):
                    return path
    return None


# -- examples -----------------------------------------------------------------------------------


def _graph(net: Net) -> StateGraph:
    return build_graph(explore(net))


def _tokens(place: str, op: str = ">=", value: int = 1) -> Compare:
    return Compare(Tokens(((place, 1),)), op, IntConst(value))


def _check(
    graph: StateGraph, formula: Formula, groups: Sequence[Group] = (), *, expected: bool
) -> LtlResult:
    result = check_ltl(graph, formula, fairness=groups)
    assert result.holds is expected, formula
    if not expected:
        assert_counterexample(graph, formula, result, groups)
    return result


CS1, CS2 = _tokens("cs1"), _tokens("cs2")
IDLE1, IDLE2 = _tokens("idle1"), _tokens("idle2")


def test_globally_finally_until_next_on_mutex() -> None:
    graph = _graph(mutex())
    _check(graph, All(Globally(Not(And((CS1, CS2))))), expected=True)
    _check(graph, All(Finally(CS1)), expected=False)  # process 2 may take the lock forever
    _check(graph, All(Globally(Finally(Or((CS1, CS2))))), expected=True)
    _check(graph, All(Next(Or((CS1, CS2)))), expected=True)
    _check(graph, All(Next(CS1)), expected=False)
    _check(graph, All(Next(Next(Not(Or((CS1, CS2)))))), expected=True)
    _check(graph, All(Until(And((IDLE1, IDLE2)), Or((CS1, CS2)))), expected=True)
    _check(graph, All(Until(Not(CS2), CS1)), expected=False)
    # The mutex's lock is free exactly when nobody is in a critical section.
    lock_free = _tokens("lock", "==", 1)
    _check(graph, Globally(Or((And((lock_free, Not(CS1))), Not(lock_free)))), expected=True)
    _check(graph, All(Const(True)), expected=True)
    result = _check(graph, All(Const(False)), expected=False)
    assert result.product_states == 0 or result.cycle


def _chain() -> Net:
    """p0 -t-> p1, then nothing: the run stutters in the dead marking p1."""
    return make_net("chain", {"p0": 1, "p1": 0}, {"t": ({"p0": 1}, {"p1": 1})})


def test_deadlocked_runs_stutter() -> None:
    graph = _graph(_chain())
    dead = Deadlock()
    _check(graph, All(Globally(Finally(dead))), expected=True)
    _check(graph, All(Finally(Globally(dead))), expected=True)
    _check(graph, All(Next(dead)), expected=True)
    _check(graph, All(Next(Next(Next(And((dead, _tokens("p1"))))))), expected=True)
    _check(graph, All(dead), expected=False)
    _check(graph, All(Finally(Fires(("t",)))), expected=True)
    _check(graph, All(Fires(("t",))), expected=True)
    _check(graph, All(Next(Fires(("t",)))), expected=False)  # no transition at the stutter
    result = _check(graph, All(Globally(Finally(Fires(("t",))))), expected=False)
    assert result.prefix[0] == (0, 0, 1) and result.cycle == [(1, -1, 1)]
    _check(graph, All(Finally(Globally(Not(Fireable(("t",)))))), expected=True)


def test_a_net_dead_from_the_start() -> None:
    graph = _graph(make_net("stuck", {"p": 0}, {"t": ({"p": 1}, {})}))
    _check(graph, All(Globally(And((Deadlock(), Next(Deadlock()))))), expected=True)
    result = _check(graph, All(Next(Not(Deadlock()))), expected=False)
    assert result.cycle == [(0, -1, 0)]


def test_fires_and_fireable() -> None:
    graph = _graph(mutex())
    enter1, exit1 = Fires(("enter1",)), Fires(("exit1",))
    _check(graph, All(Globally(Or((Not(enter1), Next(exit1))))), expected=True)
    _check(graph, All(Globally(Or((Not(enter1), Next(Fires(("enter2",))))))), expected=False)
    _check(graph, All(Globally(Or((Not(CS1), Fireable(("exit1",)))))), expected=True)
    _check(graph, All(Fireable(("enter1", "enter2"))), expected=True)
    _check(graph, All(Globally(Fires(("enter1", "exit1", "enter2", "exit2")))), expected=True)


def _starving_ring() -> Net:
    """A token at ``a`` may ``spin`` there forever although ``go`` stays enabled."""
    return make_net(
        "ring",
        {"a": 1, "b": 0},
        {"spin": ({"a": 1}, {"a": 1}), "go": ({"a": 1}, {"b": 1}), "back": ({"b": 1}, {"a": 1})},
    )


def test_weak_fairness_forbids_starving_an_always_enabled_transition() -> None:
    graph = _graph(_starving_ring())
    groups = fairness_groups(graph)
    goes = All(Finally(Fires(("go",))))
    result = _check(graph, goes, expected=False)
    assert [t for _, t, _ in result.cycle] == [graph.space.net.transition_index("spin")]
    _check(graph, goes, groups, expected=True)
    _check(graph, All(Globally(Finally(_tokens("b")))), groups, expected=True)
    # Weak, not strong, fairness: in the mutex, enter1 is disabled whenever process 2
    # holds the lock, so process 2 may still win every time.
    mutex_graph = _graph(mutex())
    _check(mutex_graph, All(Finally(CS1)), fairness_groups(mutex_graph), expected=False)


def test_errors() -> None:
    graph = _graph(mutex())
    with pytest.raises(NotLtlError):
        check_ltl(graph, All(Globally(Exists(Finally(CS1)))))
    with pytest.raises(NotLtlError):
        check_ltl(graph, Exists(Finally(CS1)))
    with pytest.raises(LtlError, match="unknown place"):
        check_ltl(graph, All(Finally(_tokens("nowhere"))))
    with pytest.raises(LtlError, match="unknown transition"):
        check_ltl(graph, All(Finally(Fires(("jump",)))))
    safe = All(Globally(Not(And((CS1, CS2)))))
    with pytest.raises(ProductTooLarge, match="budget"):
        check_ltl(graph, safe, max_product_edges=3)
    assert check_ltl(graph, safe, max_product_edges=None).holds
    # The budget stops only a search that found nothing: a counterexample in the part
    # built is one of the whole product.
    starve = All(Globally(Finally(CS1)))
    result = check_ltl(graph, starve, max_product_edges=3)
    assert not result.holds and result.product_edges > 3
    assert_counterexample(graph, starve, result)


def test_both_product_constructions_agree_on_a_deep_graph() -> None:
    # A counter up to 200: the layered construction makes one layer per step.
    net = make_net(
        "count",
        {"todo": 200, "done": 0},
        {"inc": ({"todo": 1}, {"done": 1}), "reset": ({"done": 200}, {"todo": 200})},
    )
    graph = _graph(net)
    formulas: list[Formula] = [
        All(Globally(Finally(_tokens("done", "==", 200)))),
        All(Next(Next(_tokens("done", "==", 2)))),
        All(Until(_tokens("todo", ">", 100), _tokens("done", "==", 150))),
        All(Globally(Finally(Fires(("reset",))))),
        All(Finally(Globally(_tokens("done", "<", 200)))),
    ]
    for formula in formulas:
        eager = check_ltl(graph, formula)
        with mock.patch.object(ltl, "EAGER_PRODUCT_EDGES", 0):
            layered = check_ltl(graph, formula)
            # Too many layers: the construction gives way to the whole product.
            with mock.patch.object(ltl, "DEEP_LAYERS", 10):
                switched = check_ltl(graph, formula)
        for other in (layered, switched):
            assert other.holds is eager.holds, formula
            assert (other.product_states, other.product_edges) == (
                eager.product_states,
                eager.product_edges,
            )
        if not eager.holds:
            assert_counterexample(graph, formula, eager)
            assert_counterexample(graph, formula, layered)
            with (
                mock.patch.object(ltl, "EAGER_PRODUCT_EDGES", 0),
                mock.patch.object(ltl, "FIRST_CHECK", 1),
            ):
                early = check_ltl(graph, formula)
            assert early.product_edges <= layered.product_edges
            assert_counterexample(graph, formula, early)


# -- random nets and formulas -------------------------------------------------------------------


@st.composite
def ltl_formulas(draw: st.DrawFn, net: Net) -> Formula:
    """A random LTL formula over the places and transitions of ``net``."""
    places = [p.name for p in net.places]
    transitions = [t.name for t in net.transitions]
    names = st.lists(st.sampled_from(transitions), min_size=1, max_size=2, unique=True)
    atoms: st.SearchStrategy[Formula] = st.one_of(
        st.builds(
            lambda p, op, k: Compare(Tokens(((p, 1),)), op, IntConst(k)),
            st.sampled_from(places),
            st.sampled_from(COMPARISONS),
            st.integers(0, 2),
        ),
        st.builds(
            lambda p, q: Compare(Tokens(((p, 1),)), "<=", Tokens(((q, 1),))),
            st.sampled_from(places),
            st.sampled_from(places),
        ),
        st.builds(lambda ts: Fireable(tuple(ts)), names),
        st.builds(lambda ts: Fires(tuple(ts)), names),
        st.builds(lambda t: Fires((t,)), st.sampled_from(transitions)),
        st.just(Deadlock()),
        st.builds(Const, st.booleans()),
    )

    unary: list[Callable[[Formula], Formula]] = [
        Not,
        Next,
        Finally,
        Globally,
        Next,
        Finally,
        Globally,
    ]
    binary: list[Callable[[Formula, Formula], Formula]] = [
        lambda a, b: And((a, b)),
        lambda a, b: Or((a, b)),
        Until,
        Until,
    ]

    def build(depth: int) -> Formula:
        if depth == 0 or not draw(st.integers(0, 4)):
            return draw(atoms)
        if draw(st.booleans()):
            return draw(st.sampled_from(unary))(build(depth - 1))
        return draw(st.sampled_from(binary))(build(depth - 1), build(depth - 1))

    body = build(draw(st.integers(1, 3)))
    return All(body)


@st.composite
def token_game_nets(draw: st.DrawFn) -> Net:
    """A random net that is bounded by construction: each transition consumes one or
    two arcs' worth of tokens and puts back as many (or one fewer: a way to die).
    Built from a hypothesis-driven `random.Random` so nets are varied, not minimal."""
    rnd = draw(st.randoms(use_true_random=False))
    places = [f"p{i}" for i in range(rnd.randint(2, 4))]
    initial = {p: rnd.choice([0, 1, 1, 2]) for p in places}
    initial["p0"] = max(initial["p0"], 1)
    transitions: dict[str, tuple[dict[str, int], dict[str, int]]] = {}
    for j in range(rnd.randint(2, 5)):
        inputs = {p: rnd.choice([1, 1, 2]) for p in rnd.sample(places, rnd.randint(1, 2))}
        size = sum(inputs.values()) - (rnd.random() < 0.2)
        outputs: dict[str, int] = {}
        for p in rnd.choices(places, k=size):
            outputs[p] = outputs.get(p, 0) + 1
        transitions[f"t{j}"] = (inputs, outputs)
    return make_net("game", initial, transitions)


@st.composite
def nets_and_formulas(draw: st.DrawFn) -> tuple[StateGraph, Formula, bool]:
    if draw(st.integers(0, 3)):
        net = draw(token_game_nets())
    else:
        net = draw(small_nets(max_places=3, max_transitions=4, max_weight=2, max_initial=2))
    space = explore(net, max_states=25)
    assume(space.complete)
    return build_graph(space), draw(ltl_formulas(net)), draw(st.booleans())


@pytest.mark.slow
@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.filter_too_much])
@given(nets_and_formulas())
def test_random_formulas_agree_with_the_references(
    case: tuple[StateGraph, Formula, bool],
) -> None:
    graph, formula, fair = case
    groups = fairness_groups(graph) if fair else []
    result = check_ltl(graph, formula, fairness=groups)
    assert result.holds is reference_holds(graph, formula, fair)
    # The layered construction, searching what it has built after every layer.
    with mock.patch.object(ltl, "EAGER_PRODUCT_EDGES", 0), mock.patch.object(ltl, "FIRST_CHECK", 1):
        layered = check_ltl(graph, formula, fairness=groups)
    assert layered.holds is result.holds
    if result.holds:
        assert (layered.product_states, layered.product_edges) == (
            result.product_states,
            result.product_edges,
        )
    if result.holds:
        assert bounded_violation(graph, formula, fair, max_length=6) is None
    else:
        assert_counterexample(graph, formula, result, groups)
        assert_counterexample(graph, formula, layered, groups)


@pytest.mark.slow
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.filter_too_much])
@given(nets_and_formulas())
def test_stutter_laws_on_random_nets(case: tuple[StateGraph, Formula, bool]) -> None:
    """What the stutter convention implies, whatever the net: a run fires forever iff
    no deadlock is reachable, and at a dead marking the run stays, firing nothing."""
    graph, _, _ = case
    names = tuple(t.name for t in graph.space.net.transitions)
    fires_forever = All(Globally(Finally(Fires(names))))
    result = check_ltl(graph, fires_forever)
    assert result.holds is not bool(graph.dead.any())
    if not result.holds:
        assert_counterexample(graph, fires_forever, result)
        assert [t for _, t, _ in result.cycle] == [-1]
    for name in names:
        stays = All(Globally(Or((Not(Deadlock()), Next(And((Deadlock(), Not(Fires((name,))))))))))
        assert check_ltl(graph, stays).holds


def test_the_reference_evaluator_on_hand_made_words() -> None:
    net = make_net("two", {"p": 1}, {"t": ({"p": 1}, {"p": 1})})
    up: Letter = ((1,), "t")
    down: Letter = ((0,), None)
    p = _tokens("p")
    assert holds_on_lasso(net, Globally(Finally(p)), [down], [up, down])
    assert not holds_on_lasso(net, Finally(Globally(p)), [up], [up, down])
    assert holds_on_lasso(net, Finally(Globally(p)), [down, down], [up])
    assert holds_on_lasso(net, Until(Not(p), p), [down, down], [up])
    assert not holds_on_lasso(net, Until(Not(p), p), [], [down])
    assert holds_on_lasso(net, Next(Next(p)), [down, down], [up])
    assert not holds_on_lasso(net, Next(Fires(("t",))), [up], [down])
    assert holds_on_lasso(net, Fires(("t",)), [], [up])
