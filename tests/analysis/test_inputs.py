"""Operator inputs in analysis: terminal markings, no input edges out of them, no
fairness for the operator, no partial-order reduction, legal traces; checked against a
tiny reference explorer that applies the run rule literally."""

from __future__ import annotations

import subprocess
import sys
from collections import deque
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from analysis.ctl import NetIndex, StateEvaluator
from analysis.fairness import group_of_transition
from analysis.inputs import has_inputs, legal_trace, terminal_rows
from analysis.lint import lint
from analysis.netdraw import OPERATOR_FILL, draw_net
from analysis.report import Verdict
from analysis.stateeq import (
    BadMarkings,
    Proven,
    _equation,
    check_unreachable,
    deadlocks,
    unexpected_deadlocks,
)
from analysis.stategraph import build_graph
from analysis.statespace import explore
from analysis.termination import (
    FinalPatterns,
    final_rows,
    final_states,
    non_final_dead_states,
)
from analysis.verify import VerifyOptions, verify
from coral_lang.compiler import compile_file, compile_mission, compile_source
from coral_lang.net import (
    MAX_INPUTS,
    FinalMarking,
    Net,
    Place,
    PlaceKind,
    Transition,
    TransitionKind,
)
from tests.conftest import EXAMPLES

Marking = tuple[int, ...]
ABORT = EXAMPLES / "operator" / "abort.coral"
FAULTY = EXAMPLES / "faulty" / "unhandled_abort.coral"

HEADER = "mission m\nvehicle ROMEO\ninput stop\n"


def _net(body: str) -> Net:
    result = compile_source(HEADER + body, "m.coral")
    assert result.errors == [], [d.render() for d in result.errors]
    assert result.net is not None
    return result.net


# -- the reference: the run rule, literally ------------------------------------------------


@dataclass
class Reference:
    states: set[Marking]
    edges: set[tuple[Marking, int, Marking]]
    terminal: set[Marking]
    complete: bool


def reference(net: Net, max_states: int = 400) -> Reference:
    """Breadth-first search in which an input fires only where some non-input
    transition is enabled (the run is on)."""
    start = net.initial_marking()
    seen = {start}
    edges: set[tuple[Marking, int, Marking]] = set()
    terminal: set[Marking] = set()
    queue = deque([start])
    complete = True
    while queue:
        marking = queue.popleft()
        enabled = [(i, t) for i, t in enumerate(net.transitions) if net.enabled(marking, t)]
        on = any(t.kind is not TransitionKind.INPUT for _, t in enabled)
        if not on:
            terminal.add(marking)
            continue
        for i, t in enabled:
            after = net.fire(marking, t)
            edges.add((marking, i, after))
            if after not in seen:
                if len(seen) >= max_states:
                    complete = False
                    continue
                seen.add(after)
                queue.append(after)
    return Reference(seen, edges, terminal, complete)


def _replays_legally(net: Net, trace: list[int]) -> Marking:
    marking = net.initial_marking()
    for index in trace:
        t = net.transitions[index]
        assert net.enabled(marking, t)
        if t.kind is TransitionKind.INPUT:
            assert net.runs_on(marking), f"input {t.name} fired after the run stopped"
        marking = net.fire(marking, t)
    return marking


@st.composite
def nets_with_inputs(draw: st.DrawFn, max_inputs: int = 2) -> Net:
    """A small random net with 0 to ``max_inputs`` operator inputs that some
    transitions wait on (and none marks), and up to two final markings."""
    n_places = draw(st.integers(1, 4))
    n_inputs = draw(st.integers(0, max_inputs))
    names = [f"p{i}" for i in range(n_places)]
    inputs = [f"in{k}" for k in range(n_inputs)]
    places = [Place(p, draw(st.integers(0, 2))) for p in names]
    places += [Place(x) for x in inputs]
    places += [Place(f"{x}.armed", 1, PlaceKind.ARMED, armed_of=x) for x in inputs]
    readable = st.sampled_from([*names, *inputs])
    transitions = []
    for j in range(draw(st.integers(1, 5))):
        pre = draw(st.dictionaries(readable, st.integers(1, 2), max_size=2))
        post = draw(st.dictionaries(st.sampled_from(names), st.integers(1, 2), max_size=2))
        transitions.append(
            Transition(
                f"t{j}",
                tuple(sorted(pre.items())),
                tuple(sorted(post.items())),
                draw(st.sampled_from([TransitionKind.PLAIN, TransitionKind.REPLY])),
            )
        )
    for x in inputs:
        transitions.append(
            Transition(
                f"{x}.operator",
                ((f"{x}.armed", 1),),
                ((x, 1),),
                TransitionKind.INPUT,
                operator_input=x,
            )
        )
    finals = [
        FinalMarking(
            tuple(
                sorted(
                    draw(
                        st.dictionaries(
                            st.sampled_from(names), st.integers(1, 2), min_size=1, max_size=2
                        )
                    ).items()
                )
            )
        )
        for _ in range(draw(st.integers(0, 2)))
    ]
    return Net("random", tuple(places), tuple(transitions), tuple(finals))


