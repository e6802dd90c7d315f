"""ekf.stereo_imu_ekf (seed 003's EKF as written, flaws as keywords) against closed forms and the simulator's truth."""

import numpy as np
import pytest
from scipy.linalg import expm

from ekf.drive3d import position_errors_m, run_drive
from slamio.se3 import curly_hat, exp_se3, hat, inverse
from ekf.stereo_imu_ekf import AS_THE_FIGURES_SHOW, EkfS003, expm_series
from slamio.stereo import projection, stereo_matrix, stereo_pixels
from slamio.datasets.seed003 import StereoImuNoise
from slamio.sim3d import KITTI_LIKE_CAM_T_IMU, KITTI_LIKE_K, DriveScenario, simulate_drive

SMALL = DriveScenario(straight_m=40.0, side_m=20.0, turn_radius_m=8.0)
B = 0.537


@pytest.fixture(scope="module")
def drive():
    return simulate_drive(1, SMALL)


def _filter(**kw):
    return EkfS003(KITTI_LIKE_K, B, KITTI_LIKE_CAM_T_IMU, **kw)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_expm_series_matches_scipy(seed):
    A = np.random.default_rng(seed).normal(size=(4, 4)) * (1 + 3 * seed)
    assert np.allclose(expm_series(A), expm(A), rtol=1e-9, atol=1e-9)


def test_pose_is_the_imu_integral_when_eq16_is_read_as_intended(drive):
    f = run_drive(_filter(**AS_THE_FIGURES_SHOW), drive)
    T = np.eye(4)
    for t in range(drive.n_steps - 1):
        T = T @ exp_se3(drive.dt_s(t) * drive.twist(t))
    assert np.allclose(f.current_pose(), T, atol=1e-9)  # the camera never moves the pose
    assert f.updates > 500 and f.landmarks_added > 100


def test_eq16_as_printed_forgets_the_past(drive):
    """exp(−τ û μ) ≈ exp(−τ û) when μ ≈ I: the pose is only ever the last increment."""
    f = run_drive(_filter(), drive)
    assert np.abs(f.trajectory()[:, :3, 3]).max() < 1.0  # a 170 m drive never leaves the origin
    t = drive.n_steps - 2
    last_increment = exp_se3(drive.dt_s(t) * drive.twist(t))[:3, 3]
    assert np.linalg.norm(f.current_pose()[:3, 3] - last_increment) < 0.1
    one = _filter()
    U = exp_se3([1.0, 2.0, 0.0, 0.0, 0.0, 0.5])
    one._U = U.copy()
    one.step(0.1, np.array([8.0, 0, 0, 0, 0, 0.3]), [], np.zeros((0, 4)))
    assert np.allclose(np.linalg.inv(one.current_pose()), expm(-0.1 * hat([8.0, 0, 0, 0, 0, 0.3]) @ U))


def test_pose_covariance_follows_eq17():
    f = _filter(**AS_THE_FIGURES_SHOW)
    u = np.array([8.0, 0.1, 0.0, 0.01, 0.0, 0.2])
    f.step(None, None, [], np.zeros((0, 4)))
    f.step(0.1, u, [], np.zeros((0, 4)))
    f.step(0.1, u, [], np.zeros((0, 4)))
    F = expm(-0.1 * curly_hat(u))
    W = StereoImuNoise().velocity_cov() * 0.01
    assert np.allclose(f.current_covariance(), F @ W @ F.T + W)


def test_new_landmark_is_back_projected_through_the_pose():
    f = _filter(**AS_THE_FIGURES_SHOW)
    f.step(None, None, [], np.zeros((0, 4)))
    f.step(1.0, np.array([5.0, 0.0, 0.0, 0.0, 0.0, 0.2]), [], np.zeros((0, 4)))
    world_T_imu = f.current_pose()
    m = np.array([12.0, 4.0, 1.5])
    q = KITTI_LIKE_CAM_T_IMU @ inverse(world_T_imu) @ np.append(m, 1.0)
    z = stereo_pixels(stereo_matrix(KITTI_LIKE_K, B), q)
    f.step(1e-9, np.zeros(6), [7], z[None])
    assert np.allclose(f.landmarks()[7], m, atol=1e-6)
    assert f.landmarks_added == 1
    f.step(1e-9, np.zeros(6), [8], np.array([[600.0, 100.0, 600.0, 100.0]]))  # zero disparity: no depth
    assert f.skipped_no_disparity == 1 and 8 not in f.landmarks()


