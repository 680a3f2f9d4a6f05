"""``coral-check``: compile missions (or import PNML models), then verify them.

``coral-check FILE...`` compiles and prints diagnostics;
``coral-check verify FILE [--format text|json]`` also decides every property.

Exit codes: 0 clean (and, with ``verify``, every property proven); 1 errors in a mission
or a property violated; 3 a property inconclusive (and none violated); 2 bad usage or
an unreadable file.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path

from analysis.lint import DEFAULT_LINK_RTT_S, LintOptions, lint
from coral_lang.compiler import CompileResult
from coral_lang.diagnostics import ProfileError, Severity, render_all
from coral_lang.loading import load_net_file
from coral_lang.profile import VehicleProfile, load_profile

EXIT_OK = 0
EXIT_ERRORS = 1
EXIT_USAGE = 2
EXIT_INCONCLUSIVE = 3

EXIT_CODES_HELP = (
    "exit codes: 0 clean (verify: every property proven), 1 errors in a mission or a "
    "property violated, 2 bad usage or unreadable file, 3 a property inconclusive"
)


def build_parser() -> argparse.ArgumentParser:
    """The command-line parser for ``coral-check FILE...`` (tests read its help text)."""
    parser = argparse.ArgumentParser(
        prog="coral-check",
        description="Check CORAL missions (.coral) and PNML nets (.pnml) before they run. "
        "Use 'coral-check verify FILE' to prove properties as well.",
        epilog=EXIT_CODES_HELP,
    )
    parser.add_argument(
        "files", nargs="+", metavar="FILE", help="mission (.coral) or PNML (.pnml) file"
    )
    _add_profile_option(parser)
    parser.add_argument(
        "-q", "--quiet", action="store_true", help="print diagnostics only, no summary"
    )
    return parser


def build_verify_parser() -> argparse.ArgumentParser:
    """The parser for ``coral-check verify``."""
    parser = argparse.ArgumentParser(
        prog="coral-check verify",
        description="Compile a mission (or import a PNML net) and decide its properties: "
        "boundedness, deadlock, final markings, dead transitions, resource conflicts, "
        "and the mission's own assertions. Each verdict is proven, violated (with a "
        "trace) or inconclusive (with the reason).",
        epilog=EXIT_CODES_HELP,
    )
    parser.add_argument("file", metavar="FILE", help="mission (.coral) or PNML (.pnml) file")
    _add_profile_option(parser)
    parser.add_argument(
        "--format", choices=("text", "json"), default="text", help="report format (default text)"
    )
    parser.add_argument("-o", "--output", metavar="OUT", help="write the report here, not stdout")
    parser.add_argument(
        "--max-states",
        type=_positive_int,
        default=2_000_000,
        metavar="N",
        help="state budget of the explicit search (default 2000000)",
    )
    parser.add_argument(
        "--time-limit",
        type=float,
        default=120.0,
        metavar="SECONDS",
        help="time limit of the explicit search (default 120)",
    )
    parser.add_argument(
        "--por",
        action="store_true",
        help="explore a partial-order (stubborn-set) reduced state space",
    )
    parser.add_argument(
        "--no-structure",
        action="store_true",
        help="skip invariants, structural boundedness and siphons/traps",
    )
    parser.add_argument("--progress", action="store_true", help="show search progress on stderr")
    parser.add_argument(
        "--certificate",
        metavar="FILE",
        help="also write the pre-mission certificate (net digest, verdicts, date) here; "
        "the runtime runs only nets whose certificate says every property was proven",
    )
    return parser


def _add_profile_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--profile",
        action="append",
        default=[],
        metavar="YAML",
        help="vehicle profile to use instead of the bundled one of that name (repeatable)",
    )
    parser.add_argument(
        "--link-rtt",
        type=float,
        default=DEFAULT_LINK_RTT_S,
        metavar="SECONDS",
        help="worst round trip of the link to the vehicle, for the query time-out rule "
        f"CORAL206 (default {DEFAULT_LINK_RTT_S:g})",
    )


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError("must be at least 1")
    return value


def main(argv: Sequence[str] | None = None) -> int:
    """Run coral-check; returns the exit code."""
    args_list = list(sys.argv[1:] if argv is None else argv)
    if args_list and args_list[0] == "verify":
        return _verify_main(args_list[1:])
    parser = build_parser()
    try:
        args = parser.parse_args(args_list)
    except SystemExit as exc:
        return EXIT_OK if exc.code == 0 else EXIT_USAGE
    profiles = _profiles(args.profile)
    if profiles is None:
        return EXIT_USAGE
    status = EXIT_OK
    for file in args.files:
        result = _load(file, profiles)
        if result is None:
            status = max(status, EXIT_USAGE)
            continue
        findings = lint(result, LintOptions(link_rtt_s=args.link_rtt))
        if findings:
            print(render_all(findings, result.sources), file=sys.stderr)
        errors = [d for d in (*result.diagnostics, *findings) if d.severity is Severity.ERROR]
        if errors or result.net is None:
            status = max(status, EXIT_ERRORS)
            if not args.quiet:
                print(f"{file}: {len(errors)} error{'s' if len(errors) != 1 else ''}")
        elif not args.quiet:
            warned = (
                f", {len(findings)} warning{'s' if len(findings) != 1 else ''}" if findings else ""
            )
            print(f"{file}: ok{warned}, {result.net.summary()}, digest {result.net.digest()}")
    return status


def _profiles(paths: list[str]) -> list[VehicleProfile] | None:
    profiles: list[VehicleProfile] = []
    for profile_path in paths:
        try:
            profiles.append(load_profile(profile_path))
        except ProfileError as exc:
            print(f"coral-check: error: {exc}", file=sys.stderr)
            return None
    return profiles


def _load(file: str, profiles: list[VehicleProfile]) -> CompileResult | None:
    """Compile or import ``file``, printing diagnostics; None if it cannot be read."""
    if not Path(file).is_file():
        print(f"coral-check: error: cannot read '{file}': no such file", file=sys.stderr)
        return None
    result = load_net_file(Path(file), profiles)
    if result.diagnostics:
        print(render_all(result.diagnostics, result.sources), file=sys.stderr)
    return result


def _verify_main(argv: list[str]) -> int:
    from analysis.certificate import make_certificate, write_certificate
    from analysis.progress import ProgressPrinter
    from analysis.verify import VerifyOptions, verify

    parser = build_verify_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        return EXIT_OK if exc.code == 0 else EXIT_USAGE
    if args.output and not Path(args.output).resolve().parent.is_dir():
        print(f"coral-check: error: cannot write '{args.output}': no such folder", file=sys.stderr)
        return EXIT_USAGE
    profiles = _profiles(args.profile)
    if profiles is None:
        return EXIT_USAGE
    result = _load(args.file, profiles)
    if result is None:
        return EXIT_USAGE
    if result.net is None or result.errors:
        print(f"{args.file}: not verified: fix the errors above first", file=sys.stderr)
        return EXIT_ERRORS
    findings = lint(result, LintOptions(link_rtt_s=args.link_rtt))
    if findings:
        print(render_all(findings, result.sources), file=sys.stderr)
    options = VerifyOptions(
        max_states=args.max_states,
        time_limit=args.time_limit,
        por=args.por,
        structural=not args.no_structure,
        progress=ProgressPrinter(sys.stderr, force=True) if args.progress else None,
    )
    report = verify(result.net, options)
    if args.format == "json":
        text = json.dumps(report.to_dict(), indent=2) + "\n"
    else:
        text = report.render_text(color=not args.output and sys.stdout.isatty()) + "\n"
    if args.certificate:
        try:
            write_certificate(make_certificate(report, options), args.certificate)
        except OSError as exc:
            print(
                f"coral-check: error: cannot write '{args.certificate}': {exc.strerror}",
                file=sys.stderr,
            )
            return EXIT_USAGE
    if args.output:
        try:
            Path(args.output).write_text(text, encoding="utf-8")
        except OSError as exc:
            print(
                f"coral-check: error: cannot write '{args.output}': {exc.strerror}", file=sys.stderr
            )
            return EXIT_USAGE
    else:
        sys.stdout.write(text)
    return report.exit_code()


if __name__ == "__main__":
    sys.exit(main())