@pytest.mark.slow
@given(nets_with_inputs())
@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
def test_reachable_markings_and_deadlocks_match_the_literal_run_rule(net: Net) -> None:
    ref = reference(net)
    assume(ref.complete)
    space = explore(net, max_states=10_000)
    assert space.complete
    found = {space.marking(i) for i in range(space.states)}
    assert found == ref.states
    stuck = {space.marking(int(i)) for i in non_final_dead_states(space)}
    assert stuck == {m for m in ref.terminal if not net.is_final(m)}
    graph = build_graph(space)
    edges = {
        (space.marking(s), int(t), space.marking(int(d)))
        for s, t, d in zip(
            graph.sources.tolist(), graph.labels.tolist(), graph.targets.tolist(), strict=True
        )
    }
    assert edges == ref.edges
    assert space.edges == len(ref.edges)
    assert {space.marking(int(i)) for i in np.flatnonzero(graph.dead)} == ref.terminal
    for state in non_final_dead_states(space).tolist()[:5]:
        assert _replays_legally(net, space.trace_to(state)) == space.marking(state)


@pytest.mark.slow
@given(nets_with_inputs(), st.data())
@settings(max_examples=100, deadline=None)
def test_legal_trace_reaches_the_same_marking_with_every_input_in_time(
    net: Net, data: st.DataObject
) -> None:
    """Any P/T firing sequence is reordered into one the runtime can produce."""
    marking = net.initial_marking()
    trace: list[int] = []
    for _ in range(data.draw(st.integers(0, 8))):
        enabled = [i for i, t in enumerate(net.transitions) if net.enabled(marking, t)]
        if not enabled:
            break
        index = data.draw(st.sampled_from(enabled))
        trace.append(index)
        marking = net.fire(marking, net.transitions[index])
    legal = legal_trace(net, trace)
    if legal is None:
        assert not net.runs_on(net.initial_marking())
        return
    assert sorted(legal) == sorted(trace)
    assert _replays_legally(net, legal) == marking


# -- the semantics on small missions ---------------------------------------------------------

LATE = (
    "place start = 1, done, aborted\n"
    "final { done }\nfinal { aborted }\n"
    "transition go wait { start } action { ROMEO(SURFACE) -> { ack: done, error: aborted } }\n"
    "transition stop_now wait { start, stop } signal { aborted }\n"
)


def test_a_terminal_marking_with_an_input_enabled_is_a_deadlock() -> None:
    """(a) 'finish' waits for the operator: if the operator has not acted when the
    reply arrives, only the input is enabled in '{ waiting }', so the run stops there,
    and that marking is not final."""
    net = _net(
        "place start = 1, waiting, done\nfinal { done }\n"
        "transition go wait { start } action { ROMEO(SURFACE) -> { ack: waiting, error: waiting } }\n"
        "transition finish wait { waiting, stop } signal { done }\n"
    )
    space = explore(net)
    stuck = [space.marking(int(i)) for i in non_final_dead_states(space)]
    waiting = net.marking_from({"waiting": 1, "stop.armed": 1})
    # the input is enabled there, yet the run has stopped: a deadlock
    assert waiting in stuck
    assert net.enabled(waiting, net.input_transition("stop"))
    report = verify(net, VerifyOptions(structural=False))
    assert report.property("deadlock").verdict is Verdict.VIOLATED


