"""ekf.vio (visual-inertial EKF-SLAM on SE(3)): Jacobians vs numerical ones, estimates vs the simulator's truth."""

import numpy as np
import pytest
from scipy.linalg import expm

from ekf.drive3d import position_errors_m, run_drive, steps_of
from slamio.se3 import adjoint, curly_hat, exp_se3, log_se3, skew
from slamio.stereo import point_from_stereo, stereo_matrix, stereo_pixels
from ekf.vio import (
    VioEkf,
    constrained_jacobians,
    observation_jacobians,
    pose_nees,
    predict_stereo,
    right_jacobian_se3,
)
from slamio.sim3d import KITTI_LIKE_CAM_T_IMU, KITTI_LIKE_K, DriveScenario, simulate_drive

SMALL = DriveScenario(straight_m=40.0, side_m=20.0, turn_radius_m=8.0)
M = stereo_matrix(KITTI_LIKE_K, 0.537)
T0 = exp_se3([3.0, -1.0, 0.4, 0.05, -0.02, 0.8])


def _world_point(distance_ahead=18.0):
    return (T0 @ np.array([distance_ahead, 3.0, 1.0, 1.0]))[:3]


def test_observation_jacobians_match_numerical_ones():
    m = _world_point()
    J_pose, J_m = observation_jacobians(T0, m, KITTI_LIKE_CAM_T_IMU, M)
    eps = 1e-6
    num_pose = np.stack(
        [(predict_stereo(T0 @ exp_se3(e), m, KITTI_LIKE_CAM_T_IMU, M) - predict_stereo(T0 @ exp_se3(-e), m, KITTI_LIKE_CAM_T_IMU, M)) / (2 * eps) for e in np.eye(6) * eps],
        axis=1,
    )
    num_m = np.stack(
        [(predict_stereo(T0, m + e, KITTI_LIKE_CAM_T_IMU, M) - predict_stereo(T0, m - e, KITTI_LIKE_CAM_T_IMU, M)) / (2 * eps) for e in np.eye(3) * eps],
        axis=1,
    )
    assert np.allclose(J_pose, num_pose, rtol=1e-5, atol=1e-4)
    assert np.allclose(J_m, num_m, rtol=1e-5, atol=1e-5)


def test_right_jacobian_and_the_prediction_matrix():
    xi = np.array([0.8, 0.02, -0.01, 0.01, -0.02, 0.05])
    d = np.array([1e-6, -2e-6, 1e-6, 3e-7, -1e-7, 2e-7])
    assert np.allclose(log_se3(np.linalg.inv(exp_se3(xi)) @ exp_se3(xi + d)), right_jacobian_se3(xi) @ d, atol=1e-12)
    assert np.allclose(adjoint(exp_se3(-xi)), expm(-curly_hat(xi)), atol=1e-12)  # F = exp(−τÛ)


def test_landmark_initialisation_jacobians():
    """A = ∂m/∂δ and B = ∂m/∂z as used in VioEkf._add, against numerical derivatives."""
    imu_T_cam = np.linalg.inv(KITTI_LIKE_CAM_T_IMU)
    m = _world_point()
    z = predict_stereo(T0, m, KITTI_LIKE_CAM_T_IMU, M)

    def back(T, zz):
        p = imu_T_cam @ np.append(point_from_stereo(zz, KITTI_LIKE_K, 0.537), 1.0)
        return (T @ p)[:3]

    p_imu = (imu_T_cam @ np.append(point_from_stereo(z, KITTI_LIKE_K, 0.537), 1.0))[:3]
    A = T0[:3, :3] @ np.hstack([np.eye(3), -skew(p_imu)])
    eps = 1e-6
    num_A = np.stack([(back(T0 @ exp_se3(e), z) - back(T0 @ exp_se3(-e), z)) / (2 * eps) for e in np.eye(6) * eps], axis=1)
    assert np.allclose(A, num_A, atol=1e-6)
    assert np.allclose(back(T0, z), m, atol=1e-9)


@pytest.fixture(scope="module")
def drive():
    return simulate_drive(1, SMALL)


@pytest.fixture(scope="module")
def run(drive):
    f = VioEkf(drive.K, drive.baseline_m, drive.cam_T_imu)
    nees = []
    for k, args in enumerate(steps_of(drive)):
        f.step(*args)
        nees.append(pose_nees(f.current_pose(), f.current_covariance(), drive.truth_world_T_imu[k]))
    return f, np.array(nees[1:])


def test_estimates_beat_dead_reckoning_against_truth(drive, run):
    f, _ = run
    dr = np.eye(4)
    dead = [dr]
    for t in range(drive.n_steps - 1):
        dr = dr @ exp_se3(drive.dt_s(t) * drive.twist(t))
        dead.append(dr)
    ate_vio = position_errors_m(f.trajectory(), drive.truth_world_T_imu)[0]
    ate_dead = position_errors_m(np.array(dead), drive.truth_world_T_imu)[0]
    assert ate_vio < 0.5 * ate_dead
    assert ate_vio < 0.2
    errors = [np.linalg.norm(m - drive.truth_landmarks_m[j]) for j, m in f.landmarks().items()]
    assert np.median(errors) < 0.3


