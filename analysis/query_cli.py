"""``coral-check query``: Model Checking Contest examinations on a P/T net.

::

    coral-check query MODEL.pnml QUERIES.xml [QUERIES.xml ...]
    coral-check query MODEL.pnml --examination NAME [--examination NAME ...]
    coral-check query MODEL_DIR --examination CTLFireability     (MCC layout)

Prints one MCC line per formula, ``FORMULA <id> TRUE|FALSE|<n> TECHNIQUES <words>`` or
``FORMULA <id> CANNOT_COMPUTE``; ``--format json`` prints one document instead, with
the answer, technique, seconds and witness or counterexample trace of every formula.
A global examination (ReachabilityDeadlock, QuasiLiveness, Liveness, OneSafe,
StableMarking) prints one line whose id is the examination's name, as MCC tools do.

A folder as MODEL is the MCC layout: ``MODEL/model.pnml`` with ``MODEL/<NAME>.xml``
beside it; with a ``.pnml`` file, ``--examination NAME`` of a query examination looks
for ``<NAME>.xml`` or ``<stem>.<NAME>.xml`` in the model's folder.

Exit codes: 0 every formula answered, 3 some could not be computed (a budget ran out),
2 bad usage or input (a missing file, bad XML or PNML, an unknown place).

``--time-limit`` bounds the whole command (every search, the z3 state equation, the
graph, CTL labelling and LTL products); ``--memory-limit`` (default: 80 % of the
machine's or cgroup's memory) is checked by the same searches, and an allocation that
fails anyway ends the formulas left as ``CANNOT_COMPUTE`` with the reason, not a crash.
Formulas the budget did not reach say ``not computed: <reason>``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from analysis.cli_options import (
    add_budget_options,
    add_method_option,
    add_output_options,
    memory_limit_of,
    output_conflict,
)
from analysis.outcome import EXIT_INCONCLUSIVE, EXIT_OK, EXIT_USAGE
from coral_lang.cliframe import (
    CommandParser,
    command_parser,
    positive_int,
    print_error,
    run_main,
)

__all__ = [
    "QUERY_DESCRIPTION",
    "QUERY_EXIT_CODES_HELP",
    "add_query_parser",
    "build_query_parser",
    "configure_query",
    "query_main",
    "run_query",
]

PROG = "coral-check query"
QUERY_DESCRIPTION = (
    "Answer Model Checking Contest queries on a P/T net: the formulas of MCC property "
    "files (Reachability, CTL, LTL, UpperBounds) and the global examinations. Prints one "
    "'FORMULA <id> <answer> TECHNIQUES ...' line per formula (CANNOT_COMPUTE when a budget "
    "ran out; answers are exact or absent)."
)
QUERY_EXIT_CODES_HELP = (
    "exit codes: 0 every formula answered, 3 some formula CANNOT_COMPUTE (a budget ran "
    "out), 2 bad usage or unreadable input."
)


def add_query_parser(
    subparsers: argparse._SubParsersAction[argparse.ArgumentParser],
) -> argparse.ArgumentParser:
    """``coral-check query`` as a subcommand of coral-check's parser.

    Its options are added the first time it parses or prints help: their choices and
    defaults come from `analysis.examinations`, about a second to import, which a
    ``coral-check lint`` run in a pre-commit hook must not pay."""
    # argparse makes every subparser of the class `add_subparsers` was given; this one
    # alone is lazy, so the class is switched for this call only.
    default_class = subparsers._parser_class
    subparsers._parser_class = _LazyQueryParser
    try:
        return subparsers.add_parser(
            "query",
            help="Model Checking Contest queries on a PNML net",
            description=QUERY_DESCRIPTION,
            epilog=QUERY_EXIT_CODES_HELP,
        )
    finally:
        subparsers._parser_class = default_class


class _LazyQueryParser(CommandParser):
    """A parser that adds ``coral-check query``'s arguments when first used."""

    _configured = False

    def _configure(self) -> None:
        if not self._configured:
            self._configured = True
            configure_query(self)

    def parse_known_args(  # type: ignore[override]
        self, args: Sequence[str] | None = None, namespace: argparse.Namespace | None = None
    ) -> tuple[argparse.Namespace, list[str]]:
        self._configure()
        return super().parse_known_args(args, namespace)

    def format_help(self) -> str:
        self._configure()
        return super().format_help()

    def format_usage(self) -> str:
        self._configure()
        return super().format_usage()


def build_query_parser() -> argparse.ArgumentParser:
    """``coral-check query``'s parser on its own (`query_main`)."""
    parser = command_parser(PROG, QUERY_DESCRIPTION, QUERY_EXIT_CODES_HELP)
    configure_query(parser)
    return parser


def configure_query(parser: argparse.ArgumentParser) -> None:
    """Add ``coral-check query``'s arguments to ``parser``."""
    from analysis.examinations import (
        DEFAULT_MAX_EDGES,
        DEFAULT_MAX_PRODUCT_EDGES,
        DEFAULT_MAX_STATES,
        EXAMINATIONS,
    )

    parser.add_argument(
        "model", metavar="MODEL", help="PNML file, or an MCC folder holding model.pnml"
    )
    parser.add_argument(
        "queries", nargs="*", metavar="QUERIES.xml", help="MCC property file(s) to answer"
    )
    parser.add_argument(
        "--examination",
        action="append",
        default=[],
        choices=EXAMINATIONS,
        metavar="NAME",
        help="an MCC examination (repeatable): " + ", ".join(EXAMINATIONS),
    )
    add_output_options(
        parser, ("text", "json"), format_help="output (default text)", color=False, quiet=False
    )
    budgets = add_budget_options(
        parser,
        defaults={
            "max_states": DEFAULT_MAX_STATES,
            "time_limit": 600.0,
            "max_edges": DEFAULT_MAX_EDGES,
        },
        helps={
            "max_states": f"state budget of the search (default {DEFAULT_MAX_STATES})",
            "time_limit": "time for the whole run (default 600)",
            "max_edges": "edges of the reachability graph (CTL, LTL, Liveness; "
            f"default {DEFAULT_MAX_EDGES})",
        },
    )
    budgets.add_argument(
        "--max-product-edges",
        type=positive_int,
        default=DEFAULT_MAX_PRODUCT_EDGES,
        metavar="N",
        help=f"edges of one LTL product (default {DEFAULT_MAX_PRODUCT_EDGES})",
    )
    add_method_option(budgets, "ReachabilityDeadlock and the state count")


