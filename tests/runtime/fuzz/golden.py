"""The golden fuzz runs: what a few seeds did before the runs were made faster.

``golden_runs.json`` beside this file holds, for a handful of scenarios and seeds, each
run's ending and the SHA-256 of its controller events (kinds, virtual times and data,
reply details with the vehicle's figures included). It was written by this module at
commit 4a71353, before the speed work of issue 18, and must never be rewritten to make a
test pass: a faster run is only right if it does exactly what the slower one did.
``test_golden.py`` runs the same scenarios and compares. To see what this module
computes now (e.g. to study a difference)::

    .venv/bin/python -m tests.runtime.fuzz.golden > /tmp/now.json
"""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass
from pathlib import Path

from coral_lang.compiler import compile_mission
from coral_lang.net import Net
from coral_lang.profile import load_profile
from runtime.engine import Policy
from runtime.faultplan import parse_fault_rules
from runtime.fuzz import FuzzOptions, run_one, unverified_approval
from runtime.link import load_link_profile

REPO = Path(__file__).resolve().parents[3]
GOLDEN = Path(__file__).with_name("golden_runs.json")


@dataclass(frozen=True)
class Scenario:
    """A mission, a link and a vehicle, and the seeds run on them."""

    name: str
    mission: str
    link: str
    seeds: tuple[int, ...]
    profile: str | None = None
    faults: str | None = None
    policy: Policy = Policy.RANDOM


SCENARIOS = (
    Scenario(
        "pool/genoa-lisbon",
        "examples/pool_mission/pool_mission.coral",
        "genoa-lisbon",
        (0, 1, 2, 3, 4, 5),
    ),
    Scenario(
        "pool/hostile", "examples/pool_mission/pool_mission.coral", "hostile", (100, 101, 102)
    ),
    Scenario(
        "pool/priority",
        "examples/pool_mission/pool_mission.coral",
        "lan",
        (7,),
        policy=Policy.PRIORITY,
    ),
    Scenario("racy/genoa-lisbon", "examples/racy/racy_mission.coral", "genoa-lisbon", (0, 1, 2)),
    Scenario(
        "survey/minnow-faults",
        "examples/survey_auv/survey.coral",
        "genoa-lisbon",
        (0, 1, 2),
        profile="examples/profiles/minnow.yaml",
        faults="*=any@0.1",
    ),
)


def options_of(scenario: Scenario, runs: int = 1) -> FuzzOptions:
    """The fuzz options of ``scenario``."""
    profile = None if scenario.profile is None else load_profile(REPO / scenario.profile)
    faults = None if scenario.faults is None else parse_fault_rules([scenario.faults])
    return FuzzOptions(
        runs=runs,
        seed=scenario.seeds[0],
        link=load_link_profile(scenario.link),
        policy=scenario.policy,
        profile=profile,
        faults=faults,
    )


def net_of(scenario: Scenario) -> Net:
    """The compiled mission of ``scenario``."""
    profile = None if scenario.profile is None else load_profile(REPO / scenario.profile)
    return compile_mission(REPO / scenario.mission, () if profile is None else (profile,))


def outcomes(scenario: Scenario) -> dict[str, list[str]]:
    """seed -> [ending, events digest] for every seed of ``scenario``.

    Every mission runs under the approval ``--unverified`` builds: the approval is not
    part of a run's events, and the racy mission has no certificate to give.
    """
    net = net_of(scenario)
    approval = unverified_approval(net)
    options = options_of(scenario)
    result: dict[str, list[str]] = {}
    for seed in scenario.seeds:
        run = run_one(net, approval, seed, options)
        result[str(seed)] = [run.ending(), run.events_digest]
    return result


def main() -> int:
    """Print what every scenario does now, as ``golden_runs.json`` holds it."""
    table = {s.name: outcomes(s) for s in SCENARIOS}
    json.dump(table, sys.stdout, indent=1, sort_keys=True)
    sys.stdout.write("\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
