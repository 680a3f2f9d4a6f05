"""Vehicle profiles: the bundled ROMEO profile and refusal of bad ones."""

from __future__ import annotations

from pathlib import Path

import pytest

from coral_lang.diagnostics import MAX_PROFILE_ERRORS_SHOWN, ProfileError
from coral_lang.profile import (
    SPACE_TRAP_SIGNALS,
    load_bundled_profile,
    load_profile,
    parse_profile,
)
from tests.conftest import EXAMPLES

TABLE_1 = [
    "DEPTH",
    "DEPTH?",
    "HEADING",
    "HEADING?",
    "LRM",
    "XY?",
    "SRM",
    "GOTO",
    "XYPSI?",
    "DOCKING",
    "DOCKING?",
    "FIX_XY",
    "GET_DOCK",
]


def test_romeo_profile_has_every_command_of_table_1() -> None:
    profile = load_bundled_profile("ROMEO")
    assert profile.name == "ROMEO"
    for name in [*TABLE_1, "INIT", "SURFACE"]:
        assert profile.command(name) is not None, name


def test_romeo_queries_take_time_out_and_reply_done_or_timeout() -> None:
    profile = load_bundled_profile("romeo")
    queries = [c for c in profile.commands if c.name.endswith("?")]
    assert {q.name for q in queries} >= {"DEPTH?", "HEADING?", "XY?", "XYPSI?", "DOCKING?"}
    for query in queries:
        assert query.kind == "query"
        assert set(query.replies) == {"done", "timeout"}
        assert query.param("time_out") is not None
        assert query.space_trap is not None


def test_romeo_orders_follow_the_paper() -> None:
    profile = load_bundled_profile("ROMEO")
    xy = profile.command("XY?")
    depth = profile.command("DEPTH?")
    assert xy is not None and xy.space_trap is not None and xy.space_trap.order == 0
    assert depth is not None and depth.space_trap is not None and depth.space_trap.order == 1


def test_romeo_resources_as_the_language_sketch_gives_them() -> None:
    profile = load_bundled_profile("ROMEO")
    expected = {
        "DEPTH": {"depth"},
        "DEPTH?": {"depth"},
        "HEADING": {"heading"},
        "HEADING?": {"heading"},
        "LRM": {"horizontal"},
        "XY?": {"horizontal"},
        "SRM": {"horizontal", "heading"},
        "GOTO": {"horizontal", "heading"},
        "XYPSI?": {"horizontal", "heading"},
        "DOCKING": {"horizontal", "heading"},
        "DOCKING?": {"horizontal"},
        "FIX_XY": {"horizontal"},
    }
    for name, resources in expected.items():
        command = profile.command(name)
        assert command is not None
        assert set(command.resources) == resources, name


GOOD = """
vehicle: BOT
resources: [depth]
commands:
  DIVE:
    kind: task
    params:
      - {name: z, type: float, unit: m, min: 0, max: 10}
    replies: [ack, error]
    resources: [depth]
"""

BAD_PROFILES = [
    (GOOD.replace("max: 10", "max: ten"), "commands.DIVE.params[0].max", "expected a number"),
    (
        GOOD.replace("type: float", "type: real"),
        "commands.DIVE.params[0].type",
        "type must be one of",
    ),
    (
        GOOD.replace("resources: [depth]\n    ", "resources: [dpeth]\n    ").replace(
            "replies: [ack, error]\n    resources: [depth]",
            "replies: [ack, error]\n    resources: [dpeth]",
        ),
        "commands.DIVE.resources[0]",
        "did you mean 'depth'",
    ),
    (GOOD.replace("kind: task", "kind: query"), "commands.DIVE.params", "time_out"),
    (GOOD.replace("unit: m", "unit: meters"), "commands.DIVE.params[0].unit", "unknown unit"),
    (
        GOOD.replace("min: 0, max: 10", "min: 10, max: 0"),
        "commands.DIVE.params[0].min",
        "greater than max",
    ),
    (GOOD.replace("replies: [ack, error]", "replies: []"), "commands.DIVE.replies", "at least one"),
    (
        GOOD.replace("    kind: task\n", "    kind: task\n    colour: red\n"),
        "commands.DIVE.colour",
        "unknown field",
    ),
    (GOOD.replace("vehicle: BOT\n", ""), "", "missing required field 'vehicle'"),
    ("vehicle: [1\n", "", "not valid YAML"),
]


