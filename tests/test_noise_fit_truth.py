"""slamio.noise.fit_truth.fit_noise_model against an independent reference: a synthetic MRCLAM run.

tests/mrclam_synth.py writes an MRCLAM dataset folder (the published five-file layout) from
a seeded generator with a known motion and sensor model (:class:`mrclam_synth.Truth`):

* motion: the commands delayed by 0.2 s, at 0.93 × the forward and 0.95 × the turn rate,
  plus -0.04 rad per metre driven (integrated at 1 ms; Vicon truth at 100 Hz);
* camera: pictures every ~0.25 s stamped 0.03 s late; depth ``1.03·r·cos b + 0.02`` with
  σ = 0.01·r, bearing ``0.99·b − 0.002`` with σ = 0.006 rad; 1 % gross outliers.

The run is imported as a user would (``import_mrclam``, ``write_log``/``read_log``), the
model is fitted and compared with the numbers the data were made with. Tolerances:

* lag and latency are picked on 10 ms grids: within 0.03 s / 0.02 s (one to three grid
  steps; in practice the fit finds the grid point of the truth).
* forward and turn scales within 1 %, turn_per_m within 0.01 rad/m: ~300 windows of 1 s
  over ~20 m and ~150 commands. The log's odometry is composed into one increment per pose
  (≤ 0.5 s) and the fit reads it at constant velocity within a pose, so a command change
  inside a pose costs a little; the residual bias is ~0.5 % on the turn scale.
* range and bearing scales within 1 %, biases within 1 cm / 2 mrad: ~2000 readings at
  σ ≈ 1-6 cm and 6 mrad give standard errors of ~0.1 % on the slopes.
* σ within 30 %: σ² is a regression on a few thousand squared residuals (relative
  standard error of a σ estimate from n samples is ~1/√(2n), a few %); the split between
  the constant and the per-metre / per-rad/s terms is poorly determined (few readings
  below 1.5 m; the truth has no turn-rate term), so the σ are compared where the data are:
  at ranges of 2-6 m and turn rates of 0-0.5 rad/s.
* outlier_rate within a factor 2 of the share of gross errors actually drawn (the 5σ gate
  on residuals pooled over ranges with σ growing with range can count a few far inliers
  and miss a few gross errors that happened to land near the truth).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import mrclam_synth as synth
from slamio.datasets.mrclam import import_mrclam
from slamio.geometry import compose_pose, wrap_angle
from slamio.log import TruthLandmark, TruthPose, read_log, write_log
from slamio.noise.dead_reckoning import DeadReckoning, turn_rate_radps
from slamio.noise.errors import NoiseModelError
from slamio.noise.fit_truth import fit_noise_model
from slamio.noise.model import NoiseModel, load_noise_model, save_noise_model

TRUTH = synth.Truth()
DURATION_S = 300.0


def import_log(folder, robot, path, model=None):
    header, records = import_mrclam(folder, robot, model=model)
    write_log(path, header, records)
    return read_log(path)


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    """One folder, two robots (different seeds and paths) in the same room."""
    folder = tmp_path_factory.mktemp("MRCLAM_Synth")
    run1 = synth.write_dataset(folder, seed=11, robot=1, duration_s=DURATION_S)
    run2 = synth.write_dataset(folder, seed=12, robot=2, duration_s=DURATION_S, landmarks=run1.landmarks)
    return folder, {1: run1, 2: run2}


@pytest.fixture(scope="module")
def raw_logs(dataset, tmp_path_factory):
    folder, _ = dataset
    out = tmp_path_factory.mktemp("logs")
    return {robot: import_log(folder, robot, out / f"robot{robot}.jsonl") for robot in (1, 2)}


@pytest.fixture(scope="module")
def fitted(raw_logs):
    return fit_noise_model([raw_logs[1]])


@pytest.fixture(scope="module")
def corrected_log(dataset, fitted, tmp_path_factory):
    folder, _ = dataset
    return import_log(folder, 1, tmp_path_factory.mktemp("corrected") / "robot1.jsonl", fitted)


def check_recovered(model: NoiseModel, outlier_share: float) -> None:
    o, b = model.odometry, model.observation
    assert abs(o.lag_s - TRUTH.lag_s) <= 0.03
    assert o.forward_scale == pytest.approx(TRUTH.forward_scale, rel=0.01)
    assert o.turn_scale == pytest.approx(TRUTH.turn_scale, rel=0.01)
    assert abs(o.turn_per_m_rad - TRUTH.turn_per_m_rad) <= 0.01
    assert b.range_is_depth is True
    assert b.range_scale == pytest.approx(TRUTH.range_scale, rel=0.01)
    assert abs(b.range_bias_m - TRUTH.range_bias_m) <= 0.01
    assert b.bearing_scale == pytest.approx(TRUTH.bearing_scale, rel=0.01)
    assert abs(b.bearing_bias_rad - TRUTH.bearing_bias_rad) <= 0.002
    assert abs(b.camera_latency_s - TRUTH.camera_latency_s) <= 0.02
    for r in (2.0, 3.0, 4.0, 6.0):  # truth: σ = 0.01·r, no constant term
        assert b.sigma_range_m(r) == pytest.approx(TRUTH.range_sigma_per_m * r, rel=0.3), r
    assert b.range_sigma_per_m == pytest.approx(TRUTH.range_sigma_per_m, rel=0.3)
    for w in (0.0, 0.25, 0.5):  # truth: 6 mrad whatever the turn rate
        assert b.sigma_bearing_rad(w) == pytest.approx(TRUTH.bearing_sigma_rad, rel=0.3), w
    assert outlier_share / 2 <= b.outlier_rate <= 2 * outlier_share


# ----------------------------------------------------------------------------- the generator


def test_the_synthetic_folder_has_the_published_layout(dataset):
    folder, runs = dataset
    for name in ("Barcodes.dat", "Landmark_Groundtruth.dat", "Robot1_Odometry.dat", "Robot1_Measurement.dat",
                 "Robot1_Groundtruth.dat", "Robot2_Odometry.dat"):
        lines = (folder / name).read_text().splitlines()
        assert all(line.startswith("#") for line in lines[:4]) and not lines[4].startswith("#"), name
    odometry = np.loadtxt(folder / "Robot1_Odometry.dat")
    rate = 1.0 / np.median(np.diff(odometry[:, 0]))
    assert 60 < rate < 75  # ~67 Hz like MRCLAM
    assert 0.0 <= odometry[:, 1].min() and odometry[:, 1].max() <= 0.15
    assert np.abs(odometry[:, 2]).max() <= 0.5
    assert (odometry[:, 1:] == 0).all(axis=1).mean() > 0.03  # some stops
    assert ((odometry[:, 2] == 0) & (odometry[:, 1] > 0)).mean() > 0.1  # some straight stretches
    vicon = np.loadtxt(folder / "Robot1_Groundtruth.dat")
    assert np.median(np.diff(vicon[:, 0])) == pytest.approx(0.01, abs=1e-6)
    for run in runs.values():
        assert run.n_readings > 1200 and 0.004 < run.n_outliers / run.n_readings < 0.02


# ----------------------------------------------------------------------------- the fit


def test_the_fit_recovers_the_model(dataset, fitted, raw_logs):
    _, runs = dataset
    check_recovered(fitted, runs[1].n_outliers / runs[1].n_readings)
    assert fitted.fitted_on == (raw_logs[1].path,)
    report = fitted.fit_report
    assert report["odometry"]["windows"] > 200
    n_obs = sum(len(s.observations) for s in raw_logs[1].steps())
    assert n_obs == runs[1].n_readings  # every reading was imported
    assert 0.95 * n_obs <= report["observation"]["observations"] <= n_obs  # with truth around them
    assert report["observation"]["outliers"] == pytest.approx(
        fitted.observation.outlier_rate * report["observation"]["observations"], abs=0.5)
    # the depth hypothesis fits far better than the Euclidean range
    mad = report["observation"]["range_residual_mad_m"]
    assert mad["depth"] < 0.5 * mad["range"]


def test_white_readings_fit_no_correlation(fitted):
    """The synthetic camera's errors are independent: nothing to model in time."""
    report = fitted.fit_report["observation"]["reading_correlation"]
    assert fitted.observation.correlated_share == 0.0, report
    assert abs(report["correlation"][0]) < 0.1


