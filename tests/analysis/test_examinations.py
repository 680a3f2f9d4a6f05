"""`analysis.examinations`: planning, budgets (CANNOT_COMPUTE, never a guess), traces
that replay on the net, and the global examinations on small nets."""

from __future__ import annotations

import pytest
import yaml

from analysis.examinations import Answer, QueryLimits, QuerySession, examination_of
from analysis.mccxml import MccProperty, PlaceBound
from analysis.statespace import STOPPED_BY_REQUEST
from coral_lang.formula import (
    All,
    Compare,
    Const,
    Exists,
    Finally,
    Formula,
    Globally,
    IntConst,
    Next,
    Not,
    Tokens,
)
from coral_lang.net import Net
from coral_lang.pnml import read_pnml
from tests.analysis.nets import make_net, mutex
from tests.conftest import CONFORMANCE


def prop(ident: str, query: Formula | PlaceBound, file: str = "q.xml") -> MccProperty:
    return MccProperty(ident, query, 1, file)


def at_least(place: str, n: int) -> Compare:
    return Compare(Tokens(((place, 1),)), ">=", IntConst(n))


def counter(n: int) -> Net:
    """One token walks p0 -> p1 -> ... -> p{n}; dead at the end."""
    return make_net(
        "chain",
        {f"p{i}": int(i == 0) for i in range(n + 1)},
        {f"t{i}": ({f"p{i}": 1}, {f"p{i + 1}": 1}) for i in range(n)},
    )


def replay(net: Net, trace: tuple[str, ...]) -> tuple[int, ...]:
    marking = net.initial_marking()
    for name in trace:
        t = net.transition(name)
        assert net.enabled(marking, t), name
        marking = net.fire(marking, t)
    return marking


def test_reachability_search_stops_early_with_shortest_witnesses() -> None:
    net = counter(50)
    session = QuerySession(net)
    answers = session.check(
        [
            prop("ef", Exists(Finally(at_least("p3", 1)))),
            prop("ag", All(Globally(Not(at_least("p5", 1))))),
            prop("not-ef", Not(Exists(Finally(at_least("p2", 1))))),
        ]
    )
    assert [a.value for a in answers] == [True, False, False]
    assert answers[0].trace == ("t0", "t1", "t2")
    assert answers[0].trace_kind == "witness"
    assert answers[1].trace_kind == "counterexample"
    assert replay(net, answers[1].trace or ())[5] == 1
    assert answers[2].trace == ("t0", "t1")
    assert session.space is None  # stopped early: no full state space kept
    assert all(a.method == "reachability" for a in answers)


def test_reachability_without_a_hit_needs_the_complete_space() -> None:
    net = counter(30)
    never = prop("never", Exists(Finally(at_least("p3", 2))))
    limits = QueryLimits(max_states=10, reductions=False)
    answer = QuerySession(net, limits).check([never])[0]
    assert answer.value is None and "incomplete" in (answer.reason or "")
    assert answer.mcc_line() == "FORMULA never CANNOT_COMPUTE"
    full = QuerySession(net).check([never])[0]
    assert full.value is False and full.trace is None
    assert full.mcc_line() == "FORMULA never FALSE TECHNIQUES EXPLICIT STATE_COMPRESSION"


def test_a_hit_in_an_incomplete_search_still_decides() -> None:
    net = counter(30)
    session = QuerySession(net, QueryLimits(max_states=10))
    answers = session.check(
        [
            prop("ef", Exists(Finally(at_least("p4", 1)))),
            prop("ctl", All(Finally(at_least("p4", 1)))),
        ]
    )
    assert answers[0].value is True  # found within the 10 stored states
    assert answers[1].value is None and "incomplete" in (answers[1].reason or "")
    assert session.space is not None and session.space.stopped_reason != STOPPED_BY_REQUEST


def test_state_formulas_are_read_on_the_initial_marking() -> None:
    answer = QuerySession(mutex()).check([prop("s", at_least("idle1", 1))])[0]
    assert (answer.value, answer.method, answer.techniques) == (True, "initial", ("INITIAL_STATE",))


def test_ctl_and_ltl_share_one_graph_and_give_traces() -> None:
    net = counter(4)
    session = QuerySession(net)
    answers = session.check(
        [
            prop("af", All(Finally(at_least("p4", 1)))),
            prop("ag-ef", Not(All(Globally(Exists(Next(Const(True))))))),
            prop("ltl", All(Globally(Finally(at_least("p2", 1))))),
            prop("ltl-ok", All(Finally(Globally(at_least("p4", 1))))),
        ]
    )
    assert [a.value for a in answers] == [True, True, False, True]
    assert answers[1].trace == ("t0", "t1", "t2", "t3")  # to the dead marking
    assert answers[2].method == "ltl"
    assert answers[2].trace == ("t0", "t1", "t2", "t3") and answers[2].cycle == ()
    assert session.graph is not None


