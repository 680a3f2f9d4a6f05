"""Companions of a run (`RunConfig.companions`) and the ``--watch``/``--tui`` wiring."""

from __future__ import annotations

import asyncio
import contextlib
import sys
import types
from collections.abc import AsyncIterator, Iterator, Mapping
from pathlib import Path

import pytest

from analysis.signing import TrustStore
from runtime.cli import OPERATE_TOKEN_FILE, live_companion
from runtime.controller import Controller, RunEnd
from runtime.gate import ApprovedMission, approve_mission
from runtime.operator import OperatorAction
from runtime.run import RunConfig, run_mission

MISSION = """
mission two_steps
vehicle ROMEO
place start = 1
place half, done, failed
final { done }
final { failed }
transition dive
    wait { start }
    action { ROMEO(DEPTH?, z = 0.0, time_out = 60.0) -> { done: half, timeout: failed } }
transition turn
    wait { half }
    action { ROMEO(HEADING, psi = 90.0) -> { ack: done, error: failed } }
"""


@pytest.fixture(scope="module")
def mission(tmp_path_factory: pytest.TempPathFactory) -> ApprovedMission:
    path = tmp_path_factory.mktemp("mission") / "two_steps.coral"
    path.write_text(MISSION)
    return approve_mission(path, issue=True, trusted=TrustStore())


def test_companions_are_entered_in_order_around_the_run_and_exited_after(
    mission: ApprovedMission, tmp_path: Path
) -> None:
    seen: list[str] = []

    def companion(name: str):  # type: ignore[no-untyped-def]
        @contextlib.asynccontextmanager
        async def enter(controller: Controller) -> AsyncIterator[None]:
            seen.append(f"enter {name} {controller.engine.started}")
            task = None
            if name == "operator":

                async def act() -> None:
                    await asyncio.sleep(1.0)
                    outcome = await controller.operate(OperatorAction("pause", "test"))
                    seen.append(f"pause {outcome.accepted}")
                    await asyncio.sleep(30.0)
                    outcome = await controller.operate(OperatorAction("resume", "test"))
                    seen.append(f"resume {outcome.accepted}")

                task = asyncio.create_task(act())
            try:
                yield
            finally:
                if task is not None:
                    await task
                seen.append(f"exit {name}")

        return enter

    config = RunConfig(
        out_dir=tmp_path,
        psk=bytes(32),
        console=lambda line: None,
        log_key_ephemeral=True,
        companions=(companion("first"), companion("operator")),
    )
    result = run_mission(mission, config)
    assert result.end is RunEnd.FINAL
    assert seen == [
        "enter first True",
        "enter operator True",
        "pause True",
        "resume True",
        "exit operator",
        "exit first",
    ]
    assert result.mission_time > 30.0  # the pause held the mission


def test_a_companion_that_fails_to_start_ends_the_run_and_exits_the_others(
    mission: ApprovedMission, tmp_path: Path
) -> None:
    exited: list[bool] = []

    @contextlib.asynccontextmanager
    async def good(controller: Controller) -> AsyncIterator[None]:
        try:
            yield
        finally:
            exited.append(True)

    @contextlib.asynccontextmanager
    async def bad(controller: Controller) -> AsyncIterator[None]:
        raise OSError("address in use")
        yield  # pragma: no cover

    config = RunConfig(
        out_dir=tmp_path,
        psk=bytes(32),
        console=lambda line: None,
        log_key_ephemeral=True,
        companions=(good, bad),
    )
    with pytest.raises(OSError, match="address in use"):
        run_mission(mission, config)
    assert exited == [True]


@pytest.fixture
def fake_watch(monkeypatch: pytest.MonkeyPatch) -> Iterator[dict[str, object]]:
    """Fakes of the live feed, server, page info and terminal view: what they were given."""
    seen: dict[str, object] = {"closed": 0, "views": 0}

    class Feed:
        def __init__(self, log: object, net_json: str | None) -> None:
            seen["feed"] = (log, net_json)
            self.mission = "two_steps"
            self.first_time = 0.0

        def snapshot(self) -> types.SimpleNamespace:
            return types.SimpleNamespace(to_json=lambda: {"seq": 1})

        def close(self) -> None:
            seen["closed"] = int(seen["closed"]) + 1  # type: ignore[call-overload]

    @contextlib.asynccontextmanager
    async def serve_live(feed: Feed, **kwargs: object) -> AsyncIterator[str]:
        seen["serve"] = kwargs
        yield "http://127.0.0.1:1/"

    async def run_terminal_view(snapshot: object, *, stop: asyncio.Event, **_: object) -> None:
        seen["views"] = int(seen["views"]) + 1  # type: ignore[call-overload]
        seen["snapshot"] = snapshot() if callable(snapshot) else None
        await stop.wait()
        seen["view stopped"] = True

    fakes: dict[str, dict[str, object]] = {
        "runtime.watch.feed": {"LiveFeed": Feed},
        "runtime.watch.live": {"serve_live": serve_live},
        "runtime.watch.info": {"page_info": lambda net_json, meta: {"mission": "x"}},
        "runtime.tui": {"run_terminal_view": run_terminal_view},
    }
    for name, attrs in fakes.items():
        module = types.ModuleType(name)
        for key, value in attrs.items():
            setattr(module, key, value)
        monkeypatch.setitem(sys.modules, name, module)
    yield seen


def test_watch_and_tui_share_one_feed_and_hand_the_server_the_controllers_operate(
    mission: ApprovedMission, tmp_path: Path, fake_watch: dict[str, object]
) -> None:
    lines: list[str] = []
    companion = live_companion(
        watch=("127.0.0.1", 0),
        tui=True,
        token_file=tmp_path / OPERATE_TOKEN_FILE,
        console=lines.append,
    )
    operates: list[object] = []

    @contextlib.asynccontextmanager
    async def keep(controller: Controller) -> AsyncIterator[None]:
        operates.append(controller.operate)
        yield

    config = RunConfig(
        out_dir=tmp_path,
        psk=bytes(32),
        console=lambda line: None,
        log_key_ephemeral=True,
        companions=(keep, companion),
    )
    assert run_mission(mission, config).end is RunEnd.FINAL
    serve = fake_watch["serve"]
    assert isinstance(serve, Mapping)
    assert serve["host"] == "127.0.0.1" and serve["port"] == 0
    assert serve["operate"] == operates[0]
    assert serve["token_file"] == tmp_path / OPERATE_TOKEN_FILE
    assert serve["info"] == {"mission": "x"}
    feed = fake_watch["feed"]
    assert isinstance(feed, tuple)
    net_json = feed[1]
    assert isinstance(net_json, str) and "two_steps" in net_json
    assert fake_watch["closed"] == 1 and fake_watch["views"] == 1
    assert fake_watch["snapshot"] == {"seq": 1, "start": 0.0}
    assert fake_watch["view stopped"] is True
