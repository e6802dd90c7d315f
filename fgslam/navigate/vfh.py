"""``vfh``: Borenstein and Koren's Vector Field Histogram (1991), with the VFH+ refinements
that make it usable with a narrow, slow depth camera.

From the occupancy grid the scans build (:mod:`fgslam.navigate.grid`, our histogram grid),
each step:

1. the *active window* — occupied cells within ``d_max`` of the robot — makes a polar
   histogram of ``sectors`` sectors (world frame) holding, per sector, how far the robot's
   disc enlarged to ``robot radius + half a cell's diagonal + margin`` (0.17 + 0.07 + 0.03 m:
   an occupied cell means an obstacle somewhere in it) can go that way before it covers a
   cell (:func:`free_distances_m`). This is VFH+'s binary histogram with the obstacle's
   distance for its magnitude: the paper's summed ``c²·(a − b·d)`` magnitudes against a fixed
   threshold blocked every sector in the clutter room (80 occupied cells within 1.6 m sum far
   above any threshold that still stops for one), while a distance means the same in any room;
2. a sector is blocked when its free distance is below ``block_m`` (0.3 m), free again above
   ``clear_m`` (0.45 m), as before in between (VFH+ hysteresis; :func:`blocked_sectors`). A
   sector whose corridor (out to where it is blocked: what lies behind a wall is never seen)
   was never seen is *unknown*: not free;
3. runs of free, known sectors are the candidate valleys (:func:`valleys`). A wide valley
   (more than ``s_max`` sectors) offers the directions ``s_max/2`` in from each border, and the
   goal direction itself when it lies well inside; a narrow one its middle (the paper's
   k_n/k_f rule; :func:`candidate_directions`). The robot takes the candidate that costs least
   in turning from the goal, its heading and its previous choice (VFH+'s cost with
   hysteresis, so it does not dither or turn round; :func:`choose_direction`);
4. speed rises with the free distance ahead (cruise at 0.8 m) and falls with the turn still
   to make (0 beyond 25°: arcs sweep sides the ±21° camera has not seen), and is 0 when an
   occupied cell lies in the corridor ahead within the stopping distance, or when the disc,
   enlarged as for the histogram, would come nearer than that to an occupied cell — in view
   or remembered — anywhere along the arc the command drives within the stopping distance
   (:func:`arc_free_m`).

When the goal direction was never seen the robot turns to look at it before it commits;
with no valley at all it turns toward the nearest unknown sector for up to a full circle,
then backs off and takes the opposite heading — never "blocked" for ever
(:meth:`Vfh._boxed_in`). A robot that stays 7 s within 0.15 m of one spot (two ways that
each close when looked at) does the same (:class:`~fgslam.navigate.common.SpotWatch`).
Without a goal point it wanders: the goal heading is kept and changed by a random turn every
``wander_period_s``. On a bump it backs off ~0.15 m and turns away (:class:`BackOff`), and
marks where it hit in the grid (something the scan did not show). An owner may fit a forward
escape (:attr:`Vfh.escape`, :mod:`fgslam.navigate.escape`; ``explore`` does): leaving a spot
or a box it then turns toward a free, seen sector and drives out instead of reversing
(:meth:`Vfh.leave_spot`); ``vfh`` alone has none.
"""

from __future__ import annotations

import math

import numpy as np

from fgslam.navigate.common import (CRUISE_SPEED_M_S, ROBOT_RADIUS_M, BackOff, Command, Situation, SpotWatch,
                                    heading_error_rad, limited_command, turn_towards)
from fgslam.navigate.grid import OccupancyGrid
from slamio.geometry import wrap_angle

OCCUPIED_LOG_ODDS = 0.5  # a cell above this is an obstacle (one hit: 0.9)
ESCAPE_REVERSE_M = 0.25  # leaving a spot: back the way it came, well out of a 0.1 m circle

__all__ = ["Vfh", "free_distances_m", "blocked_sectors", "valleys", "candidate_directions",
           "choose_direction", "sector_angles_rad", "arc_poses", "arc_free_m", "known_free_behind_m"]


def sector_angles_rad(sectors: int) -> np.ndarray:
    """The centre bearing of each sector: sector k spans [−π + k·α, −π + (k+1)·α), α = 2π/sectors."""
    return -math.pi + (np.arange(sectors) + 0.5) * (2 * math.pi / sectors)


