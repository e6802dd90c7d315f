"""The Gauss–Newton steps that end a smoother run (fgslam/smoother/batch.py) and what
finish() leaves: the batch optimum, and covariances that are the whole graph's marginals
at it.

References: a linear problem's closed-form least-squares solution; GTSAM's
Levenberg–Marquardt run to convergence; ``gtsam.Marginals`` built independently.
"""

from __future__ import annotations

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import L, X

from fgslam.runner import run_estimator
from fgslam.smoother import Isam2Smoother, batch_solve
from fgslam.smoother.batch import gauss_newton_steps
from slamio.log import group_steps
from slamio.sim import simulate


def _bearing_graph(landmark_start):
    """Two fixed poses 1 m apart bear on a landmark at (0.5, 1.0): the bearings are
    strongly nonlinear far from the answer."""
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    truth = gtsam.Point2(0.5, 1.0)
    for i, pose in enumerate([gtsam.Pose2(0, 0, 0), gtsam.Pose2(1, 0, 0)]):
        graph.add(gtsam.PriorFactorPose2(X(i), pose, gtsam.noiseModel.Isotropic.Sigma(3, 1e-3)))
        graph.add(gtsam.BearingFactor2D(X(i), L(0), pose.bearing(truth), gtsam.noiseModel.Isotropic.Sigma(1, 0.01)))
        values.insert(X(i), pose)
    values.insert(L(0), gtsam.Point2(*landmark_start))
    return graph, values


def test_a_linear_problem_is_solved_in_one_step():
    """Point priors and relative points: linear, so one step lands on the weighted
    least-squares solution (computed here by hand)."""
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    graph.add(gtsam.PriorFactorPoint2(L(0), gtsam.Point2(0.0, 0.0), gtsam.noiseModel.Isotropic.Sigma(2, 1.0)))
    graph.add(gtsam.PriorFactorPoint2(L(1), gtsam.Point2(3.0, 0.0), gtsam.noiseModel.Isotropic.Sigma(2, 1.0)))
    graph.add(gtsam.BetweenFactorPoint2(L(0), L(1), gtsam.Point2(2.0, 0.0), gtsam.noiseModel.Isotropic.Sigma(2, 1.0)))
    values.insert(L(0), gtsam.Point2(5.0, 5.0))
    values.insert(L(1), gtsam.Point2(-5.0, 2.0))
    polished = gauss_newton_steps(graph, values, max_iterations=10, tolerance=1e-9)
    # x: minimise a² + (b − 3)² + (b − a − 2)² → a = 1/3, b = 8/3; y: all zero
    assert np.allclose(polished.values.atPoint2(L(0)), [1 / 3, 0.0], atol=1e-9)
    assert np.allclose(polished.values.atPoint2(L(1)), [8 / 3, 0.0], atol=1e-9)
    assert polished.error == pytest.approx(0.5 * 3 * (1 / 3) ** 2, rel=1e-9)
    assert polished.iterations <= 2 and polished.failure is None


def test_converges_to_levenberg_marquardt_from_near():
    graph, values = _bearing_graph((0.6, 1.2))
    polished = gauss_newton_steps(graph, values, max_iterations=20, tolerance=1e-12)
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(1e-14)
    reference = gtsam.LevenbergMarquardtOptimizer(graph, values, params).optimize()
    assert np.allclose(polished.values.atPoint2(L(0)), reference.atPoint2(L(0)), atol=1e-9)
    assert polished.error == pytest.approx(graph.error(polished.values), rel=1e-12)


def test_a_step_that_raises_the_error_is_undone():
    """From (1.9, 2.5) Gauss–Newton's first step overshoots (GTSAM's own optimizer goes
    from χ²/2 ≈ 3 400 to ≈ 48 000): the start is kept."""
    graph, values = _bearing_graph((1.9, 2.5))
    raw = gtsam.GaussNewtonOptimizer(graph, values, gtsam.GaussNewtonParams())
    raw.iterate()
    assert raw.error() > graph.error(values)  # the premise
    polished = gauss_newton_steps(graph, values, max_iterations=10, tolerance=1e-6)
    assert polished.iterations == 0 and polished.failure is None
    assert np.allclose(polished.values.atPoint2(L(0)), [1.9, 2.5])
    assert polished.error == pytest.approx(graph.error(values))


