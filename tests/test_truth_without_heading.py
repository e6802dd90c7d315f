"""A truth that measures position only (GPS): ``truth_pose`` without ``theta_rad``.

Scored on position: the NEES is over (x, y) with 2 degrees of freedom, no heading error or
RPE is reported, and tools that need the true heading (noise redraws, odometry calibration,
a ROS pose message) say so instead of using a heading nobody measured.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from scipy.stats import chi2

from fgslam.check import check_estimator
from fgslam.cli import main
from fgslam.compare import chi2_summary, compute_metrics, nees, nees_dofs
from fgslam.runner import compare_log, truth_reference
from slamio.errors import FgslamError
from slamio.log import RunLog, TruthPose, read_log, write_log
from slamio.noise.errors import NoiseModelError
from slamio.noise.fit_truth import fit_noise_model
from slamio.redraw import redraw_noise
from slamio.sim import simulate


def _without_heading(records) -> list:
    return [TruthPose(r.stamp_s, r.x_m, r.y_m) if isinstance(r, TruthPose) else r for r in records]


@pytest.fixture(scope="module")
def gps_log() -> RunLog:
    header, records = simulate("arena-octagon", 3)
    return RunLog("gps.jsonl", header, tuple(_without_heading(records)))


def test_a_truth_pose_without_heading_reads_back_as_none(tmp_path):
    path = tmp_path / "gps.jsonl"
    header, records = simulate("arena-octagon", 1, laps=1)
    write_log(path, header, _without_heading(records))
    lines = [json.loads(line) for line in path.read_text().splitlines()]
    truth = [d for d in lines if d.get("type") == "truth_pose"]
    assert truth and all("theta_rad" not in d for d in truth)  # omitted, not written as null
    assert all(r.theta_rad is None for r in read_log(path).records if isinstance(r, TruthPose))
    # null is read as "not measured" too
    text = path.read_text().replace('"type": "truth_pose", "stamp_s": 0.0, "x_m": 0.0, "y_m": 0.0}',
                                    '"type": "truth_pose", "stamp_s": 0.0, "x_m": 0.0, "y_m": 0.0, "theta_rad": null}')
    assert "null" in text
    path.write_text(text)
    assert read_log(path).steps()[0].truth.theta_rad is None


def test_nees_without_heading_is_the_position_block_closed_form():
    """e = (0.3, −0.4); P's position block [[0.09, 0.02], [0.02, 0.16]]: NEES = eᵀ P⁻¹ e,
    computed by hand, and the heading column of P plays no part."""
    P = np.array([[0.09, 0.02, 0.05], [0.02, 0.16, -0.03], [0.05, -0.03, 0.04]])
    e = np.array([0.3, -0.4])
    det = 0.09 * 0.16 - 0.02**2
    by_hand = (0.16 * e[0] ** 2 - 2 * 0.02 * e[0] * e[1] + 0.09 * e[1] ** 2) / det
    estimate = np.array([[1.3, 1.6, 2.0], [1.3, 1.6, 2.0]])
    reference = np.array([[1.0, 2.0, np.nan], [1.0, 2.0, 1.9]])
    values = nees(estimate, [P, P], reference)
    assert values[0] == pytest.approx(by_hand, rel=1e-12)
    full = np.array([0.3, -0.4, 0.1])
    assert values[1] == pytest.approx(full @ np.linalg.solve(P, full), rel=1e-12)
    assert nees_dofs(reference).tolist() == [2, 3]


def test_chi2_summary_judges_each_value_by_its_own_degrees_of_freedom():
    # 8.0 lies between χ²(2)'s upper limit 7.38 and χ²(3)'s 9.35
    assert chi2.ppf(0.975, 2) < 8.0 < chi2.ppf(0.975, 3)
    assert chi2_summary([8.0, 8.0], [2, 3]) == (8.0, 0.5, 2)
    assert chi2_summary([np.nan], [2]) == (None, None, 0)


def test_run_scores_position_only_and_draws_no_heading(gps_log, tmp_path):
    comparison = compare_log(gps_log, ["ekf", "isam2", "dead_reckoning"])
    metrics = compute_metrics(comparison.runs, comparison.reference, log_path="gps.jsonl")
    reference = truth_reference(gps_log)
    assert reference.has_pose.all() and not reference.has_heading.any()
    for name in ("ekf", "isam2", "dead_reckoning"):
        m = metrics[name]
        assert m["nees_dof"] == 2 and m["nees_count"] == len(reference.has_pose)
        assert m["rpe_trans_rmse_m"] is None and m["rpe_heading_rmse_rad"] is None
        assert not m["aligned"]  # the start positions agree: compared as they are
    # the positions score exactly as with the full truth
    with_heading = compare_log(RunLog("full.jsonl", gps_log.header, tuple(simulate("arena-octagon", 3)[1])),
                               ["ekf", "isam2", "dead_reckoning"])
    full = compute_metrics(with_heading.runs, with_heading.reference, log_path="full.jsonl")
    for name in ("ekf", "isam2", "dead_reckoning", "batch"):
        assert metrics[name]["ate_rmse_m"] == pytest.approx(full[name]["ate_rmse_m"], rel=1e-9)
    from fgslam.report import HEADING_ERROR_PNG, NEES_PNG, write_report

    write_report(tmp_path / "report", metrics, comparison.runs, comparison.reference, comparison.stamps_s)
    assert (tmp_path / "report" / NEES_PNG).exists() and not (tmp_path / "report" / HEADING_ERROR_PNG).exists()
    assert "the reference has no heading" in (tmp_path / "report" / "report.html").read_text()


def test_check_uses_the_two_dof_band(gps_log, tmp_path):
    path = tmp_path / "gps.jsonl"
    write_log(path, gps_log.header, gps_log.records)
    result = check_estimator(path, estimator="ekf", against="truth", max_ate_m=10.0, max_nees_outside=1.0)
    assert result.passed and result.poses_scored == len(gps_log.steps())


def test_tools_that_need_the_true_heading_say_so(gps_log):
    with pytest.raises(FgslamError, match="has no heading"):
        redraw_noise(gps_log, np.random.default_rng(0))
    with pytest.raises(NoiseModelError, match="truth has no heading"):
        fit_noise_model([gps_log])


def test_export_leaves_headless_truth_to_the_run_log_topic(gps_log, tmp_path):
    pytest.importorskip("rosbags")
    from slamio.datasets.rosbag import TRUTH_TOPIC, export_rosbag, import_rosbag

    counts = export_rosbag(gps_log, tmp_path / "bag")
    assert counts[TRUTH_TOPIC] == 0 and counts["truth_poses_without_heading"] == len(gps_log.steps())
    header, records = import_rosbag(tmp_path / "bag")
    assert [r for r in records if isinstance(r, TruthPose)] == [r for r in gps_log.records if isinstance(r, TruthPose)]
    assert header == gps_log.header


def test_cli_run_reports_nees_over_position(gps_log, tmp_path, capsys):
    path = tmp_path / "gps.jsonl"
    write_log(path, gps_log.header, gps_log.records)
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--no-report"]) == 0
    assert "ground truth for every pose (positions only: no heading)" in capsys.readouterr().out
    tum = (tmp_path / "out" / "reference.tum").read_text().splitlines()
    assert tum and all(line.split()[6:] == ["nan", "nan"] for line in tum)
    metrics = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert metrics["ekf"]["nees_dof"] == 2


def test_a_mixed_truth_counts_each_pose_by_its_own_dof(gps_log):
    """The first half of the poses with a heading, the rest without: NEES values of 3 and of
    2 degrees of freedom, and the RPE over the pairs whose both ends have a heading."""
    header, records = simulate("arena-octagon", 3)
    poses = sum(isinstance(r, TruthPose) for r in records)
    k = 0
    mixed = []
    for r in records:
        if isinstance(r, TruthPose):
            k += 1
            r = r if k <= poses // 2 else dataclasses.replace(r, theta_rad=None)
        mixed.append(r)
    comparison = compare_log(RunLog("mixed.jsonl", header, tuple(mixed)), ["ekf", "isam2"])
    metrics = compute_metrics(comparison.runs, comparison.reference, log_path="mixed.jsonl")
    assert metrics["ekf"]["nees_dof"] is None and metrics["ekf"]["nees_count"] == k
    assert metrics["ekf"]["rpe_heading_rmse_rad"] is not None  # over the pairs that have headings


def test_a_model_fitted_on_gps_corrects_ranges_only(tmp_path, capsys):
    """``fgslam calibrate`` on a range-only log with GPS truth fits the radios and says the
    odometry was not fitted; applying that model to a log with bearings is refused."""
    from slamio.noise.apply import apply_noise_model
    from slamio.noise.model import load_noise_model
    from tests.test_noise_range import radio_log

    radio = radio_log(1.07, 0.2, 0.05)
    gps = RunLog("radio.jsonl", radio.header, tuple(_without_heading(radio.records)))
    path = tmp_path / "radio.jsonl"
    write_log(path, gps.header, gps.records)
    assert main(["calibrate", str(path), "--out", str(tmp_path / "radio.json")]) == 0
    assert "odometry: not fitted (the truth has no heading" in capsys.readouterr().out
    model = load_noise_model(tmp_path / "radio.json")
    assert not model.odometry_fitted and model.observation.range_scale == pytest.approx(1.07, abs=0.005)
    corrected, _ = apply_noise_model(gps, model)  # range-only: the range model alone
    assert len(corrected.records) == len(gps.records)
    header, records = simulate("arena-octagon", 1, laps=1)
    with pytest.raises(FgslamError, match="odometry part was not fitted"):
        apply_noise_model(RunLog("cam.jsonl", header, tuple(records)), model)


def test_pure_functions_score_positions_and_give_no_rpe_without_heading(gps_log):
    """Without a ``has_pose`` mask the rows with a position count (ATE, final error), and
    an RPE pair needs a true heading at both ends."""
    from fgslam.compare import ate_rmse_m, final_pose_error_m, relative_pose_errors, rpe_delta_frames
    from fgslam.runner import truth_trajectory

    truth, has = truth_trajectory(gps_log.steps())
    estimate = truth.copy()
    estimate[:, 0] += 0.01
    estimate[:, 2] = 0.3
    assert ate_rmse_m(estimate, truth, align=False) == pytest.approx(0.01)
    assert final_pose_error_m(estimate, truth) == pytest.approx(0.01)
    assert rpe_delta_frames(truth) == rpe_delta_frames(truth, has_pose=has) > 1
    trans, heading = relative_pose_errors(estimate, truth, 5, has_pose=has)
    assert len(trans) == len(heading) == 0


def test_the_mean_nees_band_needs_the_true_heading(gps_log):
    from ekf import EkfSlam
    from fgslam.consistency import mean_nees

    with pytest.raises(FgslamError, match="has no heading"):
        mean_nees(gps_log, EkfSlam)
