"""``coral-run``: run a verified mission against a vehicle, and look at what happened.

``coral-run MISSION [--vehicle HOST:PORT | --sim] [--realtime] [--link PROFILE]
[--profile YAML]`` compiles the mission (against the ``--profile`` vehicle profiles
before the bundled ones, as ``coral-check`` does), checks its certificate, which must
cover that profile (``--verify`` verifies and issues one if there is none), runs it,
writes the event logs to ``--out`` and draws the timeline.

``coral-run --resume LOG [...]`` continues the mission of a controller that died
(``kill -9`` included), from the last state it committed.

``coral-run timeline LOG...`` merges a controller log and a vehicle log and plots them.

Exit codes: 0 the mission reached a declared final marking; 1 it ended otherwise
(deadlock, the vehicle lost the mission, the time limit, an engine spin: a cycle of engine
transitions that never waits for the vehicle); 2 bad usage or input (a mission that does
not compile, no passing certificate, an unreadable log or key), never a run-time condition.
"""

from __future__ import annotations

import argparse
import gc
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path

from coral_lang.diagnostics import CoralError
from runtime.keys import TRUSTED_KEYS_HELP
from runtime.vehicle.options import add_simulation_arguments, fault_plan_from_args

EXIT_OK = 0
EXIT_MISSION_FAILED = 1
EXIT_USAGE = 2

EXIT_CODES_HELP = (
    "exit codes: 0 the mission reached a declared final marking, 1 it ended otherwise "
    "(deadlock, vehicle lost the mission, time limit, engine spin), 2 bad usage or input "
    "(mission does not compile, no passing certificate, unreadable log or key)"
)


def _host_port(text: str) -> tuple[str, int]:
    host, sep, port = text.rpartition(":")
    if not sep or not host or not (port.isascii() and port.isdigit()) or not 0 < int(port) < 65536:
        raise argparse.ArgumentTypeError(f"expected HOST:PORT, got {text!r}")
    return host, int(port)


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not value > 0 or value == float("inf"):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return value