def free_distances_m(cells_xy, robot_xy, angles_rad, radius_m: float, d_max_m: float) -> np.ndarray:
    """Per world-frame direction, how far the robot's disc enlarged to ``radius_m`` can go
    straight before it covers an occupied cell's centre (``d_max_m`` when no cell is in the
    way; 0 when one is already inside the enlarged disc ahead). Cells behind the centre (on
    the way's far side) do not count: going on moves away from them."""
    offset = np.asarray(cells_xy, dtype=float).reshape(-1, 2) - np.asarray(robot_xy, dtype=float)
    angles = np.asarray(angles_rad, dtype=float)
    free = np.full(len(angles), float(d_max_m))
    if len(offset) == 0:
        return free
    c, s = np.cos(angles)[:, None], np.sin(angles)[:, None]
    along = c * offset[:, 0] + s * offset[:, 1]  # (directions, cells)
    lateral = -s * offset[:, 0] + c * offset[:, 1]
    in_way = (np.abs(lateral) < radius_m) & (along > 0)
    reach = np.where(in_way, along - np.sqrt(np.maximum(radius_m**2 - lateral**2, 0.0)), np.inf)
    return np.clip(np.minimum(free, reach.min(axis=1)), 0.0, None)


def arc_poses(pose, speed_m_s: float, turn_rate_rad_s: float, distance_m: float, step_m: float = 0.02) -> np.ndarray:
    """Poses (n, 3) every ``step_m`` of travel along the arc the command ``(speed, turn rate)``
    drives from ``pose``, out to ``distance_m`` (the start itself excluded; none when the
    command does not move the centre forward)."""
    if speed_m_s <= 0 or distance_m <= 0:
        return np.zeros((0, 3))
    s = np.arange(1, int(math.ceil(distance_m / step_m)) + 1) * step_m
    turned = s * (turn_rate_rad_s / speed_m_s)  # heading change after s of travel (curvature · s)
    small = np.abs(turned) < 1e-6
    safe = np.where(small, 1.0, turned)
    along = np.where(small, s, s * np.sin(safe) / safe)  # slamio.geometry.arc_increment, vectorised
    aside = np.where(small, 0.5 * s * turned, s * (1 - np.cos(safe)) / safe)
    c, si = math.cos(pose[2]), math.sin(pose[2])
    return np.column_stack([pose[0] + c * along - si * aside, pose[1] + si * along + c * aside, pose[2] + turned])


def arc_free_m(cells_xy, pose, speed_m_s: float, turn_rate_rad_s: float, radius_m: float, distance_m: float,
               step_m: float = 0.02) -> float:
    """How far the robot's disc enlarged to ``radius_m`` goes along the commanded arc
    (:func:`arc_poses`) before it comes within ``radius_m`` of an occupied cell's centre
    *and nearer to it than at the start* (the last sample before that, every ``step_m``;
    ``distance_m`` when it does not within that). A cell
    already inside the enlarged disc only counts once the arc goes nearer to it: the robot may
    move along or away from what it passes, never into it. Every cell given counts, in the
    camera's view or not: the remembered ones are what a ±21° view does not show while it
    turns past a corner."""
    cells = np.asarray(cells_xy, dtype=float).reshape(-1, 2)
    poses = arc_poses(pose, speed_m_s, turn_rate_rad_s, distance_m, step_m)
    if len(cells) == 0 or len(poses) == 0:
        return float(distance_m)
    start = np.hypot(cells[:, 0] - pose[0], cells[:, 1] - pose[1])
    near = start < radius_m + distance_m  # the only cells the swept disc can reach
    cells, start = cells[near], start[near]
    if len(cells) == 0:
        return float(distance_m)
    reach = np.hypot(poses[:, None, 0] - cells[None, :, 0], poses[:, None, 1] - cells[None, :, 1])
    hit = ((reach < radius_m) & (reach < start[None, :] - 1e-3)).any(axis=1)
    return float(np.argmax(hit) * step_m) if hit.any() else float(distance_m)


