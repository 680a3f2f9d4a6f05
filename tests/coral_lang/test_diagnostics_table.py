"""Bad snippets and the exact diagnostic each must produce.

This table documents the language's errors as much as it tests them: each row is a
mistake a mission author makes, and the message they must see.
"""

from __future__ import annotations

import pytest

from coral_lang.compiler import compile_source

HEADER = "mission m\nvehicle ROMEO\n"
PLACES = "place a = 1, b, c\n"
# Two transitions for the properties to name: 'go' sends a command, 'stop' does not.
TEMPORAL = (
    "place d\n"
    "transition go wait { a } action { ROMEO(DEPTH, z = 2.0) -> { ack: b, error: c } }\n"
    "transition stop wait { b } signal { d }\n"
)


def _first(text: str) -> str:
    result = compile_source(text, "m.coral")
    assert result.errors, "expected an error"
    first = result.errors[0]
    assert first.span is not None
    return f"{first.span.line}:{first.span.col}: {first.message} [{first.code}]"


TABLE: list[tuple[str, str]] = [
    # syntax
    (
        HEADER + "place a = 1\ntransition t wait { a } signal { b c }\n",
        "4:36: expected '}' to close the place set (places are separated by ','), found 'c' [CORAL001]",
    ),
    (HEADER + "place a @\n", "3:9: unexpected character '@' [CORAL001]"),
    (
        HEADER + "place wait\n",
        "3:7: expected a place name, found keyword 'wait' (keywords are reserved) [CORAL001]",
    ),
    (
        HEADER + PLACES + "transition t wiat { a }\n",
        "4:14: unknown clause 'wiat' (did you mean 'wait'?) [CORAL001]",
    ),
    (
        HEADER + PLACES + "transition t wait { a } signal { b }\n    priority 2\n",
        "5:5: 'priority' is not a clause: it goes on the transition's line, 'transition t priority N' [CORAL001]",
    ),
    (
        HEADER + PLACES + "wait { a }\n",
        "4:1: 'wait' must belong to a transition; start one with 'transition NAME' [CORAL001]",
    ),
    (HEADER + 'const S = "open\n', "3:11: unterminated string [CORAL001]"),
    (HEADER + "const Z = 2.0 meters\n", "3:15: unknown unit 'meters' [CORAL001]"),
    (
        HEADER + PLACES + "transition t\n",
        "4:1: transition 't' has no 'wait', 'action' or 'signal' clause [CORAL001]",
    ),
    (
        HEADER + PLACES + "transition t wait { a } wait { b }\n",
        "4:25: transition 't' has two 'wait' clauses; merge them [CORAL001]",
    ),
    (
        HEADER + "assert sometimes { a }\n",
        "3:8: expected 'never', 'reachable', 'bound', 'within', 'always', 'eventually', 'ltl', "
        "'ctl' or 'P leadsto Q' after 'assert', found 'sometimes' [CORAL001]",
    ),
    (
        HEADER + "place p\ntransition t wait { p } action { ROMEO(DEPTH, 2.0) }\n",
        "4:52: expected '->' after the command: map its replies with '-> { reply: place }', found '}' [CORAL001]",
    ),
    # names
    (
        HEADER + "place depth_ok = 1, done\ntransition t wait { dpeth_ok } signal { done }\n",
        "4:21: unknown place 'dpeth_ok' (did you mean 'depth_ok'?) [CORAL002]",
    ),
    (
        HEADER
        + PLACES
        + "transition t wait { a } action { ROMEO(DEPTH, z = Z_OPP) -> { ack: b, error: c } }\n"
        "const Z_OP = 2.0\n",
        "4:51: unknown constant 'Z_OPP' (did you mean 'Z_OP'?) [CORAL002]",
    ),
    (HEADER + "place a\nplace a\n", "4:7: place 'a' is declared twice [CORAL003]"),
    (
        HEADER
        + PLACES
        + "transition t wait { a } signal { b }\ntransition t wait { b } signal { c }\n",
        "5:1: transition 't' is declared twice [CORAL003]",
    ),
    (
        HEADER + PLACES + "transition a wait { b } signal { c }\n",
        "4:1: 'a' names both a place and a transition [CORAL003]",
    ),
    (
        HEADER + PLACES + "transition t wait { a, a } signal { b }\n",
        "4:24: place 'a' appears twice in 'wait'; write 'a*N' for N tokens [CORAL003]",
    ),
    (HEADER + "const K = 1\nconst K = 2\n", "4:1: constant 'K' is declared twice [CORAL003]"),
    # values
    (
        HEADER + "place a = 1.5\n",
        "3:11: initial tokens of 'a' must be a whole number, got 1.5 [CORAL005]",
    ),
    (
        HEADER + PLACES + "transition t wait { a*0 } signal { b }\n",
        "4:23: weight of 'a' must be at least 1, got 0 [CORAL005]",
    ),
    (
        HEADER + "place a = 3 capacity 2\n",
        "3:11: place 'a' starts with 3 tokens, more than its capacity 2 [CORAL005]",
    ),
    # header and profile
    ("vehicle ROMEO\nplace a\n", "1:1: a mission file starts with 'mission NAME' [CORAL007]"),
    ("mission m\nvehicle NAUTILUS\n", "2:1: no vehicle profile for 'NAUTILUS' [CORAL006]"),
    (
        HEADER
        + PLACES
        + "transition t wait { a } action { ROBOT(DEPTH, z = 2.0) -> { ack: b, error: c } }\n",
        "4:32: this mission commands vehicle 'ROMEO', not 'ROBOT' [CORAL006]",
    ),
    # commands against the profile
    (
        HEADER
        + PLACES
        + "transition t wait { a } action { ROMEO(DEPHT, z = 2.0) -> { ack: b, error: c } }\n",
        "4:40: unknown command 'DEPHT' for ROMEO (did you mean 'DEPTH'?) [CORAL101]",
    ),
    (
        HEADER
        + PLACES
        + "transition t wait { a } action { ROMEO(DEPTH, 2.0, 3.0) -> { ack: b, error: c } }\n",
        "4:52: DEPTH takes 1 parameter, got 2 [CORAL102]",
    ),
    (
        HEADER
        + PLACES
        + "transition t wait { a } action { ROMEO(DEPTH, depth = 2.0) -> { ack: b, error: c } }\n",
        "4:47: DEPTH has no parameter 'depth' [CORAL102]",
    ),
    (
        HEADER
        + PLACES
        + "transition t wait { a } action { ROMEO(DEPTH?, z = 2.0) -> { done: b, timeout: c } }\n",
        "4:40: DEPTH? is missing parameter 'time_out' [CORAL102]",
    ),
    (
        HEADER
        + PLACES
        + "transition t wait { a } action { ROMEO(DEPTH, z = 2.0, z = 3.0) -> { ack: b, error: c } }\n",
        "4:56: parameter 'z' given twice [CORAL102]",
    ),
    (
        HEADER
        + PLACES
        + "transition t wait { a } action { ROMEO(DEPTH, z = 2.0, 3.0) -> { ack: b, error: c } }\n",
        "4:56: positional argument after a named one [CORAL102]",
    ),
    (
        HEADER
        + PLACES
        + 'transition t wait { a } action { ROMEO(DEPTH, z = "deep") -> { ack: b, error: c } }\n',
        "4:51: parameter 'z' of DEPTH is a number (float), got text \"deep\" [CORAL103]",
    ),
    (
        HEADER
        + PLACES
        + "transition t wait { a } action { ROMEO(DEPTH, z = 90 deg) -> { ack: b, error: c } }\n",
        "4:51: parameter 'z' of DEPTH is in m (length), got 'deg' (angle) [CORAL104]",
    ),
    (
        HEADER
        + PLACES
        + "transition t wait { a } action { ROMEO(DEPTH, z = -1.0) -> { ack: b, error: c } }\n",
        "4:51: parameter 'z' of DEPTH must be in [0, 500] m, got -1 m [CORAL105]",
    ),
    (
        HEADER
        + PLACES
        + "transition t wait { a } action { ROMEO(DEPTH, z = 600 m) -> { ack: b, error: c } }\n",
        "4:51: parameter 'z' of DEPTH must be in [0, 500] m, got 600 m [CORAL105]",
    ),
    (
        HEADER + PLACES + "transition t wait { a } action { ROMEO(DEPTH?, z = 2.0, time_out = 0.5) "
        "-> { done: b, timeout: c } }\n",
        "4:68: parameter 'time_out' of DEPTH? must be in [1, 3600] s, got 0.5 s [CORAL105]",
    ),
    # replies
    (
        HEADER
        + PLACES
        + "transition t wait { a } action { ROMEO(DEPTH?, z = 2.0, time_out = 60) -> { done: b } }\n",
        "4:40: DEPTH? can reply 'timeout', but transition 't' does not say where that reply goes [CORAL106]",
    ),
    (
        HEADER
        + PLACES
        + "transition t wait { a } action { ROMEO(DEPTH, z = 2.0) -> { ack: b, eror: c } }\n",
        "4:69: DEPTH never replies 'eror' (did you mean 'error'?) [CORAL107]",
    ),
    (
        HEADER
        + PLACES
        + "transition t wait { a } action { ROMEO(DEPTH, z = 2.0) -> { ack: b, ack: c, error: c } }\n",
        "4:69: reply 'ack' is mapped twice [CORAL108]",
    ),
    # temporal assertions (HEADER + PLACES + TEMPORAL, assertion on line 7)
    (
        HEADER + PLACES + TEMPORAL + "assert alwyas b\n",
        "7:8: expected 'never', 'reachable', 'bound', 'within', 'always', 'eventually', 'ltl', "
        "'ctl' or 'P leadsto Q' after 'assert', found 'alwyas' (did you mean 'always'?) [CORAL001]",
    ),
    (
        HEADER + PLACES + TEMPORAL + "assert b and c\n",
        "8:1: expected 'leadsto' after 'assert b and c', found end of file [CORAL001]",
    ),
    (
        HEADER + PLACES + TEMPORAL + "assert always b = 1\n",
        "7:17: '=' declares; write '==' to compare [CORAL001]",
    ),
    (
        HEADER + PLACES + TEMPORAL + "assert always b + c\n",
        "8:1: expected a comparison ('<', '<=', '==', '!=', '>=', '>') after 'b + c', "
        "found end of file [CORAL001]",
    ),
    (
        HEADER + PLACES + TEMPORAL + "assert always\n",
        "8:1: expected a state expression after 'assert always', found end of file [CORAL001]",
    ),
    (
        HEADER + PLACES + TEMPORAL + "assert ctl E [ b c ]\n",
        "7:18: expected 'U' in 'E [ P U Q ]', found 'c' [CORAL001]",
    ),
    (
        HEADER + PLACES + TEMPORAL + "assert always (b or c\n",
        "8:1: expected ')' to close '(', found end of file [CORAL001]",
    ),
    (
        HEADER + PLACES + TEMPORAL + "assert ltl b leadsto c leadsto a\n",
        "7:24: 'leadsto' does not chain: parenthesise one side [CORAL001]",
    ),
    (
        HEADER + PLACES + TEMPORAL + "assert eventually fired(go)\n",
        "7:19: unknown function 'fired' (did you mean 'fires'?) [CORAL001]",
    ),
    (
        HEADER + "require\n",
        "4:1: expected a requirement, e.g. 'require termination', found end of file [CORAL001]",
    ),
    (
        HEADER + PLACES + TEMPORAL + "assert go.pending leadsto b\n",
        "7:8: 'go.pending' is not a place a property can read; write 'in_flight(go)': its "
        "command awaits a reply [CORAL001]",
    ),
    (
        HEADER + PLACES + TEMPORAL + "assert always go.ack -> b\n",
        "7:15: 'go.ack' is not a place a property can read; a reply is an event: write "
        "'fires(go.ack)' or 'fireable(go.ack)' [CORAL001]",
    ),
    (
        HEADER + PLACES + TEMPORAL + "assert always dd\n",
        "7:15: unknown place 'dd' (did you mean 'd'?) [CORAL002]",
    ),
    (
        HEADER + PLACES + TEMPORAL + "assert eventually fires(goo)\n",
        "7:25: unknown transition 'goo' (did you mean 'go'?) [CORAL002]",
    ),
    (
        HEADER + PLACES + TEMPORAL + "assert always not fires(go.akc)\n",
        "7:25: transition 'go' has no reply 'akc' (did you mean 'ack'?) [CORAL002]",
    ),
    (
        HEADER + PLACES + TEMPORAL + "assert always F b\n",
        "7:15: 'F' is a temporal operator, but 'assert always' takes a state expression [CORAL008]",
    ),
    (
        HEADER + PLACES + TEMPORAL + "assert b leadsto F c\n",
        "7:18: 'F' is a temporal operator, but the two sides of 'leadsto' are state "
        "expressions [CORAL008]",
    ),
    (
        HEADER + PLACES + TEMPORAL + "assert ltl G AF b\n",
        "7:14: 'AF' is a CTL path quantifier; an LTL formula already speaks of every run "
        "[CORAL008]",
    ),
    (
        HEADER + PLACES + TEMPORAL + "assert ctl AG F b\n",
        "7:15: in CTL, 'F' needs a path quantifier: write 'AF' (on every run) or 'EF' "
        "(on some run) [CORAL008]",
    ),
    (
        HEADER + PLACES + TEMPORAL + "assert ctl b U c\n",
        "7:14: in CTL, 'U' needs a path quantifier: write 'A [ P U Q ]' (on every run) or "
        "'E [ P U Q ]' (on some run) [CORAL008]",
    ),
    (
        HEADER + PLACES + TEMPORAL + "assert ctl AG not fires(go)\n",
        "7:19: 'fires' is an event of a run, which CTL cannot see: CTL speaks of markings "
        "[CORAL008]",
    ),
    (
        HEADER + PLACES + TEMPORAL + "assert ctl AG (b leadsto c)\n",
        "7:18: 'leadsto' is LTL: in CTL write 'AG (P -> AF Q)' [CORAL008]",
    ),
    (
        HEADER + PLACES + TEMPORAL + "assert in_flight(stop) leadsto d\n",
        "7:18: transition 'stop' sends no command, so nothing of it is ever in flight [CORAL008]",
    ),
    (
        HEADER + PLACES + TEMPORAL + "assert in_flight(go.ack) leadsto d\n",
        "7:18: in_flight takes the transition that sends a command, 'in_flight(go)', not one "
        "of its replies [CORAL008]",
    ),
    (
        HEADER + PLACES + "const K = 1\nassert always K\n",
        "5:15: 'K' is a constant, not a place: compare a place with it, e.g. 'p >= K' [CORAL008]",
    ),
    (
        HEADER + PLACES + "assert eventually final\n",
        "4:19: 'final' means a declared final marking, and this mission declares none [CORAL008]",
    ),
    (
        HEADER + PLACES + "assert always a + 1 <= b\n",
        "4:15: a comparison of places with places cannot also add numbers [CORAL008]",
    ),
    (
        HEADER + "require terminaton\n",
        "3:9: unknown requirement 'terminaton' (did you mean 'termination'?) [CORAL009]",
    ),
    # operator inputs
    (
        HEADER + "place input\n",
        "3:7: expected a place name, found keyword 'input' (keywords are reserved) [CORAL001]",
    ),
    (
        HEADER + "input wait\n",
        "3:7: expected an operator input name, e.g. 'input abort_requested', found keyword "
        "'wait' (keywords are reserved) [CORAL001]",
    ),
    (
        HEADER + PLACES + "input stop_now\ntransition t wait { a } signal { b, stop_now }\n",
        "5:37: transition 't' signals operator input 'stop_now': only the operator marks it "
        "[CORAL010]",
    ),
    (
        HEADER
        + PLACES
        + "input stop_now\n"
        + "transition go wait { a } action { ROMEO(DEPTH, z = 2.0) -> { ack: stop_now, "
        + "error: c } }\n",
        "5:67: reply 'ack' of transition 'go' marks operator input 'stop_now': only the "
        "operator marks it [CORAL010]",
    ),
    (
        HEADER + "place stop_now = 1\ninput stop_now\n",
        "4:7: operator input 'stop_now' must start empty, but the place is given 1 initial "
        "tokens at m.coral:3:18 [CORAL010]",
    ),
    (
        HEADER + "place stop_now capacity 2\ninput stop_now\n",
        "4:7: operator input 'stop_now' cannot have a capacity (given at m.coral:3:25) [CORAL010]",
    ),
    (
        HEADER + "input i1, i2, i3, i4, i5, i6, i7, i8\ninput i1, i9\n",
        "4:11: too many operator inputs: 'i9' would be number 9, at most 8 are supported "
        "[CORAL010]",
    ),
    (
        HEADER + "place a\n# coral: part of m.coral\n",
        "4:1: '# coral: part of' must come before the file's first declaration [CORAL011]",
    ),
    (
        "mission m\nvehicle ROMEO\nplace start = 1 done\n",
        "3:17: expected ',' between places (or a unit after the number: s, min, ...) [CORAL001]",
    ),
]


