"""The simulated ROMEO: 4-DOF dynamics, sensors, navigation, task functions and queries.

`Vehicle` is the one object a runtime needs: commands in, replies and telemetry out,
time injected. The rest is here for tests, the bench and the ``romeo-sim`` program.
"""

from romeo_sim.config import (
    VehicleConfig,
    VehicleConfigError,
    default_config,
    load_vehicle_config,
    parse_vehicle_config,
)
from romeo_sim.recorder import CommandRecord, Recorder
from romeo_sim.scenario import MissionResult, Phase, PoolMission, run_pool_mission
from romeo_sim.vehicle import SUPPORTED_COMMANDS, Reply, Telemetry, Vehicle, VehicleEvent

__all__ = [
    "SUPPORTED_COMMANDS",
    "CommandRecord",
    "MissionResult",
    "Phase",
    "PoolMission",
    "Recorder",
    "Reply",
    "Telemetry",
    "Vehicle",
    "VehicleConfig",
    "VehicleConfigError",
    "VehicleEvent",
    "default_config",
    "load_vehicle_config",
    "parse_vehicle_config",
    "run_pool_mission",
]
