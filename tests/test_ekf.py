"""Tests of the ``ekf`` package against independent references.

* every analytic Jacobian against central finite differences (angle differences wrapped);
* the O(n²) filter arithmetic (predict, augment, Joseph update) against the dense
  textbook formulas;
* an exactly linear situation against the closed-form batch least-squares (information)
  solution;
* landmark initialisation (with cross-covariances) against a seeded Monte Carlo estimate;
* noise-free runs reproduce the truth; noisy runs (seeded) beat dead reckoning;
* bookkeeping: unknown ids skipped and counted, no NaN, P symmetric PSD, capacity growth.
"""

from __future__ import annotations

import ast
import math
import pathlib

import numpy as np
import pytest

import ekf
from ekf import DeadReckoning, EkfSlam
from ekf.models import motion_jacobians, predict_pose
from ekf.models import landmark_from_range_bearing, landmark_init_jacobians, range_bearing, range_bearing_jacobians
from ekf.covariance import (
    add_low_rank_in_place,
    augment_covariance,
    joseph_factors,
    joseph_update,
    kalman_gain,
    predict_covariance,
)
from slamio.geometry import between_pose, compose_pose, wrap_angle
from builders import minimal_header as make_header, run_estimator as run
from jacobians import assert_jacobians_match, random_poses
from slamio.log import Observation, Odometry, Step, as_matrix3

# --------------------------------------------------------------------------- helpers


def random_spd(rng, n, scale=1.0):
    """A random symmetric positive-definite n×n matrix, well conditioned: every eigenvalue
    ≥ n·scale (A·Aᵀ + n·I). Not test_association's, which allows eigenvalues down to 0.1·scale."""
    A = rng.normal(size=(n, n))
    return scale * (A @ A.T + n * np.eye(n))


def simulate_loop(rng=None, *, laps=2, steps_per_lap=60, radius_m=4.0, unknown_every=0):
    """A robot driving ``laps`` circles among a ring of landmarks.

    With ``rng=None`` the odometry and observations are exact (the sigmas are still
    positive, as the log format requires). Returns (header, steps, true poses (n,3),
    true landmarks {id: (x, y)}).
    """
    sigma_odo = np.array([0.02, 0.01, 0.015])  # dx_m, dy_m, dtheta_rad per step
    sigma_range_m, sigma_bearing_rad = 0.05, 0.02
    max_range_m = 5.0
    covariance = as_matrix3(np.diag(sigma_odo**2))
    landmarks = {}
    for k in range(8):
        a = 2 * math.pi * k / 8
        landmarks[k] = (6.5 * math.cos(a), 6.5 * math.sin(a))
    for k in range(4):
        a = 2 * math.pi * k / 4 + math.pi / 4
        landmarks[10 + k] = (1.5 * math.cos(a), 1.5 * math.sin(a))

    start = (radius_m, 0.0, math.pi / 2)
    arc = 2 * math.pi / steps_per_lap
    true_increment = (2 * radius_m * math.sin(arc / 2), 0.0, arc)  # chord, then turn
    # Drive the chord with the heading at the chord's middle: rotate half, go, rotate half.
    poses = [start]
    steps = []
    t = 0.0
    for index in range(laps * steps_per_lap + 1):
        odometry = None
        if index > 0:
            previous = poses[-1]
            mid = compose_pose(previous, (0.0, 0.0, arc / 2))
            pose = compose_pose(compose_pose(mid, (true_increment[0], 0.0, 0.0)), (0.0, 0.0, arc / 2))
            poses.append(pose)
            increment = np.array(between_pose(previous, pose))
            if rng is not None:
                increment = increment + rng.normal(size=3) * sigma_odo
            t += 0.5
            odometry = Odometry(t, *map(float, increment), covariance=covariance)
        pose = poses[-1]
        observations = []
        for lid, xy in landmarks.items():
            r, b = range_bearing(pose, xy)
            if r > max_range_m:
                continue
            if rng is not None:
                r += rng.normal() * sigma_range_m
                b = wrap_angle(b + rng.normal() * sigma_bearing_rad)
            observations.append(Observation(t, lid, r, b, sigma_range_m, sigma_bearing_rad))
            if unknown_every and index % unknown_every == 0:
                observations.append(Observation(t, None, r, b, sigma_range_m, sigma_bearing_rad))
        steps.append(Step(index, t, odometry, tuple(observations), None))
    header = make_header(start, (1e-3, 1e-3, 1e-3))
    return header, steps, np.array(poses), landmarks


