"""ekf.invariant.InvariantEkfSlam (``ekf-inv``): the right-invariant error (Barrau and
Bonnabel 2015), checked against independent references.

* The group's exponential: :func:`group_correction` against ``scipy.linalg.expm`` of the
  SE(2) twist acting on each position.
* The covariance's transport: :func:`transport_factors` against ``M P Mᵀ`` built densely.
* The consistency it is for: a rotation of the whole solution about the origin changes no
  reading, so no update may add information along it. At the current estimate that
  direction is ``N = (−ŷ, x̂, 1, −l̂y, l̂x, …)`` over (robot x, y, θ, landmarks), and with no
  odometry noise ``Nᵀ P⁻¹ N`` must stay what the start and the landmarks' first readings
  gave it. The textbook filter's grows (the spurious heading information of Huang,
  Mourikis and Roumeliotis 2008).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import expm

from builders import minimal_header
from ekf import EkfSlam, InvariantEkfSlam
from ekf.invariant import group_correction, se2_left_jacobian, transport_factors
from ekf.models import predict_pose, range_bearing
from slamio.log import Observation, Odometry, Step, as_matrix3

LANDMARKS = {1: np.array([4.0, 2.0]), 2: np.array([1.0, 5.0])}


def _drive(steps: int, odometry_sigma, seed: int = 3) -> list[Step]:
    """An arc past two landmarks; odometry with ``odometry_sigma`` (x, y, θ) of noise (and that
    covariance), readings with σ 0.05 m and 0.02 rad."""
    rng = np.random.default_rng(seed)
    sigma = np.asarray(odometry_sigma, dtype=float)
    covariance = as_matrix3(np.diag(sigma**2))
    pose = np.array([0.0, 0.0, 0.0])
    out = []
    for k in range(steps):
        odometry = None
        if k > 0:
            true_increment = np.array([0.3, 0.0, 0.15])
            pose = predict_pose(pose, true_increment)
            measured = true_increment + rng.normal(0.0, 1.0, 3) * sigma + rng.normal(0.0, [0.02, 0.01, 0.01])
            odometry = Odometry(float(k), *map(float, measured), covariance=covariance)
        readings = []
        for lid, xy in LANDMARKS.items():
            r, b = range_bearing(pose, xy)
            readings.append(Observation(float(k), lid, r + rng.normal(0.0, 0.05), b + rng.normal(0.0, 0.02), 0.05, 0.02))
        out.append(Step(k, float(k), odometry, tuple(readings), None))
    return out


def _rotation_information(estimator) -> float:
    """``Nᵀ P⁻¹ N`` for the rotation about the origin at the current estimate."""
    mean, P = estimator.state_mean(), estimator.state_covariance()
    N = np.zeros(len(mean))
    N[0], N[1], N[2] = -mean[1], mean[0], 1.0
    for lid in estimator.landmarks():
        i = estimator.landmark_index(lid)
        N[i], N[i + 1] = -mean[i + 1], mean[i]
    return float(N @ np.linalg.solve(P, N))


def test_group_correction_is_the_exponential_acting_on_each_position():
    rng = np.random.default_rng(5)
    positions = rng.normal(0.0, 3.0, (4, 2))
    shift, turn = rng.normal(0.0, 0.4, (4, 2)), 0.7
    out = group_correction(positions, shift, turn)
    J = np.array([[0.0, -1.0], [1.0, 0.0]])
    for q, d, got in zip(positions, shift, out):
        xi = d - turn * (J @ q)  # the invariant error of this position
        twist = np.zeros((3, 3))
        twist[:2, :2], twist[:2, 2] = turn * J, xi
        expected = expm(twist) @ np.array([q[0], q[1], 1.0])
        np.testing.assert_allclose(got, expected[:2], atol=1e-12)
    # a small correction is the additive one to first order
    small = group_correction(positions, 1e-6 * shift, 1e-6)
    np.testing.assert_allclose(small, positions + 1e-6 * shift, atol=1e-11)
    np.testing.assert_allclose(se2_left_jacobian(1e-9), np.eye(2), atol=1e-9)


def test_transport_factors_are_m_p_mt():
    rng = np.random.default_rng(2)
    A = rng.normal(size=(7, 7))
    P = A @ A.T
    u = rng.normal(size=7)
    u[2] = 0.0
    M = np.eye(7) + np.outer(u, np.eye(7)[2])
    X, Y = transport_factors(P, 2, u)
    np.testing.assert_allclose(P + X @ Y.T, M @ P @ M.T, atol=1e-12)


def test_no_update_adds_information_along_the_global_rotation():
    steps = _drive(25, odometry_sigma=(0.0, 0.0, 0.0))
    for cls, grows in ((InvariantEkfSlam, False), (EkfSlam, True)):
        estimator = cls(minimal_header(start_sigma=(0.05, 0.05, 0.05)))
        estimator.step(steps[0])
        first = _rotation_information(estimator)
        for step in steps[1:]:
            estimator.step(step)
        last = _rotation_information(estimator)
        if grows:
            assert last > 1.2 * first  # 400 → 598 here
        else:
            assert last == pytest.approx(first, rel=1e-6)


def test_dead_reckoning_alone_is_the_same_filter():
    steps = [Step(k, float(k), None if k == 0 else Odometry(float(k), 0.3, 0.01, 0.1,
                                                            covariance=as_matrix3(np.diag([4e-4, 1e-4, 1e-4]))), (), None)
             for k in range(20)]
    a, b = EkfSlam(minimal_header()), InvariantEkfSlam(minimal_header())
    for step in steps:
        a.step(step)
        b.step(step)
    np.testing.assert_allclose(b.trajectory(), a.trajectory(), atol=1e-15)
    np.testing.assert_allclose(b.current_covariance(), a.current_covariance(), atol=1e-15)


@pytest.mark.parametrize("association, name", [("jcbb", "ekf-inv"), ("nn", "ekf-inv-nn"), (None, "ekf-inv-ids")])
def test_names(association, name):
    assert InvariantEkfSlam(minimal_header(), association=association).name == name
