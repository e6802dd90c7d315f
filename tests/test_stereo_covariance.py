"""A 4×4 stereo pixel covariance (issue 42 part 7): the one-row mapping A Σ Aᵀ against a Monte
Carlo of the mapping and against GTSAM's own factor error, ekf-vio's update against the
Kalman update computed by hand (numerical Jacobians), the simulator's correlated noise
against the covariance it was given, and the log's noise read by ``noise_of``."""

from __future__ import annotations

import json
import math

import gtsam
import numpy as np
import pytest

from ekf.stereo_imu_ekf import EkfS003, LABEL_ORDER
from ekf.vio import VioEkf, predict_stereo
from fgslam.noise3d import noise_of, stereo_factor_noise
from slamio.datasets.seed003 import StereoImuNoise
from slamio.datasets.seed003_log import drive_to_log
from slamio.errors import FgslamError
from slamio.log import RunLog, StereoObservation, read_log, write_log
from slamio.se3 import exp_se3
from slamio.sim3d import KITTI_LIKE_BASELINE_M, KITTI_LIKE_CAM_T_IMU, KITTI_LIKE_K, DriveScenario, simulate_drive
from slamio.stereo import MEAN_ROW, mean_row_covariance, rectified_pixel_covariance, stereo_matrix, stereo_pixels

SIGMA = rectified_pixel_covariance(0.3, 1.0, 0.95, column_correlation=0.2)
M = stereo_matrix(KITTI_LIKE_K, KITTI_LIKE_BASELINE_M)
TINY = StereoImuNoise(sigma_v_mps=1e-3, sigma_w_radps=1e-4)


def _tuples(m) -> tuple:
    return tuple(tuple(float(v) for v in row) for row in np.asarray(m))


def test_rectified_pixel_covariance_is_what_it_says():
    c = rectified_pixel_covariance(0.5, 2.0, 0.9, 0.1)
    assert np.sqrt(np.diag(c)).tolist() == [0.5, 2.0, 0.5, 2.0]
    assert c[1, 3] / 4.0 == pytest.approx(0.9) and c[0, 2] / 0.25 == pytest.approx(0.1)
    assert c[0, 1] == c[0, 3] == c[1, 2] == 0.0 and np.all(np.linalg.eigvalsh(c) > 0)
    with pytest.raises(ValueError):
        rectified_pixel_covariance(0.5, 2.0, 1.0)


def test_mean_row_covariance_matches_a_monte_carlo_of_the_mapping():
    rng = np.random.default_rng(42)
    z = rng.multivariate_normal(np.zeros(4), SIGMA, size=400_000)
    mapped = np.column_stack([z[:, 0], z[:, 2], 0.5 * (z[:, 1] + z[:, 3])])  # (u_L, u_R, v), written out
    sample = np.cov(mapped.T)
    expected = mean_row_covariance(SIGMA)
    assert np.allclose(sample, expected, rtol=0.01, atol=0.002)
    # one σ: (σ², σ², σ²/2), the old model
    assert np.allclose(mean_row_covariance(0.7**2 * np.eye(4)), np.diag([0.49, 0.49, 0.245]))
    assert MEAN_ROW.shape == (3, 4)


def test_stereo_factor_noise_is_gtsams_model_of_the_mapped_covariance():
    model = stereo_factor_noise(StereoImuNoise(pixel_covariance=_tuples(SIGMA)))
    assert np.allclose(model.covariance(), mean_row_covariance(SIGMA), rtol=1e-12, atol=1e-15)
    old = stereo_factor_noise(StereoImuNoise(sigma_px=0.8))
    assert np.allclose(old.sigmas(), [0.8, 0.8, 0.8 / math.sqrt(2.0)], rtol=0, atol=0)


