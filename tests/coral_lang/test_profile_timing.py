"""Profile timing: the ``timing`` block, per-command ``work_s``, and what a certificate
records of them (nothing, when a profile declares neither)."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from coral_lang.diagnostics import ProfileError
from coral_lang.mission import load_mission
from coral_lang.profile import load_profile, parse_profile
from coral_lang.timing import DEFAULT_REPLY_LATENCY_S, DEFAULT_TOLERANCE, ProfileTiming
from tests.conftest import EXAMPLES

POOL_PROFILE_DIGEST = "sha256:f1d448df8a619993de1949a22b4aaa0208afb327481173c1f94ff2ff9f8f1607"
"""The pool mission's profile digest computed before timing existed (it is also the one
its certificate records): adding the new fields must not change it."""

BOT = """\
vehicle: BOT
resources: [depth]
commands:
  DIVE:
    kind: task
    replies: [ack, error]
    resources: [depth]
    duration_s: 10
  DEPTH?:
    kind: query
    params: [{name: time_out, type: float, unit: s}]
    replies: [done, timeout, error]
    resources: [depth]
    duration_s: 20
"""


def _with(text: str, command: str, line: str) -> str:
    """``BOT`` with ``line`` added (indented) to ``command``'s mapping."""
    anchor = f"  {command}:\n"
    assert anchor in text
    return text.replace(anchor, f"{anchor}    {line}\n")


def _errors(text: str) -> list[str]:
    with pytest.raises(ProfileError) as caught:
        parse_profile(text, "bot.yaml")
    return [error.line() for error in caught.value.errors]


def test_a_profile_without_timing_gets_the_defaults() -> None:
    profile = parse_profile(BOT, "bot.yaml")
    assert profile.timing == ProfileTiming(DEFAULT_TOLERANCE, DEFAULT_REPLY_LATENCY_S)
    assert profile.canonical_timing() is None
    dive = profile.command("DIVE")
    assert dive is not None and dive.work_s == ()
    assert "work_s" not in dive.canonical()


def test_the_timing_block_is_read() -> None:
    text = BOT + "timing:\n  tolerance: 0.05\n  reply_latency_s: 0.5\n"
    profile = parse_profile(text, "bot.yaml")
    assert profile.timing == ProfileTiming(tolerance=0.05, reply_latency_s=0.5)
    assert profile.canonical_timing() == {"tolerance": 0.05, "reply_latency_s": 0.5}


def test_a_partial_timing_block_keeps_the_other_default() -> None:
    profile = parse_profile(BOT + "timing: {tolerance: 0}\n", "bot.yaml")
    assert profile.timing == ProfileTiming(tolerance=0.0, reply_latency_s=DEFAULT_REPLY_LATENCY_S)
    spelt_out = parse_profile(BOT + "timing: {tolerance: 0.2, reply_latency_s: 0.1}\n", "b.yaml")
    assert spelt_out.canonical_timing() is None  # the defaults, written out, mean the same


def test_work_times_are_read_in_file_order() -> None:
    text = _with(BOT, "DIVE", "work_s: {error: [0, 0.5], ack: [8, 12.5]}")
    text = _with(text, "DEPTH?", "work_s: {done: [15, 40]}")
    profile = parse_profile(text, "bot.yaml")
    dive, depth = profile.command("DIVE"), profile.command("DEPTH?")
    assert dive is not None and depth is not None
    assert dive.work_s == (("error", 0.0, 0.5), ("ack", 8.0, 12.5))
    assert depth.work_s == (("done", 15.0, 40.0),)
    assert dive.canonical()["work_s"] == {"error": [0.0, 0.5], "ack": [8.0, 12.5]}


def test_work_interval_uses_the_declared_interval_else_spreads_the_duration() -> None:
    text = _with(BOT, "DIVE", "work_s: {ack: [8, 12.5]}") + "timing: {tolerance: 0.1}\n"
    profile = parse_profile(text, "bot.yaml")
    dive = profile.command("DIVE")
    assert dive is not None
    tolerance = profile.timing.tolerance
    assert dive.work_interval("ack", tolerance) == (8.0, 12.5)
    assert dive.work_interval("error", tolerance) == pytest.approx((9.0, 11.0))
    default = parse_profile(BOT, "bot.yaml").command("DIVE")
    assert default is not None
    assert default.work_interval("ack", DEFAULT_TOLERANCE) == pytest.approx((8.0, 12.0))


@given(
    low=st.floats(0, 1e6, allow_nan=False),
    span=st.floats(0, 1e6, allow_nan=False),
)
def test_any_valid_work_interval_reads_back_exactly(low: float, span: float) -> None:
    high = low + span
    text = _with(BOT, "DIVE", f"work_s: {{ack: [{low!r}, {high!r}]}}")
    dive = parse_profile(text, "bot.yaml").command("DIVE")
    assert dive is not None
    assert dive.work_interval("ack", 0.5) == (low, high)


def test_a_non_query_may_declare_its_timeout_reply() -> None:
    text = BOT.replace("replies: [ack, error]", "replies: [ack, timeout]")
    text = _with(text, "DIVE", "work_s: {timeout: [60, 60]}")
    dive = parse_profile(text, "bot.yaml").command("DIVE")
    assert dive is not None and dive.work_s == (("timeout", 60.0, 60.0),)


