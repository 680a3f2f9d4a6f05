"""Simulated vehicles plug into ``coral-run`` through this registry.

A simulator is an object with a name, a one-line summary, the vehicles it models in
particular (ROMEO's physics simulator models ``ROMEO``; the generic one, any profile) and
a ``create`` that builds a `runtime.vehicle.model.VehicleModel` for a profile. Packages
declare theirs in the ``coral.vehicles`` entry-point group (``pyproject.toml``)::

    [project.entry-points."coral.vehicles"]
    romeo = "romeo_sim.plugin:SIMULATOR"

so the runtime reaches a vehicle implementation by name, never by importing it. When
coral runs from a source tree that was never installed (no entry points), the bundled
simulators are found through `BUNDLED`, the same "module:attribute" strings.
"""

from __future__ import annotations

import functools
import importlib
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Protocol, runtime_checkable

from coral_lang.diagnostics import CoralError, did_you_mean
from coral_lang.profile import VehicleProfile
from runtime.faultplan import FaultPlan
from runtime.vehicle.model import VehicleModel

__all__ = [
    "BUNDLED",
    "ENTRY_POINT_GROUP",
    "Simulator",
    "SimulatorError",
    "SimulatorRequest",
    "choose_simulator",
    "create_vehicle",
    "inject_faults",
    "simulators",
]

ENTRY_POINT_GROUP = "coral.vehicles"
BUNDLED: dict[str, str] = {
    "romeo": "romeo_sim.plugin:SIMULATOR",
    "generic": "runtime.vehicle.generic:SIMULATOR",
}
"""The simulators that ship with coral, as entry-point values (used when none are
installed as entry points, e.g. from an uninstalled source tree)."""


class SimulatorError(CoralError, ValueError):
    """No simulator by that name, or the chosen one cannot simulate the profile."""


@dataclass(frozen=True)
class SimulatorRequest:
    """What a simulator is asked to build.

    Attributes:
        profile: the vehicle profile the mission was compiled against.
        seed: seeds every random source of the simulated vehicle.
        config: a settings file of that simulator (ROMEO's vehicle YAML), or None.
    """

    profile: VehicleProfile
    seed: int = 0
    config: Path | None = None


@runtime_checkable
class Simulator(Protocol):
    """A simulated vehicle that ``coral-run --sim`` can run a mission against."""

    @property
    def name(self) -> str:
        """Its registry name (``romeo``, ``generic``)."""
        ...

    @property
    def summary(self) -> str:
        """One line for ``--help`` and error messages."""
        ...

    @property
    def vehicles(self) -> tuple[str, ...]:
        """The vehicle names (profile ``vehicle:``) it models in particular; () for any."""
        ...

    def create(self, request: SimulatorRequest) -> VehicleModel:
        """The vehicle, ready to be served.

        Raises:
            SimulatorError: it cannot simulate this profile (say why), or the config
                file is wrong (name the file and field).
        """
        ...


def _load(value: str, origin: str) -> Simulator:
    module_name, _, attribute = value.partition(":")
    try:
        obj = getattr(importlib.import_module(module_name), attribute)
    except (ImportError, AttributeError) as exc:
        raise SimulatorError(f"{origin}: cannot load simulator {value!r}: {exc}") from None
    if not isinstance(obj, Simulator):
        raise SimulatorError(f"{origin}: {value!r} is not a coral simulator")
    return obj


@functools.cache
def simulators() -> dict[str, str]:
    """Every registered simulator: name -> its "module:attribute" (entry points first).

    Read once per process: a fuzz campaign builds a vehicle per run."""
    found = {ep.name: ep.value for ep in metadata.entry_points(group=ENTRY_POINT_GROUP)}
    return {**BUNDLED, **found}


def choose_simulator(profile: VehicleProfile, name: str | None = None) -> Simulator:
    """The simulator called ``name``, or (None) the one for ``profile``'s vehicle.

    Without a name, a simulator that lists the vehicle in `Simulator.vehicles` wins;
    otherwise the generic one, which runs any profile.

    Raises:
        SimulatorError: no simulator has that name, or it cannot be loaded.
    """
    table = simulators()
    if name is not None:
        if name not in table:
            known = ", ".join(sorted(table))
            raise SimulatorError(
                f"no simulator called {name!r}{did_you_mean(name, sorted(table))}; "
                f"registered: {known}"
            )
        return _load(table[name], f"simulator {name!r}")
    for key in sorted(table):
        if key == "generic":
            continue
        candidate = _load(table[key], f"simulator {key!r}")
        if profile.name in candidate.vehicles:
            return candidate
    return _load(table["generic"], "simulator 'generic'")


def create_vehicle(
    profile: VehicleProfile,
    *,
    simulator: str | None = None,
    seed: int = 0,
    config: Path | None = None,
    faults: FaultPlan | None = None,
) -> VehicleModel:
    """A simulated vehicle for ``profile``, with ``faults`` injected when given.

    The simulator is `choose_simulator`'s; a non-empty fault plan is checked against the
    profile and wraps the vehicle in a `runtime.vehicle.faults.FaultInjector` seeded from
    ``seed``, so the same seed gives the same forced replies.

    Raises:
        SimulatorError: no such simulator, or it cannot simulate the profile.
        runtime.faultplan.FaultPlanError: a rule names a command or reply kind the
            profile does not have.
    """
    chosen = choose_simulator(profile, simulator)
    return inject_faults(
        chosen.create(SimulatorRequest(profile, seed, config)), profile, faults, seed
    )


def inject_faults(
    model: VehicleModel, profile: VehicleProfile, faults: FaultPlan | None, seed: int
) -> VehicleModel:
    """``model`` with ``faults`` injected (itself when there are none); see `create_vehicle`.

    Raises:
        runtime.faultplan.FaultPlanError: a rule does not fit the profile.
    """
    if faults is None or not faults.rules:
        return model
    from runtime.vehicle.faults import FaultInjector

    faults.check(profile)
    return FaultInjector(model, profile, faults, seed=seed ^ 0xFA17)