def test_a_pooled_fit_of_two_robots_recovers_the_model(dataset, raw_logs):
    _, runs = dataset
    model = fit_noise_model([raw_logs[1], raw_logs[2]])
    share = sum(r.n_outliers for r in runs.values()) / sum(r.n_readings for r in runs.values())
    check_recovered(model, share)
    assert model.fitted_on == (raw_logs[1].path, raw_logs[2].path)


def test_the_fitted_model_round_trips_through_its_file(fitted, tmp_path):
    path = tmp_path / "noise.json"
    save_noise_model(path, fitted)
    assert load_noise_model(path) == fitted


def test_the_fit_is_deterministic(raw_logs, fitted):
    assert fit_noise_model([raw_logs[1]]) == fitted


# ----------------------------------------------------------------------------- applying the fit


def dead_reckoning_errors(log, run) -> np.ndarray:
    """Position error (m) of the composed odometry against the generator's truth, per pose."""
    steps = log.steps()
    pose = log.header.start_pose
    composed = []
    for step in steps:
        if step.odometry is not None:
            o = step.odometry
            pose = compose_pose(pose, (o.dx_m, o.dy_m, o.dtheta_rad))
        composed.append(pose)
    composed = np.array(composed)
    truth = run.pose_at(log.header.source["time_origin_s"] + np.array([s.stamp_s for s in steps]))
    return np.hypot(composed[:, 0] - truth[:, 0], composed[:, 1] - truth[:, 1])


