"""``vfh``: Borenstein and Koren's Vector Field Histogram (1991), with the VFH+ refinements
that make it usable with a narrow, slow depth camera.

From the occupancy grid the scans build (:mod:`fgslam.navigate.grid`, our histogram grid),
each step:

1. the *active window* — occupied cells within ``d_max`` of the robot — votes into a polar
   histogram of ``sectors`` sectors (world frame). A cell of certainty ``c`` at distance ``d``
   adds ``m = c²·(a − b·d)`` with ``a = b·d_max`` (:func:`cell_magnitudes`), enlarged over
   every sector within ``asin((robot radius + margin)/d)`` of its bearing (VFH+), so a free
   sector means the robot's disc fits that way (:func:`polar_histogram`);
2. the histogram is smoothed with the paper's triangular window of half-width ``l``
   (:func:`smooth_histogram`) and thresholded with hysteresis (two thresholds, VFH+;
   :func:`blocked_sectors`) into blocked and free sectors. A sector whose near cells were
   never seen is *unknown*: not free;
3. runs of free, known sectors are the candidate valleys (:func:`valleys`). A wide valley
   (more than ``s_max`` sectors) offers the directions ``s_max/2`` in from each border, and the
   goal direction itself when it lies well inside; a narrow one its middle (the paper's
   k_n/k_f rule; :func:`candidate_directions`). The robot takes the candidate that costs least
   in turning from the goal, its heading and its previous choice (VFH+'s cost with
   hysteresis, so it does not dither or turn round; :func:`choose_direction`);
4. speed falls with the smoothed density ahead and with the turn still to make, and is 0
   when an occupied cell lies in the corridor ahead within the stopping distance.

When the goal direction was never seen the robot turns to look at it before it commits;
with no valley at all it turns toward the nearest unknown sector (or in place when boxed in).
Without a goal point it wanders: the goal heading is kept and changed by a random turn every
``wander_period_s``. On a bump it backs off ~0.15 m and turns away (:class:`BackOff`), and
marks where it hit in the grid (something the scan did not show).
"""

from __future__ import annotations

import math

import numpy as np

from fgslam.navigate.common import (CRUISE_SPEED_M_S, ROBOT_RADIUS_M, BackOff, Command, Situation, heading_error_rad,
                                    limited_command, turn_towards)
from fgslam.navigate.grid import OccupancyGrid
from slamio.geometry import wrap_angle

__all__ = ["Vfh", "cell_magnitudes", "polar_histogram", "smooth_histogram", "blocked_sectors", "valleys",
           "candidate_directions", "choose_direction", "sector_angles_rad"]


def sector_angles_rad(sectors: int) -> np.ndarray:
    """The centre bearing of each sector: sector k spans [−π + k·α, −π + (k+1)·α), α = 2π/sectors."""
    return -math.pi + (np.arange(sectors) + 0.5) * (2 * math.pi / sectors)


def cell_magnitudes(certainty, distance_m, d_max_m: float, b: float = 1.0) -> np.ndarray:
    """The paper's obstacle vector magnitude ``c²·(a − b·d)`` with ``a = b·d_max`` (0 beyond d_max)."""
    certainty, distance = np.asarray(certainty, dtype=float), np.asarray(distance_m, dtype=float)
    return certainty**2 * np.maximum(b * d_max_m - b * distance, 0.0)


def polar_histogram(cells_xy, certainty, robot_xy, sectors: int, d_max_m: float, enlarge_m: float) -> np.ndarray:
    """Obstacle density per world-frame sector (module docstring, step 1)."""
    offset = np.asarray(cells_xy, dtype=float).reshape(-1, 2) - np.asarray(robot_xy, dtype=float)
    distance = np.hypot(offset[:, 0], offset[:, 1])
    near = distance < d_max_m
    offset, distance, certainty = offset[near], distance[near], np.asarray(certainty, dtype=float)[near]
    if len(distance) == 0:
        return np.zeros(sectors)
    bearing = np.arctan2(offset[:, 1], offset[:, 0])
    magnitude = cell_magnitudes(certainty, distance, d_max_m)
    spread = np.arcsin(np.clip(enlarge_m / np.maximum(distance, 1e-9), 0.0, 1.0))
    spread = np.where(distance <= enlarge_m, math.pi / 2, spread)  # inside the margin: the whole half-plane
    # each cell adds its magnitude to the sectors whose centre lies within spread + α/2 of
    # its bearing: a run of sectors [first, last] (unwrapped), summed with a difference array
    alpha = 2 * math.pi / sectors
    reach = spread + 0.5 * alpha
    first = np.ceil((bearing - reach + math.pi) / alpha - 0.5 - 1e-12).astype(int)
    last = np.floor((bearing + reach + math.pi) / alpha - 0.5 + 1e-12).astype(int)
    last = np.minimum(last, first + sectors - 1)
    difference = np.zeros(3 * sectors + 1)
    np.add.at(difference, first + sectors, magnitude)
    np.add.at(difference, last + sectors + 1, -magnitude)
    return np.cumsum(difference[:-1]).reshape(3, sectors).sum(axis=0)


