"""Obstacles on the floor, in 2-D: what blocks the robot and the range sensors.

A world's obstacles are vertical walls (line segments: a room's walls, the four sides of a
box) and vertical cylinders (circles), each with a height above the floor. Everything here
is pure geometry on them, the same for the simulated robot, the simulated camera and laser,
and the navigators' tests:

* :func:`ray_cast_m` — distance along rays from a point to the first obstacle (a laser's
  truth, and the truth a depth-image scan is checked against); :func:`line_of_sight` — is a
  point (a landmark) hidden behind an obstacle;
* :func:`disc_contacts` / :func:`push_disc_out` — the robot's disc against the obstacles:
  where it touches (for the bumper) and where it ends up when a move would enter one (it
  slides along, as the simulated Create does along the arena's walls);
* :func:`box_segments`, :func:`room_segments` — a box or a room as wall segments.

Coordinates are metres in the world frame; angles radians, counter-clockwise from +x.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

__all__ = ["Obstacles", "box_segments", "room_segments", "ray_cast_m", "line_of_sight", "disc_contacts",
           "push_disc_out", "clearance_m"]


def _array(rows, width: int) -> np.ndarray:
    return np.asarray(rows, dtype=float).reshape(-1, width)


@dataclass(frozen=True)
class Obstacles:
    """Vertical walls and cylinders standing on the floor.

    ``segments_m``: (n, 4) rows ``x0, y0, x1, y1``; ``circles_m``: (m, 3) rows ``x, y, radius``;
    ``segment_heights_m`` / ``circle_heights_m``: how tall each is (a camera sees over a low
    box; the robot bumps into anything standing on the floor).
    """

    segments_m: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    circles_m: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    segment_heights_m: np.ndarray | None = None
    circle_heights_m: np.ndarray | None = None

    def __post_init__(self):
        segments, circles = _array(self.segments_m, 4), _array(self.circles_m, 3)
        object.__setattr__(self, "segments_m", segments)
        object.__setattr__(self, "circles_m", circles)
        for name, rows in (("segment_heights_m", segments), ("circle_heights_m", circles)):
            heights = getattr(self, name)
            heights = np.full(len(rows), 1.0) if heights is None else np.asarray(heights, dtype=float).reshape(-1)
            if len(heights) != len(rows):
                raise ValueError(f"{name}: {len(heights)} heights for {len(rows)} obstacles")
            object.__setattr__(self, name, heights)
        if np.any(circles[:, 2] <= 0):
            raise ValueError("circles_m: every radius must be > 0")

    def __add__(self, other: "Obstacles") -> "Obstacles":
        return Obstacles(np.vstack([self.segments_m, other.segments_m]), np.vstack([self.circles_m, other.circles_m]),
                         np.concatenate([self.segment_heights_m, other.segment_heights_m]),
                         np.concatenate([self.circle_heights_m, other.circle_heights_m]))

    @property
    def empty(self) -> bool:
        return len(self.segments_m) == 0 and len(self.circles_m) == 0


def box_segments(centre_xy, size_xy, yaw_rad: float = 0.0) -> np.ndarray:
    """The four sides (4, 4) of a box of ``size_xy`` (length, width) centred at ``centre_xy``
    and turned by ``yaw_rad``."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    hx, hy = 0.5 * size_xy[0], 0.5 * size_xy[1]
    corners = np.array([[hx, hy], [-hx, hy], [-hx, -hy], [hx, -hy]]) @ np.array([[c, s], [-s, c]])
    corners += np.asarray(centre_xy, dtype=float)
    return np.hstack([corners, np.roll(corners, -1, axis=0)])


def room_segments(width_m: float, height_m: float, origin_xy=(0.0, 0.0)) -> np.ndarray:
    """The four walls (4, 4) of a ``width_m`` × ``height_m`` room with a corner at ``origin_xy``."""
    return box_segments((origin_xy[0] + 0.5 * width_m, origin_xy[1] + 0.5 * height_m), (width_m, height_m))


# --------------------------------------------------------------------------- rays


def _segment_hits(origin, dirs, segments) -> np.ndarray:
    """(rays, segments) distance along each unit ray to each segment, inf where it misses."""
    if len(segments) == 0:
        return np.full((len(dirs), 0), np.inf)
    p0, edge = segments[:, :2], segments[:, 2:] - segments[:, :2]
    offset = p0 - origin  # (s, 2)
    # origin + t·d = p0 + u·e  →  t·d − u·e = offset; Cramer's rule with cross products
    denom = dirs[:, None, 0] * (-edge[None, :, 1]) - dirs[:, None, 1] * (-edge[None, :, 0])
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (offset[None, :, 0] * (-edge[None, :, 1]) - offset[None, :, 1] * (-edge[None, :, 0])) / denom
        u = (dirs[:, None, 0] * offset[None, :, 1] - dirs[:, None, 1] * offset[None, :, 0]) / denom
    hit = (np.abs(denom) > 1e-12) & (t >= 0) & (u >= 0) & (u <= 1)
    return np.where(hit, t, np.inf)


