"""The example missions: the pool mission compiles and behaves; each faulty one shows
its one fault (checked here with the plain reference explorer)."""

from __future__ import annotations

import itertools

from coral_lang.compiler import compile_file, compile_mission
from coral_lang.net import Net, PlaceKind
from tests.analysis.reference import explore_reference
from tests.conftest import EXAMPLES

POOL = EXAMPLES / "pool_mission" / "pool_mission.coral"
FAULTY = EXAMPLES / "faulty"


def _conflicts(net: Net, marking: tuple[int, ...]) -> list[tuple[str, str]]:
    pending = [
        p for p, m in zip(net.places, marking, strict=True) if m and p.kind is PlaceKind.PENDING
    ]
    return [
        (a.name, b.name)
        for a, b in itertools.combinations(pending, 2)
        if set(a.resources) & set(b.resources)
    ]


def test_pool_mission_has_all_three_phases_and_every_table_1_task() -> None:
    net = compile_mission(POOL)
    sent = {t.command.name for t in net.transitions if t.command is not None}
    assert sent >= {
        "INIT",
        "DEPTH",
        "DEPTH?",
        "HEADING",
        "HEADING?",
        "FIX_XY",
        "GET_DOCK",
        "GOTO",
        "XYPSI?",
        "LRM",
        "XY?",
        "SRM",
        "DOCKING",
        "DOCKING?",
        "SURFACE",
        "SURFACE?",
    }
    lrm = [t for t in net.transitions if t.command is not None and t.command.name == "LRM"]
    assert len(lrm) == 4


def test_pool_mission_every_dead_marking_is_a_declared_final_and_no_resource_conflicts() -> None:
    net = compile_mission(POOL)
    result = explore_reference(net)
    assert result.complete
    assert result.dead and all(net.is_final(m) for m in result.dead)
    assert not any(_conflicts(net, m) for m in result.states)
    complete = net.marking_from({"mission_complete": 1})
    assert complete in result.parent


def test_every_failure_reply_leads_to_a_final_marking() -> None:
    net = compile_mission(POOL)
    result = explore_reference(net)
    finals = {net.place_index(n) for f in net.finals for n, _ in f.tokens}
    assert {net.place_names[i] for i in finals} == {
        "mission_complete",
        "aborted_at_surface",
        "operator_alert",
        "not_started",
    }
    # an abort token never accumulates: at most one ever
    abort = net.place_index("abort")
    assert max(m[abort] for m in result.states) == 1


def test_faulty_deadlock_leaves_a_token_behind() -> None:
    net = compile_mission(FAULTY / "deadlock.coral")
    result = explore_reference(net)
    stuck = [m for m in result.dead if not net.is_final(m)]
    assert stuck
    shortest = min(stuck, key=lambda m: len(result.trace_to(m)))
    # both branches fail: two abort tokens, and no final allows that
    assert net.marking_dict(shortest) == {"abort": 2}
    assert len(result.trace_to(shortest)) == 5
    # one branch fails, the other succeeds: its token is left behind
    assert net.marking_from({"abort": 1, "heading_ok": 1}) in stuck
    assert net.marking_from({"abort": 1, "depth_ok": 1}) in stuck


def test_faulty_unbounded_grows_without_limit() -> None:
    net = compile_mission(FAULTY / "unbounded.coral")
    result = explore_reference(net, max_states=500)
    assert not result.complete
    lap = net.place_index("lap_logged")
    assert max(m[lap] for m in result.states) > 50


def test_faulty_unhandled_reply_is_refused_by_the_compiler() -> None:
    result = compile_file(FAULTY / "unhandled_reply.coral")
    assert [e.code for e in result.errors] == ["CORAL106"]


def test_faulty_resource_conflict_has_two_pending_commands_on_one_resource() -> None:
    net = compile_mission(FAULTY / "resource_conflict.coral")
    result = explore_reference(net)
    conflicts = {pair for m in result.states for pair in _conflicts(net, m)}
    assert ("go_to_site.pending", "hold_heading.pending") in conflicts


def test_faulty_dead_transition_never_fires() -> None:
    net = compile_mission(FAULTY / "dead_transition.coral")
    result = explore_reference(net)
    record = net.place_index("position_fixed")
    assert all(m[record] == 0 for m in result.states)
    fired = {t for m in result.states for t, tr in enumerate(net.transitions) if net.enabled(m, tr)}
    assert net.transition_index("record_dock") not in fired
    assert any(not net.is_final(m) for m in result.dead)
