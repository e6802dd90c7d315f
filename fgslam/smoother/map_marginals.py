"""The map's covariances after the run: every landmark's marginal at the final estimate, from
one partial elimination of the whole graph with the landmarks eliminated last.

What :meth:`~fgslam.smoother.isam2.Isam2Smoother.landmark_covariances` answers after
:meth:`~fgslam.smoother.isam2.Isam2Smoother.finish`: the final estimate is the Gauss–Newton
steps' (past iSAM2's linearisation point), so the marginals are the whole graph's, linearised
there. ``gtsam.Marginals`` eliminates the whole graph in COLAMD order and then answers each
landmark from its clique, through the cached marginals of the separators up to the root; on
Victoria Park (151 landmarks) those queries cost as much as the elimination. Here the poses
are eliminated with the landmarks constrained last (``GaussianFactorGraph.marginal``, COLAMD
constrained last): what is left is the landmarks' joint information (the Schur complement
of the poses), and one dense inverse of it is every landmark's joint covariance. The same
quantity as ``Marginals``' to rounding: another elimination order, so the last digits differ
(docs/performance.md gives the relative differences measured on each log).

The joint is dense, so its cost grows as the cube of the map's dimension: above
:data:`MAX_JOINT_DIMS` (or when the joint cannot be formed) the caller keeps
``gtsam.Marginals``.
"""

from __future__ import annotations

import gtsam
import numpy as np
import scipy.linalg
from gtsam.symbol_shorthand import L, T

#: Largest map (landmark dimensions: 2 a point, 3 a tag) whose covariances are taken from one
#: dense joint; a larger one goes through ``gtsam.Marginals``' per-landmark queries.
MAX_JOINT_DIMS = 1200


class JointBlocks:
    """``marginalCovariance(key)`` read from one joint covariance: the key's diagonal block
    (what :func:`fgslam.smoother.online.landmark_covariances` asks of a ``gtsam.Marginals``)."""

    def __init__(self, keys: list[int], dims: list[int], joint: np.ndarray) -> None:
        starts = np.concatenate(([0], np.cumsum(dims)[:-1])).astype(int)
        self._at = {key: (int(start), int(start + dim)) for key, start, dim in zip(keys, starts, dims)}
        self.joint = joint

    def marginalCovariance(self, key: int) -> np.ndarray:  # noqa: N802 (GTSAM's name)
        a, b = self._at[key]
        return self.joint[a:b, a:b]


def landmark_keys(landmark_ids, tag_ids) -> tuple[list[int], list[int]]:
    """``(keys, dims)`` of the landmarks ``landmark_ids``: ``T(id)`` (a Pose2, 3) for a tag,
    ``L(id)`` (a Point2, 2) otherwise."""
    keys = [T(lid) if lid in tag_ids else L(lid) for lid in landmark_ids]
    dims = [3 if lid in tag_ids else 2 for lid in landmark_ids]
    return keys, dims


def landmark_joint_covariance(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values,
                              keys: list[int], dims: list[int]) -> np.ndarray:
    """The joint marginal covariance of ``keys`` (blocks in their order, ``dims`` each) of
    ``graph`` linearised at ``values``: the poses eliminated first, then the inverse of what
    is left, the landmarks' joint information (by its Cholesky factor, which also checks that
    it is positive definite). Raises RuntimeError (GTSAM's indeterminate system) or
    ``numpy.linalg.LinAlgError`` when it is singular."""
    marginal = graph.linearize(values).marginal(keys)
    n = int(sum(dims))
    information = marginal.augmentedHessian(gtsam.Ordering(keys))[:n, :n]
    joint = scipy.linalg.cho_solve(scipy.linalg.cho_factor(information, lower=True), np.eye(n))
    return 0.5 * (joint + joint.T)


def map_joint_blocks(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, landmark_ids,
                     tag_ids, max_dims: int = MAX_JOINT_DIMS) -> JointBlocks | None:
    """:class:`JointBlocks` of every landmark's joint covariance at ``values``
    (:func:`landmark_joint_covariance`); None when the map is empty, larger than ``max_dims``
    or its joint cannot be formed (the caller then asks ``gtsam.Marginals``, which says why)."""
    keys, dims = landmark_keys(landmark_ids, tag_ids)
    if not keys or sum(dims) > max_dims:
        return None
    try:
        return JointBlocks(keys, dims, landmark_joint_covariance(graph, values, keys, dims))
    except (RuntimeError, np.linalg.LinAlgError):
        return None
