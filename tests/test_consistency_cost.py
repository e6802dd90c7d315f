"""The cheaper consistency work (issue 43 part 3): each rewritten piece against an independent
reference — the float odometry chain against GTSAM's (OdometryChain), the replay of held steps
against the textbook EKF with dense matrices and ekf.models' Jacobians, the closed-form 2×2 NIS
against numpy's solve."""

from __future__ import annotations

import math

import gtsam
import numpy as np
import pytest

from ekf.models import motion_jacobians, normalised_innovation_squared, range_bearing_jacobians
from fgslam.smoother.chain import FloatChain, OdometryChain
from fgslam.smoother.factors import end_frame_covariance_entries, odometry_noise_covariance
from fgslam.smoother.online import _Replay
from slamio.log import Odometry


def _random_covariance(rng, n):
    A = rng.normal(size=(n, n)) * 0.1
    return A @ A.T + 1e-3 * np.eye(n)


def _odometry(rng) -> Odometry:
    return Odometry(0.0, rng.normal(0.2, 0.1), rng.normal(0, 0.02), rng.normal(0, 0.2),
                    tuple(map(tuple, _random_covariance(rng, 3) * 0.01)))


@pytest.mark.parametrize("seed", range(4))
def test_float_chain_is_the_odometry_chain(seed):
    rng = np.random.default_rng(seed)
    gtsam_chain, float_chain = OdometryChain(7), FloatChain(7)
    for _ in range(int(rng.integers(1, 40))):
        odo = _odometry(rng)
        increment = gtsam.Pose2(odo.dx_m, odo.dy_m, odo.dtheta_rad)
        entries = end_frame_covariance_entries(odo.covariance, odo.dtheta_rad)
        expected_pose, expected_cov = gtsam_chain.extended(increment, odometry_noise_covariance(odo))
        pose, cov = float_chain.extended(odo.dx_m, odo.dy_m, odo.dtheta_rad, entries)
        np.testing.assert_allclose([pose.x(), pose.y()], [expected_pose.x(), expected_pose.y()], rtol=1e-12, atol=1e-12)
        assert math.remainder(pose.theta() - expected_pose.theta(), 2 * math.pi) == pytest.approx(0.0, abs=1e-12)
        np.testing.assert_allclose(cov, 0.5 * (expected_cov + expected_cov.T), rtol=1e-12, atol=1e-18)
        gtsam_chain.append(increment, odometry_noise_covariance(odo))
        float_chain.append(odo.dx_m, odo.dy_m, odo.dtheta_rad, entries)
    assert float_chain.count == len(gtsam_chain.links) and float_chain.start == 7
    np.testing.assert_allclose(float_chain.covariance(), gtsam_chain.covariance(), rtol=1e-12, atol=1e-18)
    assert float_chain.compound.equals(gtsam_chain.compound, 1e-12)


def _textbook_replay(P, mean, column, landmark_at, since):
    """The replay with dense matrices: P ← F P Fᵀ + G Q Gᵀ per step (F, G of ekf.models, as
    n×n and n×3), then per reading K = P Hᵀ S⁻¹, P ← (I − K H) P, H at the predicted position."""
    P, mean, n = P.copy(), np.array(mean, dtype=float), len(P)
    for odo, used in since:
        increment = (odo.dx_m, odo.dy_m, odo.dtheta_rad)
        F_pose, G_pose = motion_jacobians(mean, increment)
        F, G = np.eye(n), np.zeros((n, 3))
        F[:3, :3], G[:3, :] = F_pose, G_pose
        P = F @ P @ F.T + G @ np.asarray(odo.covariance) @ G.T
        c, s = math.cos(mean[2]), math.sin(mean[2])
        mean = np.array([mean[0] + c * odo.dx_m - s * odo.dy_m, mean[1] + s * odo.dx_m + c * odo.dy_m,
                         mean[2] + odo.dtheta_rad])
        for lid, _, _, bearing_rad, R in used:
            H_pose, H_landmark = range_bearing_jacobians(mean, landmark_at[lid])
            rows = 2 if bearing_rad is not None else 1
            H = np.zeros((rows, n))
            H[:, :3], H[:, column[lid] : column[lid] + 2] = H_pose[:rows], H_landmark[:rows]
            S = H @ P @ H.T + np.atleast_2d(R)
            K = P @ H.T @ np.linalg.inv(S)
            P = (np.eye(n) - K @ H) @ P
            P = 0.5 * (P + P.T)
    return P


@pytest.mark.parametrize("seed", range(4))
def test_replay_is_the_textbook_ekf(seed):
    """Runs of steps without readings (gathered before they touch P), readings of one and of
    two landmarks, a range-only one, and a replay carried on over two calls."""
    rng = np.random.default_rng(seed)
    ids = [3, 8, 11]
    column = {lid: 3 + 2 * j for j, lid in enumerate(ids)}
    mean = np.array([rng.normal(), rng.normal(), rng.uniform(-math.pi, math.pi)])
    landmark_at = {lid: mean[:2] + rng.uniform(2, 6) * np.array([math.cos(lid), math.sin(lid)]) for lid in ids}
    P = _random_covariance(rng, 3 + 2 * len(ids))
    since = []
    for k in range(30):
        readings = []
        if rng.uniform() < 0.4:
            for lid in rng.choice(ids, size=int(rng.integers(1, 3)), replace=False):
                range_only = rng.uniform() < 0.25
                R = 0.01 if range_only else ((0.01, 0.0), (0.0, 0.002))
                readings.append((int(lid), None, 1.0, None if range_only else 0.1, R))
        since.append((_odometry(rng), tuple(readings)))
    replay = _Replay(P.copy(), mean.copy(), column, landmark_at)
    replay.run(since[:13])
    np.testing.assert_allclose(replay.P, _textbook_replay(P, mean, column, landmark_at, since[:13]), rtol=1e-9, atol=1e-14)
    replay.run(since)  # carried on: only the steps not replayed yet
    assert replay.steps == len(since)
    np.testing.assert_allclose(replay.P, _textbook_replay(P, mean, column, landmark_at, since), rtol=1e-9, atol=1e-14)


@pytest.mark.parametrize("seed", range(6))
def test_closed_form_nis_is_numpys_solve(seed):
    rng = np.random.default_rng(seed)
    S = _random_covariance(rng, 2) * 10.0 ** rng.uniform(-4, 2)
    nu = rng.normal(size=2) * math.sqrt(S[0, 0])
    assert normalised_innovation_squared(nu, S) == pytest.approx(float(nu @ np.linalg.solve(S, nu)), rel=1e-12)
    assert normalised_innovation_squared(list(nu), S.tolist()) == pytest.approx(float(nu @ np.linalg.solve(S, nu)), rel=1e-12)


def test_closed_form_nis_is_nan_unless_positive_definite():
    nu = np.array([0.1, 0.2])
    for S in ([[1.0, 2.0], [2.0, 1.0]], [[0.0, 0.0], [0.0, 1.0]], [[-1.0, 0.0], [0.0, 1.0]], [[np.nan, 0.0], [0.0, 1.0]]):
        assert math.isnan(normalised_innovation_squared(nu, np.array(S)))
