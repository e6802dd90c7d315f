"""A cluttered room for the navigators (issue 44): what the robot must find its way through.

:func:`clutter_world` draws, from a seed, a 6 m × 6 m room (walls 2 m tall, a corner at the
origin) with boxes (sides 0.3–1.0 m, any yaw, 0.3–0.8 m tall) and plain cylinders ("pillars",
radius 0.10–0.25 m, 0.3–0.8 m tall) standing on the floor, plus seed 000's red, green and blue
cylinders (0.10 m across, 0.40 / 0.60 / 0.80 m tall, landmark ids 0, 1, 2 as
:data:`slamio.camera.colour.DEFAULT_COLOURS` has them), which are obstacles as well. Every
object keeps a gap of at least 0.6 m to every other and to the walls (their bounding circles
do), so the Create's disc (0.34 m across) can pass between any two; the free space is then
checked on an occupancy grid (:func:`disc_free_grid`: the free cells the disc's centre may
occupy, one connected region) and the world re-drawn if it is not.

Landmarks: seed 004's AprilTags (tag36h11, 0.16 m, centre 0.20 m above the floor) — three
on each wall at 1/4, 1/2 and 3/4 along it, facing into the room (ids 0–11, counter-clockwise
from the south wall's west end), and one on a face of each box that faces open floor
(ids 12…), 5 mm proud of the face — and the colour cylinders.

The robot starts at :attr:`ClutterWorld.start_pose`, at least 0.5 m from every obstacle.
``keep_clear_xy`` (a closed polygon) keeps every object's bounding circle 0.42 m (the robot's
radius and 0.25 m) off a path — the loop ``fgslam sim clutter`` drives; the start is then its
first corner, facing the second.

:meth:`ClutterWorld.scene` is the render :class:`~slamio.camera.render.Scene`: walls and box
sides as :class:`~slamio.camera.render.WallSpec` (they appear in the depth and the colour
image and hide what is behind them; box tops are not drawn, so a camera must not look down
on a box), pillars grey, the colour cylinders in their colours, the tags.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from slamio.obstacles import Obstacles, box_segments, clearance_m, room_segments

__all__ = ["ClutterWorld", "Box", "Pillar", "ColourCylinder", "TagLandmark", "clutter_world", "disc_free_grid",
           "ROOM_M", "ROBOT_RADIUS_M"]

ROOM_M = (6.0, 6.0)
WALL_HEIGHT_M = 2.0
ROBOT_RADIUS_M = 0.17  # the Create's disc
MIN_GAP_M = 0.6
START_CLEARANCE_M = 0.5
PATH_CLEARANCE_M = ROBOT_RADIUS_M + 0.25
BOX_SIDE_M = (0.3, 1.0)
OBJECT_HEIGHT_M = (0.3, 0.8)
PILLAR_RADIUS_M = (0.10, 0.25)
TAG_SIZE_M = 0.16
TAG_HEIGHT_M = 0.20
TAG_PROUD_M = 0.005  # a tag's card stands this far off its face (no depth fight with it)
TAG_FACE_MIN_M = 0.25  # a face narrower than this takes no tag (the card is 0.20 m wide)
WALL_BGR = (168, 176, 184)
BOX_BGR = ((120, 140, 150), (140, 140, 130), (110, 125, 135), (150, 150, 145))
PILLAR_BGR = (128, 128, 128)
DRAW_ATTEMPTS = 300
WORLD_ATTEMPTS = 20


@dataclass(frozen=True)
class Box:
    x_m: float
    y_m: float
    length_m: float
    width_m: float
    yaw_rad: float
    height_m: float

    def segments(self) -> np.ndarray:
        """The four sides, counter-clockwise (:func:`slamio.obstacles.box_segments`)."""
        return box_segments((self.x_m, self.y_m), (self.length_m, self.width_m), self.yaw_rad)

    @property
    def bounding_radius_m(self) -> float:
        return 0.5 * math.hypot(self.length_m, self.width_m)


@dataclass(frozen=True)
class Pillar:
    x_m: float
    y_m: float
    radius_m: float
    height_m: float


@dataclass(frozen=True)
class ColourCylinder:
    name: str
    landmark_id: int
    x_m: float
    y_m: float
    radius_m: float
    height_m: float


@dataclass(frozen=True)
class TagLandmark:
    tag_id: int
    x_m: float
    y_m: float
    yaw_rad: float  # the world direction its face points to
    height_m: float = TAG_HEIGHT_M  # of its centre
    size_m: float = TAG_SIZE_M


@dataclass(frozen=True, eq=False)
class ClutterWorld:
    """A drawn room (module docstring); :attr:`obstacles` block the robot and the sensors."""

    seed: int
    room_m: tuple[float, float]
    boxes: tuple[Box, ...]
    pillars: tuple[Pillar, ...]
    colour_cylinders: tuple[ColourCylinder, ...]
    tags: tuple[TagLandmark, ...]
    start_pose: tuple[float, float, float]
    obstacles: Obstacles = field(init=False)

    def __post_init__(self):
        object.__setattr__(self, "obstacles", _obstacles(self.room_m, self.boxes, self.pillars, self.colour_cylinders))

    def scene(self):
        """The render :class:`~slamio.camera.render.Scene` of the room (module docstring)."""
        from slamio.camera.render import CYLINDER_BGR, CylinderSpec, Scene, TagSpec, WallSpec

        walls = [WallSpec(*row, WALL_HEIGHT_M, WALL_BGR, cull_back=True) for row in room_segments(*self.room_m)]
        for i, box in enumerate(self.boxes):
            colour = BOX_BGR[i % len(BOX_BGR)]
            # sides drawn clockwise: their fronts face out of the box
            walls += [WallSpec(x1, y1, x0, y0, box.height_m, colour, 0.2, cull_back=True)
                      for x0, y0, x1, y1 in box.segments()]
        cylinders = [CylinderSpec(p.x_m, p.y_m, p.radius_m, p.height_m, PILLAR_BGR) for p in self.pillars]
        cylinders += [CylinderSpec(c.x_m, c.y_m, c.radius_m, c.height_m, CYLINDER_BGR[c.name], c.name, c.landmark_id)
                      for c in self.colour_cylinders]
        tags = [TagSpec(t.tag_id, t.x_m, t.y_m, t.height_m, t.yaw_rad, size_m=t.size_m) for t in self.tags]
        return Scene(tags=tuple(tags), cylinders=tuple(cylinders), walls=tuple(walls))

    def tag_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(xy (n, 2), heights (n,), yaws (n,)) of the tags, in id order."""
        tags = sorted(self.tags, key=lambda t: t.tag_id)
        return (np.array([[t.x_m, t.y_m] for t in tags]), np.array([t.height_m for t in tags]),
                np.array([t.yaw_rad for t in tags]))


