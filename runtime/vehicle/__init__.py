"""The vehicle side of the coral wire protocol: what puts a vehicle on the wire.

``model`` is the contract (`VehicleModel`); the rest of this package is built on it.
Nothing here imports the controller's side of ``runtime`` (engine, controller, links).

What an integrator needs is re-exported here (``docs/vehicles.md``): `HandlerVehicle`
and `Refused` to describe their vehicle command by command, `VehicleServer` (or the
`run_vehicle` / `serve_vehicle` helpers) to serve it. The simulators (the generic one in
``runtime.vehicle.generic``, ROMEO's in ``romeo_sim``) are plugins found through
``runtime.vehicle.registry``, not imported here.
"""

from runtime.vehicle.handlers import HandlerVehicle, Job, Outcome, Refused, check_params
from runtime.vehicle.model import (
    Params,
    Reply,
    TelemetryRecord,
    VehicleModel,
)
from runtime.vehicle.server import ServerStats, VehicleServer, run_vehicle, serve_vehicle

__all__ = [
    "HandlerVehicle",
    "Job",
    "Outcome",
    "Params",
    "Refused",
    "Reply",
    "ServerStats",
    "TelemetryRecord",
    "VehicleModel",
    "VehicleServer",
    "check_params",
    "run_vehicle",
    "serve_vehicle",
]
