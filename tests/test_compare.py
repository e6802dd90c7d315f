"""Tests of fgslam.compare: alignment, error metrics, the metrics dict, the table, TUM files.

Every expected number comes from an independent construction (a transform we applied, an
offset we added, a percentile worked out by hand), never from the code under test.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fgslam.compare import (
    FIRST_POSE_TOL_M,
    METRIC_KEYS,
    ComparisonError,
    EstimatorRun,
    Reference,
    align_se2,
    apply_se2,
    ate_rmse_m,
    compute_metrics,
    final_pose_error_m,
    format_table,
    format_tum,
    heading_errors_rad,
    map_errors_m,
    map_rmse_m,
    position_errors_m,
    read_tum,
    resolve_alignment,
    shares_first_pose,
    write_tum,
    nees,
    nees_band,
    relative_pose_errors,
    rpe_delta_frames,
)


def random_trajectory(rng: np.random.Generator, n: int = 200) -> np.ndarray:
    """A planar random walk starting at the origin with heading 0: (n, 3)."""
    steps = rng.normal(0.0, [0.3, 0.3, 0.1], size=(n, 3))
    traj = np.cumsum(steps, axis=0)
    traj[:, :2] -= traj[0, :2]
    traj[:, 2] -= traj[0, 2]
    traj[:, 2] = (traj[:, 2] + np.pi) % (2 * np.pi) - np.pi
    return traj


def transform(points_xy: np.ndarray, angle_rad: float, t_xy) -> np.ndarray:
    """Independent rotation + translation of (n, 2) points with an explicit matrix."""
    R = np.array([[np.cos(angle_rad), -np.sin(angle_rad)], [np.sin(angle_rad), np.cos(angle_rad)]])
    return points_xy @ R.T + np.asarray(t_xy)


def umeyama_3d_reflection_allowed(src_xyz: np.ndarray, dst_xyz: np.ndarray):
    """Best rigid fit over O(3) — rotations *and reflections* — by SVD (Umeyama without the
    determinant correction). Stands in for a 3-D aligner that can return a mirror."""
    mu_s, mu_d = src_xyz.mean(axis=0), dst_xyz.mean(axis=0)
    H = (src_xyz - mu_s).T @ (dst_xyz - mu_d)
    U, _, Vt = np.linalg.svd(H)
    R = Vt.T @ U.T
    t = mu_d - R @ mu_s
    return R, t


# --------------------------------------------------------------------------- alignment


def test_align_se2_recovers_a_known_rotation_and_translation():
    rng = np.random.default_rng(12345)
    reference = random_trajectory(rng)
    true_angle, true_t = 0.7, np.array([3.0, -2.0])
    # Express the reference in another frame: estimate = inverse(T) applied to reference.
    estimate_xy = transform(reference[:, :2] - true_t, -true_angle, (0.0, 0.0))
    estimate = np.c_[estimate_xy, reference[:, 2] - true_angle]

    rotation_rad, translation_xy = align_se2(estimate[:, :2], reference[:, :2])

    assert rotation_rad == pytest.approx(true_angle, abs=1e-12)
    np.testing.assert_allclose(translation_xy, true_t, atol=1e-12)
    moved = apply_se2(estimate, rotation_rad, translation_xy)
    np.testing.assert_allclose(moved[:, :2], reference[:, :2], atol=1e-12)
    np.testing.assert_allclose(heading_errors_rad(moved, reference), 0.0, atol=1e-12)
    assert ate_rmse_m(estimate, reference, align=True) == pytest.approx(0.0, abs=1e-12)


@settings(max_examples=40, deadline=None)
@given(
    angle=st.floats(-math.pi + 1e-6, math.pi - 1e-6),
    tx=st.floats(-100, 100),
    ty=st.floats(-100, 100),
    seed=st.integers(0, 2**32 - 1),
)
def test_align_se2_recovers_any_transform(angle, tx, ty, seed):
    points = np.random.default_rng(seed).uniform(-10, 10, size=(20, 2))
    moved = transform(points, angle, (tx, ty))
    rotation_rad, translation_xy = align_se2(points, moved)
    assert math.remainder(rotation_rad - angle, 2 * math.pi) == pytest.approx(0.0, abs=1e-9)
    np.testing.assert_allclose(translation_xy, (tx, ty), atol=1e-8)


def test_mirrored_trajectory_is_not_aligned_away():
    rng = np.random.default_rng(7)
    reference = random_trajectory(rng)
    mirrored = reference * np.array([1.0, -1.0, -1.0])  # y -> -y (and headings mirror)
    spread_m = float(np.sqrt(np.mean(np.sum((reference[:, :2] - reference[:, :2].mean(0)) ** 2, axis=1))))

    # A reflection-allowing 3-D Umeyama "aligns" the mirror perfectly ...
    src = np.c_[mirrored[:, :2], np.zeros(len(mirrored))]
    dst = np.c_[reference[:, :2], np.zeros(len(reference))]
    R, t = umeyama_3d_reflection_allowed(src, dst)
    umeyama_rmse = float(np.sqrt(np.mean(np.sum((src @ R.T + t - dst) ** 2, axis=1))))
    assert np.linalg.det(R) == pytest.approx(-1.0)  # it chose a mirror
    assert umeyama_rmse < 1e-9

    # ... whereas SE(2) alignment cannot reflect, so the error stays of the order of the
    # trajectory's own size.
    ours = ate_rmse_m(mirrored, reference, align=True)
    assert ours > 0.3 * spread_m
    assert ours > 1e6 * umeyama_rmse


def test_no_alignment_when_first_pose_is_shared():
    rng = np.random.default_rng(3)
    reference = random_trajectory(rng)
    # A drift that grows from zero: the first pose is exactly shared.
    estimate = reference.copy()
    estimate[:, 0] += np.linspace(0.0, 2.0, len(reference))
    assert shares_first_pose(estimate, reference)
    aligned, rotation_rad, translation_xy = resolve_alignment(estimate, reference)
    assert not aligned and rotation_rad == 0.0 and np.all(translation_xy == 0.0)
    expected = math.sqrt(np.mean(np.linspace(0.0, 2.0, len(reference)) ** 2))
    assert ate_rmse_m(estimate, reference) == pytest.approx(expected, rel=1e-12)
    assert ate_rmse_m(estimate, reference, align=True) < expected  # alignment would hide drift


def test_first_pose_tolerance_absorbs_a_prior_sigma_but_not_another_frame():
    reference = random_trajectory(np.random.default_rng(4))
    near = reference.copy()
    near[0] += (1e-3, -1e-3, 2e-3)  # a few σ of the 1e-3 start prior
    assert shares_first_pose(near, reference)
    far = reference.copy()
    far[:, 0] += 0.5
    assert not shares_first_pose(far, reference)
    assert ate_rmse_m(far, reference) == pytest.approx(0.0, abs=1e-12)  # auto-aligned
    assert ate_rmse_m(far, reference, align=False) == pytest.approx(0.5)
    assert FIRST_POSE_TOL_M > 5e-3
    assert not shares_first_pose(near, reference, tol_m=1e-6, tol_rad=1e-6)


# --------------------------------------------------------------------------- error metrics


def test_ate_of_identical_and_offset_trajectories():
    reference = random_trajectory(np.random.default_rng(5))
    assert ate_rmse_m(reference.copy(), reference) == 0.0
    offset = reference.copy()
    offset[:, :2] += (0.6, 0.8)  # 1 m everywhere
    np.testing.assert_allclose(position_errors_m(offset, reference), 1.0, rtol=1e-12)
    assert ate_rmse_m(offset, reference, align=False) == pytest.approx(1.0, rel=1e-12)
    assert final_pose_error_m(offset, reference) == pytest.approx(1.0, rel=1e-12)


def test_heading_errors_wrap():
    estimate = np.array([[0.0, 0.0, 3.1], [0.0, 0.0, -3.1], [0.0, 0.0, 0.2]])
    reference = np.array([[0.0, 0.0, -3.1], [0.0, 0.0, 3.1], [0.0, 0.0, -0.1]])
    errors = heading_errors_rad(estimate, reference)
    np.testing.assert_allclose(errors, [6.2 - 2 * math.pi, 2 * math.pi - 6.2, 0.3], atol=1e-12)


def test_map_rmse_on_known_offsets():
    reference = {1: (0.0, 0.0), 2: (5.0, 5.0), 3: (9.0, 9.0)}
    estimate = {1: (3.0, 4.0), 2: (5.0, 6.0), 7: (100.0, 100.0)}  # errors 5 and 1; 7 unmatched
    assert map_errors_m(estimate, reference) == pytest.approx({1: 5.0, 2: 1.0})
    assert map_rmse_m(estimate, reference) == pytest.approx(math.sqrt((25.0 + 1.0) / 2.0))
    assert math.isnan(map_rmse_m({9: (0.0, 0.0)}, reference))
    # Landmarks in a rotated + shifted frame come back with that frame's transform.
    pts = np.array(list(reference.values()))
    moved = transform(pts, -0.4, (0.0, 0.0)) - (1.0, 2.0)  # the inverse of (0.4, R(0.4)(1, 2))
    t = transform(np.array([[1.0, 2.0]]), 0.4, (0.0, 0.0))[0]
    estimate_other_frame = {k: tuple(p) for k, p in zip(reference, moved)}
    assert map_rmse_m(estimate_other_frame, reference, 0.4, t) == pytest.approx(0.0, abs=1e-12)


def test_shape_mismatch_is_a_comparison_error():
    with pytest.raises(ComparisonError):
        position_errors_m(np.zeros((3, 3)), np.zeros((4, 3)))
    with pytest.raises(ValueError):  # ComparisonError is also a ValueError
        align_se2(np.zeros((3, 2)), np.zeros((2, 2)))


# --------------------------------------------------------------------------- metrics dict


def make_runs(n: int = 100):
    rng = np.random.default_rng(11)
    reference_traj = random_trajectory(rng, n)
    landmarks = {i: tuple(rng.uniform(-10, 10, size=2)) for i in range(6)}
    ekf_final = reference_traj.copy()
    ekf_final[-1, :2] += (0.3, 0.4)  # only the last pose is off, by 0.5 m
    ekf_landmarks = dict(landmarks)
    ekf_landmarks[0] = (landmarks[0][0] + 2.0, landmarks[0][1])  # 2 m off; 5 exact
    ekf = EstimatorRun(
        name="ekf",
        online=ekf_final.copy(),
        final=ekf_final,
        landmarks=ekf_landmarks,
        step_times_s=np.arange(1, n + 1) * 1e-3,  # 1 ms .. n ms
        total_time_s=0.25,
    )
    batch = EstimatorRun("batch", None, reference_traj.copy(), dict(landmarks), None, 1.5)
    reference = Reference("ground_truth", reference_traj, landmarks)
    return [ekf, batch], reference


def test_compute_metrics_values_keys_and_json():
    runs, reference = make_runs(100)
    metrics = compute_metrics(runs, reference, log_path="data/run.jsonl")

    text = json.dumps(metrics, allow_nan=False)  # plain types, no NaN
    assert json.loads(text) == metrics
    assert set(metrics) == {"reference", "log", "poses", "rpe_delta_frames", "reference_poses_with_truth",
                            "landmark_reference", "reference_landmarks", "dimension", "ekf", "batch"}
    assert metrics["dimension"] == 2
    assert metrics["reference"] == "ground_truth"
    assert metrics["reference_poses_with_truth"] == 100  # full truth: every pose
    assert metrics["landmark_reference"] == "ground_truth" and metrics["reference_landmarks"] == 6
    assert metrics["log"] == "data/run.jsonl"
    assert metrics["poses"] == 100
    for name in ("ekf", "batch"):
        assert set(metrics[name]) == set(METRIC_KEYS)
        assert tuple(metrics[name]) == METRIC_KEYS
        for value in metrics[name].values():
            assert type(value) in (float, int, bool, type(None))

    ekf = metrics["ekf"]
    assert ekf["ate_rmse_m"] == pytest.approx(math.sqrt(0.25 / 100))
    assert ekf["ate_online_rmse_m"] == pytest.approx(math.sqrt(0.25 / 100))
    assert ekf["final_pose_error_m"] == pytest.approx(0.5)
    assert ekf["map_rmse_m"] == pytest.approx(math.sqrt(4.0 / 6))
    assert ekf["landmarks_estimated"] == 6
    assert ekf["landmarks_found"] == 6 and ekf["landmarks_missed"] == 0
    assert ekf["aligned"] is False
    assert ekf["time_total_s"] == 0.25
    # Hand-worked linear-interpolation percentiles of 1..100 ms.
    assert ekf["time_step_p50_s"] == pytest.approx(50.5e-3)
    assert ekf["time_step_p99_s"] == pytest.approx(99.01e-3)
    assert ekf["time_step_max_s"] == pytest.approx(100e-3)
    assert ekf["steps"] == 100

    batch = metrics["batch"]
    assert batch["ate_rmse_m"] == 0.0 and batch["map_rmse_m"] == 0.0
    assert batch["ate_online_rmse_m"] is None
    assert batch["time_step_p50_s"] is None and batch["time_step_p99_s"] is None
    assert batch["time_total_s"] == 1.5


def test_compute_metrics_aligns_an_estimate_in_another_frame():
    runs, reference = make_runs(80)
    angle, t = 0.5, np.array([4.0, -1.0])
    other_xy = transform(reference.trajectory[:, :2] - t, -angle, (0.0, 0.0))
    other = np.c_[other_xy, reference.trajectory[:, 2] - angle]
    lm = {k: tuple(transform(np.array([v]) - t, -angle, (0, 0))[0]) for k, v in reference.landmarks.items()}
    run = EstimatorRun("imported", other, other, lm, np.full(80, 1e-3), 0.08)
    metrics = compute_metrics([run], reference, log_path="x")
    m = metrics["imported"]
    assert m["aligned"] is True
    assert m["ate_rmse_m"] == pytest.approx(0.0, abs=1e-9)
    assert m["ate_online_rmse_m"] == pytest.approx(0.0, abs=1e-9)
    assert m["map_rmse_m"] == pytest.approx(0.0, abs=1e-9)
    assert "*" in format_table(metrics)


def test_compute_metrics_nulls_and_short_runs():
    runs, reference = make_runs(50)
    short = EstimatorRun("live", reference.trajectory[:30], reference.trajectory[:30], {}, np.ones(30), 30.0)
    diverged_traj = reference.trajectory.copy()
    diverged_traj[10:] = np.nan
    diverged = EstimatorRun("diverged", None, diverged_traj, {0: (0.0, 0.0)}, None, 1.0)
    metrics = compute_metrics([short, diverged], reference, log_path="x")
    json.dumps(metrics, allow_nan=False)
    assert metrics["live"]["steps"] == 30
    assert metrics["live"]["map_rmse_m"] is None  # no landmark in common
    assert metrics["live"]["landmarks_estimated"] == 0
    assert metrics["live"]["landmarks_found"] == 0
    assert metrics["live"]["landmarks_missed"] == len(reference.landmarks)
    assert metrics["diverged"]["landmarks_found"] == 1  # landmark 0
    assert metrics["diverged"]["landmarks_missed"] == len(reference.landmarks) - 1
    assert metrics["diverged"]["ate_rmse_m"] is None
    assert "live estimated 30 of 50 poses" in format_table(metrics)


def test_compute_metrics_rejects_clashing_names_and_long_runs():
    runs, reference = make_runs(20)
    with pytest.raises(ComparisonError):
        compute_metrics([runs[0], runs[0]], reference, log_path="x")
    bad = EstimatorRun("poses", None, reference.trajectory, {}, None, 0.0)
    with pytest.raises(ComparisonError):
        compute_metrics([bad], reference, log_path="x")
    too_long = EstimatorRun("long", None, np.zeros((21, 3)), {}, None, 0.0)
    with pytest.raises(ComparisonError):
        compute_metrics([too_long], reference, log_path="x")


def test_format_table():
    runs, reference = make_runs(100)
    table = format_table(compute_metrics(runs, reference, log_path="data/run.jsonl"))
    lines = table.splitlines()
    assert lines[0].startswith("Reference: ground truth")
    assert "data/run.jsonl" in lines[0]
    assert "ATE final" in lines[1] and "p99" in lines[1]
    ekf_row = next(line for line in lines if line.startswith("ekf"))
    assert "0.0500" in ekf_row  # ATE sqrt(0.25/100) = 0.05 m
    assert "250.0" in ekf_row  # total 0.25 s in ms
    assert "50.500" in ekf_row and "99.010" in ekf_row  # p50 / p99 in ms
    batch_row = next(line for line in lines if line.startswith("batch"))
    assert batch_row.split()[2] == "-"  # no online ATE
    assert batch_row.split()[-1] == "-"  # no step times
    assert len({len(line) for line in lines[1:3]}) == 1  # header and rule line up


# --------------------------------------------------------------------------- TUM


def test_tum_quaternion_for_quarter_turn():
    line = format_tum([1.5], [[2.0, -3.0, math.pi / 2]]).strip()
    values = [float(v) for v in line.split()]
    assert values[:4] == [1.5, 2.0, -3.0, 0.0]
    expected = [0.0, 0.0, math.sin(math.pi / 4), math.cos(math.pi / 4)]
    np.testing.assert_allclose(values[4:], expected, atol=1e-15)


def test_tum_round_trip(tmp_path):
    rng = np.random.default_rng(21)
    stamps = 1.7e9 + np.cumsum(rng.uniform(0.01, 0.1, size=50))
    poses = np.c_[rng.normal(0, 100, size=(50, 2)), rng.uniform(-math.pi, math.pi, size=50)]
    path = tmp_path / "traj.tum"
    write_tum(path, stamps, poses)
    assert len(path.read_text().splitlines()) == 50
    stamps_back, poses_back = read_tum(path)
    np.testing.assert_array_equal(stamps_back, stamps)  # full precision
    np.testing.assert_array_equal(poses_back[:, :2], poses[:, :2])
    np.testing.assert_allclose(heading_errors_rad(poses_back, poses), 0.0, atol=1e-12)


def test_read_tum_reports_file_and_line(tmp_path):
    path = tmp_path / "bad.tum"
    path.write_text("# comment\n0 0 0 0 0 0 0 1\n1 2 3\n")
    with pytest.raises(ComparisonError, match=r"bad\.tum:3:"):
        read_tum(path)


def test_compare_imports_neither_gtsam_nor_matplotlib():
    code = (
        "import sys, fgslam.compare; "
        "bad = [m for m in ('gtsam', 'matplotlib') if m in sys.modules]; "
        "print(*bad); sys.exit(1 if bad else 0)"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert result.returncode == 0, result.stdout + result.stderr


# --------------------------------------------------------------------------- association scoring


def test_score_associations_by_hand():
    from fgslam.compare import relabel_landmarks, score_associations

    # true ids of 8 observations and the keys an estimator used them as
    true_ids = [5, 7, 5, None, 7, 5, 9, 7]
    keys = [-1, -2, -1, -1, -3, None, -2, -2]
    score = score_associations(true_ids, keys)
    # -1 stands for 5, -2 for 7; -3 is a second landmark for 7 (duplicate);
    # obs 4 (key -3) wrong, obs 5 rejected, obs 6 (true 9 as -2) wrong; obs 3 unscored.
    assert score.identity == {-1: 5, -2: 7, -3: 7}
    assert score.duplicate_keys == {-3}
    assert (score.observations, score.correct, score.rejected) == (7, 4, 1)
    assert score.rate == 4 / 7
    assert score.landmarks_created == 3
    assert relabel_landmarks({-1: (1.0, 2.0), -2: (3.0, 4.0), -3: (5.0, 6.0)}, score) == {5: (1.0, 2.0), 7: (3.0, 4.0)}


def test_a_key_stands_for_the_landmark_most_of_its_observations_saw():
    from fgslam.compare import score_associations

    # key -1 was created by a misdetection (true id 4) that fell where landmark 5 is
    score = score_associations([4, 5, 5, 5, 4, 4, 4], [-1, -1, -1, -1, -2, -2, -3])
    assert score.identity == {-1: 5, -2: 4, -3: 4}
    assert score.duplicate_keys == {-3}  # -2 holds more observations of 4
    assert (score.correct, score.wrong) == (5, 2)


def test_metrics_report_association_and_heights():
    from fgslam.compare import score_associations

    traj = np.zeros((3, 3))
    score = score_associations([1, 1, 2], [-1, -1, None])
    run = EstimatorRun("ekf-nn", traj, traj, {1: (0.0, 0.0)}, np.ones(3), 3.0, score, {1: 0.5})
    ref = Reference("ground_truth", traj, {1: (0.0, 0.0)}, {1: 0.4})
    m = compute_metrics([run], ref, log_path="x")["ekf-nn"]
    assert m["association"] == {
        "observations": 3, "correct": 2, "wrong": 0, "rate": 2 / 3, "rejected": 1, "new": 1,
        "landmarks_created": 1, "duplicate_landmarks": 0,
    }
    assert m["map_height_rmse_m"] == pytest.approx(0.1)


def _se2_matrix(pose):
    x, y, th = pose
    return np.array([[math.cos(th), -math.sin(th), x], [math.sin(th), math.cos(th), y], [0.0, 0.0, 1.0]])


@pytest.mark.parametrize("delta", [1, 3, 10])
def test_relative_pose_errors_match_homogeneous_matrices(delta):
    rng = np.random.default_rng(delta)
    reference = random_trajectory(rng, 60)
    estimate = reference + rng.normal(0.0, [0.05, 0.05, 0.02], size=reference.shape)
    trans, heading = relative_pose_errors(estimate, reference, delta)
    assert len(trans) == len(heading) == 60 - delta
    for i in range(60 - delta):
        Q = np.linalg.inv(_se2_matrix(reference[i])) @ _se2_matrix(reference[i + delta])
        P = np.linalg.inv(_se2_matrix(estimate[i])) @ _se2_matrix(estimate[i + delta])
        E = np.linalg.inv(Q) @ P
        assert trans[i] == pytest.approx(math.hypot(E[0, 2], E[1, 2]), abs=1e-12)
        assert heading[i] == pytest.approx(abs(math.atan2(E[1, 0], E[0, 0])), abs=1e-12)


def test_relative_pose_errors_ignore_a_rigid_transform_and_need_a_positive_delta():
    rng = np.random.default_rng(5)
    reference = random_trajectory(rng, 30)
    moved = np.column_stack([
        math.cos(0.7) * reference[:, 0] - math.sin(0.7) * reference[:, 1] + 3.0,
        math.sin(0.7) * reference[:, 0] + math.cos(0.7) * reference[:, 1] - 1.0,
        reference[:, 2] + 0.7,
    ])
    trans, heading = relative_pose_errors(moved, reference, 4)
    assert trans.max() < 1e-12 and heading.max() < 1e-12
    with pytest.raises(ComparisonError, match="delta_frames"):
        relative_pose_errors(moved, reference, 0)
    straight = np.column_stack([np.arange(11.0), np.zeros(11), np.zeros(11)])  # 1 m per frame
    assert rpe_delta_frames(straight, 3.0) == 3


def test_nees_is_the_mahalanobis_distance_of_the_pose_error():
    reference = np.array([[0.0, 0.0, 3.1], [1.0, 2.0, -0.5]])
    estimate = reference + np.array([[0.1, -0.2, 0.1], [0.0, 0.3, 0.02]])
    estimate[0, 2] = -3.1  # 0.083 rad from 3.1 across the wrap, not 6.2
    P = np.array([np.diag([0.01, 0.04, 0.01]), np.diag([1.0, 0.09, 0.0004])])
    expected = [0.1**2 / 0.01 + 0.2**2 / 0.04 + (2 * math.pi - 6.2) ** 2 / 0.01, 0.3**2 / 0.09 + 0.02**2 / 0.0004]
    assert nees(estimate, P, reference) == pytest.approx(expected, rel=1e-12)
    bad = P.copy()
    bad[1] = -np.eye(3)  # not positive definite: NaN, not a crash
    assert math.isnan(nees(estimate, bad, reference)[1])


def test_nees_of_a_consistent_estimator_is_chi2_with_3_dof():
    rng = np.random.default_rng(2006)
    n = 4000
    A = rng.normal(size=(n, 3, 3)) * 0.1
    P = A @ np.transpose(A, (0, 2, 1)) + 1e-3 * np.eye(3)
    errors = np.array([rng.multivariate_normal(np.zeros(3), p) for p in P])
    reference = np.zeros((n, 3))
    values = nees(errors, P, reference)
    low, high = nees_band()
    assert np.mean(values) == pytest.approx(3.0, abs=4 * math.sqrt(6 / n))
    assert np.mean((values >= low) & (values <= high)) == pytest.approx(0.95, abs=4 * math.sqrt(0.95 * 0.05 / n))


def test_nees_band_from_scipy():
    assert nees_band() == pytest.approx((0.2158, 9.3484), abs=1e-4)
    assert nees_band(3, 50) == pytest.approx((2.36, 3.72), abs=0.005)  # the N = 50 Monte Carlo band
