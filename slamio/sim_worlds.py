"""The simulator's scenarios: the worlds (landmarks), the paths the robot drives, and the
robot, odometry and sensor settings of each (:data:`SCENARIOS`; the numbers are explained
in :mod:`slamio.sim`'s docstring).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from slamio.camera.tag_noise import TagNoise
from slamio.geometry import wrap_angle
from slamio.sim_models import MotionModel, SensorModel, WheelSlipNoise, World

SCENARIOS = ("arena-square", "arena-octagon", "cylinders", "grid", "clutter")

ARENA_SIDE_M = 3.048  # 10 ft
ARENA_PATH_WIDTH_M = 1.8288  # 6 ft
TAG_HEIGHT_M = 0.20
TAG_FACING_LIMIT_RAD = math.radians(70.0)
ARENA_TAG_SIZE_M = 0.16
#: ``tag_noise="measured"``: the arena camera (640 px across its 1.2 rad FOV) and a 0.16 m tag
#: with the corner precision measured on real photos (slamio/camera/tag_noise.py).
ARENA_TAG_NOISE = TagNoise(fx_px=320.0 / math.tan(0.6), tag_size_m=ARENA_TAG_SIZE_M)
#: ``clutter``: the world is always :func:`slamio.clutter.clutter_world` of this seed (as the
#: other scenarios' worlds are fixed; the simulator's seed draws the noise), its objects kept
#: off the patrol loop, a 3 m square 1.5 m in from the walls of the 6 m room (pillars and
#: cylinders stand between it and the walls, boxes inside it: tags go out of sight behind them).
CLUTTER_WORLD_SEED = 0
CLUTTER_LOOP_INSET_M = 1.5
GRID_SPACING_M = 3.0
GRID_LANE_EVERY_ROWS = 3  # one lane per three landmark rows (9 m apart)
GRID_MARGIN_M = 2.0


@dataclass(frozen=True)
class Scenario:
    """Everything :func:`simulate` needs for one scenario."""

    name: str
    world: World
    waypoints_xy: np.ndarray  # (n, 2) closed polygon; the robot starts on waypoint 0
    default_laps: int
    motion: MotionModel
    odometry: WheelSlipNoise
    sensor: SensorModel
    extra_sensor_info: dict[str, Any]


_ARENA_MOTION = MotionModel(dt_s=0.1, speed_m_s=0.2, max_turn_rate_rad_s=0.8, turn_gain_per_s=2.0, lookahead_m=0.25)
_ARENA_ODOMETRY = WheelSlipNoise(k_wheel=0.05, slip_sigma_x_m=5e-4, slip_sigma_y_m=5e-4, slip_sigma_theta_rad=1e-3)
_TAG_CAMERA = SensorModel(
    landmark_kind="apriltag",
    fov_rad=1.2,
    min_range_m=0.15,
    max_range_m=3.5,
    sigma_range_m=0.01,
    sigma_range_per_m=0.0,
    sigma_range_per_m2=0.005,
    sigma_bearing_rad=0.01,
    sigma_tag_yaw_rad=0.05,
    facing_limit_rad=TAG_FACING_LIMIT_RAD,
)
_KINECT = SensorModel(
    landmark_kind="coloured-cylinder",
    fov_rad=math.radians(57.0),
    min_range_m=0.8,
    max_range_m=4.0,
    sigma_range_m=0.01,
    sigma_range_per_m=0.0,
    sigma_range_per_m2=1.425e-3,
    sigma_bearing_rad=0.01,
    sigma_height_m=0.02,
)
_CLUTTER_CAMERA = replace(_TAG_CAMERA, fov_rad=math.radians(57.0), max_range_m=4.0)  # the Kinect's 57° and 4 m
_GRID_MOTION = MotionModel(dt_s=0.2, speed_m_s=0.5, max_turn_rate_rad_s=1.0, turn_gain_per_s=2.0, lookahead_m=1.0)
_GRID_ODOMETRY = WheelSlipNoise(k_wheel=0.01, slip_sigma_x_m=2e-3, slip_sigma_y_m=2e-3, slip_sigma_theta_rad=1e-3)
_GRID_SENSOR = SensorModel(
    landmark_kind="point",
    fov_rad=math.radians(120.0),
    min_range_m=0.3,
    max_range_m=6.0,
    sigma_range_m=0.03,
    sigma_range_per_m=0.01,
    sigma_range_per_m2=0.0,
    sigma_bearing_rad=0.02,
)

CYLINDER_COLOURS = ("red", "green", "blue")
CYLINDER_HEIGHTS_M = (0.40, 0.60, 0.80)


def arena_tags(side_m: float = ARENA_SIDE_M) -> World:
    """Eight AprilTags, two per wall at 1/3 and 2/3 along it, facing into the square arena.

    Ids go counter-clockwise: 0–1 on the south wall (y = 0, facing +y), 2–3 east
    (x = side, facing −x), 4–5 north (y = side, facing −y), 6–7 west (x = 0, facing +x).
    """
    third, two_thirds = side_m / 3.0, 2.0 * side_m / 3.0
    xy = [
        (third, 0.0), (two_thirds, 0.0),
        (side_m, third), (side_m, two_thirds),
        (two_thirds, side_m), (third, side_m),
        (0.0, two_thirds), (0.0, third),
    ]
    yaws = [0.5 * math.pi] * 2 + [math.pi] * 2 + [-0.5 * math.pi] * 2 + [0.0] * 2
    return World(np.array(xy), np.full(8, TAG_HEIGHT_M), wrap_angle(np.array(yaws)))


def polygon_path(sides: int, width_across_flats_m: float, centre_xy: tuple[float, float]) -> np.ndarray:
    """A regular polygon, counter-clockwise, with a flat side at the bottom.

    Waypoint 0 is the left end of the bottom side, so the first leg heads along +x.
    ``sides=4`` gives a square of side ``width_across_flats_m``.
    """
    apothem = 0.5 * width_across_flats_m
    radius = apothem / math.cos(math.pi / sides)
    first = -0.5 * math.pi - math.pi / sides
    angles = first + 2.0 * math.pi * np.arange(sides) / sides
    return np.column_stack([centre_xy[0] + radius * np.cos(angles), centre_xy[1] + radius * np.sin(angles)])


def cylinder_world(room_side_m: float = 5.0, triangle_side_m: float = 2.25,
                   beyond_m: float = 1.0) -> tuple[World, np.ndarray]:
    """The three-cylinder room and its triangular path: (world, waypoints).

    The path is an equilateral triangle centred in the room (first leg along +x). Cylinder
    i stands ``beyond_m`` past the end of leg i, on the leg's line, so the robot drives
    straight at it: red (id 0) ends leg 0, green (id 1) leg 1, blue (id 2) leg 2.
    """
    centre = (0.5 * room_side_m, 0.5 * room_side_m)
    waypoints = polygon_path(3, triangle_side_m / math.sqrt(3.0), centre)
    xy = []
    for i in range(3):
        start, end = waypoints[i], waypoints[(i + 1) % 3]
        direction = (end - start) / np.linalg.norm(end - start)
        xy.append(end + beyond_m * direction)
    return World(np.array(xy), np.array(CYLINDER_HEIGHTS_M)), waypoints


def _grid_shape(n_landmarks: int) -> tuple[int, int]:
    columns = math.ceil(math.sqrt(n_landmarks))
    return columns, math.ceil(n_landmarks / columns)


def grid_landmarks_xy(n_landmarks: int, spacing_m: float = GRID_SPACING_M) -> np.ndarray:
    """(N, 2) landmark positions: id i at (spacing·(i mod C), spacing·(i div C)), C = ⌈√N⌉."""
    columns, _ = _grid_shape(n_landmarks)
    ids = np.arange(n_landmarks)
    return np.column_stack([spacing_m * (ids % columns), spacing_m * (ids // columns)]).astype(float)


def grid_path(n_landmarks: int, spacing_m: float = GRID_SPACING_M) -> np.ndarray:
    """Lawnmower waypoints for the grid: lanes between rows, then back to the start.

    Lanes run along x at y = spacing·(1/2 + 3k), k = 0 … ⌈rows/3⌉ − 1 (every landmark is
    within 1.5 spacings of a lane), alternating direction, each ``GRID_MARGIN_M`` past the
    outer columns. From the end of the last lane the robot drives straight back to the
    start; with a single lane it comes back on the far side of the first row instead.
    """
    columns, rows = _grid_shape(n_landmarks)
    x_min = -GRID_MARGIN_M
    x_max = spacing_m * (columns - 1) + GRID_MARGIN_M
    lanes = math.ceil(rows / GRID_LANE_EVERY_ROWS)
    points: list[tuple[float, float]] = []
    for k in range(lanes):
        y = spacing_m * (0.5 + GRID_LANE_EVERY_ROWS * k)
        ends = [(x_min, y), (x_max, y)]
        points.extend(ends if k % 2 == 0 else ends[::-1])
    if lanes == 1:
        y_back = spacing_m * 0.5 + spacing_m
        points.extend([(x_max, y_back), (x_min, y_back)])
    return np.array(points)


def clutter_loop(room_side_m: float = 6.0, inset_m: float = CLUTTER_LOOP_INSET_M) -> np.ndarray:
    """The ``clutter`` scenario's patrol: a square ``inset_m`` in from the room's walls."""
    return polygon_path(4, room_side_m - 2.0 * inset_m, (0.5 * room_side_m, 0.5 * room_side_m))


def clutter_scenario_world():
    """``(ClutterWorld, World, waypoints)`` of the ``clutter`` scenario: the tags as landmarks,
    hidden behind the room's obstacles."""
    from slamio.clutter import ROOM_M, clutter_world

    waypoints = clutter_loop(ROOM_M[0])
    room = clutter_world(CLUTTER_WORLD_SEED, room_m=ROOM_M, keep_clear_xy=waypoints)
    xy, heights, yaws = room.tag_arrays()
    return room, World(xy, heights, wrap_angle(yaws), room.obstacles), waypoints


