"""Keyframes in iSAM2 (``Isam2Smoother(keyframes=True)``, part of ``isam2-fast``).

Only steps with observations get a variable; the odometry in between is folded into one
compound factor and the poses in between are rebuilt. References: numerical Jacobians of
GTSAM's own Pose2 maps for the compound covariance, batch Levenberg–Marquardt on the
chain alone for the rebuilt poses, and the same log without keyframes.
"""

from __future__ import annotations

import dataclasses
import math

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import X

from fgslam.smoother import FAST_SETTINGS, Isam2Smoother, batch_solve, odometry_noise_covariance
from fgslam.smoother.chain import OdometryChain
from slamio.log import group_steps
from builders import run_smoother
from slamio.sim import simulate


def random_chain(rng, m: int) -> OdometryChain:
    chain = OdometryChain(0)
    for _ in range(m):
        z = gtsam.Pose2(rng.uniform(0.05, 0.3), rng.uniform(-0.05, 0.05), rng.uniform(-0.3, 0.3))
        L = rng.normal(size=(3, 3)) * np.array([0.01, 0.005, 0.01])
        chain.append(z, L @ L.T + np.diag([1e-5, 1e-5, 1e-5]))
    return chain


def perturbed_end(chain: OdometryChain, errors) -> gtsam.Pose2:
    """start = identity; end = z_1 Exp(e_1) ⋯ z_m Exp(e_m)."""
    pose = gtsam.Pose2()
    for (z, _), e in zip(chain.links, errors):
        pose = pose.compose(z).compose(gtsam.Pose2.Expmap(np.asarray(e, dtype=float)))
    return pose


@pytest.mark.parametrize("m", [1, 2, 5])
def test_compound_covariance_is_the_first_order_propagation_of_the_links(m):
    rng = np.random.default_rng(m)
    chain = random_chain(rng, m)
    h = 1e-6
    J = np.empty((3, 3 * m))  # ∂ Log(z⁻¹ · end(ε)) / ∂ε at ε = 0
    for col in range(3 * m):
        errors = np.zeros((m, 3))
        errors.flat[col] = h
        plus = gtsam.Pose2.Logmap(chain.compound.between(perturbed_end(chain, errors)))
        errors.flat[col] = -h
        minus = gtsam.Pose2.Logmap(chain.compound.between(perturbed_end(chain, errors)))
        J[:, col] = (plus - minus) / (2 * h)
    S = np.zeros((3 * m, 3 * m))
    for j, (_, cov) in enumerate(chain.links):
        S[3 * j : 3 * j + 3, 3 * j : 3 * j + 3] = cov
    assert np.allclose(chain.covariance(), J @ S @ J.T, rtol=1e-6, atol=1e-14)


def _least_squares_gap(scale: float) -> float:
    """Largest gap between the rebuilt interior poses and batch LM's, for link errors drawn
    from the links' covariances and multiplied by ``scale``."""
    rng = np.random.default_rng(7)
    m = 6
    chain = random_chain(rng, m)
    start = gtsam.Pose2(1.0, -2.0, 0.4)
    errors = [scale * rng.multivariate_normal(np.zeros(3), cov) for _, cov in chain.links]
    end = start.compose(perturbed_end(chain, errors))

    # reference: batch LM over the chain with both ends pinned
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    pin = gtsam.noiseModel.Isotropic.Sigma(3, 1e-9)
    graph.add(gtsam.PriorFactorPose2(X(0), start, pin))
    graph.add(gtsam.PriorFactorPose2(X(m), end, pin))
    pose = start
    values.insert(X(0), start)
    for j, (z, cov) in enumerate(chain.links):
        graph.add(gtsam.BetweenFactorPose2(X(j), X(j + 1), z, gtsam.noiseModel.Gaussian.Covariance(cov)))
        pose = pose.compose(z)
        values.insert(X(j + 1), pose if j + 1 < m else end)
    result = gtsam.LevenbergMarquardtOptimizer(graph, values).optimize()
    expected = np.array([[p.x(), p.y(), p.theta()] for p in (result.atPose2(X(i)) for i in range(1, m))])

    rebuilt = chain.poses(start, end)
    assert rebuilt.shape == (m - 1, 3)
    return float(np.abs(rebuilt - expected).max())


def test_rebuilt_poses_are_the_least_squares_poses_of_the_chain_to_first_order():
    # The split is exact to first order in the chain's residual, so shrinking the residual
    # 10x shrinks the gap to the exact least-squares poses about 100x.
    gap, small_gap = _least_squares_gap(1.0), _least_squares_gap(0.1)
    assert gap < 1e-3  # measured 4e-4 m with residuals of a few cm
    assert small_gap < gap / 30