def ate_m(trajectory, truth):
    return float(np.sqrt(np.mean(np.sum((trajectory[:, :2] - truth[:, :2]) ** 2, axis=1))))


def assert_symmetric_psd(P):
    assert np.all(np.isfinite(P))
    np.testing.assert_allclose(P, P.T, rtol=0, atol=1e-12 * max(1.0, np.abs(P).max()))
    assert np.linalg.eigvalsh(P).min() > -1e-10 * np.abs(P).max()


# --------------------------------------------------------------------------- Jacobians


def test_predict_pose_composes_like_slamio_geometry():
    rng = np.random.default_rng(1)
    for pose in random_poses(rng, 50):
        u = rng.normal(size=3)
        expected = compose_pose(pose, u)
        got = predict_pose(pose, u)
        np.testing.assert_allclose(got[:2], expected[:2], atol=1e-12)
        assert abs(wrap_angle(got[2] - expected[2])) < 1e-12
        assert -math.pi <= got[2] < math.pi


def test_motion_jacobians_match_finite_differences():
    rng = np.random.default_rng(2)
    for pose in random_poses(rng, 200):
        u = rng.normal(scale=[0.5, 0.2, 0.5])
        F_pose, F_inc = motion_jacobians(pose, u)
        assert_jacobians_match(predict_pose, pose, u, F_pose, F_inc, angle_rows=(2,))


def test_range_bearing_jacobians_match_finite_differences():
    rng = np.random.default_rng(3)
    for pose in random_poses(rng, 200):
        # Landmarks 1–15 m away in every direction, including straight behind (bearing ±π).
        a = rng.uniform(-math.pi, math.pi)
        r = rng.uniform(1.0, 15.0)
        landmark = pose[:2] + r * np.array([math.cos(a), math.sin(a)])
        H_pose, H_lm = range_bearing_jacobians(pose, landmark)
        assert_jacobians_match(range_bearing, pose, landmark, H_pose, H_lm, angle_rows=(1,))


def test_bearing_behind_the_robot_is_wrapped_and_differentiable():
    pose = np.array([0.0, 0.0, 0.0])
    for landmark in ([-3.0, 1e-9], [-3.0, -1e-9]):
        _, b = range_bearing(pose, landmark)
        assert abs(abs(b) - math.pi) < 1e-8
        _, H_lm = range_bearing_jacobians(pose, landmark)
        assert_jacobians_match(range_bearing, pose, landmark, None, H_lm, angle_rows=(1,))


def test_landmark_init_jacobians_match_finite_differences():
    rng = np.random.default_rng(4)
    for pose in random_poses(rng, 200):
        z = np.array([rng.uniform(0.3, 15.0), rng.uniform(-math.pi, math.pi)])
        G_pose, G_z = landmark_init_jacobians(pose, *z)
        assert_jacobians_match(lambda p, m: landmark_from_range_bearing(p, *m), pose, z, G_pose, G_z)


def test_inverse_observation_inverts_observation():
    rng = np.random.default_rng(5)
    for pose in random_poses(rng, 100):
        z = (rng.uniform(0.3, 15.0), rng.uniform(-math.pi, math.pi))
        r, b = range_bearing(pose, landmark_from_range_bearing(pose, *z))
        assert abs(r - z[0]) < 1e-10 and abs(wrap_angle(b - z[1])) < 1e-10


# --------------------------------------------------------------------------- O(n²) arithmetic vs dense


