"""Faster fuzz runs do what the slower ones did: the golden runs, seed for seed.

``golden_runs.json`` was written by `tests.runtime.fuzz.golden` before the runs were made
faster (its docstring says when); each scenario's seeds must end the same way with the
same controller events (virtual times and the vehicle's figures in reply details
included), bit for bit.
"""

from __future__ import annotations

import json

import pytest

from tests.runtime.fuzz.golden import GOLDEN, SCENARIOS, Scenario, outcomes


def _golden() -> dict[str, dict[str, list[str]]]:
    table: dict[str, dict[str, list[str]]] = json.loads(GOLDEN.read_text(encoding="utf-8"))
    return table


def test_every_scenario_has_golden_runs() -> None:
    table = _golden()
    assert sorted(table) == sorted(s.name for s in SCENARIOS)
    for scenario in SCENARIOS:
        assert sorted(table[scenario.name]) == sorted(str(seed) for seed in scenario.seeds)


@pytest.mark.parametrize("scenario", SCENARIOS, ids=lambda s: s.name)
def test_runs_match_the_golden_runs(scenario: Scenario) -> None:
    assert outcomes(scenario) == _golden()[scenario.name]
