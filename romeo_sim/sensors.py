"""Sensors: depth gauge, compass with rate gyro, mechanically scanning sonar.

All noise comes from seeded numpy Generators, one independent stream per sensor (so a
change to one sensor does not shift the noise of the others). Draws are taken in blocks
and handed out one float at a time: a numpy call per sample would cost more than the
whole dynamics step. The sensors read once per step, so they keep what they need of
their configuration and noise stream in attributes of their own.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from itertools import chain, repeat

import numpy as np
import numpy.typing as npt

from romeo_sim.config import SensorConfig
from romeo_sim.dynamics import Dynamics
from romeo_sim.pool import Pool

__all__ = ["Compass", "DepthGauge", "NoiseStream", "ScanningSonar", "SonarPing"]

_BLOCK = 4096
_PI = math.pi
_TWO_PI = 2.0 * math.pi
_INF = math.inf


class NoiseStream:
    """Standard normal and uniform [0, 1) samples from one seeded Generator, in blocks.

    ``normal`` and ``uniform`` are the bound ``__next__`` of endless iterators built from
    C iterators only (a chain over blocks of draws): calling one costs about as much as a
    list index, which matters at one call per sensor per step.

    Args:
        seed: a SeedSequence (or anything `numpy.random.default_rng` accepts).
    """

    __slots__ = ("normal", "uniform")

    def __init__(self, seed: np.random.SeedSequence | int) -> None:
        sequence = (
            seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
        )
        normal_seed, uniform_seed = sequence.spawn(2)
        normals = np.random.default_rng(normal_seed).standard_normal
        uniforms = np.random.default_rng(uniform_seed).random
        self.normal: Callable[[], float] = _samples(normals).__next__
        self.uniform: Callable[[], float] = _samples(uniforms).__next__


def _samples(draw: Callable[[int], npt.NDArray[np.float64]]) -> Iterator[float]:
    """The endless stream of ``draw``'s samples, drawn `_BLOCK` at a time when needed."""
    return chain.from_iterable(map(_block, repeat(draw)))


def _block(draw: Callable[[int], npt.NDArray[np.float64]]) -> list[float]:
    block: list[float] = draw(_BLOCK).tolist()
    return block


class DepthGauge:
    """Pressure depth sensor: true depth plus white noise, never reads above the surface."""

    __slots__ = ("_normal", "_sd")

    def __init__(self, config: SensorConfig, noise: NoiseStream) -> None:
        self._sd = config.depth_sd_m
        self._normal = noise.normal

    def read(self, body: Dynamics) -> float:
        """Depth, m (down positive)."""
        value = body.z + self._sd * self._normal()
        return value if value > 0.0 else 0.0


class Compass:
    """Magnetic compass (heading) with a rate gyro (yaw rate), both with white noise."""

    __slots__ = ("_gyro_sd", "_normal", "_sd")

    def __init__(self, config: SensorConfig, noise: NoiseStream) -> None:
        self._sd = math.radians(config.compass_sd_deg)
        self._gyro_sd = math.radians(config.gyro_sd_deg_s)
        self._normal = noise.normal

    def read(self, body: Dynamics) -> tuple[float, float]:
        """(heading rad, yaw rate rad/s), heading clockwise from north, not wrapped."""
        normal = self._normal
        return body.psi + self._sd * normal(), body.r + self._gyro_sd * normal()


class SonarPing:
    """The latest ping; one mutable object, reused (the sonar pings every step)."""

    __slots__ = ("false_return", "head", "range", "time")

    def __init__(self) -> None:
        self.time = 0.0
        self.head = 0.0  # rad, relative to the bow, clockwise
        self.range = 0.0  # m; math.inf when nothing came back
        self.false_return = False  # ground truth, for tests and plots only


class ScanningSonar:
    """A mechanically scanning sonar at the vehicle's centre, one ping per step.

    The head turns a full revolution in ``sonar_revolution_s``. Each ping returns the range
    to the first wall along the beam, with noise. Shallower than
    ``surface_clutter_depth_m``, the upper half of the beam reaches the surface at about
    ``depth / sin(vertical beam / 2)``; when that is shorter than the wall, a growing
    fraction of pings (up to ``surface_clutter_max_fraction`` at depth 0) return that
    surface echo, a false short range, as ROMEO's sonar did at the end of docking in the
    paper's pool trial. The surface echoes are consistent with each other, which is what
    makes them dangerous: they fool a median as easily as a mean.

    Args:
        config: noise, scan rate, clutter.
        pool: the walls.
        step_s: time between pings, s.
        noise: this sensor's noise stream.
    """

    def __init__(self, config: SensorConfig, pool: Pool, step_s: float, noise: NoiseStream) -> None:
        self._pool = pool
        self._sd = config.sonar_range_sd_m
        self._max = config.sonar_max_range_m
        self._clutter_depth = config.surface_clutter_depth_m
        self._clutter_max = config.surface_clutter_max_fraction
        self._surface_slant = 1.0 / math.sin(math.radians(0.5 * config.sonar_vertical_beam_deg))
        self._normal = noise.normal
        self._uniform = noise.uniform
        self.head_step = 2.0 * math.pi * step_s / config.sonar_revolution_s
        self.revolution_s = config.sonar_revolution_s
        self.ping = SonarPing()

    def clutter_fraction(self, depth: float) -> float:
        """Fraction of pings whose beam is dominated by the surface echo at ``depth``.

        Grows as the square root of the distance above ``surface_clutter_depth_m``: the
        surface takes a large share of the beam soon after it first touches it.
        """
        if depth >= self._clutter_depth:
            return 0.0
        return self._clutter_max * math.sqrt(1.0 - depth / self._clutter_depth)

    def sense(self, body: Dynamics, time: float) -> SonarPing:
        """Turn the head one step and ping; returns the (reused) ping object."""
        ping = self.ping
        head = ping.head + self.head_step
        if head >= _PI:
            head -= _TWO_PI
        ping.head = head
        ping.time = time
        true_range = self._pool.ray_range(body.x, body.y, body.psi + head)
        measured = true_range + self._sd * self._normal()
        ping.false_return = False
        z = body.z
        if z < self._clutter_depth and self._uniform() < self.clutter_fraction(z):
            echo = 0.3 + z * self._surface_slant * (1.0 + 0.1 * self._normal())
            if echo < true_range:
                # The surface echo arrives before the wall's.
                measured = echo
                ping.false_return = True
        ping.range = measured if 0.0 < measured <= self._max else _INF
        return ping