def _obstacles(room_m, boxes, pillars, colour_cylinders) -> Obstacles:
    segments = [room_segments(*room_m)] + [b.segments() for b in boxes]
    heights = [np.full(4, WALL_HEIGHT_M)] + [np.full(4, b.height_m) for b in boxes]
    circles = [(p.x_m, p.y_m, p.radius_m) for p in pillars] + [(c.x_m, c.y_m, c.radius_m) for c in colour_cylinders]
    circle_heights = [p.height_m for p in pillars] + [c.height_m for c in colour_cylinders]
    return Obstacles(np.vstack(segments), np.array(circles).reshape(-1, 3), np.concatenate(heights),
                     np.array(circle_heights))


# --------------------------------------------------------------------------- the occupancy grid


def _inside_objects(world: ClutterWorld, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Whether each point lies inside a box, a pillar or a colour cylinder, or outside the room."""
    inside = (x < 0) | (y < 0) | (x > world.room_m[0]) | (y > world.room_m[1])
    for b in world.boxes:
        c, s = math.cos(b.yaw_rad), math.sin(b.yaw_rad)
        u = (x - b.x_m) * c + (y - b.y_m) * s
        v = -(x - b.x_m) * s + (y - b.y_m) * c
        inside |= (np.abs(u) <= 0.5 * b.length_m) & (np.abs(v) <= 0.5 * b.width_m)
    for cx, cy, r in world.obstacles.circles_m:
        inside |= (x - cx) ** 2 + (y - cy) ** 2 <= r * r
    return inside


def disc_free_grid(world: ClutterWorld, cell_m: float = 0.05,
                   radius_m: float = ROBOT_RADIUS_M) -> tuple[np.ndarray, float]:
    """Where the robot's centre may be: a boolean grid (rows along y, columns along x; cell
    (i, j) centred at ((j + ½)·cell_m, (i + ½)·cell_m)) that is True where a disc of
    ``radius_m`` there overlaps no obstacle (the occupied cells dilated by the radius, via a
    Euclidean distance transform; a cell more, so a True cell is free for certain)."""
    from scipy.ndimage import distance_transform_edt

    columns, rows = (int(math.ceil(side / cell_m)) for side in world.room_m)
    x = (np.arange(columns) + 0.5) * cell_m
    y = (np.arange(rows) + 0.5) * cell_m
    occupied = _inside_objects(world, x[None, :], y[:, None])
    occupied = np.pad(occupied, 1, constant_values=True)  # the walls around
    distance_m = distance_transform_edt(~occupied) * cell_m
    return (distance_m > radius_m + cell_m)[1:-1, 1:-1], cell_m


def _connected(world: ClutterWorld) -> bool:
    """One connected free region for the disc, which holds the start."""
    from scipy.ndimage import label

    free, cell = disc_free_grid(world)
    labels, count = label(free)
    i, j = int(world.start_pose[1] / cell), int(world.start_pose[0] / cell)
    return count == 1 and bool(labels[i, j])


# --------------------------------------------------------------------------- drawing


def _path_distance_m(xy, path: np.ndarray | None) -> float:
    """Distance from ``xy`` to a closed polygon (inf without one)."""
    if path is None:
        return math.inf
    closed = np.vstack([path, path[:1]])
    return clearance_m(Obstacles(np.hstack([closed[:-1], closed[1:]])), xy)


def _draw_spot(rng, radius_m: float, room_m, placed: list, start_xy, path) -> tuple[float, float] | None:
    """A centre for an object of bounding ``radius_m``: ``MIN_GAP_M`` off the walls and every
    ``placed`` (x, y, radius), clear of the start and the path; None when none was found."""
    low = MIN_GAP_M + radius_m
    for _ in range(DRAW_ATTEMPTS):
        x, y = rng.uniform(low, room_m[0] - low), rng.uniform(low, room_m[1] - low)
        if any(math.hypot(x - px, y - py) < radius_m + pr + MIN_GAP_M for px, py, pr in placed):
            continue
        if math.hypot(x - start_xy[0], y - start_xy[1]) < radius_m + START_CLEARANCE_M:
            continue
        if _path_distance_m((x, y), path) < radius_m + PATH_CLEARANCE_M:
            continue
        return x, y
    return None


def _draw_objects(rng, room_m, start_xy, path):
    """Boxes, pillars and the colour cylinders, in that order (objects that find no spot are left out)."""
    from slamio.camera.colour import DEFAULT_COLOURS

    placed: list[tuple[float, float, float]] = []
    boxes, pillars, colours = [], [], []
    for _ in range(int(rng.integers(5, 9))):
        length, width = rng.uniform(*BOX_SIDE_M, 2)
        yaw, height = rng.uniform(0.0, math.pi), rng.uniform(*OBJECT_HEIGHT_M)
        radius = 0.5 * math.hypot(length, width)
        spot = _draw_spot(rng, radius, room_m, placed, start_xy, path)
        if spot is not None:
            placed.append((*spot, radius))
            boxes.append(Box(spot[0], spot[1], float(length), float(width), float(yaw), float(height)))
    for _ in range(int(rng.integers(2, 5))):
        radius, height = rng.uniform(*PILLAR_RADIUS_M), rng.uniform(*OBJECT_HEIGHT_M)
        spot = _draw_spot(rng, radius, room_m, placed, start_xy, path)
        if spot is not None:
            placed.append((*spot, radius))
            pillars.append(Pillar(spot[0], spot[1], float(radius), float(height)))
    for spec in DEFAULT_COLOURS:
        radius = 0.5 * spec.width_m
        spot = _draw_spot(rng, radius, room_m, placed, start_xy, path)
        if spot is not None:
            placed.append((*spot, radius))
            colours.append(ColourCylinder(spec.name, spec.landmark_id, spot[0], spot[1], radius, spec.height_m))
    return boxes, pillars, colours


def _wall_tags(room_m) -> list[TagLandmark]:
    """Three tags per wall at 1/4, 1/2, 3/4 along it, facing in; ids go counter-clockwise:
    0–2 the south wall (y = 0) west to east, 3–5 east, 6–8 north, 9–11 west."""
    w, h = room_m
    spots = [(a * w, 0.0, 0.5 * math.pi) for a in (0.25, 0.5, 0.75)]
    spots += [(w, a * h, math.pi) for a in (0.25, 0.5, 0.75)]
    spots += [((1.0 - a) * w, h, -0.5 * math.pi) for a in (0.25, 0.5, 0.75)]
    spots += [(0.0, (1.0 - a) * h, 0.0) for a in (0.25, 0.5, 0.75)]
    return [TagLandmark(i, x + TAG_PROUD_M * math.cos(yaw), y + TAG_PROUD_M * math.sin(yaw), yaw)
            for i, (x, y, yaw) in enumerate(spots)]


def _box_tags(rng, boxes: list[Box], obstacles: Obstacles, first_id: int) -> list[TagLandmark]:
    """One tag per box, on a face (drawn in random order) wide enough and facing open floor:
    a point 0.45 m out from its centre clears every obstacle by the robot's radius."""
    tags = []
    for box in boxes:
        for k in rng.permutation(4):
            x0, y0, x1, y1 = box.segments()[k]
            if math.hypot(x1 - x0, y1 - y0) < TAG_FACE_MIN_M:
                continue
            yaw = math.atan2(y1 - y0, x1 - x0) - 0.5 * math.pi  # right of a counter-clockwise side: out
            cx, cy = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
            out = (cx + 0.45 * math.cos(yaw), cy + 0.45 * math.sin(yaw))
            if clearance_m(obstacles, out) < ROBOT_RADIUS_M:
                continue
            tags.append(TagLandmark(first_id + len(tags), cx + TAG_PROUD_M * math.cos(yaw),
                                    cy + TAG_PROUD_M * math.sin(yaw), math.atan2(math.sin(yaw), math.cos(yaw))))
            break
    return tags