def dense_H(n, cols, H_cols):
    H = np.zeros((H_cols.shape[0], n))
    H[:, cols] = H_cols
    return H


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_joseph_update_equals_dense_textbook_formula(seed):
    rng = np.random.default_rng(seed)
    n_landmarks = 6
    n = 3 + 2 * n_landmarks
    P = random_spd(rng, n, scale=0.1)
    i = 3 + 2 * rng.integers(n_landmarks)
    cols = np.array([0, 1, 2, i, i + 1])
    pose = rng.uniform([-5, -5, -math.pi], [5, 5, math.pi])
    landmark = pose[:2] + rng.uniform(1, 5, size=2)
    H_cols = np.hstack(range_bearing_jacobians(pose, landmark))
    R = random_spd(rng, 2, scale=0.01)

    H = dense_H(n, cols, H_cols)
    S_dense = H @ P @ H.T + R
    K_dense = P @ H.T @ np.linalg.inv(S_dense)
    I_KH = np.eye(n) - K_dense @ H
    P_dense = I_KH @ P @ I_KH.T + K_dense @ R @ K_dense.T

    K, S, PHt = kalman_gain(P, cols, H_cols, R)
    np.testing.assert_allclose(K, K_dense, rtol=0, atol=1e-12)
    np.testing.assert_allclose(S, S_dense, rtol=0, atol=1e-12)
    np.testing.assert_allclose(PHt, P @ H.T, rtol=0, atol=1e-12)

    # Run on an n×n view of a larger buffer, as EkfSlam does; the rest must stay untouched.
    buffer = np.full((n + 4, n + 4), 7.0)
    buffer[:n, :n] = P
    joseph_update(buffer[:n, :n], cols, H_cols, K, R)
    np.testing.assert_allclose(buffer[:n, :n], P_dense, rtol=0, atol=1e-12)
    assert np.all(buffer[n:, :] == 7.0) and np.all(buffer[:, n:] == 7.0)
    np.testing.assert_allclose(buffer[:n, :n], buffer[:n, :n].T, rtol=0, atol=1e-15)
    # The factored form used by EkfSlam (in-place BLAS on a Fortran buffer) agrees too.
    for order in ("F", "C"):
        buffer = np.zeros((n + 5, n + 5), order=order)
        buffer[:n, :n] = P
        add_low_rank_in_place(buffer, n, *joseph_factors(P, cols, H_cols, K, R))
        np.testing.assert_allclose(buffer[:n, :n], P_dense, rtol=0, atol=1e-12)
        assert np.all(buffer[n:, :] == 0.0) and np.all(buffer[:, n:] == 0.0)
    # The simple form (I − KH)P agrees for the optimal gain.
    np.testing.assert_allclose(P_dense, I_KH @ P, rtol=0, atol=1e-12)


def test_joseph_update_is_exact_for_any_gain():
    """The Joseph form is valid for a sub-optimal gain too: check with a random K."""
    rng = np.random.default_rng(10)
    n = 3 + 2 * 5
    P = random_spd(rng, n, scale=0.1)
    cols = np.array([0, 1, 2, 7, 8])
    H_cols = rng.normal(size=(2, 5))
    R = random_spd(rng, 2, scale=0.01)
    K = rng.normal(scale=0.1, size=(n, 2))
    H = dense_H(n, cols, H_cols)
    I_KH = np.eye(n) - K @ H
    expected = I_KH @ P @ I_KH.T + K @ R @ K.T
    got = P.copy()
    joseph_update(got, cols, H_cols, K, R)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)


def test_predict_covariance_equals_dense_formula():
    rng = np.random.default_rng(11)
    n = 3 + 2 * 4
    P = random_spd(rng, n)
    pose, u = rng.normal(size=3), rng.normal(size=3)
    F_pose, F_inc = motion_jacobians(pose, u)
    Sigma = random_spd(rng, 3, 0.01)
    Q = F_inc @ Sigma @ F_inc.T
    F = np.eye(n)
    F[:3, :3] = F_pose
    Q_full = np.zeros((n, n))
    Q_full[:3, :3] = Q
    expected = F @ P @ F.T + Q_full
    got = P.copy()
    predict_covariance(got, F_pose, Q)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)


