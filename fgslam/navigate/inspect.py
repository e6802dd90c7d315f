"""Which surfaces the camera has looked at closely enough to read a tag on them.

A tag is read only from its front, within a few metres: a wall or a box face seen from afar
or edge-on is mapped (its cells occupied in the grid) but a tag on it is not read. So
``explore`` keeps, beside the occupancy grid, a mask of the occupied cells that a scan has hit
within ``read_range_m`` at an incidence (the angle between the ray and the surface's normal)
within ``read_incidence_rad`` — *inspected* (:func:`inspected_hits`). The surface's direction
at a hit comes from the scan itself: the line through the hits of the neighbouring bins
(:func:`hit_incidence_rad`); an isolated hit (a thin pole's edge, a box corner) has none and
inspects nothing.

Occupied cells not inspected yet are grouped into tiles of ``tile_m`` (:func:`inspection_targets`);
each tile offers one target, its cell nearest the tile's middle, with the direction of the
free floor around it (the way the surface faces, :func:`free_direction_rad`): a viewpoint
in front of it is where to look from (:func:`landmark_viewpoint`, which finds landmarks'
viewpoints too).
"""

from __future__ import annotations

import math

import numpy as np

from fgslam.navigate.common import ROBOT_RADIUS_M
from slamio.geometry import wrap_angle

__all__ = ["hit_incidence_rad", "inspected_hits", "free_direction_rad", "inspection_targets", "nearest_to_group_middle",
           "grid_sight", "landmark_viewpoint"]


