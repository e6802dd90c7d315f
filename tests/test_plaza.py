"""The Plaza importer (slamio/datasets/plaza.py) on the files the gtsam wheel ships."""

from __future__ import annotations

import json
import math
import shutil

import numpy as np
import pytest
from scipy.io import loadmat

from fgslam.cli import main
from slamio.datasets import DatasetFormatError
from slamio.datasets.plaza import gps_start_heading_rad, gt_heading_offset_rad, import_plaza, plaza_files
from slamio.errors import FgslamError
from slamio.geometry import arc_increment
from slamio.log import Observation, Odometry, TruthPose, read_log


@pytest.fixture(scope="module")
def plaza2():
    header, records = import_plaza("plaza2")
    return header, records


def test_odometry_pieces_add_up_to_the_dead_reckoning(plaza2):
    header, records = plaza2
    dr = np.loadtxt(plaza_files("plaza2")[0])
    odometry = [r for r in records if isinstance(r, Odometry)]
    assert sum(o.distance_m for o in odometry) == pytest.approx(dr[:, 1].sum(), rel=1e-12)
    assert sum(o.angle_rad for o in odometry) == pytest.approx(dr[:, 2].sum(), abs=1e-9)
    # every DR time is a pose; the pieces between are range times
    stamps = {o.stamp_s for o in odometry}
    assert set(dr[:, 0]) <= stamps
    assert len(odometry) > len(dr)


def test_every_range_is_at_its_own_pose(plaza2):
    header, records = plaza2
    td = np.loadtxt(plaza_files("plaza2")[1])
    observations = [r for r in records if isinstance(r, Observation)]
    assert len(observations) == len(td)  # none after the last DR time in Plaza2
    assert all(o.range_only and o.sigma_range_m == 1.5 for o in observations)
    last_pose_stamp = header.stamp_s
    for r in records:
        if isinstance(r, Odometry):
            last_pose_stamp = r.stamp_s
        elif isinstance(r, Observation):
            assert r.stamp_s == pytest.approx(max(last_pose_stamp, header.stamp_s))
    assert sorted(o.range_m for o in observations) == pytest.approx(sorted(td[:, 3]))


def test_truth_is_gps_positions_without_heading(plaza2):
    header, records = plaza2
    mat = loadmat(str(plaza_files("plaza2")[2]))
    gt = mat["GT"]
    assert gt_heading_offset_rad(gt) == pytest.approx(3.08, abs=0.02)  # Plaza2's GT heading points backwards
    assert header.start_pose[:2] == (gt[0, 1], gt[0, 2])
    # the start heading comes from the GPS track; GTSAM's example starts at the turned GT heading
    turned = math.pi - 2.021089
    start_heading = header.start_pose[2]
    assert abs(start_heading - turned) < 0.2 and header.start_sigma[2] == 0.05
    truth = {r.stamp_s: r for r in records if isinstance(r, TruthPose)}
    assert all(t.theta_rad is None for t in truth.values())  # GPS measures no heading
    for row in gt[1::500]:
        t = truth[row[0]]
        assert (t.x_m, t.y_m) == (row[1], row[2])


def test_malformed_file_names_file_and_line(tmp_path):
    for f in plaza_files("plaza1"):
        shutil.copy(f, tmp_path / f.name)
    dr = tmp_path / "Plaza1_DR.txt"
    lines = dr.read_text().splitlines()
    lines[4] = "3857.85  0.0002"
    dr.write_text("\n".join(lines) + "\n")
    with pytest.raises(DatasetFormatError, match=r"Plaza1_DR.txt:5: 2 numbers; expected 3: time_s delta_distance_m"):
        import_plaza("plaza1", tmp_path)
    with pytest.raises(Exception, match="not found"):
        import_plaza("plaza2", tmp_path)


