"""Fault plans: every rule form, every error with its location, and what a plan forces."""

from __future__ import annotations

import random
from collections import Counter
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from coral_lang.profile import (
    CommandSpec,
    VehicleProfile,
    load_bundled_profile,
    load_profile,
    parse_profile,
)
from runtime.faultplan import (
    FaultPlan,
    FaultPlanError,
    FaultRule,
    load_fault_plan,
    parse_fault_plan,
    parse_fault_rule,
    parse_fault_rules,
)
from tests.conftest import EXAMPLES

ROMEO = load_bundled_profile("ROMEO")
POOL_ROMEO = load_profile(EXAMPLES / "pool_mission" / "romeo.yaml")
MINNOW = load_profile(EXAMPLES / "profiles" / "minnow.yaml")

SINGLE = parse_profile(
    """
vehicle: PING
commands:
  PING:
    kind: action
    replies: [done]
    duration_s: 1.0
  WAIT?:
    kind: query
    params:
      - {name: time_out, type: float, unit: s}
    replies: [done, timeout]
""",
    "ping.yaml",
)


def spec(profile: VehicleProfile, name: str) -> CommandSpec:
    found = profile.command(name)
    assert found is not None
    return found


class Fixed(random.Random):
    """A generator whose ``random()`` always returns ``value`` (choice still works)."""

    def __init__(self, value: float) -> None:
        super().__init__(0)
        self.value = value

    def random(self) -> float:
        return self.value


# --------------------------------------------------------------------------- parsing


@pytest.mark.parametrize(
    ("text", "rule"),
    [
        ("DEPTH?=timeout", FaultRule("DEPTH?", None, "timeout")),
        ("GOTO#2=error", FaultRule("GOTO", 2, "error")),
        ("DIVE=error@0.1", FaultRule("DIVE", None, "error", 0.1)),
        ("*=any@0.05", FaultRule("*", None, "any", 0.05)),
        ("*#1=timeout", FaultRule("*", 1, "timeout")),
        ("GOTO#12=any@1", FaultRule("GOTO", 12, "any")),
        ("  DEPTH? = timeout @ .5 ", FaultRule("DEPTH?", None, "timeout", 0.5)),
        ("FIX_XY=error@1e-2", FaultRule("FIX_XY", None, "error", 0.01)),
    ],
)
def test_every_rule_form_parses(text: str, rule: FaultRule) -> None:
    parsed = parse_fault_rule(text)
    assert parsed == rule
    assert parsed.text == text.strip()
    assert parsed.source == f"--fault '{text}'"


def test_a_rule_prints_in_canonical_form_and_a_plan_round_trips() -> None:
    plan = parse_fault_rules(["GOTO#2=error", " DIVE = error @ 0.25", "*=any@1.0"])
    assert [str(rule) for rule in plan.rules] == ["GOTO#2=error", "DIVE=error@0.25", "*=any"]
    assert str(plan) == "GOTO#2=error DIVE=error@0.25 *=any"
    assert parse_fault_rules(str(plan).split()) == plan
    assert str(FaultPlan()) == "" and not FaultPlan() and len(plan) == 3


RULES = st.builds(
    FaultRule,
    command=st.sampled_from(["*", "DEPTH?", "GOTO", "FIX_XY", "x_1?"]),
    occurrence=st.none() | st.integers(1, 10**6),
    kind=st.sampled_from(["any", "ack", "timeout", "error", "done_late"]),
    rate=st.floats(min_value=0.0, max_value=1.0, exclude_min=True),
)


@settings(max_examples=200)
@given(RULES)
def test_parsing_a_rule_s_canonical_text_gives_the_rule_back(rule: FaultRule) -> None:
    assert parse_fault_rule(str(rule)) == rule


