"""``coral-run``: run a verified mission against a vehicle, and look at what happened.

Its commands (argparse subcommands, listed in ``coral-run --help``):

``coral-run run MISSION [--vehicle HOST:PORT | --sim] [--realtime] [--link PROFILE]
[--profile YAML]`` compiles the mission (against the ``--profile`` vehicle profiles
before the bundled ones, as ``coral-check`` does), checks its certificate, which must
cover that profile (``--verify`` verifies and issues one if there is none), runs it,
writes the event logs to ``--out`` and draws the timeline. ``run`` is the default command:
``coral-run MISSION`` is the same. ``coral-run --resume LOG [...]`` continues the
mission of a controller that died (``kill -9`` included), from the last state it committed.
``coral-run run MISSION --schedule FILE`` replays a schedule timed analysis exported
(`runtime.replay`) and exits 1 if the run did not follow it.

``coral-run fuzz MISSION --runs N --seed S`` runs it under N random schedules against the
simulator (`runtime.fuzz`).

``coral-run timeline LOG...`` merges a controller log and a vehicle log and plots them.

``coral-run watch LOG [--watch [HOST:]PORT]`` serves the mission's state as a web page,
live from its log or replayed (`runtime.watch`); ``coral-run watch LOG --tui`` shows it
in the terminal instead.

``coral-run MISSION --realtime --watch [HOST:]PORT`` serves the live page from the run
itself, with the operator's actions (give an input the mission declares, pause, resume);
``--tui`` shows a live terminal view. ``coral-run operate [HOST:]PORT ACTION [NAME]``
sends an operator action to such a run (`runtime.operator`; the token comes from the
run's ``operate.token`` file).

The parser is `coral_lang.cliframe`'s (``--version``, exit 2 on bad usage, returned
rather than raised); options ``coral-vehicle`` and ``romeo-sim`` share are defined once
in `runtime.vehicle.options`.

Ctrl-C (SIGINT) and SIGTERM end a run cleanly: no new command is sent, the vehicle is
asked to make itself safe (``MakeSafe``, acknowledged within a few seconds), the log is
committed, the plots drawn, and one message says which signal, the mission time, whether
the vehicle acknowledged, where the logs are and the ``--resume`` command. A second
signal during that stop gives up waiting and ends at once.

Exit codes: 0 the mission reached a declared final marking; 1 it ended otherwise
(deadlock, the vehicle lost the mission, the time limit, an engine spin: a cycle of engine
transitions that never waits for the vehicle); 2 bad usage or input (a mission that does
not compile, no passing certificate, an unreadable log or key), never a run-time condition;
130 stopped by SIGINT (Ctrl-C), 143 stopped by SIGTERM (128 + the signal number, the
shell's convention for "ended by a signal").
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import gc
import shlex
import signal
import sys
from collections.abc import AsyncIterator, Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import urllib.error

from coral_lang.cliframe import (
    EXIT_FAILED,
    EXIT_OK,
    EXIT_USAGE,
    CommandParser,
    command_parser,
    host_port,
    positive_float,
    print_error,
    run_main,
    subcommands,
)
from coral_lang.diagnostics import CoralError
from runtime.vehicle.options import (
    add_include_path_argument,
    add_key_arguments,
    add_profile_argument,
    add_seed_argument,
    add_simulation_arguments,
    add_trusted_keys_argument,
    fault_plan_from_args,
)
from runtime.vehicle.sigterm import Terminated, sigterm_raises

if TYPE_CHECKING:
    from runtime.controller import Controller, RunResult
    from runtime.run import Companion
    from runtime.watch.feed import LiveFeed

__all__ = [
    "EXIT_MISSION_FAILED",
    "EXIT_OK",
    "EXIT_SIGINT",
    "EXIT_SIGTERM",
    "EXIT_USAGE",
    "OPERATE_TOKEN_FILE",
    "build_parser",
    "build_run_parser",
    "live_companion",
    "main",
]

EXIT_MISSION_FAILED = EXIT_FAILED
EXIT_SIGINT = 128 + signal.SIGINT  # 130
EXIT_SIGTERM = 128 + signal.SIGTERM  # 143

OPERATE_TOKEN_FILE = "operate.token"
"""Where a run with ``--watch`` writes its operate token, in its ``--out`` folder."""
OPERATE_TOKEN_ENV = "CORAL_OPERATE_TOKEN"
"""The environment variable ``coral-run operate`` takes the token from, last."""

EXIT_CODES_HELP = (
    "exit codes: 0 the mission reached a declared final marking, 1 it ended otherwise "
    "(deadlock, vehicle lost the mission, time limit, engine spin), 2 bad usage or input "
    "(mission does not compile, no passing certificate, unreadable log or key), "
    "130 stopped by Ctrl-C (SIGINT), 143 stopped by SIGTERM. On either signal the run "
    "stops cleanly: no new command, the vehicle is asked to make itself safe (up to 5 s "
    "for its acknowledgement), logs and plots are written, and the message gives the "
    "'coral-run --resume LOG' command; a second signal ends at once"
)


def _ip_address(text: str) -> str:
    """An IP address of this machine (``--telemetry-host``): checked by binding to it, so
    a wrong one is bad usage here rather than a failure once the run has started."""
    import ipaddress
    import socket

    try:
        address = ipaddress.ip_address(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an IP address, got {text!r}") from None
    family = socket.AF_INET6 if address.version == 6 else socket.AF_INET
    try:
        with socket.socket(family, socket.SOCK_DGRAM) as probe:
            probe.bind((str(address), 0))
    except OSError as exc:
        raise argparse.ArgumentTypeError(
            f"{text} is not an address of this machine ({exc.strerror or exc})"
        ) from None
    return str(address)


def _watch_address(text: str) -> tuple[str, int]:
    """``[HOST:]PORT`` to serve on; port 0 picks a free one, so not `host_port`, which
    refuses it (`runtime.watch.main.parse_address`)."""
    from runtime.watch.main import parse_address

    try:
        return parse_address(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _served_address(text: str) -> tuple[str, int]:
    """``[HOST:]PORT`` a run serves on (``coral-run operate``): a bare port is local."""
    return host_port(text, default_host="127.0.0.1")


def build_parser() -> CommandParser:
    """The parser of ``coral-run`` and its subcommands; ``run`` is the default one
    (``coral-run MISSION`` is ``coral-run run MISSION``)."""
    parser = command_parser(
        "coral-run",
        "Run a verified CORAL mission against ROMEO (or the simulator) across a real or "
        "emulated link, logging both sides ('coral-run MISSION' is short for 'coral-run "
        "run MISSION'), and look at what happened. 'coral-run COMMAND --help' describes "
        "each command.",
        epilog=EXIT_CODES_HELP,
    )
    commands = subcommands(parser)
    _add_run_arguments(
        commands.add_parser(
            "run",
            help="run a mission (the default command), or --resume one after a crash",
            description="Compile the mission, check its certificate (or --verify it), run it "
            "against the simulator or a --vehicle, write both sides' logs to --out and plot "
            "them. 'coral-run --resume LOG' continues a run whose controller died.",
            epilog=EXIT_CODES_HELP,
        )
    )
    _add_fuzz_parser(commands)
    _add_watch_arguments(
        commands.add_parser(
            "watch",
            help="serve a run's state as a web page (live or replayed), or --tui",
            description="Serve a mission's state (marking, commands, telemetry, link) as a "
            "web page from its controller log: live while the mission runs (the log is "
            "followed until mission-end), a replay with a time scrubber once it has ended.",
            epilog="exit codes: 0 stopped with Ctrl-C, 2 unreadable log or address. Bound to "
            "127.0.0.1 by default; any other address (even 127.0.0.2) requires the access "
            "token printed once in the URL",
        )
    )
    _add_timeline_arguments(
        commands.add_parser(
            "timeline",
            help="merge a controller log and a vehicle log and plot them",
            description="Merge a controller log and a vehicle log on one time axis (the INIT "
            "clock offset) and plot the events and the telemetry.",
            epilog="exit codes: 0 plots written, 2 unreadable or mismatched logs",
        )
    )
    _add_operate_arguments(
        commands.add_parser(
            "operate",
            help="pause, resume or give an input to a run served with --watch",
            description="Send an operator action to a running mission served with --watch: "
            "pause (no new command is sent; replies are still consumed), resume, or give NAME "
            "(an input the mission declares, e.g. abort_requested). Every action is "
            "authenticated with the run's operate token and logged with its origin.",
            epilog="exit codes: 0 the action was taken, 1 the run refused it (the message "
            "says why), 2 bad usage, no token, the token refused, or the run cannot be "
            f"reached. The token comes from --token-file, else OUT/{OPERATE_TOKEN_FILE} "
            f"(--out, default out/run), else the environment variable {OPERATE_TOKEN_ENV}",
        )
    )
    return parser


def build_run_parser() -> argparse.ArgumentParser:
    """The parser of ``coral-run run`` (``coral-run MISSION`` / ``coral-run --resume LOG``)."""
    return _subparser(build_parser(), "run")


def _subparser(parser: argparse.ArgumentParser, name: str) -> argparse.ArgumentParser:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            chosen: argparse.ArgumentParser = action.choices[name]
            return chosen
    raise LookupError(name)


def _add_run_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("mission", nargs="?", metavar="MISSION", help="mission (.coral)")
    parser.add_argument(
        "--resume",
        metavar="LOG",
        type=Path,
        help="continue the mission logged in LOG (a controller.sqlite) after a crash",
    )
    where = parser.add_mutually_exclusive_group()
    where.add_argument(
        "--vehicle", type=host_port, metavar="HOST:PORT", help="a vehicle serving the protocol"
    )
    where.add_argument(
        "--sim",
        action="store_true",
        help="run a simulated vehicle in this process (default): the one registered for the "
        "mission's vehicle (ROMEO's physics for ROMEO), else the generic one for its profile",
    )
    parser.add_argument(
        "--realtime",
        action="store_true",
        help="with the simulator: real time over localhost sockets (default: virtual time)",
    )
    parser.add_argument(
        "--speed",
        type=positive_float,
        default=1.0,
        help="with --sim --realtime: simulator seconds per wall second (default 1)",
    )
    parser.add_argument(
        "--link",
        metavar="PROFILE",
        default=None,
        help="emulate a link: a built-in profile (ideal, lan, genoa-lisbon, hostile) or a "
        "YAML file (default: genoa-lisbon with the simulator, none with --vehicle)",
    )
    add_profile_argument(parser)
    add_include_path_argument(parser, extra="recorded in the log, so --resume finds it again")
    parser.add_argument(
        "--certificate",
        type=Path,
        metavar="FILE",
        help="the mission's certificate (default MISSION.certificate.json beside it)",
    )
    parser.add_argument(
        "--verify",
        action="store_true",
        help="if there is no passing certificate, verify the mission here and run on that "
        "verification (no key needed; the certificate it writes is unsigned, so a later "
        "run needs --verify again or a signed certificate)",
    )
    add_trusted_keys_argument(parser)
    add_key_arguments(parser)
    parser.add_argument(
        "--telemetry-host",
        type=_ip_address,
        metavar="ADDR",
        help="with --vehicle: this machine's address on the vehicle's network, where "
        "telemetry arrives (default: the address the routes pick to reach the vehicle; "
        "0.0.0.0: every address)",
    )
    parser.add_argument(
        "--out", type=Path, default=Path("out/run"), help="logs and plots go here (default out/run)"
    )
    add_seed_argument(parser, "seed of the simulated run")
    parser.add_argument(
        "--time-limit", type=positive_float, metavar="SECONDS", help="end the run after this long"
    )
    parser.add_argument("--no-plots", action="store_true", help="do not draw the timeline")
    parser.add_argument("-q", "--quiet", action="store_true", help="print the summary only")
    parser.add_argument(
        "--schedule",
        type=Path,
        metavar="FILE",
        help="replay a timed schedule (coral-check verify --timed --export-schedules) "
        "against the generic simulated vehicle, in virtual time, and say whether the run "
        "followed it (exit 1 if not)",
    )
    parser.add_argument(
        "--watch",
        metavar="[HOST:]PORT",
        type=_watch_address,
        default=None,
        help="serve the live operations page of this run (real time only: --realtime or "
        "--vehicle); bare PORT binds 127.0.0.1, port 0 picks a free one; the operate "
        f"token is written to OUT/{OPERATE_TOKEN_FILE} (0600)",
    )
    parser.add_argument(
        "--tui",
        action="store_true",
        help="show a live terminal view of this run below its progress lines (real time "
        "only: --realtime or --vehicle)",
    )
    add_simulation_arguments(parser)


def _add_fuzz_parser(commands: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """``coral-run fuzz``: its options and texts are `runtime.fuzz.options`' (a module
    that imports no part of a campaign, so listing the subcommand costs nothing)."""
    from runtime.fuzz.options import DESCRIPTION, EPILOG, add_fuzz_arguments

    add_fuzz_arguments(
        commands.add_parser(
            "fuzz",
            help="run a mission under many random schedules against the simulator",
            description=DESCRIPTION,
            epilog=EPILOG,
        )
    )


def _add_timeline_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("logs", nargs="+", metavar="LOG", type=Path, help="event log (.sqlite)")
    parser.add_argument("--out", type=Path, default=None, help="directory (default: the log's)")


def _add_watch_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("log", metavar="LOG", type=Path, help="controller log (.sqlite)")
    view = parser.add_mutually_exclusive_group()
    view.add_argument(
        "--watch",
        metavar="[HOST:]PORT",
        type=_watch_address,
        default=None,
        help="where to serve (default 127.0.0.1:8765; port 0 picks a free one)",
    )
    view.add_argument(
        "--tui",
        action="store_true",
        help="show the mission in this terminal instead of serving a page (follows a live "
        "log until mission-end; Ctrl-C ends it)",
    )


def _add_operate_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "address",
        metavar="[HOST:]PORT",
        type=_served_address,
        help="where the run serves (a bare PORT: 127.0.0.1)",
    )
    parser.add_argument("action", choices=["pause", "resume", "give"], help="the action")
    parser.add_argument("name", nargs="?", metavar="NAME", help="with give: the input")
    parser.add_argument("--token-file", type=Path, metavar="FILE", help="the operate token")
    parser.add_argument(
        "--out",
        type=Path,
        default=Path("out/run"),
        help=f"the run's --out folder, holding {OPERATE_TOKEN_FILE} (default out/run)",
    )


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``coral-run``; returns the exit code (2 on bad usage, never raises
    ``SystemExit``)."""
    parser = build_parser()
    args = list(sys.argv[1:] if argv is None else argv)
    if not args:  # what a newcomer types first: say what to give, not "required: command"
        return _usage_error(parser, "give a MISSION to run, or --resume LOG")
    return run_main(parser, args, lambda args: _dispatch(parser, args), default_command="run")


