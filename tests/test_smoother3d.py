"""fgslam.smoother3d: the stereo+IMU factor graph — GTSAM's model vs ekf's, iSAM2 vs batch, estimates vs truth."""

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import L, X

from ekf.drive3d import position_errors_m, run_drive
from slamio.se3 import exp_se3, inverse
from slamio.stereo import stereo_matrix
from ekf.vio import VioEkf, predict_stereo
from fgslam.smoother3d import StereoIsam2, batch_solve, gtsam_covariance, imu_increment_covariance
from slamio.datasets.seed003 import StereoImuNoise
from slamio.sim3d import KITTI_LIKE_CAM_T_IMU, KITTI_LIKE_K, DriveScenario, simulate_drive

SMALL = DriveScenario(straight_m=40.0, side_m=20.0, turn_radius_m=8.0)


def test_gtsam_stereo_factor_predicts_what_ekf_predicts():
    """The twin's measurement model is the EKF's: same (u_L, u_R, v) for the same pose and point."""
    T = exp_se3([3.0, -1.0, 0.4, 0.05, -0.02, 0.8])
    m = (T @ np.array([18.0, 3.0, 1.0, 1.0]))[:3]
    z = predict_stereo(T, m, KITTI_LIKE_CAM_T_IMU, stereo_matrix(KITTI_LIKE_K, 0.537))
    smoother = StereoIsam2(KITTI_LIKE_K, 0.537, KITTI_LIKE_CAM_T_IMU)
    factor = gtsam.GenericStereoFactor3D(
        gtsam.StereoPoint2(z[0], z[2], z[1]),
        gtsam.noiseModel.Unit.Create(3),
        X(0),
        L(0),
        smoother._calibration,
        smoother._body_P_sensor,
    )
    values = gtsam.Values()
    values.insert(X(0), gtsam.Pose3(T))
    values.insert(L(0), gtsam.Point3(m))
    assert factor.error(values) == pytest.approx(0.0, abs=1e-12)
    values.update(L(0), gtsam.Point3(m + np.array([0.0, 0.0, 0.5])))
    assert factor.error(values) > 1.0


def test_between_covariance_is_the_ekf_process_noise_in_gtsam_order():
    u = np.array([8.0, 0.1, 0.0, 0.01, 0.0, 0.2])
    cov = imu_increment_covariance(0.1, u, StereoImuNoise().velocity_cov())
    g = gtsam_covariance(cov)
    assert np.allclose(g[:3, :3], cov[3:, 3:]) and np.allclose(g[3:, 3:], cov[:3, :3]) and np.allclose(g[:3, 3:], cov[3:, :3])


@pytest.fixture(scope="module")
def drive():
    return simulate_drive(1, SMALL)


@pytest.fixture(scope="module")
def smoothed(drive):
    s = run_drive(StereoIsam2(drive.K, drive.baseline_m, drive.cam_T_imu), drive)
    online = s.trajectory().copy()
    s.finish()
    return s, online, batch_solve(s)


def test_isam2_reaches_the_batch_optimum(smoothed):
    s, _, batch = smoothed
    assert s.error() == pytest.approx(batch.error, rel=1e-3)
    assert np.allclose(s.smoothed_trajectory()[:, :3, 3], batch.trajectory()[:, :3, 3], atol=0.01)


def test_an_update_that_fails_starts_isam2_again_and_ends_at_the_same_optimum(drive, smoothed):
    """A singular update (here: the next update made to raise, as GTSAM's
    IndeterminantLinearSystemException does) rebuilds iSAM2 from the whole graph; the run goes
    on and its final estimate is the same optimum as the unbroken run's."""
    from ekf.drive3d import steps_of

    class Failing:
        def __init__(self, isam):
            self.isam, self.failed = isam, False

        def update(self, *args):
            if not self.failed:
                self.failed = True
                raise RuntimeError("Indeterminant linear system detected")
            return self.isam.update(*args)

        def __getattr__(self, name):
            return getattr(self.isam, name)

    s = StereoIsam2(drive.K, drive.baseline_m, drive.cam_T_imu)
    for t, args in enumerate(steps_of(drive)):
        if t == 40:
            s._isam = Failing(s._isam)
        s.step(*args)
    assert s.rebuilds == 1
    s.finish()
    unbroken, _, batch = smoothed
    assert s.error() == pytest.approx(batch.error, rel=1e-6)
    assert np.allclose(s.smoothed_trajectory()[:, :3, 3], unbroken.smoothed_trajectory()[:, :3, 3], atol=1e-4)


def test_estimates_against_truth(drive, smoothed):
    s, online, batch = smoothed
    truth = drive.truth_world_T_imu
    ekf = run_drive(VioEkf(drive.K, drive.baseline_m, drive.cam_T_imu), drive)
    ate_online = position_errors_m(online, truth)[0]
    ate_batch = position_errors_m(batch.trajectory(), truth)[0]
    assert ate_batch < 0.15 and ate_online < 0.2
    assert ate_batch <= position_errors_m(ekf.trajectory(), truth)[0]
    errors = [np.linalg.norm(m - drive.truth_landmarks_m[j]) for j, m in batch.landmarks().items()]
    assert np.median(errors) < 0.25
    assert np.allclose(online[0], np.eye(4), atol=1e-5)


@pytest.mark.slow
def test_huber_resists_outlier_tracks():
    d = simulate_drive(2, DriveScenario(straight_m=40.0, side_m=20.0, turn_radius_m=8.0, outlier_rate=0.05))
    ates = {}
    for robust in ("huber", "none"):
        # σ = 10 m landmark priors: without a robust kernel the 1 km default leaves a
        # landmark pushed behind the camera by an outlier indeterminate
        s = run_drive(StereoIsam2(d.K, d.baseline_m, d.cam_T_imu, robust=robust, landmark_prior_sigma_m=10.0), d)
        s.finish()
        ates[robust] = position_errors_m(batch_solve(s).trajectory(), d.truth_world_T_imu)[0]
    assert ates["huber"] < 0.15 < 1.0 < ates["none"]
