"""Termination: no engine cycle, a final marking always reachable, every fair run ends
in one; every dead non-final marking with its own trace; certificates that need them.

Each verdict is checked against a brute-force reference on random mission-like nets
(engine transitions, commands with a pending place, replies), and every lasso is
replayed on the net."""

from __future__ import annotations

import json
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from unittest import mock

import numpy as np
import pytest
from hypothesis import event, given, settings
from hypothesis import strategies as st

import analysis.stategraph as stategraph
import analysis.termination as termination
from analysis.certificate import (
    CertificateError,
    check_certificate,
    make_certificate,
    write_certificate,
)
from analysis.cli import main
from analysis.fairness import fairness_groups
from analysis.outcome import make_outcome
from analysis.report import Evidence, PropertyResult, Step, Verdict
from analysis.sarif import to_sarif
from analysis.stategraph import build_graph, fair_sccs
from analysis.statespace import explore
from analysis.termination import (
    FINAL_ALWAYS_REACHABLE,
    NO_ENGINE_CYCLE,
    TERMINATES,
    FairComponents,
    applies,
    final_states,
    non_final_dead_states,
    required_keys,
)
from analysis.verify import VerifyOptions, verify
from coral_lang import compile_mission, compile_source
from coral_lang.net import (
    Command,
    FinalMarking,
    Net,
    Place,
    PlaceKind,
    Transition,
    TransitionKind,
)
from tests.analysis.nets import mutex
from tests.analysis.reference import explore_reference
from tests.conftest import EXAMPLES

FAULTY = EXAMPLES / "faulty"
FAST = VerifyOptions(structural=False)
HEADER = "mission m\nvehicle ROMEO\n"

# An engine transition ('stop') enabled at every marking of the polling cycle and
# never taken on it: no weakly fair run stays in the cycle, so every fair run ends.
UNFAIR_ONLY = (
    HEADER
    + """
place idle = 1, go = 1, halt
final { idle, halt }
transition poll
    wait   { idle, go }
    signal { go }
    action { ROMEO(DEPTH?, z = 2.0, time_out = 60) -> { done: idle, timeout: idle } }
transition stop
    wait   { go }
    signal { halt }
"""
)

RETRY = (FAULTY / "retry_forever.coral").read_text()


def _net(text: str, name: str = "m.coral") -> Net:
    return compile_source(text, name).raise_for_errors()


def _replay(net: Net, steps: Sequence[Step], marking: tuple[int, ...]) -> tuple[int, ...]:
    for step in steps:
        transition = net.transition(step.transition)
        assert net.enabled(marking, transition), step
        marking = net.fire(marking, transition)
    return marking


def _check_lasso(net: Net, evidence: Evidence) -> tuple[tuple[int, ...], list[tuple[int, ...]]]:
    """Replay a lasso: the prefix from the initial marking, then the loop back to where
    it started (the evidence's marking). Returns the entry and the loop's markings."""
    assert evidence.loop
    entry = _replay(net, evidence.trace, net.initial_marking())
    assert net.marking_dict(entry) == evidence.marking
    visited = [entry]
    marking = entry
    for step in evidence.loop:
        marking = _replay(net, [step], marking)
        visited.append(marking)
    assert marking == entry, "the loop returns to its first marking"
    numbers = [s.number for s in (*evidence.trace, *evidence.loop)]
    assert numbers == list(range(1, len(numbers) + 1))
    return entry, visited


def _groups_of(net: Net) -> dict[str, str]:
    """Fairness group of each transition name (engine: itself; reply: its command)."""
    return {
        t.name: (t.reply_to or "") if t.kind is TransitionKind.REPLY else t.name
        for t in net.transitions
    }


def _fair_on(net: Net, visited: list[tuple[int, ...]], loop: Sequence[Step]) -> bool:
    """Whether a loop through ``visited`` taking ``loop`` satisfies weak fairness: each
    group enabled at every visited marking is taken on it."""
    group = _groups_of(net)
    taken = {group[s.transition] for s in loop}
    always = None
    for marking in visited:
        here = {group[t.name] for t in net.transitions if net.enabled(marking, t)} - {""}
        always = here if always is None else always & here
    return not (always or set()) - taken


