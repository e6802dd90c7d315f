"""Calibration fits where the sensor sits (slamio.noise.mount_fit): against the mount a log's
readings were re-taken from, and against the run whose readings were taken at the centre."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from slamio.log import read_log
from slamio.noise.errors import NoiseModelError
from slamio.noise.apply import apply_noise_model
from slamio.noise.fit_truth import fit_noise_model
from slamio.noise.model import ObservationModel, load_noise_model, save_noise_model
from slamio.noise.mount_fit import determined, fit_mount, sensor_bearings_rad
from test_mount import DATA, MOUNT, log_seen_from_mount


def test_the_mount_is_found_from_noisy_bearings_of_a_known_layout():
    rng = np.random.default_rng(7)
    n = 400
    poses = np.column_stack([rng.uniform(-3, 3, n), rng.uniform(-3, 3, n), rng.uniform(-math.pi, math.pi, n)])
    landmarks = rng.uniform(-5, 5, (n, 2))
    truth = (0.15, 0.04, -0.2)
    bearings = sensor_bearings_rad(poses, landmarks, truth) + rng.normal(0.0, 0.01, n)
    bearings[:8] += 1.0  # misread landmarks: the robust loss keeps them out
    fit = fit_mount(poses, landmarks, bearings)
    assert fit.pose == pytest.approx(truth, abs=0.01)
    assert fit.bearing_scale == pytest.approx(1.0, abs=0.01)
    assert determined(fit) and all(s < 0.01 for s in fit.sigma)
    error = np.array(fit.pose) - np.array(truth)
    assert np.all(np.abs(error) < 4 * np.array(fit.sigma) + 1e-3)  # its σ is an honest one


def test_one_place_seen_from_one_direction_does_not_determine_it():
    rng = np.random.default_rng(3)
    n = 50
    poses = np.zeros((n, 3))
    landmarks = np.column_stack([np.full(n, 4.0), np.zeros(n)])
    fit = fit_mount(poses, landmarks, rng.normal(0.0, 0.01, n))
    assert not determined(fit)


def test_calibration_places_an_unstated_sensor_and_the_model_gives_the_centre_run_back(tmp_path):
    from fgslam.runner import compare_log

    unstated = read_log(log_seen_from_mount(tmp_path, False))
    model = fit_noise_model([unstated], fit_mount=True)
    assert model.observation.sensor_pose_on_robot == pytest.approx(MOUNT, abs=0.01)
    assert model.fit_report["observation"]["sensor_mount"]["adopted"]
    applied, dropped = apply_noise_model(unstated, model)
    assert dropped == 0 and applied.header.sensor["pose_on_robot"] == pytest.approx(list(MOUNT), abs=0.01)

    def ate(log):
        runs = {r.name: r for r in compare_log(log, ["ekf", "isam2"]).runs}
        truth = np.array([[s.truth.x_m, s.truth.y_m] for s in log.steps()])
        return {n: float(np.sqrt(np.mean(np.sum((runs[n].final[:, :2] - truth) ** 2, axis=1)))) for n in runs}

    centre, fitted = ate(read_log(DATA / "arena_square.jsonl")), ate(applied)
    for name in ("ekf", "isam2"):
        assert fitted[name] < 1.5 * centre[name] + 0.01


def test_a_model_carries_the_mount_through_its_file_and_refuses_a_bad_one(tmp_path):
    model = fit_noise_model([read_log(log_seen_from_mount(tmp_path, True))], fit_mount=True)  # stated right: found again
    assert model.observation.sensor_pose_on_robot == pytest.approx(MOUNT, abs=0.01)
    path = tmp_path / "noise.json"
    save_noise_model(path, model)
    assert load_noise_model(path).observation.sensor_pose_on_robot == model.observation.sensor_pose_on_robot
    data = json.loads(path.read_text())
    data["observation"]["sensor_pose_on_robot"] = [0.1, 0.0]
    path.write_text(json.dumps(data, indent=2))
    with pytest.raises(NoiseModelError,
                       match=r"noise.json:\d+: observation.sensor_pose_on_robot must be \[x_m, y_m, yaw_rad\]"):
        load_noise_model(path)
    with pytest.raises(NoiseModelError, match="within 10 m"):
        ObservationModel(sensor_pose_on_robot=(30.0, 0.0, 0.0))


def test_calibrate_reports_the_mount_and_fit_mount_carries_it(tmp_path, capsys):
    from fgslam.cli import main

    log = log_seen_from_mount(tmp_path, False)
    assert main(["calibrate", str(log)]) == 0
    out = capsys.readouterr().out
    assert "sensor on the robot, as the bearings place it: x +0.19" in out and "pass --fit-mount" in out
    assert main(["calibrate", str(log), "--fit-mount", "--out", str(tmp_path / "m.json")]) == 0
    out = capsys.readouterr().out
    assert "states it as the log's sensor.pose_on_robot" in out
    assert load_noise_model(tmp_path / "m.json").observation.sensor_pose_on_robot == pytest.approx(MOUNT, abs=0.01)
    assert main(["calibrate", str(log), "--without-truth", "--fit-mount"]) == 1
    assert "--fit-mount fits the sensor's mount against ground truth" in capsys.readouterr().err