def smooth_histogram(histogram, half_width: int) -> np.ndarray:
    """The paper's smoothing ``h'_k = Σ_{i=−l..l} (l + 1 − |i|)·h_{k+i} / (2l + 1)``, circular."""
    h = np.asarray(histogram, dtype=float)
    if half_width == 0:
        return h.copy()
    weights = (half_width + 1 - np.abs(np.arange(-half_width, half_width + 1))) / (2 * half_width + 1)
    return np.convolve(np.concatenate([h[-half_width:], h, h[:half_width]]), weights, mode="valid")


def blocked_sectors(smoothed, low: float, high: float, previous=None) -> np.ndarray:
    """Blocked above ``high``, free below ``low``, as before in between (VFH+ hysteresis)."""
    smoothed = np.asarray(smoothed, dtype=float)
    before = np.zeros(len(smoothed), bool) if previous is None else np.asarray(previous, bool)
    return np.where(smoothed > high, True, np.where(smoothed < low, False, before))


def valleys(free) -> list[tuple[int, int]]:
    """Runs of free sectors as (first sector, length), circular (a run may wrap past the last
    sector); one run of every sector when all are free."""
    free = np.asarray(free, bool)
    n = len(free)
    if free.all():
        return [(0, n)]
    if not free.any():
        return []
    start = int(np.argmin(free))  # a blocked sector: runs after it do not wrap
    rolled = np.roll(free, -start)
    runs, k = [], 0
    while k < n:
        if rolled[k]:
            j = k
            while j < n and rolled[j]:
                j += 1
            runs.append(((k + start) % n, j - k))
            k = j
        else:
            k += 1
    return runs


def candidate_directions(valley_list, sectors: int, goal_rad: float, s_max: int) -> list[float]:
    """Directions (world-frame radians) the valleys offer (module docstring, step 3)."""
    angles = sector_angles_rad(sectors)
    alpha = 2 * math.pi / sectors
    out = []
    for first, length in valley_list:
        if length == sectors:
            return [goal_rad]
        right, left = angles[first], angles[(first + length - 1) % sectors]
        if length <= s_max:
            out.append(float(wrap_angle(right + 0.5 * (length - 1) * alpha)))
            continue
        inset = 0.5 * s_max * alpha
        out += [float(wrap_angle(right + inset)), float(wrap_angle(left - inset))]
        from_right = wrap_angle(goal_rad - right) % (2 * math.pi)
        if inset <= from_right <= (length - 1) * alpha - inset:
            out.append(float(goal_rad))
    return out


def choose_direction(candidates, goal_rad: float, heading_rad: float, previous_rad: float | None,
                     weights=(5.0, 2.0, 2.0), no_turning_back_rad: float = math.radians(100)) -> float | None:
    """The candidate of least ``μ1·|Δgoal| + μ2·|Δheading| + μ3·|Δprevious|`` (VFH+'s cost),
    among those within ``no_turning_back_rad`` of the heading when there are any: the robot
    does not turn round while a way on is open (it would come back and dither)."""
    if not candidates:
        return None
    c = np.asarray(candidates, dtype=float)
    onward = np.abs(wrap_angle(c - heading_rad)) <= no_turning_back_rad
    if onward.any():
        c = c[onward]
    previous = heading_rad if previous_rad is None else previous_rad
    cost = (weights[0] * np.abs(wrap_angle(c - goal_rad)) + weights[1] * np.abs(wrap_angle(c - heading_rad))
            + weights[2] * np.abs(wrap_angle(c - previous)))
    return float(c[int(np.argmin(cost))])


