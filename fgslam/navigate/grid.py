"""A log-odds occupancy grid built from range scans: the navigators' memory of what they saw.

The Kinect sees 57° at a time and a scan is ~0.4 s old when it arrives, so a navigator that
wants a wider view than the newest scan keeps what earlier scans showed: each scan, placed at
the pose it was taken from, lowers the log-odds of the cells its rays crossed (free) and
raises the cell each ray hit (occupied). Freeing is conservative: a cell is freed only when
every ray of the bins it spans went past it (:meth:`OccupancyGrid._seen_past`), so a ray
beside a thin pole or a box's corner seen edge-on, or at the fan's edge, does not free the
cell the obstacle stands in. A ray with no return (``inf``) is free to the scan's
maximum range; an unknown ray (``nan``) changes nothing — unknown stays unknown, and a cell
never crossed keeps log-odds 0 (:meth:`OccupancyGrid.known`).

The grid is square, fixed in the map frame, centred on ``centre_xy``; rays leaving it are cut
at its edge. Each cell is updated at most once per scan (however many rays cross it), as in
Borenstein and Koren's histogram grid.
"""

from __future__ import annotations

import math

import numpy as np

from slamio.scan import Scan

__all__ = ["OccupancyGrid"]


def _range_min(values: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """min(values[lo_i..hi_i]) for each pair (inclusive, lo ≤ hi), by a sparse table."""
    table = [np.asarray(values, dtype=float)]
    while 2 ** len(table) <= len(values):
        previous, width = table[-1], 2 ** (len(table) - 1)
        table.append(np.minimum(previous[:-width], previous[width:]))
    level = np.floor(np.log2(hi - lo + 1)).astype(int)
    out = np.empty(len(lo))
    for k in np.unique(level):
        pick = level == k
        out[pick] = np.minimum(table[k][lo[pick]], table[k][hi[pick] - 2**k + 1])
    return out


class OccupancyGrid:
    """Log-odds per cell, rows = y, columns = x (module docstring)."""

    def __init__(self, half_size_m: float = 10.0, resolution_m: float = 0.1, centre_xy=(0.0, 0.0),
                 hit_log_odds: float = 0.9, free_log_odds: float = -0.4, limit_log_odds: float = 3.5):
        self.resolution_m = float(resolution_m)
        self.cells = int(math.ceil(2 * half_size_m / resolution_m))
        self.origin_xy = (centre_xy[0] - 0.5 * self.cells * resolution_m, centre_xy[1] - 0.5 * self.cells * resolution_m)
        self.log_odds = np.zeros((self.cells, self.cells), dtype=np.float32)
        self.hit, self.free, self.limit = hit_log_odds, free_log_odds, limit_log_odds
        self._footprint = None

    # ------------------------------------------------------------------ coordinates

    def index(self, xy) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(row, column, inside) of map-frame points ``xy`` (n, 2)."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        col = np.floor((xy[:, 0] - self.origin_xy[0]) / self.resolution_m).astype(int)
        row = np.floor((xy[:, 1] - self.origin_xy[1]) / self.resolution_m).astype(int)
        inside = (row >= 0) & (row < self.cells) & (col >= 0) & (col < self.cells)
        return row, col, inside

    def centres(self, row, col) -> np.ndarray:
        """Map-frame centres (n, 2) of cells."""
        return np.column_stack([self.origin_xy[0] + (np.asarray(col) + 0.5) * self.resolution_m,
                                self.origin_xy[1] + (np.asarray(row) + 0.5) * self.resolution_m])

    def values_at(self, xy, outside: float = 0.0) -> np.ndarray:
        """Log-odds at map-frame points (``outside`` for points off the grid)."""
        row, col, inside = self.index(xy)
        values = np.full(len(row), outside, dtype=float)
        values[inside] = self.log_odds[row[inside], col[inside]]
        return values

    # ------------------------------------------------------------------ updates

    def add_scan(self, scan: Scan, scan_pose, free_range_m: float | None = None) -> None:
        """Integrate one scan taken at ``scan_pose`` (module docstring); ``free_range_m``:
        free only the cells that near (hits are marked at any range)."""
        known = scan.known
        if not known.any():
            return
        angles = scan.angles_rad[known] + scan_pose[2]
        ranges = scan.ranges_m[known]
        hit = np.isfinite(ranges)
        free_to = np.where(hit, ranges - 0.5 * self.resolution_m, scan.max_range_m)
        if free_range_m is not None:
            free_to = np.minimum(free_to, free_range_m)
        step = 0.7 * self.resolution_m
        samples = np.arange(0.0, scan.max_range_m + step, step)
        along = samples[None, :] <= free_to[:, None]  # (rays, samples)
        ray, sample = np.nonzero(along)
        distance = samples[sample]
        xy = np.column_stack([scan_pose[0] + distance * np.cos(angles[ray]),
                              scan_pose[1] + distance * np.sin(angles[ray])])
        row, col, inside = self.index(xy)
        flat = np.unique(row[inside] * self.cells + col[inside])
        flat = flat[self._seen_past(flat, scan, scan_pose)]
        grid = self.log_odds.reshape(-1)
        grid[flat] = np.maximum(grid[flat] + self.free, -self.limit)
        if hit.any():
            ends = np.column_stack([scan_pose[0] + ranges[hit] * np.cos(angles[hit]),
                                    scan_pose[1] + ranges[hit] * np.sin(angles[hit])])
            self.mark_occupied(ends)

    def _seen_past(self, flat: np.ndarray, scan: Scan, scan_pose) -> np.ndarray:
        """Which cells (flat indices) every ray through them went past: each ray of the bins
        the cell's disc (half its diagonal) spans from ``scan_pose`` reached beyond it. A ray
        beside a thin obstacle (a pole, a box's corner seen edge-on) crosses its cell without
        freeing it; a cell partly outside the fan is not freed."""
        centre = self.centres(flat // self.cells, flat % self.cells) - np.asarray(scan_pose[:2], dtype=float)
        distance = np.hypot(centre[:, 0], centre[:, 1])
        half_m = self.resolution_m / math.sqrt(2.0)
        angles = scan.angles_rad
        step = (angles[-1] - angles[0]) / max(len(angles) - 1, 1)
        if len(angles) < 2 or step <= 0:
            return np.zeros(len(flat), bool)
        bearing = (np.arctan2(centre[:, 1], centre[:, 0]) - scan_pose[2] + np.pi) % (2 * np.pi) - np.pi
        half = np.arcsin(np.clip(half_m / np.maximum(distance, 1e-9), 0.0, 1.0))
        lo = np.ceil((bearing - half - angles[0]) / step - 1e-9).astype(int)
        hi = np.floor((bearing + half - angles[0]) / step + 1e-9).astype(int)
        nearest = np.rint((bearing - angles[0]) / step).astype(int)
        lo, hi = np.where(lo > hi, nearest, lo), np.where(lo > hi, nearest, hi)
        ok = (distance > half_m) & (lo >= 0) & (hi < len(angles))
        reach = np.where(np.isnan(scan.ranges_m), -1.0, np.where(np.isinf(scan.ranges_m), np.inf, scan.ranges_m))
        return ok & (_range_min(reach, np.clip(lo, 0, len(angles) - 1), np.clip(hi, 0, len(angles) - 1))
                     >= distance + half_m)

    def mark_occupied(self, xy, log_odds: float | None = None) -> None:
        """Raise the cells holding ``xy`` (a hit, or where the bumper was pressed)."""
        row, col, inside = self.index(xy)
        flat = row[inside] * self.cells + col[inside]
        grid = self.log_odds.reshape(-1)
        grid[flat] = np.minimum(grid[flat] + (self.hit if log_odds is None else log_odds), self.limit)

    def clear_footprint(self, xy, radius_m: float) -> None:
        """Mark the unknown cells under the robot's disc at ``xy`` free: the robot stands there
        (a depth camera never sees the floor it stands on, and such pockets would look like
        frontiers). Cells already known keep their value."""
        if self._footprint is None or self._footprint[0] != radius_m:
            reach = int(math.ceil(radius_m / self.resolution_m))
            offsets = np.arange(-reach, reach + 1) * self.resolution_m
            dx, dy = np.meshgrid(offsets, offsets)
            inside = dx**2 + dy**2 <= radius_m**2
            self._footprint = (radius_m, np.column_stack([dx[inside], dy[inside]]))
        row, col, ok = self.index(self._footprint[1] + np.asarray(xy[:2], dtype=float))
        row, col = row[ok], col[ok]
        unknown = self.log_odds[row, col] == 0
        self.log_odds[row[unknown], col[unknown]] = 2 * self.free

    # ------------------------------------------------------------------ queries

    def window(self, xy, radius_m: float) -> tuple[np.ndarray, np.ndarray]:
        """The cells within a square of half-size ``radius_m`` around ``xy``: their map-frame
        centres (n, 2) and log-odds (n,), for the histogram's active window."""
        row, col, _ = self.index([xy])
        reach = int(math.ceil(radius_m / self.resolution_m))
        r0, r1 = max(row[0] - reach, 0), min(row[0] + reach + 1, self.cells)
        c0, c1 = max(col[0] - reach, 0), min(col[0] + reach + 1, self.cells)
        if r0 >= r1 or c0 >= c1:
            return np.zeros((0, 2)), np.zeros(0)
        block = self.log_odds[r0:r1, c0:c1]
        rows, cols = np.nonzero(block > 0)
        return self.centres(rows + r0, cols + c0), block[rows, cols].astype(float)

    def bounds(self, margin: int = 2) -> tuple[slice, slice]:
        """(rows, columns) slices of the smallest block holding every known cell, plus
        ``margin`` cells (an empty block before the first scan)."""
        rows, cols = np.nonzero(np.any(self.log_odds != 0, axis=1))[0], np.nonzero(np.any(self.log_odds != 0, axis=0))[0]
        if len(rows) == 0:
            return slice(0, 0), slice(0, 0)
        return (slice(max(rows[0] - margin, 0), min(rows[-1] + margin + 1, self.cells)),
                slice(max(cols[0] - margin, 0), min(cols[-1] + margin + 1, self.cells)))

    def known(self) -> np.ndarray:
        """True for cells some ray crossed or ended in."""
        return self.log_odds != 0

    def free_mask(self, threshold: float = -0.3) -> np.ndarray:
        return self.log_odds < threshold

    def occupied_mask(self, threshold: float = 0.5) -> np.ndarray:
        return self.log_odds > threshold
