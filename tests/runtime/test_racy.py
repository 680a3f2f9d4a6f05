"""The racy mission: a fault that shows only under some delays, found three ways that agree.

``examples/racy/racy_mission.coral`` assumes DEPTH's ack always beats HEADING?'s answer.
DEPTH is sent only after LRM's ack has come back, so a slow enough link (or a fast
enough heading) lets HEADING? answer first: 'depth_never_acked' aborts, and the late
DEPTH answer is left with nothing to consume it.

* Analysis flags it statically: ``coral-check verify`` reports a deadlock.
* Hypothesis finds it among engine-level schedules and shrinks it to a schedule in
  which every deviation from nominal timing is needed.
* The two agree: the dead marking the runtime ends in is one of the dead markings of
  analysis's state space (not a final one), and every such marking analysis predicts is
  reached by some schedule.
* In the simulator, over emulated links, it shows too, but only with a vehicle whose
  heading already holds 90 degrees (the bundled ROMEO starts at 0 degrees, and with no
  HEADING task in the mission HEADING? then always times out) and a long stall.

The pool mission, verified clean, never fails under the same searches.
"""

from __future__ import annotations

import dataclasses
import io
from contextlib import redirect_stdout
from pathlib import Path

import pytest
from hypothesis import Phase, find, given, settings
from hypothesis import strategies as st
from hypothesis.errors import NoSuchExample

from analysis.cli import main as coral_check
from runtime.controller import RunEnd
from runtime.engine import Outcome, Policy
from runtime.fuzz import FuzzOptions, run_one
from runtime.link import BUILTIN_PROFILES
from runtime.schedule import MessageFate, Schedule
from runtime.schedule_strategies import schedules
from tests.runtime.test_properties import MISSIONS, check_run, mission, run

RACE_MARKINGS = ({"depth_acked": 1, "aborted": 1}, {"depth_failed": 1, "aborted": 1})

# Generation and shrinking only: no "explain" phase (it re-runs the search to annotate
# the failure, seconds that tell us nothing here), no example database.
SEARCH = settings(
    database=None,
    max_examples=2000,
    phases=[Phase.generate, Phase.shrink],
    deadline=None,
    derandomize=True,
)

HOSTILE_RACE_SEED = 81
"""A run seed whose hostile-link run hits the race. Found with ``coral-run fuzz
examples/racy/racy_mission.coral --unverified --link hostile --vehicle-config FILE``
(FILE: ``initial: {psi_deg: 90}``); if a change to the simulator or the link emulator
moves the race off this seed, take one from that command's report."""


def deadlocks(schedule: Schedule) -> bool:
    return run("racy", schedule).outcome is Outcome.DEADLOCK


FACING_90 = "initial:\n  psi_deg: 90.0\n"
"""A ROMEO vehicle file (docs/sim.md): the bundled vehicle, already facing 90 degrees,
as the racy mission's author assumed. A file rather than a vehicle built in code, so the
fuzz options stay plain data (`FuzzOptions` pickles)."""


