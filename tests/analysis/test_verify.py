"""verify(): each verdict, its method, and its evidence, on missions and on nets."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import yaml
from hypothesis import given, settings

from analysis.cli import main
from analysis.report import Verdict
from analysis.verify import VerifyOptions, run_verification, verify
from coral_lang import Net, compile_mission, compile_source, read_pnml
from tests.analysis.reference import explore_reference
from tests.analysis.strategies import small_nets
from tests.conftest import CONFORMANCE, EXAMPLES

FAULTY = EXAMPLES / "faulty"
POOL = EXAMPLES / "pool_mission" / "pool_mission.coral"
FAST = VerifyOptions(structural=False)


def _lines(result_steps: object) -> list[int]:
    return [step.span.line for step in result_steps if step.span]  # type: ignore[attr-defined]


def test_pool_mission_verifies_clean() -> None:
    report = verify(compile_mission(POOL))
    assert report.verdict is Verdict.PROVEN and report.exit_code() == 0
    assert report.statespace.complete and report.statespace.states == 82
    keys = {p.key for p in report.properties}
    assert {
        "bounded",
        "deadlock",
        "final_reachable",
        "dead_transitions",
        "resource_conflicts",
        "assert:1",
        "assert:2",
        "assert:3",
    } <= keys
    assert report.structure["invariants"]


def test_faulty_deadlock_has_shortest_trace_with_replies_and_lines() -> None:
    report = verify(compile_mission(FAULTY / "deadlock.coral"), FAST)
    deadlock = report.property("deadlock")
    assert deadlock.verdict is Verdict.VIOLATED and deadlock.evidence is not None
    trace = deadlock.evidence.trace
    assert len(trace) == 5
    assert deadlock.evidence.marking == {"abort": 2}
    replies = [s.description for s in trace if s.kind == "reply"]
    assert replies == [
        "set_heading: HEADING replied error",
        "set_depth: DEPTH replied error",
    ] or replies == ["set_depth: DEPTH replied error", "set_heading: HEADING replied error"]
    source = (FAULTY / "deadlock.coral").read_text().splitlines()
    for step in trace:
        assert step.span is not None and step.span.file.endswith("deadlock.coral")
        assert (
            step.transition.split(".")[0] in source[step.span.line - 1]
            or (step.reply or "?") in source[step.span.line - 1]
        )


@pytest.mark.slow
def test_faulty_unbounded_names_the_place_with_a_pumping_loop() -> None:
    report = verify(compile_mission(FAULTY / "unbounded.coral"), FAST)
    bounded = report.property("bounded")
    assert bounded.verdict is Verdict.VIOLATED and bounded.items == ("lap_logged",)
    assert bounded.evidence is not None and bounded.evidence.loop
    assert [s.transition for s in bounded.evidence.loop][-1] == "next_lap"


def test_faulty_resource_conflict_is_found_and_nothing_else_is_wrong() -> None:
    report = verify(compile_mission(FAULTY / "resource_conflict.coral"), FAST)
    violated = {p.key for p in report.properties if p.verdict is Verdict.VIOLATED}
    assert violated == {"resource_conflicts"}
    conflict = report.property("resource_conflicts")
    assert conflict.evidence is not None and conflict.evidence.marking is not None
    assert {"go_to_site.pending", "hold_heading.pending"} <= set(conflict.evidence.marking) or {
        "go_to_site.pending",
        "check_heading.pending",
    } <= set(conflict.evidence.marking)
    assert "heading" in conflict.detail


def test_faulty_dead_transition_lists_transition_and_place() -> None:
    report = verify(compile_mission(FAULTY / "dead_transition.coral"), FAST)
    assert "record_dock" in report.property("dead_transitions").items
    assert "position_fixed" in report.property("never_marked_places").items
    assert report.property("deadlock").evidence.marking == {"fixed": 1}  # type: ignore[union-attr]


HEADER = "mission m\nvehicle ROMEO\n"
MUTEX = (
    HEADER
    + """
