"""slamio.datasets.seed003 (the seed's npz layout) and slamio.sim3d (simulated drives with truth)."""

import numpy as np
import pytest

from slamio.se3 import exp_se3, inverse
from slamio.stereo import stereo_matrix, stereo_pixels
from slamio.datasets.seed003 import DriveFormatError, load_drive, save_drive
from slamio.sim3d import DriveScenario, simulate_drive

SMALL = DriveScenario(straight_m=40.0, side_m=20.0, turn_radius_m=8.0)


@pytest.fixture(scope="module")
def drive():
    return simulate_drive(1, SMALL)


def _write_layout(path, **override):
    T, M = 5, 3
    features = -np.ones((4, M, T))
    features[:, 0, 1] = [600.0, 180.0, 590.0, 180.0]
    arrays = {
        "time_stamps": (1.3e9 + 0.1 * np.arange(T)).reshape(1, T),
        "features": features,
        "linear_velocity": np.ones((3, T)),
        "rotational_velocity": np.zeros((3, T)),
        "K": np.array([[700.0, 0, 600], [0, 700.0, 180], [0, 0, 1]]),
        "b": np.array(0.5),
        "cam_T_imu": np.eye(4),
    }
    arrays.update(override)
    arrays = {k: v for k, v in arrays.items() if v is not None}
    np.savez(path, **arrays)
    return path


def test_reads_the_layout_step_major(tmp_path):
    d = load_drive(_write_layout(tmp_path / "d.npz"))
    assert d.n_steps == 5 and d.n_landmarks == 3
    assert list(d.seen(1)) == [0] and list(d.seen(0)) == []
    assert np.allclose(d.features_px[1, 0], [600.0, 180.0, 590.0, 180.0])
    assert np.isnan(d.features_px[0, 0]).all()
    assert np.allclose(d.twist(2), [1, 1, 1, 0, 0, 0]) and d.dt_s(0) == pytest.approx(0.1)
    assert d.truth_world_T_imu is None


@pytest.mark.parametrize(
    "override, key, words",
    [
        ({"K": None}, "K", "missing"),
        ({"features": -np.ones((3, 3, 5))}, "features", "expected (4, M, 5)"),
        ({"linear_velocity": np.ones((3, 4))}, "linear_velocity", "expected (3, 5)"),
        ({"time_stamps": np.array([[0.0, 0.1, 0.1, 0.3, 0.4]])}, "time_stamps", "not strictly increasing at step 2"),
        ({"b": np.array(-0.5)}, "b", "positive"),
        ({"cam_T_imu": 2 * np.eye(4)}, "cam_T_imu", "last row"),
        ({"rotational_velocity": np.full((3, 5), np.nan)}, "rotational_velocity", "non-finite"),
    ],
)
def test_bad_input_names_file_key_and_problem(tmp_path, override, key, words):
    path = _write_layout(tmp_path / "bad.npz", **override)
    with pytest.raises(DriveFormatError) as err:
        load_drive(path)
    message = str(err.value)
    assert str(path) in message and f"key '{key}'" in message and words in message
    assert "\n" not in message


def test_partial_minus_one_and_non_npz_are_refused(tmp_path):
    features = -np.ones((4, 3, 5))
    features[0, 1, 2] = 100.0
    with pytest.raises(DriveFormatError, match="landmark 1 at step 2"):
        load_drive(_write_layout(tmp_path / "p.npz", features=features))
    (tmp_path / "x.npz").write_text("not a zip")
    with pytest.raises(DriveFormatError, match="not a readable numpy .npz"):
        load_drive(tmp_path / "x.npz")
    with pytest.raises(DriveFormatError, match="no such file"):
        load_drive(tmp_path / "none.npz")


def test_save_then_load_round_trip_and_no_silent_overwrite(tmp_path, drive):
    path = tmp_path / "sim.npz"
    save_drive(path, drive)
    back = load_drive(path)
    assert np.array_equal(np.isnan(back.features_px), np.isnan(drive.features_px))
    assert np.allclose(np.nan_to_num(back.features_px), np.nan_to_num(drive.features_px))
    assert np.allclose(back.truth_world_T_imu, drive.truth_world_T_imu)
    assert np.allclose(back.truth_landmarks_m, drive.truth_landmarks_m)
    assert np.allclose(back.linear_velocity_mps, drive.linear_velocity_mps)
    with pytest.raises(DriveFormatError, match="overwrite"):
        save_drive(path, drive)
    save_drive(path, drive, overwrite=True)


def test_simulation_is_deterministic_and_closes_its_loop(drive):
    again = simulate_drive(1, SMALL)
    assert np.array_equal(np.nan_to_num(again.features_px), np.nan_to_num(drive.features_px))
    assert not np.allclose(np.nan_to_num(simulate_drive(2, SMALL).features_px), np.nan_to_num(drive.features_px))
    start, end = drive.truth_world_T_imu[0, :3, 3], drive.truth_world_T_imu[-1, :3, 3]
    assert np.linalg.norm(end - start) < 3.0  # a loop of ~150 m returns within a few metres


def test_truth_poses_follow_the_true_twist_and_features_the_truth(drive):
    """The noisy IMU integrates to near the truth; noiseless pixels would be exact projections."""
    # truth is exp-integrated from the true twist, which the measured one equals up to noise
    T = drive.truth_world_T_imu
    for t in (0, 50, 100):
        step = inverse(T[t]) @ T[t + 1]
        measured = exp_se3(drive.dt_s(t) * drive.twist(t))
        assert np.allclose(step[:3, 3], measured[:3, 3], atol=0.05)
    M = stereo_matrix(drive.K, drive.baseline_m)
    residuals = []
    for t in range(0, drive.n_steps, 7):
        for j in drive.seen(t):
            q = drive.cam_T_imu @ inverse(T[t]) @ np.append(drive.truth_landmarks_m[j], 1.0)
            residuals.append(drive.features_px[t, j] - stereo_pixels(M, q))
    residuals = np.array(residuals)
    assert len(residuals) > 200
    assert np.abs(residuals.mean(axis=0)).max() < 0.2
    assert np.allclose(residuals.std(axis=0), 1.0, atol=0.15)  # σ_px = 1
