"""Frontiers of the occupancy grid: free cells next to unknown ones, grouped into clusters,
one goal per cluster with room for the robot (``explore``'s first kind of goal,
:mod:`fgslam.navigate.explore`), and the clearance map the goals are chosen on."""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from fgslam.navigate.common import ROBOT_RADIUS_M
from fgslam.navigate.inspect import nearest_to_group_middle

__all__ = ["frontier_mask", "clearance_map_m", "frontier_goals", "FREE_BELOW", "OCCUPIED_ABOVE"]

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
    size = np.bincount(which, minlength=count + 1)
    roomy = (clearance_m[rows, cols] >= room_m) & (size[which] >= min_cells)
    if not roomy.any():
        return []
    # the roomy cell nearest the middle of its whole cluster
    pick = nearest_to_group_middle(rows[roomy], cols[roomy], which[roomy], rows, cols, which)
    r, c, k = rows[roomy][pick], cols[roomy][pick], which[roomy][pick]
    return [(int(a), int(b), int(size[g])) for a, b, g in zip(r, c, k)]