@pytest.fixture(scope="module")
def facing_90(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("vehicle") / "facing90.yaml"
    path.write_text(FACING_90, encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def shrunk() -> Schedule:
    """The smallest racy schedule hypothesis finds (deterministic: derandomized)."""
    return find(schedules(), deadlocks, settings=SEARCH)


def test_analysis_flags_the_race_statically() -> None:
    out = io.StringIO()
    with redirect_stdout(out):
        code = coral_check(["verify", str(MISSIONS["racy"]), "--color", "never"])
    text = out.getvalue()
    assert code == 1, text
    assert "VIOLATED      no deadlock" in text
    assert "depth_never_acked" in text  # the shortest trace ends with the culprit
    racy = mission("racy")
    assert not racy.proven("deadlock")
    assert racy.proven("resource_conflicts") and racy.proven("bounded")
    for marking in RACE_MARKINGS:
        assert marking in racy.dead


def test_nominal_timing_hides_the_race() -> None:
    """With every leg on time the mission works: the fault needs delays."""
    result = run("racy", Schedule())
    assert result.outcome is Outcome.FINAL and result.marking == {"on_station": 1}


@pytest.mark.slow
def test_hypothesis_finds_the_race_and_shrinks_it_to_what_matters(shrunk: Schedule) -> None:
    result = run("racy", shrunk)
    assert result.outcome is Outcome.DEADLOCK
    # HEADING? answered before the depth branch had its answer, and the culprit fired.
    trace = result.trace
    assert trace.index("confirm_heading.done") < trace.index("depth_never_acked")
    depth_answer = next(t for t in trace if t in ("dive.ack", "dive.error", "hover.error"))
    assert trace.index("confirm_heading.done") < trace.index(depth_answer)
    # Shrunk: nothing after the last command that matters, and every deviation from
    # nominal is needed: put any one field back, or drop any outage, and the fault is
    # gone. (Which minimal schedule hypothesis lands on may vary with its version and
    # with the modules loaded: it mines them for constants.)
    assert not shrunk.messages or shrunk.messages[-1] != MessageFate()
    for k in range(len(shrunk.outages)):
        fewer = shrunk.outages[:k] + shrunk.outages[k + 1 :]
        assert not deadlocks(dataclasses.replace(shrunk, outages=fewer)), f"outage {k} not needed"
    nominal = MessageFate()
    for i, fate in enumerate(shrunk.messages):
        for name in ("reply", "up_ms", "work_permille", "down_ms", "rank"):
            if getattr(fate, name) == getattr(nominal, name):
                continue
            messages = list(shrunk.messages)
            messages[i] = dataclasses.replace(fate, **{name: getattr(nominal, name)})
            simpler = dataclasses.replace(shrunk, messages=tuple(messages))
            assert not deadlocks(simpler), f"command #{i + 1} {name} is not needed"


def test_the_runtime_dead_marking_is_one_analysis_predicts(shrunk: Schedule) -> None:
    racy = mission("racy")
    result = run("racy", shrunk)
    assert result.marking in racy.dead
    assert not racy.net.is_final(racy.net.marking_from(result.marking))


@pytest.mark.slow
@pytest.mark.parametrize("marking", RACE_MARKINGS, ids=["depth_acked", "depth_failed"])
def test_every_dead_marking_analysis_predicts_is_reached_by_some_schedule(
    marking: dict[str, int],
) -> None:
    racy = mission("racy")
    predicted = [m for m in racy.dead if not racy.net.is_final(racy.net.marking_from(m))]
    assert sorted(map(sorted, predicted)) == sorted(map(sorted, RACE_MARKINGS))
    found = find(schedules(), lambda s: run("racy", s).marking == marking, settings=SEARCH)
    assert run("racy", found).outcome is Outcome.DEADLOCK


@pytest.mark.slow
def test_the_same_search_finds_nothing_wrong_with_the_pool_mission() -> None:
    def fails(schedule: Schedule) -> bool:
        return run("pool", schedule).outcome is not Outcome.FINAL

    with pytest.raises(NoSuchExample):
        find(schedules(), fails, settings=settings(SEARCH, max_examples=400))


@settings(max_examples=100)
@given(schedule=schedules(), policy=st.sampled_from(list(Policy)), seed=st.integers(0, 2**32))
def test_the_pool_mission_never_fails_where_the_racy_one_may(
    schedule: Schedule, policy: Policy, seed: int
) -> None:
    assert run("pool", schedule, policy=policy, seed=seed).outcome is Outcome.FINAL


# --------------------------------------------------------------------------- simulator


def test_the_race_shows_in_the_simulator_over_a_hostile_link(facing_90: Path) -> None:
    """HEADING? goes first (random policy) and LRM's command is stalled past the 5 s the
    vehicle needs to confirm the heading: LRM's refusal comes too late."""
    racy = mission("racy")
    options = FuzzOptions(
        runs=1,
        seed=HOSTILE_RACE_SEED,
        link=BUILTIN_PROFILES["hostile"],
        sim_config=facing_90,
    )
    result = run_one(racy.net, racy.approval, HOSTILE_RACE_SEED, options, keep_events=True)
    assert result.end is RunEnd.DEADLOCK
    assert result.marking in racy.dead and result.marking in RACE_MARKINGS
    check_run("racy", result)  # nothing lost, every firing an edge of the graph
    fired = [str(e.data["transition"]) for e in result.events if e.kind == "fire"]
    assert fired.index("confirm_heading.done") < fired.index("depth_never_acked")


def test_with_the_bundled_vehicle_the_race_cannot_show() -> None:
    """The bundled ROMEO starts facing 0 degrees and LRM is refused before FIX_XY: HEADING?
    times out (40 s) long after LRM's error, whatever the link does."""
    racy = mission("racy")
    options = FuzzOptions(runs=1, seed=HOSTILE_RACE_SEED, link=BUILTIN_PROFILES["hostile"])
    result = run_one(racy.net, racy.approval, HOSTILE_RACE_SEED, options)
    assert result.end is RunEnd.FINAL and result.marking == {"aborted": 1}


@pytest.mark.slow
@pytest.mark.parametrize("profile", ["hostile", "genoa-lisbon"])
def test_the_pool_mission_never_fails_in_the_simulator_where_the_racy_one_does(
    profile: str, facing_90: Path
) -> None:
    pool = mission("pool")
    for seed in range(HOSTILE_RACE_SEED - 2, HOSTILE_RACE_SEED + 2):
        options = FuzzOptions(
            runs=1, seed=seed, link=BUILTIN_PROFILES[profile], sim_config=facing_90
        )
        result = run_one(pool.net, pool.approval, seed, options, keep_events=True)
        check_run("pool", result)
        assert result.end is RunEnd.FINAL, (seed, result.marking)
