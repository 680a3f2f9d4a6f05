"""coral-check's option groups, each defined once, and the settings they resolve to.

``check``, ``lint``, ``verify``, ``export``... share options (profiles, the include
path, rule selection, search budgets). Each group is added by one function here, so
the subcommands spell, type and document them the same way.

Options a configuration file may also set (`analysis.config`) default to None on
the command line; `resolve` then takes the command line's value, else the file's, else
the built-in default: the command line always wins, and ``--help`` says the default.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from analysis.cli_codes import parse_selectors
from analysis.config import Config, ConfigError, resolve_config
from analysis.lint import DEFAULT_LINK_RTT_S, LintOptions
from analysis.terminal import COLOR_MODES
from analysis.timed.options import DEFAULT_TIMED_STATES
from coral_lang.cliframe import (
    existing_folder,
    non_negative_float,
    positive_float,
    positive_int,
    print_error,
    tool_version,
    writable_output,
)
from coral_lang.diagnostics import ProfileError

if TYPE_CHECKING:
    from analysis.outcome import FileOutcome
    from analysis.pipeline import CheckOptions
    from analysis.timed.options import TimedOptions
    from analysis.verify import VerifyOptions
    from coral_lang.profile import VehicleProfile
    from coral_lang.timing import LinkBounds

__all__ = [
    "DEFAULTS",
    "PROG",
    "Settings",
    "add_budget_options",
    "add_color_option",
    "add_config_options",
    "add_explain_option",
    "add_files_argument",
    "add_method_option",
    "add_output_options",
    "add_profile_options",
    "add_rule_options",
    "add_search_options",
    "add_timed_options",
    "add_version_option",
    "memory_amount",
    "memory_limit_of",
    "output_conflict",
    "output_or_stdout",
    "read_conflict",
    "resolve",
]

PROG = "coral-check"
DEFAULT_LINK = "genoa-lisbon"
"""The link timed analysis assumes unless told: the paper's experiment's."""

DEFAULTS: dict[str, Any] = {
    "link_rtt": DEFAULT_LINK_RTT_S,
    "max_states": 2_000_000,
    "time_limit": 120.0,
    "max_edges": 8_000_000,
    "max_deadlocks": 20,
    "por": False,
    "timed": False,
    "link": DEFAULT_LINK,
    "timed_states": DEFAULT_TIMED_STATES,
    "timed_method": "auto",
}
"""Built-in defaults of the options a configuration file may set."""


def output_or_stdout(text: str) -> str:
    """An output file, or ``-`` for standard output (``export --pnml -``)."""
    return text if text == "-" else str(writable_output(text))


def _same_file(a: str | Path, b: str | Path) -> bool:
    """Whether two paths name one file: through symbolic links (realpath) and hard
    links (samefile, when both exist)."""
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:  # one does not exist yet: not the same file
        return False


def output_conflict(
    outputs: Sequence[tuple[str, str | Path | None]], inputs: Sequence[str | Path]
) -> str | None:
    """Why these outputs cannot be written (None when they can): one would overwrite an
    input file (``verify m.coral -o m.coral`` would replace the mission with its report),
    or two outputs are the same file (the second would replace the first).

    Args:
        outputs: ``(option, path)`` pairs, e.g. ``("-o", args.output)``; None (not
            given) and ``-`` (standard output) are never in conflict.
        inputs: The input files; ``-`` (standard input) is skipped.
    """
    return _conflict(outputs, [(f"the input file '{source}'", source) for source in inputs])


def read_conflict(
    outputs: Sequence[tuple[str, str | Path | None]],
    settings: Settings,
    outcomes: Iterable[FileOutcome] = (),
    *,
    extra: Sequence[tuple[str, str | Path | None]] = (),
) -> str | None:
    """Why these outputs cannot be written because the run READ one of them (None when
    they can): a profile or the config file (known once the settings are resolved), a
    file a mission includes (known only once it is compiled: `FileOutcome.sources`), or
    an ``extra`` ``(what, path)`` such as the signing key. `output_conflict` sees only
    the files named on the command line; this is the check made after compiling and
    before writing anything (``check pool.coral -o abort.coral`` would replace a part
    of the mission with its report).
    """
    inputs: list[tuple[str, str | Path]] = [(f"{what} '{p}'", p) for what, p in extra if p]
    inputs += [(f"the profile '{path}'", path) for path in settings.profile_paths]
    if settings.link_path is not None:
        inputs.append((f"the link profile '{settings.link_path}'", settings.link_path))
    if settings.config.path is not None:
        inputs.append((f"the configuration file '{settings.config.path}'", settings.config.path))
    for outcome in outcomes:
        inputs += [
            (f"'{name}', which {outcome.path} reads", name)
            for name in outcome.sources
            if not name.startswith("<")  # <stdin>: no file
        ]
    return _conflict(outputs, inputs)


def _conflict(
    outputs: Sequence[tuple[str, str | Path | None]], inputs: Sequence[tuple[str, str | Path]]
) -> str | None:
    given = [(option, path) for option, path in outputs if path is not None and str(path) != "-"]
    for option, path in given:
        for what, source in inputs:
            if str(source) != "-" and _same_file(path, source):
                return (
                    f"{option} '{path}' is {what}: refusing to overwrite it; "
                    "write the output elsewhere"
                )
    for i, (option, path) in enumerate(given):
        for other, other_path in given[i + 1 :]:
            if _same_file(path, other_path):
                return f"{option} '{path}' and {other} '{other_path}' are the same file"
    return None


# -- option groups ----------------------------------------------------------------------


def add_files_argument(parser: argparse.ArgumentParser, *, many: bool = True) -> None:
    """The files to check: missions (.coral) or PNML nets; ``-`` reads standard input."""
    help_text = "mission (.coral) or PNML (.pnml) file; - reads a mission from standard input"
    if many:
        parser.add_argument("files", nargs="+", metavar="FILE", help=help_text)
    else:
        parser.add_argument("file", metavar="FILE", help=help_text)


def add_profile_options(parser: argparse.ArgumentParser) -> None:
    """``--profile`` and ``--include-path``: what a mission compiles against."""
    group = parser.add_argument_group("compiling")
    group.add_argument(
        "--profile",
        action="append",
        metavar="YAML",
        help="vehicle profile to use instead of the bundled one of that name (repeatable; "
        "replaces the config file's 'profile')",
    )
    group.add_argument(
        "--include-path",
        action="append",
        type=existing_folder,
        metavar="DIR",
        help="a folder missions may include files from besides their own (repeatable, "
        "searched in order after the including file's folder; replaces the config "
        "file's 'include-path')",
    )


def add_rule_options(parser: argparse.ArgumentParser) -> None:
    """``--select``, ``--ignore``, ``--link-rtt``: which lint rules run, and how."""
    group = parser.add_argument_group("lint rules (docs/rules.md)")
    for name, verb in (("--select", "report only"), ("--ignore", "never report")):
        group.add_argument(
            name,
            action="extend",
            type=parse_selectors,
            metavar="CODES",
            help=f"{verb} these lint rules: comma-separated codes or prefixes "
            "(CORAL204,CORAL207 or CORAL2; repeatable; compile errors are always "
            "reported)",
        )
    group.add_argument(
        "--link-rtt",
        type=non_negative_float,
        metavar="SECONDS",
        help="worst round trip of the link to the vehicle, for the query time-out rule "
        f"CORAL206 (default {DEFAULT_LINK_RTT_S:g})",
    )


def add_explain_option(parser: argparse.ArgumentParser) -> None:
    """``--explain CODE``: print the rule's page instead of checking (`analysis.cli`
    runs it). Given, it makes FILE optional, since ``coral-check --explain CODE`` has
    none; the command then refuses any FILE rather than silently skip it."""
    parser.add_argument(
        "--explain",
        action=_ExplainAction,
        metavar="CODE",
        help="print the page of a diagnostic code (e.g. CORAL204) and exit; takes no FILE",
    )


class _ExplainAction(argparse.Action):
    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: Any,
        option_string: str | None = None,
    ) -> None:
        setattr(namespace, self.dest, values)
        # argparse checks required arguments after every one is read, so this reaches
        # the check: only the parser of this one command line is changed.
        for action in parser._actions:
            if not action.option_strings and action.dest in ("files", "file"):
                action.required = False


def add_version_option(parser: argparse.ArgumentParser) -> None:
    """``--version`` on a subcommand too, so ``coral-check m.coral --version`` answers
    as ``coral-check --version`` does rather than call it an unknown argument."""
    if "--version" not in parser._option_string_actions:
        parser.add_argument(
            "--version", action="version", version=f"{PROG} (coral {tool_version()})"
        )


def add_config_options(parser: argparse.ArgumentParser) -> None:
    """``--config FILE`` and ``--no-config`` (`analysis.config`)."""
    group = parser.add_argument_group("configuration")
    choice = group.add_mutually_exclusive_group()
    choice.add_argument(
        "--config",
        metavar="FILE",
        help="read defaults from this TOML file instead of the coral.toml or "
        "pyproject.toml [tool.coral] found from the current folder up",
    )
    choice.add_argument("--no-config", action="store_true", help="ignore configuration files")


def add_output_options(
    parser: argparse.ArgumentParser,
    formats: tuple[str, ...],
    *,
    format_help: str | None = None,
    output_help: str = "write here, not to stdout",
    color: bool = True,
    quiet: bool = True,
) -> argparse._ArgumentGroup:
    """``--format``, ``-o`` and (unless turned off) ``--color`` and ``-q``, in a group
    "output"; the group, for a command's own output options."""
    group = parser.add_argument_group("output")
    group.add_argument(
        "--format",
        choices=formats,
        default="text",
        help=format_help or f"output format: {', '.join(formats)} (default text)",
    )
    group.add_argument("-o", "--output", type=writable_output, metavar="OUT", help=output_help)
    if color:
        add_color_option(group)
    if quiet:
        group.add_argument(
            "-q",
            "--quiet",
            action="store_true",
            help="text: print only problems (diagnostics, reports that are not all proven)",
        )
    return group


