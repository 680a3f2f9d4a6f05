"""`Controller.operate` during a run in virtual time: logging, pause, the abort path."""

from __future__ import annotations

import asyncio
import contextlib
import random
from collections.abc import AsyncIterator, Callable, Coroutine
from pathlib import Path

import pytest

from coral_lang.net import Net
from romeo_sim.config import default_config
from romeo_sim.server import VehicleServer
from romeo_sim.vehicle import Vehicle
from runtime.controller import Controller, ControllerOptions, RunEnd, RunResult
from runtime.engine import Engine
from runtime.eventlog import Event, EventLog, EventLogError
from runtime.link import BUILTIN_PROFILES, LinkEmulator, MemoryLink
from runtime.operator import OperatorAction, OperatorOutcome
from runtime.vclock import run_virtual
from tests.runtime.helpers import compile_text
from tests.runtime.test_operator_engine import SURVEY, hand_approved

PSK = bytes(range(32))

Script = Callable[[Controller], Coroutine[object, object, list[OperatorOutcome]]]


@pytest.fixture(scope="module")
def survey() -> Net:
    return compile_text(SURVEY)


@contextlib.asynccontextmanager
async def _simulated_run(
    net: Net, log_path: Path, rng: random.Random, *, link: str = "lan"
) -> AsyncIterator[tuple[Controller, VehicleServer]]:
    """A controller for ``net`` (hand-approved) on the simulated ROMEO over ``link``, in
    memory, logging to ``log_path``; the log, the link and the vehicle are closed after."""
    loop = asyncio.get_running_loop()
    server = VehicleServer(
        Vehicle(default_config(), seed=1),
        PSK,
        clock=loop.time,
        nonces=random.Random(2).randbytes,
        log=lambda line: None,
    )
    mem = MemoryLink(server, LinkEmulator(BUILTIN_PROFILES[link], seed=4))
    log = EventLog.create(log_path, role="controller", mission=net.name, meta={})
    try:
        yield (
            Controller.start_new(
                Engine(net, hand_approved(net)),
                mem,
                PSK,
                log,
                mission_id=rng.getrandbits(63),
                now=loop.time(),
                nonces=rng.randbytes,
                console=lambda line: None,
                options=ControllerOptions(time_limit=600.0),
            ),
            server,
        )
    finally:
        log.close()
        await mem.aclose()
        await server.stop()


def run_with(
    net: Net, tmp: Path, script: Script, *, link: str = "lan"
) -> tuple[RunResult, list[OperatorOutcome], list[Event]]:
    """Run ``net`` against the simulator in virtual time, ``script`` beside it."""
    rng = random.Random(3)
    log_path = tmp / "controller.sqlite"

    async def main() -> tuple[RunResult, list[OperatorOutcome]]:
        async with _simulated_run(net, log_path, rng, link=link) as (controller, _):
            operator = asyncio.create_task(script(controller))
            result = await controller.run()
            outcomes = await operator
            late = await controller.operate(OperatorAction("pause", "test"))
            assert late == OperatorOutcome(False, "the run has ended")
        return result, outcomes

    result, outcomes = run_virtual(main())
    with EventLog.open(log_path) as log:
        events = list(log.events())
    return result, outcomes, events


def _kinds(events: list[Event], *kinds: str) -> list[Event]:
    return [e for e in events if e.kind in kinds]


def test_an_abort_is_logged_with_its_origin_and_ends_in_a_final_marking(
    survey: Net, tmp_path: Path
) -> None:
    async def script(controller: Controller) -> list[OperatorOutcome]:
        await asyncio.sleep(0.5)  # go_a is on its way
        return [
            await controller.operate(OperatorAction("give", "cli 127.0.0.1:4000", "stop")),
            await controller.operate(OperatorAction("give", "page 10.0.0.7:5123", "abort")),
            await controller.operate(OperatorAction("give", "page 10.0.0.7:5123", "abort")),
        ]

    result, outcomes, events = run_with(survey, tmp_path, script)
    assert [o.accepted for o in outcomes] == [False, True, False]
    assert "its inputs: abort" in outcomes[0].message
    assert "already given" in outcomes[2].message
    assert result.end is RunEnd.FINAL
    assert result.marking == {"aborted": 1}
    logged = _kinds(events, "operator")
    assert [(e.data["origin"], e.data["accepted"], e.data["input"]) for e in logged] == [
        ("cli 127.0.0.1:4000", False, "stop"),
        ("page 10.0.0.7:5123", True, "abort"),
        ("page 10.0.0.7:5123", False, "abort"),
    ]
    assert all(e.data["action"] == "give" and e.data["message"] for e in logged)
    fired = [e.data["transition"] for e in _kinds(events, "fire")]
    assert fired == ["go_a", "abort.operator", "go_a.done", "abort_at_a"]
    assert [e.data["transition"] for e in _kinds(events, "command-sent")] == ["go_a"]
    assert events[-1].kind == "mission-end" and events[-1].data["final"] is True


