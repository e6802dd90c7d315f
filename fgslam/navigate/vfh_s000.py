"""``vfh-s000``: seed 000's "VFH" as its report (§4.1) describes it, flaws kept.

"The laser range finder continuously takes scans of the environment in front of the robot
and returns distance readings from −120° to 120°. The program … found all passable regions
using a 1000mm threshold. The robot then was then programmed to drive toward the middle of
the widest region." The authors add that a robust VFH would need more work: "coding would
be required to ensure that the robot did not turn around. Also, obstacles at different
ranges would be treated differently." Those flaws are the seed's, and kept here.

So, on the newest scan only (no memory): rays between −120° and 120° (the Kinect's 57°
shows what it shows); a passable region is a run of consecutive rays whose range exceeds
1 000 mm (an unknown ray is not passable) (:func:`passable_regions`); the robot drives at
cruising speed toward the middle of the widest one (:func:`widest_region_middle_rad`),
the bearing corrected for the turn made since the scan was taken. With no passable region
it turns in place (left). Before the first scan it waits.

The seed says nothing about the bumper, so a bump changes nothing: the robot keeps its
logic (the safety monitor stops the wheels; the next command drives on).
"""

from __future__ import annotations

import math

import numpy as np

from fgslam.navigate.common import CRUISE_SPEED_M_S, MAX_TURN_RATE_RAD_S, Command, Situation, limited_command, turn_towards
from slamio.geometry import wrap_angle
from slamio.scan import Scan

__all__ = ["VfhS000", "passable_regions", "widest_region_middle_rad"]

SEED_THRESHOLD_M = 1.0
SEED_HALF_VIEW_RAD = math.radians(120)


def passable_regions(scan: Scan, threshold_m: float = SEED_THRESHOLD_M,
                     half_view_rad: float = SEED_HALF_VIEW_RAD) -> list[tuple[int, int]]:
    """Runs (first ray index, number of rays) of consecutive rays within ±``half_view_rad``
    whose range exceeds ``threshold_m`` (``inf`` passes, ``nan`` does not)."""
    in_view = np.abs(scan.angles_rad) <= half_view_rad
    passable = in_view & (np.nan_to_num(scan.ranges_m, nan=-1.0) > threshold_m)
    runs, k, n = [], 0, len(passable)
    while k < n:
        if passable[k]:
            j = k
            while j < n and passable[j]:
                j += 1
            runs.append((k, j - k))
            k = j
        else:
            k += 1
    return runs


def widest_region_middle_rad(scan: Scan, threshold_m: float = SEED_THRESHOLD_M) -> float | None:
    """The robot-frame bearing of the middle of the widest passable region (the first of
    equally wide ones), ``None`` when there is none. Width is the angle the region spans."""
    regions = passable_regions(scan, threshold_m)
    if not regions:
        return None
    angles = scan.angles_rad
    spans = [angles[first + length - 1] - angles[first] for first, length in regions]
    first, length = regions[int(np.argmax(spans))]
    return float(0.5 * (angles[first] + angles[first + length - 1]))


class VfhS000:
    """Seed 000's widest-gap follower (module docstring)."""

    name = "vfh-s000"

    def __init__(self, *, seed: int = 0, threshold_m: float = SEED_THRESHOLD_M):
        self.threshold_m = threshold_m

    def step(self, situation: Situation) -> Command:
        if situation.scan is None or situation.scan_pose is None:
            return limited_command(0.0, 0.0, "wait")
        middle = widest_region_middle_rad(situation.scan, self.threshold_m)
        if middle is None:
            return limited_command(0.0, MAX_TURN_RATE_RAD_S, "scan-turn")
        error = wrap_angle(situation.scan_pose[2] + middle - situation.pose[2])
        return limited_command(CRUISE_SPEED_M_S, turn_towards(error), "drive")