def _dispatch(parser: argparse.ArgumentParser, args: argparse.Namespace) -> int:
    if args.command == "timeline":
        return _timeline(args)
    if args.command == "watch":
        return _watch(args)
    if args.command == "operate":
        if args.action == "give" and not args.name:
            return _usage_error(_subparser(parser, "operate"), "give needs the NAME of an input")
        if args.action != "give" and args.name:
            return _usage_error(_subparser(parser, "operate"), f"{args.action} takes no NAME")
        return _operate(args)
    if args.command == "fuzz":
        from runtime.fuzz.cli import run_fuzz

        return run_fuzz(args)
    return _run_command(_subparser(parser, "run"), args)


def _usage_error(parser: argparse.ArgumentParser, message: str) -> int:
    """What ``parser.error`` prints, returned as exit 2 rather than raised: for the
    checks across options that argparse cannot express."""
    parser.print_usage(sys.stderr)
    print_error(parser.prog, message)
    return EXIT_USAGE


def _usage_problem(options: argparse.Namespace) -> str | None:
    """Why these ``run`` options do not go together, or None."""
    if options.mission is None and options.resume is None:
        return "give a MISSION to run, or --resume LOG"
    if options.realtime and options.vehicle is not None:
        return "--realtime applies to the simulator; a --vehicle always runs in real time"
    if options.vehicle is not None and (
        options.fault or options.faults or options.simulator or options.sim_config
    ):
        return (
            "--simulator, --sim-config, --fault and --faults shape a simulated vehicle; "
            "a --vehicle is a real one"
        )
    if options.speed != 1.0 and not options.realtime:
        return "--speed applies to a simulator in real time: add --realtime"
    if options.schedule is not None:
        clashes = [
            flag
            for flag, given in (
                ("--resume", options.resume is not None),
                ("--vehicle", options.vehicle is not None),
                ("--realtime", options.realtime),
                ("--link", options.link is not None),
                ("--fault/--faults", bool(options.fault or options.faults)),
                ("--sim-config", options.sim_config is not None),
                ("--simulator", options.simulator not in (None, "generic")),
            )
            if given
        ]
        if clashes:
            return (
                f"--schedule replays a schedule against the generic simulated vehicle over "
                f"its own link, in virtual time: drop {', '.join(clashes)}"
            )
    for flag, given in (("--watch", options.watch is not None), ("--tui", options.tui)):
        if given and not options.realtime and options.vehicle is None:
            return f"{flag} needs a run in real time: add --realtime (or --vehicle)"
    return None