def test_a_final_marking_with_an_input_still_armed_is_final_and_has_no_input_edge() -> None:
    """(b)"""
    net = _net(
        LATE + "transition late wait { done, stop } signal { done }\n"
        "transition late2 wait { aborted, stop } signal { aborted }\n"
    )
    space = explore(net)
    assert not non_final_dead_states(space).size
    done = net.marking_from({"done": 1, "stop.armed": 1})
    assert net.is_final(done)
    graph = build_graph(space)
    node = next(i for i in range(space.states) if space.marking(i) == done)
    assert graph.dead[node]
    assert graph.indptr[node] == graph.indptr[node + 1]
    report = verify(net, VerifyOptions(structural=False))
    assert report.verdict is Verdict.PROVEN
    assert report.property("terminates").verdict is Verdict.PROVEN


def test_without_the_late_abort_the_stray_input_token_is_a_deadlock() -> None:
    net = _net(LATE)
    space = explore(net)
    stuck = {space.marking(int(i)) for i in non_final_dead_states(space)}
    assert stuck == {
        net.marking_from({"done": 1, "stop": 1}),
        net.marking_from({"aborted": 1, "stop": 1}),
    }
    trace = space.trace_to(int(non_final_dead_states(space)[0]))
    names = [net.transitions[t].name for t in trace]
    assert "stop.operator" in names


def test_the_operator_may_never_act_so_eventually_the_input_fails() -> None:
    """(c) Under the runtime's fairness the operator has no obligation."""
    text = ABORT.read_text() + (
        "assert eventually final\nassert eventually abort_requested\n"
        "assert always abort_requested <= 1\n"
    )
    result = compile_source(text, str(ABORT), base_dir=ABORT.parent)
    assert result.errors == [], [d.render() for d in result.errors]
    assert result.net is not None
    report = verify(result.net, VerifyOptions(structural=False))
    verdicts = {p.title: p.verdict for p in report.properties}
    assert verdicts["assert eventually final"] is Verdict.PROVEN
    assert verdicts["assert eventually abort_requested"] is Verdict.VIOLATED
    assert verdicts["assert always abort_requested <= 1"] is Verdict.PROVEN


def test_inputs_have_no_fairness_group_and_are_not_engine_transitions() -> None:
    net = compile_mission(ABORT)
    groups = group_of_transition(net)
    for i, t in enumerate(net.transitions):
        if t.kind is TransitionKind.INPUT:
            assert groups[i] == -1
        elif t.kind is not TransitionKind.REPLY:
            assert groups[i] >= 0


def test_partial_order_reduction_is_off_for_nets_with_inputs() -> None:
    net = compile_mission(ABORT)
    assert has_inputs(net)
    reduced = explore(net, por=True)
    full = explore(net)
    assert not reduced.reduced
    assert reduced.states == full.states
    assert np.array_equal(reduced.deadlocks, full.deadlocks)


def test_an_initially_terminal_run_never_starts() -> None:
    """Only an input is enabled at the start: the run stops at once, so the input
    never fires and nothing after it is reachable."""
    net = _net(
        "place idle, done\nfinal { done }\n"
        "transition go wait { stop } action { ROMEO(SURFACE) -> { ack: done, error: done } }\n"
    )
    space = explore(net)
    assert space.complete and space.states == 1 and space.edges == 0
    assert non_final_dead_states(space).tolist() == [0]
    assert not space.fired_transitions.any()
    graph = build_graph(space)
    assert graph.n_edges == 0 and bool(graph.dead[0])
    report = verify(net, VerifyOptions(structural=False))
    assert report.property("deadlock").verdict is Verdict.VIOLATED


def test_state_equation_dead_markings_ignore_inputs() -> None:
    """z3 looks for markings where no non-input transition is enabled."""
    net = _net(LATE)
    assert not isinstance(check_unreachable(net, unexpected_deadlocks(net)), Proven)
    handled = _net(
        LATE + "transition late wait { done, stop } signal { done }\n"
        "transition late2 wait { aborted, stop } signal { aborted }\n"
    )
    assert isinstance(check_unreachable(handled, unexpected_deadlocks(handled)), Proven)


def test_ctl_dead_and_fireable_follow_the_run_rule() -> None:
    net = _net(LATE)
    index = NetIndex(net)
    block = np.array(
        [net.marking_from({"done": 1, "stop.armed": 1}), net.initial_marking()], dtype=np.int64
    )
    evaluator = StateEvaluator(index, block)
    assert evaluator.dead.tolist() == [True, False]
    operator = net.transition_index("stop.operator")
    assert evaluator.enabled(operator).tolist() == [False, True]
    assert terminal_rows(net, block).tolist() == [True, False]


