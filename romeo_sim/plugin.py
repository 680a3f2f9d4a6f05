"""ROMEO's physics simulator as a coral simulator plugin (``coral-run --sim``).

The runtime reaches vehicle implementations by name through
`runtime.vehicle.registry`, never by importing them; this module is what the name
``romeo`` points at (``pyproject.toml``, entry-point group ``coral.vehicles``). It
translates the simulator's own errors (a bad vehicle file, a profile naming a command
ROMEO cannot carry out) into `SimulatorError`, so the caller reports them like any other
bad input: one message naming the file and field, no traceback.
"""

from __future__ import annotations

from dataclasses import dataclass

from romeo_sim.config import VehicleConfigError, default_config, load_vehicle_config
from romeo_sim.vehicle import Vehicle
from runtime.vehicle.model import VehicleModel
from runtime.vehicle.registry import SimulatorError, SimulatorRequest

__all__ = ["SIMULATOR", "RomeoSimulator"]


@dataclass(frozen=True)
class RomeoSimulator:
    """Builds the simulated ROMEO (`romeo_sim.vehicle.Vehicle`) for a profile.

    ``request.config`` is a ROMEO vehicle file (``docs/sim.md``); without one, the
    bundled defaults. The profile must name only commands ROMEO carries out, and give each
    query a space-trap criterion: ROMEO answers queries by that criterion alone.
    """

    name: str = "romeo"
    summary: str = "ROMEO's 4-DOF physics in a pool, for the ROMEO profile (docs/sim.md)"
    vehicles: tuple[str, ...] = ("ROMEO",)

    def create(self, request: SimulatorRequest) -> VehicleModel:
        """The simulated ROMEO, seeded with ``request.seed``.

        Raises:
            SimulatorError: the vehicle file is unreadable or wrong, or the profile asks
                for something ROMEO cannot do; the message names the file and field.
        """
        try:
            config = (
                load_vehicle_config(request.config)
                if request.config is not None
                else default_config()
            )
            return Vehicle(config, request.profile, seed=request.seed)
        except VehicleConfigError as exc:
            raise SimulatorError(f"simulator 'romeo': {exc}") from None


SIMULATOR = RomeoSimulator()
"""The object ``romeo_sim.plugin:SIMULATOR`` names in the registry."""
