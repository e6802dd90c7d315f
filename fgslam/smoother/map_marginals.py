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

The joint is dense, so its cost grows as the cube of the map's dimension, and with the
landmarks last every pose's clique carries the landmarks seen both before and after it: it
pays only where the per-landmark queries cost most, a map of :data:`MIN_JOINT_LANDMARKS` or
more landmarks and at most :data:`MAX_JOINT_DIMS` dimensions. Otherwise (or when the joint
cannot be formed) the marginals come from :func:`whole_graph_bayes_tree`: ``Marginals``'
own elimination, bit for bit, without computing its COLAMD ordering again.
"""

from __future__ import annotations

import gtsam
import numpy as np
import scipy.linalg
from gtsam.symbol_shorthand import L, T

#: Largest map (landmark dimensions: 2 a point, 3 a tag) whose covariances are taken from one
#: dense joint; a larger one goes through the Bayes tree's per-landmark queries (measured on
#: simulated grids, the joint against ``Marginals``: 500 landmarks 213 against 382 ms, 1 000
#: 868 against 903 ms, 2 000 5.5 against 2.4 s).
MAX_JOINT_DIMS = 1200
#: Fewest landmarks whose covariances are taken from one joint: below, the Bayes tree's
#: queries are cheap and the joint's wider cliques are not (MRCLAM's 15 landmarks: the same
#: CPU to ±10 %; Victoria Park's 151: 71 against 143 ms, docs/performance.md).
MIN_JOINT_LANDMARKS = 50


def whole_graph_bayes_tree(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values,
                           ordering: gtsam.Ordering | None = None) -> gtsam.GaussianBayesTree:
    """``graph`` linearised at ``values`` and eliminated in ``ordering`` (default: its COLAMD
    ordering): what ``gtsam.Marginals(graph, values)`` builds (the same COLAMD ordering and
    elimination, so its ``marginalCovariance`` gives the same bits), without the ordering's
    cost when the caller has it (the final Gauss–Newton steps eliminated in it)."""
    return graph.linearize(values).eliminateMultifrontal(graph.orderingCOLAMD() if ordering is None else ordering)


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
                     tag_ids, max_dims: int = MAX_JOINT_DIMS, min_landmarks: int = MIN_JOINT_LANDMARKS) -> JointBlocks | None:
    """:class:`JointBlocks` of every landmark's joint covariance at ``values``
    (:func:`landmark_joint_covariance`); None when the map has fewer than ``min_landmarks``,
    more than ``max_dims`` dimensions, or its joint cannot be formed (the caller then asks
    :func:`whole_graph_bayes_tree`, which says why)."""
    keys, dims = landmark_keys(landmark_ids, tag_ids)
    if not keys or len(keys) < min_landmarks or sum(dims) > max_dims:
        return None
    try:
        return JointBlocks(keys, dims, landmark_joint_covariance(graph, values, keys, dims))
    except (RuntimeError, np.linalg.LinAlgError):
        return None
