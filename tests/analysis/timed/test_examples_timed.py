"""Timed analysis of the bundled examples over the paper's link (genoa-lisbon bounds).

Both explorers (``clock``, the reference, and ``events``) must agree on every example
that compiles, and every witness must be a run of the model
(`tests.analysis.timed.missions.check_witnesses`). The pool mission's figures are
pinned: analysis is deterministic, so a change in them is a change in the model or a
bug, and must be explained.

Re-deriving a figure: ``coral-check verify --timed --link genoa-lisbon
examples/pool_mission/pool_mission.coral`` prints them, and the worst/best schedules
(``--schedule-dir``) show the run that attains each. Checked by hand:
``{ not_started }`` (INIT refused) is one round trip of INIT: best 0.045 (up) + 0.4
(ROMEO's INIT, 0.5 s -20 %) + 0 (latency) + 0.045 (down) = 0.49 s, worst 9.5 + 0.6 +
0.1 + 9.5 = 19.7 s.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from analysis.report import Verdict
from analysis.statespace import explore
from analysis.timed import TimedOptions, TimedReport, analyse_timed
from coral_lang.compiler import compile_file
from coral_lang.net import Net
from coral_lang.profile import VehicleProfile
from coral_lang.timing import LinkBounds
from tests.analysis.timed.missions import check_witnesses, stuck_set, summary
from tests.conftest import EXAMPLES

LINK = LinkBounds("genoa-lisbon", 0.045, 9.5)
"""The link profile's analysis bounds (``coral_lang.linkprofile``, genoa-lisbon)."""

POOL = EXAMPLES / "pool_mission" / "pool_mission.coral"
RACY = EXAMPLES / "racy" / "racy_mission.coral"


def compiled(path: Path) -> tuple[Net, VehicleProfile]:
    result = compile_file(path)
    assert result.net is not None and result.profile is not None, path
    return result.net, result.profile


def both(net: Net, profile: VehicleProfile, max_states: int = 50_000) -> list[TimedReport]:
    return [
        analyse_timed(net, [profile], TimedOptions(LINK, max_states, None, method))
        for method in ("clock", "events")
    ]


@pytest.fixture(scope="module")
def pool() -> tuple[Net, VehicleProfile, TimedReport, TimedReport]:
    net, profile = compiled(POOL)
    clock, events = both(net, profile)
    return net, profile, clock, events


def test_pool_methods_agree(pool: tuple[Net, VehicleProfile, TimedReport, TimedReport]) -> None:
    net, profile, clock, events = pool
    assert clock.complete and events.complete
    assert summary(clock) == summary(events)
    # Nothing is stuck, by either method.
    assert clock.stuck == () == events.stuck
    check_witnesses(net, profile, clock)
    check_witnesses(net, profile, events)


def test_pool_figures(pool: tuple[Net, VehicleProfile, TimedReport, TimedReport]) -> None:
    _, _, clock, _ = pool
    figures = {tuple(f.final): (f.best_s, f.worst_s) for f in clock.finals}
    assert figures == {
        ("mission_complete",): pytest.approx((329.88, 722.4)),
        ("aborted_at_surface",): pytest.approx((25.07, 742.1)),
        ("operator_alert",): pytest.approx((1.47, 706.7)),
        ("not_started",): pytest.approx((0.49, 19.7)),
    }
    for f in clock.finals:
        assert f.best_s <= f.worst_s
    # Completing the mission takes longer than refusing it at once, however it goes.
    assert figures[("mission_complete",)][0] > figures[("not_started",)][1]


def test_pool_every_query_adequate(
    pool: tuple[Net, VehicleProfile, TimedReport, TimedReport],
) -> None:
    _, _, clock, _ = pool
    assert len(clock.queries) == 11
    margins = {}
    for q in clock.queries:
        assert q.verdict is Verdict.PROVEN, q.detail
        assert q.counterexample is None
        assert q.margin_s is not None and 0 < q.margin_s < q.time_out_s
        margins[q.transition] = q.margin_s
    assert margins == pytest.approx(
        {
            "check_depth": 24.49,
            "check_heading": 36.49,
            "check_site": 36.49,
            "reach_wp1": 42.49,
            "reach_wp2": 42.49,
            "reach_wp3": 42.49,
            "reach_wp4": 42.49,
            "check_hover": 6.49,
            "check_dock": 72.49,
            "check_surface_home": 24.49,
            "confirm_surface": 24.49,
        }
    )


def untimed_stuck(net: Net) -> set[tuple[tuple[str, int], ...]]:
    """Untimed analysis's deadlocks that are not declared final."""
    space = explore(net)
    assert space.complete
    finals = {tuple(sorted(f.tokens)) for f in net.finals}
    found = set()
    for index in space.deadlocks:
        marking = net.marking_dict(space.marking(int(index)))
        tokens = tuple(sorted((p, n) for p, n in marking.items() if n))
        if tokens not in finals:
            found.add(tokens)
    return found


def test_racy_mission_is_stuck_where_untimed_analysis_says() -> None:
    net, profile = compiled(RACY)
    clock, events = both(net, profile)
    assert clock.complete and events.complete
    assert summary(clock) == summary(events)
    expected = {
        (("aborted", 1), ("depth_acked", 1)),
        (("aborted", 1), ("depth_failed", 1)),
    }
    assert untimed_stuck(net) == expected
    assert stuck_set(clock) == stuck_set(events) == expected
    # The race survives timing: HEADING? can be confirmed before DEPTH's ack is back.
    assert [f.final for f in clock.finals] == [{"on_station": 1}, {"aborted": 1}]
    assert [f.best_s for f in clock.finals] == pytest.approx([16.09, 16.09])
    assert [f.worst_s for f in clock.finals] == pytest.approx([43.1, 43.1])
    check_witnesses(net, profile, clock)
    check_witnesses(net, profile, events)


# unhandled_reply.coral is the one faulty example that must not compile (a reply kind
# left unmapped): tests/test_examples.py checks that it does not.
FAULTY = sorted(p for p in (EXAMPLES / "faulty").glob("*.coral") if p.stem != "unhandled_reply")


@pytest.mark.parametrize("path", FAULTY, ids=lambda p: p.stem)
def test_faulty_examples_methods_agree(path: Path) -> None:
    result = compile_file(path)
    assert result.net is not None and result.profile is not None, result.diagnostics
    net, profile = result.net, result.profile
    # unbounded.coral never ends (laps pile up): a small budget keeps it quick.
    clock, events = both(net, profile, max_states=3_000)
    assert summary(clock) == summary(events)
    if clock.complete:
        assert stuck_set(clock) == stuck_set(events)
        check_witnesses(net, profile, clock)
        check_witnesses(net, profile, events)
