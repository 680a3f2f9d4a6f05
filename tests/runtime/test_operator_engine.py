"""Operator actions in the engine: give an input, pause, resume.

The missions declare their inputs with ``input NAME``, which compiles to the armed place
``NAME.armed`` and the input transition ``NAME.operator``.
"""

from __future__ import annotations

import random

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from analysis.certificate import CertificateCheck
from analysis.statespace import explore
from coral_lang.net import Net
from runtime.engine import Engine, OperatorRefused, Outcome, SentCommand, StepResult
from tests.runtime.helpers import compile_text

SURVEY = """
mission survey_abort
vehicle ROMEO
input abort
place start = 1
place at_a, at_b, done, failed, aborted
final { done }
final { failed }
final { aborted }
transition go_a
    wait { start }
    action { ROMEO(DEPTH?, z = 0.0, time_out = 60.0) -> { done: at_a, timeout: failed } }
transition go_b
    wait { at_a }
    action { ROMEO(HEADING, psi = 90.0) -> { ack: at_b, error: failed } }
transition finish
    wait { at_b }
    signal { done }
transition abort_at_a priority 1
    wait { at_a, abort }
    signal { aborted }
transition abort_at_b priority 1
    wait { at_b, abort }
    signal { aborted }
transition abort_failed
    wait { failed, abort }
    signal { failed }
"""


def hand_approved(net: Net) -> CertificateCheck:
    """An approval of ``net`` made by hand: these tests exercise the engine, not the gate."""
    return CertificateCheck("hand-made", net.digest(), "", "")


@pytest.fixture(scope="module")
def survey() -> Net:
    return compile_text(SURVEY)


def engine_of(net: Net) -> tuple[Engine, list[SentCommand]]:
    engine = Engine(net, hand_approved(net))
    return engine, list(engine.start(0.0).commands)


def test_the_engine_never_fires_an_input_by_itself(survey: Net) -> None:
    engine, pending = engine_of(survey)
    while pending:
        sent = pending.pop(0)
        pending.extend(engine.on_reply(sent.command_id, sent.command.replies[0], 1.0).commands)
    assert engine.outcome() is Outcome.FINAL
    assert engine.marking_dict() == {"done": 1, "abort.armed": 1}


def test_giving_an_input_runs_the_missions_abort_path(survey: Net) -> None:
    engine, pending = engine_of(survey)
    step = engine.give("abort", 1.0)
    assert [f.transition for f in step.firings] == ["abort.operator"]
    assert step.outcome is Outcome.RUNNING  # go_a is still in flight
    step = engine.on_reply(pending[0].command_id, "done", 2.0)
    assert [f.transition for f in step.firings] == ["go_a.done", "abort_at_a"]
    assert step.commands == () and step.outcome is Outcome.FINAL
    assert engine.marking_dict() == {"aborted": 1}


def test_inputs_unknown_given_twice_or_after_the_end_are_refused(survey: Net) -> None:
    engine, pending = engine_of(survey)
    with pytest.raises(OperatorRefused, match=r"no input 'stop' \(its inputs: abort\)"):
        engine.give("stop", 1.0)
    engine.give("abort", 1.0)
    before = engine.snapshot()
    with pytest.raises(OperatorRefused, match="already given"):
        engine.give("abort", 1.5)
    assert engine.snapshot() == before
    engine.on_reply(pending[0].command_id, "done", 2.0)
    assert engine.outcome() is Outcome.FINAL
    with pytest.raises(OperatorRefused, match=r"the run has ended \(final\)"):
        engine.give("abort", 3.0)
    with pytest.raises(OperatorRefused, match="has ended"):
        engine.pause()


def test_an_input_after_the_mission_completed_is_refused_although_armed(survey: Net) -> None:
    engine, pending = engine_of(survey)
    while pending:
        sent = pending.pop(0)
        pending.extend(engine.on_reply(sent.command_id, sent.command.replies[0], 1.0).commands)
    with pytest.raises(OperatorRefused, match="has ended"):
        engine.give("abort", 2.0)
    assert engine.marking_dict() == {"done": 1, "abort.armed": 1}


def test_a_net_without_inputs_says_so() -> None:
    net = compile_text(SURVEY.replace("input abort", "place abort"))
    engine, _ = engine_of(net)
    with pytest.raises(OperatorRefused, match="declares no inputs"):
        engine.give("abort", 1.0)


def test_paused_replies_fire_their_reply_transition_and_nothing_else(survey: Net) -> None:
    engine, pending = engine_of(survey)
    engine.pause()
    with pytest.raises(OperatorRefused, match="already paused"):
        engine.pause()
    step = engine.on_reply(pending[0].command_id, "done", 1.0)
    assert [f.transition for f in step.firings] == ["go_a.done"]
    assert step.commands == () and step.outcome is Outcome.RUNNING  # go_b is held
    assert engine.in_flight() == []
    step = engine.resume(2.0)
    assert [f.transition for f in step.firings] == ["go_b"]
    assert [c.transition for c in step.commands] == ["go_b"]
    with pytest.raises(OperatorRefused, match="not paused"):
        engine.resume(3.0)