def build_run_parser() -> argparse.ArgumentParser:
    """The parser of ``coral-run MISSION`` / ``coral-run --resume LOG``."""
    parser = argparse.ArgumentParser(
        prog="coral-run",
        description="Run a verified CORAL mission against ROMEO (or the simulator) across "
        "a real or emulated link, logging both sides. Also: 'coral-run timeline LOG...' "
        "plots a run's logs; 'coral-run fuzz MISSION --runs N --seed S' runs it under N "
        "random schedules against the simulator.",
        epilog=EXIT_CODES_HELP,
    )
    parser.add_argument("mission", nargs="?", metavar="MISSION", help="mission (.coral)")
    parser.add_argument(
        "--resume",
        metavar="LOG",
        type=Path,
        help="continue the mission logged in LOG (a controller.sqlite) after a crash",
    )
    where = parser.add_mutually_exclusive_group()
    where.add_argument(
        "--vehicle", type=_host_port, metavar="HOST:PORT", help="a vehicle serving the protocol"
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
        type=_positive,
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
    parser.add_argument(
        "--profile",
        action="append",
        default=[],
        metavar="YAML",
        help="vehicle profile to use instead of the bundled one of that name (repeatable)",
    )
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
    parser.add_argument(
        "--trusted-keys",
        type=Path,
        metavar="PATH",
        help=TRUSTED_KEYS_HELP,
    )
    parser.add_argument("--key-file", type=Path, metavar="FILE", help="pre-shared key, hex")
    parser.add_argument("--key-hex", metavar="HEX", help="pre-shared key (prefer --key-file)")
    parser.add_argument(
        "--out", type=Path, default=Path("out/run"), help="logs and plots go here (default out/run)"
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of the simulated run")
    parser.add_argument(
        "--time-limit", type=_positive, metavar="SECONDS", help="end the run after this long"
    )
    parser.add_argument("--no-plots", action="store_true", help="do not draw the timeline")
    parser.add_argument("-q", "--quiet", action="store_true", help="print the summary only")
    add_simulation_arguments(parser)
    return parser


def build_timeline_parser() -> argparse.ArgumentParser:
    """The parser of ``coral-run timeline``."""
    parser = argparse.ArgumentParser(
        prog="coral-run timeline",
        description="Merge a controller log and a vehicle log on one time axis (the INIT "
        "clock offset) and plot the events and the telemetry.",
        epilog="exit codes: 0 plots written, 2 unreadable or mismatched logs",
    )
    parser.add_argument("logs", nargs="+", metavar="LOG", type=Path, help="event log (.sqlite)")
    parser.add_argument("--out", type=Path, default=None, help="directory (default: the log's)")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``coral-run``."""
    args = list(sys.argv[1:] if argv is None else argv)
    if args and args[0] == "timeline":
        return _timeline(build_timeline_parser().parse_args(args[1:]))
    if args and args[0] == "fuzz":
        from runtime.fuzz import main as fuzz_main

        return fuzz_main(args[1:])
    parser = build_run_parser()
    options = parser.parse_args(args)
    if options.mission is None and options.resume is None:
        parser.error("give a MISSION to run, or --resume LOG")
    if options.realtime and options.vehicle is not None:
        parser.error("--realtime applies to the simulator; a --vehicle always runs in real time")
    if options.vehicle is not None and (
        options.fault or options.faults or options.simulator or options.sim_config
    ):
        parser.error(
            "--simulator, --sim-config, --fault and --faults shape a simulated vehicle; "
            "a --vehicle is a real one"
        )
    if options.speed != 1.0 and not options.realtime:
        parser.error("--speed applies to a simulator in real time: add --realtime")
    from runtime.engine import EngineSpin

    try:
        return _run(options)
    except EngineSpin as exc:  # the controller ends a run on a spin; this is a safety net
        print(f"coral-run: mission failed: {exc}", file=sys.stderr)
        return EXIT_MISSION_FAILED
    except CoralError as exc:
        print(f"coral-run: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("coral-run: interrupted; resume with --resume", file=sys.stderr)
        return EXIT_MISSION_FAILED


def _run(options: argparse.Namespace) -> int:
    import secrets

    from coral_lang.profile import load_profile
    from runtime.eventlog import EventLog
    from runtime.gate import approve_mission, trust_store
    from runtime.keys import load_psk
    from runtime.link import load_link_profile
    from runtime.run import RunConfig, controller_log_path, resume_mission, run_mission

    # First: a bad profile file is bad input (exit 2, its file, line and column), and
    # should be reported before a key or a log is touched.
    profiles = [load_profile(path) for path in options.profile]
    faults = fault_plan_from_args(options)
    simulated = options.vehicle is None
    if options.key_file is None and options.key_hex is None and simulated:
        psk = secrets.token_bytes(32)  # the simulator runs in this process: a fresh key
    else:
        psk = load_psk(options.key_file, options.key_hex, who="coral-run")
    link_name = (
        options.link if options.link is not None else ("genoa-lisbon" if simulated else None)
    )
    link = None if link_name is None else load_link_profile(link_name)
    mission_path = options.mission
    out_dir = options.out
    if options.resume is not None:
        with EventLog.open(options.resume) as log:
            recorded = log.meta.get("mission_path")
            recorded_profiles = _recorded_profiles(log.meta)
        if mission_path is None:
            if not isinstance(recorded, str):
                print(
                    f"coral-run: {options.resume} does not name its mission; give MISSION",
                    file=sys.stderr,
                )
                return EXIT_USAGE
            mission_path = recorded
        out_dir = options.resume.parent
        if not profiles:
            profiles = [load_profile(path) for path in recorded_profiles]
    trusted = trust_store(options.trusted_keys)
    approved = approve_mission(
        mission_path, options.certificate, issue=options.verify, profiles=profiles, trusted=trusted
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
    config = RunConfig(
        out_dir=out_dir,
        psk=psk,
        link=link,
        seed=options.seed,
        vehicle=options.vehicle,
        realtime=options.realtime,
        speed=options.speed,
        time_limit=options.time_limit,
        console=console,
        simulator=options.simulator,
        sim_config=options.sim_config,
        faults=faults,
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
        result = run_mission(approved, config)
    if options.quiet:
        print(result.summary())
    if result.detail:
        print(f"coral-run: {result.detail}", file=sys.stderr)
    if not options.no_plots:
        from runtime.timeline import merge_logs, plot_timeline

        logs = [p for p in (controller_log_path(out_dir), out_dir / "vehicle.sqlite") if p.exists()]
        for path in plot_timeline(merge_logs(logs), out_dir):
            print(f"coral-run: wrote {path}")
    print(f"coral-run: logs in {out_dir}/")
    return EXIT_OK if result.ok else EXIT_MISSION_FAILED


def _recorded_profiles(meta: Mapping[str, object]) -> list[Path]:
    """The profile files a run recorded in its log's ``meta`` (``--resume`` without
    ``--profile``), those that still exist."""
    recorded = meta.get("profiles")
    if not isinstance(recorded, list):
        return []
    return [Path(p) for p in recorded if isinstance(p, str) and Path(p).is_file()]


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


if __name__ == "__main__":
    raise SystemExit(main())
