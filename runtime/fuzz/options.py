"""The options of ``coral-run fuzz``: its parser, and nothing that runs a campaign.

Kept apart from `runtime.fuzz.cli` so that ``coral-run`` can list ``fuzz`` among its
subcommands without importing the engine, the certificate checks and numpy: a
``coral-run --help`` (or any other subcommand) starts as fast as before fuzzing was one.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from coral_lang.cliframe import (
    command_parser,
    finite_number,
    positive_float,
    positive_int,
    tool_version,
)
from runtime.policy import Policy
from runtime.vehicle.options import (
    add_include_path_argument,
    add_profile_argument,
    add_seed_argument,
    add_simulation_arguments,
    add_trusted_keys_argument,
    seed_number,
)

__all__ = ["DESCRIPTION", "EPILOG", "LOCAL_RAY", "PROG", "add_fuzz_arguments", "build_parser"]

PROG = "coral-run fuzz"
DESCRIPTION = (
    "Run a mission against a simulated vehicle under many random schedules "
    "(link delays, stalls, losses, resets, outages; the engine's order of enabled "
    "transitions; with --vary-replies or --fault, the vehicle's replies), in virtual "
    "time, and report how often it reaches a declared final marking, how long it takes, "
    "which transitions of the net it exercised, and the seed that replays each "
    "failure. Only a simulator is ever used."
)
LOCAL_RAY = ""
"""``--ray`` without an address: a local Ray cluster, started for the campaign."""
RAY_EXTRA_HINT = "pip install 'coral[ray]'"  # runtime.fuzz.on_ray.RAY_EXTRA, not imported here
EPILOG = (
    "exit codes: 0 every run reached a declared final marking, 1 some run did not, "
    "2 bad usage or input"
)


# -- argument types ------------------------------------------------------------------------
# Only those no other command has; counts and seconds use the frame's types, seeds and
# the mission's inputs `runtime.vehicle.options`'.


def _probability(text: str) -> float:
    """A probability, 0 .. 1."""
    value = finite_number(text)
    if not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f"must be a probability in [0, 1], got '{text}'")
    return value


# -- the parser ----------------------------------------------------------------------------


def add_fuzz_arguments(parser: argparse.ArgumentParser) -> None:
    """Add every ``coral-run fuzz`` argument to ``parser``.

    Also turns abbreviations off on ``parser``: coral-run's ``--vehicle HOST:PORT`` must
    be refused, not taken for ``--vehicle-config``, since fuzz never talks to a vehicle;
    so this holds for the subparser ``coral-run`` makes as for `build_parser`'s. And it
    gives a parser without ``--version`` (a subparser) one, so ``coral-run fuzz
    --version`` answers as ``coral-run --version`` does.
    """
    parser.allow_abbrev = False
    if "--version" not in parser._option_string_actions:  # a subparser has none of its own
        parser.add_argument(
            "--version", action="version", version=f"%(prog)s (coral {tool_version()})"
        )
    parser.add_argument("mission", metavar="MISSION", help="mission (.coral)")
    parser.add_argument("--runs", type=positive_int, default=100, help="runs (default 100)")
    add_seed_argument(parser, "run i uses run seed N + i")
    parser.add_argument(
        "--replay",
        type=seed_number,
        metavar="SEED",
        help="run only the run with this run seed (from a report) and print its events",
    )
    parser.add_argument(
        "--link",
        metavar="PROFILE",
        default="genoa-lisbon",
        help="link profile: ideal, lan, genoa-lisbon (default), hostile, or a YAML file",
    )
    add_profile_argument(parser)
    add_include_path_argument(parser)
    parser.add_argument(
        "--vary-replies",
        type=_probability,
        default=0.0,
        metavar="P",
        help="in each run, force each command's reply, with probability P, to one of its "
        "other reply kinds (the rule '*=any@P' after any --fault rules; default 0: the "
        "simulator's own replies)",
    )
    parser.add_argument(
        "--certificate",
        type=Path,
        metavar="FILE",
        help="the mission's certificate (default MISSION.certificate.json beside it)",
    )
    add_trusted_keys_argument(parser)
    parser.add_argument(
        "--unverified",
        action="store_true",
        help="fuzz a mission that has no passing certificate (simulator only; a warning "
        "is printed)",
    )
    parser.add_argument(
        "--policy",
        choices=[p.value for p in Policy],
        default=Policy.RANDOM.value,
        help="engine choice among enabled transitions: random (default, seeded per run) "
        "or priority (what runs at sea)",
    )
    parser.add_argument(
        "--time-limit",
        type=positive_float,
        default=3600.0,
        metavar="SECONDS",
        help="end a run after this many virtual seconds, as a failure (default 3600)",
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=Path("out/fuzz"),
        help="report, histogram and failed runs' logs go here (default out/fuzz)",
    )
    parser.add_argument(
        "--workers",
        type=positive_int,
        default=None,
        metavar="N",
        help="run the campaign in N local processes (default: one per core); the "
        "report is the same whatever N; with --ray and no ADDRESS, the local Ray "
        "cluster's CPUs",
    )
    parser.add_argument(
        "--ray",
        nargs="?",
        const=LOCAL_RAY,
        default=None,
        metavar="ADDRESS",
        help="run the campaign on a Ray cluster: its head's HOST:PORT (as 'ray start "
        "--head' prints it), 'auto' for the one started on this machine, or no ADDRESS "
        "for a local cluster started for this campaign; the same report as without "
        f"(docs/fuzz.md, 'On a Ray cluster'; needs {RAY_EXTRA_HINT})",
    )
    parser.add_argument("--no-plot", action="store_true", help="do not draw the histogram")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    add_simulation_arguments(parser, config_aliases=("--vehicle-config",))


def build_parser() -> argparse.ArgumentParser:
    """The stand-alone parser of ``coral-run fuzz`` (with ``--version``)."""
    parser = command_parser(PROG, DESCRIPTION, EPILOG)
    add_fuzz_arguments(parser)
    return parser