def _run_command(parser: argparse.ArgumentParser, options: argparse.Namespace) -> int:
    """``coral-run run``: the checks across options, then the run with its exit code."""
    problem = _usage_problem(options)
    if problem is not None:
        return _usage_error(parser, problem)
    from runtime.engine import EngineSpin

    try:
        with sigterm_raises():
            return _run(options)
    except EngineSpin as exc:  # the controller ends a run on a spin; this is a safety net
        print(f"coral-run: mission failed: {exc}", file=sys.stderr)
        return EXIT_MISSION_FAILED
    except CoralError as exc:
        print(f"coral-run: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except Terminated:
        _interrupted("SIGTERM", options)
        return EXIT_SIGTERM
    except KeyboardInterrupt:
        _interrupted("SIGINT", options)
        return EXIT_SIGINT


def _interrupted(name: str, options: argparse.Namespace) -> None:
    """The message for a signal outside the mission run (before it started, or after)."""
    log = options.resume if options.resume is not None else options.out / "controller.sqlite"
    print(
        f"coral-run: interrupted by {name} outside the mission run; if the mission had "
        f"started, its log is {log}: continue with {_resume_command(options, log)}",
        file=sys.stderr,
    )


def _resume_command(options: argparse.Namespace, log: Path) -> str:
    """The ``coral-run --resume`` command line that continues this run."""
    parts = ["coral-run", "--resume", str(log)]
    if options.vehicle is not None:
        parts += ["--vehicle", f"{options.vehicle[0]}:{options.vehicle[1]}"]
    if options.key_hex is not None:  # never printed: it is the key
        parts += ["--key-hex", "HEX"]
    for flag, value in (
        ("--key-file", options.key_file),
        ("--certificate", options.certificate),
        ("--trusted-keys", options.trusted_keys),
        ("--link", options.link),
        ("--telemetry-host", options.telemetry_host),
        ("--simulator", options.simulator),
        ("--sim-config", options.sim_config),
        ("--time-limit", options.time_limit),
    ):
        if value is not None:
            parts += [flag, str(value)]
    for profile in options.profile:
        parts += ["--profile", str(profile)]
    if options.realtime:
        parts.append("--realtime")
        if options.speed != 1.0:
            parts += ["--speed", f"{options.speed:g}"]
    if options.verify:
        parts.append("--verify")
    return shlex.join(parts)


def _stopped_message(result: RunResult, options: argparse.Namespace, log: Path) -> str:
    """The one message of a run stopped by a signal: which, when, the vehicle, what next."""
    if result.made_safe:
        vehicle = "the vehicle acknowledged the make-safe request (it stopped its commands)"
    else:
        vehicle = (
            "the vehicle did NOT acknowledge the make-safe request: check it; its watchdog "
            "makes it safe after its silence time-out"
        )
    return (
        f"coral-run: stopped by {result.stopped_by} at mission time "
        f"{result.mission_time:.1f} s; {vehicle}; logs in {log.parent}/; continue with: "
        f"{_resume_command(options, log)}"
    )


def _run(options: argparse.Namespace) -> int:
    import secrets

    from coral_lang.profile import load_profile
    from runtime.eventlog import EventLog, log_key
    from runtime.gate import approve_mission, trust_store
    from runtime.keys import load_psk
    from runtime.link import load_link_profile
    from runtime.run import RunConfig, controller_log_path, resume_mission, run_mission

    # First: a bad profile file is bad input (exit 2, its file, line and column), and
    # should be reported before a key or a log is touched.
    profiles = [load_profile(path) for path in options.profile]
    faults = fault_plan_from_args(options)
    simulated = options.vehicle is None
    ephemeral = simulated and options.key_file is None and options.key_hex is None
    if ephemeral:
        psk = secrets.token_bytes(32)  # the simulator runs in this process: a fresh key
    else:
        psk = load_psk(options.key_file, options.key_hex, who="coral-run")
    link_name = (
        options.link if options.link is not None else ("genoa-lisbon" if simulated else None)
    )
    link = None if link_name is None else load_link_profile(link_name)
    mission_path = options.mission
    out_dir = options.out
    include_path: list[Path] = list(options.include_path)
    if options.resume is not None:
        # Verified before its meta is believed (which mission, which profiles): with a
        # real key the whole log must check out under it; an ephemeral key (a simulated
        # run without --key-file) can verify nothing, and resume_mission says so.
        with EventLog.open(options.resume, mac_key=None if ephemeral else log_key(psk)) as log:
            recorded = log.meta.get("mission_path")
            recorded_profiles = _recorded_profiles(log.meta)
            recorded_include_path = _recorded_folders(log.meta)
        if mission_path is None:
            if not isinstance(recorded, str):
                print(
                    f"coral-run: {options.resume} does not name its mission; give MISSION",
                    file=sys.stderr,
                )
                return EXIT_USAGE
            if not _exists(Path(recorded), Path.is_file):
                print(
                    f"coral-run: {options.resume} names the mission {recorded[:200]!r}, which "
                    "is not a readable file; give MISSION",
                    file=sys.stderr,
                )
                return EXIT_USAGE
            mission_path = recorded
        out_dir = options.resume.parent
        if not profiles:
            profiles = [load_profile(path) for path in recorded_profiles]
        if not include_path:
            include_path = recorded_include_path
    if options.schedule is not None and mission_path is not None:
        # A bad schedule file is bad input: said before any certificate is checked.
        from analysis.timed import ScheduleError, read_schedule

        try:
            read_schedule(options.schedule)
        except ScheduleError as exc:
            print(f"coral-run: {exc}", file=sys.stderr)
            return EXIT_USAGE
    trusted = trust_store(options.trusted_keys)
    approved = approve_mission(
        mission_path,
        options.certificate,
        issue=options.verify,
        profiles=profiles,
        trusted=trusted,
        include_path=include_path,
    )
    # The net and the compiler's objects live as long as the run: take them out of the
    # cyclic collector's scans, which otherwise grow with the net (bench/engine.py).
    gc.collect()
    gc.freeze()
    if approved.issued_now:
        print(
            f"coral-run: verified; certificate written to {approved.approval.path} (unsigned: "
            "this run trusts its own verification; a later run needs --verify again, or a "
            "certificate signed with 'coral-check verify --signing-key')"
        )
    console = (lambda line: None) if options.quiet else print
    companions: list[Companion] = []
    if options.watch is not None:
        _check_watch_address(options.watch)  # before the mission's log says it started
    if options.watch is not None or options.tui:
        companions.append(
            live_companion(
                watch=options.watch,
                tui=options.tui,
                token_file=out_dir / OPERATE_TOKEN_FILE,
                console=print,
            )
        )
    replay = None
    sim_config = options.sim_config
    time_limit = options.time_limit
    if options.schedule is not None:
        from runtime.replay import load_replay

        replay = load_replay(options.schedule, approved.net)  # ReplayError: exit 2
        link = replay.link
        if time_limit is None:
            time_limit = replay.time_limit
    config = RunConfig(
        out_dir=out_dir,
        psk=psk,
        link=link,
        seed=options.seed,
        vehicle=options.vehicle,
        realtime=options.realtime,
        speed=options.speed,
        time_limit=time_limit,
        console=console,
        simulator="generic" if replay is not None else options.simulator,
        sim_config=sim_config,
        faults=faults,
        telemetry_host=options.telemetry_host,
        log_key_ephemeral=ephemeral,
        companions=companions,
    )
    if options.resume is not None:
        result = resume_mission(approved, options.resume, config)
    else:
        if controller_log_path(out_dir).exists():
            print(
                f"coral-run: {controller_log_path(out_dir)} holds an earlier run; give another "
                "--out, or --resume it",
                file=sys.stderr,
            )
            return EXIT_USAGE
        if replay is not None:
            from dataclasses import replace

            profile = approved.mission.profile
            latency = profile.timing.reply_latency_s if profile is not None else 0.1
            config = replace(config, sim_config=replay.write_settings(out_dir, latency))
        result = run_mission(approved, config)
    if options.quiet:
        print(result.summary())
    if result.detail:
        print(f"coral-run: {result.detail}", file=sys.stderr)
    log_path = controller_log_path(out_dir)
    if result.stopped_by:
        # Printed before the plots: it is what the operator needs now, and a second
        # signal during the plots must not lose it.
        print(_stopped_message(result, options, log_path), file=sys.stderr, flush=True)
    if not options.no_plots and result.stop_requests < 2:
        from runtime.timeline import merge_logs, plot_timeline

        logs = [p for p in (controller_log_path(out_dir), out_dir / "vehicle.sqlite") if p.exists()]
        for path in plot_timeline(merge_logs(logs), out_dir):
            print(f"coral-run: wrote {path}")
    print(f"coral-run: logs in {out_dir}/")
    if replay is not None and not result.stopped_by:
        with EventLog.open(controller_log_path(out_dir)) as replayed:
            verdict = replay.check(replayed, result)
        for line in verdict.lines:
            print(f"coral-run: {line}")
        return EXIT_OK if verdict.followed else EXIT_MISSION_FAILED
    if result.stopped_by:
        return {"SIGINT": EXIT_SIGINT, "SIGTERM": EXIT_SIGTERM}.get(
            result.stopped_by, EXIT_MISSION_FAILED
        )
    return EXIT_OK if result.ok else EXIT_MISSION_FAILED


def _recorded_profiles(meta: Mapping[str, object]) -> list[Path]:
    """The profile files a run recorded in its log's ``meta`` (``--resume`` without
    ``--profile``), those that still exist."""
    recorded = meta.get("profiles")
    if not isinstance(recorded, list):
        return []
    return [Path(p) for p in recorded if isinstance(p, str) and _exists(Path(p), Path.is_file)]


def _recorded_folders(meta: Mapping[str, object]) -> list[Path]:
    """The ``--include-path`` folders a run recorded in its log's ``meta``, those that
    still exist (a missing one shows up as the include it was needed for)."""
    recorded = meta.get("include_path")
    if not isinstance(recorded, list):
        return []
    return [Path(p) for p in recorded if isinstance(p, str) and _exists(Path(p), Path.is_dir)]


def _exists(path: Path, test: Callable[[Path], bool]) -> bool:
    """``test(path)``, False where the path cannot even be looked at (a name too long,
    a folder not readable): a path recorded in a log is data, not a promise."""
    try:
        return test(path)
    except (OSError, ValueError):
        return False


def _timeline(options: argparse.Namespace) -> int:
    from runtime.timeline import merge_logs, plot_timeline, summarize

    try:
        timeline = merge_logs(options.logs)
        out = options.out if options.out is not None else options.logs[0].parent
        out.mkdir(parents=True, exist_ok=True)
        print(summarize(timeline))
        for path in plot_timeline(timeline, out):
            print(f"coral-run: wrote {path}")
    except CoralError as exc:
        print(f"coral-run: {exc}", file=sys.stderr)
        return EXIT_USAGE
    return EXIT_OK


def _watch(options: argparse.Namespace) -> int:
    if options.tui:
        from runtime.tui import watch_log_tui

        try:
            return watch_log_tui(options.log)
        except CoralError as exc:
            print(f"coral-run watch: {exc}", file=sys.stderr)
            return EXIT_USAGE
    from runtime.watch.main import watch

    try:
        return watch(options.log, *(options.watch or ("127.0.0.1", 8765)))
    except CoralError as exc:
        print(f"coral-run watch: {exc}", file=sys.stderr)
        return EXIT_USAGE


# ---------------------------------------------------------------------- live run


def live_companion(
    *,
    watch: tuple[str, int] | None,
    tui: bool,
    token_file: Path,
    console: Callable[[str], None],
) -> Companion:
    """The companion of ``--watch`` and ``--tui``: one live feed of the run's log, the
    live server on it (operate right: the controller's `Controller.operate`) and/or the
    terminal view, entered before the run and closed after it.

    The server's address is taken at start: an address that cannot be bound is bad
    usage (`runtime.watch.main.WatchError`, exit 2), though the run's log exists by then.
    """

    @contextlib.asynccontextmanager
    async def companion(controller: Controller) -> AsyncIterator[object]:
        from runtime.watch.feed import LiveFeed

        log = controller.log
        feed = LiveFeed(log, log.net_json)
        try:
            async with contextlib.AsyncExitStack() as stack:
                if watch is not None:
                    await _serve_live(stack, feed, watch, controller, token_file, console)
                if tui:
                    await stack.enter_async_context(_terminal_view(feed))
                yield feed
        finally:
            feed.close()

    return companion


def _check_watch_address(address: tuple[str, int]) -> None:
    """Bind ``--watch``'s address once and let it go, before the run starts: an address
    that is not this machine's, or is taken, is bad usage (exit 2) with no mission
    started and no log written. (Something could still take the port in between; then the
    run's own start fails the same way, after its log exists.)"""
    import socket

    from runtime.watch.main import WatchError

    host, port = address
    if port == 0:
        try:
            socket.getaddrinfo(host, 0)
        except OSError as error:
            raise WatchError(f"cannot listen on {host}:{port}: {error}") from None
    try:
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        probe = socket.create_server((host, port), family=family)
    except OSError as error:
        raise WatchError(f"cannot listen on {host}:{port}: {error.strerror or error}") from None
    probe.close()


async def _serve_live(
    stack: contextlib.AsyncExitStack,
    feed: LiveFeed,
    address: tuple[str, int],
    controller: Controller,
    token_file: Path,
    console: Callable[[str], None],
) -> str:
    """Start the live server on ``stack``; returns its URL. An address that cannot be
    bound is a `WatchError` (bad usage), not a traceback."""
    from runtime.watch.live import serve_live
    from runtime.watch.main import WatchError
    from runtime.watch.server import static_info

    host, port = address
    server = serve_live(
        feed,
        host=host,
        port=port,
        operate=controller.operate,
        token_file=token_file,
        console=console,
        info=static_info(controller.log.net_json, controller.log.meta),
    )
    try:
        return await stack.enter_async_context(server)
    except OSError as error:
        raise WatchError(f"cannot listen on {host}:{port}: {error.strerror or error}") from None


@contextlib.asynccontextmanager
async def _terminal_view(feed: LiveFeed) -> AsyncIterator[None]:
    """The terminal view as a task beside the run; stopped (then cancelled if it does
    not stop within a few seconds) when the run ends."""
    from runtime.tui import run_terminal_view

    stop = asyncio.Event()

    def snapshot() -> Mapping[str, object]:
        # "start" puts times on the mission's own axis, as the page shows them.
        return {**feed.snapshot().to_json(), "start": feed.first_time}

    clock = asyncio.get_running_loop().time  # the controller's clock: countdowns tick
    task = asyncio.ensure_future(
        run_terminal_view(snapshot, stop=stop, mission=feed.mission, clock=clock)
    )
    try:
        yield
    finally:
        stop.set()
        try:
            await asyncio.wait_for(task, 5.0)  # cancels it after 5 s
        except TimeoutError:
            pass
        except Exception as error:  # a view that broke never changes the run's result
            print(f"coral-run: the terminal view stopped: {type(error).__name__}: {error}")


# ---------------------------------------------------------------------- operate


MAX_OPERATE_ANSWER = 64 * 1024
"""The longest answer of ``/operate`` read (a coral server's is one short line)."""
MAX_TOKEN_FILE = 4096


def _operate(options: argparse.Namespace) -> int:
    """``coral-run operate``: POST one action to a run's ``/operate``; print its answer."""
    import http.client
    import json
    import os
    import urllib.error
    import urllib.request

    host, port = options.address
    where = f"{host}:{port}"
    token = _operate_token(options, os.environ)
    if token is not None and not (token.isascii() and token.isprintable() and " " not in token):
        token = "coral-run operate: the operate token holds characters no token has"
    if token is None or token.startswith("coral-run operate:"):
        print(
            token
            or "coral-run operate: no operate token: give --token-file FILE, or --out DIR "
            f"of the run (its {OPERATE_TOKEN_FILE}), or set {OPERATE_TOKEN_ENV}",
            file=sys.stderr,
        )
        return EXIT_USAGE
    body = json.dumps({"action": options.action, "input": options.name}).encode()
    url_host = f"[{host}]" if ":" in host else host
    request = urllib.request.Request(
        f"http://{url_host}:{port}/operate",
        data=body,
        method="POST",
        headers={
            "Authorization": f"Bearer {token}",
            "Content-Type": "application/json",
            "X-Coral-Client": "cli",
        },
    )
    try:
        with urllib.request.urlopen(request, timeout=10) as response:
            raw = response.read(MAX_OPERATE_ANSWER + 1)
    except urllib.error.HTTPError as error:
        print(f"coral-run operate: {where}: {_http_refusal(error)}", file=sys.stderr)
        return EXIT_USAGE
    except (urllib.error.URLError, OSError) as error:
        reason = getattr(error, "reason", error)
        print(f"coral-run operate: cannot reach {where}: {reason}", file=sys.stderr)
        return EXIT_USAGE
    except (http.client.HTTPException, ValueError) as error:  # not HTTP, a bad address
        name = type(error).__name__
        print(f"coral-run operate: {where} is not a coral watch server ({name})", file=sys.stderr)
        return EXIT_USAGE
    try:
        if len(raw) > MAX_OPERATE_ANSWER:
            raise ValueError("too long")
        answer = json.loads(raw.decode("utf-8"))
    except (ValueError, UnicodeDecodeError, RecursionError):
        print(f"coral-run operate: {where} answered something that is not JSON", file=sys.stderr)
        return EXIT_USAGE
    if not isinstance(answer, dict) or not isinstance(answer.get("accepted"), bool):
        print(f"coral-run operate: {where} answered without 'accepted'", file=sys.stderr)
        return EXIT_USAGE
    message = str(answer.get("message", ""))
    if answer["accepted"]:
        print(f"coral-run operate: {message}")
        return EXIT_OK
    print(f"coral-run operate: refused: {message}", file=sys.stderr)
    return EXIT_MISSION_FAILED


def _operate_token(options: argparse.Namespace, environ: Mapping[str, str]) -> str | None:
    """The operate token: ``--token-file``, else the run's ``OUT/operate.token``, else
    the environment; None when there is none, an error line when a file is unreadable."""
    path: Path | None = options.token_file
    try:
        if path is None and (options.out / OPERATE_TOKEN_FILE).is_file():
            path = options.out / OPERATE_TOKEN_FILE
    except OSError as error:  # a folder we may not look into
        return f"coral-run operate: cannot look for {OPERATE_TOKEN_FILE} in {options.out}: {error}"
    if path is not None:
        try:
            with path.open("rb") as handle:
                data = handle.read(MAX_TOKEN_FILE + 1)
            if len(data) > MAX_TOKEN_FILE:
                return f"coral-run operate: {path} is too large to be a token file"
            token = data.decode("utf-8").strip()
        except (OSError, UnicodeDecodeError) as error:
            return f"coral-run operate: cannot read the token file {path}: {error}"
        return token or f"coral-run operate: the token file {path} is empty"
    token = environ.get(OPERATE_TOKEN_ENV, "").strip()
    return token or None


def _http_refusal(error: urllib.error.HTTPError) -> str:
    """What an HTTP error status of ``/operate`` means to the operator."""
    import json

    detail = ""
    try:
        data = json.loads(error.read().decode("utf-8"))
        if isinstance(data, dict):
            detail = str(data.get("message") or data.get("error") or "")
    except (ValueError, UnicodeDecodeError, OSError):
        pass
    meaning = {
        401: "the operate token was refused",
        403: "the token gives the view right only, not the operate right",
        404: "this server takes no operator actions (a replay of a finished log?)",
        413: "the request was too large",
    }.get(error.code, f"HTTP {error.code}")
    return meaning + (f" ({detail})" if detail else "")


if __name__ == "__main__":
    raise SystemExit(main())
