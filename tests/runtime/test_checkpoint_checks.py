"""A hand-edited or damaged checkpoint is refused, never resumed from (issue 17, item 5).

The red team resumed from checkpoints with negative token counts, an invented marking,
``{mission_complete: 1}`` after 9 of 23 commands (the run said "final", exit 0), and a
``next_command_id`` set back so that a new command reused an id the vehicle had already
run (and was never carried out). Each must be refused with a clear reason.
"""

from __future__ import annotations

import copy

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from analysis.certificate import CertificateCheck
from coral_lang.compiler import compile_mission
from coral_lang.net import Net
from runtime.engine import Engine, EngineError
from runtime.run import check_verified_state
from tests.runtime.helpers import POOL_MISSION


@pytest.fixture(scope="module")
def pool() -> tuple[Net, CertificateCheck]:
    net = compile_mission(POOL_MISSION)
    return net, CertificateCheck("test (checkpoint checks)", net.digest(), "", "")


def _running(net: Net, approval: CertificateCheck, replies: int) -> dict[str, object]:
    """A checkpoint after ``replies`` expected replies, as the controller commits it."""
    engine = Engine(net, approval)
    step = engine.start(0.0)
    sent = list(step.commands)
    now = 1.0
    for _ in range(replies):
        command = sent.pop(0)
        step = engine.on_reply(command.command_id, command.command.replies[0], now)
        sent += step.commands
        now += 1.0
    return engine.snapshot()


def test_an_honest_checkpoint_restores(pool: tuple[Net, CertificateCheck]) -> None:
    net, approval = pool
    for replies in (0, 3, 9):
        state = _running(net, approval, replies)
        engine = Engine.restore(net, approval, state)
        check_verified_state(net, engine.marking)
        assert engine.snapshot() == state


@pytest.mark.parametrize(
    ("edit", "reason"),
    [
        (lambda s: s["marking"].update({"init_ok": -1}), "negative token count"),
        (lambda s: s.update(firings=-4), "negative firing count"),
        (lambda s: s.update(next_command_id=2), "ids only grow"),
        (lambda s: s["in_flight"][0].__setitem__(1, "begin"), "which sends none"),
        (
            lambda s: s.update(marking={"mission_complete": 1}),
            "are in flight",  # a final marking with commands still in flight
        ),
    ],
    ids=["negative", "firings", "ids-set-back", "not-a-command", "invented-final"],
)
def test_an_edited_checkpoint_is_refused(
    pool: tuple[Net, CertificateCheck], edit: object, reason: str
) -> None:
    net, approval = pool
    state = copy.deepcopy(_running(net, approval, 9))
    assert callable(edit)
    edit(state)
    with pytest.raises(EngineError, match=reason) as exc:
        Engine.restore(net, approval, state)
    assert "do not resume from it" in str(exc.value)


def test_a_consistent_but_unreachable_marking_is_refused(
    pool: tuple[Net, CertificateCheck],
) -> None:
    """Nothing in flight and ``{mission_complete: 1}`` plus a stray token: the engine's
    own checks pass, but no run of the verified net gets there."""
    net, approval = pool
    engine = Engine(net, approval)
    marking = list(net.marking_from({"mission_complete": 1, "init_ok": 1}))
    with pytest.raises(EngineError, match="not a reachable state of the verified net"):
        check_verified_state(net, marking)
    check_verified_state(net, engine.marking)  # the initial marking is fine


@pytest.mark.slow
@settings(max_examples=30, deadline=None)
@given(replies=st.integers(0, 12))
def test_every_checkpoint_the_engine_commits_passes_the_checks(
    pool: tuple[Net, CertificateCheck], replies: int
) -> None:
    net, approval = pool
    engine = Engine.restore(net, approval, _running(net, approval, replies))
    check_verified_state(net, engine.marking)
