"""`--method` end to end: verify, the report's figures and verdicts, and query, with
the decision diagram (`analysis.symbolic.report`)."""

from __future__ import annotations

import json
import time

import pytest

from analysis.budget import Budget
from analysis.cli import main
from analysis.examinations import QueryLimits, QuerySession
from analysis.query_cli import query_main
from analysis.report import Verdict
from analysis.symbolic.report import SYMBOLIC
from analysis.verify import VerifyOptions, verify
from coral_lang.net import Net, Place, Transition
from coral_lang.pnml.read import read_pnml
from tests.analysis.nets import replay_names
from tests.conftest import CONFORMANCE

PHILOSOPHERS = CONFORMANCE / "pnml" / "Philosophers-PT-000005.pnml"


def _cycles(n: int) -> Net:
    """n independent two-place cycles: 2^n markings, no deadlock."""
    places = [Place(f"{s}{i}", initial=int(s == "a")) for i in range(n) for s in "ab"]
    trs = [
        Transition(f"{a}{i}", inputs=((f"{a}{i}", 1),), outputs=((f"{b}{i}", 1),))
        for i in range(n)
        for a, b in (("a", "b"), ("b", "a"))
    ]
    return Net(f"cycles{n}", tuple(places), tuple(trs))


def test_symbolic_method_gives_figures_and_a_replayable_deadlock() -> None:
    net = read_pnml(PHILOSOPHERS)
    report = verify(net, VerifyOptions(method="symbolic", structural=False))
    space = report.statespace
    assert space.method == "symbolic" and space.complete
    assert space.states == 243 and space.max_tokens_place == 1
    assert report.to_dict()["statespace"]["method"] == "symbolic"  # type: ignore[index]
    deadlock = report.property("deadlock")
    assert deadlock.verdict is Verdict.VIOLATED and deadlock.method == SYMBOLIC
    assert deadlock.evidence is not None and deadlock.evidence.trace
    final = replay_names(net, [step.transition for step in deadlock.evidence.trace])
    assert final == deadlock.evidence.marking
    assert report.property("bounded").method == SYMBOLIC


def test_explicit_method_keeps_the_explicit_figures() -> None:
    report = verify(read_pnml(PHILOSOPHERS), VerifyOptions(method="explicit", structural=False))
    assert report.statespace.method == "explicit"
    assert report.statespace.edges > 0
    assert report.property("deadlock").method != SYMBOLIC


def test_auto_turns_to_diagrams_when_the_explicit_search_stops() -> None:
    """2^24 markings: the explicit search stops at its state budget, the diagram
    counts them all and proves deadlock freedom."""
    net = _cycles(24)
    report = verify(net, VerifyOptions(max_states=100_000, structural=False))
    assert report.statespace.method == "symbolic"
    assert report.statespace.complete and report.statespace.states == 2**24
    assert report.property("deadlock").verdict is Verdict.PROVEN
    assert report.property("deadlock").method == SYMBOLIC
    assert report.property("bounded").verdict is Verdict.PROVEN


def test_symbolic_verify_stops_within_its_time_limit() -> None:
    # Peterson-PT-3: its diagram does not finish in 60 s (Peterson-PT-2 now does in 1 s)
    net = read_pnml(CONFORMANCE / "pnml" / "Peterson-PT-3.pnml")
    started = time.monotonic()
    report = verify(
        net, VerifyOptions(method="symbolic", time_limit=1.0, structural=False), budget=Budget()
    )
    assert time.monotonic() - started < 3.0
    assert not report.statespace.complete
    assert report.statespace.stopped_reason is not None
    assert "time limit" in report.statespace.stopped_reason


def test_cli_method_symbolic_json(capsys: pytest.CaptureFixture[str]) -> None:
    code = main(
        ["verify", str(PHILOSOPHERS), "--method", "symbolic", "--no-structure", "--format", "json"]
    )
    document = json.loads(capsys.readouterr().out)["files"][0]["report"]
    assert code == 1  # the deadlock
    assert document["statespace"]["method"] == "symbolic"
    assert document["deadlock"]["method"] == SYMBOLIC and document["deadlock"]["trace"]


def test_query_deadlock_from_the_diagram(capsys: pytest.CaptureFixture[str]) -> None:
    net = read_pnml(PHILOSOPHERS)
    session = QuerySession(net, QueryLimits(method="symbolic"))
    answer = session.check_global("ReachabilityDeadlock")
    assert answer.value is True and answer.techniques == ("DECISION_DIAGRAMS",)
    assert answer.trace is not None
    replay_names(net, list(answer.trace))
    code = query_main(
        [
            str(PHILOSOPHERS),
            "--examination",
            "ReachabilityDeadlock",
            "--method",
            "symbolic",
            "--format",
            "json",
        ]
    )
    document = json.loads(capsys.readouterr().out)
    assert code == 0
    assert document["method"] == "symbolic" and document["states"] == 243
