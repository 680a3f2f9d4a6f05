"""The vehicle server's look-ahead under virtual time changes nothing anyone can see.

Under `runtime.vclock.VirtualTimeLoop` the server takes quiet ticks ahead of the clock
(`VehicleServer._quiet_ticks`). These tests run the same scenario twice, with the
look-ahead and without it (a server whose clock is not the loop's own takes no tick
ahead), and compare everything observable: the targets the vehicle is advanced to, the
clock readings at which replies are issued and telemetry sampled, and the readings
another task's timers see.
"""

from __future__ import annotations

import asyncio
import random
from dataclasses import dataclass, field

from hypothesis import given, settings
from hypothesis import strategies as st

from runtime.telemetry import TelemetryRecord
from runtime.vclock import run_virtual
from runtime.vehicle.model import Params, Reply
from runtime.vehicle.server import VehicleServer

PSK = bytes(range(32))


@dataclass
class _Recorder:
    """A vehicle that replies now and then, and writes down how it was driven."""

    seed: int
    clock: float = 0.0
    advances: list[float] = field(default_factory=list)
    samples: list[float] = field(default_factory=list)

    def __post_init__(self) -> None:
        self._rng = random.Random(self.seed)
        self._next_id = 0

    @property
    def time(self) -> float:
        return self.clock

    @property
    def watchdog_s(self) -> float:
        return 0.0

    def advance_to(self, t: float) -> list[Reply]:
        self.advances.append(t)
        self.clock = max(self.clock, t)
        if self._rng.random() < 0.1:
            self._next_id += 1
            return [Reply(self._next_id, "PING", "done", self.clock, "")]
        return []

    def command(self, command_id: int, name: str, params: Params) -> list[Reply]:
        return []

    def heard_from_controller(self) -> None:
        pass

    def make_safe(self, reason: str) -> list[Reply]:
        return []

    def telemetry(self) -> TelemetryRecord | None:
        self.samples.append(self.clock)
        return None


@dataclass
class _Seen:
    advances: list[float]
    samples: list[float]
    issued: list[tuple[float, tuple[int, ...]]]
    others: list[float]


def _scenario(seed: int, delays: list[float], lookahead: bool) -> _Seen:
    async def main() -> _Seen:
        loop = asyncio.get_running_loop()
        vehicle = _Recorder(seed)
        clock = loop.time if lookahead else (lambda: loop.time())
        server = VehicleServer(vehicle, PSK, clock=clock, log=lambda _: None)
        issued: list[tuple[float, tuple[int, ...]]] = []
        plain_issue = server._issue

        def issue(replies: list[Reply]) -> None:
            if replies:
                issued.append((loop.time(), tuple(r.command_id for r in replies)))
            plain_issue(replies)

        server._issue = issue  # type: ignore[method-assign]
        others: list[float] = []

        async def other() -> None:  # another task's timers: the horizon
            for delay in delays:
                await asyncio.sleep(delay)
                others.append(loop.time())

        await server.start_detached()
        try:
            await other()
            await asyncio.sleep(3.0)
        finally:
            await server.stop()
        return _Seen(vehicle.advances, vehicle.samples, issued, others)

    return run_virtual(main(), start=0.0)


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**32),
    delays=st.lists(
        st.one_of(st.floats(0.0, 3.0), st.sampled_from([0.05, 0.1, 0.5, 1.0])), max_size=12
    ),
)
def test_ticks_taken_ahead_change_nothing_observable(seed: int, delays: list[float]) -> None:
    assert _scenario(seed, delays, lookahead=True) == _scenario(seed, delays, lookahead=False)


def test_the_lookahead_does_take_ticks_ahead() -> None:
    """Without other timers, the stepping task wakes for samples and replies only."""
    wakes: list[int] = []

    async def main() -> None:
        loop = asyncio.get_running_loop()
        server = VehicleServer(_Recorder(1), PSK, clock=loop.time, log=lambda _: None)
        plain = server.catch_up

        def counted() -> None:
            wakes.append(1)
            plain()

        server.catch_up = counted  # type: ignore[method-assign]
        await server.start_detached()
        await asyncio.sleep(60.0)
        await server.stop()

    run_virtual(main())
    # 60 s at 20 ticks a second is 1,200 ticks; telemetry at 2 Hz wakes it 120 times,
    # and about a tenth of the ticks taken ahead produce a reply (held, no catch_up).
    assert 100 <= len(wakes) < 300
