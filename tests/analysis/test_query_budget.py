"""`coral-check query` under one command budget: the time limit bounds every formula
(those not reached say "not computed: ..."), the memory limit stops its searches, and a
failed allocation is a per-formula CANNOT_COMPUTE, never a traceback or exit 1."""

from __future__ import annotations

import gzip
import json
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest

from analysis import examinations, stateeq
from analysis.budget import Budget
from analysis.cli import main
from analysis.examinations import QueryLimits, QuerySession
from analysis.mccxml import MccProperty, PlaceBound
from coral_lang.formula import All, Compare, Exists, Finally, Globally, IntConst, Tokens
from tests.analysis.nets import mutex
from tests.analysis.wide_nets import rings
from tests.conftest import REPO

MCC = REPO / "tests" / "data" / "mcc"
MODEL = "Philosophers-PT-000005"


def prop(ident: str, query: object) -> MccProperty:
    return MccProperty(ident, query, 1, "q.xml")  # type: ignore[arg-type]


def at_least(place: str, n: int) -> Compare:
    return Compare(Tokens(((place, 1),)), ">=", IntConst(n))


def _formulas() -> list[MccProperty]:
    """One formula of each kind: reachability, CTL, LTL, a bound, the initial marking."""
    return [
        prop("ef", Exists(Finally(at_least("cs1", 1)))),
        prop("ctl", All(Finally(at_least("cs1", 1)))),
        prop("ltl", All(Globally(Finally(at_least("cs1", 1))))),
        prop("bound", PlaceBound(("cs1",))),
        prop("initial", at_least("cs1", 1)),
    ]


class _Clock:
    """A clock that jumps ``step`` seconds per reading."""

    def __init__(self, step: float) -> None:
        self.now = 0.0
        self.step = step

    def __call__(self) -> float:
        self.now += self.step
        return self.now


def test_formulas_past_the_deadline_say_not_computed_and_why() -> None:
    session = QuerySession(mutex(), QueryLimits(time_limit=5), clock=_Clock(100.0))
    answers = {a.id: a for a in session.check(_formulas())}
    assert answers["initial"].value is False  # needs no search: answered anyway
    for ident in ("ctl", "ltl", "bound"):
        assert answers[ident].value is None
        assert "time limit of 5 s reached" in (answers[ident].reason or ""), ident
    deadlock = session.check_global("ReachabilityDeadlock")
    assert deadlock.value is None and "time limit of 5 s" in (deadlock.reason or "")


def test_the_memory_limit_stops_every_formula_with_its_reason() -> None:
    # One byte: the process is over it at the first look.
    session = QuerySession(mutex(), QueryLimits(memory_limit=1))
    answers = {a.id: a for a in session.check(_formulas())}
    assert answers["initial"].computed
    for ident in ("ef", "ctl", "ltl", "bound"):
        assert answers[ident].value is None, ident
        assert "memory limit of 1 B reached" in (answers[ident].reason or ""), ident
    for name in examinations.GLOBAL_EXAMINATIONS:
        answer = session.check_global(name)
        assert answer.value is None and "memory limit" in (answer.reason or ""), name


def test_a_failed_allocation_is_cannot_compute_for_the_formulas_left(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    calls = []

    def failing(*args: object, **kwargs: object) -> object:
        calls.append(1)
        raise MemoryError

    monkeypatch.setattr(examinations, "explore", failing)
    session = QuerySession(mutex(), QueryLimits(memory_limit=64 << 30))
    answers = session.check(_formulas())
    assert [a.computed for a in answers] == [False, False, False, False, True]
    for answer in answers[:4]:
        assert "memory limit of 64 GiB reached" in (answer.reason or ""), answer.id
    assert session.check_global("Liveness").value is None
    assert len(calls) == 1  # spent after the first failure: nothing retried


def test_memory_error_in_the_cli_is_exit_3_with_a_line_per_formula(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    model = tmp_path / "model.pnml"
    model.write_bytes(gzip.decompress((MCC / "pnml" / f"{MODEL}.pnml.gz").read_bytes()))
    queries = tmp_path / "UpperBounds.xml"
    queries.write_bytes(
        gzip.decompress((MCC / "queries" / f"{MODEL}.UpperBounds.xml.gz").read_bytes())
    )

    def failing(self: QuerySession) -> npt.NDArray[np.integer]:
        raise MemoryError

    monkeypatch.setattr(QuerySession, "table", failing)
    code = main(["query", str(model), str(queries), "--format", "json", "--memory-limit", "64G"])
    document = json.loads(capsys.readouterr().out)
    assert code == 3
    assert document["cannot_compute"] == len(document["results"]) > 0
    assert all("memory limit of 64 GiB" in r["reason"] for r in document["results"])


def test_state_equation_building_stops_at_the_deadline() -> None:
    net = rings(40, 10)  # 800 arcs, about 0.1 s to build
    budget = Budget(0.0)
    result = stateeq.check_unreachable(net, stateeq.deadlocks(), budget=budget)
    assert isinstance(result, stateeq.Unknown)
    assert "building the constraints: time limit of 0 s reached" in result.reason


def test_state_equation_is_skipped_when_the_time_left_cannot_build_it(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    net = rings(3, 4)
    tried = []
    monkeypatch.setattr(stateeq, "check_unreachable", lambda *a, **k: tried.append(1))
    session = QuerySession(net, QueryLimits(time_limit=1.0))
    monkeypatch.setattr(examinations, "STATE_EQUATION_SECONDS_PER_ARC", 10.0)
    assert session._deadlock_free_by_state_equation() is None
    assert tried == []


def test_state_equation_still_proves_when_there_is_time() -> None:
    session = QuerySession(rings(3, 4), QueryLimits(time_limit=60.0))
    proof = session._deadlock_free_by_state_equation()
    assert proof is not None and proof.value is False


def test_ltl_and_ctl_stop_at_the_memory_limit_with_its_reason() -> None:
    from analysis.budget import BudgetExceeded
    from analysis.ctl import CtlChecker
    from analysis.ltl import check_ltl
    from analysis.stategraph import build_graph
    from analysis.statespace import explore

    graph = build_graph(explore(mutex()))
    body = Finally(at_least("cs1", 1))
    with pytest.raises(BudgetExceeded, match="memory limit of 1 B reached"):
        check_ltl(graph, All(Globally(body)), budget=Budget(memory=1))
    with pytest.raises(BudgetExceeded, match="labelling stopped: memory limit of 1 B"):
        CtlChecker(graph, budget=Budget(memory=1)).holds(All(body))
    # With room, the same check answers (AG AF cs1 fails: process 2 may keep the lock).
    assert check_ltl(graph, All(Globally(body)), budget=Budget(memory=1 << 40)).holds is False