def test_resume_after_a_reply_ended_the_paused_run_is_refused(survey: Net) -> None:
    engine, pending = engine_of(survey)
    engine.pause()
    step = engine.on_reply(pending[0].command_id, "timeout", 1.0)  # -> failed: final
    assert step.outcome is Outcome.FINAL
    with pytest.raises(OperatorRefused, match=r"resume refused: the run has ended \(final\)"):
        engine.resume(2.0)


def test_giving_an_input_while_paused_resumes_the_engine(survey: Net) -> None:
    engine, pending = engine_of(survey)
    engine.pause()
    engine.on_reply(pending[0].command_id, "done", 1.0)
    step = engine.give("abort", 2.0)
    assert not engine.paused
    assert [f.transition for f in step.firings] == ["abort.operator", "abort_at_a"]
    assert step.outcome is Outcome.FINAL


def test_a_restored_engine_stays_paused_and_keeps_the_given_input(survey: Net) -> None:
    engine, _ = engine_of(survey)
    assert "paused" not in engine.snapshot()  # states of runs never paused are unchanged
    engine.give("abort", 1.0)
    engine.pause()
    restored = Engine.restore(survey, hand_approved(survey), engine.snapshot())
    assert restored.paused  # a held mission is not released by a restart
    assert restored.marking_dict() == engine.marking_dict()
    with pytest.raises(OperatorRefused, match="already given"):
        restored.give("abort", 2.0)


# ---------------------------------------------------------------------- property


def _chain_mission(steps: int, absorb_failure: bool, abort_at: frozenset[int]) -> Net:
    """A chain of ``steps`` commands with an abort input; the abort is handled at the
    stations in ``abort_at`` only (the others let it deadlock or end as the net says),
    and after a failure only if ``absorb_failure``."""
    lines = [
        "mission chain",
        "vehicle ROMEO",
        "input abort",
        "place s0 = 1",
        "place failed, aborted",
        *(f"place s{i}" for i in range(1, steps + 1)),
        f"final {{ s{steps} }}",
        "final { failed }",
        "final { aborted }",
    ]
    for i in range(steps):
        lines += [
            f"transition go{i}",
            f"    wait {{ s{i} }}",
            f"    action {{ ROMEO(DEPTH, z = {i + 1}.0) -> {{ ack: s{i + 1}, error: failed }} }}",
        ]
    for i in sorted(abort_at):
        lines += [
            f"transition stop{i} priority 1",
            f"    wait {{ s{i}, abort }}",
            "    signal { aborted }",
        ]
    if absorb_failure:
        lines += ["transition absorb", "    wait { failed, abort }", "    signal { failed }"]
    return compile_text("\n".join(lines) + "\n")


_SPACES: dict[Net, set[tuple[int, ...]]] = {}


def _reachable(net: Net) -> set[tuple[int, ...]]:
    if net not in _SPACES:
        _SPACES[net] = {tuple(row) for row in explore(net).markings.tolist()}
    return _SPACES[net]


def _check_against_analysis(engine: Engine, net: Net, step: StepResult) -> None:
    marking = tuple(engine.marking)
    assert marking in _reachable(net), net.marking_dict(marking)
    assert step.outcome is engine.outcome()
    if step.outcome is Outcome.RUNNING:
        assert net.runs_on(marking)
    else:
        assert not net.runs_on(marking)
        assert (step.outcome is Outcome.FINAL) == net.is_final(marking)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    steps=st.integers(1, 3),
    absorb=st.booleans(),
    abort_at=st.frozensets(st.integers(0, 3)),
    seed=st.integers(0, 2**32 - 1),
)
def test_random_replies_and_operator_actions_stay_inside_the_verified_state_space(
    steps: int, absorb: bool, abort_at: frozenset[int], seed: int
) -> None:
    net = _chain_mission(steps, absorb, frozenset(i for i in abort_at if i <= steps))
    rng = random.Random(seed)
    engine = Engine(net, hand_approved(net))
    step = engine.start(0.0)
    _check_against_analysis(engine, net, step)
    pending = list(step.commands)
    t = 0.0
    for _ in range(40):
        t += rng.random()
        move = rng.random()
        try:
            if move < 0.15:
                step = engine.give("abort", t)
            elif move < 0.3:
                engine.pause()
                step = StepResult((), (), engine.outcome())
            elif move < 0.45:
                step = engine.resume(t)
            elif pending:
                sent = pending.pop(rng.randrange(len(pending)))
                step = engine.on_reply(sent.command_id, rng.choice(sent.command.replies), t)
            else:
                continue
        except OperatorRefused:
            continue
        pending.extend(step.commands)
        assert all(c.transition for c in step.commands) and not (engine.paused and step.commands)
        _check_against_analysis(engine, net, step)
        if step.outcome is not Outcome.RUNNING:
            break
