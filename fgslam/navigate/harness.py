"""A fast kinematic harness: drive a navigator through a world of obstacles in simulated time.

No camera images, no SLAM: the robot is a unicycle disc (radius 0.17 m) whose pose the
navigator is told exactly (or, with ``odometry_noise``, as dead reckoning with a fractional
error on each step's distance and turn, blind to sliding along walls; the landmarks it is
told of stay at their true places, so that option only tests a drifting pose). Each step
of ``dt_s``:

* every ``scan_every_s`` (0.4 s: one Kinect frame of the live loop) a range scan is made
  from the true pose, and the landmarks in the camera's view are *sighted*: within
  ``camera_fov_rad`` of the heading, within ``camera_range_m``, not hidden
  (:func:`slamio.obstacles.line_of_sight`) and, for a landmark with a facing (a tag: its
  face's yaw in ``landmark_yaws``), seen from within ``facing_limit_rad`` (70°) of its face's
  normal, as the tag detector needs. The scan (``scan``):

  - ``"depth"`` — what the live loop's depth scan gives
    (:func:`slamio.camera.depth_scan.ray_cast_depth_scan`: rays from the Kinect 0.13 m ahead
    of the centre over its 57°, binned by bearing from the centre every 0.5°: a fan of only
    ±21°), the default when the world is a :class:`slamio.clutter.ClutterWorld`;
  - ``"rays"`` — ``rays`` rays over ``fov_rad`` from the centre (:func:`slamio.scan.ray_cast_scan`),
    the default for bare :class:`~slamio.obstacles.Obstacles`;
* the bumper: the disc touching an obstacle (:func:`slamio.obstacles.disc_contacts`) in its
  front half (bearing within ±90° of the heading) presses it. The first step of a press is a
  *bump* (counted) and its command is cut to zero, as the Create's safety monitor stops the
  wheels; while it stays pressed forward motion is refused (backing off and turning are not);
* the command (limited to the wheels by :func:`slamio.sim_models.wheel_speeds_m_s`) moves the
  disc along an exact arc; :func:`slamio.obstacles.push_disc_out` then slides it along
  whatever it would enter.

What :class:`DriveResult` reports, and how:

* ``bumps`` — presses begun (above);
* ``longest_stuck_s`` — the longest time the robot's centre stayed within 0.1 m of one spot
  (the spot is reset each time the centre leaves that circle). Turning in place counts:
  a look-around of 360° at 1 rad/s is ~6 s, so the "never stuck > 10 s" goal leaves room for
  one;
* ``area_seen_m2`` — 0.25 m cells crossed by a scan ray (up to its hit or the maximum
  range): the floor the depth camera has looked at; ``area_visited_m2`` — 0.25 m cells
  the robot's disc overlapped (its path sampled every other step);
* ``landmarks_seen`` — ids sighted at least once; ``landmarks_revisited`` — ids sighted again
  after at least ``revisit_gap_s`` (20 s) without a sighting: a second, separate visit;
* ``step_time_us`` — the wall-clock time of each ``navigator.step`` call (a busy machine
  shows in its tail); ``step_cpu_us`` — the CPU time of the calling thread for each call
  (:func:`time.thread_time`: what the step itself costs, whatever else runs).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from fgslam.navigate.common import ROBOT_RADIUS_M, Navigator, Situation
from slamio.camera.depth_scan import ray_cast_depth_scan
from slamio.camera.kinect import KINECT_HFOV_RAD
from slamio.geometry import arc_increment, compose_pose, wrap_angle
from slamio.obstacles import Obstacles, box_segments, disc_contacts, line_of_sight, push_disc_out, room_segments
from slamio.errors import FgslamError
from slamio.scan import ray_cast_scan
from slamio.sim_models import wheel_speeds_m_s, WHEEL_BASE_M

__all__ = ["drive", "DriveResult", "six_metre_room", "bump_side", "world_landmarks"]

CELL_M = 0.25


@dataclass
class DriveResult:
    """What one drive did (module docstring)."""

    path: np.ndarray  # (steps, 3) true poses
    states: list[str]
    bumps: int
    longest_stuck_s: float
    area_seen_m2: float
    area_visited_m2: float
    landmarks_seen: set[int]
    landmarks_revisited: set[int]
    sightings: dict[int, int]
    step_time_us: np.ndarray
    step_cpu_us: np.ndarray
    landmark_count: int = 0
    state_time_s: dict[str, float] = field(default_factory=dict)

    def summary(self) -> dict:
        """The numbers a report prints."""
        return {"bumps": self.bumps, "longest_stuck_s": round(self.longest_stuck_s, 1),
                "area_seen_m2": round(self.area_seen_m2, 2), "area_visited_m2": round(self.area_visited_m2, 2),
                "landmarks_seen": len(self.landmarks_seen), "landmarks_revisited": len(self.landmarks_revisited),
                "landmarks": self.landmark_count, "step_mean_us": round(float(self.step_time_us.mean()), 1),
                "step_max_us": round(float(self.step_time_us.max()), 1),
                "step_cpu_mean_us": round(float(self.step_cpu_us.mean()), 1),
                "step_cpu_max_us": round(float(self.step_cpu_us.max()), 1)}


def six_metre_room() -> tuple[Obstacles, dict[int, tuple[float, float]]]:
    """The closed-loop tests' world: a 6 × 6 m room with three boxes and three cylinders,
    and twelve landmarks on the walls (three a wall, 1 cm in front of it)."""
    boxes = [box_segments((2.0, 4.1), (0.8, 0.5)), box_segments((4.3, 2.0), (0.6, 0.6), 0.4),
             box_segments((4.4, 4.7), (1.0, 0.4))]
    obstacles = Obstacles(np.vstack([room_segments(6.0, 6.0)] + boxes),
                          np.array([[2.6, 2.0, 0.15], [1.1, 3.0, 0.1], [3.7, 3.5, 0.2]]))
    landmarks, k = {}, 0
    for along in (1.5, 3.0, 4.5):
        for xy in ((along, 0.01), (5.99, along), (6.0 - along, 5.99), (0.01, 6.0 - along)):
            landmarks[k] = xy
            k += 1
    return obstacles, landmarks


def world_landmarks(world) -> tuple[dict[int, tuple[float, float]], dict[int, float]]:
    """A :class:`slamio.clutter.ClutterWorld`'s tags: ({id: (x, y)}, {id: yaw of the face})."""
    return ({t.tag_id: (t.x_m, t.y_m) for t in world.tags}, {t.tag_id: t.yaw_rad for t in world.tags})


