"""The online correction between iSAM2 updates (fgslam/smoother/correction.py).

Checked against independent references: the textbook EKF equations written with numpy
matrices and ekf.models' Jacobians; the information-form answer of a linear case; and the
iSAM2 that updates at every step on a simulated log.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from ekf.models import motion_jacobians, predict_pose, range_bearing, range_bearing_jacobians, wrap_angle
from fgslam.smoother import Isam2Smoother
from fgslam.smoother.correction import SURPRISE_NIS, PoseCorrector, correct, correct_range, predict
from slamio.log import group_steps
from slamio.sim import simulate


def _random_covariance(rng, n):
    A = rng.normal(size=(n, n)) * 0.1
    return A @ A.T + 1e-3 * np.eye(n)


@pytest.mark.parametrize("seed", range(5))
def test_predict_equals_the_matrix_form(seed):
    rng = np.random.default_rng(seed)
    mean = (rng.normal(), rng.normal(), rng.uniform(-math.pi, math.pi))
    P = _random_covariance(rng, 3)
    increment = (rng.normal(0, 0.3), rng.normal(0, 0.05), rng.normal(0, 0.2))
    Q = _random_covariance(rng, 3)
    moved, P_new = predict(mean, P.tolist(), increment, Q.tolist())
    F, G = motion_jacobians(mean, increment)
    np.testing.assert_allclose(moved, predict_pose(mean, increment), atol=1e-12)
    np.testing.assert_allclose(P_new, F @ P @ F.T + G @ Q @ G.T, atol=1e-12)


def _random_case(seed, max_range_m):
    """A random pose, covariance and landmark within ``max_range_m`` of the pose."""
    rng = np.random.default_rng(seed)
    mean = np.array([rng.normal(), rng.normal(), rng.uniform(-math.pi, math.pi)])
    P = _random_covariance(rng, 3)
    landmark = mean[:2] + rng.uniform(1.0, max_range_m) * np.array([math.cos(seed), math.sin(seed)])
    return mean, P, landmark


def _assert_textbook_update(updated, P_new, nis, mean, P, H, R, nu):
    """The textbook EKF update with matrices, covariance in the Joseph form."""
    S = H @ P @ H.T + R
    K = P @ H.T @ np.linalg.inv(S)
    I_KH = np.eye(3) - K @ H
    expected_mean = mean + K @ nu
    np.testing.assert_allclose(updated[:2], expected_mean[:2], atol=1e-12)
    assert wrap_angle(updated[2] - expected_mean[2]) == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_allclose(P_new, I_KH @ P @ I_KH.T + K @ R @ K.T, atol=1e-12)
    assert nis == pytest.approx(float(nu @ np.linalg.solve(S, nu)), rel=1e-10)


@pytest.mark.parametrize("seed", range(5))
def test_correct_equals_the_joseph_form(seed):
    mean, P, landmark = _random_case(10 + seed, 5.0)
    R = np.diag([0.1**2, 0.02**2])
    r, b = range_bearing(mean, landmark)
    z_r, z_b = r + 0.05, wrap_angle(b - 0.01)
    updated, P_new, nis = correct(tuple(mean), P.tolist(), tuple(landmark), z_r, z_b, R.tolist())
    H, _ = range_bearing_jacobians(mean, landmark)
    _assert_textbook_update(updated, P_new, nis, mean, P, H, R, np.array([z_r - r, wrap_angle(z_b - b)]))


@pytest.mark.parametrize("seed", range(5))
def test_correct_range_equals_the_joseph_form(seed):
    mean, P, landmark = _random_case(20 + seed, 30.0)
    var = 1.5**2
    r, _ = range_bearing(mean, landmark)
    updated, P_new, nis = correct_range(tuple(mean), P.tolist(), tuple(landmark), r + 0.7, var)
    H = range_bearing_jacobians(mean, landmark)[0][:1]  # the range row
    _assert_textbook_update(updated, P_new, nis, mean, P, H, np.array([[var]]), np.array([0.7]))


def test_linear_case_equals_the_information_form():
    """Heading known exactly (zero variance) and a landmark straight ahead: range is then a
    linear measurement of x, and the update must be the product of two Gaussians."""
    P = [[0.04, 0.0, 0.0], [0.0, 0.09, 0.0], [0.0, 0.0, 0.0]]
    landmark = (5.0, 0.0)
    sigma_r = 0.1
    z_r = 4.9  # measured range: x = 5 − 4.9 = 0.1
    updated, P_new, nis = correct((0.0, 0.0, 0.0), P, landmark, z_r, 0.0, [[sigma_r**2, 0.0], [0.0, 1e-4]])
    info = 1 / 0.04 + 1 / sigma_r**2
    assert updated[0] == pytest.approx((0.1 / sigma_r**2) / info, rel=1e-9)
    assert P_new[0][0] == pytest.approx(1 / info, rel=1e-9)
    assert nis == pytest.approx(0.1**2 / (0.04 + sigma_r**2), rel=1e-9)


def test_a_surprise_is_not_used():
    corrector = PoseCorrector((0.0, 0.0, 0.0), np.diag([0.01, 0.01, 0.001]))
    assert not corrector.correct((5.0, 0.0), 8.0, 0.0, [[0.01, 0.0], [0.0, 1e-4]])  # 3 m off
    assert corrector.mean == (0.0, 0.0, 0.0) and corrector.surprises == 1
    assert corrector.correct((5.0, 0.0), 5.05, 0.0, [[0.01, 0.0], [0.0, 1e-4]])
    assert corrector.corrections == 1 and SURPRISE_NIS > 9.0


def test_online_pose_close_to_every_step_isam2():
    """On a simulated arena run, the corrected online pose between updates every 10 steps
    stays within a few millimetres of an iSAM2 that updates at every step, and is closer to
    it than the uncorrected dead reckoning between updates."""
    header, records = simulate("arena-octagon", 4)
    steps = group_steps(header, records)[:300]

    def online(**kwargs):
        smoother = Isam2Smoother(header, **kwargs)
        out = []
        for step in steps:
            smoother.step(step)
            out.append(smoother.current_pose())
        return np.array(out), smoother

    reference, _ = online(update_every=1, online_correction=False)
    corrected, smoother = online(update_every=10, online_correction=True)
    uncorrected, _ = online(update_every=10, online_correction=False)
    assert smoother.updates < len(steps) / 5  # it did hold steps

    def gap(a):
        return float(np.sqrt(np.mean(np.sum((a[:, :2] - reference[:, :2]) ** 2, axis=1))))

    assert gap(corrected) < 0.005
    assert gap(corrected) < gap(uncorrected)


def test_the_kept_replay_gives_the_covariance_a_fresh_replay_gives():
    """current_covariance() of a corrected online pose carries its replay on between calls
    (each held step once); at every step it equals that of a twin smoother whose replay is
    started afresh at each call from iSAM2's joint marginal of the landmarks used (the whole
    replay, as it was computed before the replay was kept); the predicted NIS, which keeps one
    joint marginal over every landmark asked for until iSAM2 changes, likewise."""
    header, records = simulate("arena-octagon", 4)
    steps = group_steps(header, records)[:200]
    kept, fresh = (Isam2Smoother(header, update_every=10, online_correction=True) for _ in range(2))
    compared = nis_compared = 0
    for step in steps:
        fresh._online._joint = None  # the NIS's joint marginal too: afresh, of this step's landmarks only
        nis_kept, nis_fresh = kept.predicted_nis(step), fresh.predicted_nis(step)
        assert [v is None for v in nis_kept] == [v is None for v in nis_fresh]
        np.testing.assert_allclose([v for v in nis_kept if v is not None], [v for v in nis_fresh if v is not None],
                                   rtol=1e-9)
        nis_compared += sum(v is not None for v in nis_kept)
        kept.step(step)
        fresh.step(step)
        fresh._online._replay = None
        np.testing.assert_allclose(kept.current_covariance(), fresh.current_covariance(), rtol=1e-9, atol=1e-15)
        compared += kept._online._replay is not None and kept._online._replay.steps > 1
    assert compared > 50 and nis_compared > 100