def known_free_behind_m(grid: OccupancyGrid, pose, radius_m: float, distance_m: float, step_m: float = 0.02) -> float:
    """How far the disc of ``radius_m`` can go straight back from ``pose`` with every cell it
    would newly cover known and not occupied (``distance_m`` at most): the floor behind the
    robot is only free where a scan or the robot's own footprint has shown it."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    lateral = np.linspace(-radius_m, radius_m, 9)
    for k in range(1, int(math.ceil(distance_m / step_m)) + 1):
        back = k * step_m
        # the disc's rear half-circle at this reverse: its back rim, points along it
        arc = np.arcsin(np.clip(lateral / radius_m, -1.0, 1.0))
        rim_along = -back - radius_m * np.cos(arc)
        points = np.column_stack([pose[0] + c * rim_along - s * lateral, pose[1] + s * rim_along + c * lateral])
        values = grid.values_at(points)
        if np.any(values == 0) or np.any(values > OCCUPIED_LOG_ODDS):
            return (k - 1) * step_m
    return float(distance_m)


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
                 d_max_m: float = 1.6, margin_m: float = 0.03, block_m: float = 0.3, clear_m: float = 0.45,
                 s_max: int = 16, wander_period_s: float = 20.0, look_m=(0.45, 0.7, 0.95), look_side_m=0.2,
                 relook_s: float = 5.0, near_m: float = ROBOT_RADIUS_M + 0.12, stuck_s: float = 6.0,
                 progress_m: float = 0.2, free_range_m: float | None = None, careful: bool = True):
        self.rng = np.random.default_rng(seed)
        self.goal_xy = goal_xy
        self.grid = grid if grid is not None else OccupancyGrid()
        # an occupied cell means an obstacle somewhere in it: up to half its diagonal from its centre
        cell_m = self.grid.resolution_m / math.sqrt(2.0)
        self.sectors, self.d_max_m, self.enlarge_m = sectors, d_max_m, ROBOT_RADIUS_M + cell_m + margin_m
        self.block_m, self.clear_m, self.s_max = block_m, clear_m, s_max
        self.wander_period_s = wander_period_s
        self._angles = angles = sector_angles_rad(sectors)
        look = np.asarray(look_m, dtype=float)
        # per sector, the offsets of the cells that must have been seen for it to count as known:
        # along its centre line and ``look_side_m`` to either side (the disc's corridor)
        along, side = np.meshgrid(look, [-look_side_m, 0.0, look_side_m])
        along, side = along.ravel(), side.ravel()
        c, s = np.cos(angles)[:, None], np.sin(angles)[:, None]
        self._probes = np.stack([along * c - side * s, along * s + side * c], axis=2).reshape(-1, 2)
        self._probe_along_m = along
        self.backoff = BackOff()
        # leaving a spot forward (fgslam.navigate.escape.ForwardEscape), when an owner fits one;
        # without it the robot reverses (escape_reverse_m) and turns away
        self.escape = None
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
        self._boxed_turned = 0.0  # how far it has turned since no way was open
        self._boxed_heading: float | None = None
        self._histogram = None
        self.spot = SpotWatch(stuck_s, progress_m)
        self.free_range_m = free_range_m
        # the arc stop test and the reverse over known floor only (module docstring); ``explore``
        # runs without them until they are measured live for it (docs/navigate.md)
        self.careful = careful

    @property
    def sector_angles(self) -> np.ndarray:
        """The world-frame centre bearing of each histogram sector (:func:`sector_angles_rad`)."""
        return self._angles

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
            self.grid.add_scan(situation.scan, situation.scan_pose, self.free_range_m)
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

    def histogram(self, pose, reuse: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(free distance, blocked, known) per sector at ``pose`` (module docstring, steps 1–2);
        ``reuse``: the previous step's (world-frame, so still right after a turn; at most a
        step's travel, ~1 cm, old), when the caller already did a heavy job this step."""
        if reuse and self._histogram is not None:
            return self._histogram
        cells, log_odds = self._window = self.grid.window(pose[:2], self.d_max_m)
        free = free_distances_m(cells[log_odds > OCCUPIED_LOG_ODDS], pose[:2], self._angles, self.enlarge_m,
                                self.d_max_m)
        self._blocked = blocked_sectors(-free, -self.clear_m, -self.block_m, self._blocked)
        # known: its corridor was seen, up to where it is blocked (what lies behind a wall never is)
        seen = (self.grid.values_at(self._probes + np.asarray(pose[:2])) != 0).reshape(self.sectors, -1)
        seen |= self._probe_along_m[None, :] > free[:, None] + 0.5 * self.grid.resolution_m
        self._histogram = (free, self._blocked.copy(), seen.all(axis=1) | self._blocked)
        return self._histogram

    def _gap_ahead_m(self, pose) -> float:
        """Free distance in the corridor the disc sweeps straight ahead, or 0 when an occupied
        cell is within ``near_m`` of the centre in the front ±60° (the robot arcs as it turns:
        beside an obstacle it turns in place first). Occupied cells of the active window
        :meth:`histogram` last read."""
        cells, log_odds = self._window
        cells = cells[log_odds > OCCUPIED_LOG_ODDS]
        if len(cells) == 0:
            return math.inf
        c, s = math.cos(pose[2]), math.sin(pose[2])
        dx, dy = cells[:, 0] - pose[0], cells[:, 1] - pose[1]
        ahead, side = c * dx + s * dy, -s * dx + c * dy
        if np.any((ahead > 0.5 * np.abs(side)) & (np.hypot(ahead, side) < self.near_m)):
            return 0.0
        inside = (ahead > 0) & (np.abs(side) < self.enlarge_m)
        return float(ahead[inside].min() - ROBOT_RADIUS_M) if inside.any() else math.inf

    # ------------------------------------------------------------------ steering

    def steer(self, situation: Situation, goal_rad: float, reuse: bool = False) -> Command:
        """One VFH decision toward the world-frame heading ``goal_rad`` (``reuse``: the
        previous step's histogram, :meth:`histogram`)."""
        pose = situation.pose
        free, blocked, known = self.histogram(pose, reuse)
        angles = self._angles
        goal_sector = int(np.argmin(np.abs(wrap_angle(angles - goal_rad))))
        unlooked = situation.now_s - self._looked_s > self.relook_s  # not in the camera's view lately
        if not known[goal_sector] and unlooked[goal_sector]:
            return limited_command(0.0, turn_towards(heading_error_rad(pose, goal_rad), 3.0), "look")
        direction = choose_direction(candidate_directions(valleys(~blocked & known), self.sectors, goal_rad, self.s_max),
                                     goal_rad, pose[2], self._previous)
        if direction is None:
            return self._boxed_in(situation, known, unlooked)
        self._boxed_heading = None
        self._previous = direction
        if self.goal_xy is None and abs(wrap_angle(direction - goal_rad)) > 0.5 * math.pi:
            self._wander_heading = direction  # the wander goal is out of reach: wander where the way is open
        error = heading_error_rad(pose, direction)
        heading_sector = int(np.argmin(np.abs(wrap_angle(angles - pose[2]))))
        room = min(max((free[heading_sector] - self.block_m) / 0.5, 0.0), 1.0)  # cruise with 0.8 m free
        # arcs sweep the sides the narrow camera has not seen: turn mostly on the spot
        speed = CRUISE_SPEED_M_S * (0.3 + 0.7 * room) * max(0.0, 1.0 - abs(error) / math.radians(25))
        turn = turn_towards(error)
        if self.must_stop(pose, speed, turn):
            speed = 0.0
        return limited_command(speed, turn, "drive" if speed > 0 else "turn")

    def must_stop(self, pose, speed_m_s: float, turn_rate_rad_s: float) -> bool:
        """The stop rules (module docstring, step 4) for a command at ``pose``, on the active
        window the last :meth:`histogram` read: an occupied cell in the corridor ahead within
        the stopping distance, or (``careful``) the enlarged disc nearing one along the arc."""
        stopping_m = 0.08 + speed_m_s**2 / (2 * 0.5) + speed_m_s * 0.2
        return self._gap_ahead_m(pose) < stopping_m or (
            self.careful and self._arc_free_m(pose, speed_m_s, turn_rate_rad_s, stopping_m) < stopping_m)

    def _arc_free_m(self, pose, speed_m_s: float, turn_rate_rad_s: float, distance_m: float) -> float:
        """:func:`arc_free_m` on the occupied cells of the active window (remembered ones too),
        the disc enlarged as for the histogram."""
        cells, log_odds = self._window
        return arc_free_m(cells[log_odds > OCCUPIED_LOG_ODDS], pose, speed_m_s, turn_rate_rad_s, self.enlarge_m,
                          distance_m)

    def _boxed_in(self, situation: Situation, known, unlooked) -> Command:
        """No way open: turn (toward the nearest sector not looked at lately) for up to a full
        circle, so the narrow camera sees all round; still none: back off, turn away and take
        a new wander heading, so the robot never sits turning on one spot."""
        pose = situation.pose
        if self._boxed_heading is None:  # a new search
            self._boxed_turned, self._boxed_heading = 0.0, pose[2]
            todo = np.nonzero(~known & unlooked)[0]
            if len(todo):
                nearest = todo[np.argmin(np.abs(wrap_angle(self._angles[todo] - pose[2])))]
                self._look_sign = math.copysign(1.0, heading_error_rad(pose, self._angles[nearest]) or 1.0)
        self._boxed_turned += abs(wrap_angle(pose[2] - self._boxed_heading))
        self._boxed_heading = pose[2]
        self._previous = None
        if self._boxed_turned < 2 * math.pi:
            return limited_command(0.0, self._look_sign, "look" if (~known).any() else "blocked")
        self._boxed_heading = None
        self.leave_spot(situation)
        self._wander_heading = float(wrap_angle(pose[2] + math.pi))
        self._wander_until_s = situation.now_s + self.wander_period_s
        return self.escape.step(situation) if self.escaping else self.backoff.step(situation)

    @property
    def escaping(self) -> bool:
        """A forward escape (:attr:`escape`) is under way."""
        return self.escape is not None and self.escape.active

    def leave_spot(self, situation: Situation) -> None:
        """Leave the spot the robot is on: forward toward floor known free when an escape is
        fitted and finds a way out (:mod:`fgslam.navigate.escape`), else back off
        (:meth:`escape_reverse_m`) and turn away."""
        if self.escape is not None and self.escape.start(situation):
            return
        self.backoff.start(situation, prefer_left=bool(self.rng.integers(2)),
                           distance_m=self.escape_reverse_m(situation.pose))

    def escape_reverse_m(self, pose, most_m: float = ESCAPE_REVERSE_M) -> float:
        """How far to reverse (leaving a spot: :data:`ESCAPE_REVERSE_M`; after a bump: the
        back-off's 0.15 m): at most as far as the robot's disc goes
        straight back over floor the grid knows is free (:func:`known_free_behind_m`), less
        5 cm; 0 when that is less. The robot has no eyes or bumper behind: a reverse into a
        corner it never saw, then a turn, brings that corner onto its bumper."""
        if not self.careful:  # as before: the histogram's free distance behind, at least 5 cm
            behind = int(np.argmin(np.abs(wrap_angle(self._angles - (pose[2] + math.pi)))))
            return (ESCAPE_REVERSE_M if self._histogram is None else
                    float(np.clip(self._histogram[0][behind] - 0.05, 0.05, ESCAPE_REVERSE_M)))
        free = known_free_behind_m(self.grid, pose, ROBOT_RADIUS_M, most_m + 0.05)
        return float(np.clip(free - 0.05, 0.0, most_m))

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
        fresh = self.observe(situation)  # a scan integrated: one heavy job is enough for a step
        if self.spot.update(situation) and not self.backoff.active and not self.escaping:
            # dithering on one spot (two ways that each close when looked at): leave it
            self.leave_spot(situation)
            self._wander_heading = float(wrap_angle(situation.pose[2] + math.pi))
            self._wander_until_s = situation.now_s + self.wander_period_s
        if situation.bumped:
            if self.escape is not None:
                self.escape.cancel()
            self.backoff.start(situation, prefer_left=bool(self.rng.integers(2)),
                               distance_m=self.escape_reverse_m(situation.pose, self.backoff.distance_m))
        if self.backoff.active:
            return self.backoff.step(situation)
        if self.escaping:
            return self.escape.step(situation, reuse=fresh)
        return self.steer(situation, self.goal_heading_rad(situation), reuse=fresh)
