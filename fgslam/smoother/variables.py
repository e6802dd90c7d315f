"""The graph's variables: which landmarks iSAM2 holds, and reading ``gtsam.Values`` back.

Keys (``gtsam.symbol_shorthand``): ``X(i)`` pose *i* (``Pose2``), ``L(id)`` a point landmark
(``Point2``), ``T(id)`` a tag (``Pose2``: centre and facing direction), ``H(id)`` a
landmark's height (a scalar).
"""

from __future__ import annotations

import gtsam
import numpy as np
from gtsam.symbol_shorthand import H, L, T, X


#: A key is its symbol's character in the top 8 bits and its index in the 56 below (gtsam.Symbol).
_INDEX_BITS = 56
_INDEX_MASK = (1 << _INDEX_BITS) - 1
_L, _T = ord("l"), ord("t")


class LandmarkRegistry:
    """The landmarks seen so far: which are in iSAM2, which are tags, which have a height."""

    def __init__(self):
        self.ids: list[int] = []  # landmarks in iSAM2, in order of entry
        self.known: set[int] = set()  # the same, as a set
        self.tag_ids: set[int] = set()  # landmarks in iSAM2 that are tags (Pose2 T(id))
        self.height_ids: set[int] = set()  # landmarks with a height variable H(id) (in iSAM2 or held)
        self._is_tag: dict[int, bool] = {}  # every landmark seen: tag or point (first sight decides)

    def is_tag(self, landmark_id: int, if_new: bool) -> bool:
        """Whether ``landmark_id`` is a tag; the first sighting decides (``if_new``)."""
        return self._is_tag.setdefault(landmark_id, if_new)

    def enter(self, values: gtsam.Values) -> None:
        """Note the landmarks among ``values``, the new variables of an accepted update."""
        for key in values.keys():
            kind = key >> _INDEX_BITS  # gtsam.Symbol(key).chr(), without building the Symbol
            if kind == _L or kind == _T:
                lid = key & _INDEX_MASK  # its index()
                self.known.add(lid)
                self.ids.append(lid)
                if kind == _T:
                    self.tag_ids.add(lid)

    def positions(self, values: gtsam.Values) -> dict[int, tuple[float, float]]:
        """Landmark id → (x_m, y_m) in ``values``, for the landmarks in iSAM2 in order of entry."""
        return landmarks_of(values, self.ids, self.tag_ids)

    def yaws(self, values: gtsam.Values) -> dict[int, float]:
        return yaws_of(values, self.tag_ids)

    def heights(self, values: gtsam.Values) -> dict[int, float]:
        return heights_of(values, self.height_ids)


def poses_of(values: gtsam.Values, n: int) -> np.ndarray:
    """(n, 3): poses ``X(0)`` … ``X(n − 1)`` of ``values`` as (x_m, y_m, theta_rad).

    Read in one call (``gtsam.utilities.extractPose2``: every ``Pose2`` of ``values`` in key
    order, as ``x(), y(), theta()``) when those poses are the last n keys of ``values`` (the
    smoother's other variables, ``H``, ``L`` and ``T``, sort before ``X``), else pose by pose."""
    keys = np.asarray(values.keys(), dtype=np.uint64)
    if len(keys) >= n and np.array_equal(keys[len(keys) - n :], np.uint64(X(0)) + np.arange(n, dtype=np.uint64)):
        rows = np.asarray(gtsam.utilities.extractPose2(values), dtype=float).reshape(-1, 3)
        return rows[len(rows) - n :]
    out = np.empty((n, 3))
    for i in range(n):
        p = values.atPose2(X(i))
        out[i] = (p.x(), p.y(), p.theta())
    return out


def landmarks_of(values: gtsam.Values, ids, tag_ids) -> dict[int, tuple[float, float]]:
    """Landmark id → (x_m, y_m) for ``ids`` (a tag's position is its centre)."""
    out = {}
    for lid in ids:
        if lid in tag_ids:
            pose = values.atPose2(T(lid))
            out[lid] = (pose.x(), pose.y())
        else:
            p = values.atPoint2(L(lid))
            out[lid] = (float(p[0]), float(p[1]))
    return out


def yaws_of(values: gtsam.Values, tag_ids) -> dict[int, float]:
    """Tag id → the world direction its face points to (rad), by id."""
    return {lid: values.atPose2(T(lid)).theta() for lid in sorted(tag_ids)}


def heights_of(values: gtsam.Values, height_ids) -> dict[int, float]:
    """Landmark id → height (m), by id."""
    return {lid: values.atDouble(H(lid)) for lid in sorted(height_ids)}