def test_innovations_are_consistent(run):
    f, nees = run
    assert 3.6 < f.nis().mean() < 4.4  # NIS ~ χ²₄
    assert f.rejected < 0.01 * len(f.nis())
    # the pose NEES (χ²₆, mean 6) is consistent while the drive is short; see docs/seed003.md
    assert 2.0 < nees[:100].mean() < 12.0


def test_a_point_ahead_is_seen_where_the_stereo_model_says():
    f = VioEkf(KITTI_LIKE_K, 0.537, KITTI_LIKE_CAM_T_IMU)
    m = np.array([20.0, 2.0, 1.0])
    z = stereo_pixels(M, KITTI_LIKE_CAM_T_IMU @ np.append(m, 1.0))
    f.step(None, None, [3], z[None])
    assert np.allclose(f.landmarks()[3], m)
    f.step(0.1, np.zeros(6), [3, 4], np.vstack([z, [600.0, 100.0, 598.0, 100.0]]))
    assert f.skipped_small_disparity == 1 and f.updates == 1


def _information_along_global_motions(ekf, *, first_estimates: bool) -> np.ndarray:
    """Nᵀ Σ⁻¹ N (6×6) with N the directions of a rigid motion of the whole world: the pose's
    right perturbation Ad(T⁻¹)δ and each landmark's [I, −m^]δ (no gravity: none observable).
    With first-estimate Jacobians N is built at the first estimates, else at the current ones."""
    T = ekf._T_fe if first_estimates else ekf._T
    rows = [adjoint(np.linalg.inv(T))]
    for lid, slot in sorted(ekf._slot.items(), key=lambda item: item[1]):
        m = ekf._m_fe[lid] if first_estimates else ekf._x[3 * slot : 3 * slot + 3]
        rows.append(np.hstack([np.eye(3), -skew(m)]))
    N = np.vstack(rows)
    return N.T @ np.linalg.solve(ekf._P, N)


def test_projected_jacobians_are_blind_to_a_rigid_motion_and_exact_at_the_first_estimate():
    T = exp_se3(np.array([3.0, -1.0, 0.2, 0.02, -0.01, 0.4]))
    m_first = T[:3, :3] @ np.array([25.0, 4.0, 1.0]) + T[:3, 3]
    m_now = m_first + T[:3, :3] @ np.array([3.0, 0.3, -0.2])  # the depth corrected by 3 m since
    U = np.vstack([adjoint(np.linalg.inv(T)), np.hstack([np.eye(3), -skew(m_first)])])
    J_pose, J_m = constrained_jacobians(T, m_now, m_first, KITTI_LIKE_CAM_T_IMU, M)
    assert np.allclose(np.hstack([J_pose, J_m]) @ U, 0.0, atol=1e-9)
    # the exact Jacobians at one point are blind already (z depends on T⁻¹m only): unchanged
    exact = observation_jacobians(T, m_first, KITTI_LIKE_CAM_T_IMU, M)
    same = constrained_jacobians(T, m_first, m_first, KITTI_LIKE_CAM_T_IMU, M)
    assert np.allclose(same[0], exact[0], atol=1e-9) and np.allclose(same[1], exact[1], atol=1e-9)
    # of the Jacobians blind to N (plain FEJ's among them), the projection is the nearest to the
    # Jacobian at the current estimate
    now = np.hstack(observation_jacobians(T, m_now, KITTI_LIKE_CAM_T_IMU, M))
    assert np.linalg.norm(np.hstack([J_pose, J_m]) - now) < np.linalg.norm(np.hstack(exact) - now)


@pytest.mark.parametrize(("first_estimates", "projected"), [(False, True), (True, True), (True, False)])
def test_first_estimate_jacobians_gain_no_information_on_unobservable_directions(first_estimates, projected):
    """The test behind ekf-vio-fej: the camera and the IMU cannot see where the world is, so
    no update may add information along N (an exact property of the linearised system: its
    prior information there, 100 = 1/0.1², must only fall). The standard EKF linearises at
    moving estimates and gains millions; with first-estimate Jacobians nothing is gained."""
    drive = simulate_drive(3, SMALL)
    ekf = VioEkf(drive.K, drive.baseline_m, drive.cam_T_imu, start_sigma=0.1, first_estimates=first_estimates,
                 projected_jacobians=projected)
    gained = []
    for t, args in enumerate(steps_of(drive)):
        ekf.step(*args)
        if t == 0:
            prior = _information_along_global_motions(ekf, first_estimates=first_estimates)
        elif t in (20, 60):
            info = _information_along_global_motions(ekf, first_estimates=first_estimates)
            gained.append(np.linalg.eigvalsh(info - prior).max())
        if t == 60:
            break
    if first_estimates:
        assert max(gained) < 1e-6 * 100.0
    else:
        assert min(gained) > 1e3


def test_first_estimate_jacobians_keep_the_estimate_close_to_the_standard_one():
    drive = simulate_drive(2, SMALL)
    standard = run_drive(VioEkf(drive.K, drive.baseline_m, drive.cam_T_imu), drive)
    fej = run_drive(VioEkf(drive.K, drive.baseline_m, drive.cam_T_imu, first_estimates=True), drive)
    assert fej.name == "ekf-vio-fej"
    a_std, _ = position_errors_m(standard.trajectory(), drive.truth_world_T_imu)
    a_fej, _ = position_errors_m(fej.trajectory(), drive.truth_world_T_imu)
    assert a_fej < 2.0 * a_std + 0.05 and 3.0 < np.mean(fej.nis()) < 5.0