def test_a_plan_file_skips_blank_lines_and_comments(tmp_path: Path) -> None:
    path = tmp_path / "faults.txt"
    path.write_text(
        "# rehearse the recoveries\n"
        "\n"
        "DEPTH?=timeout   # every depth check times out\n"
        "   GOTO#2=error\n"
        "*=any@0.05\t# the '#' of GOTO#2 above is no comment: no blank before it\n",
        encoding="utf-8",
    )
    plan = load_fault_plan(path)
    assert plan == FaultPlan(
        (
            FaultRule("DEPTH?", None, "timeout"),
            FaultRule("GOTO", 2, "error"),
            FaultRule("*", None, "any", 0.05),
        )
    )
    assert [rule.source for rule in plan.rules] == [
        f"{path}:3:1",
        f"{path}:4:4",
        f"{path}:5:1",
    ]
    assert plan.rules[0].text == "DEPTH?=timeout"
    assert load_fault_plan(_write(tmp_path, "# nothing\n\n")) == FaultPlan()


def _write(folder: Path, text: str) -> Path:
    path = folder / "plan.txt"
    path.write_text(text, encoding="utf-8")
    return path


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", "empty fault rule"),
        ("DEPTH?", "found no '=' in 'DEPTH?'"),
        ("=timeout", "missing command before '='"),
        ("GO TO=error", "bad command name 'GO TO'"),
        ("DEPTH??=done", "bad command name 'DEPTH??'"),
        ("#2=error", "missing command before '='"),
        ("GOTO#0=error", "positive whole number (1 for the first use), got '0'"),
        ("GOTO#-1=error", "got '-1'"),
        ("GOTO#two=error", "got 'two'"),
        ("GOTO#=error", "got ''"),
        ("GOTO=", "missing reply kind after '='"),
        ("GOTO=@0.5", "missing reply kind after '='"),
        ("GOTO=error=ack", "bad reply kind 'error=ack'"),
        ("GOTO=error@0", "probability in (0, 1], got '0'"),
        ("GOTO=error@1.5", "got '1.5'"),
        ("GOTO=error@-0.1", "got '-0.1'"),
        ("GOTO=error@nan", "got 'nan'"),
        ("GOTO=error@5%", "got '5%'"),
        ("GOTO=error@", "got ''"),
    ],
)
def test_a_bad_command_line_rule_is_named_with_the_problem(text: str, message: str) -> None:
    with pytest.raises(FaultPlanError) as exc:
        parse_fault_rules(["DEPTH?=timeout", text])
    assert str(exc.value).startswith(f"--fault '{text}': ")
    assert message in str(exc.value)


@pytest.mark.parametrize(
    ("line", "column", "message"),
    [
        ("DEPTH?", 1, "found no '='"),
        ("  GO TO=error", 3, "bad command name"),
        ("GOTO#0=error", 6, "positive whole number"),
        ("GOTO = ", 8, "missing reply kind"),  # where the kind should be
        ("GOTO = err-or", 8, "bad reply kind 'err-or'"),
        ("   GOTO=error @ 2  # too likely", 17, "probability in (0, 1], got '2'"),
    ],
)
def test_a_bad_line_in_a_plan_file_is_named_by_file_line_and_column(
    tmp_path: Path, line: str, column: int, message: str
) -> None:
    path = _write(tmp_path, f"# plan\nDEPTH?=timeout\n{line}\n")
    with pytest.raises(FaultPlanError) as exc:
        load_fault_plan(path)
    rule = line.split(" #")[0].strip()
    assert str(exc.value).startswith(f"{path}:3:{column}: fault rule '{rule}': ")
    assert message in str(exc.value)


def test_an_unreadable_plan_file_is_named(tmp_path: Path) -> None:
    with pytest.raises(FaultPlanError, match=r"missing\.txt: cannot read fault plan"):
        load_fault_plan(tmp_path / "missing.txt")
    binary = tmp_path / "binary.txt"
    binary.write_bytes(b"\xff\xfe\x00")
    with pytest.raises(FaultPlanError, match=r"binary\.txt: cannot read fault plan"):
        load_fault_plan(binary)


def test_rules_built_in_code_are_validated() -> None:
    with pytest.raises(ValueError, match="rate"):
        FaultRule("GOTO", None, "error", 0.0)
    with pytest.raises(ValueError, match="occurrence"):
        FaultRule("GOTO", 0, "error")
    assert FaultRule("GOTO", 2, "error").text == "GOTO#2=error"


# --------------------------------------------------------------------------- what it forces


