"""Property tests: printing and parsing agree; no input crashes the compiler."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from coral_lang.compiler import compile_source
from coral_lang.diagnostics import Severity
from coral_lang.parser import parse
from coral_lang.printer import format_mission
from tests.conftest import EXAMPLES
from tests.coral_lang.strategies import missions

POOL = (EXAMPLES / "pool_mission" / "go_to_operating_site.coral").read_text()


@pytest.mark.slow
@given(missions())
@settings(max_examples=150)
def test_printed_mission_parses_back_to_the_same_tree(mission: object) -> None:
    text = format_mission(mission)  # type: ignore[arg-type]
    parsed, diagnostics = parse(text, "gen.coral")
    assert diagnostics == []
    assert parsed == mission


@pytest.mark.slow
@given(missions())
@settings(max_examples=100)
def test_generated_missions_compile_and_reprint_to_the_same_net(mission: object) -> None:
    text = format_mission(mission)  # type: ignore[arg-type]
    first = compile_source(text, "gen.coral")
    assert first.errors == [], [d.render() for d in first.errors]
    assert first.net is not None
    again = compile_source(format_mission(parse(text, "gen.coral")[0]), "again.coral")
    assert again.net is not None and again.net.digest() == first.net.digest()


def _compiles_without_crashing(text: str) -> None:
    result = compile_source(text, "fuzz.coral")
    for diagnostic in result.diagnostics:
        assert diagnostic.span is None or diagnostic.span.line >= 1
        diagnostic.render(result.sources)
    if result.net is None:
        assert any(d.severity is Severity.ERROR for d in result.diagnostics)


@pytest.mark.slow
@given(st.text(max_size=300))
@settings(max_examples=300)
def test_arbitrary_text_gives_diagnostics_not_exceptions(text: str) -> None:
    _compiles_without_crashing(text)


_ALPHABET = st.sampled_from(
    [
        *list('{}(),=*:->?#"\n ab_1.9[]+<>!'),
        *("wait", "place", "ROMEO(", "transition", "assert ", "always ", "leadsto ", " U "),
        *("ltl G ", "ctl AG ", "E [", "in_flight(", "fires(", "final", "not ", "require "),
    ]
)


@pytest.mark.slow
@given(st.integers(0, len(POOL)), st.integers(0, 40), st.lists(_ALPHABET, max_size=6))
@settings(max_examples=300)
def test_damaged_real_mission_gives_diagnostics_not_exceptions(
    at: int, cut: int, inserted: list[str]
) -> None:
    damaged = "mission m\nvehicle ROMEO\n" + POOL[:at] + "".join(inserted) + POOL[at + cut :]
    _compiles_without_crashing(damaged)