def add_color_option(parser: argparse.ArgumentParser | argparse._ArgumentGroup) -> None:
    """``--color``: colour text output only where it helps."""
    parser.add_argument(
        "--color",
        choices=COLOR_MODES,
        default="auto",
        help="colour text output: auto (only on a terminal, and not when NO_COLOR is "
        "set), always, never",
    )


def add_budget_options(
    parser: argparse.ArgumentParser,
    *,
    defaults: Mapping[str, Any] | None = None,
    helps: Mapping[str, str] | None = None,
) -> argparse._ArgumentGroup:
    """``--max-states``, ``--time-limit`` and ``--max-edges``, in a group "verification";
    the group, for a command's own search options.

    Args:
        defaults: Values for the options, by dest name. Without one the option defaults
            to None, so a configuration file may set it (`resolve`).
        helps: Help texts by dest name, for a command whose budget means something else
            (``coral-check query``'s time limit is the whole run's).
    """
    defaults = defaults or {}
    helps = helps or {}
    group = parser.add_argument_group("verification")
    texts = {
        "max_states": f"state budget of the explicit search (default {DEFAULTS['max_states']})",
        "time_limit": "time limit of the whole command: search, proofs, timed analysis "
        f"and structure (default {DEFAULTS['time_limit']:g})",
        "max_edges": "edge budget of the reachability graph that the termination properties "
        "need, 12 bytes an edge; past it they are inconclusive "
        f"(default {DEFAULTS['max_edges']})",
    }
    for dest, kind, metavar in (
        ("max_states", positive_int, "N"),
        ("time_limit", positive_float, "SECONDS"),
        ("max_edges", positive_int, "N"),
    ):
        group.add_argument(
            "--" + dest.replace("_", "-"),
            type=kind,
            default=defaults.get(dest),
            metavar=metavar,
            help=helps.get(dest, texts[dest]),
        )
    group.add_argument(
        "--memory-limit",
        type=memory_amount,
        default=None,
        metavar="BYTES",
        help="resident memory the whole command may use, with a K, M or G suffix "
        "(e.g. 200M); past it the search stops and its open verdicts are inconclusive "
        "(default: 80%% of the cgroup's memory limit, else of the memory available)",
    )
    return group