def test_a_pause_holds_new_commands_while_replies_are_still_consumed(
    survey: Net, tmp_path: Path
) -> None:
    async def script(controller: Controller) -> list[OperatorOutcome]:
        paused = await controller.operate(OperatorAction("pause", "page 1.2.3.4:5"))
        await asyncio.sleep(120.0)  # go_a's reply comes in meanwhile
        return [paused, await controller.operate(OperatorAction("resume", "page 1.2.3.4:5"))]

    result, outcomes, events = run_with(survey, tmp_path, script)
    assert all(o.accepted for o in outcomes)
    assert result.end is RunEnd.FINAL and result.marking == {"done": 1, "abort.armed": 1}
    order = [
        (e.kind, e.data.get("action") or e.data.get("transition") or e.data.get("kind"))
        for e in _kinds(events, "operator", "command-sent", "reply")
    ]
    assert order == [
        ("command-sent", "go_a"),  # committed at the start, before the pause
        ("operator", "pause"),
        ("reply", "go_a.done"),  # consumed while paused
        ("operator", "resume"),
        ("command-sent", "go_b"),  # only after the resume
        ("reply", "go_b.ack"),
    ]
    resume = _kinds(events, "operator")[1]
    reply_a = _kinds(events, "reply")[0]
    assert reply_a.time < resume.time - 60.0  # the reply did not wait for the resume


def test_an_abort_while_paused_resumes_and_ends_the_idle_mission_at_once(
    survey: Net, tmp_path: Path
) -> None:
    async def script(controller: Controller) -> list[OperatorOutcome]:
        await controller.operate(OperatorAction("pause", "cli 127.0.0.1:1"))
        await asyncio.sleep(100.0)  # go_a answered: nothing in flight, go_b held
        return [await controller.operate(OperatorAction("give", "cli 127.0.0.1:1", "abort"))]

    result, outcomes, events = run_with(survey, tmp_path, script)
    assert outcomes[0].accepted and "resumed" in outcomes[0].message
    assert result.end is RunEnd.FINAL and result.marking == {"aborted": 1}
    give = _kinds(events, "operator")[-1]
    # The run was waiting on the vehicle: the abort woke it, it did not wait for a frame.
    assert events[-1].kind == "mission-end" and events[-1].time - give.time < 1e-6


EARLY = """
mission early_abort
vehicle ROMEO
input abort
place start = 1
place idle = 1
place at_a, done, turned, aborted
final { done }
final { aborted }
transition go_a
    wait { start }
    action { ROMEO(DEPTH?, z = 0.0, time_out = 60.0) -> { done: at_a, timeout: at_a } }
transition finish
    wait { at_a, idle }
    signal { done }
transition turn_back priority 1
    wait { idle, abort }
    action { ROMEO(HEADING, psi = 180.0) -> { ack: turned, error: turned } }
transition end_aborted
    wait { at_a, turned }
    signal { aborted }
"""


def test_an_input_given_with_no_connection_sends_its_commands_on_the_next_one(
    tmp_path: Path,
) -> None:
    """The action is taken before the run has connected (as while the link is down): its
    command waits in flight and goes out, once, on the connection that comes next."""
    net = compile_text(EARLY)
    rng = random.Random(5)
    log_path = tmp_path / "controller.sqlite"

    async def main() -> tuple[RunResult, OperatorOutcome, int]:
        async with _simulated_run(net, log_path, rng) as (controller, server):
            outcome = await controller.operate(OperatorAction("give", "cli 127.0.0.1:9", "abort"))
            result = await controller.run()
        return result, outcome, server.stats.commands

    result, outcome, carried_out = run_virtual(main())
    assert outcome.accepted
    assert result.end is RunEnd.FINAL and result.marking == {"aborted": 1}
    with EventLog.open(log_path) as log:
        sent = [e.data["transition"] for e in log.events("command-sent")]
    assert sent == ["go_a", "turn_back"]
    assert result.commands_sent == 2 and carried_out == 2


def test_an_operator_step_the_log_cannot_take_ends_the_run_with_that_error(
    survey: Net, tmp_path: Path
) -> None:
    seen: list[OperatorOutcome] = []

    async def script(controller: Controller) -> list[OperatorOutcome]:
        await asyncio.sleep(0.5)

        def full() -> None:
            raise EventLogError("controller.sqlite: database or disk is full")

        controller._commit = full  # type: ignore[method-assign]
        seen.append(await controller.operate(OperatorAction("give", "cli 127.0.0.1:1", "abort")))
        return seen

    with pytest.raises(EventLogError, match="disk is full"):
        run_with(survey, tmp_path, script)
    assert seen == [
        OperatorOutcome(
            False, "the log cannot be written: " + "controller.sqlite: database or disk is full"
        )
    ]