def clutter_world(seed: int, *, room_m: tuple[float, float] = ROOM_M,
                  keep_clear_xy: np.ndarray | None = None) -> ClutterWorld:
    """The cluttered room of ``seed`` (module docstring). ``keep_clear_xy``: a closed polygon
    (n, 2) kept free for the robot; the start is then its first corner facing the second."""
    rng = np.random.default_rng(int(seed))
    path = None if keep_clear_xy is None else np.asarray(keep_clear_xy, dtype=float)
    for _ in range(WORLD_ATTEMPTS):
        if path is None:
            start = (*rng.uniform(1.0, np.asarray(room_m) - 1.0), float(rng.uniform(-math.pi, math.pi)))
        else:
            start = (path[0, 0], path[0, 1], math.atan2(path[1, 1] - path[0, 1], path[1, 0] - path[0, 0]))
        start = tuple(float(v) for v in start)
        boxes, pillars, colours = _draw_objects(rng, room_m, start[:2], path)
        bare = ClutterWorld(int(seed), tuple(room_m), tuple(boxes), tuple(pillars), tuple(colours), (), start)
        if not _connected(bare) or clearance_m(bare.obstacles, start[:2]) < START_CLEARANCE_M:
            continue
        tags = _wall_tags(room_m)
        tags += _box_tags(rng, boxes, bare.obstacles, len(tags))
        return ClutterWorld(int(seed), tuple(room_m), tuple(boxes), tuple(pillars), tuple(colours), tuple(tags), start)
    raise RuntimeError(f"clutter_world({seed}): no connected room in {WORLD_ATTEMPTS} draws")
