"""The one way a simulated vehicle is described, built and served, for ``coral-run`` and
fuzzing.

``coral-run --sim`` builds one vehicle per run, ``coral-run fuzz`` one per run seed;
both go through `VehicleSpec`, so a simulator name, a settings file and a fault plan
mean the same in each, and through `serve_simulated`, which serves the vehicle on the
wire protocol and joins the controller's link to it (in memory, or over localhost
sockets for a real-time run), through the link emulator. The spec is plain, picklable
data (no callables): a fuzz campaign can hand it to worker processes, each building its
vehicles from it and a run seed.

Vehicles are reached through `runtime.vehicle.registry`, by name: the controller's side
never imports a vehicle implementation (docs/architecture.md).
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from runtime.link import Link, LinkEmulator, MemoryLink, SocketLink
from runtime.linkpipe import quiet

if TYPE_CHECKING:
    from coral_lang.profile import VehicleProfile
    from runtime.eventlog import EventLog
    from runtime.faultplan import FaultPlan
    from runtime.vehicle.model import VehicleModel
    from runtime.vehicle.server import VehicleServer

__all__ = ["VehicleSpec", "serve_simulated"]


@dataclass(frozen=True)
class VehicleSpec:
    """Which simulated vehicle to build; `build` makes one for a seed.

    Attributes:
        profile: the vehicle profile the mission was compiled against.
        simulator: the registered simulator (None: the one made for the profile's
            vehicle, else the generic one).
        config: that simulator's settings file (ROMEO: a vehicle YAML), if any.
        faults: replies to force (``runtime.faultplan``); a rule with a rate draws from
            the seed given to `build`.
    """

    profile: VehicleProfile
    simulator: str | None = None
    config: Path | None = None
    faults: FaultPlan | None = None

    def build(self, seed: int) -> VehicleModel:
        """The vehicle, every random source seeded from ``seed``, faults injected.

        Raises:
            runtime.vehicle.registry.SimulatorError: no such simulator, or it cannot
                simulate the profile, or its settings file is wrong.
            runtime.faultplan.FaultPlanError: a fault rule does not fit the profile.
        """
        from runtime.vehicle.registry import create_vehicle

        return create_vehicle(
            self.profile,
            simulator=self.simulator,
            seed=seed,
            config=self.config,
            faults=self.faults,
        )


@contextlib.asynccontextmanager
async def serve_simulated(
    model: VehicleModel,
    psk: bytes,
    emulator: LinkEmulator | None,
    *,
    nonces: Callable[[int], bytes],
    sockets: bool = False,
    speed: float = 1.0,
    log: Callable[[str], None] = quiet,
    link_log: Callable[[str], None] = quiet,
    event_log: EventLog | None = None,
) -> AsyncIterator[tuple[VehicleServer[VehicleModel], Link]]:
    """Serve ``model`` on the running loop's clock and yield it with a link to it.

    Args:
        model: the vehicle (`VehicleSpec.build`).
        psk: the pre-shared key both ends use.
        emulator: the link emulator on the controller's side (None: a perfect link).
        nonces: the server's handshake nonces (seeded, for a reproducible run).
        sockets: serve on localhost TCP and UDP (real time) rather than in memory.
        speed: simulator seconds per loop second (1 under virtual time).
        log: the server's progress lines.
        link_log: the link's lines (resets, outages).
        event_log: the vehicle's own event log, if kept.

    The link is closed, then the server stopped, however the block ends.
    """
    from runtime.vehicle.server import VehicleServer

    loop = asyncio.get_running_loop()
    server = VehicleServer(
        model,
        psk,
        clock=loop.time,
        speed=speed,
        nonces=nonces,
        log=log,
        event_log=event_log,
    )
    try:
        link: Link
        if sockets:
            host, port = await server.start()
            link = SocketLink(host, port, emulator, log=link_log)
        else:
            link = MemoryLink(server, emulator, log=link_log)
        try:
            yield server, link
        finally:
            await link.aclose()
    finally:
        await server.stop()