# -- the examples ---------------------------------------------------------------------------


def test_the_operator_abort_example_verifies() -> None:
    """(e)"""
    net = compile_mission(ABORT)
    assert net.inputs == ("abort_requested",)
    report = verify(net, VerifyOptions(structural=False))
    assert report.verdict is Verdict.PROVEN and report.exit_code() == 0
    assert all(p.verdict is Verdict.PROVEN for p in report.properties)


def test_the_unhandled_abort_deadlocks_with_the_operator_in_the_trace() -> None:
    """(e)"""
    net = compile_mission(FAULTY)
    report = verify(net, VerifyOptions(structural=False))
    deadlock = report.property("deadlock")
    assert deadlock.verdict is Verdict.VIOLATED
    evidence = [deadlock.evidence, *deadlock.more_evidence]
    markings = [e.marking for e in evidence if e is not None]
    assert {"surfaced": 1, "abort_requested": 1} in markings
    steps = [s for e in evidence if e is not None for s in e.trace]
    operator = [s for s in steps if s.description == "the operator gives input abort_requested"]
    assert operator
    assert all(
        s.span is not None and s.span.file.endswith("unhandled_abort.coral") for s in operator
    )
    assert report.exit_code() == 1


def test_the_abort_example_lints_clean_and_an_unused_input_is_a_warning() -> None:
    assert lint(compile_file(ABORT)) == []
    unused = compile_source(HEADER + LATE.replace("start, stop", "start"), "m.coral")
    assert "CORAL209" in [d.code for d in lint(unused)]
    used = compile_source(HEADER + LATE, "m.coral")
    assert "CORAL209" not in [d.code for d in lint(used)]


def test_the_builtin_drawing_fills_inputs_and_armed_places() -> None:
    net = compile_mission(FAULTY)
    svg = draw_net(net, "builtin").svg
    assert svg.count(f'fill="{OPERATOR_FILL}"') == 2


# -- final markings without the 2**k expansion ---------------------------------------------


@pytest.mark.slow
@given(nets_with_inputs(max_inputs=3))
@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])
def test_projected_finals_pick_the_same_reachable_markings_as_the_expanded_ones(
    net: Net,
) -> None:
    """Every consumer's final test agrees with membership in `Net.final_markings` (the
    old, expanded definition) on all reachable markings."""
    space = explore(net, max_states=300)
    states = [space.marking(i) for i in range(space.states)]
    expanded = set(net.final_markings())
    old = [m in expanded for m in states]
    assert [net.is_final(m) for m in states] == old
    assert final_states(space).tolist() == old
    block = np.array(states, dtype=np.int64).reshape(len(states), len(net.places))
    assert final_rows(block, FinalPatterns.of(net)).tolist() == old
    dead = {space.marking(int(i)) for i in space.deadlocks}
    stuck = {space.marking(int(i)) for i in non_final_dead_states(space)}
    assert stuck == {m for m in dead if m not in expanded}
    new_bad, old_bad = unexpected_deadlocks(net), deadlocks(expanded)
    assert [new_bad.matches(net, m) for m in states] == [old_bad.matches(net, m) for m in states]


def _z3_admits(net: Net, bad: BadMarkings, marking: Marking) -> bool:
    """Whether the state-equation encoding of ``bad`` admits ``marking`` (a reachable
    marking always solves the equation itself, so this is the bad-set encoding)."""
    import z3

    solver, variables, _ = _equation(net, bad, None)
    solver.set("timeout", 5_000)
    solver.add(*[v == k for v, k in zip(variables, marking, strict=True)])
    return bool(solver.check() == z3.sat)


@pytest.mark.slow
@given(nets_with_inputs(max_inputs=3))
@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
def test_the_z3_encoding_of_projected_finals_excludes_the_same_markings(net: Net) -> None:
    space = explore(net, max_states=60)
    bad = unexpected_deadlocks(net)
    old = deadlocks(net.final_markings())
    for i in range(min(space.states, 12)):
        marking = space.marking(i)
        assert _z3_admits(net, bad, marking) == old.matches(net, marking), marking
        assert bad.matches(net, marking) == old.matches(net, marking)