def test_augment_covariance_equals_dense_formula():
    rng = np.random.default_rng(12)
    n = 3 + 2 * 3
    P = random_spd(rng, n)
    pose = rng.normal(size=3)
    G_pose, G_z = landmark_init_jacobians(pose, 2.5, 0.3)
    R = random_spd(rng, 2, 0.01)
    # New state = [x; g(x_r, z)]: Jacobian [[I_n], [G_pose 0]] wrt the old state, [0; G_z] wrt z.
    J_x = np.zeros((n + 2, n))
    J_x[:n, :n] = np.eye(n)
    J_x[n:, :3] = G_pose
    J_z = np.zeros((n + 2, 2))
    J_z[n:, :] = G_z
    expected = J_x @ P @ J_x.T + J_z @ R @ J_z.T
    buffer = np.zeros((n + 2, n + 2))
    buffer[:n, :n] = P
    augment_covariance(buffer, n, G_pose, G_z, R)
    np.testing.assert_allclose(buffer, expected, rtol=0, atol=1e-12)


def test_add_low_rank_in_place_writes_into_the_buffer():
    rng = np.random.default_rng(13)
    n, cap = 9, 16
    X, Y = rng.normal(size=(n, 4)), rng.normal(size=(n, 4))
    for order in ("F", "C"):
        buffer = np.asarray(rng.normal(size=(cap, cap)), order=order)
        expected = buffer.copy()
        expected[:n, :n] += X @ Y.T
        add_low_rank_in_place(buffer, n, X, Y)
        np.testing.assert_allclose(buffer, expected, rtol=0, atol=1e-13)


# --------------------------------------------------------------------------- wrapping


def test_bearing_innovation_is_wrapped_across_the_cut():
    """A landmark straight behind, first seen at bearing π − 0.01 and then at −π + 0.01
    (0.02 rad further round, across the ±π cut). The same world geometry seen by a robot
    facing the other way has bearings −0.01 and +0.01, far from the cut. The two filters
    must agree (headings differ by π); an unwrapped innovation would be ≈ −2π instead."""
    results = []
    for heading, bearings in ((0.0, (math.pi - 0.01, -math.pi + 0.01)), (math.pi, (-0.01, 0.01))):
        estimator = EkfSlam(make_header((0.0, 0.0, heading), (0.05, 0.05, 0.02)))
        observations = tuple(Observation(0.0, 7, 3.0, b, 0.05, 0.02) for b in bearings)
        estimator.step(Step(0, 0.0, None, observations, None))
        assert estimator.updates == 1
        results.append(estimator)
    a, b = results
    np.testing.assert_allclose(a.landmarks()[7], b.landmarks()[7], atol=1e-9)
    np.testing.assert_allclose(a.current_pose()[:2], b.current_pose()[:2], atol=1e-9)
    assert abs(wrap_angle(a.current_pose()[2] - b.current_pose()[2] - math.pi)) < 1e-9
    np.testing.assert_allclose(a.state_covariance(), b.state_covariance(), atol=1e-12)
    assert abs(a.current_pose()[2]) < 0.05  # no 2π-sized jump


# --------------------------------------------------------------------------- exactly linear case


def batch_information_solution(start_x, start_var, increments, odo_var, ranges, range_var):
    """Closed-form least squares for the 1-D problem along the x axis.

    Unknowns: robot x_0..x_k and the landmark x coordinates seen so far. Factors:
    prior x_0 = start_x, odometry x_j − x_{j−1} = dx_j, range z = l − x_j. Returns
    (mean, covariance) of (x_k, l_1, l_2, ...) marginalised from the full solution.
    """
    k = len(increments)
    ids = sorted({lid for _, lid, _ in ranges})
    col = {lid: k + 1 + c for c, lid in enumerate(ids)}
    dim = k + 1 + len(ids)
    rows, rhs = [], []

    def factor(coefficients, value, variance):
        a = np.zeros(dim)
        for j, c in coefficients:
            a[j] = c
        w = 1.0 / math.sqrt(variance)
        rows.append(a * w)
        rhs.append(value * w)

    factor([(0, 1.0)], start_x, start_var)
    for j, dx in enumerate(increments, start=1):
        factor([(j, 1.0), (j - 1, -1.0)], dx, odo_var)
    for j, lid, z in ranges:
        factor([(col[lid], 1.0), (j, -1.0)], z, range_var)
    A, b = np.array(rows), np.array(rhs)
    information = A.T @ A
    covariance = np.linalg.inv(information)
    mean = covariance @ (A.T @ b)
    keep = [k] + [col[lid] for lid in ids]
    return mean[keep], covariance[np.ix_(keep, keep)], ids


