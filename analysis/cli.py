"""``coral-check``: lint and verify CORAL missions (or PNML nets) before they run.

::

    coral-check FILE...              the same as 'coral-check check FILE...'
    coral-check check FILE...        compile, lint and verify; text, json, sarif or html
    coral-check lint FILE...         compile and lint only: fast, for pre-commit hooks
    coral-check verify FILE          one file's verification report, and its certificate
    coral-check fmt FILE...          rewrite missions in the canonical layout (--check, --diff)
    coral-check export FILE ...      the compiled net as PNML (--pnml OUT) or DOT (--dot OUT)
    coral-check keygen --out KEY     a key pair to sign certificates with (KEY, KEY.pub)
    coral-check resign CERT          sign a certificate with a new key (key rotation)
    coral-check query NET ...        Model Checking Contest queries (analysis.query_cli)
    coral-check --explain CODE       the page of a diagnostic code

One parser (`coral_lang.cliframe`) with a subparser per command: the usage line lists
them, ``--version`` works, and every usage error returns 2 instead of raising. A first
argument that names no command means ``check``. Defaults may come from ``coral.toml``
or ``[tool.coral]`` in ``pyproject.toml`` (`analysis.config`).

Exit codes (`analysis.outcome`): 0 no errors and every property proven; 1 errors in a
mission (compile or lint) or a property violated; 3 a property inconclusive and none
violated; 2 bad usage or a file that cannot be read. Over several files the worst one
wins, in the order 2 > 1 > 3 > 0.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence

from analysis.cli_check import SIGNING_KEY_ENV, run_check, run_verify
from analysis.cli_export import EXPORT_EPILOG, EXPORT_HELP, configure_export, run_export
from analysis.cli_fmt import FMT_EPILOG, FMT_HELP, configure_fmt, run_fmt
from analysis.cli_keys import (
    KEYGEN_EPILOG,
    KEYGEN_HELP,
    RESIGN_EPILOG,
    RESIGN_HELP,
    configure_keygen,
    configure_resign,
    run_keygen,
    run_resign,
)
from analysis.cli_options import (
    PROG,
    add_config_options,
    add_explain_option,
    add_files_argument,
    add_output_options,
    add_profile_options,
    add_rule_options,
    add_search_options,
    add_timed_options,
    add_version_option,
    memory_limit_of,
)
from analysis.outcome import EXIT_ERRORS, EXIT_INCONCLUSIVE, EXIT_OK, EXIT_USAGE
from coral_lang.cliframe import command_parser, print_error, run_main, subcommands, writable_output

__all__ = [
    "EXIT_ERRORS",
    "EXIT_INCONCLUSIVE",
    "EXIT_OK",
    "EXIT_USAGE",
    "SIGNING_KEY_ENV",
    "build_lint_parser",
    "build_parser",
    "build_verify_parser",
    "main",
]

WARNINGS_HELP = (
    " A property the mission does not require ('terminates' without 'require "
    "termination') is only a warning when it fails: shown, never in the exit code."
)
EXIT_CODES_HELP = (
    "exit codes: 0 clean (no errors, every property proven), 1 errors in a mission or a "
    "property violated, 2 bad usage or unreadable file, 3 a property inconclusive (none "
    "violated). With several files the worst wins: 2 > 1 > 3 > 0." + WARNINGS_HELP
)
VERIFY_EXIT_CODES_HELP = (
    "exit codes: 0 clean (no errors, every property proven), 1 errors in the mission or a "
    "property violated, 2 bad usage or unreadable file, 3 a property inconclusive (none "
    "violated)." + WARNINGS_HELP
)
LINT_EXIT_CODES_HELP = (
    "exit codes: 0 no errors (warnings allowed), 1 errors in a mission, "
    "2 bad usage or unreadable file; with several files the worst wins (2 > 1 > 0)."
)
CHECK_FORMATS = ("text", "json", "sarif", "html")
LINT_FORMATS = ("text", "json", "sarif")
NET_LAYOUTS = ("auto", "graphviz", "builtin")

DESCRIPTION = (
    "Check CORAL missions (.coral) and PNML nets (.pnml) before they run. 'coral-check "
    "FILE...' is 'coral-check check FILE...'. Each command has its own --help. Defaults "
    "come from coral.toml or [tool.coral] in pyproject.toml, found from the current folder "
    "up (docs/verify.md, 'Configuration'). 'coral-check --explain CODE' prints a "
    "diagnostic's page."
)
CHECK_HELP = (
    "Compile, lint, and prove boundedness, absence of deadlock, reachability of the final "
    "markings, termination (no engine cycle, a final marking always reachable, every fair "
    "run ends in one), no dead transitions, no resource conflicts and the mission's own "
    "assertions. Formats: text for a terminal, json (docs/json.md), sarif (SARIF 2.1.0 "
    "for code scanning), html (one self-contained page with the net and counterexamples)."
)
LINT_HELP = (
    "Compile and lint missions without verifying them: the fast check for pre-commit "
    "hooks and editors. Rules and suppressions: docs/rules.md."
)
VERIFY_HELP = (
    "Compile a mission (or import a PNML net) and decide its properties: boundedness, "
    "deadlock, final markings, termination, dead transitions, resource conflicts, and the "
    "mission's own assertions. Each verdict is proven, violated (with a trace) or "
    "inconclusive (with the reason). Diagnostics go to stderr, the report to stdout or OUT."
)


# -- parsers --------------------------------------------------------------------------


def build_parser() -> argparse.ArgumentParser:
    """coral-check's parser: every command a subparser (tests read its help)."""
    parser = command_parser(PROG, DESCRIPTION, EXIT_CODES_HELP)
    commands = subcommands(parser)
    configure_check(
        commands.add_parser(
            "check",
            help="compile, lint and verify (the default)",
            description=CHECK_HELP,
            epilog=EXIT_CODES_HELP,
        )
    )
    configure_lint(
        commands.add_parser(
            "lint",
            help="compile and lint only (fast)",
            description=LINT_HELP,
            epilog=LINT_EXIT_CODES_HELP,
        )
    )
    configure_verify(
        commands.add_parser(
            "verify",
            help="one file's report and certificate",
            description=VERIFY_HELP,
            epilog=VERIFY_EXIT_CODES_HELP,
        )
    )
    configure_fmt(
        commands.add_parser("fmt", help="format missions", description=FMT_HELP, epilog=FMT_EPILOG)
    )
    configure_export(
        commands.add_parser(
            "export",
            help="the net as PNML or DOT",
            description=EXPORT_HELP,
            epilog=EXPORT_EPILOG,
        )
    )
    configure_keygen(
        commands.add_parser(
            "keygen",
            help="a key pair for certificates",
            description=KEYGEN_HELP,
            epilog=KEYGEN_EPILOG,
        )
    )
    configure_resign(
        commands.add_parser(
            "resign",
            help="re-sign a certificate with a new key",
            description=RESIGN_HELP,
            epilog=RESIGN_EPILOG,
        )
    )
    from analysis.query_cli import add_query_parser

    add_query_parser(commands)
    for command in commands.choices.values():
        add_version_option(command)
    return parser


