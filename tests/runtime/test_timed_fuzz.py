"""Fuzz runs stay within what timed analysis proves (issue 15's property).

A fuzz run (`runtime.fuzz.run_one`: the engine, the controller, the link emulator and
the generic simulated vehicle, which keeps to the timed model) over a link whose
analysis bound holds (``lan``: no stalls, outages or resets; `FuzzRun.over_bound` is
checked to be 0, the premise) must:

* end in a declared final marking no sooner than analysis's best time to it and no
  later than its worst time, or else end stuck in a marking analysis says a run can end
  in;
* never see a query proven adequate reply ``timeout``.

Time origin. Analysis's time 0 is the mission's start: the first firing. The run's
`FuzzRun.duration` counts from the controller's ``mission-start`` event, which is at the
same virtual instant as the first firing (checked below), so no offset is needed. One
thing the model leaves out: the first command is sent before the connection is up and
reaches the vehicle only after the handshake (the ``handshake`` event, about 1 ms into a
``lan`` run), so it can arrive up to that long after its link delay allows; the worst
bound is allowed that much (``slack``) and nothing more. The best bound needs no slack:
the handshake only ever delays.
"""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from analysis.certificate import CertificateCheck
from analysis.report import Verdict
from analysis.timed import TimedOptions, TimedReport, analyse_timed
from coral_lang.compiler import compile_file
from coral_lang.linkprofile import load_link_profile
from coral_lang.net import Net, PlaceKind
from coral_lang.profile import VehicleProfile
from runtime.controller import RunEnd
from runtime.fuzz import FuzzOptions, FuzzRun, run_one, unverified_approval
from tests.analysis.timed.missions import EPS, TimedMission, stuck_set, timed_missions
from tests.conftest import EXAMPLES

LAN = load_link_profile("lan")
BOUNDS = LAN.analysis_bounds()
POOL = EXAMPLES / "pool_mission" / "pool_mission.coral"


def approval(net: Net) -> CertificateCheck:
    """The approval ``coral-run fuzz --unverified`` builds: these runs are simulated."""
    return unverified_approval(net)


def analyse(net: Net, profile: VehicleProfile) -> TimedReport:
    report = analyse_timed(
        net, [profile], TimedOptions(BOUNDS, max_states=50_000, time_limit_s=None, method="clock")
    )
    assert report.complete, report.reason
    return report


def fuzz_once(net: Net, profile: VehicleProfile, seed: int) -> FuzzRun:
    options = FuzzOptions(
        runs=1, seed=seed, link=LAN, time_limit=600.0, profile=profile, simulator="generic"
    )
    return run_one(net, approval(net), seed, options, keep_events=True)


def check_run(net: Net, report: TimedReport, run: FuzzRun) -> None:
    """The run is within what ``report`` proves (module docstring)."""
    assert run.over_bound == 0 and run.connections == 1, "the premise: the link bound holds"
    fires = [e for e in run.events if e.kind == "fire"]
    start = next(e for e in run.events if e.kind == "mission-start")
    assert fires and fires[0].time == start.time == 0.0
    handshake = next(e.time for e in run.events if e.kind == "handshake")
    slack = handshake + EPS
    mission = {p: n for p, n in run.marking.items() if n and net.place(p).kind is PlaceKind.MISSION}
    if run.end is RunEnd.FINAL:
        timing = next(f for f in report.finals if f.final == mission)
        assert timing.best_s - EPS <= run.duration <= timing.worst_s + slack, (
            run.seed,
            mission,
            run.duration,
            timing.describe(),
        )
    else:
        assert run.end is RunEnd.DEADLOCK, run.ending()
        marked = tuple(sorted((p, n) for p, n in run.marking.items() if n))
        assert marked in stuck_set(report), (run.seed, run.ending(), report.stuck)
    proven = {q.transition for q in report.queries if q.verdict is Verdict.PROVEN}
    for event in run.events:
        if event.kind == "fire":
            name = str(event.data.get("transition"))
            sender, _, reply = name.partition(".")
            assert not (reply == "timeout" and sender in proven), (run.seed, name)


@pytest.fixture(scope="module")
def pool() -> tuple[Net, VehicleProfile, TimedReport]:
    result = compile_file(POOL)
    assert result.net is not None and result.profile is not None
    return result.net, result.profile, analyse(result.net, result.profile)


@pytest.mark.parametrize("seed", range(4))
def test_pool_mission_runs_within_its_bounds(
    pool: tuple[Net, VehicleProfile, TimedReport], seed: int
) -> None:
    net, profile, report = pool
    assert all(q.verdict is Verdict.PROVEN for q in report.queries)
    run = fuzz_once(net, profile, seed)
    assert run.ok, run.ending()
    check_run(net, report, run)


@settings(
    max_examples=20,
    derandomize=True,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)
@given(timed_missions(), st.integers(min_value=0, max_value=2**20))
def test_generated_missions_run_within_their_bounds(mission: TimedMission, seed: int) -> None:
    # The drawn link bounds are the analysis's business; the run's link is lan, so the
    # analysis here assumes lan's bounds. The generic vehicle polls every 0.1 s, so it
    # refuses a profile promising replies sooner than that.
    assume(mission.profile.timing.reply_latency_s >= 0.1)
    report = analyse(mission.net, mission.profile)
    run = fuzz_once(mission.net, mission.profile, seed)
    check_run(mission.net, report, run)
