"""`fgslam check` and `fgslam bench` on 3-D logs (seed 003's stereo + IMU), and partial truth in 3-D.

References are independent of the code under test: the estimators run directly on the
simulated drive (not through the log) and the errors are computed here with numpy.
"""

from __future__ import annotations

import concurrent.futures
import json

import numpy as np
import pytest

from ekf.drive3d import steps_of
from ekf.vio import VioEkf, pose_nees
from fgslam.check import check_estimator
from fgslam.cli import main
from fgslam.compare import nees_band
from fgslam.montecarlo import monte_carlo
from fgslam.montecarlo import run_one_3d
from fgslam.runner import UnusableReferenceError
from slamio.datasets.seed003_log import drive_to_log
from slamio.errors import FgslamError
from slamio.log import write_log
from slamio.log import StereoObservation, TruthPose3
from slamio.sim3d import DriveScenario, simulate_drive

SMALL = DriveScenario(straight_m=40.0, side_m=25.0)  # 258 steps: what `fgslam sim stereo-loop` writes, shorter
SEED = 5


@pytest.fixture(scope="module")
def drive():
    return simulate_drive(SEED, SMALL)


def write(path, drive, keep=lambda record, index: True):
    header, records = drive_to_log(drive, source={"generator": "test"})
    write_log(path, header, [r for i, r in enumerate(records) if keep(r, i)])
    return path


@pytest.fixture(scope="module")
def small_log(tmp_path_factory, drive):
    return write(tmp_path_factory.mktemp("check3d") / "small.jsonl", drive)


@pytest.fixture(scope="module")
def gappy_log(tmp_path_factory, drive):
    """The same drive with the truth of every third pose missing (2 of 3 poses keep it)."""
    stamps_without = set(drive.stamps_s[1::3].tolist())
    return write(tmp_path_factory.mktemp("check3d") / "gappy.jsonl", drive,
                 lambda r, i: not (isinstance(r, TruthPose3) and r.stamp_s in stamps_without))


def direct_vio(drive, first_estimates):
    """ekf-vio(-fej) fed the drive's arrays directly (no log), with its pose NEES per step."""
    ekf = VioEkf(drive.K, drive.baseline_m, drive.cam_T_imu, first_estimates=first_estimates)
    nees = []
    for t, args in enumerate(steps_of(drive)):
        ekf.step(*args)
        nees.append(pose_nees(ekf.current_pose(), ekf.current_covariance(), drive.truth_world_T_imu[t]))
    return ekf, np.array(nees)


def rmse_m(a, b):
    return float(np.sqrt(np.mean(np.sum((a[:, :3, 3] - b[:, :3, 3]) ** 2, axis=1))))


def test_check_against_the_truth_scores_what_the_filter_does_on_the_drive(small_log, drive):
    ekf, nees = direct_vio(drive, first_estimates=True)
    low, high = nees_band(6)
    outside = float(np.mean((nees < low) | (nees > high)))
    result = check_estimator(small_log, estimator="ekf-vio-fej", against="truth")
    assert result.ate_m == pytest.approx(rmse_m(ekf.trajectory(), drive.truth_world_T_imu), abs=1e-9)
    assert result.nees_outside == pytest.approx(outside)
    assert result.passed and result.verdict.startswith("PASS ekf-vio-fej vs truth on small.jsonl: ATE ")
    assert result.poses_scored == result.poses == drive.n_steps


def test_the_inconsistent_ekf_fails_the_nees_tolerance(small_log, capsys):
    # the standard EKF gains information along the unobservable directions: NEES far above its band
    assert main(["check", str(small_log), "--estimator", "ekf-vio", "--against", "truth"]) == 1
    line = capsys.readouterr().out.strip()
    assert line.startswith("FAIL ekf-vio vs truth on small.jsonl") and "NEES outside the 95 % band" in line


def test_check_defaults_to_the_consistent_ekf_against_the_smoothed_solution(small_log, capsys):
    assert main(["check", str(small_log)]) == 0
    assert capsys.readouterr().out.startswith("PASS ekf-vio-fej vs smoothed on small.jsonl")
    # isam2 after finish() is the batch solution's starting point and ends at it
    result = check_estimator(small_log, estimator="isam2-3d")
    assert result.passed and result.ate_m < 0.01


def test_planar_estimators_are_refused_on_a_3d_log(small_log):
    with pytest.raises(FgslamError, match="unknown estimator 'ekf' for a 3-D log; choose from ekf-s003"):
        check_estimator(small_log, estimator="ekf")


def test_a_graph_with_no_landmark_seen_twice_is_not_a_reference(tmp_path, drive):
    first = {}
    log = write(tmp_path / "once.jsonl", drive,
                lambda r, i: not isinstance(r, StereoObservation) or first.setdefault(r.track_id, i) == i)
    with pytest.raises(UnusableReferenceError, match="no landmark is seen twice"):
        check_estimator(log, estimator="ekf-vio-fej", against="smoothed")


# ------------------------------------------------------------------ partial truth


