"""The map's covariances after a run (fgslam/smoother/map_marginals.py): the whole graph's
Bayes tree in the final Gauss–Newton steps' ordering, or, for a map of many landmarks, every
landmark's block of the landmarks' joint covariance, the poses eliminated first.

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
from fgslam.smoother.online import landmark_covariances
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
    assert map_joint_blocks(graph, values, [4, 7], {7}, min_landmarks=1) is not None
    assert map_joint_blocks(graph, values, [4, 7], {7}) is None  # fewer than MIN_JOINT_LANDMARKS
    assert map_joint_blocks(graph, values, [4, 7], {7}, max_dims=4, min_landmarks=1) is None  # 5 dimensions
    assert map_joint_blocks(graph, values, [], set(), min_landmarks=0) is None
    values.insert(L(9), gtsam.Point2(0.0, 5.0))  # a landmark no factor constrains
    graph.add(gtsam.RangeFactor2D(X(0), L(9), 5.0, gtsam.noiseModel.Isotropic.Sigma(1, 0.1)))  # range only: rank 1
    assert map_joint_blocks(graph, values, [4, 7, 9], {7}, min_landmarks=1) is None


@pytest.fixture(scope="module", params=[False, True], ids=["points", "tags"])
def finished(request):
    header, records = simulate("arena-octagon", 3, laps=1)
    smoother = run_smoother(header, group_steps(header, records), tags=request.param)
    return smoother, request.param


def _reference(smoother, tags):
    """What ``landmark_covariances`` returned before: ``gtsam.Marginals`` at the final
    estimate, a tag's position block rotated into the world frame."""
    marginals = gtsam.Marginals(smoother.graph(), smoother.estimate())
    out = {}
    for lid in smoother.landmarks():
        if tags:
            theta = smoother.estimate().atPose2(T(lid)).theta()
            rot = np.array([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]])
            out[lid] = rot @ marginals.marginalCovariance(T(lid))[:2, :2] @ rot.T
        else:
            out[lid] = marginals.marginalCovariance(L(lid))
    return out


def test_a_small_map_s_covariances_are_marginals_bit_for_bit(finished):
    """Eight landmarks: the Bayes tree in the final Gauss–Newton steps' ordering, which is
    the graph's COLAMD ordering, so ``Marginals``' own numbers."""
    smoother, tags = finished
    ordering, colamd = smoother._final_ordering, smoother.graph().orderingCOLAMD()
    assert [ordering.at(i) for i in range(ordering.size())] == [colamd.at(i) for i in range(colamd.size())]
    covariances = smoother.landmark_covariances()
    assert smoother._final_map is False  # too few landmarks for the joint
    reference = _reference(smoother, tags)
    assert covariances and set(covariances) == set(reference)
    for lid, cov in covariances.items():
        assert np.array_equal(cov, reference[lid])
    pose = X(smoother.num_poses - 1)
    assert np.array_equal(smoother._marginals().marginalCovariance(pose),
                          gtsam.Marginals(smoother.graph(), smoother.estimate()).marginalCovariance(pose))


def test_the_joint_of_a_finished_run_s_map_is_its_marginals(finished):
    """The joint path on the same graph (taken here for eight landmarks), to a relative 1e-9."""
    smoother, tags = finished
    blocks = map_joint_blocks(smoother.graph(), smoother.estimate(), smoother._landmarks.ids,
                              smoother._landmarks.tag_ids, min_landmarks=1)
    assert blocks is not None
    covariances = landmark_covariances(blocks, smoother.estimate(), smoother._landmarks.ids, smoother._landmarks.tag_ids)
    reference = _reference(smoother, tags)
    for lid, cov in covariances.items():
        assert np.allclose(cov, reference[lid], rtol=1e-9, atol=1e-15)
        assert tags or np.array_equal(cov, cov.T)  # a point's block of the symmetrised joint