def test_the_fitted_odometry_dead_reckons_much_closer_to_the_truth(dataset, raw_logs, corrected_log):
    _, runs = dataset
    raw = dead_reckoning_errors(raw_logs[1], runs[1])
    fitted = dead_reckoning_errors(corrected_log, runs[1])
    assert raw[0] < 1e-6 and fitted[0] < 1e-6  # both start at the truth
    assert raw[-1] > 0.5  # the raw commands are far off: 7 % short, 5 % over-turning, curving
    assert fitted[-1] <= 0.5 * raw[-1]
    assert np.sqrt(np.mean(fitted**2)) <= 0.5 * np.sqrt(np.mean(raw**2))
    assert fitted.max() <= 0.5 * raw.max()


def observation_residuals(log, run) -> np.ndarray:
    """Rows (z_range, z_bearing, range error m, bearing error rad) of every reading vs the truth."""
    landmarks = log.truth_landmarks()
    obs = [o for step in log.steps() for o in step.observations]
    x, y, th = run.pose_at(log.header.source["time_origin_s"] + np.array([o.stamp_s for o in obs])).T
    lm = np.array([(landmarks[o.landmark_id].x_m, landmarks[o.landmark_id].y_m) for o in obs])
    r = np.hypot(lm[:, 0] - x, lm[:, 1] - y)
    b = wrap_angle(np.arctan2(lm[:, 1] - y, lm[:, 0] - x) - th)
    er = np.array([o.range_m for o in obs]) - r
    eb = wrap_angle(np.array([o.bearing_rad for o in obs]) - b)
    return np.column_stack([er / np.array([o.sigma_range_m for o in obs]),
                            eb / np.array([o.sigma_bearing_rad for o in obs]), er, eb])


def test_the_corrected_observations_are_unbiased_with_the_right_sigma(dataset, corrected_log):
    _, runs = dataset
    z = observation_residuals(corrected_log, runs[1])
    assert len(z) >= 0.95 * runs[1].n_readings  # hardly any reading lost to the correction
    inlier = (np.abs(z[:, 0]) < 5) & (np.abs(z[:, 1]) < 5)
    share = runs[1].n_outliers / runs[1].n_readings
    assert 0.5 * share <= 1 - inlier.mean() <= 2 * share  # the gross errors, and hardly anything else
    for j in (0, 1):
        zi = z[inlier, j]
        assert abs(zi.mean()) < 0.3, j
        assert 0.7 < math.sqrt(np.mean(zi**2)) < 1.4, j