def _circle_hits(origin, dirs, circles) -> np.ndarray:
    """(rays, circles) distance along each unit ray to each circle's near side, inf where it
    misses (a ray starting inside a circle hits it at 0)."""
    if len(circles) == 0:
        return np.full((len(dirs), 0), np.inf)
    offset = origin - circles[:, :2]  # (c, 2)
    b = dirs @ offset.T  # (rays, c): d·(o − c)
    c = np.sum(offset**2, axis=1) - circles[:, 2] ** 2  # (c,)
    disc = b**2 - c[None, :]
    with np.errstate(invalid="ignore"):
        t = -b - np.sqrt(disc)
    inside = c[None, :] <= 0
    t = np.where(inside, 0.0, t)
    return np.where((disc >= 0) & (t >= 0), t, np.inf)


def ray_cast_m(obstacles: Obstacles, origin_xy, angles_rad, max_range_m: float = math.inf,
               min_height_m: float = 0.0) -> np.ndarray:
    """Distance from ``origin_xy`` along each world-frame angle to the first obstacle at least
    ``min_height_m`` tall; ``inf`` where nothing is hit within ``max_range_m``."""
    angles = np.atleast_1d(np.asarray(angles_rad, dtype=float))
    origin = np.asarray(origin_xy, dtype=float)
    dirs = np.column_stack([np.cos(angles), np.sin(angles)])
    tall_segments = obstacles.segments_m[obstacles.segment_heights_m >= min_height_m]
    tall_circles = obstacles.circles_m[obstacles.circle_heights_m >= min_height_m]
    hits = np.hstack([_segment_hits(origin, dirs, tall_segments), _circle_hits(origin, dirs, tall_circles)])
    nearest = hits.min(axis=1) if hits.shape[1] else np.full(len(dirs), np.inf)
    return np.where(nearest <= max_range_m, nearest, np.inf)


def line_of_sight(obstacles: Obstacles, from_xy, to_xy, min_height_m: float = 0.0) -> bool:
    """True when no obstacle at least ``min_height_m`` tall stands between the two points
    (a landmark on an obstacle's face is seen: the hit must come before the point itself)."""
    offset = np.asarray(to_xy, dtype=float) - np.asarray(from_xy, dtype=float)
    distance = float(np.hypot(*offset))
    if distance == 0.0:
        return True
    hit = ray_cast_m(obstacles, from_xy, [math.atan2(offset[1], offset[0])], min_height_m=min_height_m)[0]
    return bool(hit >= distance - 1e-6)


# --------------------------------------------------------------------------- the robot's disc


def _nearest_points(obstacles: Obstacles, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each obstacle the point of it nearest ``xy`` (k, 2) and that point's distance (k,)."""
    segments = obstacles.segments_m
    p0, edge = segments[:, :2], segments[:, 2:] - segments[:, :2]
    length2 = np.maximum(np.sum(edge**2, axis=1), 1e-18)
    u = np.clip(np.sum((xy - p0) * edge, axis=1) / length2, 0.0, 1.0)
    on_segments = p0 + u[:, None] * edge
    circles = obstacles.circles_m
    away = xy - circles[:, :2]
    norm = np.maximum(np.linalg.norm(away, axis=1), 1e-12)
    on_circles = circles[:, :2] + away * (circles[:, 2] / norm)[:, None]
    inside = np.linalg.norm(away, axis=1) < circles[:, 2]
    points = np.vstack([on_segments, on_circles])
    distance = np.linalg.norm(points - xy, axis=1)
    distance[len(segments):][inside] *= -1.0  # a centre inside a cylinder: negative clearance
    return points, distance


def clearance_m(obstacles: Obstacles, xy) -> float:
    """Distance from ``xy`` to the nearest obstacle (negative inside a cylinder; inf if none)."""
    if obstacles.empty:
        return math.inf
    return float(_nearest_points(obstacles, np.asarray(xy, dtype=float))[1].min())


def disc_contacts(obstacles: Obstacles, xy, radius_m: float, tolerance_m: float = 1e-3) -> np.ndarray:
    """World-frame directions (radians) from the disc's centre to every obstacle it touches
    (within ``tolerance_m``): what presses the bumper."""
    if obstacles.empty:
        return np.zeros(0)
    xy = np.asarray(xy, dtype=float)
    points, distance = _nearest_points(obstacles, xy)
    touching = distance <= radius_m + tolerance_m
    towards = points[touching] - xy
    return np.arctan2(towards[:, 1], towards[:, 0])


def push_disc_out(obstacles: Obstacles, xy, radius_m: float, iterations: int = 4) -> tuple[float, float]:
    """The nearest place to ``xy`` where a disc of ``radius_m`` overlaps no obstacle: each
    overlap is undone along its normal, a few rounds for corners, so a disc driven into a wall
    slides along it."""
    xy = np.asarray(xy, dtype=float).copy()
    if obstacles.empty:
        return float(xy[0]), float(xy[1])
    for _ in range(iterations):
        points, distance = _nearest_points(obstacles, xy)
        overlap = radius_m - distance
        worst = int(np.argmax(overlap))
        if overlap[worst] <= 0:
            break
        normal = xy - points[worst]
        norm = np.linalg.norm(normal)
        if distance[worst] < 0:  # centre inside a cylinder: out through the near side
            normal = -normal
        normal = normal / norm if norm > 1e-12 else np.array([1.0, 0.0])
        xy = xy + normal * overlap[worst]
    return float(xy[0]), float(xy[1])