def test_linear_case_matches_closed_form_least_squares():
    """Heading 0, pure x translations, landmarks on the x axis ahead: range = l − x and
    bearing = 0 exactly, so the x-block of the EKF is an exactly linear Kalman filter and
    must equal the batch least-squares marginal after every step."""
    rng = np.random.default_rng(20)
    start_sigma = (0.1, 0.05, 0.02)
    sigma_odo = np.array([0.03, 0.01, 0.005])
    sigma_range, sigma_bearing = 0.07, 0.01
    true_landmarks = {1: 10.0, 2: 14.0}
    header = make_header((0.0, 0.0, 0.0), start_sigma)
    estimator = EkfSlam(header, landmark_capacity=1)  # also exercises capacity growth
    true_x = 0.0
    increments, ranges = [], []
    for index in range(20):
        odometry = None
        if index > 0:
            true_dx = 0.25
            true_x += true_dx
            dx = true_dx + rng.normal() * sigma_odo[0]
            increments.append(dx)
            odometry = Odometry(float(index), dx, 0.0, 0.0, covariance=as_matrix3(np.diag(sigma_odo**2)))
        observations = []
        for lid, lx in true_landmarks.items():
            if lid == 2 and index < 4:
                continue  # landmark 2 first seen at step 4: augmentation mid-run
            z = lx - true_x + rng.normal() * sigma_range
            ranges.append((index, lid, z))
            observations.append(Observation(float(index), lid, z, 0.0, sigma_range, sigma_bearing))
        estimator.step(Step(index, float(index), odometry, tuple(observations), None))

        mean_ref, cov_ref, ids = batch_information_solution(
            0.0, start_sigma[0] ** 2, increments, sigma_odo[0] ** 2, ranges, sigma_range**2
        )
        mean = estimator.state_mean()
        P = estimator.state_covariance()
        x_block = [0] + [estimator.landmark_index(lid) for lid in ids]
        np.testing.assert_allclose(mean[x_block], mean_ref, rtol=0, atol=1e-10)
        np.testing.assert_allclose(P[np.ix_(x_block, x_block)], cov_ref, rtol=0, atol=1e-12)
        # The (y, θ, landmark y) block stays exactly at zero and uncorrelated with x.
        other = [i for i in range(mean.size) if i not in x_block]
        np.testing.assert_allclose(mean[other], 0.0, atol=1e-12)
        np.testing.assert_allclose(P[np.ix_(x_block, other)], 0.0, atol=1e-12)
    assert estimator.trajectory().shape == (20, 3)
    assert estimator.updates == len(ranges) - 2  # two first sightings augment instead


# --------------------------------------------------------------------------- landmark initialisation


def test_landmark_initialisation_covariance_matches_monte_carlo():
    """Sample the state before augmentation and the measurement, push them through the
    inverse observation model, and compare the sample covariance of the augmented state
    (robot, an old landmark, the new landmark) with the EKF's."""
    rng = np.random.default_rng(30)
    header = make_header((1.0, 2.0, 0.7), (0.02, 0.015, 0.01))
    estimator = EkfSlam(header)
    sigma_r, sigma_b = 0.02, 0.008
    odo_cov = as_matrix3(np.diag([0.01, 0.005, 0.006]) ** 2)
    estimator.step(Step(0, 0.0, None, (Observation(0.0, 1, 3.0, 0.4, sigma_r, sigma_b),), None))
    estimator.step(Step(1, 1.0, Odometry(1.0, 0.5, 0.1, 0.2, odo_cov), (), None))
    mean_before, P_before = estimator.state_mean(), estimator.state_covariance()
    z = (4.0, -0.9)
    estimator.step(Step(2, 2.0, None, (Observation(2.0, 2, *z, sigma_r, sigma_b),), None))
    P_after = estimator.state_covariance()
    assert P_after.shape == (7, 7)

    samples = 400_000
    x = rng.multivariate_normal(mean_before, P_before, size=samples)
    r = z[0] + sigma_r * rng.normal(size=samples)
    b = z[1] + sigma_b * rng.normal(size=samples)
    a = x[:, 2] + b
    new = np.column_stack([x[:, 0] + r * np.cos(a), x[:, 1] + r * np.sin(a)])
    empirical = np.cov(np.hstack([x, new]).T)
    # Standard error of a sample covariance entry: sqrt((Σii Σjj + Σij²) / N).
    d = np.diag(P_after)
    standard_error = np.sqrt((np.outer(d, d) + P_after**2) / samples)
    assert np.all(np.abs(empirical - P_after) < 5 * standard_error + 1e-9)
    np.testing.assert_allclose(
        estimator.landmarks()[2], landmark_from_range_bearing(mean_before[:3], *z), atol=1e-12
    )
    # The new landmark is correlated with the old one (through the robot).
    assert abs(P_after[5, 3]) > 10 * standard_error[5, 3]