def scenario(name: str, n_landmarks: int, grid_spacing_m: float = GRID_SPACING_M) -> Scenario:
    centre = (0.5 * ARENA_SIDE_M, 0.5 * ARENA_SIDE_M)
    if name in ("arena-square", "arena-octagon"):
        sides = 4 if name == "arena-square" else 8
        return Scenario(
            name, arena_tags(), polygon_path(sides, ARENA_PATH_WIDTH_M, centre), 2,
            _ARENA_MOTION, _ARENA_ODOMETRY, _TAG_CAMERA,
            {"arena_m": [0.0, 0.0, ARENA_SIDE_M, ARENA_SIDE_M], "tag_height_m": TAG_HEIGHT_M},
        )
    if name == "cylinders":
        world, waypoints = cylinder_world()
        return Scenario(
            name, world, waypoints, 3, _ARENA_MOTION, _ARENA_ODOMETRY, _KINECT,
            {"landmark_colours": list(CYLINDER_COLOURS), "room_m": [0.0, 0.0, 5.0, 5.0], "camera": "Kinect v1"},
        )
    if name == "clutter":
        room, world, waypoints = clutter_scenario_world()
        return Scenario(
            name, world, waypoints, 2, _ARENA_MOTION, _ARENA_ODOMETRY, _CLUTTER_CAMERA,
            {"room_m": [0.0, 0.0, *room.room_m], "tag_height_m": TAG_HEIGHT_M,
             "world": f"slamio.clutter.clutter_world({CLUTTER_WORLD_SEED}) kept off the loop",
             "occlusion": "tags hidden behind walls, boxes and cylinders are not seen"},
        )
    return Scenario(
        name, World(grid_landmarks_xy(n_landmarks, grid_spacing_m)), grid_path(n_landmarks, grid_spacing_m), 2,
        _GRID_MOTION, _GRID_ODOMETRY, _GRID_SENSOR,
        {"grid_spacing_m": grid_spacing_m},
    )

