"""After a search stops with states stored but not expanded, their bounds are recorded
only within the time limit (plus `RECORD_GRACE`): on a net of 20,000 places that was
17 s past a 4 s limit. What is recorded stays true, and says how much it covers."""

from __future__ import annotations

import numpy as np
import pytest

import analysis.statespace as statespace
from analysis.budget import Budget
from analysis.encoding import CompactNet
from analysis.statespace import explore
from coral_lang.pnml import read_pnml
from tests.conftest import CONFORMANCE


@pytest.fixture(scope="module")
def philosophers() -> CompactNet:
    return CompactNet.from_net(read_pnml(CONFORMANCE / "pnml" / "Philosophers-PT-000010.pnml"))


class _Clock:
    """Stands still until `run` says the search is over, then ticks on every reading."""

    def __init__(self) -> None:
        self.now = 0.0
        self.tick = 0.0

    def __call__(self) -> float:
        self.now += self.tick
        return self.now


def test_pending_bounds_stop_past_the_grace(
    monkeypatch: pytest.MonkeyPatch, philosophers: CompactNet
) -> None:
    monkeypatch.setattr(statespace, "RECORD_CELLS", 64)  # many small blocks to record
    clock = _Clock()
    run = statespace._Explorer.run

    def run_then_time_passes(self: statespace._Explorer) -> None:
        try:
            run(self)
        finally:
            clock.now = 100.0  # the search ends past its 10 s limit
            clock.tick = statespace.RECORD_GRACE / 3

    monkeypatch.setattr(statespace._Explorer, "run", run_then_time_passes)
    space = explore(philosophers, max_states=20_000, budget=Budget(10.0, clock=clock))
    monkeypatch.undo()
    full = explore(philosophers, max_states=20_000)
    assert space.states == full.states == 20_000 and not space.complete
    assert full.recorded == -1  # no deadline: every stored state counted
    assert 0 < space.recorded < space.states  # a few blocks, then the grace was over
    assert np.all(space.place_bounds <= full.place_bounds)
    assert space.max_tokens_marking <= full.max_tokens_marking


def test_a_complete_search_records_every_state(philosophers: CompactNet) -> None:
    space = explore(philosophers, max_states=100_000, budget=Budget(3600.0))
    assert space.complete and space.recorded == -1