# -- the examples -----------------------------------------------------------------------


def test_livelock_is_an_engine_cycle_with_a_lasso_at_its_lines() -> None:
    net = compile_mission(FAULTY / "livelock.coral")
    report = verify(net, FAST)
    assert report.property("deadlock").verdict is Verdict.PROVEN  # deadlock-free, yet wrong
    cycle = report.property(NO_ENGINE_CYCLE)
    assert cycle.verdict is Verdict.VIOLATED and cycle.required
    assert cycle.evidence is not None
    assert [s.transition for s in cycle.evidence.trace] == ["set_depth", "set_depth.error"]
    assert [s.transition for s in cycle.evidence.loop] == ["ping", "pong"]
    assert [s.span.line for s in cycle.evidence.loop if s.span] == [27, 31]
    assert cycle.evidence.trace[1].span is not None and cycle.evidence.trace[1].span.line == 21
    _check_lasso(net, cycle.evidence)
    assert set(cycle.items) == {"ping", "pong"}
    final = report.property(FINAL_ALWAYS_REACHABLE)
    assert final.verdict is Verdict.VIOLATED and final.evidence is not None
    assert final.evidence.marking == {"depth_failed": 1} and len(final.evidence.trace) == 2
    assert report.verdict is Verdict.VIOLATED and report.exit_code() == 1


def test_retry_forever_needs_termination_and_its_lasso_is_fair() -> None:
    net = compile_mission(FAULTY / "retry_forever.coral")
    assert net.requirements == ("termination",)
    report = verify(net, FAST)
    assert report.property(NO_ENGINE_CYCLE).verdict is Verdict.PROVEN
    assert report.property(FINAL_ALWAYS_REACHABLE).verdict is Verdict.PROVEN
    terminates = report.property(TERMINATES)
    assert terminates.verdict is Verdict.VIOLATED and terminates.required
    evidence = terminates.evidence
    assert evidence is not None
    assert [s.description for s in evidence.loop] == [
        "check_depth: sends ROMEO(DEPTH?, z = 2.0, time_out = 60.0)",
        "check_depth: DEPTH? replied timeout",
        "retry",
    ]
    assert [s.span.line for s in evidence.loop if s.span] == [24, 26, 28]
    _, visited = _check_lasso(net, evidence)
    assert _fair_on(net, visited, evidence.loop)
    assert report.verdict is Verdict.VIOLATED and report.exit_code() == 1