def memory_amount(text: str) -> int:
    """``--memory-limit``'s type: ``200M`` -> bytes (`analysis.budget.parse_bytes`)."""
    from analysis.budget import parse_bytes

    try:
        return parse_bytes(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def memory_limit_of(args: argparse.Namespace) -> int | None:
    """The command's memory limit: ``--memory-limit``, else the machine's default
    (`analysis.budget.default_memory_limit`); None for commands without the option."""
    if not hasattr(args, "memory_limit"):
        return None
    if args.memory_limit is not None:
        return int(args.memory_limit)
    from analysis.budget import default_memory_limit

    return default_memory_limit()


METHODS = ("auto", "explicit", "symbolic")


def add_method_option(group: argparse._ArgumentGroup, what: str) -> None:
    """``--method {auto,explicit,symbolic}``: how the state space is built; ``what``
    names the answers a decision diagram gives in that command."""
    group.add_argument(
        "--method",
        choices=METHODS,
        default="auto",
        help="state space method: 'explicit' (every marking stored; shortest traces), "
        f"'symbolic' (a decision diagram: {what} on nets no explicit search can store), "
        "or 'auto' (explicit, then symbolic when the explicit search stops before the "
        "end); the report says which produced the figures (default auto)",
    )


def add_search_options(parser: argparse.ArgumentParser) -> None:
    """The verification's budgets (`add_budget_options`) and switches."""
    group = add_budget_options(parser)
    add_method_option(group, "exact state count, place bounds, boundedness and deadlock")
    group.add_argument(
        "--por",
        action=argparse.BooleanOptionalAction,
        help="explore a partial-order (stubborn-set) reduced state space (default off)",
    )
    group.add_argument(
        "--no-structure",
        action="store_true",
        help="skip invariants, structural boundedness and siphons/traps",
    )
    group.add_argument("--progress", action="store_true", help="show search progress on stderr")
    group.add_argument(
        "--max-deadlocks",
        type=positive_int,
        metavar="N",
        help="list at most N dead non-final markings, each with its own shortest trace; "
        f"the rest are counted (default {DEFAULTS['max_deadlocks']})",
    )


def add_timed_options(parser: argparse.ArgumentParser, *, schedules: bool = False) -> None:
    """``--timed``, ``--link``, ``--timed-states`` and (``schedules``) ``--export-schedules``:
    timed analysis (`analysis.timed`, ``docs/analysis-methods.md``)."""
    group = parser.add_argument_group("timed analysis (docs/analysis-methods.md)")
    group.add_argument(
        "--timed",
        action=argparse.BooleanOptionalAction,
        help="also prove the best and worst mission time to each final marking, whether "
        "each query's time-out is adequate, and the mission's 'assert within' deadlines, "
        "with the vehicle working within its profile's bounds (default off)",
    )
    group.add_argument(
        "--link",
        metavar="NAME|FILE",
        help="the link profile whose delay bounds timed analysis assumes: a built-in name "
        f"or a YAML file (docs/link.md; default {DEFAULT_LINK})",
    )
    group.add_argument(
        "--timed-states",
        type=positive_int,
        metavar="N",
        help="symbolic states timed analysis explores before giving up "
        f"(default {DEFAULT_TIMED_STATES})",
    )
    group.add_argument(
        "--timed-method",
        choices=["auto", "events", "clock"],
        help="the explorer: 'events' (event times and partial-order reduction: fast with "
        "independent parallel branches), 'clock' (one global clock: the reference), or "
        "'auto' (events when the commands fall into independent groups); all give the "
        "same answers (default auto)",
    )
    if schedules:
        group.add_argument(
            "--export-schedules",
            type=schedule_folder,
            metavar="DIR",
            help="write the best- and worst-case schedule of each final marking and each "
            "counterexample's schedule here as JSON (created if needed), for "
            "'coral-run run --schedule FILE'",
        )


def schedule_folder(text: str) -> Path:
    """A folder to write schedules to: refused at once when it is a file (it is created,
    with its parents, only once there is something to write)."""
    path = Path(text)
    if path.exists() and not path.is_dir():
        raise argparse.ArgumentTypeError(f"cannot write schedules to '{text}': it is a file")
    return path


# -- settings ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Settings:
    """What a check/lint/verify/export run uses: command line over config over defaults."""

    profiles: tuple[VehicleProfile, ...]
    include_path: tuple[Path, ...]
    select: tuple[str, ...]
    ignore: tuple[str, ...]
    values: dict[str, Any]
    config: Config
    profile_paths: tuple[Path, ...] = ()
    """The ``--profile`` (or config) files read: no output may overwrite them."""
    link: LinkBounds | None = None
    """The link bounds timed analysis assumes; None: the run is not timed."""
    link_path: Path | None = None
    """The link profile file read for them (None: a built-in one)."""

    def lint_options(self) -> LintOptions:
        return LintOptions(link_rtt_s=float(self.values["link_rtt"]))

    def verify_options(self, args: argparse.Namespace, *, structural: bool) -> VerifyOptions:
        """The verification settings (``structural``: compute invariants, siphons... for
        the formats that show them)."""
        from analysis.progress import ProgressPrinter
        from analysis.verify import VerifyOptions

        return VerifyOptions(
            max_states=self.values["max_states"],
            time_limit=self.values["time_limit"],
            por=self.values["por"],
            structural=structural and not args.no_structure,
            progress=ProgressPrinter(sys.stderr, force=True) if args.progress else None,
            max_deadlocks=self.values["max_deadlocks"],
            max_edges=self.values["max_edges"],
            timed=self.timed_options(),
            memory_limit=memory_limit_of(args),
            method=getattr(args, "method", "auto"),
        )

    def timed_options(self) -> TimedOptions | None:
        """Timed analysis's settings, or None when the run is not timed."""
        if self.link is None:
            return None
        from analysis.timed.options import TimedOptions

        limit = self.values.get("time_limit")
        return TimedOptions(
            link=self.link,
            max_states=int(self.values["timed_states"]),
            time_limit_s=None if limit is None else float(limit),
            method=str(self.values["timed_method"]),
        )

    def check_options(
        self, *, verify: VerifyOptions | None = None, text: str | None = None
    ) -> CheckOptions:
        from analysis.pipeline import CheckOptions

        return CheckOptions(
            profiles=self.profiles,
            include_path=self.include_path,
            lint=self.lint_options(),
            verify=verify,
            select=self.select,
            ignore=self.ignore,
            text=text,
        )


def resolve(args: argparse.Namespace) -> Settings | None:
    """The run's settings, or None after printing why they cannot be had (a bad config
    file, a bad profile): the caller exits 2."""
    try:
        config = resolve_config(
            getattr(args, "config", None),
            disabled=getattr(args, "no_config", False),
            cwd=Path(os.getcwd()),
        )
    except ConfigError as exc:
        print_error(PROG, str(exc))
        return None

    def pick(name: str, default: Any) -> Any:
        given = getattr(args, name, None)
        if given is not None:
            return given
        from_file = getattr(config, name)
        return from_file if from_file is not None else default

    profile_paths = tuple(Path(p) for p in pick("profile", ()))
    profiles = _load_profiles(profile_paths)
    if profiles is None:
        return None
    values = {name: pick(name, default) for name, default in DEFAULTS.items()}
    link: LinkBounds | None = None
    link_path: Path | None = None
    # Only a command with --timed times anything: a config file's 'timed = true' does
    # not make 'lint' load a link profile.
    timed = hasattr(args, "timed") and bool(values["timed"])
    if hasattr(args, "timed") and not timed:
        for option in ("link", "timed_states", "timed_method", "export_schedules"):
            if getattr(args, option, None) is not None:
                print_error(PROG, f"--{option.replace('_', '-')} applies to --timed; add it")
                return None
    if timed:
        loaded = _load_link(str(values["link"]))
        if loaded is None:
            return None
        link, link_path = loaded
    return Settings(
        profiles=profiles,
        include_path=tuple(pick("include_path", ())),
        select=tuple(pick("select", ())),
        ignore=tuple(pick("ignore", ())),
        values=values,
        config=config,
        profile_paths=profile_paths,
        link=link,
        link_path=link_path,
    )


def _load_link(spec: str) -> tuple[LinkBounds, Path | None] | None:
    """The analysis bounds of the link profile ``spec`` (a built-in name or a YAML file)
    and the file read, or None after saying why it cannot be used."""
    from coral_lang.linkprofile import BUILTIN_PROFILES, LinkProfileError, load_link_profile

    try:
        profile = load_link_profile(spec)
        bounds = profile.analysis_bounds()
    except (LinkProfileError, ValueError) as exc:
        print_error(PROG, f"--link: {exc}")
        return None
    return bounds, None if spec in BUILTIN_PROFILES else Path(spec)


def _load_profiles(paths: tuple[Path, ...]) -> tuple[VehicleProfile, ...] | None:
    from coral_lang.profile import load_profile

    profiles: list[VehicleProfile] = []
    for path in paths:
        try:
            profiles.append(load_profile(path))
        except ProfileError as exc:
            print_error(PROG, str(exc))
            return None
    return tuple(profiles)
