"""scripts/experiments/online_kernel.py: the DCS weight and the innovation gate it measures,
against GTSAM's own kernel and a hand computation; and the gate on a simulated log with
misdetections (they must still be dropped)."""

import math

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import L, X

from fgslam.smoother.factors import PendingObservation
from scripts.experiments.online_kernel import DCS_PHI, dcs_weight, innovation_half_d2, smoother
from scripts.bench_mrclam import ate_pair_m
from fgslam.runner import run_estimator, truth_trajectory
from slamio.log import group_steps
from slamio.sim import simulate


@pytest.mark.parametrize("r", [0.0, 1.0, 3.7, 3.8, 5.0, 20.0])
def test_dcs_weight_is_gtsams(r):
    gtsam_dcs = gtsam.noiseModel.mEstimator.DCS.Create(DCS_PHI)
    assert dcs_weight(r * r) == pytest.approx(gtsam_dcs.weight(r), rel=1e-12)


def _bearing_range(pose_xyt, landmark_xy):
    x, y, t = pose_xyt
    dx, dy = landmark_xy[0] - x, landmark_xy[1] - y
    return np.array([math.atan2(dy, dx) - t, math.hypot(dx, dy)])


def test_innovation_gate_matches_a_hand_computation():
    """½ rᵀ S⁻¹ r with S = R + J Σ Jᵀ, J by central differences of the bearing-range model
    (the pose perturbed in its own frame, as GTSAM's Pose2 is), Σ the priors' covariances
    (iSAM2's marginals of two variables that only have priors)."""
    pose = (1.0, -0.5, 0.3)
    landmark = np.array([4.0, 1.5])
    P_pose = np.array([[0.04, 0.01, 0.002], [0.01, 0.09, -0.003], [0.002, -0.003, 0.01]])
    P_landmark = np.array([[0.25, -0.05], [-0.05, 0.16]])
    sigma_b, sigma_r = 0.01, 0.05
    measured = (0.5, 3.4)  # bearing, range: a few σ off the prediction
    isam = gtsam.ISAM2()
    graph = gtsam.NonlinearFactorGraph()
    graph.add(gtsam.PriorFactorPose2(X(0), gtsam.Pose2(*pose), gtsam.noiseModel.Gaussian.Covariance(P_pose)))
    graph.add(gtsam.PriorFactorPoint2(L(1), landmark, gtsam.noiseModel.Gaussian.Covariance(P_landmark)))
    values = gtsam.Values()
    values.insert(X(0), gtsam.Pose2(*pose))
    values.insert(L(1), landmark)
    isam.update(graph, values)
    noise = gtsam.noiseModel.Diagonal.Sigmas(np.array([sigma_b, sigma_r]))
    factor = gtsam.BearingRangeFactor2D(X(0), L(1), gtsam.Rot2(measured[0]), measured[1], noise)
    entry = PendingObservation(1, L(1), 0, factor, factor, None, gtsam.Pose2(*pose), polar=(measured[1], measured[0]))

    def h(delta):
        moved = gtsam.Pose2(*pose).retract(delta[:3])
        return _bearing_range((moved.x(), moved.y(), moved.theta()), landmark + delta[3:])

    eps = 1e-6
    J = np.column_stack([(h(eps * e) - h(-eps * e)) / (2 * eps) for e in np.eye(5)])
    sigma = np.zeros((5, 5))
    sigma[:3, :3], sigma[3:, 3:] = P_pose, P_landmark
    S = np.diag([sigma_b**2, sigma_r**2]) + J @ sigma @ J.T
    r = h(np.zeros(5)) - np.array([measured[0], measured[1]])
    expected = 0.5 * r @ np.linalg.solve(S, r)
    got = innovation_half_d2(entry, gtsam.Pose2(*pose), landmark, isam)
    assert got == pytest.approx(expected, rel=1e-5)
    assert got < factor.error(values)  # the pose and landmark's uncertainty widen the gate


def test_innovation_gate_still_drops_misdetections():
    """Arena-octagon seed 3 with 10 % misdetections: the plain gate drops three waiting
    sightings, all misdetections; the innovation gate must drop them too and keep the ATE."""
    header, records = simulate("arena-octagon", 3, outliers=0.1)
    steps = group_steps(header, records)
    truth, mask = truth_trajectory(steps)
    results = {}
    for variant in ("base", "innovation-gate"):
        drops = []
        sm = smoother(variant, header, lambda e, pose, landmark: drops.append(e.landmark_id))
        run, _ = run_estimator(sm, steps, covariances=False)
        results[variant] = (len(drops), ate_pair_m(run.final, truth[:, :2], mask)[0])
    assert results["base"][0] == 3
    assert results["innovation-gate"][0] == results["base"][0]
    assert results["innovation-gate"][1] == pytest.approx(results["base"][1], abs=1e-3)
    assert results["base"][1] < 0.02
