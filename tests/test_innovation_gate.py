"""The innovation-covariance gate of fgslam.smoother.pending: a waiting observation the plain
gate (the reading's R alone) fails is judged against S = R + J Σ Jᵀ, Σ the iSAM2 marginals
of its pose and landmark.

Checked against numpy (rᵀ S⁻¹ r with R, J and Σ given; J by central differences of the
bearing-range model), on a hand-built drive where the plain gate would drop a correct old
sighting (a loop closure) that the new gate keeps, and on a simulated arena log with 10 %
misdetections, which must still be dropped.
"""

from __future__ import annotations

import math

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import L, X

from fgslam.compare import ate_rmse_m
from fgslam.runner import run_estimator
from fgslam.smoother import Isam2Smoother
from fgslam.smoother.factors import PendingObservation
from fgslam.smoother.pending import PENDING_GATE, innovation_gate_half_d2, innovation_half_d2, within_gate
from slamio.geometry import wrap_angle
from slamio.log import Observation, Odometry, Step, TruthPose, as_matrix3, group_steps
from slamio.sim import simulate
from loop_logs import make_header


def bearing_range(pose_xyt, landmark_xy) -> np.ndarray:
    """(bearing_rad, range_m) of a landmark from a pose."""
    x, y, t = pose_xyt
    dx, dy = landmark_xy[0] - x, landmark_xy[1] - y
    return np.array([wrap_angle(math.atan2(dy, dx) - t), math.hypot(dx, dy)])


def test_innovation_half_d2_is_the_unwhitened_mahalanobis_distance():
    """Whitened in, the same ½ rᵀ (R + J Σ Jᵀ)⁻¹ r as numpy computes unwhitened; Σ = 0
    gives the plain gate's ½‖R^-½ r‖²."""
    rng = np.random.default_rng(7)
    for _ in range(5):
        J = rng.normal(size=(2, 5))
        M = rng.normal(size=(5, 5))
        sigma = M @ M.T * 0.1
        B = rng.normal(size=(2, 2))
        R = B @ B.T + 0.01 * np.eye(2)
        r = rng.normal(size=2)
        W = np.linalg.inv(np.linalg.cholesky(R))  # R^-½: W R Wᵀ = I
        expected = 0.5 * r @ np.linalg.inv(R + J @ sigma @ J.T) @ r
        assert innovation_half_d2(W @ r, W @ J, sigma) == pytest.approx(expected, rel=1e-10)
        assert innovation_half_d2(W @ r, W @ J, np.zeros((5, 5))) == pytest.approx(0.5 * r @ np.linalg.inv(R) @ r,
                                                                                   rel=1e-10)


def test_innovation_gate_matches_a_hand_computation_with_isam2_marginals():
    """A pose and a landmark with only priors: iSAM2's marginals are the priors' covariances.
    ½ rᵀ S⁻¹ r with J by central differences (the pose perturbed in its own frame, as
    GTSAM's Pose2 retract does) agrees, and is smaller than the plain gate's ½‖r‖²."""
    pose = (1.0, -0.5, 0.3)
    landmark = np.array([4.0, 1.5])
    P_pose = np.array([[0.04, 0.01, 0.002], [0.01, 0.09, -0.003], [0.002, -0.003, 0.01]])
    P_landmark = np.array([[0.25, -0.05], [-0.05, 0.16]])
    sigma_bearing_rad, sigma_range_m = 0.01, 0.05
    measured = np.array([0.5, 3.4])  # bearing, range: many σ off the prediction
    isam = gtsam.ISAM2()
    graph = gtsam.NonlinearFactorGraph()
    graph.add(gtsam.PriorFactorPose2(X(0), gtsam.Pose2(*pose), gtsam.noiseModel.Gaussian.Covariance(P_pose)))
    graph.add(gtsam.PriorFactorPoint2(L(1), landmark, gtsam.noiseModel.Gaussian.Covariance(P_landmark)))
    values = gtsam.Values()
    values.insert(X(0), gtsam.Pose2(*pose))
    values.insert(L(1), landmark)
    isam.update(graph, values)
    noise = gtsam.noiseModel.Diagonal.Sigmas(np.array([sigma_bearing_rad, sigma_range_m]))
    factor = gtsam.BearingRangeFactor2D(X(0), L(1), gtsam.Rot2(measured[0]), measured[1], noise)
    entry = PendingObservation(1, L(1), 0, factor, factor, None, gtsam.Pose2(*pose), polar=(measured[1], measured[0]))

    def h(delta):
        moved = gtsam.Pose2(*pose).retract(delta[:3])
        return bearing_range((moved.x(), moved.y(), moved.theta()), landmark + delta[3:])

    eps = 1e-6
    J = np.column_stack([(h(eps * e) - h(-eps * e)) / (2 * eps) for e in np.eye(5)])
    sigma = np.zeros((5, 5))
    sigma[:3, :3], sigma[3:, 3:] = P_pose, P_landmark
    S = np.diag([sigma_bearing_rad**2, sigma_range_m**2]) + J @ sigma @ J.T
    r = h(np.zeros(5)) - measured
    expected = 0.5 * r @ np.linalg.solve(S, r)
    got = innovation_gate_half_d2(entry, gtsam.Pose2(*pose), landmark, isam)
    assert got == pytest.approx(expected, rel=1e-5)
    plain = 0.5 * np.sum((r / [sigma_bearing_rad, sigma_range_m]) ** 2)
    assert factor.error(values) == pytest.approx(plain, rel=1e-9)
    assert got < PENDING_GATE < plain  # the plain gate drops it, the innovation gate keeps it


