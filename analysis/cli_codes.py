"""Rule codes as ``--select`` / ``--ignore`` (and the config file) name them.

A selector is a code (``CORAL204``) or a prefix of codes (``CORAL2`` for every lint
rule), as in ruff. A selector that matches no known code is refused at once, naming
it: a typo in ``--ignore`` must not silently keep a rule on, nor one in ``--select``
silently turn every rule off. So is one that matches only compile codes (CORAL0xx,
CORAL1xx): compile errors are always reported, so ``--ignore CORAL001`` would promise
what it cannot do, and ``--select CORAL0`` would select no lint rule at all.
"""

from __future__ import annotations

import argparse

__all__ = [
    "compile_only_selectors",
    "known_codes",
    "lint_codes",
    "parse_selectors",
    "selector_problem",
    "unknown_selectors",
]


def lint_codes() -> tuple[str, ...]:
    """The lint rules' codes (CORAL2xx), sorted."""
    from analysis.lint import RULES

    return tuple(sorted(RULES))


def known_codes() -> tuple[str, ...]:
    """Every diagnostic code: the compiler's (CORAL0xx, CORAL1xx) and lint's, sorted."""
    from coral_lang.codes import CODES

    return tuple(sorted({*CODES, *lint_codes()}))


def unknown_selectors(selectors: list[str] | tuple[str, ...]) -> list[str]:
    """The selectors that match no known code (empty when all are fine)."""
    codes = known_codes()
    return [s for s in selectors if not any(code.startswith(s) for code in codes)]


def compile_only_selectors(selectors: list[str] | tuple[str, ...]) -> list[str]:
    """The known selectors that match compile codes only, no lint rule."""
    known = known_codes()
    lint = lint_codes()
    return [
        s
        for s in selectors
        if any(code.startswith(s) for code in known) and not any(c.startswith(s) for c in lint)
    ]


def selector_problem(selectors: list[str] | tuple[str, ...]) -> str | None:
    """Why these selectors cannot be used (None when they can): an unknown code, or
    one that names compile codes only. The message lists what may be given."""
    unknown = unknown_selectors(selectors)
    if unknown:
        return (
            f"unknown rule code {', '.join(unknown)} (known: {', '.join(known_codes())}; "
            "a prefix such as CORAL2 selects every code it starts)"
        )
    compile_only = compile_only_selectors(selectors)
    if compile_only:
        return (
            f"{', '.join(compile_only)}: compile errors cannot be selected or ignored "
            f"(they are always reported); lint codes: {', '.join(lint_codes())}"
        )
    return None


def parse_selectors(text: str) -> list[str]:
    """``--select``/``--ignore``'s argument type: comma-separated codes or prefixes.

    Raises `argparse.ArgumentTypeError` naming the selectors that match no code, or
    only compile codes (`selector_problem`)."""
    selectors = [part.strip().upper() for part in text.split(",") if part.strip()]
    if not selectors:
        raise argparse.ArgumentTypeError("expected rule codes such as CORAL204 or CORAL2")
    problem = selector_problem(selectors)
    if problem is not None:
        raise argparse.ArgumentTypeError(problem)
    return selectors