def _one_update(m_true, m_est, **kw):
    """A filter at the identity pose with landmark 0 at ``m_est``, updated with the pixels of ``m_true``."""
    f = _filter(**kw)
    M = stereo_matrix(KITTI_LIKE_K, B)
    z_est = stereo_pixels(M, KITTI_LIKE_CAM_T_IMU @ np.append(m_est, 1.0))
    f.step(None, None, [0], z_est[None])
    z = stereo_pixels(M, KITTI_LIKE_CAM_T_IMU @ np.append(m_true, 1.0))
    Sigma0 = f.landmark_covariance(0)
    f.step(1e-12, np.zeros(6), [0], z[None])
    return f, z, Sigma0


def test_mapping_update_is_eqs_20_to_23_with_the_numerical_jacobian():
    m_est = np.array([15.0, 2.0, 1.0])
    m_true = m_est + np.array([0.3, -0.2, 0.1])
    f, z, Sigma0 = _one_update(m_true, m_est, **AS_THE_FIGURES_SHOW)
    M = stereo_matrix(KITTI_LIKE_K, B)

    def h(m):
        return M @ projection(KITTI_LIKE_CAM_T_IMU @ np.append(m, 1.0))

    H = np.stack([(h(m_est + e) - h(m_est - e)) / 2e-6 for e in np.eye(3) * 1e-6], axis=1)
    K = Sigma0 @ H.T @ np.linalg.inv(H @ Sigma0 @ H.T + 3000.0 * np.eye(4))
    assert np.allclose(f.landmarks()[0], m_est + K @ (z - h(m_est)), atol=1e-6)
    assert np.allclose(f.landmark_covariance(0), (np.eye(3) - K @ H) @ Sigma0, atol=1e-9)


def test_eq1_label_order_crosses_rows_and_eq11_collapses_the_covariance():
    m = np.array([15.0, 2.0, 1.0])
    # a perfect measurement: no change with M's row order, a wrong change with eq. 1's labels
    f, _, _ = _one_update(m, m, **AS_THE_FIGURES_SHOW)
    assert np.allclose(f.landmarks()[0], m, atol=1e-9)
    f, _, _ = _one_update(m, m, eq16_literal=False)
    assert np.linalg.norm(f.landmarks()[0] - m) > 0.1
    f, _, Sigma0 = _one_update(m, m, eq16_literal=False, stereo_rows="matrix", covariance_update="eq11")
    assert np.all(np.linalg.eigvalsh(f.landmark_covariance(0)) < 1e-3 * np.linalg.eigvalsh(Sigma0).min())


def test_v_as_process_noise_uses_the_pixel_noise_in_the_update():
    m_est = np.array([15.0, 2.0, 1.0])
    m_true = m_est + np.array([0.3, -0.2, 0.1])
    paper, _, _ = _one_update(m_true, m_est, **AS_THE_FIGURES_SHOW)
    process, _, _ = _one_update(m_true, m_est, v_role="process", **AS_THE_FIGURES_SHOW)
    # 1 px² instead of 3000 px²: one update moves the landmark most of the way
    assert np.linalg.norm(process.landmarks()[0] - m_true) < 0.5 * np.linalg.norm(paper.landmarks()[0] - m_true)


def test_bad_choices_are_refused():
    with pytest.raises(ValueError, match="stereo_rows"):
        _filter(stereo_rows="columns")
    with pytest.raises(ValueError, match="covariance_update"):
        _filter(covariance_update="eq12")


def test_measured_cost_on_a_simulated_drive(drive):
    """The as-written filter is far off; with the typos read as intended it is dead reckoning."""
    ates = {}
    for name, kw in {"paper": {}, "figures": AS_THE_FIGURES_SHOW}.items():
        f = run_drive(_filter(**kw), drive)
        ates[name] = position_errors_m(f.trajectory(), drive.truth_world_T_imu)[0]
    assert ates["paper"] > 20.0 * ates["figures"]
    assert ates["figures"] < 1.0