def test_the_first_matching_rule_decides() -> None:
    plan = parse_fault_rules(["DEPTH?=timeout", "DEPTH?=done", "*=any"])
    depth_query = spec(ROMEO, "DEPTH?")
    forced = plan.forced_reply(depth_query, 1, random.Random(0))
    assert forced is not None and forced[0] == "timeout" and forced[1] is plan.rules[0]
    # Even when the deciding rule's draw says no, later rules are not asked.
    plan = parse_fault_rules(["DEPTH?=timeout@0.5", "*=timeout"])
    assert plan.forced_reply(depth_query, 1, Fixed(0.75)) is None
    forced = plan.forced_reply(depth_query, 1, Fixed(0.25))
    assert forced is not None and forced[1] is plan.rules[0]
    # A rule for another command, or another use, does not match and does not decide.
    plan = parse_fault_rules(["GOTO=error", "DEPTH?#2=done", "*=timeout"])
    forced = plan.forced_reply(depth_query, 1, Fixed(0.0))
    assert forced is not None and forced[1] is plan.rules[2]


def test_a_wildcard_rule_matches_only_commands_it_can_apply_to() -> None:
    plan = parse_fault_rules(["*=timeout", "*=any", "*=done"])
    depth = spec(ROMEO, "DEPTH")  # replies ack | error: no timeout
    forced = plan.forced_reply(depth, 1, random.Random(1))
    assert forced == ("error", plan.rules[1])
    ping = spec(SINGLE, "PING")  # a single reply kind: nothing for 'any' to draw
    assert plan.forced_reply(ping, 1, random.Random(1)) == ("done", plan.rules[2])


def test_an_occurrence_rule_forces_only_that_use() -> None:
    plan = parse_fault_rules(["GOTO#2=error"])
    goto = spec(ROMEO, "GOTO")
    decided = [plan.forced_reply(goto, use, random.Random(use)) for use in range(1, 6)]
    assert decided == [None, ("error", plan.rules[0]), None, None, None]
    assert parse_fault_rules(["*#3=error"]).forced_reply(spec(ROMEO, "LRM"), 3, Fixed(0.0))


def _decisions(plan: FaultPlan, command: CommandSpec, seed: int, uses: int) -> list[str | None]:
    rng = random.Random(seed)
    out: list[str | None] = []
    for use in range(1, uses + 1):
        forced = plan.forced_reply(command, use, rng)
        out.append(None if forced is None else forced[0])
    return out


def test_rate_draws_are_reproducible_per_seed_and_near_the_rate() -> None:
    plan = parse_fault_rules(["DIVE=error@0.1"])
    dive = spec(MINNOW, "DIVE")
    first = _decisions(plan, dive, 42, 2000)
    assert first == _decisions(plan, dive, 42, 2000)
    assert first != _decisions(plan, dive, 43, 2000)
    share = first.count("error") / len(first)
    assert 0.08 < share < 0.12, share
    assert set(first) == {None, "error"}


def test_a_plan_without_rates_or_any_never_draws() -> None:
    rng = random.Random(0)
    before = rng.getstate()
    plan = parse_fault_rules(["DEPTH?=timeout", "GOTO#2=error"])
    assert plan.forced_reply(spec(ROMEO, "DEPTH?"), 1, rng) is not None
    assert plan.forced_reply(spec(ROMEO, "GOTO"), 1, rng) is None
    assert plan.forced_reply(spec(ROMEO, "GOTO"), 2, rng) is not None
    assert rng.getstate() == before
    parse_fault_rules(["GOTO=any"]).forced_reply(spec(ROMEO, "GOTO"), 1, rng)
    assert rng.getstate() != before


@settings(max_examples=100)
@given(
    seed=st.integers(0, 2**32),
    name=st.sampled_from(MINNOW.command_names + ROMEO.command_names),
    use=st.integers(1, 50),
)
def test_any_never_forces_the_expected_reply(seed: int, name: str, use: int) -> None:
    command = MINNOW.command(name) or ROMEO.command(name)
    assert command is not None
    forced = parse_fault_rules(["*=any"]).forced_reply(command, use, random.Random(seed))
    assert forced is not None
    assert forced[0] in command.replies[1:]


