"""``coral-check [check] FILE...``, ``coral-check lint FILE...``, ``coral-check verify FILE``.

All three check each file through the one pipeline, `analysis.pipeline.check_file`, and
differ only in what they show: ``check`` and ``lint`` render a run of outcomes (text,
JSON, SARIF, HTML); ``verify`` shows one file's report with the diagnostics on stderr,
and can write its certificate. Their JSON is the one document of
`analysis.outcome.to_json_document`, whose ``command`` says which ran.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from analysis.cli_options import PROG, Settings, output_conflict, read_conflict, resolve
from analysis.outcome import EXIT_ERRORS, EXIT_USAGE, FileOutcome, worst_exit_code
from coral_lang.cliframe import print_error, tool_version

if TYPE_CHECKING:
    import datetime as dt

    from analysis.signing import SigningKey
    from analysis.timed.results import TimedReport
    from analysis.timed.schedule import TimedSchedule
    from analysis.verify import VerifyOptions

__all__ = [
    "SIGNING_KEY_ENV",
    "STDIN",
    "read_stdin_once",
    "refused_output",
    "run_check",
    "run_verify",
    "schedule_files",
]

STDIN = "-"
"""The file name that means standard input (shown as ``<stdin>``)."""

SIGNING_KEY_ENV = "CORAL_SIGNING_KEY"
"""Mirrors `analysis.signing.SIGNING_KEY_ENV`, which is only imported when signing (the
cryptography package takes time to load, and most runs never sign)."""


def read_stdin_once(files: Sequence[str]) -> str | None:
    """The text of standard input when ``-`` is among ``files`` (None otherwise).

    Raises:
        ValueError: ``-`` was given more than once (standard input is read once).
    """
    if files.count(STDIN) > 1:
        raise ValueError("'-' (standard input) can be given only once")
    return sys.stdin.read() if STDIN in files else None


def _write(text: str, output: str | Path | None) -> bool:
    if not output:
        sys.stdout.write(text)
        return True
    try:
        Path(output).write_text(text, encoding="utf-8")
    except OSError as exc:
        print_error(PROG, f"cannot write '{output}': {exc.strerror}")
        return False
    return True


def _check_one(
    file: str, settings: Settings, verify: VerifyOptions | None, stdin: str | None
) -> FileOutcome:
    from analysis.pipeline import check_file

    options = settings.check_options(verify=verify, text=stdin if file == STDIN else None)
    outcome = check_file(file, options)
    if outcome.input_error is not None:
        print_error(PROG, f"cannot read '{outcome.path}': {outcome.input_error}")
    return outcome


def refused_output(
    outputs: Sequence[tuple[str, str | Path | None]],
    settings: Settings,
    outcome: FileOutcome | None = None,
    *,
    extra: Sequence[tuple[str, str | Path | None]] = (),
) -> bool:
    """Whether an output would overwrite a file the run read (`read_conflict`), after
    saying so: checked once the settings are known, then after each file is compiled
    (its includes are known only then), always before anything is written."""
    conflict = read_conflict(outputs, settings, () if outcome is None else (outcome,), extra=extra)
    if conflict is not None:
        print_error(PROG, conflict)
    return conflict is not None


# -- check and lint ---------------------------------------------------------------------


def run_check(args: argparse.Namespace, *, lint_only: bool) -> int:
    """``coral-check check`` (lint and verify) or ``coral-check lint``; the exit code."""
    from analysis.terminal import render_footer, render_outcome, use_color

    conflict = output_conflict([("-o", args.output)], args.files)
    if conflict is not None:
        print_error(PROG, conflict)
        return EXIT_USAGE
    try:
        stdin = read_stdin_once(args.files)
    except ValueError as exc:
        print_error(PROG, str(exc))
        return EXIT_USAGE
    settings = resolve(args)
    if settings is None or refused_output([("-o", args.output)], settings):
        return EXIT_USAGE
    # The structural facts (invariants, siphons...) appear in JSON and HTML only.
    verify = (
        None
        if lint_only
        else settings.verify_options(args, structural=args.format in ("json", "html"))
    )
    streaming = args.format == "text" and not args.output
    color = use_color(args.color, sys.stdout, os.environ) if streaming else args.color == "always"
    outcomes: list[FileOutcome] = []
    printed = False
    for file in args.files:
        outcome = _check_one(file, settings, verify, stdin)
        if refused_output([("-o", args.output)], settings, outcome):
            return EXIT_USAGE  # before the next file's work, and before writing anything
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


def _render(
    outcomes: list[FileOutcome], args: argparse.Namespace, lint_only: bool, color: bool
) -> str:
    if args.format == "text":
        from analysis.terminal import render_run

        return render_run(outcomes, lint_only=lint_only, color=color, quiet=args.quiet)
    if args.format == "json":
        return _json(outcomes, "lint" if lint_only else "check")
    if args.format == "sarif":
        from analysis.sarif import to_sarif

        return json.dumps(to_sarif(outcomes, tool_version=tool_version()), indent=2) + "\n"
    from analysis.html_report import render_html

    return render_html(outcomes, layout=args.net_layout, tool_version=tool_version())


def _json(outcomes: list[FileOutcome], command: str) -> str:
    from analysis.outcome import to_json_document

    return json.dumps(to_json_document(outcomes, command, tool_version()), indent=2) + "\n"


# -- verify -----------------------------------------------------------------------------


def run_verify(args: argparse.Namespace) -> int:
    """``coral-check verify FILE``: diagnostics to stderr, the report to stdout or
    ``-o``, the certificate to ``--certificate``; the exit code."""
    from coral_lang.diagnostics import render_all

    conflict = output_conflict(
        [("-o", args.output), ("--certificate", args.certificate)], [args.file]
    )
    if conflict is not None:
        print_error(PROG, conflict)
        return EXIT_USAGE
    signing = _certificate_settings(args)
    if signing is None:
        return EXIT_USAGE
    key, expires = signing
    settings = resolve(args)
    outputs = [("-o", args.output), ("--certificate", args.certificate)]
    key_file = [("the signing key", args.signing_key)]
    if settings is None or refused_output(outputs, settings, extra=key_file):
        return EXIT_USAGE
    stdin = read_stdin_once([args.file])
    verify = settings.verify_options(args, structural=True)
    outcome = _check_one(args.file, settings, verify, stdin)
    if outcome.input_error is not None or refused_output(outputs, settings, outcome):
        return EXIT_USAGE
    schedules: list[tuple[Path, TimedSchedule]] = []
    if args.export_schedules is not None and outcome.report is not None:
        timed = outcome.report.timed
        if timed is not None:
            folder = Path(args.export_schedules)
            schedules = [(folder / name, s) for name, s in schedule_files(timed)]
        named = [("--export-schedules", path) for path, _ in schedules]
        if refused_output([*outputs, *named], settings, outcome):
            return EXIT_USAGE
    shown = outcome.path
    if outcome.diagnostics:
        print(render_all(outcome.diagnostics, outcome.sources), file=sys.stderr)
    if outcome.net is None or outcome.errors:
        print(f"{shown}: not verified: fix the errors above first", file=sys.stderr)
        return EXIT_ERRORS
    report = outcome.report
    if report is None:  # a part of a mission: its mission is what gets verified
        import shlex

        mission = outcome.part_of
        if args.certificate and mission is not None:
            print_error(
                PROG,
                f"{shown} is a part of {mission}: certificates are for whole missions: "
                f"{PROG} verify {shlex.quote(mission)} --certificate "
                f"{shlex.quote(str(args.certificate))}",
            )
            return EXIT_USAGE
        hint = f": coral-check verify {shlex.quote(mission)}" if mission else ""
        print(
            f"{shown}: a part of {mission or 'a mission'}, not verified on its own; "
            f"verify the mission{hint}",
            file=sys.stderr,
        )
    if args.format == "json":
        text = _json([outcome], "verify")
    elif report is None:
        text = ""
    else:
        from analysis.terminal import render_report, use_color

        color = (
            use_color(args.color, sys.stdout, os.environ)
            if not args.output
            else args.color == "always"
        )
        text = render_report(outcome, color) + "\n"
    if (
        args.certificate
        and report is not None
        and not _write_certificate(args, outcome, settings, verify, key, expires)
    ):
        return EXIT_USAGE
    if args.export_schedules is not None and not _write_schedules(
        Path(args.export_schedules), schedules, outcome
    ):
        return EXIT_USAGE
    if not _write(text, args.output):
        return EXIT_USAGE
    return outcome.exit_code()


def schedule_files(timed: TimedReport) -> list[tuple[str, TimedSchedule]]:
    """The schedules ``--export-schedules`` writes, with their file names: the best and
    worst case to each final marking (``worst-mission_complete.json``), each query's
    time-out counterexample (``timeout-check_depth.json``) and each missed deadline's
    (``deadline-assert-3.json``). Names are stable across runs, so a script can find
    them; a name taken twice gets ``-2``, ``-3``..."""
    from analysis.report import Verdict

    named: list[tuple[str, TimedSchedule]] = []
    for final in timed.finals:
        tokens = sorted(final.final.items())
        marking = "+".join(p if n == 1 else f"{p}_x{n}" for p, n in tokens)
        named.append((f"worst-{marking or 'empty'}", final.worst))
        named.append((f"best-{marking or 'empty'}", final.best))
    for query in timed.queries:
        if query.verdict is Verdict.VIOLATED and query.counterexample is not None:
            named.append((f"timeout-{query.transition}", query.counterexample))
    for deadline in timed.deadlines:
        if deadline.verdict is Verdict.VIOLATED and deadline.counterexample is not None:
            named.append((f"deadline-assert-{deadline.index}", deadline.counterexample))
    files: list[tuple[str, TimedSchedule]] = []
    taken: set[str] = set()
    for stem, schedule in named:
        stem = "".join(c if c.isalnum() or c in "_+-." else "_" for c in stem)
        name, number = f"{stem}.json", 1
        while name.lower() in taken:  # case-insensitive file systems too
            number += 1
            name = f"{stem}-{number}.json"
        taken.add(name.lower())
        files.append((name, schedule))
    return files


def _write_schedules(
    folder: Path, schedules: list[tuple[Path, TimedSchedule]], outcome: FileOutcome
) -> bool:
    """Write the schedules (`schedule_files`) into ``folder``, made if needed; say how
    many, or why there are none (an untimed or unverified report)."""
    if outcome.report is None or outcome.report.timed is None:
        print(
            f"{PROG}: no schedules written: {outcome.path} has no timed analysis "
            "(it needs the mission's vehicle profile)",
            file=sys.stderr,
        )
        return True
    try:
        folder.mkdir(parents=True, exist_ok=True)
        for path, schedule in schedules:
            schedule.write(path)
    except OSError as exc:
        print_error(PROG, f"cannot write schedules to '{folder}': {exc.strerror}")
        return False
    print(f"{PROG}: {len(schedules)} schedule(s) written to {folder}", file=sys.stderr)
    return True


def _write_certificate(
    args: argparse.Namespace,
    outcome: FileOutcome,
    settings: Settings,
    verify: VerifyOptions,
    key: SigningKey | None,
    expires: dt.datetime | None,
) -> bool:
    from analysis.certificate import make_certificate, write_certificate
    from coral_lang.mission import Mission

    assert outcome.result is not None and outcome.report is not None
    # The certificate records the profile the mission compiled against: the runtime
    # refuses it once that profile changes in anything the mission depends on.
    path = None if args.file == STDIN else Path(args.file)
    mission = Mission.from_result(outcome.result, path, settings.profiles)
    certificate = make_certificate(
        outcome.report,
        verify,
        profile_content=mission.profile_content(),
        expires=expires,
        profiles=() if mission.profile is None else (mission.profile,),
    )
    if key is not None:
        from analysis.signing import sign_certificate

        certificate = sign_certificate(certificate, key)
    try:
        write_certificate(certificate, args.certificate)
    except OSError as exc:
        print_error(PROG, f"cannot write '{args.certificate}': {exc.strerror}")
        return False
    if key is not None:
        note = f"signed by key {key.public.key_id}"
    else:
        note = (
            "UNSIGNED: no run accepts it; sign with --signing-key KEY "
            f"(or ${SIGNING_KEY_ENV}), made by 'coral-check keygen --out KEY'"
        )
    print(f"{PROG}: certificate written to {args.certificate} ({note})", file=sys.stderr)
    return True


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
                print_error(
                    PROG, f"--{option.replace('_', '-')} applies to --certificate FILE; add it"
                )
                return None
        return key, expires
    from analysis.signing import KeyFileError, load_signing_key, signing_key_from_env

    try:
        if args.signing_key is not None:
            key = load_signing_key(args.signing_key)
        else:
            key = signing_key_from_env(os.environ)
    except KeyFileError as exc:
        print_error(PROG, str(exc))
        return None
    if args.expires is not None:
        import datetime as dt

        from analysis.certificate import parse_expires

        try:
            expires = parse_expires(args.expires, dt.datetime.now(dt.UTC))
        except ValueError as exc:
            print_error(PROG, f"--expires: {exc}")
            return None
    return key, expires