def test_a_singular_system_keeps_the_start_and_says_why():
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    graph.add(gtsam.BetweenFactorPose2(X(0), X(1), gtsam.Pose2(1, 0, 0), gtsam.noiseModel.Isotropic.Sigma(3, 0.1)))
    values.insert(X(0), gtsam.Pose2())
    values.insert(X(1), gtsam.Pose2(0.5, 0, 0))  # no prior: the pair can move freely
    polished = gauss_newton_steps(graph, values, max_iterations=5, tolerance=1e-6)
    assert polished.iterations == 0 and polished.failure
    assert polished.values.atPose2(X(1)).x() == 0.5


@pytest.fixture(scope="module")
def finished():
    header, records = simulate("arena-octagon", 4, laps=1)
    smoother = Isam2Smoother(header)
    run_estimator(smoother, group_steps(header, records), covariances=False)
    return smoother


def test_finish_ends_at_the_batch_optimum_and_its_covariances_are_there(finished):
    smoother = finished
    batch = batch_solve(smoother)
    assert abs(smoother.error() - batch.final_error) <= 1e-6 * batch.final_error
    marginals = gtsam.Marginals(smoother.graph(), smoother.estimate())
    covariances = smoother.landmark_covariances()
    assert covariances
    for lid, cov in covariances.items():
        assert np.allclose(cov, marginals.marginalCovariance(L(lid)), rtol=1e-9, atol=1e-15)
    last = smoother.num_poses - 1
    theta = smoother.estimate().atPose2(X(last)).theta()
    c, s = np.cos(theta), np.sin(theta)
    J = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])  # body → world
    expected = J @ marginals.marginalCovariance(X(last)) @ J.T
    assert np.allclose(smoother.current_covariance(), expected, rtol=1e-9, atol=1e-15)


def _vector_values(*blocks):
    values = gtsam.VectorValues()
    for i, block in enumerate(blocks):
        values.insert(L(i), np.asarray(block, dtype=float))
    return values


@pytest.mark.parametrize("ratio", [0.2, 0.5, 0.9])
def test_the_extrapolation_sums_a_geometric_series_of_steps(ratio):
    """Steps s, ρs, ρ²s, … sum to ρ/(1 − ρ) times the last beyond it (Aitken's Δ²)."""
    from fgslam.smoother.batch import extrapolated_step_scale

    previous = _vector_values([1.0, -2.0], [0.5, 0.25])
    step = _vector_values([ratio * 1.0, ratio * -2.0], [ratio * 0.5, ratio * 0.25])
    assert extrapolated_step_scale(step, previous) == pytest.approx(ratio / (1 - ratio), rel=1e-12)


@pytest.mark.parametrize("ratio", [-0.5, 0.0, 0.1, 0.95, 1.0, 2.0])
def test_no_extrapolation_for_oscillating_fast_stalled_or_growing_steps(ratio):
    from fgslam.smoother.batch import extrapolated_step_scale

    previous = _vector_values([1.0, -2.0])
    assert extrapolated_step_scale(_vector_values([ratio, -2.0 * ratio]), previous) == 0.0
    assert extrapolated_step_scale(previous, _vector_values([0.0, 0.0])) == 0.0


def test_the_extrapolation_speeds_up_a_robust_kernels_linear_convergence():
    """A point seen by 20 inliers and 6 readings in a cluster 3σ away, with the DCS kernel:
    Gauss–Newton on the IRLS weights converges linearly. Both runs reach GTSAM's
    Levenberg–Marquardt optimum; the extrapolated one in fewer steps and closer."""
    rng = np.random.default_rng(3)
    graph = gtsam.NonlinearFactorGraph()
    noise = gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.DCS.Create(1.0),
                                           gtsam.noiseModel.Isotropic.Sigma(2, 1.0))
    readings = list(rng.normal(0, 1, (20, 2))) + list(rng.normal(0, 0.3, (6, 2)) + [2.5, 1.5])
    for reading in readings:
        graph.add(gtsam.PriorFactorPoint2(L(0), gtsam.Point2(*reading), noise))
    start = gtsam.Values()
    start.insert(L(0), gtsam.Point2(3.0, 2.0))
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(1e-15)
    params.setAbsoluteErrorTol(1e-15)
    params.setMaxIterations(500)
    optimum = gtsam.LevenbergMarquardtOptimizer(graph, start, params).optimize()
    plain = gauss_newton_steps(graph, start, 50, 1e-8, extrapolate=False)
    faster = gauss_newton_steps(graph, start, 50, 1e-8)
    for polished in (plain, faster):
        assert np.allclose(polished.values.atPoint2(L(0)), optimum.atPoint2(L(0)), atol=2e-4)
    assert faster.iterations < 0.75 * plain.iterations
    assert faster.error - graph.error(optimum) < 0.01 * (plain.error - graph.error(optimum))
