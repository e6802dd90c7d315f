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
from slamio.datasets.plaza import gt_heading_offset_rad, import_plaza, plaza_files
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


def test_truth_is_gps_with_plaza2_heading_turned(plaza2):
    header, records = plaza2
    mat = loadmat(str(plaza_files("plaza2")[2]))
    gt = mat["GT"]
    assert gt_heading_offset_rad(gt) == pytest.approx(3.08, abs=0.02)
    assert header.source["gt_heading_turned_by_pi"] is True
    assert header.start_pose[:2] == (gt[0, 1], gt[0, 2])
    assert header.start_pose[2] == pytest.approx(math.pi - 2.021089, abs=1e-6)  # GTSAM's example start
    truth = {r.stamp_s: r for r in records if isinstance(r, TruthPose)}
    for row in gt[1::500]:
        t = truth[row[0]]
        assert (t.x_m, t.y_m) == (row[1], row[2])
    h1, _ = import_plaza("plaza1")
    assert h1.source["gt_heading_turned_by_pi"] is False


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