def hit_incidence_rad(scan, scan_pose, max_gap_m: float = 0.08) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(hit points (n, 2) in the map frame, their ranges (n,), their incidence (n,)) for the
    scan's hits. The incidence is the angle between the ray and the normal of the line through
    the neighbouring bins' hits (both sides when both are within ``max_gap_m`` plus the bins'
    spacing of the hit, else the one that is); ``nan`` when neither is."""
    ranges = np.asarray(scan.ranges_m, dtype=float)
    bearing = np.asarray(scan.angles_rad, dtype=float) + scan_pose[2]
    hit = np.isfinite(ranges)
    r = np.where(hit, ranges, np.nan)
    xy = np.column_stack([scan_pose[0] + r * np.cos(bearing), scan_pose[1] + r * np.sin(bearing)])
    step = float(np.median(np.diff(scan.angles_rad))) if len(ranges) > 1 else 0.0
    # neighbours: the previous and the next bin's hit (nan-padded at the fan's ends)
    before = np.vstack([[np.nan, np.nan], xy[:-1]])
    after = np.vstack([xy[1:], [np.nan, np.nan]])
    limit = max_gap_m + 2.0 * np.nan_to_num(r) * step
    near_before = np.hypot(*(xy - before).T) <= limit
    near_after = np.hypot(*(after - xy).T) <= limit
    tangent = np.where((near_before & near_after)[:, None], after - before,
                       np.where(near_after[:, None], after - xy, np.where(near_before[:, None], xy - before, np.nan)))
    length = np.hypot(tangent[:, 0], tangent[:, 1])
    ray = np.column_stack([np.cos(bearing), np.sin(bearing)])
    # |sin(ray, tangent)| = cos(incidence)
    cos_incidence = np.abs(ray[:, 0] * tangent[:, 1] - ray[:, 1] * tangent[:, 0]) / np.where(length > 0, length, np.nan)
    incidence = np.arccos(np.clip(cos_incidence, 0.0, 1.0))
    return xy[hit], ranges[hit], incidence[hit]


def inspected_hits(scan, scan_pose, read_range_m: float, read_incidence_rad: float) -> np.ndarray:
    """The hit points (n, 2) near enough and faced enough to read a tag there (module docstring)."""
    xy, ranges, incidence = hit_incidence_rad(scan, scan_pose)
    ok = (ranges <= read_range_m) & (np.nan_to_num(incidence, nan=math.pi) <= read_incidence_rad)
    return xy[ok]


def free_direction_rad(free: np.ndarray, rows, cols, reach: int = 3) -> np.ndarray:
    """Per cell (``rows``, ``cols`` of the boolean mask ``free``), the direction (radians, x =
    columns, y = rows) of the free cells within ``reach`` cells: the sum of their unit offsets.
    ``nan`` where no free cell is that near."""
    offsets = np.array([(dr, dc) for dr in range(-reach, reach + 1) for dc in range(-reach, reach + 1)
                        if 0 < dr * dr + dc * dc <= reach * reach])
    rr = np.asarray(rows)[:, None] + offsets[None, :, 0]
    cc = np.asarray(cols)[:, None] + offsets[None, :, 1]
    inside = (rr >= 0) & (rr < free.shape[0]) & (cc >= 0) & (cc < free.shape[1])
    is_free = np.zeros(rr.shape, bool)
    is_free[inside] = free[rr[inside], cc[inside]]
    unit = offsets / np.hypot(offsets[:, 0], offsets[:, 1])[:, None]
    dy, dx = is_free.astype(float) @ unit[:, 0], is_free.astype(float) @ unit[:, 1]
    return np.where(is_free.any(axis=1), np.arctan2(dy, dx), np.nan)


def nearest_to_group_middle(rows, cols, group, weights_rows=None, weights_cols=None, group_count=None) -> np.ndarray:
    """Per group (``group``: a label per cell), the index of its cell nearest the group's
    middle — the mean of ``weights_rows`` / ``weights_cols`` with their labels
    ``group_count`` (default: the cells themselves); ties go to the first cell. Returns the
    chosen indices into ``rows`` / ``cols``, one per group present, in label order."""
    rows, cols, group = np.asarray(rows), np.asarray(cols), np.asarray(group)
    if weights_rows is None:
        weights_rows, weights_cols, group_count = rows, cols, group
    size = int(max(group.max(), np.max(group_count)) + 1)
    n = np.bincount(group_count, minlength=size).astype(float)
    middle_r = np.bincount(group_count, weights_rows, minlength=size) / np.maximum(n, 1)
    middle_c = np.bincount(group_count, weights_cols, minlength=size) / np.maximum(n, 1)
    distance = (rows - middle_r[group]) ** 2 + (cols - middle_c[group]) ** 2
    order = np.lexsort((distance, group))
    firsts = np.flatnonzero(np.r_[True, group[order][1:] != group[order][:-1]])
    return order[firsts]


def inspection_targets(occupied: np.ndarray, inspected: np.ndarray, free: np.ndarray, tile_cells: int = 5,
                       min_cells: int = 2) -> list[tuple[int, int, float]]:
    """(row, column, facing) per tile of ``tile_cells`` holding at least ``min_cells``
    occupied cells not inspected (module docstring): the tile's such cell nearest their
    middle, and the direction of the free floor from it (cells with none are left out)."""
    rows, cols = np.nonzero(occupied & ~inspected)
    if len(rows) == 0:
        return []
    tile = (rows // tile_cells) * (occupied.shape[1] // tile_cells + 1) + cols // tile_cells
    _, tile, counts = np.unique(tile, return_inverse=True, return_counts=True)
    keep = counts[tile] >= min_cells
    if not keep.any():
        return []
    rows, cols, tile = rows[keep], cols[keep], tile[keep]
    pick = nearest_to_group_middle(rows, cols, tile)
    rows, cols = rows[pick], cols[pick]
    facing = free_direction_rad(free, rows, cols)
    return [(int(r), int(c), float(f)) for r, c, f in zip(rows, cols, facing) if np.isfinite(f)]


def grid_sight(grid, from_xy, to_xy, stop_short_m: float = 0.15, occupied_above: float = 0.5) -> bool:
    """No occupied cell on the segment (up to ``stop_short_m`` before ``to_xy``, the landmark
    sits on its wall)."""
    offset = np.subtract(to_xy, from_xy)
    length = float(np.hypot(*offset))
    steps = np.arange(0.0, max(length - stop_short_m, 0.0), 0.5 * grid.resolution_m)
    points = np.asarray(from_xy) + steps[:, None] * offset / max(length, 1e-9)
    return not np.any(grid.values_at(points) > occupied_above)


def landmark_viewpoint(grid, clearance_m_at, landmark_xy, robot_xy, distances_m=(1.0, 1.25, 1.5),
                       directions: int = 16, room_m: float = ROBOT_RADIUS_M + 0.12, facing_rad: float | None = None,
                       facing_limit_rad: float = math.radians(40), free_below: float = -0.3) -> tuple[float, float] | None:
    """The viewpoint nearest the robot from which to look at a landmark or a surface: on
    known free floor with ``room_m`` clearance, ``distances_m`` from it, nothing occupied
    between (:func:`grid_sight`);
    ``clearance_m_at(xy)`` gives the clearance at points. With ``facing_rad`` (the direction
    the landmark was seen from), only viewpoints within ``facing_limit_rad`` of it: a tag is
    seen from its front only. ``None`` when there is none."""
    angles = np.arange(directions) * (2 * math.pi / directions)
    if facing_rad is not None:
        angles = angles[np.abs(wrap_angle(angles - facing_rad)) <= facing_limit_rad]
    candidates = np.array([[landmark_xy[0] + d * math.cos(a), landmark_xy[1] + d * math.sin(a)]
                           for d in distances_m for a in angles])
    ok = (grid.values_at(candidates, outside=0.0) < free_below) & (clearance_m_at(candidates) >= room_m)
    candidates = candidates[ok]
    order = np.argsort(np.hypot(candidates[:, 0] - robot_xy[0], candidates[:, 1] - robot_xy[1]))
    for k in order:
        if grid_sight(grid, candidates[k], landmark_xy):
            return float(candidates[k, 0]), float(candidates[k, 1])
    return None
