"""The map's covariances after a run (fgslam/smoother/map_marginals.py): every landmark's block
of the landmarks' joint covariance, the poses eliminated first.

References: the inverse of the whole graph's dense information matrix (numpy), and
``gtsam.Marginals`` built independently on the same graph and estimate (what
``landmark_covariances`` returned before).
"""

from __future__ import annotations

import math

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import L, T, X

from builders import run_smoother
from fgslam.smoother.map_marginals import (JointBlocks, landmark_joint_covariance, landmark_keys,
                                           map_joint_blocks)
from slamio.log import group_steps
from slamio.sim import simulate


def _small_graph():
    """Three poses on a line, a point landmark seen by range and bearing from each and a
    tag (Pose2 landmark) seen as a relative pose from two."""
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    poses = [gtsam.Pose2(i, 0.1 * i, 0.05 * i) for i in range(3)]
    graph.add(gtsam.PriorFactorPose2(X(0), poses[0], gtsam.noiseModel.Diagonal.Sigmas([0.01, 0.01, 0.005])))
    odometry = gtsam.noiseModel.Diagonal.Sigmas([0.05, 0.02, 0.01])
    for i in range(2):
        graph.add(gtsam.BetweenFactorPose2(X(i), X(i + 1), poses[i].between(poses[i + 1]), odometry))
    point, tag = gtsam.Point2(1.5, 2.0), gtsam.Pose2(2.5, -1.0, 0.7)
    reading = gtsam.noiseModel.Diagonal.Sigmas([0.03, 0.1])
    for i, pose in enumerate(poses):
        graph.add(gtsam.BearingRangeFactor2D(X(i), L(4), pose.bearing(point), pose.range(point), reading))
        values.insert(X(i), pose)
    for i in (1, 2):
        graph.add(gtsam.BetweenFactorPose2(X(i), T(7), poses[i].between(tag),
                                           gtsam.noiseModel.Diagonal.Sigmas([0.04, 0.04, 0.02])))
    values.insert(L(4), point)
    values.insert(T(7), tag)
    return graph, values


def test_the_joint_is_the_dense_inverse_of_the_whole_information():
    graph, values = _small_graph()
    keys, dims = landmark_keys([4, 7], {7})
    assert keys == [L(4), T(7)] and dims == [2, 3]
    joint = landmark_joint_covariance(graph, values, keys, dims)
    ordering = gtsam.Ordering([X(0), X(1), X(2), L(4), T(7)])
    information = graph.linearize(values).augmentedHessian(ordering)[:-1, :-1]
    expected = np.linalg.inv(information)[9:, 9:]  # the landmarks' rows and columns, in order
    assert np.allclose(joint, expected, rtol=1e-10, atol=1e-14)
    blocks = JointBlocks(keys, dims, joint)
    marginals = gtsam.Marginals(graph, values)
    assert np.allclose(blocks.marginalCovariance(L(4)), marginals.marginalCovariance(L(4)), rtol=1e-10, atol=1e-14)
    assert np.allclose(blocks.marginalCovariance(T(7)), marginals.marginalCovariance(T(7)), rtol=1e-10, atol=1e-14)


def test_a_map_too_large_or_singular_is_left_to_marginals():
    graph, values = _small_graph()
    assert map_joint_blocks(graph, values, [4, 7], {7}, max_dims=4) is None  # 5 dimensions
    assert map_joint_blocks(graph, values, [], set()) is None
    values.insert(L(9), gtsam.Point2(0.0, 5.0))  # a landmark no factor constrains
    graph.add(gtsam.RangeFactor2D(X(0), L(9), 5.0, gtsam.noiseModel.Isotropic.Sigma(1, 0.1)))  # range only: rank 1
    assert map_joint_blocks(graph, values, [4, 7, 9], {7}) is None


@pytest.mark.parametrize("tags", [False, True])
def test_a_finished_run_s_map_covariances_are_the_whole_graph_s_marginals(tags):
    """What ``landmark_covariances`` returned before (``gtsam.Marginals`` at the final estimate,
    a tag's position block rotated into the world frame), to a relative 1e-9."""
    header, records = simulate("arena-octagon", 3, laps=1)
    smoother = run_smoother(header, group_steps(header, records), tags=tags)
    covariances = smoother.landmark_covariances()
    assert smoother._final_map is not None  # the joint answered, not Marginals
    marginals = gtsam.Marginals(smoother.graph(), smoother.estimate())
    assert covariances and set(covariances) == set(smoother.landmarks())
    for lid, cov in covariances.items():
        if tags:
            theta = smoother.estimate().atPose2(T(lid)).theta()
            rot = np.array([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]])
            expected = rot @ marginals.marginalCovariance(T(lid))[:2, :2] @ rot.T
        else:
            expected = marginals.marginalCovariance(L(lid))
        assert np.allclose(cov, expected, rtol=1e-9, atol=1e-15)
        assert tags or np.array_equal(cov, cov.T)  # a point's block of the symmetrised joint
