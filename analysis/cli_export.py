"""``coral-check export FILE --pnml OUT --dot OUT``: the compiled net for other tools.

PNML takes a mission's net to other Petri net tools (the Model Checking Contest's
format, `coral_lang.pnml`); DOT draws it with Graphviz (`coral_lang.dot`). ``-`` as
OUT writes to standard output. A mission with errors writes nothing: its diagnostics go
to stderr and the exit code is 1, so a build never ships the net of a broken mission.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from analysis.cli_check import STDIN, read_stdin_once, refused_output
from analysis.cli_options import (
    PROG,
    add_config_options,
    add_files_argument,
    add_profile_options,
    output_conflict,
    output_or_stdout,
    resolve,
)
from analysis.outcome import EXIT_ERRORS, EXIT_OK, EXIT_USAGE
from coral_lang.cliframe import print_error

__all__ = ["EXPORT_EPILOG", "EXPORT_HELP", "configure_export", "run_export"]

EXPORT_HELP = (
    "Compile a mission (or read a PNML net) and write its net as PNML (--pnml OUT, for "
    "other Petri net tools) and/or as Graphviz DOT (--dot OUT, to draw it); '-' as OUT "
    "is standard output. A mission with errors writes nothing."
)
EXPORT_EPILOG = (
    "exit codes: 0 written, 1 errors in the mission (nothing written), 2 bad usage or "
    "a file that cannot be read or written"
)


def configure_export(parser: argparse.ArgumentParser) -> None:
    """The arguments of ``coral-check export``."""
    add_files_argument(parser, many=False)
    group = parser.add_argument_group("outputs (at least one)")
    group.add_argument(
        "--pnml", type=output_or_stdout, metavar="OUT", help="write the net as PNML here"
    )
    group.add_argument(
        "--dot", type=output_or_stdout, metavar="OUT", help="write the net as Graphviz DOT here"
    )
    add_profile_options(parser)
    add_config_options(parser)


def run_export(args: argparse.Namespace) -> int:
    """Compile and write the requested formats; the exit code."""
    from analysis.pipeline import check_file
    from coral_lang.diagnostics import render_all

    if args.pnml is None and args.dot is None:
        print_error(PROG, "export: nothing to write: give --pnml OUT and/or --dot OUT")
        return EXIT_USAGE
    if args.pnml == args.dot:
        print_error(PROG, f"export: --pnml and --dot both write to '{args.pnml}'")
        return EXIT_USAGE
    conflict = output_conflict([("--pnml", args.pnml), ("--dot", args.dot)], [args.file])
    if conflict is not None:
        print_error(PROG, f"export: {conflict}")
        return EXIT_USAGE
    outputs = [("--pnml", args.pnml), ("--dot", args.dot)]
    settings = resolve(args)
    if settings is None or refused_output(outputs, settings):
        return EXIT_USAGE
    stdin = read_stdin_once([args.file])
    outcome = check_file(
        args.file, settings.check_options(text=stdin if args.file == STDIN else None)
    )
    if outcome.input_error is not None:
        print_error(PROG, f"cannot read '{outcome.path}': {outcome.input_error}")
        return EXIT_USAGE
    if refused_output(outputs, settings, outcome):  # an include of the mission
        return EXIT_USAGE
    net = outcome.result.net if outcome.result is not None else None
    if outcome.errors or net is None:
        print(render_all(outcome.errors, outcome.sources), file=sys.stderr)
        print(f"{outcome.path}: not exported: fix the errors above first", file=sys.stderr)
        return EXIT_ERRORS
    texts: list[tuple[str, str]] = []
    if args.pnml is not None:
        from coral_lang.diagnostics import PnmlError
        from coral_lang.pnml import to_pnml

        try:
            texts.append((args.pnml, to_pnml(net)))
        except PnmlError as exc:  # a name XML cannot carry: nothing is written
            print_error(PROG, f"cannot export '{outcome.path}' as PNML: {exc}")
            return EXIT_ERRORS
    if args.dot is not None:
        from coral_lang.dot import to_dot

        texts.append((args.dot, to_dot(net)))
    for output, text in texts:
        if output == "-":
            sys.stdout.write(text)
            continue
        try:
            Path(output).write_text(text, encoding="utf-8")
        except OSError as exc:
            print_error(PROG, f"cannot write '{output}': {exc.strerror}")
            return EXIT_USAGE
    return EXIT_OK
