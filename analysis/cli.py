"""``coral-check``: lint and verify CORAL missions (or PNML nets) before they run.

::

    coral-check FILE...          compile, lint and verify each file; text, json, sarif or html
    coral-check lint FILE...     compile and lint only: fast, for pre-commit hooks
    coral-check verify FILE      one file's verification report, and its certificate
    coral-check keygen --out KEY a key pair to sign certificates with (KEY, KEY.pub)
    coral-check resign CERT      sign a certificate with a new key (key rotation)
    coral-check query NET ...    Model Checking Contest queries (analysis.query_cli)

Exit codes (`analysis.outcome`): 0 no errors and every property proven; 1 errors in a
mission (compile or lint) or a property violated; 3 a property inconclusive and none
violated; 2 bad usage or a file that cannot be read. Over several files the worst one
wins, in the order 2 > 1 > 3 > 0.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from analysis.argtypes import non_negative_float, positive_float, positive_int
from analysis.lint import DEFAULT_LINK_RTT_S, LintOptions, lint
from analysis.outcome import (
    EXIT_ERRORS,
    EXIT_INCONCLUSIVE,
    EXIT_OK,
    EXIT_USAGE,
    FileOutcome,
    make_outcome,
    worst_exit_code,
)
from analysis.terminal import COLOR_MODES, render_footer, render_outcome, render_run, use_color
from coral_lang.compiler import CompileResult
from coral_lang.diagnostics import ProfileError, render_all
from coral_lang.loading import is_pnml, load_net_file
from coral_lang.profile import VehicleProfile, load_profile

SIGNING_KEY_ENV = "CORAL_SIGNING_KEY"
"""Mirrors `analysis.signing.SIGNING_KEY_ENV`, which is only imported when signing (the
cryptography package takes time to load, and most runs never sign)."""

if TYPE_CHECKING:
    import datetime as dt

    from analysis.signing import SigningKey
    from analysis.verify import VerifyOptions

__all__ = [
    "EXIT_ERRORS",
    "EXIT_INCONCLUSIVE",
    "EXIT_OK",
    "EXIT_USAGE",
    "build_keygen_parser",
    "build_lint_parser",
    "build_parser",
    "build_resign_parser",
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


# -- parsers --------------------------------------------------------------------------


def build_parser() -> argparse.ArgumentParser:
    """The parser for ``coral-check FILE...`` (lint and verify; tests read its help)."""
    parser = argparse.ArgumentParser(
        prog="coral-check",
        description="Check CORAL missions (.coral) and PNML nets (.pnml) before they run: "
        "compile, lint, and prove boundedness, absence of deadlock, reachability of the "
        "final markings, termination (no engine cycle, a final marking always reachable, "
        "every fair run ends in one), no dead transitions, no resource conflicts and the "
        "mission's own assertions. Also: 'coral-check lint FILE...' (lint only, fast, for "
        "pre-commit hooks), 'coral-check verify FILE' (one report, with --certificate), "
        "'coral-check keygen' and 'coral-check resign' (signing keys and their rotation) "
        "and 'coral-check query' (Model Checking Contest queries). "
        "Formats: text for a terminal, json (docs/verify.md), sarif (SARIF 2.1.0 for code "
        "scanning), html (one self-contained page with the net and counterexamples).",
        epilog=EXIT_CODES_HELP,
    )
    parser.add_argument(
        "files", nargs="+", metavar="FILE", help="mission (.coral) or PNML (.pnml) file"
    )
    _add_profile_options(parser)
    _add_output_options(parser, CHECK_FORMATS)
    _add_search_options(parser)
    parser.add_argument(
        "--net-layout",
        choices=NET_LAYOUTS,
        default="auto",
        help="how the html report lays out the net: Graphviz's dot when installed "
        "(auto), Graphviz (graphviz), or coral's own layered layout (builtin)",
    )
    return parser


def build_lint_parser() -> argparse.ArgumentParser:
    """The parser for ``coral-check lint FILE...``."""
    parser = argparse.ArgumentParser(
        prog="coral-check lint",
        description="Compile and lint missions without verifying them: the fast check "
        "for pre-commit hooks and editors. Rules and suppressions: docs/rules.md.",
        epilog=LINT_EXIT_CODES_HELP,
    )
    parser.add_argument(
        "files", nargs="+", metavar="FILE", help="mission (.coral) or PNML (.pnml) file"
    )
    _add_profile_options(parser)
    _add_output_options(parser, LINT_FORMATS)
    return parser


def build_verify_parser() -> argparse.ArgumentParser:
    """The parser for ``coral-check verify``."""
    parser = argparse.ArgumentParser(
        prog="coral-check verify",
        description="Compile a mission (or import a PNML net) and decide its properties: "
        "boundedness, deadlock, final markings, termination, dead transitions, resource "
        "conflicts, and the mission's own assertions. Each verdict is proven, violated "
        "(with a trace) or inconclusive (with the reason). Diagnostics go to stderr, the "
        "report to stdout or OUT.",
        epilog=VERIFY_EXIT_CODES_HELP,
    )
    parser.add_argument("file", metavar="FILE", help="mission (.coral) or PNML (.pnml) file")
    _add_profile_options(parser)
    parser.add_argument(
        "--format", choices=("text", "json"), default="text", help="report format (default text)"
    )
    parser.add_argument("-o", "--output", metavar="OUT", help="write the report here, not stdout")
    _add_color_option(parser)
    _add_search_options(parser)
    parser.add_argument(
        "--certificate",
        metavar="FILE",
        help="also write the pre-mission certificate (net digest, verdicts, date) here; "
        "the runtime runs only nets whose certificate says every property was proven and "
        "is signed by a key it trusts",
    )
    parser.add_argument(
        "--signing-key",
        metavar="KEY",
        help="sign the certificate with this private key (from 'coral-check keygen'; "
        f"default: ${SIGNING_KEY_ENV}, a key file or the PEM itself); without one the "
        "certificate is unsigned and no run accepts it",
    )
    parser.add_argument(
        "--expires",
        metavar="DAYS|DATE",
        help="the certificate expires after DAYS days, or at the end of DATE (UTC, "
        "e.g. 2026-12-31); default: never",
    )
    return parser


def build_resign_parser() -> argparse.ArgumentParser:
    """The parser for ``coral-check resign``."""
    parser = argparse.ArgumentParser(
        prog="coral-check resign",
        description="Sign a certificate with another key, to rotate keys without "
        "verifying again: the certificate's present signature must be by a key the trust "
        "store trusts and does not revoke, and must match its content; only the "
        "signature changes, so a run still checks everything else (net, profile, "
        "expiry, checker revision). A certificate whose signer is revoked must be "
        "verified again (coral-check verify ... --certificate FILE --signing-key KEY).",
        epilog="exit codes: 0 re-signed, 2 bad usage, an unusable key or trust store, or a "
        "certificate that cannot be re-signed (the message says why)",
    )
    parser.add_argument("certificate", metavar="CERT", help="the certificate to re-sign")
    parser.add_argument(
        "--signing-key",
        metavar="KEY",
        help=f"the new private key (default: ${SIGNING_KEY_ENV}, a key file or the PEM itself)",
    )
    parser.add_argument(
        "--trusted-keys",
        metavar="PATH",
        help="trust store to check the present signature against: a file of public key "
        "lines or a folder of .pub files, with any revocations (default: "
        "$XDG_CONFIG_HOME/coral/trusted_keys)",
    )
    parser.add_argument(
        "-o", "--output", metavar="OUT", help="write the re-signed certificate here (default: CERT)"
    )
    return parser


def build_keygen_parser() -> argparse.ArgumentParser:
    """The parser for ``coral-check keygen``."""
    parser = argparse.ArgumentParser(
        prog="coral-check keygen",
        description="Create an Ed25519 key pair for signing certificates: the private key "
        "in KEY (PEM, mode 0600: keep it with the verifier) and the public key in KEY.pub "
        "(one line: give it to the operators, whose coral-run trusts it with "
        "--trusted-keys). Prints the key id. Never overwrites a file.",
        epilog="exit codes: 0 written, 2 bad usage or a file that exists or cannot be written",
    )
    parser.add_argument("--out", required=True, metavar="KEY", help="private key file to create")
    parser.add_argument(
        "--comment",
        metavar="TEXT",
        help="written after the public key, to tell keys apart (default USER@HOST)",
    )
    return parser


def _add_profile_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--profile",
        action="append",
        default=[],
        metavar="YAML",
        help="vehicle profile to use instead of the bundled one of that name (repeatable)",
    )
    parser.add_argument(
        "--include-path",
        action="append",
        default=[],
        metavar="DIR",
        help="a folder missions may include files from besides their own (repeatable, "
        "searched in order after the including file's folder)",
    )
    parser.add_argument(
        "--link-rtt",
        type=non_negative_float,
        default=DEFAULT_LINK_RTT_S,
        metavar="SECONDS",
        help="worst round trip of the link to the vehicle, for the query time-out rule "
        f"CORAL206 (default {DEFAULT_LINK_RTT_S:g})",
    )


def _add_output_options(parser: argparse.ArgumentParser, formats: Sequence[str]) -> None:
    parser.add_argument(
        "--format",
        choices=formats,
        default="text",
        help=f"output format: {', '.join(formats)} (default text)",
    )
    parser.add_argument(
        "-o", "--output", metavar="OUT", help="write the output here, not to stdout"
    )
    _add_color_option(parser)
    parser.add_argument(
        "-q",
        "--quiet",
        action="store_true",
        help="text: print only problems (diagnostics, reports that are not all proven)",
    )


def _add_color_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--color",
        choices=COLOR_MODES,
        default="auto",
        help="colour text output: auto (only on a terminal, and not when NO_COLOR is "
        "set), always, never",
    )


def _add_search_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--max-states",
        type=positive_int,
        default=2_000_000,
        metavar="N",
        help="state budget of the explicit search (default 2000000)",
    )
    parser.add_argument(
        "--time-limit",
        type=positive_float,
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
        "--max-deadlocks",
        type=positive_int,
        default=20,
        metavar="N",
        help="list at most N dead non-final markings, each with its own shortest trace; "
        "the rest are counted (default 20)",
    )
    parser.add_argument(
        "--max-edges",
        type=positive_int,
        default=8_000_000,
        metavar="N",
        help="edge budget of the reachability graph that the termination properties "
        "need, 12 bytes an edge; past it they are inconclusive (default 8000000)",
    )


# -- entry point --------------------------------------------------------------------------


def main(argv: Sequence[str] | None = None) -> int:
    """Run coral-check; returns the exit code (see the module docstring).

    ``coral-check lint ...``, ``coral-check verify ...``, ``coral-check keygen ...``,
    ``coral-check resign ...`` and ``coral-check query ...`` are subcommands; anything
    else is a list of files to lint and verify (name a file called ``lint`` or
    ``verify`` as ``./lint``).
    """
    args_list = list(sys.argv[1:] if argv is None else argv)
    try:
        if args_list[:1] == ["verify"]:
            return _verify_main(args_list[1:])
        if args_list[:1] == ["lint"]:
            return _check_main(args_list[1:], lint_only=True)
        if args_list[:1] == ["keygen"]:
            return _keygen_main(args_list[1:])
        if args_list[:1] == ["resign"]:
            return _resign_main(args_list[1:])
        if args_list[:1] == ["query"]:
            from analysis.query_cli import query_main

            return query_main(args_list[1:])
        return _check_main(args_list, lint_only=False)
    except BrokenPipeError:  # the reader went away (`coral-check ... | head`)
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # no second error when Python flushes
        return EXIT_USAGE


def _parse(parser: argparse.ArgumentParser, argv: Sequence[str]) -> argparse.Namespace | int:
    """Parsed arguments, or the exit code when argparse stopped (help: 0, misuse: 2)."""
    try:
        return parser.parse_args(argv)
    except SystemExit as exc:
        return EXIT_OK if exc.code == 0 else EXIT_USAGE


def _error(message: str) -> None:
    print(f"coral-check: error: {message}", file=sys.stderr)


def _output_folder_ok(output: str | None) -> bool:
    if output and Path(output).is_dir():
        _error(f"cannot write '{output}': it is a directory")
        return False
    if output and not Path(output).resolve().parent.is_dir():
        _error(f"cannot write '{output}': no such folder")
        return False
    return True


def _include_path_ok(folders: list[str]) -> bool:
    for folder in folders:
        if not Path(folder).is_dir():
            _error(f"--include-path {folder}: no such folder")
            return False
    return True


def _profiles(paths: list[str]) -> list[VehicleProfile] | None:
    profiles: list[VehicleProfile] = []
    for profile_path in paths:
        try:
            profiles.append(load_profile(profile_path))
        except ProfileError as exc:
            _error(str(exc))
            return None
    return profiles


def _unreadable(file: str) -> str | None:
    """Why ``file`` cannot be read as input at all (None when it can)."""
    path = Path(file)
    if not path.exists():
        return "no such file"
    if path.is_dir():
        return "it is a directory"
    from coral_lang.safefile import MISSION_LIMIT, PNML_LIMIT, UnreadableFile, read_file_bytes

    try:
        data = read_file_bytes(path, PNML_LIMIT if is_pnml(path) else MISSION_LIMIT)
    except UnreadableFile as exc:
        return exc.reason
    if not is_pnml(path):  # XML declares its own encoding; the PNML reader checks it
        try:
            data.decode("utf-8")
        except UnicodeDecodeError as exc:
            return f"not UTF-8 text ({exc.reason} at byte {exc.start})"
    return None


def _write(text: str, output: str | None) -> bool:
    if not output:
        sys.stdout.write(text)
        return True
    try:
        Path(output).write_text(text, encoding="utf-8")
    except OSError as exc:
        _error(f"cannot write '{output}': {exc.strerror}")
        return False
    return True


def _verify_options(args: argparse.Namespace, structural: bool) -> VerifyOptions:
    from analysis.progress import ProgressPrinter
    from analysis.verify import VerifyOptions

    return VerifyOptions(
        max_states=args.max_states,
        time_limit=args.time_limit,
        por=args.por,
        structural=structural and not args.no_structure,
        progress=ProgressPrinter(sys.stderr, force=True) if args.progress else None,
        max_deadlocks=args.max_deadlocks,
        max_edges=args.max_edges,
    )


# -- coral-check FILE... and coral-check lint FILE... --------------------------------------


def _check_main(argv: Sequence[str], lint_only: bool) -> int:
    parser = build_lint_parser() if lint_only else build_parser()
    args = _parse(parser, argv)
    if isinstance(args, int):
        return args
    if not _output_folder_ok(args.output):
        return EXIT_USAGE
    profiles = _profiles(args.profile)
    if profiles is None or not _include_path_ok(args.include_path):
        return EXIT_USAGE
    # The structural facts (invariants, siphons...) appear in JSON and HTML only.
    options = None if lint_only else _verify_options(args, args.format in ("json", "html"))
    lint_options = LintOptions(link_rtt_s=args.link_rtt)
    streaming = args.format == "text" and not args.output
    color = use_color(args.color, sys.stdout, os.environ) if streaming else args.color == "always"
    outcomes: list[FileOutcome] = []
    printed = False
    for file in args.files:
        outcome = _check_file(file, profiles, lint_options, options, args.include_path)
        outcomes.append(outcome)
        if streaming:  # a terminal sees each file as soon as it is done
            block = render_outcome(outcome, lint_only=lint_only, color=color, quiet=args.quiet)
            if block:
                sys.stdout.write(("\n" if printed else "") + block + "\n")
                sys.stdout.flush()
                printed = True
    if streaming:
        footer = render_footer(outcomes, args.quiet)
        if footer:
            sys.stdout.write(("\n" if printed else "") + footer + "\n")
    elif not _write(_render(outcomes, args, lint_only, color), args.output):
        return EXIT_USAGE
    return worst_exit_code(o.exit_code() for o in outcomes)


def _check_file(
    file: str,
    profiles: list[VehicleProfile],
    lint_options: LintOptions,
    options: VerifyOptions | None,
    include_path: Sequence[str] = (),
) -> FileOutcome:
    """Compile (or import), verify unless ``options`` is None, and lint one file."""
    problem = _unreadable(file)
    if problem is not None:
        _error(f"cannot read '{file}': {problem}")
        return FileOutcome(path=file, input_error=problem)
    result = load_net_file(Path(file), profiles, include_path=include_path)
    if result.net is None or result.errors:
        return make_outcome(file, result.diagnostics, sources=result.sources)
    if options is None:
        findings = lint(result, lint_options)
        return make_outcome(
            file, [*result.diagnostics, *findings], net=result.net, sources=result.sources
        )
    from analysis.verify import run_verification

    verification = run_verification(result.net, options)
    # One exploration serves both: lint's race rule reads the verifier's state space.
    findings = lint(result, lint_options, verification.space)
    return make_outcome(
        file,
        [*result.diagnostics, *findings],
        report=verification.report,
        net=result.net,
        sources=result.sources,
    )


def _render(
    outcomes: list[FileOutcome], args: argparse.Namespace, lint_only: bool, color: bool
) -> str:
    if args.format == "text":
        return render_run(outcomes, lint_only=lint_only, color=color, quiet=args.quiet)
    from analysis.certificate import tool_version

    if args.format == "json":
        from analysis.outcome import to_json_document

        document = to_json_document(outcomes, "lint" if lint_only else "check", tool_version())
        return json.dumps(document, indent=2) + "\n"
    if args.format == "sarif":
        from analysis.sarif import to_sarif

        return json.dumps(to_sarif(outcomes, tool_version=tool_version()), indent=2) + "\n"
    from analysis.html_report import render_html

    return render_html(outcomes, layout=args.net_layout, tool_version=tool_version())


# -- coral-check verify FILE -----------------------------------------------------------


def _load(
    file: str, profiles: list[VehicleProfile], include_path: Sequence[str] = ()
) -> CompileResult | None:
    """Compile or import ``file``, printing diagnostics; None if it cannot be read."""
    problem = _unreadable(file)
    if problem is not None:
        _error(f"cannot read '{file}': {problem}")
        return None
    result = load_net_file(Path(file), profiles, include_path=include_path)
    if result.diagnostics:
        print(render_all(result.diagnostics, result.sources), file=sys.stderr)
    return result


def _verify_main(argv: list[str]) -> int:
    from analysis.verify import run_verification

    args = _parse(build_verify_parser(), argv)
    if isinstance(args, int):
        return args
    if not _output_folder_ok(args.output):
        return EXIT_USAGE
    profiles = _profiles(args.profile)
    if profiles is None or not _include_path_ok(args.include_path):
        return EXIT_USAGE
    signing = _certificate_settings(args)
    if signing is None:
        return EXIT_USAGE
    key, expires = signing
    result = _load(args.file, profiles, args.include_path)
    if result is None:
        return EXIT_USAGE
    if result.net is None or result.errors:
        print(f"{args.file}: not verified: fix the errors above first", file=sys.stderr)
        return EXIT_ERRORS
    options = _verify_options(args, structural=True)
    verification = run_verification(result.net, options)
    findings = lint(result, LintOptions(link_rtt_s=args.link_rtt), verification.space)
    if findings:
        print(render_all(findings, result.sources), file=sys.stderr)
    report = verification.report
    if args.format == "json":
        text = json.dumps(report.to_dict(), indent=2) + "\n"
    else:
        color = (
            use_color(args.color, sys.stdout, os.environ)
            if not args.output
            else args.color == "always"
        )
        text = report.render_text(color=color) + "\n"
    if args.certificate:
        from analysis.certificate import make_certificate, write_certificate
        from coral_lang.mission import Mission

        # The certificate records the profile the mission compiled against: the runtime
        # refuses it once that profile changes in anything the mission depends on.
        mission = Mission.from_result(result, Path(args.file), profiles)
        certificate = make_certificate(
            report, options, profile_content=mission.profile_content(), expires=expires
        )
        if key is not None:
            from analysis.signing import sign_certificate

            certificate = sign_certificate(certificate, key)
        try:
            write_certificate(certificate, args.certificate)
        except OSError as exc:
            _error(f"cannot write '{args.certificate}': {exc.strerror}")
            return EXIT_USAGE
        if key is not None:
            note = f"signed by key {key.public.key_id}"
        else:
            note = (
                "UNSIGNED: no run accepts it; sign with --signing-key KEY "
                f"(or ${SIGNING_KEY_ENV}), made by 'coral-check keygen --out KEY'"
            )
        print(f"coral-check: certificate written to {args.certificate} ({note})", file=sys.stderr)
    if not _write(text, args.output):
        return EXIT_USAGE
    return report.exit_code()


def _certificate_settings(
    args: argparse.Namespace,
) -> tuple[SigningKey | None, dt.datetime | None] | None:
    """The signing key and expiry for ``--certificate``, or None (after saying why)
    when a key cannot be used or ``--expires`` is not a future date. Read before
    verifying, so a bad key fails in a second, not after a long search."""
    key: SigningKey | None = None
    expires: dt.datetime | None = None
    if not args.certificate:
        for option in ("signing_key", "expires"):
            if getattr(args, option) is not None:
                _error(f"--{option.replace('_', '-')} applies to --certificate FILE; add it")
                return None
        return key, expires
    from analysis.signing import KeyFileError, load_signing_key, signing_key_from_env

    try:
        if args.signing_key is not None:
            key = load_signing_key(args.signing_key)
        else:
            key = signing_key_from_env(os.environ)
    except KeyFileError as exc:
        _error(str(exc))
        return None
    if args.expires is not None:
        import datetime as dt

        from analysis.certificate import parse_expires

        try:
            expires = parse_expires(args.expires, dt.datetime.now(dt.UTC))
        except ValueError as exc:
            _error(f"--expires: {exc}")
            return None
    return key, expires


# -- coral-check keygen ---------------------------------------------------------------------


def _keygen_main(argv: list[str]) -> int:
    import getpass
    import socket

    from analysis.signing import KeyFileError, generate_key_files, public_path

    args = _parse(build_keygen_parser(), argv)
    if isinstance(args, int):
        return args
    comment = args.comment
    if comment is None:
        try:
            comment = f"{getpass.getuser()}@{socket.gethostname()}"
        except (OSError, KeyError):
            comment = "coral"
    try:
        public = generate_key_files(args.out, comment)
    except KeyFileError as exc:
        _error(str(exc))
        return EXIT_USAGE
    print(f"key id: {public.key_id}")
    print(f"private key: {args.out} (keep it secret; the verifier signs with it)")
    print(f"public key: {public_path(Path(args.out))} (give it to operators: --trusted-keys)")
    return EXIT_OK


# -- coral-check resign -------------------------------------------------------------------


def _resign_main(argv: list[str]) -> int:
    from analysis.certificate import CertificateError, resign_certificate, write_certificate
    from analysis.signing import (
        KeyFileError,
        load_signing_key,
        resolve_trust_store,
        signing_key_from_env,
    )

    args = _parse(build_resign_parser(), argv)
    if isinstance(args, int):
        return args
    output = Path(args.output or args.certificate)
    if not _output_folder_ok(str(output)):
        return EXIT_USAGE
    key: SigningKey | None
    try:
        if args.signing_key is not None:
            key = load_signing_key(args.signing_key)
        else:
            key = signing_key_from_env(os.environ)
        trusted = resolve_trust_store(args.trusted_keys, os.environ)
    except KeyFileError as exc:
        _error(str(exc))
        return EXIT_USAGE
    if key is None:
        _error(f"no signing key: give --signing-key KEY (or ${SIGNING_KEY_ENV})")
        return EXIT_USAGE
    try:
        certificate = resign_certificate(args.certificate, key, trusted)
    except CertificateError as exc:
        _error(f"not re-signed: {exc}")
        return EXIT_USAGE
    old = _certificate_signer(args.certificate)
    partial = output.with_name(f".{output.name}.{os.getpid()}.tmp")
    try:  # a new file renamed over the old: never a half-written certificate
        write_certificate(certificate, partial)
        partial.replace(output)
    except OSError as exc:
        partial.unlink(missing_ok=True)
        _error(f"cannot write '{output}': {exc.strerror}")
        return EXIT_USAGE
    print(
        f"coral-check: {output}: re-signed by key {key.public.key_id} (was {old}); once "
        "every certificate is re-signed, revoke the old key in the trust stores",
        file=sys.stderr,
    )
    if trusted.get(key.public.key_id) is None:
        print(
            f"coral-check: note: key {key.public.key_id} is not in the trust store "
            f"({trusted.describe()}): add its .pub line there before runs use {output}",
            file=sys.stderr,
        )
    return EXIT_OK


def _certificate_signer(path: str) -> str:
    """The key id a certificate file names as its signer ("unknown" if unreadable)."""
    from analysis.certificate import CertificateError, read_certificate

    try:
        signature = read_certificate(Path(path)).get("signature")
    except CertificateError:
        return "unknown"
    kid = signature.get("key_id") if isinstance(signature, dict) else None
    return kid if isinstance(kid, str) else "unknown"


if __name__ == "__main__":
    sys.exit(main())
