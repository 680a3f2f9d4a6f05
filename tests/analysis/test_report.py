"""The text report: every finding located as ``file:line:col: message``, every trace
shown step by step (bounded), witnesses of proven reachability included."""

from __future__ import annotations

import re
from dataclasses import replace

import pytest

from analysis.report import (
    MAX_FINDINGS_SHOWN,
    MAX_TRACE_STEPS,
    Evidence,
    Finding,
    PropertyResult,
    Report,
    StateSpaceFigures,
    Step,
    Verdict,
    element_span,
    located_findings,
)
from analysis.verify import VerifyOptions, verify
from coral_lang import compile_file
from coral_lang.diagnostics import Span
from coral_lang.net import Net
from tests.analysis.nets import make_net
from tests.conftest import EXAMPLES

FAST = VerifyOptions(structural=False)
FAULTY = EXAMPLES / "faulty"


def _compiled(name: str) -> Net:
    net = compile_file(FAULTY / name).net
    assert net is not None
    return net


def _lines_at(text: str, message: str) -> list[str]:
    """The report lines ``file:line:col: message`` (anchored: editors jump to them)."""
    pattern = re.compile(rf"^\S+:\d+:\d+: {re.escape(message)}$", re.MULTILINE)
    return pattern.findall(text)


def test_each_dead_transition_is_located_where_it_is_written() -> None:
    net = _compiled("dead_transition.coral")
    report = verify(net, FAST)
    text = report.render_text(net=net)
    span = net.transition("record_dock").span
    assert span is not None
    assert f"{span}: transition 'record_dock' can never fire" in text.splitlines()
    dead = report.property("dead_transitions")
    located = [f for f in located_findings(dead, net) if f.span is not None]
    assert located and all(f.message.endswith("can never fire") for f in located)
    assert len(_lines_at(text, "transition 'record_dock' can never fire")) == 1
    # Without the net the report is as before: names only, no located lines.
    assert "can never fire" not in "\n".join(
        line for line in report.render_text().splitlines() if re.match(r"^\S+:\d+:\d+:", line)
    )


@pytest.mark.slow
def test_unbounded_places_conflicts_and_deadlocks_are_located() -> None:
    net = _compiled("unbounded.coral")
    text = verify(net, FAST).render_text(net=net)
    place = net.place("lap_logged").span
    assert f"{place}: place 'lap_logged' is unbounded" in text.splitlines()

    net = _compiled("resource_conflict.coral")
    text = verify(net, FAST).render_text(net=net)
    for name in ("go_to_site", "hold_heading"):
        span = net.transition(name).span
        assert any(
            line.startswith(f"{span}: command of transition '{name}' in flight together")
            for line in text.splitlines()
        )

    net = _compiled("deadlock.coral")
    report = verify(net, FAST)
    deadlock = report.property("deadlock")
    found = located_findings(deadlock, net)
    assert len(found) == 1 + len(deadlock.more_evidence)  # one per dead marking listed
    assert all(f.span is not None and f.message.startswith("dead marking {") for f in found)
    last = deadlock.evidence.trace[-1].span if deadlock.evidence else None
    assert found[0].span == last


def test_a_violated_assertion_is_located_at_its_text() -> None:
    where = Span("m.coral", 12, 5, 12, 30)
    prop = PropertyResult(
        "assert:1", "assert never { a, b }", Verdict.VIOLATED, "m", "d", span=where
    )
    assert located_findings(prop, None) == [Finding("violated: assert never { a, b }", where)]
    assert Finding("x", where).render() == "m.coral:12:5: x" and Finding("x").render() == "x"
    proven = PropertyResult("assert:1", "t", Verdict.PROVEN, "m", "d", span=where)
    assert located_findings(proven, None) == []


def _steps(count: int, start: int = 1) -> tuple[Step, ...]:
    return tuple(
        Step(n, f"t{n}", "mission", f"t{n} fires", Span("long.coral", n, 1, n, 3))
        for n in range(start, start + count)
    )