def test_any_draws_every_unexpected_kind() -> None:
    line_end = spec(MINNOW, "LINE_END?")  # done | timeout | error
    plan = parse_fault_rules(["LINE_END?=any"])
    rng = random.Random(5)
    drawn = Counter(plan.forced_reply(line_end, use, rng) for use in range(1, 400))
    assert {forced[0] for forced in drawn if forced is not None} == {"timeout", "error"}
    assert None not in drawn


def test_plans_merge_in_order() -> None:
    cli = parse_fault_rules(["DEPTH?=done"])
    file = parse_fault_plan("DEPTH?=timeout\nGOTO=error\n", "plan.txt")
    both = cli + file
    assert both == cli.merged(file)
    assert [str(r) for r in both.rules] == ["DEPTH?=done", "DEPTH?=timeout", "GOTO=error"]
    assert both.forced_reply(spec(ROMEO, "DEPTH?"), 1, Fixed(0.0)) == ("done", cli.rules[0])


# --------------------------------------------------------------------------- against a profile


@pytest.mark.parametrize("profile", [ROMEO, POOL_ROMEO], ids=["bundled", "pool_mission"])
def test_sensible_plans_fit_romeo(profile: VehicleProfile) -> None:
    parse_fault_rules(
        ["DEPTH?=timeout", "GOTO#2=error", "FIX_XY=error@0.5", "INIT=any", "*=timeout", "*=any"]
    ).check(profile)


def test_sensible_plans_fit_minnow() -> None:
    parse_fault_rules(["DIVE=error@0.1", "LINE_END?=error", "GPS_FIX?#1=any", "*=any@0.05"]).check(
        MINNOW
    )


@pytest.mark.parametrize(
    ("profile", "text", "message"),
    [
        (
            ROMEO,
            "DPETH?=timeout",
            "unknown command 'DPETH?' (did you mean 'DEPTH?'?); ROMEO has: INIT, DEPTH,",
        ),
        (MINNOW, "DEPTH=error", "unknown command 'DEPTH' (did you mean 'DEPTH?'?); MINNOW has:"),
        (MINNOW, "GOTO=error", "unknown command 'GOTO'; MINNOW has: INIT, GPS_FIX?, DIVE"),
        (ROMEO, "DEPTH=timeout", "DEPTH cannot reply 'timeout'; its replies: ack, error"),
        (MINNOW, "DEPTH?=errro", "DEPTH? cannot reply 'errro'; its replies: done, timeout"),
        (
            MINNOW,
            "LINE_END?=errro",
            "cannot reply 'errro' (did you mean 'error'?); its replies: done, timeout, error",
        ),
        (SINGLE, "PING=any", "'any' needs a command with an unexpected reply kind, but PING"),
        (ROMEO, "*=erorr", "no command of ROMEO can reply 'erorr' (did you mean 'error'?)"),
        (SINGLE, "*=ack", "no command of PING can reply 'ack'; reply kinds: done, timeout"),
    ],
)
def test_a_rule_that_does_not_fit_the_profile_is_named_with_the_reason(
    profile: VehicleProfile, text: str, message: str
) -> None:
    with pytest.raises(FaultPlanError) as exc:
        parse_fault_rules(["*=any", text]).check(profile)
    assert str(exc.value).startswith(f"--fault '{text}': ")
    assert message in str(exc.value)


def test_any_everywhere_on_a_profile_of_single_replies_is_refused() -> None:
    only_ping = parse_profile(
        "vehicle: PING\ncommands:\n  PING: {kind: action, replies: [done]}\n", "p.yaml"
    )
    with pytest.raises(FaultPlanError, match="every command has a single reply kind"):
        parse_fault_rules(["*=any"]).check(only_ping)


def test_a_file_rule_that_does_not_fit_names_its_line(tmp_path: Path) -> None:
    path = _write(tmp_path, "DEPTH?=timeout\n\n  GOTO=timeout\n")
    plan = load_fault_plan(path)
    with pytest.raises(FaultPlanError) as exc:
        plan.check(ROMEO)
    assert str(exc.value).startswith(f"{path}:3:3: GOTO cannot reply 'timeout'")


def test_a_rule_built_in_code_is_named_by_its_text() -> None:
    with pytest.raises(FaultPlanError, match=r"^fault rule 'GOTO#2=timeout': GOTO cannot"):
        FaultPlan((FaultRule("GOTO", 2, "timeout"),)).check(ROMEO)
