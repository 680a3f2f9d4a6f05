"""``coral-check fmt FILE...``: rewrite missions in the canonical layout.

One layout for every mission, so reviews show changes of meaning, not of spacing. The
layout is `coral_lang.formatting.format_source`'s (comments kept); this module only
decides what happens to the files:

* default: rewrite each file that changes, atomically (a temporary file in the same
  folder renamed over it: an interrupted run never leaves half a mission);
* ``--check``: change nothing, list the files that would change, exit 1 if any (CI);
* ``--diff``: change nothing, print a unified diff of each, exit 1 if any;
* ``-`` formats standard input to standard output.

A file that does not parse is never touched: its errors are printed and the run exits
1. Exit codes: 0 nothing to change (or everything rewritten), 1 a file would change
(``--check``, ``--diff``) or does not parse, 2 bad usage or a file that cannot be read.
"""

from __future__ import annotations

import argparse
import difflib
import os
import shutil
import sys
import tempfile
from pathlib import Path

from analysis.cli_options import PROG
from analysis.outcome import EXIT_ERRORS, EXIT_OK, EXIT_USAGE, worst_exit_code
from coral_lang.cliframe import print_error

__all__ = [
    "FMT_EPILOG",
    "FMT_HELP",
    "NO_NEWLINE",
    "configure_fmt",
    "diff_lines",
    "run_fmt",
    "unified_diff",
]

FMT_HELP = (
    "Rewrite missions in the canonical layout (comments kept). With --check or --diff "
    "nothing is written: CI fails when a mission is not formatted. '-' formats standard "
    "input to standard output. A file that does not parse is never touched."
)
FMT_EPILOG = (
    "exit codes: 0 formatted (nothing left to change), 1 a file would change (--check, "
    "--diff) or does not parse, 2 bad usage or a file that cannot be read"
)


def configure_fmt(parser: argparse.ArgumentParser) -> None:
    """The arguments of ``coral-check fmt``."""
    parser.add_argument(
        "files", nargs="+", metavar="FILE", help="mission (.coral) to format; - for stdin"
    )
    mode = parser.add_mutually_exclusive_group()
    mode.add_argument(
        "--check",
        action="store_true",
        help="write nothing; list the files that would change, exit 1 if any",
    )
    mode.add_argument(
        "--diff",
        action="store_true",
        help="write nothing; print a unified diff of each change, exit 1 if any",
    )


def _format(text: str, file: str) -> str:
    """The canonical layout of ``text`` (a seam: tests may replace it)."""
    from coral_lang.formatting import format_source

    return format_source(text, file)


def run_fmt(args: argparse.Namespace) -> int:
    """Format the files; the exit code (see the module docstring)."""
    if args.files.count("-") > 1:
        print_error(PROG, "'-' (standard input) can be given only once")
        return EXIT_USAGE
    codes = [_format_one(file, args) for file in args.files]
    changed = codes.count(_CHANGED)
    unchanged = codes.count(EXIT_OK)
    if len(args.files) > 1 or args.check:
        verb = "would be reformatted" if args.check or args.diff else "reformatted"
        print(f"{_files(changed)} {verb}, {_files(unchanged)} already formatted", file=sys.stderr)
    if args.check or args.diff:
        return worst_exit_code(EXIT_ERRORS if c == _CHANGED else c for c in codes)
    return worst_exit_code(EXIT_OK if c == _CHANGED else c for c in codes)


_CHANGED = -1  # a file whose layout changed (exit 1 with --check/--diff, 0 otherwise)


def _files(n: int) -> str:
    return f"{n} file{'s' if n != 1 else ''}"


def _format_one(file: str, args: argparse.Namespace) -> int:
    from coral_lang.diagnostics import CompileError

    text = _read(file)
    if text is None:
        return EXIT_USAGE
    shown = "<stdin>" if file == "-" else file
    try:
        formatted = _format(text, shown)
    except CompileError as exc:
        print(str(exc), file=sys.stderr)
        print(f"{shown}: not formatted: fix the errors above first", file=sys.stderr)
        return EXIT_ERRORS
    if file == "-" and not (args.check or args.diff):
        sys.stdout.write(formatted)
        return EXIT_OK if formatted == text else _CHANGED
    if formatted == text:
        return EXIT_OK
    if args.diff:
        sys.stdout.writelines(unified_diff(text, formatted, shown))
    elif args.check:
        print(f"would reformat {shown}", file=sys.stderr)
    else:
        try:
            _replace(Path(file), formatted)
        except OSError as exc:
            print_error(PROG, f"cannot write '{file}': {exc.strerror}")
            return EXIT_USAGE
        print(f"reformatted {shown}", file=sys.stderr)
    return _CHANGED


def _read(file: str) -> str | None:
    """The mission's text, or None after saying why it cannot be read."""
    if file == "-":
        return sys.stdin.read()
    from analysis.pipeline import unreadable
    from coral_lang.loading import is_pnml

    problem = "a PNML net has no CORAL layout" if is_pnml(file) else unreadable(file)
    if problem is None:
        try:
            # newline="": the layout decides line endings, so they must be seen as written
            with open(file, encoding="utf-8", newline="") as handle:
                return handle.read()
        except OSError as exc:
            problem = exc.strerror or str(exc)
    print_error(PROG, f"cannot read '{file}': {problem}")
    return None


NO_NEWLINE = "\\ No newline at end of file\n"
"""The marker diff and patch put after a last line that has no line end."""


def unified_diff(before: str, after: str, shown: str) -> list[str]:
    """The unified diff from ``before`` to ``after``, as ``diff -u`` writes it.

    `difflib.unified_diff` leaves a last line without a line end as it is, so the next
    line of the diff would be glued to it; diff and patch write it with a line end and
    the marker `NO_NEWLINE` after it, which is what this does, so ``patch`` applies it.
    """
    lines: list[str] = []
    for line in difflib.unified_diff(
        diff_lines(before),
        diff_lines(after),
        fromfile=shown,
        tofile=f"{shown} (formatted)",
    ):
        if line.endswith("\n"):
            lines.append(line)
        else:
            lines += [line + "\n", NO_NEWLINE]
    return lines


def diff_lines(text: str) -> list[str]:
    """``text``'s lines as diff and patch see them: ended by ``\\n`` only, each keeping
    its end. `str.splitlines` also breaks at form feeds, ``\\v``, ``\\x1c``-``\\x1e``,
    ``\\x85``, U+2028 and U+2029, which a comment may hold: a diff cut there would not
    apply."""
    lines = text.split("\n")
    last = lines.pop()
    return [line + "\n" for line in lines] + ([last] if last else [])


def _replace(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically, keeping the file's permissions.

    A symbolic link is written through: the file it points to is replaced (the
    temporary file is made in that file's folder, so the rename stays atomic) and the
    link stays a link, as editors do."""
    target = Path(os.path.realpath(path))
    fd, name = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="") as handle:
            handle.write(text)
        shutil.copymode(target, name)
        os.replace(name, target)
    except BaseException:
        Path(name).unlink(missing_ok=True)
        raise
