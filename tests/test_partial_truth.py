"""Ground truth for only some poses (Vicon gaps), or only for the landmarks.

The logs are the bundled arena-square run with some ``truth_pose`` records removed (a gap of
40 poses in the middle, every 7th pose over a stretch, and the last 25 poses), or with all of
them removed (landmark-only truth). Every expected number is computed here independently:
dead reckoning and its covariance are re-integrated with explicit SE(2) matrices, the other
estimates are read back from the TUM files with ``numpy.loadtxt``, and RMSEs, RPE pairs and
NEES counts are worked out with plain numpy over the poses that kept their truth.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chi2

from fgslam.check import check_estimator
from fgslam.cli import main
from fgslam.compare import (
    EstimatorRun,
    Reference,
    ate_rmse_m,
    compute_metrics,
    final_pose_error_m,
    format_table,
    relative_pose_errors,
    rpe_delta_frames,
)
from slamio.errors import FgslamError
from slamio.log import Odometry, TruthLandmark, TruthPose, read_log, write_log

DATA = Path(__file__).resolve().parent.parent / "data"
SOURCE = DATA / "arena_square.jsonl"


# --------------------------------------------------------------------------- building the logs


def pose_of_each_record(records) -> list[int]:
    """The pose each record belongs to: pose k starts with the k-th odometry record."""
    pose, out = 0, []
    for r in records:
        if isinstance(r, Odometry):
            pose += 1
        out.append(pose)
    return out


def write_without_truth_at(path: Path, drop) -> Path:
    """The bundled log without the ``truth_pose`` records of the poses in ``drop``
    (``drop="all"`` removes every one; truth landmarks are kept)."""
    log = read_log(SOURCE)
    poses = pose_of_each_record(log.records)
    kept = [
        r for r, k in zip(log.records, poses)
        if not (isinstance(r, TruthPose) and (drop == "all" or k in drop))
    ]
    write_log(path, log.header, kept)
    return path


def truth_arrays(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(truth (n, 3) with NaN rows, has_truth (n,)) read straight from the records."""
    log = read_log(path)
    records = log.records
    n = 1 + sum(isinstance(r, Odometry) for r in records)
    truth = np.full((n, 3), np.nan)
    for r, k in zip(records, pose_of_each_record(records)):
        if isinstance(r, TruthPose):
            truth[k] = (r.x_m, r.y_m, r.theta_rad)
    return truth, np.isfinite(truth[:, 0])


def se2(x, y, theta) -> np.ndarray:
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s, x], [s, c, y], [0.0, 0.0, 1.0]])


def from_se2(T) -> tuple[float, float, float]:
    return float(T[0, 2]), float(T[1, 2]), math.atan2(T[1, 0], T[0, 0])