BAD_TIMING = [
    (
        "timing: {tolerance: 1}\n",
        "bot.yaml:15:21: timing.tolerance: tolerance must be at least 0 and below 1",
    ),
    ("timing: {tolerance: -0.1}\n", "bot.yaml:15:21: timing.tolerance: tolerance must be"),
    ("timing: {tolerance: high}\n", "bot.yaml:15:21: timing.tolerance: expected a number"),
    ("timing: {tolerance: .nan}\n", "bot.yaml:15:21: timing.tolerance: expected a finite number"),
    (
        "timing: {reply_latency_s: -1}\n",
        "bot.yaml:15:27: timing.reply_latency_s: reply latency must be >= 0 seconds",
    ),
    (
        "timing: {reply_latency_s: .inf}\n",
        "bot.yaml:15:27: timing.reply_latency_s: expected a finite number",
    ),
    (
        "timing: {tolerence: 0.1}\n",
        "bot.yaml:15:21: timing.tolerence: unknown field 'tolerence' (did you mean 'tolerance'?)",
    ),
    ("timing: 0.2\n", "bot.yaml:15:9: timing: expected a mapping"),
    ("timeing: {}\n", "bot.yaml:15:10: timeing: unknown field 'timeing' (did you mean 'timing'?)"),
]


@pytest.mark.parametrize(("block", "expected"), BAD_TIMING)
def test_a_bad_timing_block_names_file_line_column_and_field(block: str, expected: str) -> None:
    lines = _errors(BOT + block)
    assert len(lines) == 1 and lines[0].startswith(expected), lines


BAD_WORK = [
    (
        "DIVE",
        "work_s: {ak: [1, 2]}",
        "bot.yaml:5:18: commands.DIVE.work_s.ak: 'ak' is not a reply of this command "
        "(did you mean 'ack'?); its replies: ack, error",
    ),
    (
        "DIVE",
        "work_s: {ack: [3, 1]}",
        "bot.yaml:5:19: commands.DIVE.work_s.ack: min 3 s is greater than max 1 s",
    ),
    (
        "DIVE",
        "work_s: {ack: [-1, 1]}",
        "bot.yaml:5:20: commands.DIVE.work_s.ack[0]: work time must be >= 0 seconds",
    ),
    (
        "DIVE",
        "work_s: {ack: [1, .inf]}",
        "bot.yaml:5:23: commands.DIVE.work_s.ack[1]: expected a finite number",
    ),
    (
        "DIVE",
        "work_s: {ack: [1, soon]}",
        "bot.yaml:5:23: commands.DIVE.work_s.ack[1]: expected a number, got text ('soon')",
    ),
    (
        "DIVE",
        "work_s: {ack: [1]}",
        "bot.yaml:5:19: commands.DIVE.work_s.ack: expected [min, max] in seconds, got 1 values",
    ),
    (
        "DIVE",
        "work_s: {ack: 5}",
        "bot.yaml:5:19: commands.DIVE.work_s.ack: expected a list, got a number (5)",
    ),
    ("DIVE", "work_s: [1, 2]", "bot.yaml:5:13: commands.DIVE.work_s: expected a mapping"),
    (
        "DIVE",
        "wrok_s: {ack: [1, 2]}",
        "bot.yaml:5:13: commands.DIVE.wrok_s: unknown field 'wrok_s' (did you mean 'work_s'?)",
    ),
    (
        "DEPTH?",
        "work_s: {timeout: [1, 2]}",
        "bot.yaml:10:23: commands.DEPTH?.work_s.timeout: a query's 'timeout' takes the "
        "time-out the mission gives it",
    ),
]


@pytest.mark.parametrize(("command", "line", "expected"), BAD_WORK)
def test_a_bad_work_time_names_file_line_column_and_field(
    command: str, line: str, expected: str
) -> None:
    lines = _errors(_with(BOT, command, line))
    assert len(lines) == 1 and lines[0].startswith(expected), lines


def test_every_timing_mistake_is_reported_at_once_with_the_others() -> None:
    text = _with(BOT, "DIVE", "work_s: {ack: [2, 1], eror: [0, 1]}")
    text = _with(text, "DEPTH?", "work_s: {done: [1, 2], timeout: [1, 2]}")
    text = text.replace("duration_s: 10", "duration_s: -1")
    lines = _errors(text + "timing: {tolerance: 2, reply_latency_s: -1}\n")
    assert [line.split(": ")[1] for line in lines] == [
        "commands.DIVE.duration_s",
        "commands.DIVE.work_s.ack",
        "commands.DIVE.work_s.eror",
        "commands.DEPTH?.work_s.timeout",
        "timing.tolerance",
        "timing.reply_latency_s",
    ]


def test_a_malformed_reply_list_does_not_make_every_work_kind_an_error() -> None:
    text = _with(
        BOT.replace("replies: [ack, error]", "replies: ack"), "DIVE", "work_s: {x: [1, 2]}"
    )
    lines = _errors(text)
    assert [line.split(": ")[1] for line in lines] == ["commands.DIVE.replies"]


def test_the_pool_missions_profile_digest_is_unchanged() -> None:
    mission = load_mission(EXAMPLES / "pool_mission" / "pool_mission.coral")
    assert mission.profile_digest() == POOL_PROFILE_DIGEST
    with_own_file = load_mission(
        EXAMPLES / "pool_mission" / "pool_mission.coral",
        [load_profile(EXAMPLES / "pool_mission" / "romeo.yaml")],
    )
    assert with_own_file.profile_digest() == POOL_PROFILE_DIGEST


def test_declaring_work_times_changes_the_commands_canonical_form() -> None:
    plain = parse_profile(BOT, "bot.yaml").command("DIVE")
    timed = parse_profile(_with(BOT, "DIVE", "work_s: {ack: [8, 12]}"), "bot.yaml").command("DIVE")
    assert plain is not None and timed is not None
    assert timed.canonical() == plain.canonical() | {"work_s": {"ack": [8.0, 12.0]}}