def test_gtsams_stereo_factor_error_is_the_mahalanobis_distance_of_u_l_u_r_v():
    """The factor's rows are (u_L, u_R, v): its error for a known pixel residual is ½ rᵀ C⁻¹ r
    with C = A Σ Aᵀ — the order the mapping A assumes."""
    K = KITTI_LIKE_K
    calibration = gtsam.Cal3_S2Stereo(K[0, 0], K[1, 1], 0.0, K[0, 2], K[1, 2], KITTI_LIKE_BASELINE_M)
    point = np.array([1.0, -0.5, 12.0])  # in the camera's optical frame (body = camera here)
    z = stereo_pixels(M, np.append(point, 1.0))  # (u_L, v_L, u_R, v_R), v_L = v_R
    r = np.array([0.4, -0.3, 0.7])  # (u_L, u_R, v)
    measured = gtsam.StereoPoint2(z[0] + r[0], z[2] + r[1], z[1] + r[2])
    model = stereo_factor_noise(StereoImuNoise(pixel_covariance=_tuples(SIGMA)))
    factor = gtsam.GenericStereoFactor3D(measured, model, 0, 1, calibration)
    values = gtsam.Values()
    values.insert(0, gtsam.Pose3())
    values.insert(1, gtsam.Point3(*point))
    expected = 0.5 * r @ np.linalg.solve(mean_row_covariance(SIGMA), r)
    assert factor.error(values) == pytest.approx(expected, rel=1e-9)


def _kalman_by_hand(T, landmarks, P, pixels, R):
    """One EKF update over (δ, m_1, m_2, …) computed from scratch: numerical Jacobians of the
    stereo prediction, S = H P Hᵀ + blockdiag(R), K = P Hᵀ S⁻¹, Σ − K S Kᵀ, T exp(δ̂)."""
    n = P.shape[0]
    eps = 1e-6

    def predicted(x):
        Tx = T @ exp_se3(x[:6])
        return np.concatenate([predict_stereo(Tx, m + x[6 + 3 * i: 9 + 3 * i], KITTI_LIKE_CAM_T_IMU, M)
                               for i, m in enumerate(landmarks)])

    H = np.column_stack([(predicted(e) - predicted(-e)) / (2 * eps) for e in np.eye(n) * eps])
    r = np.concatenate(pixels) - predicted(np.zeros(n))
    S = H @ P @ H.T + np.kron(np.eye(len(landmarks)), R)
    gain = P @ H.T @ np.linalg.inv(S)
    dx = gain @ r
    return T @ exp_se3(dx[:6]), [m + dx[6 + 3 * i: 9 + 3 * i] for i, m in enumerate(landmarks)], P - gain @ S @ gain.T


def test_ekf_vio_update_with_a_4x4_covariance_is_the_kalman_update_by_hand():
    noise = StereoImuNoise(pixel_covariance=_tuples(SIGMA))
    f = VioEkf(KITTI_LIKE_K, KITTI_LIKE_BASELINE_M, KITTI_LIKE_CAM_T_IMU, noise, gate=None, start_sigma=0.05)
    points = [np.array([20.0, 2.0, 1.0]), np.array([14.0, -3.0, 2.0])]
    first = [stereo_pixels(M, KITTI_LIKE_CAM_T_IMU @ np.append(m, 1.0)) for m in points]
    f.step(None, None, [3, 4], np.vstack(first))
    assert f.state_landmark_ids() == [3, 4]
    f._predict(0.5, np.array([2.0, 0.1, 0.0, 0.0, 0.01, 0.05]))  # the pose moves away from the landmarks
    T, P = f.current_pose(), f.state_covariance()
    landmarks = [f.landmarks()[3], f.landmarks()[4]]
    seen = [first[0] + [0.6, -0.4, 0.1, -0.3], first[1] + [-0.2, 0.9, 0.3, 0.8]]
    f.step(None, None, [3, 4], np.vstack(seen))  # no prediction (dt None): the update alone
    T_hand, m_hand, P_hand = _kalman_by_hand(T, landmarks, P, seen, SIGMA)
    assert np.allclose(f.current_pose(), T_hand, atol=1e-8)
    assert np.allclose(f.landmarks()[3], m_hand[0], atol=1e-7) and np.allclose(f.landmarks()[4], m_hand[1], atol=1e-7)
    assert np.allclose(f.state_covariance(), P_hand, rtol=1e-5, atol=1e-7 * np.abs(P_hand).max())  # numerical H
    # the correlation matters: the update with the diagonal alone is another one
    T_diag, _, _ = _kalman_by_hand(T, landmarks, P, seen, np.diag(np.diag(SIGMA)))
    assert np.linalg.norm(T_hand[:3, 3] - T[:3, 3]) > 1e-3
    assert not np.allclose(T_diag, T_hand, atol=1e-5)


