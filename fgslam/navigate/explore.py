"""``explore``: look at every surface closely, and come back to the landmarks; steered by ``vfh``.

A smoother is worth having when the robot sees the same landmarks again after a while (loop
closures), and a tag is read only from its front within a few metres. So this navigator
keeps, on the occupancy grid its scans build (:mod:`fgslam.navigate.grid`, log-odds; unknown
stays unknown), four kinds of goal:

* **frontiers** — free cells next to unknown ones (:func:`frontier_mask`), grouped into
  clusters; each cluster offers one goal, its cell nearest the cluster's middle among those
  with room for the robot (:func:`frontier_goals`). The floor counts as explored only within
  ``explored_range_m`` (3 m) of where a scan was taken;
* **surfaces to inspect** — occupied cells no scan has hit from within ``read_range_m``
  (2.5 m) at an incidence within ``read_incidence_rad`` (55°): a wall or box face seen only
  from afar or edge-on, where a tag would not have been read
  (:mod:`fgslam.navigate.inspect`). Per ``tile_m`` (1 m) tile of them one target, looked at
  from a viewpoint 0.9–1.7 m in front of it (the side the free floor is on), where the
  robot turns to face it; the tile then counts as looked at;
* **landmark revisits** — a mapped landmark seen on fewer than ``visits_wanted`` separate
  visits and not seen for ``revisit_gap_s`` becomes a goal: a viewpoint ``view_m``
  (1–2.5 m) from it, on known free floor with room for the robot, with no occupied cell
  between, and within 40° of the mean direction it was seen from (the Situation carries no
  tag yaws: where it was seen from is the estimate of its facing)
  (:func:`~fgslam.navigate.inspect.landmark_viewpoint`); there the robot turns to face it.
  A visit is counted, as the harness counts it, when the landmark's sighting count rises
  again after ``revisit_gap_s`` without a rise;
* **glances** — such a landmark in sight from where the robot is (within
  ``glance_range_m``, 2.8 m, and 45° of its facing, nothing occupied between): the robot
  turns to it there and then, on the way to another goal too (not when it has stood
  ``glance_still_s`` on one spot already: turning there would keep it on that spot).

Goals are chosen by cost: the length of the way over the known floor (Dijkstra on 0.2 m
cells with room for the robot's enlarged disc, :mod:`fgslam.navigate.paths`; a goal the
known floor does not lead to waits) plus ``turn_cost_m_per_rad`` for the turn toward it,
landmark goals weighted by ``landmark_weight``; when none is left it goes back to the
landmark it saw longest ago, or wanders. It starts with a look-around turn (a circle less
the camera's view). It steers with :class:`~fgslam.navigate.vfh.Vfh` (local avoidance,
turn-to-look) toward the point ``lookahead_m`` along the way. A frontier goal is reached
when the robot is within ``reach_m`` or the cell is no longer a frontier (seen from afar).
Stuck (no ``progress_m`` shorter way left for ``stuck_s``), or ``spot_s`` (5 s) within
0.2 m of one spot whatever the goals: the goal is abandoned, its neighbourhood black-listed
for ``blacklist_s`` (60 s: the map grows, a way that failed may open), and the robot leaves
the spot *forward* (:class:`~fgslam.navigate.escape.ForwardEscape`: it turns on the spot
toward the nearest sector the grid shows free and seen, looks, and drives out 0.35 m under
``vfh``'s stop rules), reversing only over floor known free when no sector is (then often
not at all: it turns away). ``vfh`` runs with its careful rules (the arc stop test, the
reverse over known floor only). On a bump the robot backs off up to 0.15 m over floor known
free and turns away from the bump side; bumped twice on the way, the goal is dropped.

Work per step stays small: at most one heavy job a step besides steering (a scan; the
surfaces that scan inspected; the clearance map; the frontiers; the inspection targets; the
ways from the robot; a glance check; a goal choice, which looks for at most two viewpoints),
the map's offers recomputed once every ``replan_s``, on the block of known cells only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from fgslam.navigate.common import ROBOT_RADIUS_M, Command, Situation, heading_error_rad, limited_command, turn_towards
from fgslam.navigate.escape import ForwardEscape
from fgslam.navigate.grid import OccupancyGrid
from fgslam.navigate.inspect import (grid_sight, inspected_hits, inspection_targets, landmark_viewpoint,
                                     nearest_to_group_middle)
from fgslam.navigate.paths import coarse_passable, geodesic_from, way_ahead_xy, way_left_m, way_to
from fgslam.navigate.vfh import Vfh
from slamio.camera.kinect import KINECT_HFOV_RAD
from slamio.geometry import wrap_angle

__all__ = ["Explore", "frontier_mask", "frontier_goals", "landmark_viewpoint", "goal_cost_m", "Goal"]

FREE_BELOW = -0.3
WAY_FACTOR = 2  # the ways' coarse cells: 2 × 2 grid cells (0.2 m)
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
    size = np.bincount(which, minlength=count + 1)
    roomy = (clearance_m[rows, cols] >= room_m) & (size[which] >= min_cells)
    if not roomy.any():
        return []
    # the roomy cell nearest the middle of its whole cluster
    pick = nearest_to_group_middle(rows[roomy], cols[roomy], which[roomy], rows, cols, which)
    r, c, k = rows[roomy][pick], cols[roomy][pick], which[roomy][pick]
    return [(int(a), int(b), int(size[g])) for a, b, g in zip(r, c, k)]


def goal_cost_m(pose, goal_xy, turn_cost_m_per_rad: float = 0.5) -> float:
    """Straight-line distance plus the turn toward the goal at ``turn_cost_m_per_rad``."""
    dx, dy = goal_xy[0] - pose[0], goal_xy[1] - pose[1]
    return math.hypot(dx, dy) + turn_cost_m_per_rad * abs(wrap_angle(math.atan2(dy, dx) - pose[2]))


@dataclass
class Goal:
    kind: str  # "frontier", "inspect", "landmark" or "return"
    xy: tuple[float, float]
    landmark: int | None = None
    target: tuple[float, float] | None = None  # what to face at the viewpoint (an inspection's surface)
    started_s: float = 0.0
    best_m: float = math.inf
    improved_s: float = 0.0
    bumps: int = 0
    facing: bool = False
    facing_rad: float | None = None  # the direction the target faces (where to look at it from)
    resolved: bool = True  # False while ``xy`` is only a first guess of the viewpoint


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
                 blacklist_s: float = 60.0, explored_range_m: float = 3.0, read_range_m: float = 2.5,
                 read_incidence_rad: float = math.radians(55), inspect_weight: float = 1.0,
                 glance_range_m: float = 2.8, glance_facing_rad: float = math.radians(45), lookahead_m: float = 0.8,
                 view_m=(1.0, 1.5, 2.0, 2.5), tile_m: float = 1.0, glance_still_s: float = 2.0, spot_s: float = 5.0):
        self.rng = np.random.default_rng(seed)
        self.grid = grid if grid is not None else OccupancyGrid()
        # the floor counts as explored only where the tag detector could have read a tag
        self.vfh = Vfh(seed=int(self.rng.integers(2**31)), grid=self.grid, free_range_m=explored_range_m,
                       stuck_s=spot_s)
        self.vfh.escape = ForwardEscape(self.vfh)  # leaves a spot forward, not reversing
        self.replan_s, self.reach_m, self.stuck_s, self.progress_m = replan_s, reach_m, stuck_s, progress_m
        self.visits_wanted, self.landmark_weight, self.turn_cost = visits_wanted, landmark_weight, turn_cost_m_per_rad
        self.visits = _Visits(revisit_gap_s)
        self.goal: Goal | None = None
        self.blacklist: list[tuple[float, float, float]] = []  # (x, y, until when)
        self.blacklist_s = blacklist_s
        self.read_range_m, self.read_incidence_rad, self.inspect_weight = read_range_m, read_incidence_rad, inspect_weight
        self.inspected = np.zeros(self.grid.log_odds.shape, bool)  # :mod:`fgslam.navigate.inspect`
        self.glance_range_m, self.glance_facing_rad = glance_range_m, glance_facing_rad
        self.lookahead_m, self.view_m, self.tile_m = lookahead_m, tuple(view_m), tile_m
        self.glance_still_s = glance_still_s
        self._glance_failed: dict[int, float] = {}  # landmark: no glance at it before then
        self._glance_check = False  # look for a glance on the next free step (after a refresh)
        self._targets: list[tuple[float, float, float]] = []  # inspection targets: x, y, facing
        self._frontiers: list[tuple[float, float]] = []
        self._clearance = None  # (block, row slice, column slice)
        self._replanned_s = -math.inf
        self._pending = None  # a clearance map waiting for its frontiers (:meth:`_refresh`)
        self._ways = None  # (distance, predecessors, row and column of the block's corner): paths.geodesic_from
        self._way: np.ndarray | None = None  # the way to the goal (xy, n × 2)
        self._unread_scan = None  # a scan whose inspected cells are marked on the next step
        self._look_until: float | None = None
        self._look_turned = 0.0
        self._last_heading: float | None = None

    # ------------------------------------------------------------------ the map's offers

    def _refresh(self, situation: Situation) -> bool:
        """One stage of recomputing the map's offers on the known block, so that no step costs
        much: the clearance map, then the frontiers, then the inspection targets, then the
        ways from the robot (:mod:`fgslam.navigate.paths`). True when all are new."""
        now_s = situation.now_s
        if self._pending is None:
            rows, cols = self.grid.bounds()
            block = self.grid.log_odds[rows, cols].copy()
            if block.size == 0:
                self._frontiers, self._targets, self._clearance, self._replanned_s = [], [], None, now_s
                return True
            self._pending = {"block": block, "rows": rows, "cols": cols,
                             "clearance": clearance_map_m(block, self.grid.resolution_m)}
            return False
        job = self._pending
        block, rows, cols = job["block"], job["rows"], job["cols"]
        if "frontiers" not in job:
            found = frontier_goals(block, job["clearance"])
            job["frontiers"] = [tuple(self.grid.centres([r + rows.start], [c + cols.start])[0]) for r, c, _ in found]
            return False
        if "targets" not in job:
            found = inspection_targets(block > OCCUPIED_ABOVE, self.inspected[rows, cols], block < FREE_BELOW,
                                       tile_cells=int(round(self.tile_m / self.grid.resolution_m)), min_cells=3)
            job["targets"] = [(*self.grid.centres([r + rows.start], [c + cols.start])[0], f) for r, c, f in found]
            return False
        self._pending = None
        self._clearance, self._frontiers, self._targets = (job["clearance"], rows, cols), job["frontiers"], job["targets"]
        passable = coarse_passable(block < FREE_BELOW, job["clearance"], self.vfh.enlarge_m, WAY_FACTOR)
        start = self._coarse_cell(situation.pose[:2], rows, cols, passable.shape)
        self._ways = None
        if start is not None:
            distance, previous = geodesic_from(passable, start, WAY_FACTOR * self.grid.resolution_m)
            nearest = ndimage.minimum_filter(distance, size=3, mode="constant", cval=math.inf)
            self._ways = (distance, previous, rows.start, cols.start, nearest)
        self._replanned_s = now_s
        return True

    def _coarse_cell(self, xy, rows: slice, cols: slice, shape) -> tuple[int, int] | None:
        row, col, _ = self.grid.index([xy])
        r, c = (int(row[0]) - rows.start) // WAY_FACTOR, (int(col[0]) - cols.start) // WAY_FACTOR
        return (r, c) if 0 <= r < shape[0] and 0 <= c < shape[1] else None

    def way_lengths_m(self, xy) -> np.ndarray:
        """The length of the way over the floor from where the robot was at the last refresh
        to each of the points ``xy`` (n, 2) (the best of its coarse cell and their neighbours,
        plus a cell); ``nan`` before the first refresh; ``inf`` where the known floor leads
        not there."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        if self._ways is None:
            return np.full(len(xy), math.nan)
        distance, _, r0, c0, nearest = self._ways
        row, col, _ = self.grid.index(xy)
        r, c = (row - r0) // WAY_FACTOR, (col - c0) // WAY_FACTOR
        inside = (r >= 0) & (r < distance.shape[0]) & (c >= 0) & (c < distance.shape[1])
        out = np.full(len(xy), math.inf)
        out[inside] = nearest[r[inside], c[inside]] + WAY_FACTOR * self.grid.resolution_m
        return out

    def _plan_way(self, situation: Situation) -> None:
        """The way to the goal from the last refresh's search (none: head straight for it)."""
        goal, self._way = self.goal, None
        if goal is None or self._ways is None or goal.kind == "glance":
            return
        distance, previous, r0, c0, _ = self._ways
        row, col, _ = self.grid.index([goal.xy])
        r, c = (int(row[0]) - r0) // WAY_FACTOR, (int(col[0]) - c0) // WAY_FACTOR
        h, w = distance.shape
        best = None
        for rr in range(max(r - 1, 0), min(r + 2, h)):
            for cc in range(max(c - 1, 0), min(c + 2, w)):
                if np.isfinite(distance[rr, cc]) and (best is None or distance[rr, cc] < distance[best]):
                    best = (rr, cc)
        cells = way_to(previous, distance, best) if best is not None else []
        if len(cells) < 2:
            return
        cells = np.asarray(cells)
        xy = self.grid.centres(WAY_FACTOR * cells[:, 0] + r0 + 0.5 * (WAY_FACTOR - 1),
                               WAY_FACTOR * cells[:, 1] + c0 + 0.5 * (WAY_FACTOR - 1))
        self._way = np.vstack([xy[1:], [goal.xy]])
        goal.best_m = min(goal.best_m, way_left_m(self._way, situation.pose[:2])[0] + self.progress_m)

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
        return bool(self._listed_many([xy], now_s)[0])

    def _listed_many(self, xy, now_s: float) -> np.ndarray:
        """Per point (n, 2): within 0.5 m of a black-listed spot still banned."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        banned = np.array([b[:2] for b in self.blacklist if b[2] > now_s]).reshape(-1, 2)
        if len(banned) == 0 or len(xy) == 0:
            return np.zeros(len(xy), bool)
        gap = np.hypot(xy[:, None, 0] - banned[None, :, 0], xy[:, None, 1] - banned[None, :, 1])
        return (gap < 0.5).any(axis=1)

    def _ban(self, xy, now_s: float) -> None:
        """Black-list a goal's neighbourhood for ``blacklist_s``: the map grows, and a way
        that failed may open once more of it is seen."""
        self.blacklist = [b for b in self.blacklist if b[2] > now_s] + [(xy[0], xy[1], now_s + self.blacklist_s)]

    def _landmark_goals(self, situation: Situation, stale_only: bool = True) -> list[Goal]:
        """A goal per landmark due a visit, at a first guess of its viewpoint (out along the
        direction it was seen from, as far as the robot is, within ``view_m``; :meth:`_resolve`
        finds the real one)."""
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
            if facing is None:
                guess = xy
            else:  # the point out along its facing, within the viewpoints' distances, nearest the robot
                out = (situation.pose[0] - xy[0]) * math.cos(facing) + (situation.pose[1] - xy[1]) * math.sin(facing)
                out = min(max(out, self.view_m[0]), self.view_m[-1])
                guess = (xy[0] + out * math.cos(facing), xy[1] + out * math.sin(facing))
            goals.append(Goal("landmark" if stale_only else "return", guess, key, target=xy, facing_rad=facing,
                              resolved=False))
        return goals

    def _glance(self, situation: Situation) -> Goal | None:
        """A landmark due a visit that can be seen from where the robot stands — within
        ``glance_range_m``, within ``glance_facing_rad`` of the direction it was seen from,
        nothing occupied between — as a goal here: turn to it (the one needing the least turn)."""
        pose, now = situation.pose, situation.now_s
        anchor = self.vfh.spot.anchor
        if anchor is not None and now - anchor[2] > self.glance_still_s:
            return None  # on this spot a while already: a turn here would keep it there too long
        due = []
        for key, xy in situation.landmarks.items():
            if now - self.visits.last_s.get(key, -math.inf) < self.visits.gap_s or \
                    self.visits.visits.get(key, 0) >= self.visits_wanted or now < self._glance_failed.get(key, -math.inf):
                continue
            facing = self.visits.seen_from.get(key)
            dx, dy = pose[0] - xy[0], pose[1] - xy[1]
            if facing is None or not any(facing) or math.hypot(dx, dy) > self.glance_range_m or \
                    abs(wrap_angle(math.atan2(dy, dx) - math.atan2(facing[1], facing[0]))) > self.glance_facing_rad:
                continue
            due.append((abs(wrap_angle(math.atan2(-dy, -dx) - pose[2])), key, xy))
        for _, key, xy in sorted(due)[:3]:
            if grid_sight(self.grid, pose[:2], xy):
                goal = Goal("glance", (pose[0], pose[1]), key, target=xy)
                goal.started_s = goal.improved_s = now
                return goal
        return None

    def _inspect_goals(self, situation: Situation) -> list[Goal]:
        """A goal per surface tile not inspected yet, 1.25 m in front of it (a first guess)."""
        goals = []
        for x, y, facing in self._targets:
            if self._inspected_near((x, y)):
                continue  # looked at since the last refresh
            guess = (x + 1.25 * math.cos(facing), y + 1.25 * math.sin(facing))
            goals.append(Goal("inspect", guess, target=(x, y), facing_rad=facing, resolved=False))
        return goals

    def _resolve(self, goal: Goal, situation: Situation) -> bool:
        """Replace a goal's first guess by a viewpoint on free floor in sight of its target
        (:func:`landmark_viewpoint`); False (and the guess black-listed) when there is none."""
        if goal.resolved:
            return True
        distances = self.view_m if goal.kind != "inspect" else (0.9, 1.3, 1.7)
        view = landmark_viewpoint(self.grid, self.clearance_at, goal.target, situation.pose[:2], distances,
                                  facing_rad=goal.facing_rad)
        if view is None or self._listed(view, situation.now_s):
            self._ban(goal.xy, situation.now_s)
            return False
        goal.xy, goal.resolved = view, True
        return True

    def _costs_m(self, pose, goals: list[Goal]) -> np.ndarray:
        """:func:`goal_cost_m` per goal, with the way's length over the floor for the straight
        distance (:meth:`way_lengths_m`), weighted by the goal's kind."""
        if not goals:
            return np.zeros(0)
        xy = np.array([g.xy for g in goals])
        straight = np.hypot(xy[:, 0] - pose[0], xy[:, 1] - pose[1])
        way = self.way_lengths_m(xy)
        way = np.where(np.isnan(way), straight, way)
        turn = np.abs(wrap_angle(np.arctan2(xy[:, 1] - pose[1], xy[:, 0] - pose[0]) - pose[2]))
        weight = np.array([{"inspect": self.inspect_weight, "landmark": self.landmark_weight}.get(g.kind, 1.0)
                           for g in goals])
        return weight * (way + self.turn_cost * turn)

    def _choose(self, situation: Situation, tries: int = 2) -> Goal | None:
        """The cheapest offer (module docstring) whose viewpoint exists; at most ``tries``
        viewpoints are looked for per call (each costs a few hundred µs)."""
        pose = situation.pose
        glance = self._glance(situation)
        if glance is not None:
            return glance
        goals = [Goal("frontier", xy) for xy in self._frontiers]
        goals += self._inspect_goals(situation) + self._landmark_goals(situation)
        listed = self._listed_many([g.xy for g in goals] + [g.target or g.xy for g in goals], situation.now_s)
        goals = [g for g, a, b in zip(goals, listed[:len(goals)], listed[len(goals):])
                 if not a and not (b and g.kind == "inspect")]  # an inspection's surface banned too
        # a goal the known floor leads not to (yet) is left for later
        offers = [(cost, g) for cost, g in zip(self._costs_m(pose, goals), goals) if cost < math.inf]
        if not offers:  # explored and every landmark visited: go back to the one seen longest ago
            returns = [g for g in self._landmark_goals(situation, stale_only=False)
                       if not self._listed(g.xy, situation.now_s)]
            offers = [(self.visits.last_s.get(g.landmark, 0.0), g) for g in returns]
        offers.sort(key=lambda pair: pair[0])
        for _, goal in offers:
            if not goal.resolved:
                if tries == 0:
                    return None
                tries -= 1
                if not self._resolve(goal, situation):
                    continue
            goal.started_s = goal.improved_s = situation.now_s
            return goal
        return None

    # ------------------------------------------------------------------ stepping

    def _abandon(self, situation: Situation) -> None:
        """Black-list the goal's neighbourhood, drop it, leave the spot (forward when the
        known floor allows: :meth:`Vfh.leave_spot`)."""
        if self.goal is not None:
            self._ban(self.goal.xy, situation.now_s)
            if self.goal.kind == "inspect":
                self._ban(self.goal.target, situation.now_s)
        self.goal = None
        self.vfh.leave_spot(situation)

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
        """At a viewpoint: face the landmark (or the surface) until it is seen (inspected),
        or give up after 3 s: a landmark's viewpoint is black-listed, a surface counts as
        looked at (nothing there can be read from where it can be seen)."""
        goal = self.goal
        target = situation.landmarks.get(goal.landmark, goal.target or goal.xy)
        error = heading_error_rad(situation.pose, math.atan2(target[1] - situation.pose[1], target[0] - situation.pose[0]))
        if not goal.facing:
            goal.facing, goal.started_s = True, situation.now_s
        if goal.kind == "inspect":
            seen = self._inspected_near(target)
        else:
            seen = situation.now_s - self.visits.last_s.get(goal.landmark, -math.inf) < 0.5
        if (seen and abs(error) < 0.3) or situation.now_s - goal.started_s > 3.0 + abs(error):
            if goal.kind == "inspect":  # looked at from in front: done, whatever was read
                self._mark_inspected(target, 0.3)
            elif not seen and goal.kind == "glance":
                self._glance_failed[goal.landmark] = situation.now_s + self.visits.gap_s
            elif not seen:
                self._ban(goal.xy, situation.now_s)
            self.goal = None
        return limited_command(0.0, turn_towards(error, 3.0), "face-landmark" if goal.kind != "inspect" else "face-surface")

    def _inspect_scan(self, scan, scan_pose) -> None:
        """Mark the cells a scan inspected (:func:`inspected_hits`); drop an inspection goal
        whose surface it looked at on the way."""
        self._unread_scan = None
        row, col, inside = self.grid.index(inspected_hits(scan, scan_pose, self.read_range_m, self.read_incidence_rad))
        self.inspected[row[inside], col[inside]] = True
        if self.goal is not None and self.goal.kind == "inspect" and not self.goal.facing \
                and self._inspected_near(self.goal.target):
            self.goal = None

    def _inspected_near(self, xy, radius_cells: int = 1) -> bool:
        row, col, inside = self.grid.index([xy])
        if not inside[0]:
            return True
        r, c = int(row[0]), int(col[0])
        return bool(self.inspected[max(r - radius_cells, 0):r + radius_cells + 1,
                                   max(c - radius_cells, 0):c + radius_cells + 1].any())

    def _mark_inspected(self, xy, radius_m: float) -> None:
        """Count the cells within ``radius_m`` of ``xy`` as inspected."""
        row, col, inside = self.grid.index([xy])
        if inside[0]:
            k = int(math.ceil(radius_m / self.grid.resolution_m))
            r, c = int(row[0]), int(col[0])
            self.inspected[max(r - k, 0):r + k + 1, max(c - k, 0):c + k + 1] = True

    def _progress(self, situation: Situation) -> bool:
        """Track the distance to the goal; False when stuck (no progress for ``stuck_s``)."""
        goal = self.goal
        distance = (math.hypot(goal.xy[0] - situation.pose[0], goal.xy[1] - situation.pose[1]) if self._way is None
                    else way_left_m(self._way, situation.pose[:2])[0])
        if distance < goal.best_m - self.progress_m:
            goal.best_m, goal.improved_s = distance, situation.now_s
        return situation.now_s - goal.improved_s <= self.stuck_s

    def step(self, situation: Situation) -> Command:
        fresh_scan = self.vfh.observe(situation)
        self.visits.update(situation.sightings, situation.now_s, situation.landmarks, situation.pose[:2])
        if situation.bumped and not self.vfh.backoff.active:
            if self.goal is not None:
                self.goal.bumps += 1
                if self.goal.bumps >= 2:
                    self._ban(self.goal.xy, situation.now_s)
                    self.goal = None
            self.vfh.escape.cancel()  # back off over known floor, turn away from the bump side
            self.vfh.backoff.start(situation, prefer_left=bool(self.rng.integers(2)),
                                   distance_m=self.vfh.escape_reverse_m(situation.pose, self.vfh.backoff.distance_m))
        if self.vfh.spot.update(situation) and not self.vfh.backoff.active and not self.vfh.escaping:
            self._abandon(situation)  # goal after goal and still on one spot: leave it
        if self.vfh.backoff.active:
            return self.vfh.backoff.step(situation)
        if self.vfh.escaping:
            return self.vfh.escape.step(situation, reuse=fresh_scan)
        looking = self._look_around(situation)
        if looking is not None:
            return looking
        # at most one heavy job a step besides steering (a scan, the map's offers, a choice),
        # so that no step costs much more than the others
        busy = fresh_scan
        if fresh_scan:
            self._unread_scan = (situation.scan, situation.scan_pose)
        elif self._unread_scan is not None:
            busy = True
            self._inspect_scan(*self._unread_scan)
        if self._glance_check and not busy and (self.goal is None or self.goal.kind in ("frontier", "inspect")):
            busy, self._glance_check = True, False
            glance = self._glance(situation)
            if glance is not None:
                self.goal, self._way = glance, None  # on the way: a landmark due a visit is in sight, turn to it
        if situation.now_s - self._replanned_s >= self.replan_s and not busy:
            busy = True
            self._glance_check = True
            if self._refresh(situation):
                if self.goal is not None and self.goal.kind == "frontier" and not any(
                        math.hypot(f[0] - self.goal.xy[0], f[1] - self.goal.xy[1]) < 0.3 for f in self._frontiers):
                    self.goal = None  # seen from afar: that frontier is gone
                self._plan_way(situation)
        if self.goal is None:
            if busy:
                return limited_command(0.0, 0.0, "plan")  # choose next step
            self.goal, busy = self._choose(situation), True
            self._plan_way(situation)
        if self.goal is None:
            command = self.vfh.steer(situation, self.vfh.goal_heading_rad(situation), reuse=busy)
            return limited_command(command.speed_m_s, command.turn_rate_rad_s, "wander")
        if not self._progress(situation):
            self._abandon(situation)
            return self.vfh.escape.step(situation) if self.vfh.escaping else self.vfh.backoff.step(situation)
        distance = math.hypot(self.goal.xy[0] - situation.pose[0], self.goal.xy[1] - situation.pose[1])
        if self.goal.kind != "frontier" and (self.goal.facing or distance < self.reach_m):
            return self._at_landmark(situation)
        if self.goal.kind == "frontier" and distance < self.reach_m:
            self._ban(self.goal.xy, situation.now_s)  # if it is still a frontier, it cannot be seen from here
            self.goal = None
            return limited_command(0.0, 0.0, "reached")
        toward = self.goal.xy if self._way is None else way_ahead_xy(self._way, situation.pose[:2], self.lookahead_m)
        command = self.vfh.steer(situation, math.atan2(toward[1] - situation.pose[1], toward[0] - situation.pose[0]),
                                 reuse=busy)
        state = f"to-{self.goal.kind}" if command.state == "drive" else command.state
        return limited_command(command.speed_m_s, command.turn_rate_rad_s, state)
