"""Lint rules: each documented example fires its rule; suppressions need a reason."""

from __future__ import annotations

import re
from typing import Any

import pytest

from analysis import statespace
from analysis.cli import main
from analysis.lint import RULES, LintOptions, lint
from analysis.verify import VerifyOptions, run_verification
from coral_lang import compile_file, compile_source, parse_profile
from tests.conftest import EXAMPLES, REPO

RULES_DOC = (REPO / "docs" / "rules.md").read_text()
SECTIONS = re.findall(r"^## (CORAL\d{3}):.*?\n```coral\n(.*?)```", RULES_DOC, re.S | re.M)

# A renamed place is both waited on and left behind; an unexplained suppression does
# not suppress.
EXPECTED = {"CORAL204": {"CORAL204", "CORAL205"}, "CORAL208": {"CORAL207", "CORAL208"}}


def _codes(text: str, **options: float) -> list[str]:
    result = compile_source(text, "doc.coral")
    assert result.errors == [], [d.render() for d in result.errors]
    return [d.code for d in lint(result, LintOptions(**options))]  # type: ignore[arg-type]


def test_every_rule_is_documented_with_an_example() -> None:
    assert sorted(code for code, _ in SECTIONS) == sorted(RULES)


@pytest.mark.parametrize(("code", "example"), SECTIONS, ids=[c for c, _ in SECTIONS])
def test_each_documented_example_fires_exactly_its_rule(code: str, example: str) -> None:
    assert set(_codes(example)) == EXPECTED.get(code, {code})


def test_the_pool_mission_and_clean_examples_lint_clean() -> None:
    for path in (
        EXAMPLES / "pool_mission" / "pool_mission.coral",
        EXAMPLES / "faulty" / "deadlock.coral",
    ):
        assert lint(compile_file(path)) == []


HEADER = "mission m\nvehicle ROMEO\n"
RACE = (
    HEADER + "place s = 1, a, b\nfinal { a }\nfinal { b }\ntransition ta wait { s } signal { a }\n"
)


def test_suppression_with_reason_silences_one_rule_on_one_line() -> None:
    plain = RACE + "transition tb wait { s } signal { b }\n"
    assert _codes(plain) == ["CORAL207"]
    same_line = (
        RACE + "transition tb wait { s } signal { b }  # coral: allow CORAL207 -- either is fine\n"
    )
    assert _codes(same_line) == []
    line_above = (
        RACE + "# coral: allow CORAL207 -- either is fine\ntransition tb wait { s } signal { b }\n"
    )
    assert _codes(line_above) == []
    other_rule = (
        RACE + "transition tb wait { s } signal { b }  # coral: allow CORAL205 -- wrong rule\n"
    )
    assert _codes(other_rule) == ["CORAL207"]


def test_a_suppression_after_code_covers_its_own_line_only() -> None:
    # after code on the line above: it is about that line (ta), not the next
    after_code = (
        HEADER + "place s = 1, a, b\nfinal { a }\nfinal { b }\n"
        "transition ta wait { s } signal { a }  # coral: allow CORAL207 -- either is fine\n"
        "transition tb wait { s } signal { b }\n"
    )
    assert _codes(after_code) == ["CORAL207"]
    # alone on its line, with a blank line before the statement: it reaches nothing
    apart = (
        RACE
        + "# coral: allow CORAL207 -- either is fine\n\ntransition tb wait { s } signal { b }\n"
    )
    assert _codes(apart) == ["CORAL207"]


def test_bad_suppressions_are_reported() -> None:
    unknown = RACE + "transition tb wait { s } signal { b }  # coral: allow CORAL999 -- typo\n"
    assert sorted(_codes(unknown)) == ["CORAL207", "CORAL208"]


@pytest.mark.parametrize("odd", ["\f", "\v", "\x1c", "\x85", "\u2028", "\u2029"])
def test_a_line_break_only_str_splitlines_sees_does_not_shift_suppressions(odd: str) -> None:
    # the lexer (and so every finding) counts lines on "\n" only
    text = (
        RACE
        + f"# about the race{odd} more words\n"
        + ("# coral: allow CORAL207 -- either is fine\ntransition tb wait { s } signal { b }\n")
    )
    assert _codes(text) == []


def test_an_allow_inside_a_string_is_no_suppression() -> None:
    text = RACE + (
        'const NOTE = "# coral: allow CORAL207 -- not a comment"  # coral: allow CORAL202 -- doc\n'
        'transition tb wait { s } signal { b } const TEXT = "# coral: allow CORAL207 -- no"\n'
    )
    assert sorted(_codes(text)) == ["CORAL202", "CORAL207"]  # TEXT's; tb's race


def test_a_suppression_after_another_comment_alone_on_its_line_covers_the_next() -> None:
    text = RACE + (
        "# note # coral: allow CORAL207 -- either is fine\ntransition tb wait { s } signal { b }\n"
    )
    assert _codes(text) == []
    [finding] = lint(compile_source(RACE + "# note # coral: allow CORAL207\n", "m.coral"))
    assert finding.code == "CORAL208" and finding.span is not None
    assert (finding.span.line, finding.span.col) == (7, 8)


