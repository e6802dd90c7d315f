"""fgslam.linearized: the whitened Jacobian in a fill-reducing column order holds the same
least-squares problem as GTSAM's own column order (keys ascending), and the hat traces read
from it equal the exact ones."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest
import scipy.sparse as sp

from fgslam.linearized import fill_reducing_columns, whitened_system
from slamio.noise.fit_self import hat_traces


def small_slam_graph(poses=12, landmarks=5, seed=4):
    """A planar pose chain with a prior, odometry and bearing-range sightings, at a perturbed
    estimate (non-zero residuals)."""
    rng = np.random.default_rng(seed)
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    X, L = (lambda i: gtsam.symbol("x", i)), (lambda j: gtsam.symbol("l", j))
    graph.add(gtsam.PriorFactorPose2(X(0), gtsam.Pose2(), gtsam.noiseModel.Isotropic.Sigma(3, 0.01)))
    odometry = gtsam.noiseModel.Diagonal.Sigmas(np.array([0.05, 0.05, 0.02]))
    sighting = gtsam.noiseModel.Diagonal.Sigmas(np.array([0.03, 0.1]))
    marks = rng.uniform(-3.0, 3.0, size=(landmarks, 2))
    for i in range(poses):
        values.insert(X(i), gtsam.Pose2(0.5 * i + rng.normal(0, 0.05), rng.normal(0, 0.05), rng.normal(0, 0.02)))
        if i:
            graph.add(gtsam.BetweenFactorPose2(X(i - 1), X(i), gtsam.Pose2(0.5, 0.0, 0.0), odometry))
        for j, (x, y) in enumerate(marks):
            pose = gtsam.Pose2(0.5 * i, 0.0, 0.0)
            graph.add(gtsam.BearingRangeFactor2D(X(i), L(j), pose.bearing(gtsam.Point2(x, y)),
                                                 pose.range(gtsam.Point2(x, y)), sighting))
    for j, (x, y) in enumerate(marks):
        values.insert(L(j), gtsam.Point2(x + rng.normal(0, 0.1), y + rng.normal(0, 0.1)))
    return graph, values


def gtsam_order_jacobian(graph, values) -> np.ndarray:
    """The whitened Jacobian in GTSAM's own column order (keys ascending), dense."""
    A, _ = graph.linearize(values).jacobian()
    return A


def test_the_columns_are_a_permutation_of_gtsams_order():
    graph, values = small_slam_graph()
    columns = fill_reducing_columns(graph, values)
    assert sorted(columns.tolist()) == list(range(12 * 3 + 5 * 2))
    A, b = whitened_system(graph, values)
    reference, reference_b = graph.linearize(values).jacobian()
    assert A.toarray() == pytest.approx(reference[:, columns], abs=1e-12)
    assert b == pytest.approx(reference_b, abs=1e-12)


def test_hat_traces_in_the_fill_reducing_order_are_the_exact_ones():
    graph, values = small_slam_graph()
    A, _ = whitened_system(graph, values)
    dense = gtsam_order_jacobian(graph, values)  # a different column order: the same projection
    exact = np.einsum("ij,ji->i", dense, np.linalg.solve(dense.T @ dense, dense.T))
    groups = np.zeros((A.shape[0], 2))
    groups[: A.shape[0] // 2, 0] = 1.0
    groups[A.shape[0] // 2:, 1] = 1.0
    ordered = hat_traces(sp.csr_matrix(A), groups, probes=4000, columns_ordered=True)
    assert ordered == pytest.approx(groups.T @ exact, rel=0.05)
    # the same probes through SuperLU's own ordering give the same numbers to rounding
    assert hat_traces(sp.csr_matrix(A), groups, probes=4000) == pytest.approx(ordered, rel=1e-9)


def test_variables_held_by_priors_alone_are_ordered_without_crashing_metis():
    # a landmark's height with priors and no factor joining it to another variable (the
    # cylinders scenario): GTSAM's METIS crashes on such a variable, so it is placed last
    graph, values = small_slam_graph(poses=4, landmarks=2)
    height = gtsam.symbol("h", 0)
    values.insert(height, 0.4)
    for reading in (0.38, 0.43):
        graph.add(gtsam.PriorFactorDouble(height, reading, gtsam.noiseModel.Isotropic.Sigma(1, 0.02)))
    columns = fill_reducing_columns(graph, values)
    n = values.dim()
    assert sorted(columns.tolist()) == list(range(n))
    A, _ = whitened_system(graph, values)
    reference, _ = graph.linearize(values).jacobian()
    assert A.toarray() == pytest.approx(reference[:, columns], abs=1e-12)


def test_a_graph_of_one_variable_has_its_columns():
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    values.insert(gtsam.symbol("x", 0), gtsam.Pose2())
    graph.add(gtsam.PriorFactorPose2(gtsam.symbol("x", 0), gtsam.Pose2(), gtsam.noiseModel.Isotropic.Sigma(3, 0.1)))
    assert fill_reducing_columns(graph, values).tolist() == [0, 1, 2]