def test_the_raw_observations_are_biased(dataset, raw_logs, corrected_log):
    # the same check on the raw import fails: depth, not range, and scaled; so the fit is what helps
    _, runs = dataset
    raw = observation_residuals(raw_logs[1], runs[1])
    fixed = observation_residuals(corrected_log, runs[1])
    raw_in = (np.abs(raw[:, 2]) < 0.5) & (np.abs(raw[:, 3]) < 0.05)
    fixed_in = (np.abs(fixed[:, 2]) < 0.5) & (np.abs(fixed[:, 3]) < 0.05)
    assert np.sqrt(np.mean(fixed[fixed_in, 2] ** 2)) < 0.5 * np.sqrt(np.mean(raw[raw_in, 2] ** 2))
    assert np.sqrt(np.mean(fixed[fixed_in, 3] ** 2)) < 0.8 * np.sqrt(np.mean(raw[raw_in, 3] ** 2))


def test_the_corrected_log_says_what_was_applied(fitted, corrected_log, raw_logs):
    noise = corrected_log.header.noise
    assert noise["fitted_on"] == [raw_logs[1].path]
    assert noise["odometry"]["lag_s"] == fitted.odometry.lag_s
    assert noise["observation"]["range_is_depth"] is True
    assert "fitted" in noise["odometry"]["model"]


def test_turn_rate_of_the_chain(raw_logs):
    # a chain turning at a known rate: |ω| everywhere, also for a clockwise turn
    stamps = np.arange(0.0, 10.01, 0.25)
    for w in (0.4, -0.3):
        chain = DeadReckoning(stamps, np.tile([0.02, 0.0, w * 0.25], (len(stamps) - 1, 1)))
        assert turn_rate_radps(chain, np.array([1.0, 5.0, 9.0])) == pytest.approx(abs(w), rel=1e-9)
        pose = chain.pose_at(5.0)
        assert pose[2] == pytest.approx(w * 5.0, rel=1e-9)
        assert chain.pose_at(-0.1) is None and chain.pose_at(10.1) is None


# ----------------------------------------------------------------------------- refusals


def test_no_logs_is_a_calibration_error():
    with pytest.raises(NoiseModelError, match="no logs"):
        fit_noise_model([])


def test_a_log_without_truth_is_a_calibration_error(raw_logs, tmp_path):
    log = raw_logs[1]
    path = tmp_path / "no_truth.jsonl"
    write_log(path, log.header, [r for r in log.records if not isinstance(r, TruthPose)])
    with pytest.raises(NoiseModelError, match="ground truth") as info:
        fit_noise_model([read_log(path)])
    message = str(info.value)
    assert str(path) in message and "0 poses with ground truth" in message


def test_a_log_without_truth_landmarks_is_a_calibration_error(raw_logs, tmp_path):
    log = raw_logs[1]
    path = tmp_path / "no_landmarks.jsonl"
    write_log(path, log.header, [r for r in log.records if not isinstance(r, TruthLandmark)])
    with pytest.raises(NoiseModelError, match="truth_landmark"):
        fit_noise_model([read_log(path)])


def test_a_log_imported_with_a_model_is_refused(corrected_log, raw_logs):
    with pytest.raises(NoiseModelError, match="--noise") as info:
        fit_noise_model([corrected_log])
    assert corrected_log.path in str(info.value)
    with pytest.raises(NoiseModelError, match="--noise"):  # also pooled with a good one
        fit_noise_model([raw_logs[1], corrected_log])


def test_the_observations_are_stamped_at_the_picture_time(dataset, fitted, corrected_log):
    # the corrected log places each reading camera_latency_s before its file stamp
    folder, _ = dataset
    stamps = np.loadtxt(folder / "Robot1_Measurement.dat")[:, 0]
    origin = corrected_log.header.source["time_origin_s"]
    logged = np.array(sorted({o.stamp_s for s in corrected_log.steps() for o in s.observations})) + origin
    expected = np.unique(stamps - fitted.observation.camera_latency_s)
    expected = expected[expected >= origin]
    assert len(logged) == len(expected)
    assert np.abs(logged - expected).max() < 1e-5