def test_with_no_residual_the_rebuilt_poses_are_dead_reckoning():
    chain = random_chain(np.random.default_rng(3), 5)
    start = gtsam.Pose2(0.3, 0.2, -1.0)
    exact_end = start.compose(chain.compound)
    assert np.allclose(chain.poses(start, exact_end), chain.dead_reckoned(start)[:-1], atol=1e-12)


@pytest.fixture(scope="module")
def sparse_octagon():
    """Arena-octagon seed 1 with observations kept on every 4th step only."""
    header, records = simulate("arena-octagon", 1)
    steps = [
        s if s.index % 4 == 0 else dataclasses.replace(s, observations=())
        for s in group_steps(header, records)
    ]
    return header, steps


def test_keyframes_solve_the_same_problem(sparse_octagon):
    header, steps = sparse_octagon
    full = run_smoother(header, steps)
    keyed = run_smoother(header, steps, keyframes=True)
    assert len(keyed._keyframes.indices) < len(steps) / 3
    # graph() is the whole problem in both cases: same factors, same error at the same values
    graph, keyed_graph = full.graph(), keyed.graph()
    assert keyed_graph.size() == graph.size()
    at = full.estimate()
    assert keyed_graph.error(at) == pytest.approx(graph.error(at), rel=1e-9)
    # ... and keyframed iSAM2 ends at its optimum to first order
    batch = batch_solve(full)
    assert keyed.error() == pytest.approx(batch.final_error, rel=1e-3)
    assert np.abs(keyed.trajectory() - batch.trajectory)[:, :2].max() < 2e-3
    assert batch_solve(keyed).final_error == pytest.approx(batch.final_error, rel=1e-9)


def test_keyframed_online_pose_and_covariance_between_keyframes(sparse_octagon):
    header, steps = sparse_octagon
    full = Isam2Smoother(header)
    keyed = Isam2Smoother(header, keyframes=True)
    for step in steps[:203]:  # ends 3 steps after a keyframe
        full.step(step)
        keyed.step(step)
    assert steps[202].index % 4 == 2 and keyed._keyframes.open.links
    assert np.allclose(keyed.current_pose(), full.current_pose(), atol=1e-3)
    assert np.allclose(keyed.current_covariance(), full.current_covariance(), rtol=1e-2, atol=1e-12)
    assert keyed.trajectory().shape == (203, 3)


def test_a_log_without_observations_is_dead_reckoning(sparse_octagon):
    header, steps = sparse_octagon
    blind = [dataclasses.replace(s, observations=()) for s in steps[:40]]
    keyed = run_smoother(header, blind, keyframes=True, max_keyframe_gap=15)
    full = run_smoother(header, blind)
    assert keyed._keyframes.indices == [0, 15, 30]
    assert np.allclose(keyed.trajectory(), full.trajectory(), atol=1e-9)
    assert keyed.error() == pytest.approx(0.0, abs=1e-12)


def test_fast_preset_uses_keyframes():
    assert FAST_SETTINGS["keyframes"] is True
    with pytest.raises(Exception, match="max_keyframe_gap"):
        Isam2Smoother(simulate("arena-square", 1)[0], keyframes=True, max_keyframe_gap=0)
    assert math.isfinite(FAST_SETTINGS["update_every"])


@pytest.mark.parametrize("keyframes", [False, True])
def test_covariance_of_the_online_pose_does_not_flush_held_steps(sparse_octagon, keyframes):
    """current_covariance() is the last iSAM2 marginal carried through the held odometry:
    asking for it must not change when iSAM2 updates (NEES is taken at every step)."""
    header, steps = sparse_octagon
    held = Isam2Smoother(header, update_every=40, update_on="observations", keyframes=keyframes)
    for step in steps[:203]:
        held.step(step)
    assert held._held.steps > 0
    updates = held.updates
    cov = held.current_covariance()
    assert held.updates == updates and held._held.steps > 0  # nothing was flushed
    # Held steps 201, 202: the marginal of the newest pose in iSAM2 carried through their
    # odometry, Σ ← A Σ Aᵀ + Σ_z with A = Ad(z⁻¹), written out here step by step.
    smoother = Isam2Smoother(header, update_every=40, update_on="observations", keyframes=keyframes)
    for step in steps[:201]:
        smoother.step(step)
    smoother._flush()
    last = smoother._keyframes.last
    assert last == 200  # step 200 has observations: a keyframe in both modes
    sigma = np.asarray(smoother._isam.marginalCovariance(X(last)))
    for step in steps[last + 1 : 203]:
        o = step.odometry
        z = gtsam.Pose2(o.dx_m, o.dy_m, o.dtheta_rad)
        A = z.inverse().AdjointMap()
        sigma = A @ sigma @ A.T + odometry_noise_covariance(o)
    for step in steps[201:203]:
        smoother.step(step)
    assert np.allclose(smoother.current_covariance(frame="body"), sigma, rtol=1e-9, atol=1e-18)
    assert np.all(np.linalg.eigvalsh(cov) > 0)
