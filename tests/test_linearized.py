"""fgslam.linearized: the whitened Jacobian in a fill-reducing column order holds the same
least-squares problem as GTSAM's own column order (keys ascending), the hat traces read
from it equal the exact ones, and GTSAM's Cholesky factor of its normal equations solves them
as numpy does."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest
import scipy.sparse as sp

from fgslam.linearized import fill_reducing_columns, normal_cholesky, whitened_system
from slamio.noise.errors import NoiseModelError
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


def test_gtsams_cholesky_factor_solves_the_normal_equations():
    """normal_cholesky's R (from GTSAM's elimination, in the fill-reducing order) is the
    Cholesky factor of AᵀA of whitened_system's A: RᵀR = AᵀA, and its solve is numpy's."""
    graph, values = small_slam_graph()
    A, _ = whitened_system(graph, values)
    factor = normal_cholesky(graph, values)
    N = (A.T @ A).toarray()
    W = np.random.default_rng(3).standard_normal((A.shape[1], 5))
    assert factor.solve(W) == pytest.approx(np.linalg.solve(N, W), rel=1e-9, abs=1e-12)
    assert factor.solve(W[:, 0]) == pytest.approx(np.linalg.solve(N, W[:, 0]), rel=1e-9, abs=1e-12)
    R = np.linalg.cholesky(N).T  # the unique upper factor with a positive diagonal: GTSAM's, up to row signs
    ours = factor._unit.toarray() * np.sqrt(factor._pivots)[:, None]
    assert np.abs(ours) == pytest.approx(np.abs(R), abs=1e-9 * np.abs(R).max())


def test_hat_traces_from_gtsams_factor_are_superlus():
    graph, values = small_slam_graph()
    A, _ = whitened_system(graph, values)
    groups = np.zeros((A.shape[0], 2))
    groups[: A.shape[0] // 3, 0] = 1.0
    groups[A.shape[0] // 3:, 1] = 1.0
    superlu = hat_traces(A, groups, columns_ordered=True)
    assert hat_traces(A, groups, factor=normal_cholesky(graph, values)) == pytest.approx(superlu, rel=1e-10)


def test_gtsams_factor_of_a_graph_with_a_variable_held_by_priors_alone():
    graph, values = small_slam_graph(poses=4, landmarks=2)
    height = gtsam.symbol("h", 0)
    values.insert(height, 0.4)
    graph.add(gtsam.PriorFactorDouble(height, 0.38, gtsam.noiseModel.Isotropic.Sigma(1, 0.02)))
    A, _ = whitened_system(graph, values)
    W = np.eye(A.shape[1])
    assert normal_cholesky(graph, values).solve(W) == pytest.approx(np.linalg.inv((A.T @ A).toarray()), rel=1e-8,
                                                                   abs=1e-12)


def test_a_variable_no_factor_fixes_is_a_noise_model_error():
    graph, values = small_slam_graph(poses=3, landmarks=1)
    lonely = gtsam.symbol("l", 9)  # a landmark seen once, by bearing alone: its range is free
    values.insert(lonely, gtsam.Point2(3.0, 1.0))
    graph.add(gtsam.BearingFactor2D(gtsam.symbol("x", 0), lonely, gtsam.Rot2(0.3),
                                    gtsam.noiseModel.Isotropic.Sigma(1, 0.01)))
    with pytest.raises(NoiseModelError):
        normal_cholesky(graph, values)


def test_the_verdict_through_gtsams_factor_is_superlus(monkeypatch):
    """Above SUPERLU_MAX_NONZEROS the verdict factorises AᵀA with GTSAM: the same verdict."""
    import fgslam.verdict as verdict

    graph, values = small_slam_graph()
    small = verdict.graph_verdict(graph, values)
    monkeypatch.setattr(verdict, "SUPERLU_MAX_NONZEROS", 0)
    large = verdict.graph_verdict(graph, values)
    assert small.keys() == large.keys() == {"odometry", "bearing", "range"}
    for group in small:
        assert large[group].redundancy == pytest.approx(small[group].redundancy, rel=1e-10)
        assert large[group].chi2 == small[group].chi2
