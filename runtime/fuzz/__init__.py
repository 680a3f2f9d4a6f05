"""``coral-run fuzz``: run one mission under many random schedules against the simulator.

Verification proves what a mission does whatever the network does; fuzzing shows it, on
the real code path: the CORAL Engine, the controller with its event log, the link
emulator and the simulated vehicle served on the wire protocol, all under virtual time
(`runtime.vclock.run_virtual`), so a ten-minute mission takes a fraction of a second.
Each run draws everything random from its own *run seed*: the link emulator's delays,
stalls, losses, resets and outages, the simulator's sensor noise, the handshake nonces,
the mission id, and the engine's choice among enabled transitions (`Policy.RANDOM`, so
every order analysis allows gets tried, not just the priority order).

Run ``i`` of ``--seed S`` has run seed ``S + i``. The report names the run seed of every
failure, and ``--replay X`` (or ``--runs 1 --seed X``) runs exactly that run again: same
outcome, same events at the same virtual times (``events_digest`` proves it).

Only the simulator is ever used: there is no option to reach a vehicle, and a mission
without a passing certificate is accepted only with ``--unverified``, under an approval
that exists in this process alone (`UNVERIFIED`).

A run that ends otherwise (a deadlock, the time limit, an engine spin: a cycle of engine
transitions that never waits for the vehicle) is a failure, reported with its run seed;
the campaign goes on.

The package, one module per job:

* `runtime.fuzz.one_run`: one run (`FuzzOptions`, `FuzzRun`, `run_one`);
* `runtime.fuzz.campaign`: many runs and what they add up to (`fuzz`, `FuzzReport`,
  `Coverage`);
* `runtime.fuzz.on_ray`: the runs as tasks on a Ray cluster (`RayTarget`, `RayError`;
  Ray itself is imported only when used);
* `runtime.fuzz.report`: the text report, the histogram, a replay, the progress bar;
* `runtime.fuzz.approval`: the certificate gate (`approval_for`, `UNVERIFIED`,
  `unverified_approval`);
* `runtime.fuzz.options`: the command's options (`add_fuzz_arguments`), importing no
  part of a campaign, so ``coral-run`` lists ``fuzz`` without loading one;
* `runtime.fuzz.cli`: the command on the shared CLI frame (`run_fuzz`, `main`).

Every public name is re-exported here, so ``from runtime.fuzz import X`` is all a caller
needs; the modules are imported when a name is first used.

Exit codes: 0 every run reached a declared final marking, 1 some run did not, 2 bad input.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from runtime.fuzz.approval import UNVERIFIED, approval_for, unverified_approval
    from runtime.fuzz.campaign import (
        Coverage,
        FuzzReport,
        NeverFired,
        Progress,
        fuzz,
        predicted_deadlocks,
    )
    from runtime.fuzz.cli import add_fuzz_arguments, build_parser, main, run_fuzz
    from runtime.fuzz.on_ray import RayError, RayTarget
    from runtime.fuzz.one_run import (
        PSK,
        SEED_LIMIT,
        FuzzOptions,
        FuzzRun,
        events_digest,
        make_vehicle,
        run_one,
        run_seed,
    )
    from runtime.fuzz.report import (
        FAILURES_DIR,
        HISTOGRAM,
        NEVER_SHOWN,
        REPORT_JSON,
        ProgressBar,
        format_replay,
        format_report,
        plot_histogram,
    )

__all__ = [
    "FAILURES_DIR",
    "HISTOGRAM",
    "NEVER_SHOWN",
    "PSK",
    "REPORT_JSON",
    "SEED_LIMIT",
    "UNVERIFIED",
    "Coverage",
    "FuzzOptions",
    "FuzzReport",
    "FuzzRun",
    "NeverFired",
    "Progress",
    "ProgressBar",
    "RayError",
    "RayTarget",
    "add_fuzz_arguments",
    "approval_for",
    "build_parser",
    "events_digest",
    "format_replay",
    "format_report",
    "fuzz",
    "main",
    "make_vehicle",
    "plot_histogram",
    "predicted_deadlocks",
    "run_fuzz",
    "run_one",
    "run_seed",
    "unverified_approval",
]

_HOMES = {
    "Coverage": "runtime.fuzz.campaign",
    "FAILURES_DIR": "runtime.fuzz.report",
    "FuzzOptions": "runtime.fuzz.one_run",
    "FuzzReport": "runtime.fuzz.campaign",
    "FuzzRun": "runtime.fuzz.one_run",
    "HISTOGRAM": "runtime.fuzz.report",
    "NEVER_SHOWN": "runtime.fuzz.report",
    "NeverFired": "runtime.fuzz.campaign",
    "PSK": "runtime.fuzz.one_run",
    "Progress": "runtime.fuzz.campaign",
    "ProgressBar": "runtime.fuzz.report",
    "REPORT_JSON": "runtime.fuzz.report",
    "RayError": "runtime.fuzz.on_ray",
    "RayTarget": "runtime.fuzz.on_ray",
    "SEED_LIMIT": "runtime.fuzz.one_run",
    "UNVERIFIED": "runtime.fuzz.approval",
    "add_fuzz_arguments": "runtime.fuzz.cli",
    "approval_for": "runtime.fuzz.approval",
    "unverified_approval": "runtime.fuzz.approval",
    "build_parser": "runtime.fuzz.cli",
    "events_digest": "runtime.fuzz.one_run",
    "format_replay": "runtime.fuzz.report",
    "format_report": "runtime.fuzz.report",
    "fuzz": "runtime.fuzz.campaign",
    "main": "runtime.fuzz.cli",
    "make_vehicle": "runtime.fuzz.one_run",
    "plot_histogram": "runtime.fuzz.report",
    "predicted_deadlocks": "runtime.fuzz.campaign",
    "run_fuzz": "runtime.fuzz.cli",
    "run_one": "runtime.fuzz.one_run",
    "run_seed": "runtime.fuzz.one_run",
}
"""Where each public name lives. The package imports its modules when a name is first
asked for (PEP 562), so ``coral-run`` can import `runtime.fuzz.options` for its parser
without the engine, the certificate checks and numpy that a campaign needs."""


def __getattr__(name: str) -> object:
    home = _HOMES.get(name)
    if home is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(home), name)
    globals()[name] = value
    return value
