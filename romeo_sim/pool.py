"""The pool: a rectangular basin with walls, a surface, a bottom and an optional current.

Frame (used everywhere in the simulator): origin at the south-west corner of the pool, at
the surface; x points north along the pool's length, y east along its width, z down
(depth). Headings are clockwise from north, so heading 0 faces +x and 90 faces +y.

Walls are numbered by the bearing of their outward normal: 0 north (x = length), 1 east
(y = width), 2 south (x = 0), 3 west (y = 0).
"""

from __future__ import annotations

import math

from romeo_sim.config import PoolConfig

__all__ = ["WALL_NAMES", "Pool"]

WALL_NAMES: tuple[str, str, str, str] = ("north", "east", "south", "west")
_HALF_PI = 0.5 * math.pi


class Pool:
    """Geometry of the pool, with the few queries the sonar and the guidance need.

    Args:
        config: the pool's size and current.
    """

    __slots__ = ("current_east", "current_north", "depth", "length", "width")

    def __init__(self, config: PoolConfig) -> None:
        self.length = config.length_m
        self.width = config.width_m
        self.depth = config.depth_m
        self.current_north = config.current_north_m_s
        self.current_east = config.current_east_m_s

    def ray_range(self, x: float, y: float, bearing: float) -> float:
        """Distance from (x, y) along ``bearing`` (rad, clockwise from north) to a wall."""
        c = math.cos(bearing)
        s = math.sin(bearing)
        if c > 1e-12:
            tx = (self.length - x) / c
        elif c < -1e-12:
            tx = -x / c
        else:
            tx = math.inf
        if s > 1e-12:
            ty = (self.width - y) / s
        elif s < -1e-12:
            ty = -y / s
        else:
            ty = math.inf
        return tx if tx < ty else ty

    def wall_distance(self, wall: int, x: float, y: float) -> float:
        """Perpendicular distance from (x, y) to ``wall`` (0 north, 1 east, 2 south, 3 west)."""
        if wall == 0:
            return self.length - x
        if wall == 1:
            return self.width - y
        if wall == 2:
            return x
        return y

    def contains(self, x: float, y: float, margin: float = 0.0) -> bool:
        """True when (x, y) lies at least ``margin`` inside every wall."""
        return margin <= x <= self.length - margin and margin <= y <= self.width - margin


def nearest_wall(bearing: float) -> tuple[int, float]:
    """The wall whose outward normal is closest to ``bearing`` (rad), and the angle off it.

    Returns:
        (wall index, signed angle in rad from that wall's normal, in [-pi/4, pi/4]).
    """
    quarter = round(bearing / _HALF_PI)
    return quarter % 4, bearing - quarter * _HALF_PI