def _error(message: str) -> None:
    print_error(PROG, message)


class _BadInput(Exception):
    """Input that cannot be used; the message says why."""


def _model_path(model: str) -> Path:
    path = Path(model)
    if path.is_dir():
        inner = path / "model.pnml"
        if not inner.is_file():
            raise _BadInput(f"'{model}' is a folder without model.pnml")
        return inner
    if not path.exists():
        raise _BadInput(f"cannot read '{model}': no such file")
    return path


def _examination_file(model: Path, name: str) -> Path:
    """``<NAME>.xml`` (MCC layout) or ``<stem>.<NAME>.xml`` beside the model."""
    for candidate in (model.parent / f"{name}.xml", model.parent / f"{model.stem}.{name}.xml"):
        if candidate.is_file():
            return candidate
    raise _BadInput(
        f"no {name}.xml beside '{model}' (looked for {name}.xml and {model.stem}.{name}.xml);"
        " pass the query file itself"
    )


def query_main(argv: Sequence[str] | None = None) -> int:
    """Run ``coral-check query`` on its own; returns the exit code (2 on bad usage)."""
    return run_main(build_query_parser(), argv, _bounded_query)


def _bounded_query(args: argparse.Namespace) -> int:
    """`run_query` under the memory ceiling that coral-check's dispatcher sets for its
    subcommands (`analysis.budget.memory_ceiling`)."""
    from analysis.budget import memory_ceiling

    with memory_ceiling(memory_limit_of(args)):
        return run_query(args)


def run_query(args: argparse.Namespace) -> int:
    """Answer the parsed query command; the exit code."""
    if not args.queries and not args.examination:
        _error("nothing to do: give query files or --examination NAME")
        return EXIT_USAGE
    conflict = output_conflict([("-o", args.output)], [args.model, *args.queries])
    if conflict is not None:
        _error(conflict)
        return EXIT_USAGE
    try:
        document, lines, complete = _run(args)
    except _BadInput as exc:
        _error(str(exc))
        return EXIT_USAGE
    text = json.dumps(document, indent=2) + "\n" if args.format == "json" else lines
    if args.output:
        try:
            Path(args.output).write_text(text, encoding="utf-8")
        except OSError as exc:
            _error(f"cannot write '{args.output}': {exc.strerror}")
            return EXIT_USAGE
    else:
        sys.stdout.write(text)
    return EXIT_OK if complete else EXIT_INCONCLUSIVE


def _run(args: argparse.Namespace) -> tuple[dict[str, Any], str, bool]:
    from analysis.examinations import GLOBAL_EXAMINATIONS, Answer, QueryLimits, QuerySession
    from analysis.mccxml import MccProperty, MccXmlError, read_properties
    from coral_lang.diagnostics import PnmlError
    from coral_lang.pnml import read_pnml

    started = time.perf_counter()
    model = _model_path(args.model)
    try:
        net = read_pnml(model)
    except PnmlError as exc:
        raise _BadInput(str(exc)) from None
    files = [Path(q) for q in args.queries]
    globals_: list[str] = []
    for name in dict.fromkeys(args.examination):
        if name in GLOBAL_EXAMINATIONS:
            globals_.append(name)
        else:
            files.append(_examination_file(model, name))
    props: list[MccProperty] = []
    for file in files:
        if not file.is_file():
            why = "it is a directory" if file.is_dir() else "no such file"
            raise _BadInput(f"cannot read '{file}': {why}")
        try:
            props.extend(read_properties(file, net))
        except MccXmlError as exc:
            raise _BadInput(str(exc)) from None
    limits = QueryLimits(
        max_states=args.max_states,
        time_limit=args.time_limit,
        max_edges=args.max_edges,
        max_product_edges=args.max_product_edges,
        memory_limit=memory_limit_of(args),
        method=args.method,
    )
    session = QuerySession(net, limits)
    answers: list[Answer] = session.check(props)
    answers += [session.check_global(name) for name in globals_]
    lines = "".join(a.mcc_line() + "\n" for a in answers)
    space = session.space
    figures: dict[str, Any] = {
        "method": None if space is None else "explicit",
        "states": None if space is None else space.states,
        "complete": None if space is None else space.complete,
    }
    symbolic = session.symbolic
    if symbolic is not None and (space is None or not space.complete or symbolic.complete):
        figures = {"method": "symbolic", "states": symbolic.states, "complete": symbolic.complete}
    document: dict[str, Any] = {
        "tool": "coral-check query",
        "model": net.name,
        "file": str(model),
        "queries": [str(f) for f in files],
        **figures,
        "shared_seconds": round(session.shared_seconds, 6),
        "seconds": round(time.perf_counter() - started, 6),
        "answered": sum(a.computed for a in answers),
        "cannot_compute": sum(not a.computed for a in answers),
        "results": [a.to_dict() for a in answers],
    }
    return document, lines, all(a.computed for a in answers)