def test_ekf_s003_process_role_takes_the_covariance_in_its_rows_order():
    noise = StereoImuNoise(pixel_covariance=_tuples(SIGMA))
    labels = EkfS003(KITTI_LIKE_K, KITTI_LIKE_BASELINE_M, KITTI_LIKE_CAM_T_IMU, noise, v_role="process")
    matrix = EkfS003(KITTI_LIKE_K, KITTI_LIKE_BASELINE_M, KITTI_LIKE_CAM_T_IMU, noise, v_role="process",
                     stereo_rows="matrix")
    assert np.array_equal(matrix._V, SIGMA)
    assert np.array_equal(labels._V, SIGMA[np.ix_(LABEL_ORDER, LABEL_ORDER)])  # rows (u_L, u_R, v_L, v_R)
    assert labels._V[2, 3] == SIGMA[1, 3]


def test_the_simulator_draws_the_pixel_covariance_it_is_given():
    """The same seed with the covariance and with (almost) none: the pixels' difference is
    the drawn noise, whose sample covariance is the one given."""
    scenario = DriveScenario(straight_m=40.0, side_m=20.0, turn_radius_m=8.0, max_features=30)
    noisy = simulate_drive(3, scenario, StereoImuNoise(pixel_covariance=_tuples(SIGMA)))
    clean = simulate_drive(3, scenario, StereoImuNoise(pixel_covariance=_tuples(1e-12 * np.eye(4))))
    seen = ~np.isnan(noisy.features_px[..., 0])
    assert np.array_equal(seen, ~np.isnan(clean.features_px[..., 0]))
    e = (noisy.features_px - clean.features_px)[seen]
    assert len(e) > 3000
    tolerance = 4.0 * np.sqrt((np.outer(np.diag(SIGMA), np.diag(SIGMA)) + SIGMA**2) / len(e))  # 4 standard errors
    assert np.all(np.abs(np.cov(e.T) - SIGMA) < tolerance)
    assert np.allclose(e.mean(axis=0), 0.0, atol=4.0 * np.sqrt(np.diag(SIGMA) / len(e)))


def test_a_logs_pixel_covariance_reaches_the_estimators_and_must_be_one(tmp_path):
    drive = simulate_drive(2, DriveScenario(straight_m=20.0, side_m=10.0, turn_radius_m=5.0))
    header, records = drive_to_log(drive, StereoImuNoise(pixel_covariance=_tuples(SIGMA)))
    write_log(tmp_path / "c.jsonl", header, records)
    log = read_log(tmp_path / "c.jsonl")
    noise = noise_of(log)
    assert np.array_equal(noise.pixel_cov(), SIGMA)
    assert noise.sigma_px == pytest.approx(math.sqrt(np.trace(SIGMA) / 4.0))  # a summary only
    assert "covariance_px2" in json.dumps(log.header.noise)
    i = next(i for i, r in enumerate(records) if isinstance(r, StereoObservation))
    mixed = list(records)
    mixed[i] = StereoObservation(**{**records[i].__dict__, "covariance_px2": None, "sigma_px": 1.0})
    with pytest.raises(FgslamError, match="2 different pixel noises .*same 4×4 pixel covariance"):
        noise_of(RunLog("mixed.jsonl", header, tuple(mixed)))
    with pytest.raises(ValueError, match="exactly one"):
        StereoObservation(**{**records[i].__dict__, "sigma_px": 1.0})


