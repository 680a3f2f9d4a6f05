"""The frame every coral command line shares: parser, argument types, exit codes.

``coral-check``, ``coral-run``, ``coral-vehicle`` and ``romeo-sim`` all build their
parsers with `command_parser`, read their options with the types below, and run through
`run_main`. So every command:

* answers ``--version`` with ``PROG (coral X.Y.Z)``;
* lists its subcommands in its usage line (argparse subparsers, never a peek at argv);
* returns 2 on a usage error, after argparse's usage line and message, and 0 after
  ``--help``, instead of raising ``SystemExit`` out of ``main``;
* returns 2, silently, when the reader of its output goes away (``coral-check ... | head``).

It lives in ``coral_lang``, the package every other one may import (docs/architecture.md).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import NoReturn

__all__ = [
    "EXIT_FAILED",
    "EXIT_OK",
    "EXIT_USAGE",
    "CommandParser",
    "ParserExit",
    "command_parser",
    "existing_folder",
    "finite_number",
    "host_port",
    "non_negative_float",
    "port_number",
    "positive_float",
    "positive_int",
    "print_error",
    "run_main",
    "subcommands",
    "tool_version",
    "writable_output",
]

EXIT_OK = 0
"""Success: what the command was asked to do was done, and found nothing wrong."""
EXIT_FAILED = 1
"""A definite negative answer: errors in a mission, a property violated, a failed run."""
EXIT_USAGE = 2
"""Bad usage or input the command cannot read: nothing was checked or run."""


class ParserExit(Exception):
    """Raised instead of ``SystemExit`` by `CommandParser`; `run_main` turns it into
    the exit code (0 after ``--help`` or ``--version``, 2 after a usage error)."""

    def __init__(self, status: int) -> None:
        super().__init__(status)
        self.status = status


class CommandParser(argparse.ArgumentParser):
    """An ``ArgumentParser`` that raises `ParserExit` rather than exiting the process.

    Subparsers made from it are ``CommandParser`` too (argparse makes them of the
    parent's class), so a usage error in a subcommand is caught the same way.
    """

    def exit(self, status: int = 0, message: str | None = None) -> NoReturn:
        if message:
            sys.stderr.write(message)
        raise ParserExit(status)

    def error(self, message: str) -> NoReturn:
        self.print_usage(sys.stderr)
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message}\n")


def tool_version() -> str:
    """The installed coral version (``0+unknown`` when run from a tree never installed)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("coral")
    except PackageNotFoundError:
        return "0+unknown"


def command_parser(prog: str, description: str, epilog: str | None = None) -> CommandParser:
    """A top-level parser with ``--version``; its help keeps paragraphs as written."""
    parser = CommandParser(prog=prog, description=description, epilog=epilog)
    parser.add_argument("--version", action="version", version=f"%(prog)s (coral {tool_version()})")
    return parser


def subcommands(
    parser: argparse.ArgumentParser, *, required: bool = True
) -> argparse._SubParsersAction[argparse.ArgumentParser]:
    """The subcommands of ``parser``, listed in its usage line; the chosen one is
    ``args.command``."""
    return parser.add_subparsers(dest="command", required=required, title="commands")


def run_main(
    parser: argparse.ArgumentParser,
    argv: Sequence[str] | None,
    dispatch: Callable[[argparse.Namespace], int],
    *,
    default_command: str | None = None,
) -> int:
    """Parse ``argv`` (default ``sys.argv[1:]``) and call ``dispatch``; its exit code.

    Args:
        parser: The command's parser, from `command_parser`.
        argv: The arguments, without the program name.
        dispatch: Runs the parsed command and returns its exit code.
        default_command: The subcommand meant when the first argument names none: the
            shorthand ``coral-check FILE...`` for ``coral-check check FILE...`` and
            ``coral-run MISSION`` for ``coral-run run MISSION``. The test uses the
            subcommand names argparse holds, so the usage line and the shorthand never
            disagree; ``--help`` and ``--version`` stay the top level's.
    """
    args = list(sys.argv[1:] if argv is None else argv)
    if default_command is not None:
        misplaced = _misplaced_command(parser, args, default_command)
        if misplaced is not None:
            parser.print_usage(sys.stderr)
            print_error(parser.prog, misplaced)
            return EXIT_USAGE
        if _needs_default(parser, args):
            args.insert(0, default_command)
    try:
        try:
            namespace = parser.parse_args(args)
        except ParserExit as exc:
            return exc.status
        return dispatch(namespace)
    except BrokenPipeError:  # the reader went away (`coral-check ... | head`)
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # no second error when Python flushes
        return EXIT_USAGE


def _command_names(parser: argparse.ArgumentParser) -> set[str]:
    names: set[str] = set()
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            names.update(action.choices)
    return names


def _needs_default(parser: argparse.ArgumentParser, args: Sequence[str]) -> bool:
    if not args:
        return False
    if args[0] in ("-h", "--help", "--version"):
        return False
    return args[0] not in _command_names(parser)


def _misplaced_command(
    parser: argparse.ArgumentParser, args: Sequence[str], default_command: str
) -> str | None:
    """Why ``args`` would be misread, or None: options before a command's name
    (``coral-check --no-config lint m.coral``). The shorthand would take them for the
    default command's and the name for a file. The arguments are not reordered
    silently: an option taking a value makes that ambiguous (``--config lint``).

    Only the first positional argument can be a command's name: the leading options
    are walked with the default command's option table, so an option's value that
    happens to be a command's name (``coral-run --sim --out run m.coral``) is a value.
    """
    if not args or not args[0].startswith("-") or args[0] in ("-", "-h", "--help", "--version"):
        return None
    index = _first_positional(_option_table(parser, default_command), args)
    if index is None or args[index] not in _command_names(parser):
        return None
    import shlex

    arg = args[index]
    fixed = shlex.join([parser.prog, arg, *args[:index], *args[index + 1 :]])
    return f"options go after the command name: {fixed} (a file named '{arg}' is given as ./{arg})"


def _option_table(
    parser: argparse.ArgumentParser, default_command: str
) -> dict[str, argparse.Action]:
    """The options the shorthand's arguments are read with: the top level's, then the
    default command's (which win, as they are the ones argparse will use)."""
    table = dict(parser._option_string_actions)
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            command = action.choices.get(default_command)
            if command is not None:
                table.update(command._option_string_actions)
    return table


def _lookup(table: dict[str, argparse.Action], option: str) -> argparse.Action | None:
    """The action of ``option``, also when abbreviated (``--lim`` for ``--limit``) as
    argparse allows; None when it names no option, or more than one."""
    if option in table:
        return table[option]
    if option.startswith("--"):
        matches = {id(a): a for name, a in table.items() if name.startswith(option)}
        if len(matches) == 1:
            return next(iter(matches.values()))
    return None


def _first_positional(table: dict[str, argparse.Action], args: Sequence[str]) -> int | None:
    """The index of the first argument that is neither an option nor an option's value;
    None when there is none before ``--`` (after it everything is a file)."""
    index = 0
    while index < len(args):
        arg = args[index]
        if arg == "--":
            return None
        if arg == "-" or not arg.startswith("-"):
            return index
        index += 1
        if arg.startswith("--") and "=" in arg:
            continue  # --opt=value is one argument
        action = _lookup(table, arg)
        # None: -oVALUE or a cluster of short flags (one argument), or an unknown
        # option, which argparse reports; either way no value follows.
        if action is not None:
            index = _skip_values(action.nargs, args, index)
    return None


def _skip_values(nargs: int | str | None, args: Sequence[str], index: int) -> int:
    """The index after the values an option with ``nargs`` takes from ``args[index:]``."""
    if nargs is None:
        return index + 1
    if isinstance(nargs, int):
        return index + nargs
    if nargs == argparse.OPTIONAL:
        takes = index < len(args) and not args[index].startswith("-")
        return index + 1 if takes else index
    if nargs in (argparse.ZERO_OR_MORE, argparse.ONE_OR_MORE):
        while index < len(args) and not args[index].startswith("-"):
            index += 1
        return index
    return index  # SUPPRESS, PARSER, REMAINDER: nothing the shorthand reads


def print_error(prog: str, message: str) -> None:
    """``PROG: error: MESSAGE`` on stderr: the one shape of every command's errors."""
    print(f"{prog}: error: {message}", file=sys.stderr)


# -- argument types ---------------------------------------------------------------------
# Each takes the text argparse hands over and returns the value, or raises
# `argparse.ArgumentTypeError` with the message argparse prints after the option name.


def positive_int(text: str) -> int:
    """A whole number of at least 1 (state budgets, edge budgets, limits)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a whole number: '{text}'") from None
    if value < 1:
        raise argparse.ArgumentTypeError("must be at least 1")
    return value


def finite_number(text: str) -> float:
    """Any finite number (no ``nan``, no ``inf``)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: '{text}'") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"not a finite number: '{text}'")
    return value


def positive_float(text: str) -> float:
    """A finite number above 0 (time limits in seconds, speed factors)."""
    value = finite_number(text)
    if value <= 0:
        raise argparse.ArgumentTypeError("must be more than 0")
    return value


def non_negative_float(text: str) -> float:
    """A finite number of at least 0."""
    value = finite_number(text)
    if value < 0:
        raise argparse.ArgumentTypeError("must be 0 or more")
    return value


def port_number(text: str) -> int:
    """A TCP or UDP port, 0..65535 (0: the system picks one)."""
    if not (text.isascii() and text.isdigit()) or not 0 <= int(text) <= 65535:
        raise argparse.ArgumentTypeError(f"expected a port in 0..65535, got '{text}'")
    return int(text)


def host_port(text: str, *, default_host: str | None = None) -> tuple[str, int]:
    """``HOST:PORT`` (port 1..65535); with ``default_host``, a bare ``PORT`` too.

    IPv6 hosts are written in brackets (``[::1]:8080``), which are removed."""
    host, sep, port = text.rpartition(":")
    if not sep and default_host is not None:
        host, port = default_host, text
    if host.startswith("[") and host.endswith("]"):
        host = host[1:-1]
    if not host or not (port.isascii() and port.isdigit()) or not 0 < int(port) < 65536:
        expected = "[HOST:]PORT" if default_host is not None else "HOST:PORT"
        raise argparse.ArgumentTypeError(f"expected {expected}, got '{text}'")
    return host, int(port)


def existing_folder(text: str) -> Path:
    """An existing folder (``--include-path``): a missing one is bad usage at once, not
    a compile error that blames the mission's include."""
    path = Path(text)
    if not path.is_dir():
        raise argparse.ArgumentTypeError(f"{text}: no such folder")
    return path


def writable_output(text: str) -> Path:
    """A file to write (``-o OUT``): refused at once when it is a folder or its folder
    does not exist, rather than after a long verification."""
    path = Path(text)
    if path.is_dir():
        raise argparse.ArgumentTypeError(f"cannot write '{text}': it is a directory")
    if not path.resolve().parent.is_dir():
        raise argparse.ArgumentTypeError(f"cannot write '{text}': no such folder")
    return path
