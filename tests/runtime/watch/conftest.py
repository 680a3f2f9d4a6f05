"""A real run's controller log of the pool mission, made once per session (virtual time,
about two seconds), and the net it carries rebuilt independently of `runtime.watch`."""

from __future__ import annotations

import asyncio
import contextlib
import json
from collections.abc import AsyncIterator, Awaitable, Callable
from pathlib import Path

import pytest

from coral_lang.net import Net, Place, Transition
from runtime.cli import main as coral_run
from runtime.watch.server import WatchServer
from tests.conftest import EXAMPLES

POOL_MISSION = EXAMPLES / "pool_mission" / "pool_mission.coral"

NET = json.dumps(
    {
        "name": "n",
        "places": [["a", 1, "mission", None, [], None, None]],
        "transitions": [{"name": "go", "inputs": [["a", 1]], "outputs": [["b", 2]]}],
    }
)
"""A one-transition net as a log's header carries it, for the servers' tests."""


@contextlib.asynccontextmanager
async def serving(server: WatchServer) -> AsyncIterator[str]:
    """``server`` started (its URL), and stopped on the way out whatever happened."""
    url = await server.start()
    try:
        yield url
    finally:
        await server.stop()


def run(test: Callable[[], Awaitable[None]]) -> None:
    """Run one async test body, bounded: a server test must never hang the suite."""
    asyncio.run(asyncio.wait_for(test(), timeout=10))


@pytest.fixture(scope="session")
def pool_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("watch-pool")
    argv = [str(POOL_MISSION), "--verify", "--certificate", str(folder / "c.json")]
    argv += ["--no-plots", "-q", "--out", str(folder / "run")]
    assert coral_run(argv) == 0
    return folder / "run" / "controller.sqlite"


def net_from_json(net_json: str) -> Net:
    """The places and arcs of a log's ``net_json`` as a `Net` (what `Net.fire` needs)."""
    data = json.loads(net_json)
    places = tuple(Place(entry[0], entry[1]) for entry in data["places"])
    transitions = tuple(
        Transition(
            entry["name"],
            tuple((p, w) for p, w in entry["inputs"]),
            tuple((p, w) for p, w in entry["outputs"]),
        )
        for entry in data["transitions"]
    )
    return Net(data["name"], places, transitions)
