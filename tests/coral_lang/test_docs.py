"""The documentation cannot drift from the code: its examples compile, its code table
matches the codes the compiler emits."""

from __future__ import annotations

import re

import pytest

from coral_lang.codes import CODES
from coral_lang.compiler import compile_source
from tests.conftest import REPO

LANGUAGE = (REPO / "docs" / "language.md").read_text()
SNIPPETS = re.findall(r"```coral\n(.*?)```", LANGUAGE, re.S)


@pytest.mark.parametrize("snippet", SNIPPETS)
def test_every_coral_example_in_the_language_doc_compiles(snippet: str) -> None:
    result = compile_source(snippet, "doc.coral")
    assert result.errors == [], [d.render() for d in result.errors]


def test_every_code_emitted_by_the_front_end_is_registered_and_documented() -> None:
    emitted: set[str] = set()
    for module in ("lexer.py", "parser.py", "compiler.py", "loading.py", "properties.py"):
        emitted |= set(re.findall(r'"(CORAL\d{3})"', (REPO / "coral_lang" / module).read_text()))
    assert emitted <= set(CODES), emitted - set(CODES)
    documented = set(re.findall(r"^\| (CORAL\d{3}) \|", LANGUAGE, re.M))
    assert documented == set(CODES)


def test_every_registered_code_appears_in_the_diagnostics_table() -> None:
    table = (REPO / "tests" / "coral_lang" / "test_diagnostics_table.py").read_text()
    missing = {code for code in CODES if f"[{code}]" not in table}
    assert missing == {"CORAL004"}  # include failures need files: tests/coral_lang/test_compiler.py
