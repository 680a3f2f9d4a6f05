"""The command-line options that choose and shape a simulated vehicle.

``coral-run --sim``, ``coral-run fuzz`` and ``coral-vehicle serve`` all build their
simulated vehicle from the same four options, so they mean the same everywhere:
``--simulator NAME``, ``--sim-config FILE``, ``--fault RULE`` (repeatable) and
``--faults FILE`` (one rule a line; grammar in ``runtime.faultplan`` and
``docs/vehicles.md``).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from runtime.faultplan import FaultPlan, load_fault_plan, parse_fault_rules

__all__ = ["add_simulation_arguments", "fault_plan_from_args"]


def add_simulation_arguments(
    parser: argparse.ArgumentParser, *, config_aliases: tuple[str, ...] = ()
) -> None:
    """Add ``--simulator``, ``--sim-config``, ``--fault`` and ``--faults`` to ``parser``."""
    group = parser.add_argument_group("simulated vehicle")
    group.add_argument(
        "--simulator",
        metavar="NAME",
        default=None,
        help="which simulated vehicle: 'romeo' (ROMEO's physics, for the ROMEO profile), "
        "'generic' (any profile: replies after the profile's durations), or another "
        "registered one (default: the one made for the mission's vehicle, else generic)",
    )
    group.add_argument(
        "--sim-config",
        *config_aliases,
        dest="sim_config",
        type=Path,
        metavar="FILE",
        default=None,
        help="settings file of the simulator (ROMEO: a vehicle YAML, see docs/sim.md)",
    )
    group.add_argument(
        "--fault",
        action="append",
        default=[],
        metavar="RULE",
        help="force a reply to rehearse a failure: 'DEPTH?=timeout' (every use), "
        "'GOTO#2=error' (the 2nd GOTO), 'DIVE=error@0.1' (each use with probability 0.1), "
        "'*=any@0.05' (any command, any unexpected reply); repeatable, first match wins",
    )
    group.add_argument(
        "--faults",
        type=Path,
        metavar="FILE",
        default=None,
        help="a fault plan file: one rule a line, '#' comments (after the --fault rules)",
    )


def fault_plan_from_args(args: argparse.Namespace) -> FaultPlan | None:
    """The plan the ``--fault`` and ``--faults`` options give, None when they give none.

    Raises:
        runtime.faultplan.FaultPlanError: a rule that does not parse (the message names
            the option or file, line and column).
    """
    rules = parse_fault_rules(args.fault, source="--fault").rules if args.fault else ()
    if args.faults is not None:
        rules = (*rules, *load_fault_plan(args.faults).rules)
    return FaultPlan(rules=tuple(rules)) if rules else None