def build_lint_parser() -> argparse.ArgumentParser:
    """``coral-check lint`` on its own (the CI documentation's test parses with it)."""
    parser = command_parser(f"{PROG} lint", LINT_HELP, LINT_EXIT_CODES_HELP)
    configure_lint(parser)
    return parser


def build_verify_parser() -> argparse.ArgumentParser:
    """``coral-check verify`` on its own."""
    parser = command_parser(f"{PROG} verify", VERIFY_HELP, VERIFY_EXIT_CODES_HELP)
    configure_verify(parser)
    return parser


def configure_check(parser: argparse.ArgumentParser) -> None:
    """The arguments of ``coral-check check``."""
    add_files_argument(parser)
    add_output_options(parser, CHECK_FORMATS)
    parser.add_argument(
        "--net-layout",
        choices=NET_LAYOUTS,
        default="auto",
        help="how the html report lays out the net: Graphviz's dot when installed "
        "(auto), Graphviz (graphviz), or coral's own layered layout (builtin)",
    )
    _add_checking_options(parser)
    add_search_options(parser)
    add_timed_options(parser)


def configure_lint(parser: argparse.ArgumentParser) -> None:
    """The arguments of ``coral-check lint``."""
    add_files_argument(parser)
    add_output_options(parser, LINT_FORMATS)
    _add_checking_options(parser)


