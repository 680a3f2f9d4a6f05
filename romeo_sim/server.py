"""The simulated ROMEO served on the coral wire protocol (``romeo-sim serve``).

The server is not ROMEO's: `runtime.vehicle.server.VehicleServer` serves any
`runtime.vehicle.model.VehicleModel`. This module keeps the old import path working
(``from romeo_sim.server import VehicleServer``) for the code and scripts written before
the move, with the server specialised to ROMEO: ``server.vehicle`` is a
`romeo_sim.vehicle.Vehicle` for type checkers, so callers keep its events, status and
replies. It is called as before: ``VehicleServer(Vehicle(seed=1), psk, ...)``.
"""

from __future__ import annotations

from typing import TypeAlias

from romeo_sim.vehicle import Vehicle
from runtime.vehicle.server import ServerStats
from runtime.vehicle.server import VehicleServer as _AnyVehicleServer

__all__ = ["ServerStats", "VehicleServer"]

VehicleServer: TypeAlias = _AnyVehicleServer[Vehicle]
"""`runtime.vehicle.server.VehicleServer` serving the simulated ROMEO."""