@pytest.mark.parametrize(("text", "path", "message"), BAD_PROFILES)
def test_bad_profile_names_the_offending_field(text: str, path: str, message: str) -> None:
    with pytest.raises(ProfileError) as caught:
        parse_profile(text, "bot.yaml")
    assert caught.value.path == path
    assert message in str(caught.value)
    assert str(caught.value).startswith("bot.yaml")


def test_bad_profile_error_has_line_and_column() -> None:
    with pytest.raises(ProfileError) as caught:
        parse_profile(GOOD.replace("max: 10", "max: ten"), "bot.yaml")
    assert str(caught.value).startswith("bot.yaml:8:54:")


def test_good_profile_loads(tmp_path: Path) -> None:
    path = tmp_path / "bot.yaml"
    path.write_text(GOOD)
    profile = load_profile(path)
    dive = profile.command("DIVE")
    assert dive is not None and dive.params[0].maximum == 10.0


def test_unreadable_profile_is_a_profile_error(tmp_path: Path) -> None:
    with pytest.raises(ProfileError, match="cannot read profile"):
        load_profile(tmp_path / "missing.yaml")
    with pytest.raises(ProfileError, match="no bundled profile"):
        load_bundled_profile("NOSUCH")


def test_the_fast_yaml_parser_gives_the_same_values_and_positions(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Profiles are parsed with libyaml when PyYAML has it: same data, same line and
    column of every field as the pure-Python parser, so error messages point alike."""
    import yaml

    from coral_lang import yamlsource

    text = (Path(yamlsource.__file__).parent / "profiles" / "romeo.yaml").read_text()
    fast = yamlsource.load_yaml(text, "romeo.yaml")
    monkeypatch.setattr(yamlsource, "_LOADER", yaml.SafeLoader)
    slow = yamlsource.load_yaml(text, "romeo.yaml")
    assert fast.data == slow.data and fast.positions == slow.positions
    assert len(fast.positions) > 100


QUERY = """
vehicle: BOT
resources: [gnss]
commands:
  GPS_FIX?:
    kind: query
    params:
      - {name: time_out, type: float, unit: s, min: 10, max: 600}
    replies: [done, timeout, error]
    resources: [gnss]
"""


def test_query_without_a_tracking_criterion_loads() -> None:
    fix = parse_profile(QUERY, "bot.yaml").command("GPS_FIX?")
    assert fix is not None and fix.kind == "query" and fix.space_trap is None
    assert fix.replies == ("done", "timeout", "error")


def test_query_without_a_space_trap_still_needs_its_time_out() -> None:
    with pytest.raises(ProfileError, match="must take a 'time_out'") as caught:
        parse_profile(QUERY.replace("name: time_out", "name: wait"), "bot.yaml")
    assert caught.value.path == "commands.GPS_FIX?.params"


def test_unknown_space_trap_signal_is_refused_with_the_known_ones() -> None:
    text = QUERY + "    space_trap: {signal: banana, order: 0, eps: [1.0], window_s: 1}\n"
    with pytest.raises(ProfileError) as caught:
        parse_profile(text, "bot.yaml")
    assert caught.value.path == "commands.GPS_FIX?.space_trap.signal"
    message = str(caught.value)
    assert message.startswith("bot.yaml:11:")
    assert "unknown space-trap signal 'banana'" in message
    assert "known signals: " + ", ".join(SPACE_TRAP_SIGNALS) in message
    with pytest.raises(ProfileError, match="did you mean 'depth'"):
        parse_profile(text.replace("banana", "depht"), "bot.yaml")


def test_every_bundled_space_trap_signal_is_a_known_one() -> None:
    for command in load_bundled_profile("ROMEO").commands:
        if command.space_trap is not None:
            assert command.space_trap.signal in SPACE_TRAP_SIGNALS


@pytest.mark.parametrize(
    ("file", "vehicle", "untracked_query"),
    [
        ("minnow.yaml", "MINNOW", "GPS_FIX?"),
        ("glider.yaml", "GLIDER", "SURFACE_COMMS?"),
        ("usv.yaml", "USV", "GPS_FIX?"),
    ],
)
def test_example_vehicle_profiles_load(file: str, vehicle: str, untracked_query: str) -> None:
    profile = load_profile(EXAMPLES / "profiles" / file)
    assert profile.name == vehicle
    query = profile.command(untracked_query)
    assert query is not None and query.kind == "query" and query.space_trap is None
    assert {"timeout", "error"} <= set(query.replies)
    for command in profile.commands:
        if command.kind == "query":
            assert command.param("time_out") is not None, command.name


THREE_MISTAKES = """\
vehicle: BOT
resources: [depth]
commands:
  DEPTH:
    kind: taks
    replies: [ack, error]
  DEPTH?:
    kind: query
    params:
      - {name: z, type: float, unit: m}
      - {name: time_out, type: float, unit: furlong}
    replies: [done, timeout]
  DIVE:
    kind: task
    replies: [ack]
    duration_s: -1
"""


def test_every_mistake_of_a_profile_is_reported_each_at_its_field() -> None:
    with pytest.raises(ProfileError) as caught:
        parse_profile(THREE_MISTAKES, "bot.yaml")
    error = caught.value
    assert str(error).splitlines() == [
        "bot.yaml:5:11: commands.DEPTH.kind: kind must be one of task, query, action, not 'taks'",
        "bot.yaml:11:45: commands.DEPTH?.params[1].unit: unknown unit 'furlong'",
        "bot.yaml:16:17: commands.DIVE.duration_s: duration must be >= 0 seconds",
    ]
    assert [e.path for e in error.errors] == [
        "commands.DEPTH.kind",
        "commands.DEPTH?.params[1].unit",
        "commands.DIVE.duration_s",
    ]
    assert (error.path, error.detail) == (error.errors[0].path, error.errors[0].detail)


def test_a_mistake_that_others_depend_on_is_reported_once() -> None:
    # An unknown kind: whether the command is a query (and needs a time_out) is unknown,
    # so only the kind is reported; a second unknown field in the same mapping is not lost.
    text = THREE_MISTAKES.replace("kind: query", "kind: qeury").replace(
        "replies: [ack]\n", "replies: [ack]\n    duraton_s: 1\n"
    )
    with pytest.raises(ProfileError) as caught:
        parse_profile(text.replace("unit: furlong", "unit: s"), "bot.yaml")
    assert [e.path for e in caught.value.errors] == [
        "commands.DEPTH.kind",
        "commands.DEPTH?.kind",
        "commands.DIVE.duraton_s",
        "commands.DIVE.duration_s",
    ]


def test_a_profile_with_hundreds_of_mistakes_lists_the_first_ones_and_counts_the_rest() -> None:
    commands = "".join(f"  C{i}: {{kind: bad, replies: [ack]}}\n" for i in range(300))
    with pytest.raises(ProfileError) as caught:
        parse_profile("vehicle: BOT\ncommands:\n" + commands, "bot.yaml")
    assert len(caught.value.errors) == 300
    lines = str(caught.value).splitlines()
    assert len(lines) == MAX_PROFILE_ERRORS_SHOWN + 1
    assert lines[0].startswith("bot.yaml:3:") and lines[-1] == "... and 250 more errors"
