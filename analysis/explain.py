"""``coral-check --explain CODE``: a rule's page, where the diagnostic is read.

A warning in a terminal names its code; the page that says why it matters at sea and
how to fix it is in ``docs/rules.md`` (lint rules, CORAL2xx) or in the code table of
``docs/language.md`` (compile errors, CORAL0xx and CORAL1xx). This prints that section,
so nobody needs the repository open beside the terminal.

The pages are read from the source tree when coral runs from one (a clone, an
editable install), so they are always the documentation as written. An installed
package has no ``docs/`` folder: it carries a copy of ``docs/rules.md`` as package data
(``analysis/rules.md``, kept identical by ``tests/analysis/test_explain.py``), and for
compile codes it falls back to their one-line meanings in `coral_lang.codes`.
"""

from __future__ import annotations

import re
from importlib import resources
from pathlib import Path

from analysis.cli_codes import known_codes, lint_codes

__all__ = ["UnknownCode", "explain", "rules_text"]

_DOCS = Path(__file__).resolve().parent.parent / "docs"
_PACKAGED_RULES = "rules.md"


class UnknownCode(LookupError):
    """A code no rule has; the message lists the known ones."""


def explain(code: str) -> str:
    """The page of ``code`` (case-insensitive), as Markdown text ending in a newline.

    Raises:
        UnknownCode: No diagnostic has this code.
    """
    code = code.strip().upper()
    if code not in known_codes():
        raise UnknownCode(f"unknown rule code '{code}'; known codes: {', '.join(known_codes())}")
    if code in lint_codes():
        return _lint_page(code)
    return _compile_page(code)


def rules_text() -> str:
    """The text of the lint rules' page: ``docs/rules.md``, or the packaged copy."""
    source = _DOCS / "rules.md"
    if source.is_file():
        return source.read_text(encoding="utf-8")
    return resources.files("analysis").joinpath(_PACKAGED_RULES).read_text(encoding="utf-8")


def _lint_page(code: str) -> str:
    text = rules_text()
    match = re.search(rf"^## {code}\b.*?(?=^## |\Z)", text, re.M | re.S)
    if match is None:  # the test keeps every rule documented; say so rather than crash
        return f"{code}: no page in docs/rules.md\n"
    return match.group(0).rstrip() + "\n"


def _compile_page(code: str) -> str:
    language = _DOCS / "language.md"
    meaning = None
    if language.is_file():
        row = re.search(rf"^\| {code} \| (.*?) \|\s*$", language.read_text(encoding="utf-8"), re.M)
        meaning = row.group(1) if row else None
    if meaning is None:
        from coral_lang.codes import CODES

        meaning = CODES[code]
    return (
        f"## {code}: {meaning}\n\n"
        "A compile error: the mission does not compile, so it is neither verified nor "
        "run. The message at the error's line says what to change. Compile errors "
        "cannot be ignored with --ignore or a `# coral: allow` comment. See "
        'docs/language.md, "Diagnostics".\n'
    )
