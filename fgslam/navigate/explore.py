"""``explore``: frontier exploration that also comes back to the landmarks, steered by ``vfh``.

A smoother is worth having when the robot sees the same landmarks again after a while (loop
closures). So this navigator does two things on the occupancy grid its scans build
(:mod:`fgslam.navigate.grid`, log-odds; unknown stays unknown):

* **frontiers** — free cells next to unknown ones (:func:`frontier_mask`), grouped into
  clusters; each cluster offers one goal, its cell nearest the cluster's middle among those
  with room for the robot (:func:`frontier_goals`);
* **landmark revisits** — a mapped landmark seen on fewer than ``visits_wanted`` separate
  visits and not seen for ``revisit_gap_s`` becomes a goal: a viewpoint 1–1.5 m from it,
  on known free floor with room for the robot, with no occupied cell between, and within
  40° of the mean direction it was seen from (a tag is read from its front only; the
  Situation carries no tag yaws, so where it was seen from is the estimate of its facing)
  (:func:`landmark_viewpoint`); there the robot turns to face it. A visit is counted, as
  the harness counts it, when the landmark's sighting count rises again after
  ``revisit_gap_s`` without a rise.

The floor counts as explored (freed in the grid) only within ``explored_range_m`` (3 m) of
where a scan was taken: the tag detector reads a 16 cm tag to ~3.5 m, so a room seen only
from afar still has frontiers that bring the robot near its walls.

Goals are chosen by cost: distance plus ``turn_cost_m_per_rad`` for the turn toward them
(:func:`goal_cost_m`), landmark goals weighted by ``landmark_weight``; when none is left it
goes back to the landmark it saw longest ago, or wanders. It starts with a look-around turn (a circle less the camera's view).
It steers to the goal with :class:`~fgslam.navigate.vfh.Vfh` (local avoidance, turn-to-look).
A frontier goal is reached when the robot is within ``reach_m`` or the cell is no longer a
frontier (seen from afar). Stuck (no ``progress_m`` closer to the goal for ``stuck_s``) or
bumped twice on the way, or 7 s on one spot whatever the goals: the goal is abandoned and
its neighbourhood black-listed for ``blacklist_s`` (60 s: the map grows, a way that failed
may open). On a bump
the robot backs off ~0.15 m and turns away from the bump side.

Work per step stays small: at most one heavy job a step (a scan, the clearance map, the
frontiers, a goal choice; the steering then reuses the previous step's histogram), and the
clearance map and the frontiers are recomputed once every ``replan_s``, on two steps, on the
block of known cells only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from fgslam.navigate.common import ROBOT_RADIUS_M, Command, Situation, heading_error_rad, limited_command, turn_towards
from fgslam.navigate.grid import OccupancyGrid
from fgslam.navigate.vfh import Vfh
from slamio.camera.kinect import KINECT_HFOV_RAD
from slamio.geometry import wrap_angle

__all__ = ["Explore", "frontier_mask", "frontier_goals", "landmark_viewpoint", "goal_cost_m", "Goal"]

FREE_BELOW = -0.3
OCCUPIED_ABOVE = 0.5


def frontier_mask(log_odds: np.ndarray) -> np.ndarray:
    """Free cells with an unknown (log-odds 0) 4-neighbour."""
    unknown = log_odds == 0
    near_unknown = np.zeros_like(unknown)
    near_unknown[1:, :] |= unknown[:-1, :]
    near_unknown[:-1, :] |= unknown[1:, :]
    near_unknown[:, 1:] |= unknown[:, :-1]
    near_unknown[:, :-1] |= unknown[:, 1:]
    return (log_odds < FREE_BELOW) & near_unknown


def clearance_map_m(log_odds: np.ndarray, resolution_m: float) -> np.ndarray:
    """Distance from each cell to the nearest occupied cell (the block's edge counts as far)."""
    return ndimage.distance_transform_edt(~(log_odds > OCCUPIED_ABOVE)) * resolution_m


def frontier_goals(log_odds: np.ndarray, clearance_m: np.ndarray, min_cells: int = 3,
                   room_m: float = ROBOT_RADIUS_M + 0.08) -> list[tuple[int, int, int]]:
    """(row, column, size) per frontier cluster (8-connected, at least ``min_cells``): the
    cluster's cell with ``room_m`` clearance nearest its centroid (clusters without one are
    left out)."""
    labels, count = ndimage.label(frontier_mask(log_odds), structure=np.ones((3, 3)))
    if count == 0:
        return []
    rows, cols = np.nonzero(labels)
    which = labels[rows, cols]
    goals = []
    for k in range(1, count + 1):
        member = which == k
        if member.sum() < min_cells:
            continue
        r, c = rows[member], cols[member]
        roomy = clearance_m[r, c] >= room_m
        if not roomy.any():
            continue
        r, c = r[roomy], c[roomy]
        centre = np.array([rows[member].mean(), cols[member].mean()])
        best = int(np.argmin((r - centre[0]) ** 2 + (c - centre[1]) ** 2))
        goals.append((int(r[best]), int(c[best]), int(member.sum())))
    return goals


def _grid_sight(grid: OccupancyGrid, from_xy, to_xy, stop_short_m: float = 0.15) -> bool:
    """No occupied cell on the segment (up to ``stop_short_m`` before ``to_xy``, the landmark
    sits on its wall)."""
    offset = np.subtract(to_xy, from_xy)
    length = float(np.hypot(*offset))
    steps = np.arange(0.0, max(length - stop_short_m, 0.0), 0.5 * grid.resolution_m)
    points = np.asarray(from_xy) + steps[:, None] * offset / max(length, 1e-9)
    return not np.any(grid.values_at(points) > OCCUPIED_ABOVE)


def landmark_viewpoint(grid: OccupancyGrid, clearance_m_at, landmark_xy, robot_xy, distances_m=(1.0, 1.25, 1.5),
                       directions: int = 16, room_m: float = ROBOT_RADIUS_M + 0.12, facing_rad: float | None = None,
                       facing_limit_rad: float = math.radians(40)) -> tuple[float, float] | None:
    """The viewpoint nearest the robot from which to look at a landmark (module docstring);
    ``clearance_m_at(xy)`` gives the clearance at points. With ``facing_rad`` (the direction
    the landmark was seen from), only viewpoints within ``facing_limit_rad`` of it: a tag is
    seen from its front only. ``None`` when there is none."""
    angles = np.arange(directions) * (2 * math.pi / directions)
    if facing_rad is not None:
        angles = angles[np.abs(wrap_angle(angles - facing_rad)) <= facing_limit_rad]
    candidates = np.array([[landmark_xy[0] + d * math.cos(a), landmark_xy[1] + d * math.sin(a)]
                           for d in distances_m for a in angles])
    ok = (grid.values_at(candidates, outside=0.0) < FREE_BELOW) & (clearance_m_at(candidates) >= room_m)
    candidates = candidates[ok]
    order = np.argsort(np.hypot(candidates[:, 0] - robot_xy[0], candidates[:, 1] - robot_xy[1]))
    for k in order:
        if _grid_sight(grid, candidates[k], landmark_xy):
            return float(candidates[k, 0]), float(candidates[k, 1])
    return None


def goal_cost_m(pose, goal_xy, turn_cost_m_per_rad: float = 0.5) -> float:
    """Straight-line distance plus the turn toward the goal at ``turn_cost_m_per_rad``."""
    dx, dy = goal_xy[0] - pose[0], goal_xy[1] - pose[1]
    return math.hypot(dx, dy) + turn_cost_m_per_rad * abs(wrap_angle(math.atan2(dy, dx) - pose[2]))


@dataclass
class Goal:
    kind: str  # "frontier", "landmark" or "return"
    xy: tuple[float, float]
    landmark: int | None = None
    started_s: float = 0.0
    best_m: float = math.inf
    improved_s: float = 0.0
    bumps: int = 0
    facing: bool = False


class _Visits:
    """Separate visits per landmark, from the sighting counts (module docstring)."""

    def __init__(self, gap_s: float):
        self.gap_s = gap_s
        self.count: dict[int, int] = {}
        self.last_s: dict[int, float] = {}
        self.visits: dict[int, int] = {}
        self.seen_from: dict[int, list[float]] = {}  # sum of unit vectors from the landmark to the robot

    def update(self, sightings, now_s: float, landmarks=None, robot_xy=None) -> None:
        for key, count in sightings.items():
            if count > self.count.get(key, 0):
                if landmarks is not None and robot_xy is not None and key in landmarks:
                    dx, dy = robot_xy[0] - landmarks[key][0], robot_xy[1] - landmarks[key][1]
                    norm = max(math.hypot(dx, dy), 1e-9)
                    total = self.seen_from.setdefault(key, [0.0, 0.0])
                    total[0] += dx / norm
                    total[1] += dy / norm
                if key not in self.last_s or now_s - self.last_s[key] >= self.gap_s:
                    self.visits[key] = self.visits.get(key, 0) + 1
                self.last_s[key] = now_s
                self.count[key] = count


class Explore:
    """The ``explore`` navigator (module docstring)."""

    name = "explore"

    def __init__(self, *, seed: int = 0, grid: OccupancyGrid | None = None, replan_s: float = 1.0,
                 reach_m: float = 0.35, stuck_s: float = 6.0, progress_m: float = 0.15, revisit_gap_s: float = 20.0,
                 visits_wanted: int = 2, landmark_weight: float = 0.5, turn_cost_m_per_rad: float = 0.5,
                 blacklist_s: float = 60.0, explored_range_m: float = 3.0):
        self.rng = np.random.default_rng(seed)
        self.grid = grid if grid is not None else OccupancyGrid()
        # the floor counts as explored only where the tag detector could have read a tag
        self.vfh = Vfh(seed=int(self.rng.integers(2**31)), grid=self.grid, free_range_m=explored_range_m,
                       careful=False)
        self.replan_s, self.reach_m, self.stuck_s, self.progress_m = replan_s, reach_m, stuck_s, progress_m
        self.visits_wanted, self.landmark_weight, self.turn_cost = visits_wanted, landmark_weight, turn_cost_m_per_rad
        self.visits = _Visits(revisit_gap_s)
        self.goal: Goal | None = None
        self.blacklist: list[tuple[float, float, float]] = []  # (x, y, until when)
        self.blacklist_s = blacklist_s
        self._frontiers: list[tuple[float, float]] = []
        self._clearance = None  # (block, row slice, column slice)
        self._replanned_s = -math.inf
        self._pending = None  # a clearance map waiting for its frontiers (:meth:`_refresh`)
        self._look_until: float | None = None
        self._look_turned = 0.0
        self._last_heading: float | None = None

    # ------------------------------------------------------------------ the map's offers

    def _refresh(self, now_s: float) -> bool:
        """Recompute the clearance map, then (on the next call) the frontiers, on the known
        block: two steps, so that neither costs much. True when both are new."""
        if self._pending is None:
            rows, cols = self.grid.bounds()
            block = self.grid.log_odds[rows, cols].copy()
            if block.size == 0:
                self._frontiers, self._clearance, self._replanned_s = [], None, now_s
                return True
            self._pending = (block, clearance_map_m(block, self.grid.resolution_m), rows, cols)
            return False
        block, clearance, rows, cols = self._pending
        self._pending = None
        self._clearance = (clearance, rows, cols)
        found = frontier_goals(block, clearance)
        self._frontiers = [tuple(self.grid.centres([r + rows.start], [c + cols.start])[0]) for r, c, _ in found]
        self._replanned_s = now_s
        return True

    def clearance_at(self, xy) -> np.ndarray:
        """Clearance (m) at map-frame points from the last refresh (0 off the known block)."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        if self._clearance is None:
            return np.zeros(len(xy))
        clearance, rows, cols = self._clearance
        row, col, inside = self.grid.index(xy)
        row, col = row - rows.start, col - cols.start
        inside &= (row >= 0) & (row < clearance.shape[0]) & (col >= 0) & (col < clearance.shape[1])
        out = np.zeros(len(xy))
        out[inside] = clearance[row[inside], col[inside]]
        return out

    def _listed(self, xy, now_s: float) -> bool:
        return any(b[2] > now_s and math.hypot(xy[0] - b[0], xy[1] - b[1]) < 0.5 for b in self.blacklist)

    def _ban(self, xy, now_s: float) -> None:
        """Black-list a goal's neighbourhood for ``blacklist_s``: the map grows, and a way
        that failed may open once more of it is seen."""
        self.blacklist = [b for b in self.blacklist if b[2] > now_s] + [(xy[0], xy[1], now_s + self.blacklist_s)]

    def _landmark_goals(self, situation: Situation, stale_only: bool = True) -> list[Goal]:
        goals = []
        for key, xy in situation.landmarks.items():
            last = self.visits.last_s.get(key, -math.inf)
            if situation.now_s - last < self.visits.gap_s:
                continue
            if stale_only and self.visits.visits.get(key, 0) >= self.visits_wanted:
                continue
            # a tag faces where it was seen from (the mean direction of the sightings)
            facing = self.visits.seen_from.get(key)
            facing = math.atan2(facing[1], facing[0]) if facing is not None and any(facing) else None
            view = landmark_viewpoint(self.grid, self.clearance_at, xy, situation.pose[:2], facing_rad=facing)
            if view is not None and not self._listed(view, situation.now_s):
                goals.append(Goal("landmark" if stale_only else "return", view, key))
        return goals

    def _choose(self, situation: Situation) -> Goal | None:
        pose = situation.pose
        offers = [(goal_cost_m(pose, xy, self.turn_cost), Goal("frontier", xy))
                  for xy in self._frontiers if not self._listed(xy, situation.now_s)]
        offers += [(self.landmark_weight * goal_cost_m(pose, g.xy, self.turn_cost), g)
                   for g in self._landmark_goals(situation)]
        if not offers:  # explored and every landmark visited: go back to the one seen longest ago
            returns = self._landmark_goals(situation, stale_only=False)
            offers = [(self.visits.last_s.get(g.landmark, 0.0), g) for g in returns]
        if not offers:
            return None
        goal = min(offers, key=lambda pair: pair[0])[1]
        goal.started_s = goal.improved_s = situation.now_s
        return goal

    # ------------------------------------------------------------------ stepping

    def _abandon(self, situation: Situation, distance_m: float | None = None) -> None:
        """Black-list the goal's neighbourhood, drop it, back off (``distance_m``)."""
        if self.goal is not None:
            self._ban(self.goal.xy, situation.now_s)
        self.goal = None
        self.vfh.backoff.start(situation, prefer_left=bool(self.rng.integers(2)), distance_m=distance_m)

    def _look_around(self, situation: Situation) -> Command | None:
        """The first turn on the spot, so the map starts all round: a full circle less the
        camera's view (what it saw at the start)."""
        if self._look_turned >= 2 * math.pi - 0.9 * KINECT_HFOV_RAD:
            return None
        if self._last_heading is not None:
            self._look_turned += abs(wrap_angle(situation.pose[2] - self._last_heading))
        self._last_heading = situation.pose[2]
        return limited_command(0.0, 1.0, "look-around")

    def _at_landmark(self, situation: Situation) -> Command:
        """At a viewpoint: face the landmark until it is seen (or give up after 3 s)."""
        goal = self.goal
        target = situation.landmarks.get(goal.landmark, goal.xy)
        error = heading_error_rad(situation.pose, math.atan2(target[1] - situation.pose[1], target[0] - situation.pose[0]))
        if not goal.facing:
            goal.facing, goal.started_s = True, situation.now_s
        seen = situation.now_s - self.visits.last_s.get(goal.landmark, -math.inf) < 0.5
        if (seen and abs(error) < 0.3) or situation.now_s - goal.started_s > 3.0 + abs(error):
            if not seen:
                self._ban(goal.xy, situation.now_s)
            self.goal = None
        return limited_command(0.0, turn_towards(error, 3.0), "face-landmark")

    def _progress(self, situation: Situation) -> bool:
        """Track the distance to the goal; False when stuck (no progress for ``stuck_s``)."""
        goal = self.goal
        distance = math.hypot(goal.xy[0] - situation.pose[0], goal.xy[1] - situation.pose[1])
        if distance < goal.best_m - self.progress_m:
            goal.best_m, goal.improved_s = distance, situation.now_s
        return situation.now_s - goal.improved_s <= self.stuck_s

    def step(self, situation: Situation) -> Command:
        fresh_scan = self.vfh.observe(situation)
        self.visits.update(situation.sightings, situation.now_s, situation.landmarks, situation.pose[:2])
        if situation.bumped and not self.vfh.backoff.active:
            if self.goal is not None:
                self.goal.bumps += 1
            if self.goal is not None and self.goal.bumps >= 2:
                self._abandon(situation)
            else:
                self.vfh.backoff.start(situation, prefer_left=bool(self.rng.integers(2)))
        if self.vfh.spot.update(situation) and not self.vfh.backoff.active:
            self._abandon(situation, self.vfh.escape_reverse_m(situation.pose))  # goal after goal and still on one spot: leave it
        if self.vfh.backoff.active:
            return self.vfh.backoff.step(situation)
        looking = self._look_around(situation)
        if looking is not None:
            return looking
        # at most one heavy job a step besides steering (a scan, the map's offers, a choice),
        # so that no step costs much more than the others
        busy = fresh_scan
        if situation.now_s - self._replanned_s >= self.replan_s and not busy:
            busy = True
            if self._refresh(situation.now_s) and (self.goal is not None and self.goal.kind == "frontier"
                    and not any(math.hypot(f[0] - self.goal.xy[0], f[1] - self.goal.xy[1]) < 0.3 for f in self._frontiers)):
                self.goal = None  # seen from afar: that frontier is gone
        if self.goal is None:
            if busy:
                return limited_command(0.0, 0.0, "plan")  # choose next step
            self.goal, busy = self._choose(situation), True
        if self.goal is None:
            command = self.vfh.steer(situation, self.vfh.goal_heading_rad(situation), reuse=busy)
            return limited_command(command.speed_m_s, command.turn_rate_rad_s, "wander")
        if not self._progress(situation):
            self._abandon(situation, self.vfh.escape_reverse_m(situation.pose))
            return self.vfh.backoff.step(situation)
        distance = math.hypot(self.goal.xy[0] - situation.pose[0], self.goal.xy[1] - situation.pose[1])
        if self.goal.kind != "frontier" and (self.goal.facing or distance < self.reach_m):
            return self._at_landmark(situation)
        if self.goal.kind == "frontier" and distance < self.reach_m:
            self._ban(self.goal.xy, situation.now_s)  # if it is still a frontier, it cannot be seen from here
            self.goal = None
            return limited_command(0.0, 0.0, "reached")
        command = self.vfh.steer(situation, math.atan2(self.goal.xy[1] - situation.pose[1],
                                                       self.goal.xy[0] - situation.pose[0]), reuse=busy)
        state = f"to-{self.goal.kind}" if command.state == "drive" else command.state
        return limited_command(command.speed_m_s, command.turn_rate_rad_s, state)