def configure_verify(parser: argparse.ArgumentParser) -> None:
    """The arguments of ``coral-check verify``."""
    add_files_argument(parser, many=False)
    add_output_options(
        parser,
        ("text", "json"),
        format_help="report format (default text)",
        output_help="write the report here",
        quiet=False,
    )
    certificate = parser.add_argument_group("certificate")
    certificate.add_argument(
        "--certificate",
        type=writable_output,
        metavar="FILE",
        help="also write the pre-mission certificate (net digest, verdicts, date) here; "
        "the runtime runs only nets whose certificate says every property was proven and "
        "is signed by a key it trusts",
    )
    certificate.add_argument(
        "--signing-key",
        metavar="KEY",
        help="sign the certificate with this private key (from 'coral-check keygen'; "
        f"default: ${SIGNING_KEY_ENV}, a key file or the PEM itself); without one the "
        "certificate is unsigned and no run accepts it",
    )
    certificate.add_argument(
        "--expires",
        metavar="DAYS|DATE",
        help="the certificate expires after DAYS days, or at the end of DATE (UTC, "
        "e.g. 2026-12-31); default: never",
    )
    _add_checking_options(parser)
    add_search_options(parser)
    add_timed_options(parser, schedules=True)


def _add_checking_options(parser: argparse.ArgumentParser) -> None:
    """What check, lint and verify share: compiling, rules, configuration, --explain."""
    add_profile_options(parser)
    add_rule_options(parser)
    add_config_options(parser)
    add_explain_option(parser)


# -- entry point --------------------------------------------------------------------------

_COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {
    "check": lambda args: run_check(args, lint_only=False),
    "lint": lambda args: run_check(args, lint_only=True),
    "verify": run_verify,
    "fmt": run_fmt,
    "export": run_export,
    "keygen": run_keygen,
    "resign": run_resign,
}


def _dispatch(args: argparse.Namespace) -> int:
    if getattr(args, "explain", None) is not None:
        return _explain(args)
    from analysis.budget import bytes_text, memory_ceiling

    limit = memory_limit_of(args)
    # The hard safety net under the memory budget (see `memory_ceiling`); an allocation
    # that still fails ends as an honest inconclusive, never a traceback or exit 1.
    with memory_ceiling(limit):
        try:
            if args.command == "query":
                from analysis.query_cli import run_query

                return run_query(args)
            return _COMMANDS[args.command](args)
        except MemoryError:
            shown = "the machine's memory" if limit is None else bytes_text(limit)
            print_error(PROG, f"inconclusive: memory limit of {shown} reached")
            return EXIT_INCONCLUSIVE


def _explain(args: argparse.Namespace) -> int:
    """``--explain CODE``: the code's page; a usage error when files were given too
    (they would otherwise be skipped without a word)."""
    from analysis.explain import UnknownCode, explain

    files = getattr(args, "files", None) or [f for f in [getattr(args, "file", None)] if f]
    if files:
        print_error(PROG, f"--explain takes no FILE: '{PROG} --explain {args.explain}' alone")
        return EXIT_USAGE
    try:
        sys.stdout.write(explain(args.explain))
    except UnknownCode as exc:
        print_error(PROG, str(exc))
        return EXIT_USAGE
    return EXIT_OK


def main(argv: Sequence[str] | None = None) -> int:
    """Run coral-check; returns the exit code (see the module docstring), never raises
    ``SystemExit``. A first argument that names no command means ``check`` (name a
    file called ``lint`` as ``./lint``); options go after the command's name."""
    return run_main(build_parser(), argv, _dispatch, default_command="check")


if __name__ == "__main__":
    sys.exit(main())