def test_priority_settles_a_race_and_exclusive_joins_are_not_races() -> None:
    prioritised = RACE + "transition tb priority 1 wait { s } signal { b }\n"
    assert _codes(prioritised) == []
    join = HEADER + (
        "place s = 1, ok, bad, x = 1, done, failed\nfinal { done }\nfinal { failed }\n"
        "transition pick wait { s } action { ROMEO(FIX_XY) -> { done: ok, error: bad } }\n"
        "transition good wait { ok, x } signal { done }\n"
        "transition poor wait { bad, x } signal { failed }\n"
    )
    assert _codes(join) == []  # 'good' and 'poor' share x but are never enabled together


def test_time_out_rule_uses_the_link_rtt_and_the_profiles_duration() -> None:
    text = HEADER + (
        "place s = 1, going, there, abort\nfinal { there }\nfinal { abort }\n"
        "transition go wait { s } action { ROMEO(DEPTH, z = 2.0) -> { ack: going, error: abort } }\n"
        "transition check wait { going } action { ROMEO(DEPTH?, z = 2.0, time_out = 50) -> { done: there, timeout: abort } }\n"
    )
    assert _codes(text) == []  # 50 s >= 14 s round trip + 30 s nominal duration
    assert _codes(text, link_rtt_s=30.0) == ["CORAL206"]


def test_time_out_rule_reads_a_custom_profile() -> None:
    profile = parse_profile(
        "vehicle: BOT\nresources: [depth]\ncommands:\n"
        "  DIVE?:\n    kind: query\n    params: [{name: time_out, type: float, unit: s}]\n"
        "    replies: [done, timeout]\n    duration_s: 100\n"
        "    space_trap: {signal: depth, order: 0, eps: [0.1], window_s: 1}\n",
        "bot.yaml",
    )
    text = (
        "mission m\nvehicle BOT\nplace s = 1, a, b\nfinal { a }\nfinal { b }\n"
        "transition t wait { s } action { BOT(DIVE?, 60) -> { done: a, timeout: b } }\n"
    )
    result = compile_source(text, "m.coral", profiles=[profile])
    assert [d.code for d in lint(result)] == ["CORAL206"]


def test_cli_prints_warnings_and_keeps_exit_0(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["lint", str(EXAMPLES / "faulty" / "dead_transition.coral")]) == 0
    out = capsys.readouterr().out
    assert "[CORAL204]" in out and "2 warnings" in out


SHARED = [
    *(text for _, text in SECTIONS),
    (EXAMPLES / "pool_mission" / "pool_mission.coral").read_text(),
    *(p.read_text() for p in sorted((EXAMPLES / "faulty").glob("*.coral"))),
]


@pytest.mark.slow
@pytest.mark.parametrize("text", SHARED, ids=[f"mission{i}" for i in range(len(SHARED))])
def test_a_shared_state_space_gives_the_same_findings(text: str) -> None:
    """coral-check hands lint the verifier's state space: the findings must not change."""
    result = compile_source(text, "doc.coral", base_dir=EXAMPLES / "pool_mission")
    if result.net is None:
        return  # the faulty mission that does not compile
    alone = lint(result)
    space = run_verification(result.net, VerifyOptions(structural=False)).space
    assert lint(result, space=space) == alone


def test_a_complete_shared_space_is_not_explored_again(monkeypatch: pytest.MonkeyPatch) -> None:
    text = dict(SECTIONS)["CORAL207"]
    result = compile_source(text, "doc.coral")
    assert result.net is not None
    space = run_verification(result.net, VerifyOptions(structural=False)).space
    assert space is not None and space.complete

    def no_search(*args: object, **kwargs: object) -> None:
        raise AssertionError("explored again")

    monkeypatch.setattr("analysis.lint.explore", no_search)
    assert [d.code for d in lint(result, space=space)] == ["CORAL207"]


def test_a_reduced_or_smaller_space_is_not_trusted(monkeypatch: pytest.MonkeyPatch) -> None:
    text = dict(SECTIONS)["CORAL207"]
    result = compile_source(text, "doc.coral")
    assert result.net is not None
    reduced = run_verification(result.net, VerifyOptions(structural=False, por=True)).space
    cut = run_verification(result.net, VerifyOptions(structural=False, max_states=1)).space
    assert reduced is not None and reduced.reduced and cut is not None and not cut.complete
    searches = []
    original = statespace.explore

    def counted(*args: Any, **kwargs: Any) -> Any:
        searches.append(1)
        return original(*args, **kwargs)

    monkeypatch.setattr("analysis.lint.explore", counted)
    for space in (reduced, cut):
        assert [d.code for d in lint(result, space=space)] == ["CORAL207"]
    assert len(searches) == 2


def test_pnml_imports_are_not_linted() -> None:
    from coral_lang import load_net_file
    from tests.conftest import CONFORMANCE

    result = load_net_file(CONFORMANCE / "pnml" / "Philosophers-PT-000005.pnml")
    assert result.net is not None and lint(result) == []