def _report(prop: PropertyResult) -> Report:
    figures = StateSpaceFigures(1, 0, 1, 1, {}, True, None, False, 0.0, 0.0)
    return Report("n", "sha256:0", (), figures, [prop])


def test_long_traces_are_cut_with_the_count_of_the_rest() -> None:
    evidence = Evidence(trace=_steps(70), marking={"stuck": 1})
    prop = PropertyResult("deadlock", "no deadlock", Verdict.VIOLATED, "m", "d", evidence)
    text = _report(prop).render_text()
    numbered = [line for line in text.splitlines() if re.match(r"^\s+\d+\. t\d+ fires", line)]
    assert len(numbered) == MAX_TRACE_STEPS == 50
    assert "(long.coral:50)" in numbered[-1]
    assert "      ... 20 more steps (full trace in --format json)" in text.splitlines()
    assert "reaching { stuck }" in text
    short = _report(prop).render_text(max_steps=80)
    assert "more step" not in short and "(long.coral:70)" in short
    # A lasso: the loop counts against the same bound.
    lasso = Evidence(trace=_steps(45), loop=_steps(10, start=46), marking={"x": 1})
    prop = PropertyResult("terminates", "ends", Verdict.VIOLATED, "m", "d", lasso)
    text = _report(prop).render_text()
    assert "then repeat forever:" in text and "(long.coral:50)" in text
    assert "(long.coral:51)" not in text and "... 5 more steps" in text


def test_the_witness_of_a_proven_reachability_property_is_shown() -> None:
    net = compile_file(EXAMPLES / "pool_mission" / "pool_mission.coral").net
    assert net is not None
    report = verify(net, FAST)
    reach = report.property("final_reachable")
    assert reach.verdict is Verdict.PROVEN and reach.evidence is not None
    text = report.render_text(net=net)
    block = text.split(reach.title, 1)[1].split("\n  PROVEN", 1)[0]
    assert "      witness:" in block
    for step in reach.evidence.trace:
        assert step.render() in block
    assert "in the JSON report" not in block.replace(reach.detail, "")


def test_many_findings_of_one_property_are_capped_in_text() -> None:
    names = tuple(f"t{n}" for n in range(MAX_FINDINGS_SHOWN + 7))
    net = make_net(
        "many",
        {"p": 0, "q": 0},
        {name: ({"p": 1}, {"q": 1}) for name in names},
    )
    net = replace(
        net,
        transitions=tuple(
            replace(t, span=Span("many.coral", i + 1, 1, i + 1, 3))
            for i, t in enumerate(net.transitions)
        ),
    )
    prop = PropertyResult(
        "dead_transitions", "no dead transitions", Verdict.VIOLATED, "m", "d", items=names
    )
    text = _report(prop).render_text(net=net)
    assert len(_lines_at(text, "transition 't0' can never fire")) == 1
    located = [line for line in text.splitlines() if line.startswith("many.coral:")]
    assert len(located) == MAX_FINDINGS_SHOWN
    assert "      ... 7 more located (all in --format json)" in text.splitlines()
    assert len(located_findings(prop, net)) == len(names)  # JSON lists them all


def test_a_property_that_is_not_required_says_so_where_it_is_located() -> None:
    where = Span("m.coral", 3, 1, 3, 9)
    loop = Evidence(loop=(Step(1, "t", "mission", "t fires", where),), marking={})
    prop = PropertyResult(
        "terminates", "every run ends", Verdict.VIOLATED, "m", "d", loop, required=False
    )
    assert located_findings(prop, None) == [
        Finding("violated, not required: every run ends", where)
    ]


def test_element_span_finds_places_and_transitions_by_name() -> None:
    net = compile_file(EXAMPLES / "pool_mission" / "pool_mission.coral").net
    assert net is not None
    place, transition = net.places[0], net.transitions[0]
    assert element_span(net, place.name) == place.span is not None
    assert element_span(net, transition.name) == transition.span is not None
    assert element_span(net, "no such element") is None
    assert element_span(None, place.name) is None