def test_the_graph_budget_makes_ctl_cannot_compute() -> None:
    session = QuerySession(mutex(), QueryLimits(max_edges=3))
    answer = session.check([prop("af", All(Finally(at_least("cs1", 1))))])[0]
    assert answer.value is None and "budget" in (answer.reason or "")


def test_the_time_limit_makes_formulas_cannot_compute() -> None:
    ticks = iter(range(0, 10_000, 10))
    session = QuerySession(mutex(), QueryLimits(time_limit=5), clock=lambda: float(next(ticks)))
    answers = session.check([prop("af", All(Finally(at_least("cs1", 1))))])
    assert answers[0].value is None


def test_upper_bounds_with_a_witness() -> None:
    net = make_net(
        "bag", {"a": 3, "b": 0}, {"move": ({"a": 1}, {"b": 1}), "back": ({"b": 2}, {"a": 2})}
    )
    answers = QuerySession(net).check(
        [prop("ub-b", PlaceBound(("b",))), prop("ub-ab", PlaceBound(("a", "b")))]
    )
    assert [a.value for a in answers] == [3, 3]
    assert replay(net, answers[0].trace or ())[1] == 3
    assert answers[0].mcc_line() == "FORMULA ub-b 3 TECHNIQUES EXPLICIT STATE_COMPRESSION"


def test_upper_bounds_on_an_incomplete_space_use_p_invariants() -> None:
    net = counter(30)  # one token in total: every place is bounded by 1
    answers = QuerySession(net, QueryLimits(max_states=5, reductions=False)).check(
        [prop("p1", PlaceBound(("p1",))), prop("p20", PlaceBound(("p20",)))]
    )
    assert answers[0].value == 1 and "TOPOLOGICAL" in answers[0].techniques
    assert answers[1].value is None  # not reached within the budget


@pytest.mark.parametrize(
    ("net", "expected"),
    [
        (
            mutex(),
            {
                "ReachabilityDeadlock": False,
                "QuasiLiveness": True,
                "Liveness": True,
                "OneSafe": True,
                "StableMarking": False,
            },
        ),
        (
            counter(3),
            {
                "ReachabilityDeadlock": True,
                "QuasiLiveness": True,
                "Liveness": False,
                "OneSafe": True,
                "StableMarking": False,
            },
        ),
        (
            make_net(
                "stuck",
                {"a": 2, "b": 0, "c": 0, "s": 1},
                {
                    "ab": ({"a": 1}, {"b": 1}),
                    "ba": ({"b": 1}, {"a": 1}),
                    "never": ({"c": 1}, {"a": 1}),
                },
            ),
            {
                "ReachabilityDeadlock": False,
                "QuasiLiveness": False,
                "Liveness": False,
                "OneSafe": False,
                "StableMarking": True,
            },
        ),
        (
            # Live in the cycle, but the first transition can never fire again.
            make_net(
                "start",
                {"i": 1, "x": 0, "y": 0},
                {
                    "go": ({"i": 1}, {"x": 1}),
                    "xy": ({"x": 1}, {"y": 1}),
                    "yx": ({"y": 1}, {"x": 1}),
                },
            ),
            {
                "ReachabilityDeadlock": False,
                "QuasiLiveness": True,
                "Liveness": False,
                "OneSafe": True,
                "StableMarking": False,
            },
        ),
    ],
)
def test_global_examinations(net: Net, expected: dict[str, bool]) -> None:
    session = QuerySession(net)
    found = {name: session.check_global(name) for name in expected}
    assert {name: a.value for name, a in found.items()} == expected
    for name, answer in found.items():
        assert answer.id == name and answer.examination == name
        if answer.trace is not None:
            replay(net, answer.trace)


def test_liveness_counterexample_names_the_transition() -> None:
    net = make_net(
        "start",
        {"i": 1, "x": 0, "y": 0},
        {"go": ({"i": 1}, {"x": 1}), "xy": ({"x": 1}, {"y": 1}), "yx": ({"y": 1}, {"x": 1})},
    )
    answer = QuerySession(net).check_global("Liveness")
    assert answer.trace == ("go",) and "go can never fire again" in (answer.reason or "")


def test_deadlock_on_an_incomplete_search_uses_stubborn_sets() -> None:
    # Ten independent two-step chains: 3**10 markings, but a stubborn-set search
    # fires one chain at a time.
    net = make_net(
        "chains",
        {f"{c}{i}": int(i == 0) for c in "abcdefghij" for i in range(3)},
        {f"{c}{i}": ({f"{c}{i}": 1}, {f"{c}{i + 1}": 1}) for c in "abcdefghij" for i in range(2)},
    )
    limits = QueryLimits(max_states=1_000, reductions=False)  # a random walk finds it
    answer = QuerySession(net, limits).check_global("ReachabilityDeadlock")
    assert answer.value is True and "STUBBORN_SETS" in answer.techniques
    assert replay(net, answer.trace or ()) == tuple(
        int(i == 2) for _ in range(10) for i in range(3)
    )


