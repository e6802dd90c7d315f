"""A horizontal range scan in the robot's frame: what the navigators steer by.

Whatever made it — the Kinect's depth image (nearest depth per column in the band of rows
between the floor and the robot's height), a 2-D laser, or ray casting in simulation — a scan
is a fan of rays from the robot's centre:

* ``angles_rad``: each ray's bearing in the robot frame (0 straight ahead, positive to the
  left), increasing;
* ``ranges_m``: the distance to the first obstacle along it; ``inf`` where the ray is free
  out to ``max_range_m``; ``nan`` where the sensor could not tell (no depth: glass, black,
  too near) — *unknown*, which a navigator must not treat as free.

A narrow sensor (the Kinect's 57°) leaves most directions without rays at all: a navigator
that wants to go there turns to look first.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from slamio.obstacles import Obstacles, ray_cast_m

__all__ = ["Scan", "scan_from_ranges", "ray_cast_scan"]


@dataclass(frozen=True)
class Scan:
    """Ranges along a fan of rays in the robot frame (module docstring)."""

    angles_rad: np.ndarray
    ranges_m: np.ndarray
    max_range_m: float
    min_range_m: float = 0.0

    def __post_init__(self):
        angles = np.asarray(self.angles_rad, dtype=float).reshape(-1)
        ranges = np.asarray(self.ranges_m, dtype=float).reshape(-1)
        if len(angles) != len(ranges):
            raise ValueError(f"a scan needs one range per angle: {len(angles)} angles, {len(ranges)} ranges")
        if len(angles) > 1 and np.any(np.diff(angles) <= 0):
            raise ValueError("a scan's angles must increase")
        if not self.max_range_m > self.min_range_m >= 0:
            raise ValueError(f"a scan needs 0 <= min_range_m < max_range_m; got {self.min_range_m}, {self.max_range_m}")
        object.__setattr__(self, "angles_rad", angles)
        object.__setattr__(self, "ranges_m", ranges)

    @property
    def known(self) -> np.ndarray:
        """True where the ray's range is known (a hit, or free to the maximum range)."""
        return ~np.isnan(self.ranges_m)

    @property
    def field_of_view_rad(self) -> float:
        """The angle the rays span (0 for one ray)."""
        return float(self.angles_rad[-1] - self.angles_rad[0]) if len(self.angles_rad) else 0.0

    def free_distance_m(self) -> np.ndarray:
        """Each ray's free distance: its range, ``max_range_m`` where free, 0 where unknown."""
        ranges = np.where(np.isinf(self.ranges_m), self.max_range_m, self.ranges_m)
        return np.where(np.isnan(ranges), 0.0, ranges)

    def nearest_m(self) -> float:
        """The nearest known hit (inf when every known ray is free or none is known)."""
        hits = self.ranges_m[np.isfinite(self.ranges_m)]
        return float(hits.min()) if len(hits) else math.inf


def scan_from_ranges(angles_rad, ranges_m, max_range_m: float, min_range_m: float = 0.0) -> Scan:
    """A :class:`Scan` from raw ranges as sensors give them: beyond ``max_range_m`` is free
    (``inf``), below ``min_range_m``, zero, negative or not finite-and-positive is unknown."""
    ranges = np.asarray(ranges_m, dtype=float).copy()
    free = np.isposinf(ranges) | (ranges > max_range_m)
    unknown = ~np.isfinite(ranges) & ~np.isposinf(ranges) | (ranges <= 0) | (ranges < min_range_m)
    ranges[free] = np.inf
    ranges[unknown & ~free] = np.nan
    return Scan(np.asarray(angles_rad, dtype=float), ranges, max_range_m, min_range_m)


def ray_cast_scan(obstacles: Obstacles, pose, field_of_view_rad: float, rays: int, max_range_m: float,
                  min_height_m: float = 0.0) -> Scan:
    """The true scan from a robot at ``pose`` (x, y, θ): ``rays`` rays spread evenly over
    ``field_of_view_rad`` centred straight ahead, cast against the obstacles at least
    ``min_height_m`` tall (a simulated laser; the truth a depth-image scan is checked against)."""
    if rays < 1:
        raise ValueError(f"a scan needs at least one ray, got {rays}")
    half = 0.5 * field_of_view_rad
    angles = np.linspace(-half, half, rays) if rays > 1 else np.zeros(1)
    ranges = ray_cast_m(obstacles, pose[:2], angles + pose[2], max_range_m, min_height_m)
    return Scan(angles, ranges, max_range_m)
