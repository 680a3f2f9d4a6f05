"""The command-line options more than one coral command has, each defined once here.

``coral-run`` (``run``, ``fuzz``), ``coral-vehicle serve`` and ``romeo-sim`` share options:
the simulated vehicle (``--simulator``, ``--sim-config``, ``--fault``, ``--faults``), the
pre-shared key (``--key-file``/``--key-hex``), ``--seed``, the mission's inputs
(``--profile``, ``--include-path``, ``--trusted-keys``) and a served vehicle's
``--host``/``--port``/``--speed``/``--duration``/``--log``. Each is added by one function
below, so its name, type, check and help read the same in every command.

Why here, on the vehicle side: ``coral-vehicle`` and ``romeo-sim`` may import only the
vehicle side and ``coral_lang`` (docs/architecture.md), while the controller side may
import the vehicle side; so the one definition every command can reach lives here. The
argument types themselves (numbers, ports, folders) are `coral_lang.cliframe`'s.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from coral_lang.cliframe import existing_folder, non_negative_float, port_number, positive_float
from runtime.faultplan import FaultPlan, load_fault_plan, parse_fault_rules
from runtime.keys import TRUSTED_KEYS_HELP

__all__ = [
    "LOG_HELP",
    "SEED_LIMIT",
    "add_include_path_argument",
    "add_key_arguments",
    "add_profile_argument",
    "add_seed_argument",
    "add_serve_arguments",
    "add_simulation_arguments",
    "add_trusted_keys_argument",
    "fault_plan_from_args",
    "seed_number",
]

SEED_LIMIT = 2**63
"""Seeds are 0 .. 2**63-1: what every simulator's generator takes (numpy refuses
negative seeds), and what a run's report can print back for a replay."""

LOG_HELP = (
    "write the vehicle's event log (SQLite) to this new file, created when the first "
    "controller is adopted; its mission is the wire mission id in decimal"
)
"""The help of ``--log``, the same on ``coral-vehicle serve`` and ``romeo-sim serve``."""


def seed_number(text: str) -> int:
    """A seed: a whole number from 0 to 2**63-1."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a whole number: '{text}'") from None
    if not 0 <= value < SEED_LIMIT:
        raise argparse.ArgumentTypeError(f"a seed is 0 .. 2**63-1, got {value}")
    return value


def add_seed_argument(parser: argparse.ArgumentParser, what: str) -> None:
    """``--seed N`` (default 0); ``what`` says what it seeds, for the help."""
    parser.add_argument(
        "--seed", type=seed_number, default=0, metavar="N", help=f"{what} (default 0)"
    )


def add_key_arguments(parser: argparse.ArgumentParser) -> None:
    """``--key-file FILE`` or ``--key-hex HEX``, the pre-shared key (`runtime.keys.load_psk`
    reads it); giving both is bad usage."""
    key = parser.add_mutually_exclusive_group()
    key.add_argument(
        "--key-file",
        type=Path,
        metavar="FILE",
        help="file holding the pre-shared key as hex text (white space ignored; mode 0600)",
    )
    key.add_argument(
        "--key-hex",
        metavar="HEX",
        help="the pre-shared key as hex on the command line; other users can see it in the "
        "process list: prefer --key-file",
    )


def add_profile_argument(parser: argparse.ArgumentParser) -> None:
    """``--profile YAML`` (repeatable): vehicle profiles used before the bundled ones."""
    parser.add_argument(
        "--profile",
        action="append",
        default=[],
        type=Path,
        metavar="YAML",
        help="vehicle profile to use instead of the bundled one of that name, or for a "
        "vehicle that has none (repeatable; as for coral-check)",
    )


def add_include_path_argument(parser: argparse.ArgumentParser, *, extra: str = "") -> None:
    """``--include-path DIR`` (repeatable): an existing folder, else bad usage at once."""
    parser.add_argument(
        "--include-path",
        action="append",
        default=[],
        type=existing_folder,
        metavar="DIR",
        help="a folder the mission may include files from besides its own (repeatable"
        f"{'; ' + extra if extra else ''})",
    )


def add_trusted_keys_argument(parser: argparse.ArgumentParser) -> None:
    """``--trusted-keys PATH``: the keys whose signed certificates are accepted."""
    parser.add_argument("--trusted-keys", type=Path, metavar="PATH", help=TRUSTED_KEYS_HELP)


def add_serve_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of a ``serve`` command (``coral-vehicle serve``, ``romeo-sim serve``):
    ``--host``, ``--port``, the key, ``--speed``, ``--duration`` and ``--log``, which
    `runtime.vehicle.cli.serve_with_log` reads."""
    parser.add_argument(
        "--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)"
    )
    parser.add_argument(
        "--port",
        type=port_number,
        default=0,
        help="TCP port; 0 lets the system pick one (default 0)",
    )
    add_key_arguments(parser)
    parser.add_argument(
        "--speed",
        type=positive_float,
        default=1.0,
        metavar="FACTOR",
        help="vehicle seconds per wall second (default 1)",
    )
    parser.add_argument(
        "--duration",
        type=non_negative_float,
        default=None,
        metavar="SECONDS",
        help="stop after this many wall seconds (default: until Ctrl-C)",
    )
    parser.add_argument("--log", type=Path, metavar="FILE", help=LOG_HELP)


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
