"""How missions lower to nets: actions, replies, capacities, includes, finals, digest."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from coral_lang.compiler import compile_file, compile_mission, compile_source
from coral_lang.diagnostics import CompileError
from coral_lang.net import AssertKind, PlaceKind, TransitionKind
from coral_lang.profile import parse_profile
from tests.analysis.reference import explore_reference

SKETCH = re.search(
    r"```coral\n(.*?)```",
    (Path(__file__).resolve().parents[1] / "data" / "language-sketch.md").read_text(),
    re.S,
)

HEADER = "mission m\nvehicle ROMEO\n"


def test_language_sketch_example_compiles_as_it_stands() -> None:
    assert SKETCH is not None
    result = compile_source(SKETCH.group(1), "phase1.coral")
    assert result.errors == []
    assert result.net is not None
    assert len([t for t in result.net.transitions if t.kind is TransitionKind.COMMAND]) == 8


def test_action_lowers_to_command_pending_place_and_one_reply_transition_per_kind() -> None:
    text = HEADER + (
        "place a = 1, ok, bad\n"
        "transition check wait { a } signal { }\n"
        "    action { ROMEO(DEPTH?, z = 2.0, time_out = 30) -> { done: ok, timeout: bad } }\n"
    )
    net = compile_source(text, "m.coral").raise_for_errors()
    command = net.transition("check")
    assert command.kind is TransitionKind.COMMAND
    assert command.inputs == (("a", 1),)
    assert command.outputs == (("check.pending", 1),)
    assert command.command is not None and command.command.resources == ("depth",)
    pending = net.place("check.pending")
    assert pending.kind is PlaceKind.PENDING and pending.resources == ("depth",)
    done, timeout = net.transition("check.done"), net.transition("check.timeout")
    assert done.inputs == timeout.inputs == (("check.pending", 1),)
    assert done.outputs == (("ok", 1),) and timeout.outputs == (("bad", 1),)
    assert timeout.describe() == "check: DEPTH? replied timeout"


def test_ignored_reply_consumes_the_pending_token_and_marks_nothing() -> None:
    text = (
        HEADER
        + "place a = 1, b\ntransition t wait { a } action { ROMEO(DEPTH, 1.0) -> { ack: b, error: ignore } }\n"
    )
    net = compile_source(text, "m.coral").raise_for_errors()
    assert net.transition("t.error").outputs == ()


def test_reply_to_several_places_and_weights() -> None:
    text = (
        HEADER
        + "place a = 1, b, c\ntransition t wait { a } action { ROMEO(FIX_XY) -> { done: { b, c*2 }, error: b } }\n"
    )
    net = compile_source(text, "m.coral").raise_for_errors()
    assert net.transition("t.done").outputs == (("b", 1), ("c", 2))


def test_positional_and_named_params_give_the_same_command() -> None:
    named = (
        HEADER
        + "place a = 1, b\ntransition t wait { a } action { ROMEO(GOTO, x = 1, y = 2, psi = 3) -> { ack: b, error: b } }\n"
    )
    positional = named.replace("x = 1, y = 2, psi = 3", "1, 2, 3")
    mixed = named.replace("x = 1, y = 2, psi = 3", "1, psi = 3, y = 2")
    digests = {
        compile_source(t, "m.coral").raise_for_errors().digest() for t in (named, positional, mixed)
    }
    assert len(digests) == 1


def test_capacity_becomes_a_complement_place_that_blocks_overfilling() -> None:
    text = HEADER + "place src = 5, buf capacity 2\ntransition put wait { src } signal { buf }\n"
    net = compile_source(text, "m.coral").raise_for_errors()
    free = net.place("buf.free")
    assert free.kind is PlaceKind.COMPLEMENT and free.initial == 2
    result = explore_reference(net)
    buf = net.place_index("buf")
    assert max(m[buf] for m in result.states) == 2
    assert len(result.dead) == 1  # stuck with src = 3, buf full


def test_final_marking_ignores_complement_places() -> None:
    text = (
        HEADER
        + "place a = 1, buf capacity 2\ntransition t wait { a } signal { buf }\nfinal { buf }\n"
    )
    net = compile_source(text, "m.coral").raise_for_errors()
    result = explore_reference(net)
    assert result.dead and all(net.is_final(m) for m in result.dead)


def test_constants_with_units_are_converted_and_range_checked() -> None:
    text = (
        HEADER
        + "const DEEP = 150 cm\nplace a = 1, b\ntransition t wait { a } action { ROMEO(DEPTH, DEEP) -> { ack: b, error: b } }\n"
    )
    net = compile_source(text, "m.coral").raise_for_errors()
    command = net.transition("t").command
    assert command is not None and command.params == (("z", 1.5),)


def test_constant_error_points_at_the_use_and_notes_the_definition() -> None:
    text = (
        HEADER
        + "const DEEP = 900\nplace a = 1, b\ntransition t wait { a } action { ROMEO(DEPTH, DEEP) -> { ack: b, error: b } }\n"
    )
    error = compile_source(text, "m.coral").errors[0]
    assert error.code == "CORAL105" and error.span is not None and error.span.line == 5
    assert error.notes == ("'DEEP' is defined at m.coral:3:1",)


def test_assertions_and_finals_reach_the_net() -> None:
    text = (
        HEADER
        + "place a = 1, b\nfinal { b }\nfinal { b }\nassert never { a, b }\nassert bound { a, b } <= 1\nassert reachable { b }\n"
    )
    net = compile_source(text, "m.coral").raise_for_errors()
    assert len(net.finals) == 1  # the same final twice is one final
    assert [a.kind for a in net.assertions] == [
        AssertKind.NEVER,
        AssertKind.BOUND,
        AssertKind.REACHABLE,
    ]
    assert net.assertions[1].bound == 1


def test_digest_ignores_comments_and_layout_but_not_parameters() -> None:
    text = (
        HEADER
        + "place a = 1, b\ntransition t wait { a } action { ROMEO(DEPTH, z = 2.0) -> { ack: b, error: b } }\n"
    )
    base = compile_source(text, "m.coral").raise_for_errors().digest()
    reformatted = compile_source("# a comment\n" + text.replace(" { a }", "{a}"), "x.coral")
    assert reformatted.raise_for_errors().digest() == base
    changed = compile_source(text.replace("2.0", "2.5"), "m.coral").raise_for_errors().digest()
    assert changed != base
    assert base.startswith("sha256:") and len(base) == len("sha256:") + 64


def test_source_map_points_every_element_at_its_line() -> None:
    net = compile_mission(Path("examples/pool_mission/pool_mission.coral"))
    spans = net.source_map()
    assert spans["transition:check_depth"].file.endswith("go_to_operating_site.coral")
    timeout = spans["transition:check_depth.timeout"]
    line = Path(timeout.file).read_text().splitlines()[timeout.line - 1]
    assert line[timeout.col - 1 : timeout.end_col - 1] == "timeout: depth_failed"
    for transition in net.transitions:
        assert f"transition:{transition.name}" in spans
    for place in net.places:
        assert f"place:{place.name}" in spans


def test_includes_join_phases_through_shared_places(tmp_path: Path) -> None:
    (tmp_path / "phase.coral").write_text(
        "place go, there, abort\ntransition move wait { go } signal { there }\n"
    )
    (tmp_path / "main.coral").write_text(
        HEADER + 'place go = 1, abort\ninclude "phase.coral"\nfinal { there }\n'
    )
    net = compile_file(tmp_path / "main.coral").raise_for_errors()
    assert [p.name for p in net.places] == ["go", "abort", "there"]
    assert net.place("go").initial == 1


def test_include_problems_are_reported_at_the_include(tmp_path: Path) -> None:
    (tmp_path / "a.coral").write_text(HEADER + 'include "b.coral"\ninclude "missing.coral"\n')
    (tmp_path / "b.coral").write_text('include "a.coral"\nplace x = 1\n')
    (tmp_path / "c.coral").write_text("mission c\nvehicle OTHER\n")
    result = compile_file(tmp_path / "a.coral")
    messages = [d.message for d in result.errors]
    assert any(m.startswith("include cycle: a.coral -> b.coral -> a.coral") for m in messages)
    assert any(m.startswith("file not found:") and "missing.coral" in m for m in messages)


def test_conflicting_initial_tokens_across_files_are_an_error(tmp_path: Path) -> None:
    (tmp_path / "p.coral").write_text("place go = 2\n")
    (tmp_path / "m.coral").write_text(HEADER + 'place go = 1\ninclude "p.coral"\n')
    errors = compile_file(tmp_path / "m.coral").errors
    assert [e.code for e in errors] == ["CORAL003"]
    assert "given 2 initial tokens here and 1" in errors[0].message


def test_included_file_for_another_vehicle_is_refused(tmp_path: Path) -> None:
    (tmp_path / "p.coral").write_text("vehicle NAUTILUS\nplace go\n")
    (tmp_path / "m.coral").write_text(HEADER + 'include "p.coral"\n')
    errors = compile_file(tmp_path / "m.coral").errors
    assert [e.code for e in errors] == ["CORAL004"]


def test_a_custom_profile_replaces_the_bundled_one() -> None:
    profile = parse_profile(
        "vehicle BOT\nresources: [depth]\ncommands:\n  DIVE:\n    kind: task\n"
        "    params: [{name: z, type: int, unit: m, min: 0, max: 10}]\n    replies: [ok]\n"
        "    resources: [depth]\n".replace("vehicle BOT", "vehicle: BOT"),
        "bot.yaml",
    )
    text = "mission m\nvehicle BOT\nplace a = 1, b\ntransition t wait { a } action { BOT(DIVE, 3) -> { ok: b } }\n"
    net = compile_source(text, "m.coral", profiles=[profile]).raise_for_errors()
    command = net.transition("t").command
    assert (
        command is not None
        and command.params == (("z", 3),)
        and isinstance(command.params[0][1], int)
    )
    bad = compile_source(text.replace("DIVE, 3", "DIVE, 3.5"), "m.coral", profiles=[profile])
    assert [e.code for e in bad.errors] == ["CORAL103"]


def test_compile_mission_raises_one_error_listing_everything(tmp_path: Path) -> None:
    path = tmp_path / "bad.coral"
    path.write_text(HEADER + "place a\ntransition t wait { x } signal { y }\n")
    with pytest.raises(CompileError) as caught:
        compile_mission(path)
    assert len(caught.value.diagnostics) == 2
    assert "unknown place 'x'" in str(caught.value) and "unknown place 'y'" in str(caught.value)
    assert isinstance(caught.value, ValueError)


def test_unreadable_file_is_a_diagnostic(tmp_path: Path) -> None:
    (tmp_path / "latin1.coral").write_bytes(b"mission m\n# caf\xe9\n")
    result = compile_file(tmp_path / "latin1.coral")
    assert result.net is None and result.errors[0].code == "CORAL004"
    assert "not UTF-8" in result.errors[0].message
