"""``explore-s001``: seed 001's outer navigation loop as its paper writes it.

"The robot has an outer navigation control loop where it scans for obstacles and changes
orientation in steps till it finds an obstacle. It then moves towards the nearest obstacle
and stops when it reaches within 2.5 robot lengths. Then it turns 45° left or right based on
a random selection and repeats the process." Its robot moves only forward or turns in place,
each move under encoder control to a target; there is no backing up and no arcs.

Here, one cycle is a small state machine:

* ``scan-wait`` — stand still until a scan taken *after* the robot stopped arrives; if it
  holds a hit (any finite range), the nearest one becomes the target (a map-frame point,
  :func:`nearest_obstacle`); if not, ``scan-step``: turn ``step_rad`` (30°; the paper does
  not give the step) and scan again;
* ``face`` — turn in place to face the target;
* ``approach`` — drive straight toward it until within ``2.5 × 0.34 m`` of it (the Create is
  0.34 m long); the distance is fixed when the move starts, as an encoder target is
  (:func:`approach_distance_m`);
* ``turn-45`` — turn 45° left or right, chosen by the seeded generator; then scan again.

The paper says nothing of a bumper: a bump changes nothing (the safety monitor stops the
wheels; the robot keeps trying to finish its move).
"""

from __future__ import annotations

import math

import numpy as np

from fgslam.navigate.common import (CRUISE_SPEED_M_S, MAX_TURN_RATE_RAD_S, ROBOT_LENGTH_M, Command, Situation,
                                    heading_error_rad, limited_command, turn_towards)
from slamio.geometry import wrap_angle
from slamio.scan import Scan

__all__ = ["ExploreS001", "nearest_obstacle", "approach_distance_m", "STOP_DISTANCE_M"]

STOP_DISTANCE_M = 2.5 * ROBOT_LENGTH_M


def nearest_obstacle(scan: Scan, scan_pose) -> tuple[float, float, float] | None:
    """(x, y, range) in the map frame of the scan's nearest hit, ``None`` when nothing was hit."""
    ranges = np.where(np.isfinite(scan.ranges_m), scan.ranges_m, np.inf)
    k = int(np.argmin(ranges))
    if not np.isfinite(ranges[k]):
        return None
    bearing = scan_pose[2] + scan.angles_rad[k]
    r = float(ranges[k])
    return scan_pose[0] + r * math.cos(bearing), scan_pose[1] + r * math.sin(bearing), r


def approach_distance_m(range_m: float, stop_m: float = STOP_DISTANCE_M) -> float:
    """How far to drive toward an obstacle ``range_m`` away to stop ``stop_m`` from it (0 if
    already within)."""
    return max(0.0, range_m - stop_m)


class ExploreS001:
    """Seed 001's scan / approach / turn-45 loop (module docstring)."""

    name = "explore-s001"

    def __init__(self, *, seed: int = 0, step_rad: float = math.radians(30), tolerance_rad: float = math.radians(2)):
        self.rng = np.random.default_rng(seed)
        self.step_rad, self.tolerance_rad = step_rad, tolerance_rad
        self.state = "scan-wait"
        self._stale_scan = None  # scans up to this one were taken before the robot stopped
        self._target_heading = 0.0
        self._target_xy = (0.0, 0.0)
        self._start_xy = (0.0, 0.0)
        self._distance_m = 0.0

    def _turn_to(self, heading_rad: float, state: str) -> None:
        self._target_heading = float(wrap_angle(heading_rad))
        self.state = state

    def _rotate(self, situation: Situation) -> bool:
        """Turn toward the target heading; True once there."""
        error = heading_error_rad(situation.pose, self._target_heading)
        return abs(error) <= self.tolerance_rad

    def step(self, situation: Situation) -> Command:
        pose = situation.pose
        if self.state == "scan-wait":
            fresh = (situation.scan is not None and situation.scan is not self._stale_scan
                     and abs(heading_error_rad(situation.scan_pose, pose[2])) <= self.tolerance_rad)
            if not fresh:
                return limited_command(0.0, 0.0, "scan-wait")
            target = nearest_obstacle(situation.scan, situation.scan_pose)
            if target is None:
                self._turn_to(pose[2] + self.step_rad, "scan-step")
            else:
                self._target_xy = target[:2]
                self._turn_to(math.atan2(target[1] - pose[1], target[0] - pose[0]), "face")
        if self.state in ("scan-step", "face", "turn-45"):
            if not self._rotate(situation):
                error = heading_error_rad(pose, self._target_heading)
                rate = turn_towards(error, 3.0)
                rate = math.copysign(max(abs(rate), 0.2), error)
                return limited_command(0.0, rate, self.state)
            if self.state == "face":
                range_m = math.hypot(self._target_xy[0] - pose[0], self._target_xy[1] - pose[1])
                self._distance_m, self._start_xy, self.state = approach_distance_m(range_m), pose[:2], "approach"
            else:
                self._stale_scan, self.state = situation.scan, "scan-wait"
                return limited_command(0.0, 0.0, "scan-wait")
        if self.state == "approach":
            travelled = math.hypot(pose[0] - self._start_xy[0], pose[1] - self._start_xy[1])
            if travelled < self._distance_m:
                return limited_command(min(CRUISE_SPEED_M_S, 2.0 * (self._distance_m - travelled) + 0.02), 0.0, "approach")
            side = 1.0 if self.rng.integers(2) else -1.0
            self._turn_to(pose[2] + side * math.radians(45), "turn-45")
            return limited_command(0.0, side * MAX_TURN_RATE_RAD_S, "turn-45")
        return limited_command(0.0, 0.0, self.state)