@pytest.mark.parametrize(
    ("text", "expected"),
    TABLE,
    ids=[row[1].split("[")[1][:-1] + f"-{i}" for i, row in enumerate(TABLE)],
)
def test_bad_snippet_gives_exact_diagnostic(text: str, expected: str) -> None:
    assert _first(text) == expected


def test_all_errors_of_a_file_in_one_run() -> None:
    text = (
        HEADER
        + "place a = 1, b\n"
        + "transition t1 wait { x } signal { b }\n"
        + "transition t2 wait { a } action { ROMEO(DEPHT) -> { done: b } }\n"
        + "transition t3 wait { a } action { ROMEO(DEPTH, z = 900) -> { ack: b, error: b } }\n"
        + "place @\n"
    )
    result = compile_source(text, "m.coral")
    codes = [d.code for d in result.errors]
    assert codes == ["CORAL002", "CORAL101", "CORAL105", "CORAL001"]
    assert result.net is None


def test_rendered_diagnostic_shows_source_line_and_caret() -> None:
    text = HEADER + "place depth_ok = 1, done\ntransition t wait { dpeth_ok } signal { done }\n"
    result = compile_source(text, "pool.coral")
    rendered = result.errors[0].render(result.sources)
    assert rendered.splitlines() == [
        "pool.coral:4:21: error: unknown place 'dpeth_ok' (did you mean 'depth_ok'?) [CORAL002]",
        "   |",
        " 4 | transition t wait { dpeth_ok } signal { done }",
        "   |                     ^~~~~~~~",
    ]


def test_profile_notes_list_accepted_commands() -> None:
    text = HEADER + PLACES + "transition t wait { a } action { ROMEO(DIVE) -> { ack: b } }\n"
    error = compile_source(text, "m.coral").errors[0]
    assert error.code == "CORAL101"
    assert any("DEPTH?" in note and "GOTO" in note for note in error.notes)


def test_unit_conversion_is_applied() -> None:
    text = (
        HEADER
        + PLACES
        + "transition t wait { a } action { ROMEO(DEPTH, z = 250 cm) -> { ack: b, error: c } }\n"
    )
    result = compile_source(text, "m.coral")
    assert result.net is not None
    command = result.net.transition("t").command
    assert command is not None and command.params == (("z", 2.5),)