def test_run_scores_only_the_poses_with_truth(gappy_log, drive, tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["run", str(gappy_log), "--out", str(out), "--estimators", "ekf-vio-fej,isam2-3d", "--no-report"]) == 0
    text = capsys.readouterr().out
    has = np.ones(drive.n_steps, dtype=bool)
    has[1::3] = False
    n = int(has.sum())
    assert f"ground truth, {n} of {drive.n_steps} poses" in text
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["reference"] == "ground_truth" and metrics["reference_poses_with_truth"] == n
    ekf, nees = direct_vio(drive, first_estimates=True)
    truth = drive.truth_world_T_imu
    m = metrics["ekf-vio-fej"]
    assert m["ate_rmse_m"] == pytest.approx(rmse_m(ekf.trajectory()[has], truth[has]), abs=1e-9)
    low, high = nees_band(6)
    assert m["nees_mean"] == pytest.approx(float(np.mean(nees[has])))
    assert m["nees_inside_95"] == pytest.approx(float(np.mean((nees[has] >= low) & (nees[has] <= high))))
    last = np.flatnonzero(has)[-1]
    assert m["final_pose_error_m"] == pytest.approx(np.linalg.norm(ekf.trajectory()[last, :3, 3] - truth[last, :3, 3]))
    assert len((out / "reference.tum").read_text().splitlines()) == n


def test_check_against_partial_truth_says_how_many_poses_it_scored(gappy_log, drive):
    result = check_estimator(gappy_log, estimator="ekf-s003-figures", against="truth")
    n = drive.n_steps - len(range(1, drive.n_steps, 3))
    assert result.poses_scored == n
    assert f"({n} of {drive.n_steps} poses have truth; only they are scored)" in result.verdict


def test_too_little_truth_is_refused(tmp_path, drive):
    log = write(tmp_path / "sparse.jsonl", drive, lambda r, i: not isinstance(r, TruthPose3) or r.stamp_s < 1.0)
    with pytest.raises(FgslamError, match=r"only 10 of 258 poses have ground truth.*use --against smoothed"):
        check_estimator(log, estimator="ekf-vio-fej", against="truth")


# ------------------------------------------------------------------ bench


@pytest.mark.slow  # a small Monte Carlo: CI runs it, the quick suite stays under 4 min
def test_bench_stereo_loop_averages_the_se3_nees_of_the_runs():
    with concurrent.futures.ThreadPoolExecutor(max_workers=2) as pool:
        result = monte_carlo("stereo-loop", 2, estimators=("ekf-s003-figures", "ekf-vio-fej"), first_seed=3,
                             executor=pool, drive_scenario=SMALL)
    assert [r.seed for r in result.runs] == [3, 4] and result.dof == 6
    assert result.band == nees_band(6, 2)
    one = run_one_3d(4, ("ekf-vio-fej",), SMALL)
    assert np.allclose(result.runs[1].nees["ekf-vio-fej"], one.nees["ekf-vio-fej"])  # seeded: the same run
    drive = simulate_drive(4, SMALL)
    ekf, nees = direct_vio(drive, first_estimates=True)
    assert np.allclose(one.nees["ekf-vio-fej"], nees)
    assert one.ate_final_m["ekf-vio-fej"] == pytest.approx(rmse_m(ekf.trajectory(), drive.truth_world_T_imu))
    expected = np.mean([r.nees["ekf-vio-fej"] for r in result.runs], axis=0)
    assert np.allclose(result.average_nees["ekf-vio-fej"], expected)


@pytest.mark.parametrize(("argv", "message"), [
    (["--laps", "2"], "--laps: not available for stereo-loop"),
    (["--estimators", "ekf,isam2"], "unknown estimator(s) ekf, isam2 for stereo-loop"),
])
def test_bench_stereo_loop_refuses_planar_options(argv, message, capsys):
    assert main(["bench", "stereo-loop", "--runs", "1", *argv]) != 0
    assert message in capsys.readouterr().err


@pytest.mark.slow
def test_fgslam_bench_on_the_stereo_loop_end_to_end(tmp_path, capsys):
    out = tmp_path / "mc"
    assert main(["bench", "stereo-loop", "--runs", "2", "--jobs", "2", "--estimators", "ekf-vio-fej,isam2-3d",
                 "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "stereo-loop, 2 runs (seeds 0-1)" in text and "ekf-vio-fej" in text
    summary = json.loads((out / "montecarlo.json").read_text())
    assert summary["nees_dof"] == 6 and summary["band"] == pytest.approx(list(nees_band(6, 2)))
    assert (out / "nees.png").stat().st_size > 10_000


@pytest.mark.slow
def test_fgslam_sim_stereo_loop_then_check(tmp_path, capsys):
    log = tmp_path / "sim1.jsonl"
    assert main(["sim", "stereo-loop", "--seed", "1", "--out", str(log)]) == 0
    assert main(["check", str(log), "--against", "truth"]) == 0
    assert capsys.readouterr().out.strip().splitlines()[-1].startswith("PASS ekf-vio-fej vs truth on sim1.jsonl")