def test_unknown_global_examination() -> None:
    with pytest.raises(ValueError, match="unknown global examination"):
        QuerySession(mutex()).check_global("Reversibility")


def test_examination_of_reads_file_names_and_ids() -> None:
    q = Const(True)
    assert examination_of(prop("x", q, "dir/CTLFireability.xml")) == "CTLFireability"
    assert examination_of(prop("x", q, "M.LTLCardinality.xml")) == "LTLCardinality"
    assert examination_of(prop("M-UpperBounds-03", q, "q.xml")) == "UpperBounds"
    assert examination_of(prop("x", q, "q.xml")) is None


def test_answer_json() -> None:
    answer = Answer("f", False, ("EXPLICIT",), 0.5, "ctl", ("t",), None, None, "CTLFireability")
    assert answer.to_dict()["trace_kind"] == "counterexample"
    assert answer.to_dict()["status"] == "answered"
    assert Answer("g", None, reason="x").to_dict()["status"] == "cannot_compute"


@pytest.mark.slow
@pytest.mark.parametrize("width", [1, 12])
def test_explore_stop_when_stops_at_the_shallowest_hit(width: int) -> None:
    """``explore(stop_when=...)``: narrow layers (one chain) and wide ones (12 chains)."""
    import numpy as np
    import numpy.typing as npt

    from analysis.statespace import explore

    net = make_net(
        "chains",
        {f"c{k}p{i}": int(i == 0) for k in range(width) for i in range(6)},
        {
            f"c{k}t{i}": ({f"c{k}p{i}": 1}, {f"c{k}p{i + 1}": 1})
            for k in range(width)
            for i in range(5)
        },
    )
    target = net.place_index("c0p4")
    full = explore(net)
    expected = full.find(lambda m: m[:, target] == 1)
    assert expected is not None
    hits: list[int] = []

    def stop_when(first: int, markings: npt.NDArray[np.int64]) -> bool:
        found = np.flatnonzero(markings[:, target] == 1)
        if found.size:
            hits.append(first + int(found[0]))
        return bool(found.size)

    part = explore(net, stop_when=stop_when)
    assert part.stopped_reason == STOPPED_BY_REQUEST and not part.complete
    assert hits == [expected]
    assert part.marking(hits[0]) == full.marking(expected)
    assert len(part.trace_to(hits[0])) == 4
    assert replay(net, tuple(part.trace_names(hits[0])))[target] == 1
    if width > 1:
        assert part.states < full.states


def test_unknown_names_are_cannot_compute_not_a_crash() -> None:
    answers = QuerySession(mutex()).check(
        [
            prop("p", Exists(Finally(at_least("nope", 1)))),
            prop("b", PlaceBound(("cs1", "nada"))),
            prop("ok", Exists(Finally(at_least("cs1", 1)))),
        ]
    )
    assert [a.value for a in answers] == [None, None, True]
    assert answers[0].reason == "cannot check: the net has no place 'nope'"
    assert answers[1].reason == "cannot check: the net has no place 'nada'"


SMALL_BUDGET_MODELS = (
    "Dekker-PT-010",
    "Peterson-PT-2",
    "SimpleLoadBal-PT-02",
    "Philosophers-PT-000005",
    "DoubleExponent-PT-002",
    "Eratosthenes-PT-010",
)


@pytest.mark.slow
@pytest.mark.parametrize("name", SMALL_BUDGET_MODELS)
def test_deadlock_with_a_search_too_small_is_never_wrong(name: str) -> None:
    """With 20 markings no search completes: a deadlock-free net may then be proven so by
    the state equation (FALSE), a deadlock found is TRUE, and nothing else is guessed."""
    oracle = {
        m["model"]: m for m in yaml.safe_load((CONFORMANCE / "oracle.yaml").read_text())["models"]
    }
    expected = oracle[name]["deadlock"]
    net = read_pnml(CONFORMANCE / "pnml" / f"{name}.pnml")
    limits = QueryLimits(max_states=20, reductions=False)  # the state equation's turn
    answer = QuerySession(net, limits).check_global("ReachabilityDeadlock")
    assert answer.value in (expected, None)
    if answer.value is False:
        assert answer.techniques == ("STATE_EQUATION",)


def test_deadlock_freedom_of_a_large_net_is_proven_without_exploring_it() -> None:
    """Kanban-PT-00005 has 2.5M markings; 1,000 are explored, z3 proves the rest."""
    net = read_pnml(CONFORMANCE / "pnml" / "Kanban-PT-00005.pnml")
    limits = QueryLimits(max_states=1_000, reductions=False)  # they reduce it to nothing
    answer = QuerySession(net, limits).check_global("ReachabilityDeadlock")
    assert answer.value is False
    assert answer.mcc_line().endswith("FALSE TECHNIQUES STATE_EQUATION")