def _many_inputs_mission(n_finals: int) -> str:
    """A mission with `MAX_INPUTS` inputs, each eaten from any end place (26,756
    reachable markings, 512 dead ones), and ``n_finals`` finals."""
    names = [f"i{k}" for k in range(MAX_INPUTS)]
    lines = [
        "mission many",
        "vehicle ROMEO",
        f"input {', '.join(names)}",
        "place start = 1",
        "place ready, done_, failed",
        *[f"place p{k}" for k in range(n_finals)],
        "final { done_ }",
        "final { failed }",
        *[f"final {{ p{k} }}" for k in range(n_finals - 2)],
        "transition initialise wait { start }",
        "    action { ROMEO(INIT) -> { done: ready, error: failed } }",
        "transition fin wait { ready }",
        "    action { ROMEO(SURFACE) -> { ack: done_, error: failed } }",
    ]
    for x in names:
        for end, place in (("r", "ready"), ("d", "done_"), ("f", "failed")):
            lines.append(f"transition eat_{x}_{end} wait {{ {place}, {x} }} signal {{ {place} }}")
    return "\n".join(lines) + "\n"


def test_eight_inputs_compare_one_row_per_declared_final() -> None:
    """The memory regression, without timing: the arrays compared are as many rows as
    declared finals, not 2**8 times that."""
    net = compile_source(_many_inputs_mission(6), "many.coral").raise_for_errors()
    assert len(net.inputs) == MAX_INPUTS and len(net.finals) == 6
    finals = FinalPatterns.of(net)
    assert finals.patterns.shape == (6, len(net.places) - MAX_INPUTS)
    assert finals.armed.size == MAX_INPUTS
    assert len(unexpected_deadlocks(net).exclude) == 6
    space = explore(net)
    assert space.states == 26_756
    assert final_states(space).sum() == len(space.deadlocks) == 2 * 2**MAX_INPUTS
    assert not non_final_dead_states(space).size


_RSS_SCRIPT = """
import contextlib, io, sys
from analysis.cli import main
with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
    code = main(["verify", sys.argv[1]])
with open("/proc/self/status") as status:
    peak = next(line.split()[1] for line in status if line.startswith("VmHWM:"))
print(code, peak)
"""


@pytest.mark.slow
def test_verify_on_an_eight_input_mission_stays_small(tmp_path: Path) -> None:
    """`coral-check verify` on 8 inputs and 6 finals peaked at about 2.1 GB when finals
    were expanded (about 130 MB now, mostly imports). The child reports the peak of
    its own address space (VmHWM: ``ru_maxrss`` survives fork and exec, so it would
    carry the pytest worker's peak), so other processes cannot disturb the figure."""
    if not Path("/proc/self/status").exists():
        pytest.skip("needs /proc (Linux) to read the child's own peak RSS")
    mission = tmp_path / "many.coral"
    mission.write_text(_many_inputs_mission(6))
    done = subprocess.run(
        [sys.executable, "-c", _RSS_SCRIPT, str(mission)],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=Path(__file__).resolve().parents[2],
        check=False,
    )
    assert done.returncode == 0, done.stderr
    code, peak_kb = (int(x) for x in done.stdout.split())
    assert code in (0, 1)  # verdicts, not a crash (unused places are a violation)
    assert peak_kb < 400 * 1024, f"peak RSS {peak_kb // 1024} MB"


def test_an_armed_place_holding_two_tokens_is_not_left_free_by_a_final() -> None:
    """A final leaves an armed place free only as 0 or 1 (as the expansion did): a
    hand-built net that puts a second token there ends in a deadlock, everywhere."""
    net = Net(
        "twice",
        (
            Place("go", 1),
            Place("done"),
            Place("x"),
            Place("x.armed", 1, PlaceKind.ARMED, armed_of="x"),
        ),
        (
            Transition("t", (("go", 1),), (("done", 1), ("x.armed", 1))),
            Transition("x.operator", (("x.armed", 1),), (("x", 1),), TransitionKind.INPUT),
        ),
        (FinalMarking((("done", 1),)),),
    )
    end = net.marking_from({"done": 1, "x.armed": 2})
    assert not net.is_final(end) and end not in net.final_markings()
    space = explore(net)
    states = [space.marking(i) for i in range(space.states)]
    assert end in states
    assert not final_states(space)[states.index(end)]
    assert not final_rows(np.array([end], dtype=np.int64), FinalPatterns.of(net))[0]
    assert end in {space.marking(int(i)) for i in non_final_dead_states(space)}
    bad = unexpected_deadlocks(net)
    assert bad.matches(net, end) and _z3_admits(net, bad, end)