# --------------------------------------------------------------------------- whole runs


def test_noise_free_run_reproduces_truth():
    header, steps, true_poses, true_landmarks = simulate_loop(None, unknown_every=7)
    ekf_ = run(EkfSlam(header, association=None), steps)  # the known-ids filter
    dr = run(DeadReckoning(header), steps)
    for estimator in (ekf_, dr):
        trajectory = estimator.trajectory()
        assert trajectory.shape == true_poses.shape
        np.testing.assert_allclose(trajectory[:, :2], true_poses[:, :2], atol=1e-6)
        np.testing.assert_allclose(wrap_angle(trajectory[:, 2] - true_poses[:, 2]), 0.0, atol=1e-6)
        landmarks = estimator.landmarks()
        assert set(landmarks) == set(true_landmarks)
        for lid, xy in true_landmarks.items():
            np.testing.assert_allclose(landmarks[lid], xy, atol=1e-6)
        np.testing.assert_allclose(estimator.current_pose(), trajectory[-1], atol=0)
    expected_unknown = sum(1 for s in steps for o in s.observations if o.landmark_id is None)
    assert expected_unknown > 0
    assert ekf_.skipped_unknown_id == expected_unknown
    assert dr.skipped_unknown_id == expected_unknown
    known = sum(1 for s in steps for o in s.observations if o.landmark_id is not None)
    assert ekf_.updates + ekf_.landmarks_added == known
    assert ekf_.landmarks_added == len(true_landmarks)
    # The robot passed through θ = ±π; headings stay wrapped.
    assert np.all((ekf_.trajectory()[:, 2] >= -math.pi) & (ekf_.trajectory()[:, 2] < math.pi))

    # The default filter associates the id-less copies (JCBB) instead of skipping them:
    # each goes to the landmark whose id its twin carries; the estimate is still exact.
    assoc = EkfSlam(header)
    for step in steps:
        assoc.step(step)
        used = assoc.step_associations()
        assert len(used) == len(step.observations)
        for k, observation in enumerate(step.observations):
            if observation.landmark_id is not None:
                assert used[k] == observation.landmark_id
            else:
                assert used[k] == step.observations[k - 1].landmark_id  # its twin
    np.testing.assert_allclose(assoc.trajectory()[:, :2], true_poses[:, :2], atol=1e-6)
    assert assoc.skipped_unknown_id == 0 and assoc.rejected_observations == 0
    assert assoc.landmarks_created == 0 and set(assoc.landmarks()) == set(true_landmarks)
    assert assoc.updates + assoc.landmarks_added == known + expected_unknown


