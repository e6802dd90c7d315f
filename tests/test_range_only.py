"""Range-only landmarks: trilateration, the delayed-initialisation rule, the log format,
and both estimators on a simulated ranging-radio run (iSAM2 against batch LM)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from builders import minimal_header
from ekf import DeadReckoning, EkfSlam
from ekf.range_only import DelayedInitRule, mirror_across_line, trilaterate, try_initialise
from fgslam.compare import ate_rmse_m
from fgslam.runner import run_estimator
from fgslam.smoother import Isam2Smoother, batch_solve
from slamio.geometry import arc_increment, arc_increment_jacobian
from slamio.log import Observation, Odometry, TruthPose, group_steps, parse_record, read_log, write_log

BEACONS = {0: (6.0, 1.0), 1: (-3.0, 7.0), 5: (2.0, -6.0), 6: (-7.0, -2.0)}


def test_trilaterate_recovers_a_point_from_exact_ranges():
    rng = np.random.default_rng(1)
    target = np.array([3.0, -2.0])
    positions = rng.uniform(-5, 5, size=(8, 2))
    ranges = np.hypot(*(positions - target).T)
    fit = trilaterate(positions, ranges, np.full(8, 0.1))
    np.testing.assert_allclose(fit.xy, target, atol=1e-9)
    assert fit.chi2 < 1e-12
    # covariance (JᵀWJ)⁻¹ with J the unit vectors from the positions to the point
    J = (target - positions) / ranges[:, None]
    np.testing.assert_allclose(fit.covariance, np.linalg.inv(J.T @ J / 0.01), rtol=1e-6)


def test_mirror_is_the_reflection_across_the_positions_line():
    positions = np.array([[0.0, 1.0], [1.0, 2.0], [2.0, 3.0]])  # the line y = x + 1
    np.testing.assert_allclose(mirror_across_line([2.0, 0.0], positions), [-1.0, 3.0], atol=1e-12)


def test_straight_drive_waits_for_a_turn():
    """On a straight line the landmark and its mirror fit equally well: not initialised."""
    rule = DelayedInitRule(min_ranges=6)
    target = np.array([4.0, 3.0])
    line = np.c_[np.linspace(0, 6, 10), np.zeros(10)]
    ranges = np.hypot(*(line - target).T)
    assert try_initialise(line, ranges, np.full(10, 0.05), rule) is None
    turned = np.vstack([line, [[6.0, 1.0], [6.0, 2.0], [5.5, 3.0]]])
    ranges = np.hypot(*(turned - target).T)
    fit = try_initialise(turned, ranges, np.full(len(turned), 0.05), rule)
    assert fit is not None
    np.testing.assert_allclose(fit.xy, target, atol=1e-6)
    assert try_initialise(turned[:4], ranges[:4], np.full(4, 0.05), rule) is None  # too few ranges


def test_log_accepts_range_only_observations():
    record = parse_record({"type": "observation", "stamp_s": 1.0, "landmark_id": 3, "range_m": 12.5,
                           "sigma_range_m": 1.5})
    assert record.range_only and record.bearing_rad is None and record.sigma_bearing_rad is None
    with pytest.raises(Exception, match="go together"):
        parse_record({"type": "observation", "stamp_s": 1.0, "landmark_id": 3, "range_m": 12.5,
                      "sigma_range_m": 1.5, "bearing_rad": 0.1})
    with pytest.raises(Exception, match="tag yaw"):
        parse_record({"type": "observation", "stamp_s": 1.0, "landmark_id": 3, "range_m": 12.5,
                      "sigma_range_m": 1.5, "tag_yaw_rad": 0.1, "sigma_tag_yaw_rad": 0.1})


def range_only_run(seed: int = 3, laps: float = 2.0, sigma_range_m: float = 0.3):
    """A robot driving a 4 m circle (0.1 s steps) ranging to four beacons, one range per step
    in turn; noisy odometry with the covariance it states."""
    rng = np.random.default_rng(seed)
    header = minimal_header(start_pose=(0.0, -4.0, 0.0))
    steps_per_lap = 250
    distance, angle = 2 * math.pi * 4.0 / steps_per_lap, 2 * math.pi / steps_per_lap
    sd, sa = 0.02 * distance + 0.002, 0.02 * angle + 0.002
    pose = np.array(header.start_pose)
    records = [TruthPose(0.0, *pose)]
    for k in range(1, int(laps * steps_per_lap) + 1):
        t = 0.1 * k
        dx, dy, dth = arc_increment(distance, angle)
        c, s = math.cos(pose[2]), math.sin(pose[2])
        pose = np.array([pose[0] + c * dx - s * dy, pose[1] + s * dx + c * dy, pose[2] + dth])
        noisy = arc_increment(distance + rng.normal(0, sd), angle + rng.normal(0, sa))
        J = arc_increment_jacobian(distance, angle)
        cov = J @ np.diag([sd**2, sa**2]) @ J.T + np.diag([1e-8, 1e-8, 1e-10])
        records.append(Odometry(t, *noisy, tuple(map(tuple, cov))))
        records.append(TruthPose(t, *pose))
        lid = list(BEACONS)[k % 4]
        true_range = math.hypot(BEACONS[lid][0] - pose[0], BEACONS[lid][1] - pose[1])
        records.append(Observation(t, lid, true_range + rng.normal(0, sigma_range_m), None, sigma_range_m, None))
    return header, records


@pytest.fixture(scope="module")
def simulated():
    header, records = range_only_run()
    steps = group_steps(header, records)
    truth = np.array([[s.truth.x_m, s.truth.y_m, s.truth.theta_rad] for s in steps])
    return header, records, steps, truth


def test_both_estimators_place_every_beacon_and_beat_dead_reckoning(simulated):
    header, _, steps, truth = simulated
    ekf_run, ekf = run_estimator(EkfSlam(header), steps)
    isam_run, _ = run_estimator(Isam2Smoother(header), steps)
    dr_run, _ = run_estimator(DeadReckoning(header), steps)
    for run in (ekf_run, isam_run):
        assert set(run.landmarks) == set(BEACONS)
        for lid, xy in run.landmarks.items():
            assert math.dist(xy, BEACONS[lid]) < 0.3, (run.name, lid, xy)
        assert ate_rmse_m(run.final, truth) < 0.5 * ate_rmse_m(dr_run.final, truth)
    assert ekf.range_landmarks_initialised == 4 and ekf.range_updates > 300


def test_isam2_with_range_factors_reaches_the_batch_optimum(simulated):
    header, _, steps, truth = simulated
    _, smoother = run_estimator(Isam2Smoother(header), steps, covariances=False)
    batch = batch_solve(smoother)
    final = smoother.trajectory()
    assert np.max(np.hypot(*(final[:, :2] - batch.trajectory[:, :2]).T)) < 1e-3
    assert smoother.error() == pytest.approx(batch.final_error, rel=1e-4)


def test_online_correction_uses_ranges_between_updates(simulated):
    """Between iSAM2 updates the pose-only correction takes the ranges to placed beacons
    (fgslam/smoother/correction.py): the online pose is closer to an iSAM2 that updates at
    every step than the dead reckoning between the same updates."""
    header, _, steps, _ = simulated

    def online(**kwargs):
        settings = {"update_every": 25, "update_observations": None, **kwargs}
        run, smoother = run_estimator(Isam2Smoother(header, **settings), steps, covariances=False)
        return run.online, smoother

    reference, _ = online(update_every=1, online_correction=False)
    corrected, smoother = online()
    uncorrected, _ = online(online_correction=False)
    assert smoother._corrector.corrections > 100

    def gap(a):
        return float(np.sqrt(np.mean(np.sum((a[:, :2] - reference[:, :2]) ** 2, axis=1))))

    assert gap(corrected) < gap(uncorrected)


def test_range_only_log_round_trips(simulated, tmp_path):
    header, records, _, _ = simulated
    path = tmp_path / "ranges.jsonl"
    write_log(path, header, records)
    log = read_log(path)
    assert list(log.records) == list(records)


def test_ekf_range_update_is_the_textbook_update(simulated):
    """One range update against the full-state formula with a finite-difference Jacobian."""
    import copy

    from slamio.log import Step

    header, _, steps, _ = simulated
    ekf = EkfSlam(header)
    for step in steps[:300]:
        ekf.step(step)
    step = next(s for s in steps[300:] if s.observations and s.observations[0].landmark_id in ekf.landmarks())
    twin = copy.deepcopy(ekf)
    twin.step(Step(step.index, step.stamp_s, step.odometry, (), step.truth))
    x, P = twin.state_mean(), twin.state_covariance()
    obs = step.observations[0]
    i = twin.landmark_index(obs.landmark_id)

    def h(state):
        return math.hypot(state[i] - state[0], state[i + 1] - state[1])

    H = np.array([[(h(x + e) - h(x - e)) / 2e-6 for e in 1e-6 * np.eye(len(x))]])
    R = np.array([[obs.sigma_range_m**2]])
    K = P @ H.T @ np.linalg.inv(H @ P @ H.T + R)
    expected_mean = x + (K * (obs.range_m - h(x))).ravel()
    A = np.eye(len(x)) - K @ H
    expected_cov = A @ P @ A.T + K @ R @ K.T
    ekf.step(step)
    np.testing.assert_allclose(ekf.state_mean(), expected_mean, atol=1e-8)
    np.testing.assert_allclose(ekf.state_covariance(), expected_cov, atol=1e-10)


@pytest.mark.parametrize("scale", [1.0, 1.07])
def test_a_radios_range_scale_is_learned_without_truth(scale):
    """Ranges read ``scale`` long (Plaza's radios: 1.069 by GPS) are recognised against the
    odometry, the only other measure of distance the run has: the fit without truth finds
    the scale put in, and the σ of the ranges about it."""
    from fgslam.self_calibration import fit_without_truth
    from slamio.log import RunLog

    header, records = range_only_run(seed=5, laps=3.0)
    scaled = tuple(dataclasses.replace(r, range_m=scale * r.range_m) if isinstance(r, Observation) else r
                   for r in records)
    fit = fit_without_truth([RunLog("scaled.jsonl", header, scaled)])
    observation = fit.model.observation
    assert observation.range_scale == pytest.approx(scale, abs=0.005)
    assert observation.range_sigma_m == pytest.approx(0.3 * scale, rel=0.15)
    assert "observation.range_scale" not in fit.report["not_determined_without_truth"]
    from fgslam.cli.calibrate import noise_model_summary, self_fit_notes
    assert f"ranges (no bearing): measured = {observation.range_scale:.4f} x distance" in noise_model_summary(fit.model)
    assert f"radio ranges read {observation.range_scale:.4f} x the distance" in self_fit_notes(fit)