LANDMARK = (3.0, 2.0)
STEP_M = 0.1
ODOMETRY_BIAS = 1.07  # the odometry reads 7 % long: 0.5 m of drift over the 75 steps unseen
SIGMA_ODO = (0.03, 0.01, 0.002)  # dx_m, dy_m, dtheta_rad a step: the drift is 2σ along the track


def drifting_drive(first_sighting: bool = True):
    """Header, steps and true poses of a straight 100-step drive along x.

    The landmark is seen (exact readings, σ 5 cm / 0.01 rad) from step 5, then not again
    until steps 80–99, after the odometry has drifted 0.5 m. Without ``first_sighting`` the
    reading from step 5 is left out of the log."""
    header = make_header(start_pose=(0.0, 0.0, 0.0))
    truth = [(STEP_M * k, 0.0, 0.0) for k in range(100)]
    Q = as_matrix3(np.diag(np.square(SIGMA_ODO)))
    steps = []
    for k, pose in enumerate(truth):
        stamp = 0.1 * k
        odometry = None if k == 0 else Odometry(stamp, STEP_M * ODOMETRY_BIAS, 0.0, 0.0, covariance=Q)
        seen = (k == 5 and first_sighting) or k >= 80
        b, r = bearing_range(pose, LANDMARK)
        observations = (Observation(stamp, 7, r, b, 0.05, 0.01),) if seen else ()
        steps.append(Step(k, stamp, odometry, observations, TruthPose(stamp, *pose)))
    return header, steps, np.array(truth)


def test_the_innovation_gate_keeps_a_loop_closure_the_plain_gate_would_drop():
    """The sighting from step 5 disagrees with the one from step 80 (0.5 m apart), so the
    landmark is confirmed by steps 80 and 81 and seeded from the drifted pose; the old
    sighting, judged with R alone at that estimate, fails the plain gate by far, but its
    pose's and the landmark's marginals account for the drift: it is kept and closes the
    loop. The reference: the same drive with that reading left out of the log."""
    header, steps, truth = drifting_drive()
    smoother = Isam2Smoother(header, robust="dcs")
    judged = []
    for step in steps:
        waiting = [e for e in smoother._pending.withheld if e.pose_index == 5]
        if waiting and 7 in smoother._landmarks.known and not judged:
            e, isam = waiting[0], smoother._isam
            pose, landmark = isam.calculateEstimatePose2(X(5)), isam.calculateEstimatePoint2(L(7))
            judged = [e.gate_factor.error(_values(pose, landmark)), innovation_gate_half_d2(e, pose, landmark, isam)]
        smoother.step(step)
    smoother.finish()
    assert judged, "the sighting from step 5 should wait for the landmark's estimate"
    assert judged[0] > 2 * PENDING_GATE and not within_gate(e, pose, landmark)  # the plain gate drops it
    assert judged[1] < PENDING_GATE  # the innovation gate keeps it
    assert smoother.dropped_observations == 0 and smoother._pending.kept_by_innovation_gate == 1
    without = run_estimator(Isam2Smoother(header, robust="dcs"), drifting_drive(first_sighting=False)[1])[1]
    ate_with, ate_without = ate_rmse_m(smoother.trajectory(), truth), ate_rmse_m(without.trajectory(), truth)
    assert ate_with < 0.5 * ate_without, (ate_with, ate_without)


def _values(pose, landmark) -> gtsam.Values:
    values = gtsam.Values()
    values.insert(X(5), pose)
    values.insert(L(7), landmark)
    return values


def test_misdetections_are_still_dropped_on_an_arena_log_with_10_percent_outliers():
    """Arena-octagon seed 3 with 10 % misdetections (replacing readings), DCS as `fgslam run`
    chooses it. The misdetections are the readings that differ from the same seed's clean
    log. Every reading that stays out of the graph is one of them (no correct one lost),
    three are gated out, and the final and online ATE are within 1.2× of the same smoother
    on the log with exactly the misdetections removed (the oracle)."""
    header, clean_records = simulate("arena-octagon", 3)
    clean = group_steps(header, clean_records)
    noisy_header, records = simulate("arena-octagon", 3, outliers=0.1)
    noisy = group_steps(noisy_header, records)
    misdetections = {(b.index, o1.range_m, o1.bearing_rad) for a, b in zip(clean, noisy)
                     for o0, o1 in zip(a.observations, b.observations) if o0 != o1}
    oracle = [Step(b.index, b.stamp_s, b.odometry,
                   tuple(o1 for o0, o1 in zip(a.observations, b.observations) if o0 == o1), b.truth)
              for a, b in zip(clean, noisy)]
    truth = np.array([[s.truth.x_m, s.truth.y_m, s.truth.theta_rad] for s in clean])
    run, robust = run_estimator(Isam2Smoother(noisy_header, robust="dcs"), noisy, covariances=False)
    reference, _ = run_estimator(Isam2Smoother(header), oracle, covariances=False)
    in_graph = set()
    graph = robust.graph()
    for i in range(graph.size()):
        factor = graph.at(i)
        if isinstance(factor, gtsam.BearingRangeFactor2D):
            k = gtsam.Symbol(factor.keys()[0]).index()
            in_graph.add((k, round(factor.measured().range(), 9), round(factor.measured().bearing().theta(), 9)))
    left_out = {(s.index, round(o.range_m, 9), round(wrap_angle(o.bearing_rad), 9))
                for s in noisy for o in s.observations} - in_graph
    assert left_out <= {(k, round(r, 9), round(wrap_angle(b), 9)) for k, r, b in misdetections}
    assert robust.dropped_observations == 3 and robust._pending.kept_by_innovation_gate == 0
    assert ate_rmse_m(run.final, truth) <= 1.2 * ate_rmse_m(reference.final, truth)
    assert ate_rmse_m(run.online, truth) <= 1.2 * ate_rmse_m(reference.online, truth)
