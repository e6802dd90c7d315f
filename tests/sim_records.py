"""Simulated runs for the simulator's tests, cached, and the independent reading of their
records (which landmark is in view, and its exact range and bearing, recomputed with
``math`` one landmark at a time)."""

from __future__ import annotations

import functools
import math

from slamio.geometry import wrap_angle
from slamio.log import TruthLandmark
from slamio.sim import simulate


# Small but complete variants of every scenario, used by the exactness tests.
SMALL = [
    ("arena-square", {}),
    ("arena-octagon", {}),
    ("cylinders", {"laps": 1}),
    ("grid", {"landmarks": 30, "laps": 1}),
]


@functools.lru_cache(maxsize=None)
def sim(scenario: str, seed: int, **kwargs):
    """Cached ``simulate`` (records are immutable; the list is converted to a tuple)."""
    header, records = simulate(scenario, seed, **kwargs)
    return header, tuple(records)


def of_type(records, cls):
    return [r for r in records if isinstance(r, cls)]


def truth_map(records) -> dict[int, TruthLandmark]:
    return {r.landmark_id: r for r in of_type(records, TruthLandmark)}


def in_view(pose, landmark: TruthLandmark, sensor: dict) -> tuple[bool, float, float]:
    """Independent visibility test and exact (range, bearing) of one landmark from one pose."""
    x, y, th = pose
    dx, dy = landmark.x_m - x, landmark.y_m - y
    range_m = math.hypot(dx, dy)
    bearing_rad = wrap_angle(math.atan2(dy, dx) - th)
    seen = sensor["min_range_m"] <= range_m <= sensor["max_range_m"] and abs(bearing_rad) <= sensor["fov_rad"] / 2
    if sensor["landmark_kind"] == "apriltag":
        # the tag's face normal against the tag→robot direction
        cos_facing = (math.cos(landmark.yaw_rad) * -dx + math.sin(landmark.yaw_rad) * -dy) / range_m
        seen = seen and cos_facing >= math.cos(sensor["facing_limit_rad"])
    return seen, range_m, bearing_rad
