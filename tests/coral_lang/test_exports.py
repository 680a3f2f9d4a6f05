"""The public surface of coral_lang is deliberate: adding or removing a name is a
decision, so this test must change with it."""

from __future__ import annotations

import coral_lang

EXPECTED = {
    "AssertKind", "Assertion", "Command", "CommandSpec", "CompileError", "CompileResult",
    "CoralError", "Diagnostic", "FinalMarking", "Mission", "Net", "NetError", "ParamSpec", "Place",
    "PlaceKind", "PnmlError", "ProfileError", "Severity", "SpaceTrap", "Span", "Transition",
    "TransitionKind", "VehicleProfile", "compile_file", "compile_mission", "compile_source",
    "format_mission", "load_bundled_profile", "load_mission", "load_net_file", "load_profile", "parse",
    "parse_pnml", "parse_profile", "read_pnml", "render_all", "to_dot", "to_pnml", "write_pnml",
}  # fmt: skip


def test_public_names_are_exactly_the_expected_ones() -> None:
    assert set(coral_lang.__all__) == EXPECTED


def test_every_public_name_exists_and_is_documented() -> None:
    for name in coral_lang.__all__:
        obj = getattr(coral_lang, name)
        assert getattr(obj, "__doc__", None), f"{name} has no docstring"


def test_errors_mix_in_the_builtin_they_resemble() -> None:
    for error in (
        coral_lang.CompileError,
        coral_lang.ProfileError,
        coral_lang.PnmlError,
        coral_lang.NetError,
    ):
        assert issubclass(error, coral_lang.CoralError) and issubclass(error, ValueError)