def test_without_require_termination_a_fair_cycle_is_a_warning_only(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    text = RETRY.replace("require termination\n", "# termination not required\n")
    net = _net(text, "retry.coral")
    report = verify(net, FAST)
    terminates = report.property(TERMINATES)
    assert terminates.verdict is Verdict.VIOLATED and not terminates.required
    assert terminates.warning and terminates.to_dict()["required"] is False
    assert report.verdict is Verdict.PROVEN and report.exit_code() == 0
    text_report = report.render_text()
    assert "WARNING" in text_report and "not required" in text_report
    assert "then repeat forever:" in text_report and "retry.coral:28" in text_report
    assert text_report.splitlines()[-1].endswith("0 violated, 0 inconclusive, 1 warning")
    # The CLI passes, the certificate passes and lists the violated property.
    mission = tmp_path / "retry.coral"
    mission.write_text(text)
    cert = tmp_path / "retry.cert.json"
    assert main(["verify", str(mission), "--no-structure", "--certificate", str(cert)]) == 0
    assert "WARNING" in capsys.readouterr().out
    assert main([str(mission)]) == 0  # lint and verify: CI passes, the warning is shown
    assert "retry.coral: proven, 0 warnings, 1 property warning" in capsys.readouterr().out
    listed = {p["key"]: p for p in json.loads(cert.read_text())["properties"]}
    assert listed[TERMINATES]["verdict"] == "violated" and listed[TERMINATES]["required"] is False
    check_certificate(net, cert)


def test_an_unfair_cycle_does_not_break_termination() -> None:
    report = verify(_net(UNFAIR_ONLY), FAST)
    for key in (NO_ENGINE_CYCLE, FINAL_ALWAYS_REACHABLE, TERMINATES):
        assert report.property(key).verdict is Verdict.PROVEN, key
    assert report.verdict is Verdict.PROVEN


def test_pool_mission_proves_all_three() -> None:
    net = compile_mission(EXAMPLES / "pool_mission" / "pool_mission.coral")
    report = verify(net, FAST)
    for key in (NO_ENGINE_CYCLE, FINAL_ALWAYS_REACHABLE, TERMINATES):
        result = report.property(key)
        assert result.verdict is Verdict.PROVEN and result.required == (key != TERMINATES)
        assert "82" in result.detail


def test_a_deadlock_alone_violates_termination_with_its_trace() -> None:
    text = HEADER + (
        "place a = 1, b, c\nfinal { c }\n"
        "transition t wait { a } signal { b }\ntransition u wait { a } signal { c }\n"
    )
    report = verify(_net(text), FAST)
    terminates = report.property(TERMINATES)
    assert terminates.verdict is Verdict.VIOLATED and terminates.evidence is not None
    assert terminates.evidence.marking == {"b": 1} and not terminates.evidence.loop
    assert [s.transition for s in terminates.evidence.trace] == ["t"]
    assert report.property(NO_ENGINE_CYCLE).verdict is Verdict.PROVEN
    final = report.property(FINAL_ALWAYS_REACHABLE)
    assert final.verdict is Verdict.VIOLATED and final.evidence is not None
    assert final.evidence.marking == {"b": 1} and "(a dead marking)" in final.detail
    assert "1 of the 3 reachable markings" in final.detail


def test_a_mission_without_finals_can_never_end_properly() -> None:
    report = verify(_net(HEADER + "place a = 1\n"), FAST)
    final = report.property(FINAL_ALWAYS_REACHABLE)
    assert final.verdict is Verdict.VIOLATED and "declares no final marking" in final.detail


def test_which_nets_get_the_properties() -> None:
    plain = mutex()  # a PNML-like model: no finals, no commands, no vehicle
    assert not applies(plain) and required_keys(plain) == ()
    keys = {p.key for p in verify(plain, FAST).properties}
    assert not keys & {NO_ENGINE_CYCLE, FINAL_ALWAYS_REACHABLE, TERMINATES}
    with_final = Net(plain.name, plain.places, plain.transitions, finals=(FinalMarking(()),))
    assert applies(with_final) and required_keys(with_final) == (
        NO_ENGINE_CYCLE,
        FINAL_ALWAYS_REACHABLE,
    )
    retry = compile_mission(FAULTY / "retry_forever.coral")
    assert required_keys(retry) == (NO_ENGINE_CYCLE, FINAL_ALWAYS_REACHABLE, TERMINATES)


def test_an_unknown_requirement_is_inconclusive_not_ignored() -> None:
    net = _net(UNFAIR_ONLY)
    odd = Net(net.name, net.places, net.transitions, net.finals, requirements=("fairness",))
    report = verify(odd, FAST)
    result = report.property("require:fairness")
    assert result.verdict is Verdict.INCONCLUSIVE and "termination" in result.detail
    assert report.verdict is Verdict.INCONCLUSIVE


# -- every dead non-final marking ---------------------------------------------------------


def test_every_deadlock_is_listed_up_to_the_limit_with_the_rest_counted(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    net = compile_mission(FAULTY / "deadlock.coral")
    reference = explore_reference(net)
    stuck = [m for m in reference.dead if not net.is_final(m)]
    assert len(stuck) >= 3
    full = verify(net, FAST).property("deadlock")
    assert 1 + len(full.more_evidence) == len(stuck) and full.omitted == 0
    listed = [full.evidence, *full.more_evidence]
    assert all(e is not None for e in listed)
    markings = []
    for evidence in listed:
        assert evidence is not None and evidence.marking is not None
        end = _replay(net, evidence.trace, net.initial_marking())
        assert net.marking_dict(end) == evidence.marking
        assert not any(net.enabled(end, t) for t in net.transitions) and not net.is_final(end)
        assert len(evidence.trace) == len(reference.trace_to(end))  # each one's shortest
        markings.append(end)
    assert sorted(markings) == sorted(stuck)
    depths = [len(e.trace) for e in listed if e is not None]
    assert depths == sorted(depths)
    limited = verify(net, VerifyOptions(structural=False, max_deadlocks=2)).property("deadlock")
    assert len(limited.more_evidence) == 1 and limited.omitted == len(stuck) - 2
    assert f"{len(stuck)} such dead markings in all" in limited.detail
    text = verify(net, VerifyOptions(structural=False, max_deadlocks=2)).render_text()
    assert "counterexample 2:" in text and f"and {len(stuck) - 2} more not listed" in text
    # JSON: the first as before, the others listed, the rest counted
    out = tmp_path / "r.json"
    args = ["verify", str(FAULTY / "deadlock.coral"), "--no-structure", "--format", "json"]
    assert main([*args, "--max-deadlocks", "2", "-o", str(out)]) == 1
    data = json.loads(out.read_text())["files"][0]["report"]
    (deadlock,) = [p for p in data["properties"] if p["key"] == "deadlock"]
    assert len(deadlock["more_evidence"]) == 1 and deadlock["omitted"] == len(stuck) - 2
    assert deadlock["required"] is True and deadlock["evidence"]["trace"]
    assert data["deadlock"]["marking"] == deadlock["evidence"]["marking"]
    assert main([*args, "--max-deadlocks", "0"]) == 2
    capsys.readouterr()


def test_sarif_has_one_result_per_deadlock_and_marks_the_loop() -> None:
    net = compile_mission(FAULTY / "deadlock.coral")
    report = verify(net, FAST)
    outcome = make_outcome("examples/faulty/deadlock.coral", [], report=report, net=net)
    results = to_sarif([outcome], tool_version="0", info_uri="urn:x")["runs"][0]["results"]  # type: ignore[index]
    deadlocks = [r for r in results if r["ruleId"] == "CORAL-V-deadlock"]
    prop = report.property("deadlock")
    assert len(deadlocks) == 1 + len(prop.more_evidence)
    for result, evidence in zip(deadlocks, [prop.evidence, *prop.more_evidence], strict=True):
        assert evidence is not None
        flow = result["codeFlows"][0]["threadFlows"][0]["locations"]
        assert len(flow) == len(evidence.trace)
        last = evidence.trace[-1].span
        assert last is not None
        assert result["locations"][0]["physicalLocation"]["region"]["startLine"] == last.line
    livelock = compile_mission(FAULTY / "livelock.coral")
    report = verify(livelock, FAST)
    outcome = make_outcome("examples/faulty/livelock.coral", [], report=report, net=livelock)
    results = to_sarif([outcome], tool_version="0", info_uri="urn:x")["runs"][0]["results"]  # type: ignore[index]
    (cycle,) = [r for r in results if r["ruleId"] == "CORAL-V-no-engine-cycle"]
    steps = cycle["codeFlows"][0]["threadFlows"][0]["locations"]
    assert [s.get("nestingLevel", 0) for s in steps] == [0, 0, 1, 1]
    assert [s.get("properties", {}).get("loop", False) for s in steps] == [0, 0, 1, 1]
    assert "repeat forever" in cycle["codeFlows"][0]["message"]["text"]
    lines = sorted(loc["physicalLocation"]["region"]["startLine"] for loc in cycle["locations"])
    assert lines == [27, 31]  # the cycle's own transitions
    (warning,) = [r for r in results if r["ruleId"] == "CORAL-V-terminates"]
    assert warning["level"] == "warning" and warning["properties"]["required"] is False


# -- incomplete state spaces ---------------------------------------------------------------


@pytest.mark.slow
def test_never_proven_from_an_incomplete_search() -> None:
    net = compile_mission(EXAMPLES / "pool_mission" / "pool_mission.coral")
    report = verify(net, VerifyOptions(structural=False, max_states=10))
    for key in (NO_ENGINE_CYCLE, FINAL_ALWAYS_REACHABLE, TERMINATES):
        result = report.property(key)
        assert result.verdict is Verdict.INCONCLUSIVE and "incomplete" in result.detail, key
    over = verify(net, VerifyOptions(structural=False, max_edges=100))
    for key in (NO_ENGINE_CYCLE, FINAL_ALWAYS_REACHABLE, TERMINATES):
        result = over.property(key)
        assert result.verdict is Verdict.INCONCLUSIVE and "budget of 100" in result.detail, key
    assert over.verdict is Verdict.INCONCLUSIVE and over.exit_code() == 3


def test_an_incomplete_search_still_reports_the_deadlocks_it_found() -> None:
    net = compile_mission(FAULTY / "deadlock.coral")
    report = verify(net, VerifyOptions(structural=False, max_states=20))
    assert not report.statespace.complete
    assert report.property(NO_ENGINE_CYCLE).verdict is Verdict.INCONCLUSIVE
    for key in (FINAL_ALWAYS_REACHABLE, TERMINATES):
        result = report.property(key)
        assert result.verdict is Verdict.VIOLATED and result.evidence is not None, key
        end = _replay(net, result.evidence.trace, net.initial_marking())
        assert not any(net.enabled(end, t) for t in net.transitions) and not net.is_final(end)


def test_partial_order_reduction_explores_the_full_graph_for_these() -> None:
    net = compile_mission(FAULTY / "livelock.coral")
    report = verify(net, VerifyOptions(structural=False, por=True))
    assert report.statespace.reduced
    assert report.property(NO_ENGINE_CYCLE).verdict is Verdict.VIOLATED
    pool = compile_mission(EXAMPLES / "pool_mission" / "pool_mission.coral")
    assert verify(pool, VerifyOptions(structural=False, por=True)).verdict is Verdict.PROVEN


# -- certificates --------------------------------------------------------------------------


def test_an_old_style_certificate_is_refused_with_the_way_out(tmp_path: Path) -> None:
    net = compile_mission(EXAMPLES / "pool_mission" / "pool_mission.coral")
    certificate = make_certificate(verify(net, FAST))
    properties = certificate["properties"]
    assert isinstance(properties, list)
    assert {p["key"]: p["verdict"] for p in properties}[NO_ENGINE_CYCLE] == "proven"
    path = tmp_path / "pool.cert.json"
    write_certificate(certificate, path)
    check_certificate(net, path)
    old = dict(certificate)  # as an older coral wrote it: no termination properties
    old["properties"] = [
        {k: v for k, v in p.items() if k != "required"}
        for p in properties
        if p["key"] not in (NO_ENGINE_CYCLE, FINAL_ALWAYS_REACHABLE, TERMINATES)
    ]
    old["tool_version"] = "0.0.9"
    write_certificate(old, path)
    with pytest.raises(CertificateError) as refused:
        check_certificate(net, path)
    message = str(refused.value)
    assert "no_engine_cycle missing" in message and "final_always_reachable missing" in message
    assert "coral 0.0.9" in message and "coral-check verify MISSION --certificate" in message


def test_require_termination_needs_terminates_proven(tmp_path: Path) -> None:
    net = compile_mission(FAULTY / "retry_forever.coral")
    path = tmp_path / "retry.cert.json"
    certificate = make_certificate(verify(net, FAST))
    assert certificate["verdict"] == "violated"
    write_certificate(certificate, path)
    with pytest.raises(CertificateError, match="terminates violated"):
        check_certificate(net, path)
    # A certificate that says proven but lacks 'terminates' (hand-edited, or older).
    forged = {**certificate, "verdict": "proven"}
    forged["properties"] = [
        {**p, "verdict": "proven"}
        for p in certificate["properties"]  # type: ignore[attr-defined]
        if p["key"] != TERMINATES
    ]
    write_certificate(forged, path)
    with pytest.raises(CertificateError, match="terminates missing"):
        check_certificate(net, path)


def test_the_gate_lists_only_required_failures() -> None:
    from runtime.gate import approve_mission

    with pytest.raises(CertificateError) as refused:
        approve_mission(FAULTY / "livelock.coral", Path("/nonexistent/cert.json"), issue=True)
    message = str(refused.value)
    assert "no_engine_cycle violated" in message and TERMINATES not in message


# -- the algorithms ---------------------------------------------------------------------------


def test_final_states_compare_packed_keys_but_confirm_them() -> None:
    net = compile_mission(EXAMPLES / "pool_mission" / "pool_mission.coral")
    space = explore(net)
    expected = [net.is_final(space.marking(i)) for i in range(space.states)]
    assert final_states(space).tolist() == expected
    assert sum(expected) == 4
    with pytest.MonkeyPatch.context() as patch:  # blocks of 7 keys: the same answers
        patch.setattr(termination, "DEAD_CHUNK", 7)
        assert final_states(space).tolist() == expected
    stuck = non_final_dead_states(space)
    assert stuck.size == 0


def test_python_and_scipy_searches_agree_on_the_pool_mission() -> None:
    net = compile_mission(EXAMPLES / "pool_mission" / "pool_mission.coral")
    small = [(p.key, p.verdict, p.detail) for p in verify(net, FAST).properties]
    with mock.patch.object(stategraph, "SMALL_GRAPH", 0):
        big = [(p.key, p.verdict, p.detail) for p in verify(net, FAST).properties]
    assert small == big


# -- random mission-like nets against a brute-force reference ----------------------------


@st.composite
def mission_nets(draw: st.DrawFn) -> Net:
    """Small nets shaped like compiled missions: plain transitions, commands with a
    pending place and one or two replies; no finals yet (drawn from the reachable
    markings by the test)."""
    n_places = draw(st.integers(2, 4))
    places = [Place(f"p{i}", draw(st.integers(0, 1)) if i else 1) for i in range(n_places)]
    arcs = st.lists(st.integers(0, n_places - 1), min_size=0, max_size=2, unique=True)
    inputs = st.lists(st.integers(0, n_places - 1), min_size=1, max_size=2, unique=True)
    transitions: list[Transition] = []
    for j in range(draw(st.integers(1, 4))):
        ins = draw(inputs)
        outs = draw(arcs)
        transitions.append(
            Transition(f"t{j}", tuple((f"p{i}", 1) for i in ins), tuple((f"p{i}", 1) for i in outs))
        )
    for c in range(draw(st.integers(0, 2))):
        name = f"c{c}"
        pending = f"{name}.pending"
        places.append(Place(pending, kind=PlaceKind.PENDING, pending_of=name))
        ins = draw(inputs)
        kinds = draw(st.sampled_from([("done",), ("done", "timeout")]))
        transitions.append(
            Transition(
                name,
                tuple((f"p{i}", 1) for i in ins),
                ((pending, 1),),
                kind=TransitionKind.COMMAND,
                command=Command("ROMEO", "Q", (), replies=kinds),
                pending=pending,
            )
        )
        for kind in kinds:
            outs = draw(arcs)
            transitions.append(
                Transition(
                    f"{name}.{kind}",
                    ((pending, 1),),
                    tuple((f"p{i}", 1) for i in outs),
                    kind=TransitionKind.REPLY,
                    label="Q",
                    reply_to=name,
                    reply=kind,
                )
            )
    return Net("random_mission", tuple(places), tuple(transitions), vehicle="ROMEO")


@dataclass
class Truth:
    """What brute force says about a net's reachability graph."""

    engine_cycle_depth: int | None  # shortest prefix to a marking on an engine cycle
    bad_depth: int | None  # shortest trace to a marking that cannot reach a final one
    fair_cycle: bool
    stuck: list[tuple[int, ...]]


def _truth(net: Net, states: list[tuple[int, ...]], depth: dict[tuple[int, ...], int]) -> Truth:
    index = {m: i for i, m in enumerate(states)}
    group = _groups_of(net)
    edges: list[list[tuple[int, str]]] = []
    for m in states:
        out = []
        for t in net.transitions:
            if net.enabled(m, t):
                out.append((index[net.fire(m, t)], t.name))
        edges.append(out)

    def reach(v: int, engine_only: bool = False) -> set[int]:
        seen: set[int] = set()
        todo = deque([v])
        while todo:
            u = todo.popleft()
            for w, name in edges[u]:
                if engine_only and net.transition(name).kind is TransitionKind.REPLY:
                    continue
                if w not in seen:
                    seen.add(w)
                    todo.append(w)
        return seen  # nodes reachable in one step or more

    n = len(states)
    on_engine_cycle = [v for v in range(n) if v in reach(v, engine_only=True)]
    finals = {i for i, m in enumerate(states) if net.is_final(m)}
    bad = [v for v in range(n) if v not in finals and not (reach(v) & finals)]
    after = [reach(v) for v in range(n)]
    fair = False
    for v in range(n):
        if v not in after[v]:
            continue  # not on a cycle
        component = {w for w in after[v] if v in after[w]}
        taken = {name for u in component for w, name in edges[u] if w in component}
        always = None
        for u in component:
            here = {group[name] for _, name in edges[u]} - {""}
            always = here if always is None else always & here
        if not (always or set()) - {group[name] for name in taken}:
            fair = True
    return Truth(
        engine_cycle_depth=min((depth[states[v]] for v in on_engine_cycle), default=None),
        bad_depth=min((depth[states[v]] for v in bad), default=None),
        fair_cycle=fair,
        stuck=[m for i, m in enumerate(states) if not edges[i] and i not in finals],
    )


def _verdicts(report_properties: list[PropertyResult]) -> dict[str, PropertyResult]:
    return {p.key: p for p in report_properties}


@pytest.mark.slow
@given(mission_nets(), st.data())
@settings(max_examples=200, deadline=None)
def test_verdicts_agree_with_brute_force(net: Net, data: st.DataObject) -> None:
    reference = explore_reference(net, max_states=300)
    if reference.complete:
        finals = data.draw(
            st.lists(st.sampled_from(reference.states), max_size=2, unique=True), label="finals"
        )
        net = Net(
            net.name,
            net.places,
            net.transitions,
            tuple(FinalMarking(tuple(net.marking_dict(m).items())) for m in finals),
            vehicle=net.vehicle,
        )
    options = VerifyOptions(max_states=400, time_limit=20, structural=False, max_deadlocks=3)
    results = _verdicts(verify(net, options).properties)
    if not reference.complete:
        for key in (NO_ENGINE_CYCLE, FINAL_ALWAYS_REACHABLE, TERMINATES):
            assert results[key].verdict is not Verdict.PROVEN
        return
    depth = {m: len(reference.trace_to(m)) for m in reference.states}
    truth = _truth(net, reference.states, depth)
    event(f"engine cycle: {truth.engine_cycle_depth is not None}")
    event(f"final not always reachable: {truth.bad_depth is not None}")
    event(f"fair cycle: {truth.fair_cycle}, dead non-final: {bool(truth.stuck)}")

    cycle = results[NO_ENGINE_CYCLE]
    if truth.engine_cycle_depth is None:
        assert cycle.verdict is Verdict.PROVEN
    else:
        assert cycle.verdict is Verdict.VIOLATED and cycle.evidence is not None
        assert len(cycle.evidence.trace) == truth.engine_cycle_depth
        _check_lasso(net, cycle.evidence)
        assert all(s.kind != "reply" for s in cycle.evidence.loop)

    final = results[FINAL_ALWAYS_REACHABLE]
    if truth.bad_depth is None:
        assert final.verdict is Verdict.PROVEN
    else:
        assert final.verdict is Verdict.VIOLATED and final.evidence is not None
        assert len(final.evidence.trace) == truth.bad_depth
        end = _replay(net, final.evidence.trace, net.initial_marking())
        assert net.marking_dict(end) == final.evidence.marking

    terminates = results[TERMINATES]
    assert not terminates.required
    if not truth.fair_cycle and not truth.stuck:
        assert terminates.verdict is Verdict.PROVEN
    else:
        assert terminates.verdict is Verdict.VIOLATED and terminates.evidence is not None
        if truth.fair_cycle:
            _, visited = _check_lasso(net, terminates.evidence)
            assert _fair_on(net, visited, terminates.evidence.loop)
        else:
            assert not terminates.evidence.loop

    deadlock = results["deadlock"]
    if truth.stuck:
        assert deadlock.verdict is Verdict.VIOLATED
        assert 1 + len(deadlock.more_evidence) + deadlock.omitted == len(truth.stuck)
        assert len(deadlock.more_evidence) == min(2, len(truth.stuck) - 1)
    else:
        assert deadlock.verdict is Verdict.PROVEN


@pytest.mark.slow
@given(mission_nets())
@settings(max_examples=60, deadline=None)
def test_fair_components_agree_with_fair_sccs_and_both_search_paths_agree(net: Net) -> None:
    space = explore(net, max_states=300)
    if not space.complete:
        return
    graph = build_graph(space)
    mine = FairComponents(graph)
    comp, fair = fair_sccs(graph.n_states, graph.sources, graph.targets, fairness_groups(graph))
    assert mine.target.tolist() == fair[comp].tolist()
    with mock.patch.object(stategraph, "SMALL_GRAPH", 0):
        scipy_side = FairComponents(graph)
    assert scipy_side.target.tolist() == mine.target.tolist()
    small = [(p.key, p.verdict, p.detail) for p in verify(net, FAST).properties]
    with mock.patch.object(stategraph, "SMALL_GRAPH", 0):
        big = [(p.key, p.verdict, p.detail) for p in verify(net, FAST).properties]
    assert [(k, v) for k, v, _ in small] == [(k, v) for k, v, _ in big]
    n = graph.n_states
    start = np.zeros(n, dtype=np.bool_)
    start[0] = True
    for goal_node in range(n):
        goal = np.zeros(n, dtype=np.bool_)
        goal[goal_node] = True
        one = stategraph.shortest_path(n, graph.sources, graph.targets, start, goal)
        with mock.patch.object(stategraph, "SMALL_GRAPH", 0):
            other = stategraph.shortest_path(n, graph.sources, graph.targets, start, goal)
        assert one is not None and other is not None and len(one) == len(other)
        assert len(one) == space.depth_of(goal_node)


def test_a_mission_with_no_places_is_checked_not_crashed(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """bench/redteam.py: a survey cut after its constants compiles to a net with no
    places, and ``reshape(-1, 0)`` of its final markings raised ValueError."""
    mission = tmp_path / "empty.coral"
    mission.write_text("mission empty\nvehicle MINNOW\n\nconst A = 1.0 m\n", encoding="utf-8")
    profile = Path(__file__).parents[2] / "examples" / "profiles" / "minnow.yaml"
    code = main([str(mission), "--profile", str(profile), "--color", "never"])
    out = capsys.readouterr()
    assert code == 1 and "Traceback" not in out.err
    assert "empty.coral: violated" in out.out  # no final marking is declared: stuck at once


def test_termination_stops_at_the_memory_limit_and_says_so() -> None:
    """The command's budget reaches the graph that termination needs: past its memory
    limit the three properties are inconclusive with the memory reason."""
    from analysis.budget import Budget
    from analysis.termination import TerminationLimits, check_termination

    net = _net(UNFAIR_ONLY)
    results = check_termination(explore(net), TerminationLimits(), None, Budget(memory=1))
    assert {r.key for r in results} == {NO_ENGINE_CYCLE, FINAL_ALWAYS_REACHABLE, TERMINATES}
    for result in results:
        assert result.verdict is Verdict.INCONCLUSIVE, result.key
        assert "memory limit of 1 B reached" in result.detail, result.detail
