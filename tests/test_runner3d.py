"""``fgslam run`` on a 3-D log: the 3-D estimators end to end, metrics against independent
references (closed forms, evo as the oracle for the TUM files and the ATE), the report."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from evo.core import metrics as evo_metrics  # a dev extra (GPL-3.0): tests only, never shipped
from evo.core import sync
from evo.tools import file_interface

from fgslam.cli import main
from fgslam.runner3d import (
    ESTIMATORS_3D,
    estimator_entries_3d,
    Reference3d,
    Run3d,
    format_tum3,
    nees_values,
    noise_of,
    parse_estimator_names_3d,
    position_rmse_m,
)
from slamio.errors import FgslamError
from slamio.log import read_log, write_log
from slamio.log import StereoObservation
from slamio.se3 import exp_se3
from slamio.sim3d import simulate_drive

from builders import SMALL_DRIVE as SMALL, write_small_drive


@pytest.fixture(scope="module")
def small_log(tmp_path_factory):
    return write_small_drive(tmp_path_factory.mktemp("log3d") / "small.jsonl")


@pytest.fixture(scope="module")
def run_dir(small_log, tmp_path_factory):
    out = tmp_path_factory.mktemp("run3d")
    assert main(["run", str(small_log), "--out", str(out),
                 "--estimators", "ekf-s003,ekf-s003-figures,ekf-vio,ekf-vio-fej,isam2-3d"]) == 0
    return out


def evo_trajectory(path):
    return file_interface.read_tum_trajectory_file(str(path))


@pytest.mark.parametrize("name", ["ekf-s003-figures", "ekf-vio", "ekf-vio-fej", "isam2-3d", "batch"])
def test_evo_reads_our_se3_tum_files_and_agrees_on_the_3d_ate(run_dir, name):
    metrics = json.loads((run_dir / "metrics.json").read_text())
    ref, est = sync.associate_trajectories(evo_trajectory(run_dir / "reference.tum"),
                                           evo_trajectory(run_dir / f"{name}.tum"))
    ape = evo_metrics.APE(evo_metrics.PoseRelation.translation_part)
    ape.process_data((ref, est))
    rmse = float(ape.get_statistic(evo_metrics.StatisticsType.rmse))
    assert rmse == pytest.approx(metrics[name]["ate_rmse_m"], abs=1e-6)
    # evo sees a genuinely 3-D trajectory: rotations about x and y and a changing height
    poses = np.array(est.poses_se3)
    assert np.ptp(poses[:, 2, 3]) > 0.1 and np.max(np.abs(poses[:, 2, 0])) > 1e-3


def test_the_reference_tum_file_is_the_logs_truth(run_dir, small_log):
    drive = simulate_drive(5, SMALL)
    poses = np.array(evo_trajectory(run_dir / "reference.tum").poses_se3)
    assert np.allclose(poses, drive.truth_world_T_imu, atol=1e-9)


def test_the_comparison_shows_what_seed_003_is_about(run_dir):
    m = json.loads((run_dir / "metrics.json").read_text())
    e = estimator_entries_3d(m)
    assert m["dimension"] == 3 and m["reference"] == "ground_truth"
    # the factor graph beats the joint EKF, which beats the IMU alone; the paper as written is lost
    assert e["isam2-3d"]["ate_rmse_m"] < e["ekf-vio"]["ate_rmse_m"] < e["ekf-s003-figures"]["ate_rmse_m"]
    assert e["ekf-s003"]["ate_rmse_m"] > 10.0 * e["ekf-s003-figures"]["ate_rmse_m"]
    for name, row in e.items():
        assert row["ate_2d_rmse_m"] <= row["ate_rmse_m"] + 1e-12, name
    # iSAM2 after finish() reaches the batch solution on a simulated drive
    assert m["isam2_graph_error"] == pytest.approx(m["batch_graph_error"], rel=1e-3)
    assert e["ekf-vio"]["nis_mean"] == pytest.approx(4.0, abs=1.0)
    # first-estimate Jacobians make the joint EKF consistent (docs/seed003.md, *Consistency*)
    assert e["ekf-vio-fej"]["nees_inside_95"] >= 0.9 > e["ekf-vio"]["nees_inside_95"]
    assert 0.0 <= e["isam2-3d"]["nees_inside_95"] <= 1.0 and e["batch"].get("nees_mean") is None
    assert (run_dir / "report.html").exists() and (run_dir / "top_view.png").stat().st_size > 10_000
    assert "top view" in (run_dir / "report.html").read_text()


def test_a_3d_run_writes_the_planar_metrics_schema(run_dir):
    from fgslam.compare import METRIC_KEYS, TOP_LEVEL_KEYS
    from fgslam.runner3d import METRIC_KEYS_3D, estimator_entries_3d, table_rows_3d

    m = json.loads((run_dir / "metrics.json").read_text())
    assert "estimators" not in m and m["blas_threads"] == 1
    assert set(TOP_LEVEL_KEYS) - {"rpe_delta_frames"} <= set(m) and m["landmark_reference"] == "ground_truth"
    entries = estimator_entries_3d(m)
    assert list(entries) == ["ekf-s003", "ekf-s003-figures", "ekf-vio", "ekf-vio-fej", "isam2-3d", "batch"]
    shared = {"ate_rmse_m", "ate_online_rmse_m", "final_pose_error_m", "landmarks_estimated", "map_rmse_m",
              "time_step_p50_s", "time_step_p99_s", "time_step_max_s", "time_total_s", "steps", "nees_mean",
              "nees_inside_95", "nees_dof", "nis_mean", "nis_inside_95"}
    assert shared <= set(METRIC_KEYS) and shared <= set(METRIC_KEYS_3D)
    vio = entries["ekf-vio"]
    assert set(vio) == set(METRIC_KEYS_3D) and vio["nees_dof"] == 6
    assert vio["time_step_p50_s"] <= vio["time_step_p99_s"] <= vio["time_step_max_s"] <= vio["time_total_s"]
    assert entries["batch"]["time_step_p99_s"] is None and entries["batch"]["ate_online_rmse_m"] is None
    # a metrics.json from before the one schema reads the same
    old_names = {"ate_rmse_m": "ate_3d_m", "ate_2d_rmse_m": "ate_2d_m", "ate_online_rmse_m": "ate_3d_online_m",
                 "final_pose_error_m": "final_position_error_m", "landmarks_estimated": "landmarks",
                 "time_total_s": "total_s", "nees_inside_95": "nees_in_band", "nis_inside_95": "nis_in_band"}
    old = {k: v for k, v in m.items() if k not in entries}
    old["estimators"] = {}
    for name, e in entries.items():
        row = {old_names.get(k, k): v for k, v in e.items() if not k.startswith("time_step")}
        row["step_ms_mean"] = None if e["time_step_mean_s"] is None else 1e3 * e["time_step_mean_s"]
        old["estimators"][name] = row
    assert table_rows_3d(old) == table_rows_3d(m)


def test_position_rmse_and_nees_against_closed_forms():
    truth = np.array([exp_se3(np.array([t, 0.0, 0.0, 0.0, 0.0, 0.1 * t])) for t in range(5)])
    shifted = truth.copy()
    shifted[:, :3, 3] += [1.0, 2.0, 3.0]
    assert position_rmse_m(shifted, truth, 3) == pytest.approx(math.sqrt(14.0))
    assert position_rmse_m(shifted, truth, 2) == pytest.approx(math.sqrt(5.0))
    e = np.array([0.1, -0.2, 0.05, 0.01, 0.02, -0.03])
    estimate = np.array([T @ exp_se3(e) for T in truth])  # truth = estimate · exp(−e)
    cov = np.diag([0.01, 0.04, 0.01, 1e-4, 4e-4, 9e-4])
    run = Run3d("x", estimate, estimate, {}, None, 0.0, np.array([cov] * 5))
    expected = float(np.sum(e**2 / np.diag(cov)))
    assert nees_values(run, Reference3d("ground_truth", truth, {})) == pytest.approx([expected] * 5)
    assert nees_values(run, Reference3d("batch", truth, {})) is None


def test_tum3_writes_position_and_quaternion_and_projects_a_non_rigid_pose():
    from slamio.log import pose3_matrix

    T = exp_se3(np.array([1.0, 2.0, 3.0, 0.3, -0.2, 0.1]))
    values = [float(v) for v in format_tum3([0.5], [T]).split()]
    assert values[0] == 0.5 and np.allclose(pose3_matrix(tuple(values[1:])), T, atol=1e-12)
    bent = T.copy()
    bent[:3, :3] *= 1.01  # ekf-s003 as written: μ⁻¹ need not be rigid
    bent_values = [float(v) for v in format_tum3([0.5], [bent]).split()]
    assert np.allclose(bent_values, values, atol=1e-12)


def test_estimator_names_and_help_are_in_step():
    from fgslam.cli.estimators import ESTIMATOR_HELP_3D

    assert list(ESTIMATOR_HELP_3D) == list(ESTIMATORS_3D)
    assert parse_estimator_names_3d(None) == ["ekf-s003", "ekf-vio", "ekf-vio-fej", "isam2-3d"]
    with pytest.raises(FgslamError, match=r"unknown estimator\(s\) for a 3-D log: ekf;"):
        parse_estimator_names_3d("ekf,isam2-3d")
    with pytest.raises(FgslamError, match="keep isam2-3d"):
        parse_estimator_names_3d("ekf-vio")


def test_one_noise_level_is_required(small_log, tmp_path):
    log = read_log(small_log)
    assert noise_of(log).sigma_px == 1.0 and noise_of(log).sigma_w_radps == pytest.approx(0.005)
    records = list(log.records)
    i = next(k for k, r in enumerate(records) if isinstance(r, StereoObservation))
    records[i] = StereoObservation(**{**records[i].__dict__, "sigma_px": 2.0})
    write_log(tmp_path / "mixed.jsonl", log.header, records)
    with pytest.raises(FgslamError, match="one noise level"):
        noise_of(read_log(tmp_path / "mixed.jsonl"))


def test_user_errors_on_a_3d_log_are_one_line(small_log, tmp_path, capsys):
    assert main(["run", str(small_log), "--out", str(tmp_path / "a"), "--estimators", "ekf,isam2"]) == 1
    assert "unknown estimator(s) for a 3-D log: ekf, isam2" in capsys.readouterr().err
    assert main(["run", str(small_log), "--out", str(tmp_path / "b"), "--noise", "n.json"]) == 1
    assert "--noise applies to planar logs" in capsys.readouterr().err


# ------------------------------------------------------------------ 3-D logs as real datasets state them


def _moved_world(log, world_T_start):
    """``log`` with its world frame moved: the first pose at ``world_T_start``, the truth with it."""
    import dataclasses

    from slamio.log import TruthLandmark3, TruthPose3, pose3_from_matrix

    T = np.asarray(world_T_start)
    records = []
    for r in log.records:
        if isinstance(r, TruthPose3):
            r = TruthPose3(r.stamp_s, *pose3_from_matrix(T @ r.matrix()))
        elif isinstance(r, TruthLandmark3):
            p = T[:3, :3] @ np.array([r.x_m, r.y_m, r.z_m]) + T[:3, 3]
            r = TruthLandmark3(r.landmark_id, *(float(v) for v in p))
        records.append(r)
    header = dataclasses.replace(log.header, start_pose3=pose3_from_matrix(T))
    return dataclasses.replace(log, header=header, records=tuple(records))


def test_a_start_pose_other_than_the_identity_is_respected(tmp_path):
    """The same drive in a world frame where the IMU starts 5 m away, turned and tilted:
    every estimator's ATE and NEES are those of the drive in the IMU's own frame."""
    from fgslam.cli import main
    from fgslam.runner3d import compute_metrics_3d, run_log3d
    from slamio.log import read_log
    from slamio.se3 import exp_se3

    path = tmp_path / "s.jsonl"
    assert main(["sim", "stereo-loop", "--seed", "3", "--out", str(path)]) == 0
    log = read_log(path)
    world_T_start = exp_se3(np.array([5.0, -2.0, 1.0, 0.1, -0.2, 1.2]))
    names = ["ekf-vio", "isam2-3d"]
    plain = compute_metrics_3d(run_log3d(log, names), log_path="plain")
    moved = compute_metrics_3d(run_log3d(_moved_world(log, world_T_start), names), log_path="moved")
    for name in names + ["batch"]:
        assert moved[name]["ate_rmse_m"] == pytest.approx(plain[name]["ate_rmse_m"], rel=1e-6)
    for name in names:
        assert moved[name]["nees_mean"] == pytest.approx(plain[name]["nees_mean"], rel=1e-6)


def test_a_per_axis_velocity_covariance_is_taken_as_stated():
    import dataclasses

    from fgslam.runner3d import noise_of
    from slamio.datasets.seed003_log import drive_to_log
    from slamio.log import RunLog, VelocityOdometry
    from slamio.sim3d import DriveScenario, simulate_drive

    header, records = drive_to_log(simulate_drive(1, DriveScenario(straight_m=20.0, side_m=10.0)))
    cov = np.diag([0.04, 0.01, 0.0025, 1e-4, 4e-5, 2.5e-5])
    cov[0, 5] = cov[5, 0] = 1e-5
    stated = tuple(tuple(float(v) for v in row) for row in cov)
    records = tuple(dataclasses.replace(r, covariance=stated) if isinstance(r, VelocityOdometry) else r for r in records)
    noise = noise_of(RunLog("per-axis", header, records))
    assert np.array_equal(noise.velocity_cov(), cov)


def test_the_verdict_of_a_3d_run_finds_an_imu_noise_stated_ten_times_too_small():
    """The simulator's drive with its own noise stated: both groups fit; with the IMU's σ
    stated 10× too small (what a seed 003 drive of another year does to the importer's
    defaults), the IMU group is flagged as too small and the run says what to do."""
    from fgslam.runner3d import run_log3d
    from fgslam.verdict import verdict_lines
    from slamio.datasets.seed003 import StereoImuNoise
    from slamio.datasets.seed003_log import drive_to_log
    from slamio.log import RunLog
    from slamio.sim3d import DriveScenario, simulate_drive

    drive = simulate_drive(2, DriveScenario(straight_m=30.0, side_m=20.0))
    exact = run_log3d(RunLog("exact", *_as_log(drive_to_log(drive))), ["isam2-3d"]).verdict
    assert set(exact) == {"imu", "stereo"} and all(v.fits for v in exact.values())
    wrong = StereoImuNoise(sigma_v_mps=0.005, sigma_w_radps=0.0005)
    told = run_log3d(RunLog("wrong", *_as_log(drive_to_log(drive, wrong))), ["isam2-3d"]).verdict
    assert not told["imu"].fits and told["imu"].sigma_factor > 3
    assert any("imu sigma is" in line and "too small" in line for line in verdict_lines(told, None))


def _as_log(header_records):
    header, records = header_records
    return header, tuple(records)