def bump_side(contact_bearings_rad) -> str:
    """"left", "right" or "front" from the robot-frame bearings of the pressing contacts."""
    mean = float(np.arctan2(np.mean(np.sin(contact_bearings_rad)), np.mean(np.cos(contact_bearings_rad))))
    return "left" if mean > 0.35 else "right" if mean < -0.35 else "front"


def _cells_of_scan(scan, pose) -> np.ndarray:
    reach = scan.free_distance_m()
    samples = np.arange(0.0, scan.max_range_m + 0.1, 0.1)
    ray, sample = np.nonzero(samples[None, :] <= reach[:, None])
    bearing = scan.angles_rad[ray] + pose[2]
    xy = np.column_stack([pose[0] + samples[sample] * np.cos(bearing), pose[1] + samples[sample] * np.sin(bearing)])
    cells = np.floor(xy / CELL_M).astype(np.int64)
    return np.unique(cells[:, 0] * 1_000_003 + cells[:, 1])  # one key per cell (worlds < 250 km)


def visited_area_m2(path_xy: np.ndarray) -> float:
    """Floor the robot's disc overlapped along ``path_xy``: the cells of :data:`CELL_M` it touched."""
    return _visited_cells(path_xy) * CELL_M**2


def _visited_cells(path_xy: np.ndarray) -> int:
    lo = np.floor((path_xy.min(axis=0) - ROBOT_RADIUS_M) / CELL_M).astype(int)
    hi = np.floor((path_xy.max(axis=0) + ROBOT_RADIUS_M) / CELL_M).astype(int)
    gx, gy = np.meshgrid(np.arange(lo[0], hi[0] + 1), np.arange(lo[1], hi[1] + 1))
    centres = (np.column_stack([gx.ravel(), gy.ravel()]) + 0.5) * CELL_M
    visited = np.zeros(len(centres), bool)
    for chunk in np.array_split(path_xy[::2], max(1, len(path_xy) // 400)):
        # distance from each path point to each cell's nearest point: the disc overlaps the cell
        gap = np.maximum(np.abs(centres[:, None, :] - chunk[None, :, :]) - 0.5 * CELL_M, 0.0)
        visited |= ((gap**2).sum(axis=2) < ROBOT_RADIUS_M**2).any(axis=1)
    return int(visited.sum())


def longest_stuck_s(stamps_s: np.ndarray, path_xy: np.ndarray, radius_m: float = 0.1) -> float:
    """The longest stretch of time over which the centre stayed within ``radius_m`` of where
    the stretch began (turning in place counts as stuck)."""
    longest, anchor, start = 0.0, path_xy[0], 0
    for i, xy in enumerate(path_xy):
        if (xy[0] - anchor[0]) ** 2 + (xy[1] - anchor[1]) ** 2 > radius_m**2:
            anchor, start = xy, i
        longest = max(longest, float(stamps_s[i] - stamps_s[start]))
    return longest


class _Sightings:
    """Landmark sightings and visits (a new visit after ``gap_s`` unseen)."""

    def __init__(self, landmarks, fov_rad: float, range_m: float, gap_s: float, yaws=None,
                 facing_limit_rad: float = math.radians(70)):
        self.landmarks = dict(landmarks or {})
        self.yaws, self.facing_limit_rad = dict(yaws or {}), facing_limit_rad
        self.fov_rad, self.range_m, self.gap_s = fov_rad, range_m, gap_s
        self.count: dict[int, int] = {}
        self.last_s: dict[int, float] = {}
        self.revisited: set[int] = set()

    def look(self, obstacles: Obstacles, pose, now_s: float) -> None:
        for key, (lx, ly) in self.landmarks.items():
            dx, dy = lx - pose[0], ly - pose[1]
            if math.hypot(dx, dy) > self.range_m or abs(wrap_angle(math.atan2(dy, dx) - pose[2])) > 0.5 * self.fov_rad:
                continue
            if key in self.yaws and abs(wrap_angle(math.atan2(-dy, -dx) - self.yaws[key])) > self.facing_limit_rad:
                continue  # seen from behind or too obliquely
            if not line_of_sight(obstacles, pose[:2], (lx, ly)):
                continue
            if key in self.last_s and now_s - self.last_s[key] >= self.gap_s:
                self.revisited.add(key)
            self.count[key] = self.count.get(key, 0) + 1
            self.last_s[key] = now_s


def drive(obstacles, navigator: Navigator, start_pose=None, *, duration_s: float, dt_s: float = 0.05,
          scan_every_s: float = 0.4, scan: str | None = None, fov_rad: float = KINECT_HFOV_RAD, rays: int = 58,
          max_range_m: float = 4.0, landmarks=None, landmark_yaws=None, camera_fov_rad: float = KINECT_HFOV_RAD,
          camera_range_m: float = 3.5, revisit_gap_s: float = 20.0, odometry_noise: float = 0.0,
          seed: int = 0) -> DriveResult:
    """Drive ``navigator`` from ``start_pose`` for ``duration_s`` of simulated time (module
    docstring). ``obstacles`` may be a :class:`slamio.clutter.ClutterWorld`: then the start
    pose, the landmarks (its tags) and their facings default to the world's, and the scan to
    ``"depth"``."""
    if hasattr(obstacles, "tags"):  # a ClutterWorld
        world = obstacles
        obstacles, scan = world.obstacles, scan or "depth"
        start_pose = world.start_pose if start_pose is None else start_pose
        if landmarks is None:
            landmarks, landmark_yaws = world_landmarks(world)
    scan = scan or "rays"
    if scan not in ("depth", "rays") or start_pose is None:
        raise FgslamError(f"drive: scan must be 'depth' or 'rays' (got {scan!r}) and a start pose is needed "
                          "(only a ClutterWorld has its own)")
    rng = np.random.default_rng(seed)
    steps = int(round(duration_s / dt_s))
    pose, estimate = tuple(map(float, start_pose)), tuple(map(float, start_pose))
    kind, scan, scan_pose = scan, None, None
    next_scan_s, pressed_before, bumps = 0.0, False, 0
    sight = _Sightings(landmarks, camera_fov_rad, camera_range_m, revisit_gap_s, landmark_yaws)
    path, states, step_us, cpu_us, seen_cells, state_time = [], [], np.zeros(steps), np.zeros(steps), set(), {}
    for i in range(steps):
        now = i * dt_s
        contacts = wrap_angle(disc_contacts(obstacles, pose[:2], ROBOT_RADIUS_M) - pose[2])
        front = contacts[np.abs(contacts) < 0.5 * math.pi - 1e-6]
        pressed = len(front) > 0
        bumps += int(pressed and not pressed_before)
        if now + 1e-9 >= next_scan_s:
            scan = (ray_cast_depth_scan(obstacles, pose, max_range_m=max_range_m) if kind == "depth"
                    else ray_cast_scan(obstacles, pose, fov_rad, rays, max_range_m))
            scan_pose = estimate
            seen_cells.update(_cells_of_scan(scan, pose).tolist())
            sight.look(obstacles, pose, now)
            next_scan_s += scan_every_s
        situation = Situation(now, estimate, scan, scan_pose, pressed, bump_side(front) if pressed else None,
                              {k: sight.landmarks[k] for k in sight.count}, dict(sight.count))
        started, started_cpu = time.perf_counter(), time.thread_time()
        command = navigator.step(situation)
        step_us[i], cpu_us[i] = (time.perf_counter() - started) * 1e6, (time.thread_time() - started_cpu) * 1e6
        left, right = wheel_speeds_m_s(command.speed_m_s, command.turn_rate_rad_s)
        speed, turn = 0.5 * (left + right), (right - left) / WHEEL_BASE_M
        if pressed and (not pressed_before or speed > 0):
            speed, turn = 0.0, (0.0 if not pressed_before else turn)
        pressed_before = pressed
        moved = compose_pose(pose, arc_increment(speed * dt_s, turn * dt_s))
        pose = (*push_disc_out(obstacles, moved[:2], ROBOT_RADIUS_M), moved[2])
        if odometry_noise:
            speed, turn = speed * (1 + odometry_noise * rng.standard_normal()), turn * (1 + odometry_noise * rng.standard_normal())
        estimate = compose_pose(estimate, arc_increment(speed * dt_s, turn * dt_s)) if odometry_noise else pose
        path.append(pose)
        states.append(command.state)
        state_time[command.state] = state_time.get(command.state, 0.0) + dt_s
    path_xy = np.asarray(path)[:, :2]
    return DriveResult(np.asarray(path), states, bumps, longest_stuck_s(dt_s * np.arange(len(path_xy)), path_xy),
                       len(seen_cells) * CELL_M**2, visited_area_m2(path_xy), set(sight.count), set(sight.revisited), dict(sight.count),
                       step_us, cpu_us, len(sight.landmarks), state_time)