place idle_a = 1, idle_b = 1, lock = 1, crit_a, crit_b
transition enter_a wait { idle_a, lock } signal { crit_a }
transition leave_a wait { crit_a } signal { idle_a, lock }
transition enter_b wait { idle_b, lock } signal { crit_b }
transition leave_b wait { crit_b } signal { idle_b, lock }
assert never { crit_a, crit_b }
assert bound lock <= 1
assert reachable { crit_b }
"""
)


def test_assertions_proven_by_exhaustive_search() -> None:
    report = verify(compile_source(MUTEX, "mutex.coral").raise_for_errors(), FAST)
    results = {p.key: p for p in report.properties}
    assert results["assert:1"].verdict is Verdict.PROVEN
    assert results["assert:2"].verdict is Verdict.PROVEN
    assert (
        results["assert:3"].verdict is Verdict.PROVEN and results["assert:3"].evidence is not None
    )
    assert results["assert:1"].span is not None and results["assert:1"].span.line == 9


def test_safety_assertions_proven_by_state_equation_when_search_is_cut_short() -> None:
    net = compile_source(MUTEX, "mutex.coral").raise_for_errors()
    report = verify(net, VerifyOptions(max_states=2, structural=False))
    assert not report.statespace.complete
    never = report.property("assert:1")
    assert never.verdict is Verdict.PROVEN and never.method.startswith("state equation")
    deadlock = report.property("deadlock")  # the reduced net (no place left) decides first
    assert deadlock.verdict is Verdict.PROVEN
    assert deadlock.method.startswith(("state equation", "structural reductions"))


def test_violated_assertions_come_with_a_trace() -> None:
    text = MUTEX.replace("assert never { crit_a, crit_b }", "assert never { crit_a, idle_b }")
    report = verify(compile_source(text, "m.coral").raise_for_errors(), FAST)
    never = report.property("assert:1")
    assert never.verdict is Verdict.VIOLATED and never.evidence is not None
    assert [s.transition for s in never.evidence.trace] == ["enter_a"]
    unreachable = text.replace("assert reachable { crit_b }", "assert reachable { crit_a, crit_b }")
    report = verify(compile_source(unreachable, "m.coral").raise_for_errors(), FAST)
    assert report.property("assert:3").verdict is Verdict.VIOLATED


def test_no_final_reachable_is_violated() -> None:
    text = HEADER + "place a = 1, b, c\ntransition t wait { a } signal { b }\nfinal { c }\n"
    report = verify(compile_source(text, "m.coral").raise_for_errors(), FAST)
    assert report.property("final_reachable").verdict is Verdict.VIOLATED


@pytest.mark.slow
def test_inconclusive_when_neither_search_nor_state_equation_decides() -> None:
    net = read_pnml(CONFORMANCE / "pnml" / "LamportFastMutEx-PT-2.pnml")
    report = verify(net, VerifyOptions(max_states=5, structural=False))
    deadlock = report.property("deadlock")
    assert deadlock.verdict is Verdict.INCONCLUSIVE
    assert "incomplete" in deadlock.detail and "not a counterexample" in deadlock.detail
    assert report.exit_code() == 3


ORACLE = yaml.safe_load((CONFORMANCE / "oracle.yaml").read_text())
SMALL = [m for m in ORACLE["models"] if m["states"] <= 20_000]


@pytest.mark.slow
@pytest.mark.parametrize("model", SMALL, ids=[m["model"] for m in SMALL])
def test_verify_agrees_with_the_conformance_oracle(model: dict[str, object]) -> None:
    net = read_pnml(CONFORMANCE / str(model["pnml"]))
    report = verify(net, FAST)
    space = report.statespace
    assert (space.states, space.edges) == (model["states"], model["edges"])
    assert space.max_tokens_place == model["max_tokens_place"]
    assert space.max_tokens_marking == model["max_tokens_marking"]
    deadlock = report.property("deadlock").verdict
    assert deadlock is (Verdict.VIOLATED if model["deadlock"] else Verdict.PROVEN)
    if model["quasi_live"] is not None:
        dead = report.property("dead_transitions").verdict
        assert dead is (Verdict.PROVEN if model["quasi_live"] else Verdict.VIOLATED)


@pytest.mark.slow
@given(small_nets())
@settings(max_examples=60)
def test_verify_never_contradicts_the_reference_explorer(net: Net) -> None:
    reference = explore_reference(net, max_states=400)  # below verify's budget: when the
    report = verify(
        net, VerifyOptions(max_states=500, time_limit=10, structural=False)
    )  # reference completes, so does verify
    deadlock = report.property("deadlock")
    bounded = report.property("bounded")
    if reference.complete:
        assert bounded.verdict is Verdict.PROVEN
        assert deadlock.verdict is (Verdict.VIOLATED if reference.dead else Verdict.PROVEN)
        if reference.dead:
            assert deadlock.evidence is not None
            shortest = min(len(reference.trace_to(m)) for m in reference.dead)
            assert len(deadlock.evidence.trace) == shortest
    if bounded.verdict is Verdict.VIOLATED:
        assert not reference.complete
    if deadlock.verdict is Verdict.PROVEN:
        assert not reference.dead
    if deadlock.verdict is Verdict.VIOLATED and deadlock.evidence is not None:
        marking = net.initial_marking()
        for step in deadlock.evidence.trace:
            transition = net.transition(step.transition)
            assert net.enabled(marking, transition)
            marking = net.fire(marking, transition)
        assert not any(net.enabled(marking, t) for t in net.transitions)


@pytest.mark.slow
def test_cli_verify_json_schema_and_exit_codes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "report.json"
    assert main(["verify", str(POOL), "--format", "json", "-o", str(out)]) == 0
    data = json.loads(out.read_text())["files"][0]["report"]
    assert set(data["statespace"]) >= {"states", "edges", "max_tokens_place", "max_tokens_marking"}
    assert set(data["deadlock"]) >= {"verdict", "trace"} and data["deadlock"]["verdict"] == "proven"
    assert set(data["bounded"]) >= {"verdict", "unbounded_places"}
    assert (
        main(["verify", str(FAULTY / "unbounded.coral"), "--format", "json", "--no-structure"]) == 1
    )
    data = json.loads(capsys.readouterr().out)["files"][0]["report"]
    assert data["bounded"] == {
        "verdict": "violated",
        "method": "Karp-Miller coverability tree",
        "unbounded_places": ["lap_logged"],
    }
    lamport = str(CONFORMANCE / "pnml" / "LamportFastMutEx-PT-2.pnml")
    assert main(["verify", lamport, "--max-states", "5", "--no-structure"]) == 3
    assert main(["verify", str(tmp_path / "missing.coral")]) == 2
    assert main(["verify", str(FAULTY / "unhandled_reply.coral")]) == 1
    assert main(["verify", "--max-states", "0", str(POOL)]) == 2
    capsys.readouterr()
    assert main(["verify", "--help"]) == 0
    assert "exit codes: 0 clean" in capsys.readouterr().out


def test_text_report_shows_verdicts_traces_and_no_colour_in_a_pipe(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["verify", str(FAULTY / "deadlock.coral"), "--no-structure"]) == 1
    out = capsys.readouterr().out
    assert "VIOLATED" in out and "set_depth: DEPTH replied error" in out and "\033[" not in out
    assert "deadlock.coral:" in out


def test_state_equation_solution_realised_into_a_replayable_deadlock(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # The reductions' random walk would find this deadlock first: switched off here.
    monkeypatch.setattr("analysis.reduce.deadlock.walk_to_deadlock", lambda net: None)
    net = read_pnml(CONFORMANCE / "pnml" / "Philosophers-PT-000005.pnml")
    report = verify(net, VerifyOptions(max_states=3, structural=False))
    assert not report.statespace.complete
    deadlock = report.property("deadlock")
    assert deadlock.verdict is Verdict.VIOLATED
    assert deadlock.method == "state equation, solution realised as a firing sequence"
    assert deadlock.evidence is not None
    marking = net.initial_marking()
    for step in deadlock.evidence.trace:
        transition = net.transition(step.transition)
        assert net.enabled(marking, transition)
        marking = net.fire(marking, transition)
    assert not any(net.enabled(marking, t) for t in net.transitions)
    assert net.marking_dict(marking) == deadlock.evidence.marking


def test_a_net_of_30_million_cells_is_verified_end_to_end_from_pnml(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """6,001 places x 5,000 transitions: refused until dense matrices were dropped from
    every method it needs; a chain of one token gives exact, checkable answers."""
    from coral_lang.pnml import write_pnml
    from tests.analysis.wide_nets import chain

    net = chain(5_000, spare_places=1_000)
    assert len(net.places) * len(net.transitions) > 30_000_000
    path = tmp_path / "wide.pnml"
    write_pnml(net, path)
    code = main(["verify", str(path), "--no-structure", "--format", "json"])
    report = json.loads(capsys.readouterr().out)["files"][0]["report"]
    assert code == 1 and report["verdict"] == "violated"  # the token stops at the end
    figures = report["statespace"]
    assert (figures["states"], figures["edges"], figures["complete"]) == (5_001, 5_000, True)
    assert figures["max_tokens_place"] == 1 and report["bounded"]["verdict"] == "proven"
    deadlock = report["deadlock"]
    assert deadlock["verdict"] == "violated"
    assert [step["transition"] for step in deadlock["trace"]] == [f"t{k}" for k in range(5_000)]


def test_run_verification_keeps_the_state_space_of_its_report() -> None:
    net = compile_mission(EXAMPLES / "pool_mission" / "pool_mission.coral")
    verification = run_verification(net, VerifyOptions(structural=False))
    space = verification.space
    assert space is not None and space.complete and not space.reduced
    figures = verification.report.statespace
    assert (space.states, space.edges) == (figures.states, figures.edges) == (82, 139)
    assert [p.verdict for p in verification.report.properties] == [
        p.verdict for p in verify(net, VerifyOptions(structural=False)).properties
    ]


@pytest.mark.slow
def test_structural_boundedness_comes_from_covering_invariants_without_z3() -> None:
    net = compile_mission(EXAMPLES / "pool_mission" / "pool_mission.coral")
    structure = verify(net).structure
    invariants = structure["invariants"]
    assert isinstance(invariants, dict) and invariants["covered_by_p_invariants"] is True
    assert structure["structural_boundedness"] == {
        "verdict": True,
        "summary": "structurally bounded: the P-invariants cover every place, so their sum "
        "is a positive weighting y with y^T C = 0",
    }
    unbounded = compile_mission(EXAMPLES / "faulty" / "unbounded.coral")
    facts = verify(unbounded).structure["structural_boundedness"]
    assert isinstance(facts, dict) and facts["verdict"] is False  # the z3 linear program