def test_fgslam_import_seed003_states_a_pixel_covariance(tmp_path, capsys):
    from fgslam.cli import main
    from slamio.datasets.seed003 import save_drive

    npz = tmp_path / "drive.npz"
    save_drive(npz, simulate_drive(4, DriveScenario(straight_m=20.0, side_m=10.0, turn_radius_m=5.0)))
    assert main(["import", "seed003", str(npz), str(tmp_path / "a.jsonl"), "--pixel-covariance", "0.3", "1", "0.95"]) == 0
    expected = rectified_pixel_covariance(0.3, 1.0, 0.95)
    assert np.array_equal(noise_of(read_log(tmp_path / "a.jsonl")).pixel_cov(), expected)
    full = [repr(float(v)) for v in SIGMA.ravel()]
    assert main(["import", "seed003", str(npz), str(tmp_path / "b.jsonl"), "--pixel-covariance", *full]) == 0
    assert np.array_equal(noise_of(read_log(tmp_path / "b.jsonl")).pixel_cov(), SIGMA)
    for extra, words in ((["--pixel-covariance", "1", "2"], "takes 3 numbers"),
                         (["--pixel-covariance", "1", "2", "1.5"], "RHO"),
                         (["--pixel-covariance", *(["1"] * 16)], "'covariance_px2' must be positive definite"),
                         (["--pixel-covariance", "1", "2", "0.5", "--pixel-sigma", "1"], "give one of them")):
        assert main(["import", "seed003", str(npz), str(tmp_path / "x.jsonl"), *extra]) == 1
        assert words in capsys.readouterr().err
    assert not (tmp_path / "x.jsonl").exists()


@pytest.fixture(scope="module")
def told_true_and_isotropic():
    """told → estimator → metrics over two small simulated drives whose pixel noise is rectified
    stereo's (σ_u 0.3 px, σ_v 1 px, v_L and v_R correlated 0.95), each run through ``fgslam
    run``'s pipeline told the true covariance, and told one σ = √(trace/4)."""
    from fgslam.runner3d import compute_metrics_3d, run_log3d

    scenario = DriveScenario(straight_m=40.0, side_m=20.0, turn_radius_m=8.0, max_features=20)
    true_cov = rectified_pixel_covariance(0.3, 1.0, 0.95)
    told = {"true": StereoImuNoise(pixel_covariance=_tuples(true_cov)),
            "isotropic": StereoImuNoise(sigma_px=math.sqrt(np.trace(true_cov) / 4.0))}
    names = ["ekf-vio", "ekf-vio-fej", "isam2-3d"]
    out: dict = {k: {n: [] for n in names} for k in told}
    for seed in (1, 2):
        drive = simulate_drive(seed, scenario, told["true"])
        for key, noise in told.items():
            metrics = compute_metrics_3d(run_log3d(RunLog(f"{key}{seed}", *drive_to_log(drive, noise)), names),
                                         log_path=f"{key}{seed}")
            for n in names:
                out[key][n].append(metrics[n])
    return out


def _mean(runs: list, key: str) -> float:
    return float(np.mean([m[key] for m in runs]))


def test_told_the_true_pixel_covariance_the_estimators_are_consistent(told_true_and_isotropic):
    true, isotropic = told_true_and_isotropic["true"], told_true_and_isotropic["isotropic"]
    for name in ("ekf-vio", "ekf-vio-fej"):
        assert 3.8 < _mean(true[name], "nis_mean") < 4.2  # χ²₄: mean 4
        assert _mean(isotropic[name], "nis_mean") < 3.4  # one σ: u over-stated, the row mean v under-stated
        assert _mean(true[name], "nees_inside_95") > 0.97
        assert _mean(isotropic[name], "nees_inside_95") < 0.9
    assert _mean(true["isam2-3d"], "nees_inside_95") > 0.93
    for name in true:  # told one σ, the pose is over-confident: the NEES mean rises
        assert _mean(true[name], "nees_mean") < _mean(isotropic[name], "nees_mean")


def test_told_the_true_pixel_covariance_the_estimators_are_at_least_as_accurate(told_true_and_isotropic):
    true, isotropic = told_true_and_isotropic["true"], told_true_and_isotropic["isotropic"]
    for name in ("ekf-vio", "ekf-vio-fej"):
        assert _mean(true[name], "ate_rmse_m") < 0.8 * _mean(isotropic[name], "ate_rmse_m")
    # the smoother: as accurate within 5 % on these two drives (0.037 m against 0.038 m)
    assert _mean(true["isam2-3d"], "ate_rmse_m") < 1.05 * _mean(isotropic["isam2-3d"], "ate_rmse_m")