class Vfh:
    """The ``vfh`` navigator (module docstring). ``grid`` may be shared with an owner that
    builds it (``explore``); then the owner calls :meth:`observe` and :meth:`steer`."""

    name = "vfh"

    def __init__(self, *, seed: int = 0, goal_xy=None, grid: OccupancyGrid | None = None, sectors: int = 72,
                 d_max_m: float = 1.6, margin_m: float = 0.1, smoothing: int = 2, low: float = 1.0, high: float = 2.5,
                 s_max: int = 16, wander_period_s: float = 20.0, look_m=(0.45, 0.7, 0.95), look_side_m=0.2,
                 relook_s: float = 5.0, near_m: float = ROBOT_RADIUS_M + 0.1):
        self.rng = np.random.default_rng(seed)
        self.goal_xy = goal_xy
        self.grid = grid if grid is not None else OccupancyGrid()
        self.sectors, self.d_max_m, self.enlarge_m = sectors, d_max_m, ROBOT_RADIUS_M + margin_m
        self.smoothing, self.low, self.high, self.s_max = smoothing, low, high, s_max
        self.wander_period_s = wander_period_s
        self._angles = angles = sector_angles_rad(sectors)
        look = np.asarray(look_m, dtype=float)
        # per sector, the offsets of the cells that must have been seen for it to count as known:
        # along its centre line and ``look_side_m`` to either side (the disc's corridor)
        along, side = np.meshgrid(look, [-look_side_m, 0.0, look_side_m])
        along, side = along.ravel(), side.ravel()
        c, s = np.cos(angles)[:, None], np.sin(angles)[:, None]
        self._probes = np.stack([along * c - side * s, along * s + side * c], axis=2).reshape(-1, 2)
        self.backoff = BackOff()
        self._last_scan = None
        self._blocked = None
        self._previous: float | None = None
        self._wander_heading: float | None = None
        self._wander_until_s = 0.0
        self._look_sign = 1.0
        self._cleared_xy = None
        self.relook_s, self.near_m = relook_s, near_m
        self._looked_s = np.full(sectors, -math.inf)  # when each sector was last in a scan's view
        self._window = (np.zeros((0, 2)), np.zeros(0))

    # ------------------------------------------------------------------ memory

    def observe(self, situation: Situation) -> bool:
        """Put a new scan, the floor under the robot (free) and a bump into the grid; True when
        there was a new scan."""
        x, y = situation.pose[:2]
        if self._cleared_xy is None or abs(x - self._cleared_xy[0]) + abs(y - self._cleared_xy[1]) > 0.05:
            self.grid.clear_footprint((x, y), ROBOT_RADIUS_M)
            self._cleared_xy = (x, y)
        fresh = situation.scan is not None and situation.scan is not self._last_scan and situation.scan_pose is not None
        if fresh:
            self.grid.add_scan(situation.scan, situation.scan_pose)
            bearings = wrap_angle(self._angles - situation.scan_pose[2])
            scan = situation.scan
            self._looked_s[(bearings >= scan.angles_rad[0]) & (bearings <= scan.angles_rad[-1])] = situation.now_s
            self._last_scan = situation.scan
        if situation.bumped:
            x, y, theta = situation.pose
            side = {"left": 0.6, "right": -0.6}.get(situation.bump_side or "front", 0.0)
            reach = ROBOT_RADIUS_M + 0.05
            self.grid.mark_occupied([[x + reach * math.cos(theta + side), y + reach * math.sin(theta + side)]],
                                    self.grid.limit)
        return fresh

    def histogram(self, pose) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(smoothed density, blocked, known) per sector at ``pose``."""
        cells, log_odds = self._window = self.grid.window(pose[:2], self.d_max_m)
        certainty = np.clip(log_odds / self.grid.hit, 0.0, self.grid.limit / self.grid.hit)
        raw = polar_histogram(cells, certainty, pose[:2], self.sectors, self.d_max_m, self.enlarge_m)
        smoothed = smooth_histogram(raw, self.smoothing)
        self._blocked = blocked_sectors(smoothed, self.low, self.high, self._blocked)
        seen = (self.grid.values_at(self._probes + np.asarray(pose[:2])) != 0).reshape(self.sectors, -1).all(axis=1)
        return smoothed, self._blocked.copy(), seen | self._blocked

    def _gap_ahead_m(self, pose) -> float:
        """Free distance in the corridor the disc sweeps straight ahead, or 0 when an occupied
        cell is within ``near_m`` of the centre in the front ±60° (the robot arcs as it turns:
        beside an obstacle it turns in place first). Occupied cells of the active window
        :meth:`histogram` last read."""
        cells, log_odds = self._window
        cells = cells[log_odds > 0.5]
        if len(cells) == 0:
            return math.inf
        c, s = math.cos(pose[2]), math.sin(pose[2])
        dx, dy = cells[:, 0] - pose[0], cells[:, 1] - pose[1]
        ahead, side = c * dx + s * dy, -s * dx + c * dy
        if np.any((ahead > 0.5 * np.abs(side)) & (np.hypot(ahead, side) < self.near_m)):
            return 0.0
        inside = (ahead > 0) & (np.abs(side) < ROBOT_RADIUS_M + 0.03)
        return float(ahead[inside].min() - ROBOT_RADIUS_M) if inside.any() else math.inf

    # ------------------------------------------------------------------ steering

    def steer(self, situation: Situation, goal_rad: float) -> Command:
        """One VFH decision toward the world-frame heading ``goal_rad``."""
        pose = situation.pose
        smoothed, blocked, known = self.histogram(pose)
        angles = self._angles
        goal_sector = int(np.argmin(np.abs(wrap_angle(angles - goal_rad))))
        unlooked = situation.now_s - self._looked_s > self.relook_s  # not in the camera's view lately
        if not known[goal_sector] and unlooked[goal_sector]:
            return limited_command(0.0, turn_towards(heading_error_rad(pose, goal_rad), 3.0), "look")
        direction = choose_direction(candidate_directions(valleys(~blocked & known), self.sectors, goal_rad, self.s_max),
                                     goal_rad, pose[2], self._previous)
        if direction is None:
            if self._previous is not None:  # a new search: toward the nearest sector not looked at lately
                todo = np.nonzero(~known & unlooked)[0]
                if len(todo):
                    nearest = todo[np.argmin(np.abs(wrap_angle(angles[todo] - pose[2])))]
                    self._look_sign = math.copysign(1.0, heading_error_rad(pose, angles[nearest]) or 1.0)
            self._previous = None  # keep turning the same way until a valley opens
            return limited_command(0.0, self._look_sign, "look" if (~known).any() else "blocked")
        self._previous = direction
        if self.goal_xy is None and abs(wrap_angle(direction - goal_rad)) > 0.5 * math.pi:
            self._wander_heading = direction  # the wander goal is out of reach: wander where the way is open
        error = heading_error_rad(pose, direction)
        heading_sector = int(np.argmin(np.abs(wrap_angle(angles - pose[2]))))
        density = min(smoothed[heading_sector], 3 * self.high) / (3 * self.high)
        speed = CRUISE_SPEED_M_S * (1.0 - density) * max(0.0, 1.0 - abs(error) / math.radians(35))
        if self._gap_ahead_m(pose) < 0.08 + speed**2 / (2 * 0.5) + speed * 0.2:
            speed = 0.0
        return limited_command(speed, turn_towards(error), "drive" if speed > 0 else "turn")

    def goal_heading_rad(self, situation: Situation) -> float:
        """The world-frame heading toward the goal point, or the wander heading (module docstring)."""
        x, y, theta = situation.pose
        if self.goal_xy is not None:
            return math.atan2(self.goal_xy[1] - y, self.goal_xy[0] - x)
        if self._wander_heading is None or situation.now_s >= self._wander_until_s:
            base = theta if self._wander_heading is None else self._wander_heading
            turn = 0.0 if self._wander_heading is None else self.rng.uniform(-0.5 * math.pi, 0.5 * math.pi)
            self._wander_heading = float(wrap_angle(base + turn))
            self._wander_until_s = situation.now_s + self.wander_period_s
        return self._wander_heading

    def step(self, situation: Situation) -> Command:
        self.observe(situation)
        if situation.bumped:
            self.backoff.start(situation, prefer_left=bool(self.rng.integers(2)))
        if self.backoff.active:
            return self.backoff.step(situation)
        return self.steer(situation, self.goal_heading_rad(situation))