def dead_reckoning_by_hand(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Odometry composed with 3×3 matrices, and its first-order covariance
    P ← F P Fᵀ + G Q Gᵀ (F: Jacobian of the composition in the pose, G: in the increment)."""
    log = read_log(path)
    x, y, th = log.header.start_pose
    T = se2(x, y, th)
    P = np.diag(np.square(log.header.start_sigma))
    poses, covariances = [from_se2(T)], [P]
    for r in log.records:
        if not isinstance(r, Odometry):
            continue
        _, _, heading = from_se2(T)
        c, s = math.cos(heading), math.sin(heading)
        F = np.array([[1.0, 0.0, -s * r.dx_m - c * r.dy_m], [0.0, 1.0, c * r.dx_m - s * r.dy_m], [0.0, 0.0, 1.0]])
        G = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        P = F @ P @ F.T + G @ np.asarray(r.covariance) @ G.T
        T = T @ se2(r.dx_m, r.dy_m, r.dtheta_rad)
        poses.append(from_se2(T))
        covariances.append(P)
    return np.array(poses), np.array(covariances)


def tum_xy(path: Path) -> np.ndarray:
    """(n, 2) positions of a TUM file."""
    return np.loadtxt(path, ndmin=2)[:, 1:3]


def tum_poses(path: Path) -> np.ndarray:
    """(n, 3) poses of a TUM file (yaw from qz, qw: the files are planar)."""
    a = np.loadtxt(path, ndmin=2)
    return np.c_[a[:, 1:3], 2.0 * np.arctan2(a[:, 6], a[:, 7])]


def rmse_over(estimate_xy, truth, has_truth) -> float:
    d = estimate_xy[has_truth] - truth[has_truth, :2]
    return math.sqrt(float(np.mean(np.sum(d * d, axis=1))))


GAP = set(range(100, 140)) | set(range(300, 400, 7))


@pytest.fixture(scope="module")
def partial(tmp_path_factory):
    """A log with truth gaps, and `fgslam run` on it (with the report), NEES and NIS at every
    step (the default sample's draw among the poses with truth: test_consistency_sample)."""
    folder = tmp_path_factory.mktemp("partial")
    log = write_without_truth_at(folder / "gappy.jsonl", GAP | set(range(800, 825)))
    truth, has_truth = truth_arrays(log)
    out = folder / "run"
    stdout = io.StringIO()
    with contextlib.redirect_stdout(stdout):
        assert main(["run", str(log), "--out", str(out), "--consistency", "all"]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    return log, truth, has_truth, out, metrics, stdout.getvalue()


def test_the_log_really_has_gaps(partial):
    log, truth, has_truth, *_ = partial
    n = len(has_truth)
    assert n == 825 and not has_truth[100:140].any() and not has_truth[800:].any()
    assert int(has_truth.sum()) == n - 40 - len(range(300, 400, 7)) - 25
    assert has_truth[0]  # the start keeps its truth
    assert read_log(log).has_full_truth() is False


# --------------------------------------------------------------------------- fgslam run


def test_reference_line_and_summary_say_how_many_poses_have_truth(partial):
    log, _, has_truth, _, _, text = partial
    n, k = len(has_truth), int(has_truth.sum())
    assert f"ground truth for {k} of {n} poses" in text.splitlines()[0]
    expected = (f"Reference: ground truth recorded in the log, {k} of {n} poses "
                f"(gaps in the truth: {n - k} poses without truth are not scored) - {log}")
    assert expected in text.splitlines()


def test_metrics_json_says_what_the_reference_is(partial):
    _, _, has_truth, _, metrics, _ = partial
    assert metrics["reference"] == "ground_truth"
    assert metrics["poses"] == len(has_truth)
    assert metrics["reference_poses_with_truth"] == int(has_truth.sum())
    assert metrics["landmark_reference"] == "ground_truth"
    assert metrics["reference_landmarks"] == 8


def test_dead_reckoning_ate_final_error_and_nees_over_the_poses_with_truth(partial):
    log, truth, has_truth, _, metrics, _ = partial
    poses, covariances = dead_reckoning_by_hand(log)
    m = metrics["dead_reckoning"]
    expected_ate = rmse_over(poses[:, :2], truth, has_truth)
    assert m["ate_rmse_m"] == pytest.approx(expected_ate, rel=1e-9)
    assert m["ate_online_rmse_m"] == pytest.approx(expected_ate, rel=1e-9)
    last = 799  # poses 800.. have no truth: the final error is that of pose 799
    assert m["final_pose_error_m"] == pytest.approx(float(np.hypot(*(poses[last, :2] - truth[last, :2]))), rel=1e-9)
    # NEES at the poses with truth only
    err = poses[has_truth] - truth[has_truth]
    err[:, 2] = (err[:, 2] + np.pi) % (2 * np.pi) - np.pi
    values = np.array([e @ np.linalg.solve(P, e) for e, P in zip(err, covariances[has_truth])])
    low, high = chi2.ppf(0.025, 3), chi2.ppf(0.975, 3)
    assert m["nees_count"] == int(has_truth.sum())
    assert m["nees_mean"] == pytest.approx(float(values.mean()), rel=1e-6)
    assert m["nees_inside_95"] * m["nees_count"] == pytest.approx(int(np.sum((values >= low) & (values <= high))))


@pytest.mark.parametrize("name", ["ekf", "isam2", "batch"])
def test_ate_of_every_estimator_is_the_rmse_over_the_poses_with_truth(partial, name):
    _, truth, has_truth, out, metrics, _ = partial
    assert metrics[name]["aligned"] is False
    assert metrics[name]["ate_rmse_m"] == pytest.approx(rmse_over(tum_xy(out / f"{name}.tum"), truth, has_truth), rel=1e-9)
    if name != "batch":
        online = tum_xy(out / f"{name}_online.tum")
        assert metrics[name]["ate_online_rmse_m"] == pytest.approx(rmse_over(online, truth, has_truth), rel=1e-9)


@pytest.mark.parametrize("name", ["ekf", "isam2"])
def test_rpe_uses_only_pairs_whose_two_ends_have_truth(partial, name):
    _, truth, has_truth, out, metrics, _ = partial
    # Δ: frames per ~1 m, from consecutive poses that both have truth
    both = has_truth[:-1] & has_truth[1:]
    step_m = np.hypot(*np.diff(truth[:, :2], axis=0).T)[both]
    delta = metrics["rpe_delta_frames"]
    assert delta == max(1, round(1.0 / float(step_m.mean())))
    estimate = tum_poses(out / f"{name}.tum")
    trans, heading = [], []
    for i in range(len(truth) - delta):
        if not (has_truth[i] and has_truth[i + delta]):
            continue
        Q = np.linalg.inv(se2(*truth[i])) @ se2(*truth[i + delta])
        P = np.linalg.inv(se2(*estimate[i])) @ se2(*estimate[i + delta])
        E = np.linalg.inv(Q) @ P
        trans.append(math.hypot(E[0, 2], E[1, 2]))
        heading.append(math.atan2(E[1, 0], E[0, 0]))
    pairs = len(trans)
    assert pairs == sum(has_truth[i] and has_truth[i + delta] for i in range(len(truth) - delta)) < len(truth) - delta
    assert metrics[name]["rpe_trans_rmse_m"] == pytest.approx(math.sqrt(np.mean(np.square(trans))), rel=1e-6)
    assert metrics[name]["rpe_heading_rmse_rad"] == pytest.approx(math.sqrt(np.mean(np.square(heading))), rel=1e-6)


def test_reference_tum_holds_only_the_poses_with_truth_and_evo_agrees(partial):
    evo_metrics = pytest.importorskip("evo.core.metrics")
    from evo.core import sync
    from evo.tools import file_interface

    _, truth, has_truth, out, metrics, _ = partial
    reference = np.loadtxt(out / "reference.tum")
    assert len(reference) == int(has_truth.sum())
    np.testing.assert_array_equal(reference[:, 1:3], truth[has_truth, :2])
    ref = file_interface.read_tum_trajectory_file(str(out / "reference.tum"))
    est = file_interface.read_tum_trajectory_file(str(out / "dead_reckoning.tum"))
    ref, est = sync.associate_trajectories(ref, est)  # by time stamp: the gaps drop out
    ape = evo_metrics.APE(evo_metrics.PoseRelation.translation_part)
    ape.process_data((ref, est))
    rmse = float(ape.get_statistic(evo_metrics.StatisticsType.rmse))
    assert rmse == pytest.approx(metrics["dead_reckoning"]["ate_rmse_m"], abs=1e-6)


def test_report_says_which_reference_and_breaks_at_the_gaps(partial):
    _, _, has_truth, out, _, _ = partial
    text = (out / "report.html").read_text(encoding="utf-8")
    n, k = len(has_truth), int(has_truth.sum())
    assert f"ground truth recorded in the log, {k} of {n} poses" in text
    assert "poses without truth are not scored" in text
    for name in ("trajectories.png", "position_error.png", "heading_error.png", "nees.png"):
        assert (out / name).stat().st_size > 10_000


def test_truth_gaps_in_time():
    from fgslam.report import truth_gaps_s

    t = np.arange(10.0)
    mask = np.array([1, 1, 0, 0, 1, 0, 1, 1, 0, 0], dtype=bool)
    # a curve breaks from the last pose with truth before a gap to the first after it
    assert truth_gaps_s(t, mask) == [(1.0, 4.0), (4.0, 6.0), (7.0, 9.0)]
    assert truth_gaps_s(t, np.ones(10, bool)) == []
    assert truth_gaps_s(t[:3], np.array([0, 1, 1], bool)) == [(0.0, 1.0)]


# --------------------------------------------------------------------------- fgslam check


def test_check_against_partial_truth_scores_only_the_poses_with_truth(partial, capsys):
    log, truth, has_truth, *_ = partial
    poses, _ = dead_reckoning_by_hand(log)
    result = check_estimator(log, estimator="dead_reckoning", against="truth", max_ate_m=100.0,
                             max_nees_outside=1.0)
    assert result.passed
    assert result.ate_m == pytest.approx(rmse_over(poses[:, :2], truth, has_truth), rel=1e-9)
    assert (result.poses_scored, result.poses) == (int(has_truth.sum()), len(has_truth))
    assert main(["check", str(log), "--estimator", "ekf", "--against", "truth"]) == 0
    line = capsys.readouterr().out.strip()
    assert line.startswith("PASS ekf vs truth on gappy.jsonl")
    assert f"({int(has_truth.sum())} of {len(has_truth)} poses have truth; only they are scored)" in line


@pytest.mark.parametrize("keep, needed", [(range(0, 400), 413), (range(0, 8), 413)])
def test_check_refuses_too_little_truth_naming_the_fix(tmp_path, capsys, keep, needed):
    log = write_without_truth_at(tmp_path / "sparse.jsonl", set(range(825)) - set(keep))
    with pytest.raises(FgslamError, match=rf"only {len(keep)} of 825 poses have ground truth.*use --against smoothed"):
        check_estimator(log, against="truth")
    assert main(["check", str(log), "--against", "truth"]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"at least {needed} needed" in err and "--against smoothed" in err


def test_check_on_a_short_log_with_full_truth_is_still_accepted(tmp_path):
    from fgslam.check import require_enough_truth

    require_enough_truth("short.jsonl", 5, 5)  # fewer than 10 poses, but all of them
    with pytest.raises(FgslamError, match="only 9 of 20 poses"):
        require_enough_truth("x.jsonl", 9, 20)
    with pytest.raises(FgslamError, match="only 10 of 21 poses"):  # less than half
        require_enough_truth("x.jsonl", 10, 21)
    require_enough_truth("x.jsonl", 11, 21)


# --------------------------------------------------------------------------- landmark-only truth


@pytest.fixture(scope="module")
def landmark_only(tmp_path_factory):
    from fgslam.runner import compare_log

    log_path = write_without_truth_at(tmp_path_factory.mktemp("lmonly") / "surveyed.jsonl", "all")
    log = read_log(log_path)
    result = compare_log(log, ("ekf", "isam2", "dead_reckoning"))
    metrics = compute_metrics(result.runs, result.reference, log_path=str(log_path))
    surveyed = {r.landmark_id: (r.x_m, r.y_m) for r in log.records if isinstance(r, TruthLandmark)}
    return result, metrics, surveyed


def test_landmark_only_truth_scores_the_map_against_the_surveyed_landmarks(landmark_only):
    result, metrics, surveyed = landmark_only
    assert metrics["reference"] == "smoothed"
    assert metrics["landmark_reference"] == "ground_truth"
    assert metrics["reference_poses_with_truth"] == 0 and metrics["reference_landmarks"] == len(surveyed) == 8
    runs = {r.name: r for r in result.runs}
    batch_map = runs["batch"].landmarks
    for name in ("ekf", "isam2", "dead_reckoning", "batch"):
        lm = runs[name].landmarks
        ids = sorted(set(lm) & set(surveyed))
        d = np.array([lm[i] for i in ids]) - np.array([surveyed[i] for i in ids])
        expected = math.sqrt(float(np.mean(np.sum(d * d, axis=1))))
        assert metrics[name]["map_rmse_m"] == pytest.approx(expected, rel=1e-9)
        assert metrics[name]["nees_mean"] is None  # no pose truth, no NEES
    assert metrics["batch"]["map_rmse_m"] > 1e-4  # not against its own (smoothed) landmarks
    assert metrics["batch"]["ate_rmse_m"] == pytest.approx(0.0, abs=1e-12)  # the trajectory reference
    assert set(batch_map) == set(surveyed)
    line = format_table(metrics).splitlines()[0]
    assert line.startswith("Reference: smoothed solution (batch LM over the whole log) for the trajectory")
    assert "map error against the 8 surveyed landmarks recorded in the log" in line


def test_no_truth_at_all_is_the_smoothed_reference(tmp_path):
    from fgslam.runner import choose_reference

    log = read_log(write_without_truth_at(tmp_path / "bare.jsonl", "all"))
    bare = read_log(SOURCE)
    n = len(log.steps())
    traj = np.zeros((n, 3))
    ref = choose_reference(log, traj, {1: (0.0, 0.0)})
    assert (ref.kind, ref.landmark_reference) == ("smoothed", "ground_truth")
    no_landmarks = type(log)(log.path, log.header, tuple(r for r in log.records if not isinstance(r, TruthLandmark)))
    ref = choose_reference(no_landmarks, traj, {1: (0.0, 0.0)})
    assert (ref.kind, ref.landmark_reference, ref.landmarks) == ("smoothed", "smoothed", {1: (0.0, 0.0)})
    assert ref.description == "smoothed solution (batch LM over the whole log; no ground truth)"
    full = choose_reference(bare, traj, {})
    assert full.kind == "ground_truth" and full.poses_with_truth == n and full.description == (
        "ground truth recorded in the log")


# --------------------------------------------------------------------------- the pure functions


def circle(n: int = 60) -> np.ndarray:
    a = np.linspace(0.0, 2.0 * np.pi, n)
    return np.c_[2.0 * np.sin(a), 2.0 - 2.0 * np.cos(a), (a + np.pi) % (2 * np.pi) - np.pi]


def test_poses_without_truth_do_not_count_even_when_the_estimate_is_wild_there():
    truth = circle()
    has = np.ones(len(truth), bool)
    has[[10, 11, 12, 40, 59]] = False
    reference = np.where(has[:, None], truth, np.nan)
    estimate = truth.copy()
    estimate[:, 0] += np.linspace(0.0, 0.6, len(truth))  # a drift growing from 0
    estimate[~has] = (1e6, -1e6, 3.0)  # garbage where there is no truth
    drift = np.linspace(0.0, 0.6, len(truth))
    assert ate_rmse_m(estimate, reference) == pytest.approx(math.sqrt(np.mean(drift[has] ** 2)), rel=1e-12)
    assert ate_rmse_m(estimate, truth, has_pose=has) == pytest.approx(math.sqrt(np.mean(drift[has] ** 2)), rel=1e-12)
    assert final_pose_error_m(estimate, reference) == pytest.approx(drift[58], rel=1e-12)  # 59 has no truth
    trans, _ = relative_pose_errors(estimate, reference, 2)
    assert len(trans) == sum(has[i] and has[i + 2] for i in range(len(truth) - 2)) and np.all(np.isfinite(trans))
    steps = np.hypot(*np.diff(truth[:, :2], axis=0).T)[has[:-1] & has[1:]]
    assert rpe_delta_frames(reference) == round(1.0 / steps.mean())


def test_alignment_is_fitted_to_the_poses_with_truth_only():
    truth = circle()
    has = np.ones(len(truth), bool)
    has[:5] = False  # pose 0 has no truth: the first-pose test looks at pose 5
    has[30:35] = False
    reference = np.where(has[:, None], truth, np.nan)
    angle, t = 0.6, np.array([3.0, -1.0])
    c, s = math.cos(angle), math.sin(angle)
    other = truth.copy()
    other[:, :2] = truth[:, :2] @ np.array([[c, -s], [s, c]]).T + t
    other[:, 2] += angle
    other[~has] = (50.0, 50.0, 0.0)  # would ruin a fit that used them
    run = EstimatorRun("other", other, other, {}, None, 0.0)
    m = compute_metrics([run], Reference("ground_truth", reference, {}), log_path="x")["other"]
    assert m["aligned"] is True and m["ate_rmse_m"] == pytest.approx(0.0, abs=1e-9)
    # the same trajectory in the reference's frame: pose 5 is shared, no alignment
    same = EstimatorRun("same", truth, truth, {}, None, 0.0)
    m = compute_metrics([same], Reference("ground_truth", reference, {}), log_path="x")
    assert m["same"]["aligned"] is False and m["reference_poses_with_truth"] == int(has.sum())
    assert m["landmark_reference"] is None
    assert "no landmark truth, so no map error" in format_table(m).splitlines()[0]


def test_has_pose_mask_blanks_the_rows_it_marks():
    truth = circle(10)
    has = np.array([1, 1, 1, 0, 1, 1, 1, 1, 1, 1], bool)
    ref = Reference("ground_truth", truth, {0: (1.0, 1.0)}, has_pose=has)
    assert np.isnan(ref.trajectory[3]).all() and np.isfinite(ref.trajectory[has]).all()
    assert ref.poses_with_truth == 9 and ref.landmark_reference == "ground_truth"
    assert not np.isnan(truth).any()  # the caller's array is untouched
    with pytest.raises(ValueError, match="has_pose"):
        Reference("ground_truth", truth, {}, has_pose=has[:5])


def test_monte_carlo_judges_only_the_steps_every_run_has_truth_at():
    from fgslam.montecarlo import MonteCarloResult

    average = np.array([3.0, 50.0, 3.0, 3.0])
    result = MonteCarloResult("x", [], {"ekf": average}, (2.0, 4.0), np.array([1, 0, 1, 1], bool))
    assert result.share_inside("ekf") == 1.0 and result.share_above("ekf") == 0.0
    assert result.mean_nees("ekf") == 3.0
    unmasked = MonteCarloResult("x", [], {"ekf": average}, (2.0, 4.0))
    assert unmasked.share_inside("ekf") == 0.75
