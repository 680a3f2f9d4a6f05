"""``coral-check --explain CODE``: every code has a page, from the docs or the package."""

from __future__ import annotations

from pathlib import Path

import pytest

from analysis import explain as explain_module
from analysis.cli import main
from analysis.cli_codes import known_codes, lint_codes
from analysis.explain import UnknownCode, explain
from coral_lang.codes import CODES
from tests.conftest import REPO


@pytest.mark.parametrize("code", lint_codes())
def test_every_lint_rule_has_its_page(code: str) -> None:
    page = explain(code)
    assert page.startswith(f"## {code}: ") and "**Fix.**" in page
    assert page.count("\n## ") == 0  # this rule's section only


@pytest.mark.parametrize("code", sorted(CODES))
def test_every_compile_code_has_its_meaning(code: str) -> None:
    page = explain(code.lower())
    assert page.startswith(f"## {code}: ") and "compile error" in page


def test_the_packaged_copy_is_the_documentation() -> None:
    """An installed coral has no docs/ folder and reads analysis/rules.md instead: it must
    be docs/rules.md exactly (copy it over after editing the page)."""
    packaged = (REPO / "analysis" / "rules.md").read_text(encoding="utf-8")
    assert packaged == (REPO / "docs" / "rules.md").read_text(encoding="utf-8")


def test_without_the_source_tree_the_packaged_pages_serve(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    from_docs = {code: explain(code) for code in known_codes()}
    monkeypatch.setattr(explain_module, "_DOCS", tmp_path / "no-docs")
    for code in lint_codes():
        assert explain(code) == from_docs[code]
    for code, meaning in CODES.items():
        assert explain(code).startswith(f"## {code}: {meaning}\n")


def test_unknown_code_raises_with_the_known_ones() -> None:
    with pytest.raises(UnknownCode, match="unknown rule code 'CORAL999'; known codes: CORAL001"):
        explain("CORAL999")


def test_the_option_prints_the_page_and_exits(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--explain", "CORAL207"]) == 0
    out = capsys.readouterr().out
    assert out == explain("CORAL207") and "priority" in out
    assert main(["lint", "--explain", "coral204"]) == 0  # also after a subcommand
    assert capsys.readouterr().out.startswith("## CORAL204: ")
    assert main(["--explain", "CORAL2"]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and "coral-check: error: unknown rule code 'CORAL2'" in captured.err
    assert main(["--explain"]) == 2
