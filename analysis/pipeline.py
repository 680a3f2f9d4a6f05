"""One check pipeline: read -> compile (or import) -> verify -> lint -> `FileOutcome`.

``coral-check FILE...``, ``coral-check lint``, ``coral-check verify`` and the runtime's
gate all check a file through `check_file`, so they agree on what a file's outcome is,
and every output format (text, JSON, SARIF, HTML, certificate) renders the same outcome.

Three things change what a file's outcome holds:

* ``select`` / ``ignore`` (``--select`` / ``--ignore``, ruff-like) keep or drop lint
  findings by code or code prefix (``CORAL2`` is every CORAL2xx). They never touch the
  compiler's diagnostics: a mission that does not compile cannot be made to pass.
* ``text``: the mission came from standard input (``coral-check -``); it is shown as
  ``<stdin>`` and its includes resolve from the current folder.
* a *part* of a mission (a file whose header says ``# coral: part of FILE.coral``,
  `coral_lang.compiler.CompileResult.part_of`) is compiled and linted within its whole
  mission but not verified: the mission is verified when it is checked itself. Its
  outcome keeps the diagnostics located in the part and says which mission it was
  checked with (status ``part``).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from analysis.budget import Budget
from analysis.lint import LintOptions, lint
from analysis.outcome import FileOutcome, make_outcome
from coral_lang.compiler import CompileResult, compile_source
from coral_lang.diagnostics import Diagnostic
from coral_lang.loading import is_pnml, load_net_file
from coral_lang.profile import VehicleProfile

if TYPE_CHECKING:
    from analysis.verify import VerifyOptions

__all__ = [
    "STDIN",
    "STDIN_NAME",
    "CheckOptions",
    "check_file",
    "is_selected",
    "unreadable",
]

STDIN = "-"
"""The file name that means standard input (its text is `CheckOptions.text`)."""
STDIN_NAME = "<stdin>"
"""How a mission read from standard input is named in diagnostics and reports."""


@dataclass(frozen=True)
class CheckOptions:
    """How to check a file.

    Attributes:
        profiles: Vehicle profiles to compile against before the bundled ones.
        include_path: Folders a mission's includes may come from besides its own.
        lint: Settings of the lint rules.
        verify: Settings of the verification; None checks without verifying (lint only).
        select: Lint codes or code prefixes to report (empty: every rule).
        ignore: Lint codes or code prefixes never to report; wins over ``select``.
        text: The file's content when it came from standard input (the file is then
            `STDIN`); None reads the file.
    """

    profiles: Sequence[VehicleProfile] = ()
    include_path: Sequence[str | Path] = ()
    lint: LintOptions = field(default_factory=LintOptions)
    verify: VerifyOptions | None = None
    select: tuple[str, ...] = ()
    ignore: tuple[str, ...] = ()
    text: str | None = None


def is_selected(code: str, select: Sequence[str] = (), ignore: Sequence[str] = ()) -> bool:
    """Whether a lint finding with ``code`` is reported: it matches a selector when it
    starts with it; an empty ``select`` selects every code; ``ignore`` wins."""
    if any(code.startswith(prefix) for prefix in ignore):
        return False
    return not select or any(code.startswith(prefix) for prefix in select)


def _selected(findings: Iterable[Diagnostic], options: CheckOptions) -> list[Diagnostic]:
    return [d for d in findings if is_selected(d.code, options.select, options.ignore)]


def unreadable(file: str | Path) -> str | None:
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


def _unreadable_text(text: str) -> str | None:
    from coral_lang.safefile import MISSION_LIMIT

    size = len(text.encode("utf-8", errors="surrogatepass"))
    if size > MISSION_LIMIT:
        return f"{size} bytes, over the limit of {MISSION_LIMIT}"
    return None


def _load(file: str | Path, options: CheckOptions) -> tuple[str, CompileResult] | str:
    """The name to show and the compile result; or why the input cannot be read."""
    if options.text is not None:
        problem = _unreadable_text(options.text)
        if problem is not None:
            return problem
        named_stdin = str(file) == STDIN
        name = STDIN_NAME if named_stdin else str(file)
        base = Path.cwd() if named_stdin else Path(file).parent
        result = compile_source(
            options.text, name, options.profiles, base, include_path=options.include_path
        )
        return name, result
    problem = unreadable(file)
    if problem is not None:
        return problem
    result = load_net_file(Path(file), options.profiles, include_path=options.include_path)
    return str(file), result


def check_file(
    file: str | Path, options: CheckOptions, *, budget: Budget | None = None
) -> FileOutcome:
    """Compile (or import) ``file``, verify it unless ``options.verify`` is None, lint it.

    Never raises for bad input: a file that cannot be read is an outcome with
    ``input_error`` set, a mission with errors an outcome with those diagnostics.

    The verification's time limit (``options.verify.time_limit``) is counted from here,
    before the file is read: reading a large PNML net takes seconds, and the limit
    bounds the whole check of the file, not only the analysis after it. ``budget``: the
    caller's, started before (tests pass one on a fake clock); the time limit is then
    a slice of it.
    """
    if options.verify is not None:
        limit = options.verify.time_limit
        budget = Budget(limit) if budget is None else budget.child(seconds=limit)
    loaded = _load(file, options)
    if isinstance(loaded, str):
        name = STDIN_NAME if str(file) == STDIN else str(file)
        return FileOutcome(path=name, input_error=loaded)
    name, result = loaded
    if result.part_of is not None:
        return _part_outcome(name, Path(file), result.part_of, result, options)
    if result.net is None or result.errors:
        return make_outcome(name, result.diagnostics, sources=result.sources, result=result)
    if options.verify is None:
        findings = _selected(lint(result, options.lint), options)
        return make_outcome(
            name,
            [*result.diagnostics, *findings],
            net=result.net,
            sources=result.sources,
            result=result,
        )
    from analysis.verify import run_verification

    # Timed analysis takes work times from the profile the mission compiled against
    # (an imported PNML net has none).
    profiles = () if result.profile is None else (result.profile,)
    verification = run_verification(result.net, options.verify, budget=budget, profiles=profiles)
    # One exploration serves both: lint's race rule reads the verifier's state space.
    findings = _selected(lint(result, options.lint, verification.space), options)
    return make_outcome(
        name,
        [*result.diagnostics, *findings],
        report=verification.report,
        net=result.net,
        sources=result.sources,
        result=result,
    )


def _same_file(a: str | Path, b: str | Path) -> bool:
    try:
        return Path(a).resolve() == Path(b).resolve()
    except (OSError, RuntimeError):
        return str(a) == str(b)


def _part_outcome(
    name: str, file: Path, mission: Path, result: CompileResult, options: CheckOptions
) -> FileOutcome:
    """A part's outcome: its whole mission compiled and linted (never verified).

    When the mission compiles, only the diagnostics located in the part (or nowhere in
    particular) are kept: the others belong to the mission's own check. When it does
    not, every error is kept, wherever it is, since the part cannot pass without them
    and each one names its own file.
    """
    if result.net is None or result.errors:
        return make_outcome(
            name, result.diagnostics, sources=result.sources, result=result, part_of=str(mission)
        )
    part = result.part_path or file
    findings = _selected(lint(result, options.lint), options)
    own = [
        d
        for d in [*result.diagnostics, *findings]
        if d.span is None or _same_file(d.span.file, part)
    ]
    return make_outcome(
        name, own, net=result.net, sources=result.sources, result=result, part_of=str(mission)
    )
