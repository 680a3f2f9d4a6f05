"""One fuzz run: the same seed gives the same run, and the options are plain data."""

from __future__ import annotations

import pickle
from collections import Counter
from pathlib import Path

import pytest

from runtime.faultplan import parse_fault_rules
from runtime.fuzz import (
    FuzzOptions,
    events_digest,
    run_one,
    run_seed,
)
from runtime.link import BUILTIN_PROFILES
from tests.runtime.test_properties import mission
from tests.runtime.test_racy import HOSTILE_RACE_SEED


@pytest.mark.slow
@pytest.mark.parametrize("name", ["racy", "pool"])
def test_the_same_seed_gives_the_same_outcome_and_the_same_events(name: str) -> None:
    m = mission(name)
    options = FuzzOptions(runs=1, seed=7, link=BUILTIN_PROFILES["hostile"])
    first = run_one(m.net, m.approval, 7, options, keep_events=True)
    second = run_one(m.net, m.approval, 7, options, keep_events=True)
    assert (first.end, first.marking, first.duration) == (
        second.end,
        second.marking,
        second.duration,
    )
    assert [(e.time, e.kind, e.data) for e in first.events] == [
        (e.time, e.kind, e.data) for e in second.events
    ]
    assert first.events_digest == second.events_digest
    other = run_one(m.net, m.approval, 8, options)
    assert other.events_digest != first.events_digest  # the seed does matter


def test_run_seeds_follow_the_base_seed() -> None:
    assert [run_seed(40, i) for i in range(3)] == [40, 41, 42]
    assert run_seed(2**63 - 1, 1) == 0


@pytest.mark.slow
def test_a_run_counts_the_transitions_its_events_fired() -> None:
    pool = mission("pool")
    options = FuzzOptions(runs=1, seed=4, link=BUILTIN_PROFILES["lan"])
    run = run_one(pool.net, pool.approval, 4, options, keep_events=True)
    fires = Counter(e.data["transition"] for e in run.events if e.kind == "fire")
    assert dict(run.fired) == dict(fires) and fires
    assert run.events_digest == events_digest(run.events)
    lean = run_one(pool.net, pool.approval, 4, options)
    assert lean.events == () and lean.fired == run.fired
    assert lean.events_digest == run.events_digest
    assert lean.to_json()["transitions_fired"] == len(run.fired)


def test_the_options_are_plain_data_that_pickle(tmp_path: Path) -> None:
    """Nothing callable in `FuzzOptions`: a worker process given the pickled options
    builds the same vehicle and runs the same run, event for event."""
    racy = mission("racy")
    vehicle_file = tmp_path / "facing90.yaml"
    vehicle_file.write_text("initial:\n  psi_deg: 90.0\n", encoding="utf-8")
    options = FuzzOptions(
        runs=1,
        seed=HOSTILE_RACE_SEED,
        link=BUILTIN_PROFILES["hostile"],
        sim_config=vehicle_file,
        faults=parse_fault_rules(["DEPTH=error@0.5"], source="test"),
    )
    copy = pickle.loads(pickle.dumps(options))
    assert copy == options
    assert pickle.loads(pickle.dumps(copy.vehicle(racy.net))) == options.vehicle(racy.net)
    first = run_one(racy.net, racy.approval, HOSTILE_RACE_SEED, options)
    second = run_one(racy.net, racy.approval, HOSTILE_RACE_SEED, copy)
    assert first.events_digest == second.events_digest