def test_import_then_run_reports_ate_against_gps(tmp_path, capsys):
    log = tmp_path / "plaza2.jsonl"
    assert main(["import", "plaza2", str(log)]) == 0
    assert read_log(log).header.sensor["kind"] == "range-only"
    out = tmp_path / "run"
    assert main(["run", str(log), "--out", str(out), "--estimators", "ekf,isam2-fast,dead_reckoning",
                 "--no-report"]) == 0
    text = capsys.readouterr().out
    assert "Reference: ground truth" in text
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["reference"] == "ground_truth"
    for name in ("ekf", "isam2-fast", "batch"):
        assert metrics[name]["landmarks_found"] == 4
        # dead reckoning drifts tens of metres on Plaza2; ranges to four beacons keep both near GPS
        assert metrics[name]["ate_rmse_m"] < 0.5 * metrics["dead_reckoning"]["ate_rmse_m"]
    # the truth has no heading: NEES over the position (2 DoF), no RPE
    for name in ("ekf", "isam2-fast", "dead_reckoning"):
        assert metrics[name]["nees_dof"] == 2 and metrics[name]["rpe_heading_rmse_rad"] is None
    # scored against the GT heading, every estimator had 5.0 % of its NEES inside the band; over
    # the position they differ, and dead reckoning (28 m off) is inside least often
    inside = {name: metrics[name]["nees_inside_95"] for name in ("ekf", "isam2-fast", "dead_reckoning")}
    assert len(set(inside.values())) == 3
    assert inside["dead_reckoning"] < min(inside["ekf"], inside["isam2-fast"])


def test_gps_start_heading_undoes_a_rotation_of_the_track():
    """A dead-reckoned L-shaped drive and its GPS track turned by 0.2 rad about the start:
    the start heading is the logged one plus 0.2 rad."""
    dr = np.array([[0.1 * (k + 1), 0.5, 0.0 if k != 30 else 1.2] for k in range(80)])
    gt = np.zeros((81, 4))
    gt[:, 0] = np.r_[0.0, dr[:, 0]]
    x = y = 0.0
    theta = 0.3
    for k, (_, ds, da) in enumerate(dr, start=1):
        dx, dy, _ = arc_increment(ds, da)
        c, s = math.cos(theta), math.sin(theta)
        x, y, theta = x + c * dx - s * dy, y + s * dx + c * dy, theta + da
        gt[k, 1:3] = (x, y)
    turn = np.array([[math.cos(0.2), -math.sin(0.2)], [math.sin(0.2), math.cos(0.2)]])
    gt[:, 1:3] = gt[:, 1:3] @ turn.T + (5.0, -2.0)
    gt[:, 3] = 0.3
    assert gps_start_heading_rad(gt, dr, track_m=30.0) == pytest.approx(0.5, abs=1e-9)


def test_a_fitted_range_model_corrects_every_range(tmp_path):
    """``--noise``: each range becomes (r − bias)/scale with the model's σ / scale."""
    from slamio.noise.model import NoiseModel, ObservationModel

    model = NoiseModel(observation=ObservationModel(range_scale=1.07, range_bias_m=0.03, range_sigma_m=0.54))
    _, raw = import_plaza("plaza2")
    header, records = import_plaza("plaza2", range_model=model)
    before = [r for r in raw if isinstance(r, Observation)]
    after = [r for r in records if isinstance(r, Observation)]
    assert len(before) == len(after)
    for a, b in zip(before[::100], after[::100]):
        assert b.range_m == pytest.approx((a.range_m - 0.03) / 1.07, rel=1e-12)
        assert b.sigma_range_m == pytest.approx(0.54 / 1.07, rel=1e-12)
    assert header.noise["observation"]["range_scale"] == 1.07
    with pytest.raises(FgslamError, match="not both"):
        import_plaza("plaza2", range_model=model, range_bias_m=2.8)


def test_run_noise_on_a_range_only_log_applies_the_range_model_as_the_importer_does():
    """``fgslam run --noise`` on Plaza2: the same records as ``import plaza2 --noise`` (the
    odometry kept, every range corrected alike), though the model's odometry part — fitted
    against a truth heading that is the odometry's own — says the heading never errs. A log
    with a range model already in it is refused, whichever way it got there."""
    from slamio.log import RunLog
    from slamio.noise.apply import apply_noise_model
    from slamio.noise.model import NoiseModel, ObservationModel, OdometryModel, OdometryNoiseRates

    degenerate = OdometryNoiseRates(heading_rad2_per_rad=3e-30, heading_rad2_per_m=3e-31)
    model = NoiseModel(odometry=OdometryModel(noise=degenerate), fitted_on=("plaza1.jsonl",),
                       observation=ObservationModel(range_scale=1.07, range_bias_m=0.03, range_sigma_m=0.54))
    raw_header, raw = import_plaza("plaza2")
    _, imported = import_plaza("plaza2", range_model=model)
    applied, dropped = apply_noise_model(RunLog("p2", raw_header, tuple(raw)), model)
    assert dropped == 0 and applied.records == tuple(imported)
    assert applied.header.noise["odometry"] == raw_header.noise["odometry"]
    for log in (applied, RunLog("p2", *import_plaza("plaza2", range_model=model))):
        with pytest.raises(FgslamError, match="already carries a fitted noise model"):
            apply_noise_model(log, model)
