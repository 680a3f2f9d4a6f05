"""``coral-check``: compile missions (or import PNML models) and report every problem.

Exit codes: 0 clean, 1 errors in a mission, 2 bad usage or unreadable file.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from coral_lang.diagnostics import ProfileError, Severity, render_all
from coral_lang.loading import load_net_file
from coral_lang.profile import VehicleProfile, load_profile

EXIT_OK = 0
EXIT_ERRORS = 1
EXIT_USAGE = 2


def build_parser() -> argparse.ArgumentParser:
    """The command-line parser (tests read its help text)."""
    parser = argparse.ArgumentParser(
        prog="coral-check",
        description="Check CORAL missions (.coral) and PNML nets (.pnml) before they run.",
        epilog="exit codes: 0 clean, 1 errors found in a mission, 2 bad usage or unreadable file",
    )
    parser.add_argument(
        "files", nargs="+", metavar="FILE", help="mission (.coral) or PNML (.pnml) file"
    )
    parser.add_argument(
        "--profile",
        action="append",
        default=[],
        metavar="YAML",
        help="vehicle profile to use instead of the bundled one of that name (repeatable)",
    )
    parser.add_argument(
        "-q", "--quiet", action="store_true", help="print diagnostics only, no summary"
    )
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run coral-check; returns the exit code."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        return EXIT_OK if exc.code == 0 else EXIT_USAGE
    profiles: list[VehicleProfile] = []
    for profile_path in args.profile:
        try:
            profiles.append(load_profile(profile_path))
        except ProfileError as exc:
            print(f"coral-check: error: {exc}", file=sys.stderr)
            return EXIT_USAGE
    status = EXIT_OK
    for file in args.files:
        path = Path(file)
        if not path.is_file():
            print(f"coral-check: error: cannot read '{file}': no such file", file=sys.stderr)
            status = max(status, EXIT_USAGE)
            continue
        result = load_net_file(path, profiles)
        if result.diagnostics:
            print(render_all(result.diagnostics, result.sources), file=sys.stderr)
        errors = [d for d in result.diagnostics if d.severity is Severity.ERROR]
        unreadable = any(d.code == "CORAL004" and d.span is None for d in errors)
        if unreadable:
            status = max(status, EXIT_USAGE)
        elif errors or result.net is None:
            status = max(status, EXIT_ERRORS)
            if not args.quiet:
                print(f"{file}: {len(errors)} error{'s' if len(errors) != 1 else ''}")
        elif not args.quiet:
            print(f"{file}: ok, {result.net.summary()}, digest {result.net.digest()}")
    return status


if __name__ == "__main__":
    sys.exit(main())
