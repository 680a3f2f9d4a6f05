"""The ``coral-run fuzz`` command on the shared CLI frame (`coral_lang.cliframe`).

`add_fuzz_arguments` puts every option on a parser (``coral-run``'s ``fuzz`` subparser,
or the stand-alone one `build_parser` makes); `run_fuzz` runs the parsed command and
returns its exit code; `main` does both, for scripts and tests. Bad input (a mission
that does not compile, an unknown link profile, a wrong vehicle file, no passing
certificate) is one ``coral-run fuzz: error: ...`` line and exit 2, never a traceback.

Only the simulator is ever used: there is no option to reach a vehicle (and no
abbreviations, so coral-run's ``--vehicle HOST:PORT`` is refused rather than taken for
``--vehicle-config``).

Exit codes: 0 every run reached a declared final marking, 1 some run did not (or the
campaign was interrupted), 2 bad usage or input.
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import IO, TYPE_CHECKING

from coral_lang.cliframe import EXIT_FAILED, EXIT_OK, EXIT_USAGE, run_main
from coral_lang.diagnostics import CoralError
from runtime.engine import Policy
from runtime.fuzz.approval import approval_for
from runtime.fuzz.campaign import fuzz
from runtime.fuzz.one_run import FuzzOptions, make_vehicle, run_one
from runtime.fuzz.options import (
    DESCRIPTION,
    EPILOG,
    LOCAL_RAY,
    PROG,
    add_fuzz_arguments,
    build_parser,
)
from runtime.fuzz.report import (
    FAILURES_DIR,
    HISTOGRAM,
    REPORT_JSON,
    ProgressBar,
    format_replay,
    format_report,
    plot_histogram,
)
from runtime.link import load_link_profile
from runtime.vehicle.options import fault_plan_from_args

if TYPE_CHECKING:
    from runtime.fuzz.on_ray import RayTarget

__all__ = [
    "DESCRIPTION",
    "EPILOG",
    "PROG",
    "add_fuzz_arguments",
    "build_parser",
    "main",
    "run_fuzz",
]


# -- running it ----------------------------------------------------------------------------


def main(argv: Sequence[str] | None = None, *, stderr: IO[str] | None = None) -> int:
    """``coral-run fuzz`` on its own; returns the exit code (2 on a usage error)."""
    return run_main(build_parser(), argv, lambda args: run_fuzz(args, stderr=stderr))


def run_fuzz(args: argparse.Namespace, *, stderr: IO[str] | None = None) -> int:
    """Run the command ``args`` describe (parsed by a parser `add_fuzz_arguments` filled).

    Args:
        args: the parsed arguments.
        stderr: warnings, errors and the progress bar (default ``sys.stderr``); the
            report itself goes to standard output.

    Returns:
        0 every run reached a declared final marking, 1 some did not (or the campaign
        was interrupted), 2 bad input, reported in one line on ``stderr``.
    """
    err = stderr if stderr is not None else sys.stderr
    try:
        return _fuzz(args, err)
    except (CoralError, OSError) as exc:
        print(f"{PROG}: error: {exc}", file=err)
        return EXIT_USAGE


def _fuzz(options: argparse.Namespace, err: IO[str]) -> int:
    from coral_lang.mission import load_mission
    from coral_lang.profile import load_profile
    from runtime.faultplan import parse_fault_rules

    ray_target = _ray_target(options, err)
    mission = Path(options.mission)
    compiled = load_mission(
        mission,
        [load_profile(path) for path in options.profile],
        include_path=options.include_path,
    )
    net = compiled.net
    link = load_link_profile(options.link)
    faults = fault_plan_from_args(options)
    if options.vary_replies > 0.0:
        vary = parse_fault_rules([f"*=any@{options.vary_replies:g}"], source="--vary-replies")
        faults = vary if faults is None else faults + vary
    from runtime.gate import trust_store

    approval, unverified = approval_for(
        compiled,
        options.certificate,
        unverified=options.unverified,
        trusted=trust_store(options.trusted_keys),
    )
    if unverified is not None:
        print(
            f"coral-run fuzz: WARNING: {mission} is NOT verified ({unverified}).\n"
            "  Fuzzing it anyway against the simulator only; this approval exists in this "
            "process alone and cannot run it on a vehicle.",
            file=err,
        )
    fuzz_options = FuzzOptions(
        runs=1 if options.replay is not None else options.runs,
        seed=options.replay if options.replay is not None else options.seed,
        link=link,
        time_limit=options.time_limit,
        policy=Policy(options.policy),
        profile=compiled.profile,
        simulator=options.simulator,
        sim_config=options.sim_config,
        faults=faults,
    )
    make_vehicle(net, fuzz_options, 0)  # a simulator or fault plan that cannot be used: now
    out: Path = options.out
    out.mkdir(parents=True, exist_ok=True)
    command = _command(options)
    if options.replay is not None:
        log = out / f"replay-seed-{options.replay}.sqlite"
        log.unlink(missing_ok=True)
        run = run_one(net, approval, options.replay, fuzz_options, keep_log=log, keep_events=True)
        print(format_replay(run))
        print(f"coral-run fuzz: log in {log} (plot it with: coral-run timeline {log})")
        return EXIT_OK if run.ok else EXIT_FAILED
    bar = ProgressBar(err)
    if options.quiet:
        bar.enabled = False
    try:
        report = fuzz(
            net,
            approval,
            fuzz_options,
            mission_path=str(mission),
            failed_logs=out / FAILURES_DIR,
            progress=bar,
            workers=1 if ray_target is not None else options.workers or os.cpu_count() or 1,
            ray=ray_target,
        )
    finally:
        bar.close()
    print(format_report(report, command))
    (out / REPORT_JSON).write_text(json.dumps(report.to_json(), indent=2) + "\n", encoding="utf-8")
    print(f"coral-run fuzz: wrote {out / REPORT_JSON}")
    if not options.no_plot and report.runs:
        print(f"coral-run fuzz: wrote {plot_histogram(report, out / HISTOGRAM)}")
    if any(run.log is not None for run in report.failures):
        print(f"coral-run fuzz: logs of failed runs in {out / FAILURES_DIR}/")
    if report.interrupted:
        return EXIT_FAILED
    return EXIT_OK if not report.failures else EXIT_FAILED


def _ray_target(options: argparse.Namespace, err: IO[str]) -> RayTarget | None:
    """Where ``--ray`` asks the campaign to run (None: not on Ray), Ray imported now so
    that a missing extra is said before anything runs.

    Raises:
        RayError: ``--ray`` without Ray installed, or with both ADDRESS and --workers.
    """
    if options.ray is None:
        return None
    if options.replay is not None:
        print("coral-run fuzz: --replay runs here, not on Ray", file=err)
        return None
    from runtime.fuzz.on_ray import RayError, RayTarget, import_ray

    address = None if options.ray == LOCAL_RAY else options.ray
    if address is not None and options.workers is not None:
        raise RayError(
            f"--workers sizes a local Ray cluster; the cluster at {address} has its own CPUs"
        )
    import_ray()
    return RayTarget(address=address, cpus=options.workers)


def _command(options: argparse.Namespace) -> str:
    """How to call fuzz again with what shapes a run (not --runs/--seed/--out)."""
    parts = ["coral-run fuzz", str(options.mission), "--link", str(options.link)]
    parts += [f"--profile {shlex.quote(str(p))}" for p in options.profile]
    parts += [f"--include-path {shlex.quote(str(d))}" for d in options.include_path]
    if options.simulator is not None:
        parts += ["--simulator", options.simulator]
    if options.sim_config is not None:
        parts += ["--sim-config", str(options.sim_config)]
    parts += [f"--fault {shlex.quote(rule)}" for rule in options.fault]
    if options.faults is not None:
        parts += ["--faults", str(options.faults)]
    if options.vary_replies > 0.0:
        parts += ["--vary-replies", f"{options.vary_replies:g}"]
    if options.certificate is not None:
        parts += ["--certificate", str(options.certificate)]
    if options.trusted_keys is not None:
        parts += ["--trusted-keys", shlex.quote(str(options.trusted_keys))]
    if options.unverified:
        parts.append("--unverified")
    if options.policy != Policy.RANDOM.value:
        parts += ["--policy", options.policy]
    if options.time_limit != 3600.0:
        parts += ["--time-limit", f"{options.time_limit:g}"]
    return " ".join(parts)
