"""Deadlock verdicts on the smaller MCC conformance instances, with reductions, equal the
oracle; every witness replays on the original net (all 47 are in bench/reductions.py)."""

from __future__ import annotations

from functools import cache
from typing import Any

import pytest
import yaml

from analysis.reduce import decide_deadlock
from analysis.reduce.deadlock import is_dead, replay
from coral_lang.pnml import parse_pnml
from tests.conftest import CONFORMANCE

MAX_ORACLE_STATES = 20_000
"""Instances up to this many reachable markings (unreduced) run here: a few seconds."""


@cache
def _models() -> list[dict[str, Any]]:
    with (CONFORMANCE / "oracle.yaml").open() as handle:
        models: list[dict[str, Any]] = yaml.safe_load(handle)["models"]
    return [m for m in models if m["states"] <= MAX_ORACLE_STATES]


@pytest.mark.parametrize("model", _models(), ids=lambda m: str(m["model"]))
def test_deadlock_with_reductions_matches_the_oracle(model: dict[str, Any]) -> None:
    name = model["model"]
    net = parse_pnml((CONFORMANCE / "pnml" / f"{name}.pnml").read_bytes(), f"{name}.pnml")
    answer = decide_deadlock(net)
    assert answer.deadlock == model["deadlock"]
    assert answer.states <= model["states"]
    if answer.deadlock:
        assert answer.trace is not None
        reached = replay(net, answer.trace)
        assert reached is not None and is_dead(net, reached)