@pytest.mark.parametrize("seed", [101, 202, 303])
def test_noisy_run_beats_dead_reckoning_and_stays_healthy(seed):
    rng = np.random.default_rng(seed)
    header, steps, true_poses, true_landmarks = simulate_loop(rng, laps=3, unknown_every=5)
    estimator = EkfSlam(header, landmark_capacity=2, association=None)  # the known-ids filter
    for step in steps:
        estimator.step(step)
        mean, P = estimator.state_mean(), estimator.state_covariance()
        assert np.all(np.isfinite(mean))
        assert_symmetric_psd(P)
        assert -math.pi <= mean[2] < math.pi
    dr = run(DeadReckoning(header), steps)
    ekf_ate, dr_ate = ate_m(estimator.trajectory(), true_poses), ate_m(dr.trajectory(), true_poses)
    assert ekf_ate < 0.35 * dr_ate, (ekf_ate, dr_ate)
    assert ekf_ate < 0.15

    def map_rmse(landmarks):
        return math.sqrt(np.mean([np.sum((np.array(landmarks[i]) - true_landmarks[i]) ** 2) for i in true_landmarks]))

    assert map_rmse(estimator.landmarks()) < map_rmse(dr.landmarks())
    assert estimator.skipped_unknown_id > 0
    # Accessors agree with the full state.
    for lid in true_landmarks:
        i = estimator.landmark_index(lid)
        np.testing.assert_array_equal(estimator.landmark_covariance(lid), P[i : i + 2, i : i + 2])
    np.testing.assert_array_equal(estimator.current_covariance(), P[:3, :3])
    # Dead reckoning's covariance only grows and is well formed.
    assert_symmetric_psd(dr.current_covariance())
    assert np.trace(dr.current_covariance()) > np.trace(estimator.current_covariance())


def test_capacity_growth_does_not_change_the_estimate():
    rng = np.random.default_rng(40)
    header, steps, _, _ = simulate_loop(rng, laps=1)
    small = run(EkfSlam(header, landmark_capacity=1), steps)
    large = run(EkfSlam(header, landmark_capacity=1000), steps)
    assert small.capacity < large.capacity
    assert small.capacity >= small.state_mean().size
    np.testing.assert_allclose(small.state_mean(), large.state_mean(), rtol=0, atol=1e-12)
    np.testing.assert_allclose(small.state_covariance(), large.state_covariance(), rtol=0, atol=1e-12)


def test_step_without_observations_and_unknown_only():
    header = make_header((1.0, -1.0, 3.1), (0.1, 0.1, 0.05))
    estimator = EkfSlam(header, association=None)  # the known-ids filter
    np.testing.assert_allclose(estimator.current_covariance(), np.diag([0.01, 0.01, 0.0025]))
    unknown = Observation(0.0, None, 2.0, 0.1, 0.1, 0.01)
    estimator.step(Step(0, 0.0, None, (unknown, unknown), None))
    odo = Odometry(1.0, 0.5, 0.0, 0.2, as_matrix3(np.diag([1e-4, 1e-4, 1e-4])))
    estimator.step(Step(1, 1.0, odo, (), None))
    assert estimator.skipped_unknown_id == 2 and estimator.updates == 0
    assert estimator.landmarks() == {}
    expected = predict_pose((1.0, -1.0, 3.1), (0.5, 0.0, 0.2))
    np.testing.assert_allclose(estimator.current_pose(), expected, atol=1e-12)
    assert estimator.current_pose()[2] < 0  # 3.3 rad wrapped
    assert estimator.trajectory().shape == (2, 3)
    with pytest.raises(KeyError):
        estimator.landmark_covariance(5)


def test_estimators_follow_the_protocol_and_never_import_gtsam():
    header = make_header()
    factories = (
        (EkfSlam, "ekf"),
        (lambda h: EkfSlam(h, association="nn"), "ekf-nn"),
        (lambda h: EkfSlam(h, association=None), "ekf-ids"),
        (DeadReckoning, "dead_reckoning"),
    )
    for cls, name in factories:
        estimator = cls(header)
        assert estimator.name == name
        for method in ("step", "current_pose", "finish", "trajectory", "landmarks"):
            assert callable(getattr(estimator, method))
        assert estimator.trajectory().shape == (0, 3)
    package = pathlib.Path(ekf.__file__).parent
    for source in package.glob("*.py"):
        tree = ast.parse(source.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                names = [node.module or ""]
            else:
                continue
            for name in names:
                root = name.split(".")[0]
                assert root not in {"gtsam", "fgslam", "matplotlib"}, f"{source.name} imports {name}"
