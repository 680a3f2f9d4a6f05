"""The example missions: the pool mission compiles and behaves; each faulty one shows
its one fault (checked here with the plain reference explorer, and for the termination
faults with the verifier's lassos at their source lines)."""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from pathlib import Path

import pytest

from analysis.certificate import check_certificate, make_certificate, write_certificate
from analysis.report import Step, Verdict
from analysis.verify import VerifyOptions, verify
from coral_lang.compiler import compile_file, compile_mission
from coral_lang.formatting import format_source
from coral_lang.loading import load_net_file
from coral_lang.net import Net, PlaceKind
from coral_lang.profile import load_profile
from tests.analysis.reference import explore_reference
from tests.conftest import EXAMPLES

POOL = EXAMPLES / "pool_mission" / "pool_mission.coral"
FAULTY = EXAMPLES / "faulty"
SURVEY = EXAMPLES / "survey_auv" / "survey.coral"


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


# -- termination (issue 11): verified means cannot get stuck, cannot spin, ends properly --


def _lines(steps: Sequence[Step]) -> list[int]:
    return [s.span.line for s in steps if s.span is not None]


def _replays_as_a_lasso(net: Net, trace: Sequence[Step], loop: Sequence[Step]) -> bool:
    marking = net.initial_marking()
    for step in trace:
        marking = net.fire(marking, net.transition(step.transition))
    entry = marking
    for step in loop:
        transition = net.transition(step.transition)
        if not net.enabled(marking, transition):
            return False
        marking = net.fire(marking, transition)
    return marking == entry and bool(loop)


@pytest.mark.parametrize(
    ("name", "key", "trace_lines", "loop_lines"),
    [
        # DEPTH refused, then ping and pong hand the token back and forth forever
        ("livelock.coral", "no_engine_cycle", [19, 21], [27, 31]),
        # DEPTH? times out, retry sends it again, forever; the mission requires termination
        ("retry_forever.coral", "terminates", [20, 22], [24, 26, 28]),
    ],
)
def test_faulty_non_termination_is_caught_with_a_lasso_at_its_lines(
    name: str, key: str, trace_lines: list[int], loop_lines: list[int]
) -> None:
    net = compile_mission(FAULTY / name)
    report = verify(net, VerifyOptions(structural=False))
    assert report.property("deadlock").verdict is Verdict.PROVEN  # no deadlock to find
    result = report.property(key)
    assert result.verdict is Verdict.VIOLATED and result.required
    assert result.evidence is not None
    assert _lines(result.evidence.trace) == trace_lines
    assert _lines(result.evidence.loop) == loop_lines
    for step in (*result.evidence.trace, *result.evidence.loop):
        assert step.span is not None and step.span.file.endswith(name)
    assert _replays_as_a_lasso(net, result.evidence.trace, result.evidence.loop)
    assert report.verdict is Verdict.VIOLATED and report.exit_code() == 1


def test_pool_mission_proves_termination_and_its_certificate_is_accepted(
    tmp_path: Path,
) -> None:
    net = compile_mission(POOL)
    report = verify(net, VerifyOptions(structural=False))
    assert report.verdict is Verdict.PROVEN
    for key in ("no_engine_cycle", "final_always_reachable", "terminates"):
        assert report.property(key).verdict is Verdict.PROVEN, key
    path = tmp_path / "pool.cert.json"
    write_certificate(make_certificate(report), path)
    assert check_certificate(net, path).net_digest == net.digest()


def test_the_faulty_readme_lists_every_faulty_mission() -> None:
    listed = (FAULTY / "README.md").read_text()
    for path in sorted(FAULTY.glob("*.coral")):
        assert f"`{path.name}`" in listed, path.name


def test_survey_auv_mission_verifies_clean_against_its_profile(tmp_path: Path) -> None:
    """Issue 12: a mission for another vehicle (MINNOW, with queries that have no
    tracking criterion) maps every reply and proves every property, termination too."""
    minnow = load_profile(EXAMPLES / "profiles" / "minnow.yaml")
    net = compile_mission(SURVEY, [minnow])
    sent = {t.command.name for t in net.transitions if t.command is not None}
    assert sent == set(minnow.command_names)
    report = verify(net, VerifyOptions(structural=False))
    assert report.verdict is Verdict.PROVEN and report.exit_code() == 0
    assert all(p.verdict is Verdict.PROVEN for p in report.properties)
    assert report.property("terminates").verdict is Verdict.PROVEN
    path = tmp_path / "survey.cert.json"
    write_certificate(make_certificate(report), path)
    assert check_certificate(net, path).net_digest == net.digest()


def test_every_example_file_loads_and_every_part_says_which_mission_it_belongs_to() -> None:
    """``coral-check examples/pool_mission/*.coral`` passes: a phase file is checked as
    the mission it is a part of (its header), never alone (docs/language.md)."""
    minnow = load_profile(EXAMPLES / "profiles" / "minnow.yaml")
    parts = 0
    for path in sorted(EXAMPLES.glob("*/*.coral")):
        if path.parent == FAULTY:
            continue
        result = load_net_file(path, [minnow])
        assert result.ok, [d.render(result.sources) for d in result.errors]
        is_mission = path.read_text().find("\nmission ") >= 0
        assert (result.part_of is None) == is_mission, path
        if result.part_of is not None:
            parts += 1
            assert result.part_path == path and result.part_of.exists()
    assert parts == 5  # the pool mission's four phases and the operator's abort path


@pytest.mark.parametrize(
    "path", sorted(EXAMPLES.rglob("*.coral")), ids=lambda p: str(p.relative_to(EXAMPLES))
)
def test_every_example_is_in_canonical_layout(path: Path) -> None:
    # docs/ci.md runs `coral-check fmt --check` on the examples, and so does the
    # pre-commit hook: the repository's own missions must pass it
    text = path.read_text()
    assert format_source(text, str(path)) == text, f"run: coral-check fmt {path}"
