"""fgslam.window3d: the bounded isam2-3d against the one that keeps every variable.

The short simulated loop (214 steps, 152 landmarks, 2 654 factors) run with iSAM2 bounded
to 600 factors slides 7 times and re-enters 11 landmarks seen again after they left. The
references: the unbounded smoother on the same drive, the drive's truth, and the counts of
what iSAM2 itself holds (``getFactorsUnsafe``, ``calculateEstimate``), not timing.
"""

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import L, X

from ekf.drive3d import position_errors_m, run_drive, steps_of
from fgslam.smoother3d import MAX_HELD_FACTORS, StereoIsam2, batch_solve
from fgslam.window3d import RE_ENTERED, StereoWindow
from slamio.sim3d import DriveScenario, simulate_drive

SMALL = DriveScenario(straight_m=40.0, side_m=20.0, turn_radius_m=8.0)
BOUND = 600


@pytest.fixture(scope="module")
def drive():
    return simulate_drive(1, SMALL)


def _smoother(drive, bound):
    return StereoIsam2(drive.K, drive.baseline_m, drive.cam_T_imu, max_held_factors=bound)


@pytest.fixture(scope="module")
def unbounded(drive):
    s = run_drive(_smoother(drive, None), drive)
    online = s.trajectory().copy()
    s.finish()
    return s, online


@pytest.fixture(scope="module")
def bounded(drive):
    """The bounded run, with what iSAM2 held after every step: (factors, variables, poses)."""
    s, held = _smoother(drive, BOUND), []
    for args in steps_of(drive):
        s.step(*args)
        estimate = s._isam.calculateEstimate()
        poses = sum(1 for k in estimate.keys() if gtsam.Symbol(k).chr() == ord("x"))
        held.append((s._isam.getFactorsUnsafe().nrFactors(), estimate.size(), poses))
    online = s.trajectory().copy()
    s.finish()
    return s, online, np.array(held)


def test_a_run_the_bound_never_reaches_is_the_unbounded_run(drive, unbounded):
    """Below the bound nothing leaves: every online pose is the unbounded smoother's and the
    final estimate is the batch optimum (≤ 1.001× its graph error)."""
    s = run_drive(_smoother(drive, 10 * unbounded[0].graph.size()), drive)
    assert s.window.slides == 0
    assert np.array_equal(s.trajectory(), unbounded[1])
    s.finish()
    assert s.error() <= 1.001 * batch_solve(unbounded[0]).error
    assert np.allclose(s.smoothed_trajectory(), unbounded[0].smoothed_trajectory(), atol=1e-9)


def test_the_default_bound_keeps_the_seed_drives_whole():
    """The seed's real drives hold ≤ 4 763 factors (0027: 3 460 sightings, 1 106 steps, 197
    landmarks) and the default simulated stereo loop ~7 400 (seed 5: 7 365): the default bound
    is above, so their final estimate stays the optimum."""
    assert MAX_HELD_FACTORS > max(3460 + 1106 + 197, 7365)


def test_bounded_iSAM2_holds_a_bounded_number_of_variables(drive, bounded, unbounded):
    s, _, held = bounded
    assert s.window.slides >= 5 and s.window.re_entered > 0
    # factors iSAM2 holds after a step (a slide included): never above the bound
    assert held[:, 0].max() <= BOUND
    # variables and poses iSAM2 holds stay bounded while the unbounded one holds everything
    everything = unbounded[0].estimate().size()  # after finish(): every variable, refined
    assert everything == s.n_steps + s.landmarks_added
    assert held[:, 1].max() < 0.3 * everything  # 99 of 366
    assert held[len(held) // 2:, 2].max() <= held[: len(held) // 2, 2].max() + 5  # no growth with the run
    # the whole graph is still kept: the same factors as the unbounded smoother's
    assert s.graph.size() == unbounded[0].graph.size()


def test_bounded_and_unbounded_agree_on_a_short_log(drive, bounded, unbounded):
    """Stated tolerance: the bounded online trajectory within 5 cm RMS of the unbounded one's
    (each ~6 cm from the truth) and its ATE within 25 % of the unbounded ATE; its final
    estimate (the fixed-lag one) within 10 cm RMS of the batch optimum."""
    s, online, _ = bounded
    truth = drive.truth_world_T_imu
    assert position_errors_m(online, unbounded[1])[0] < 0.05
    ate_bounded, ate_unbounded = position_errors_m(online, truth)[0], position_errors_m(unbounded[1], truth)[0]
    assert ate_unbounded < 0.1 and ate_bounded < 1.25 * ate_unbounded
    assert position_errors_m(s.smoothed_trajectory(), unbounded[0].smoothed_trajectory())[0] < 0.1


def test_the_batch_solve_sees_the_whole_graph(bounded, unbounded):
    """From the bounded smoother's estimate the batch solve reaches the unbounded optimum."""
    batch = batch_solve(bounded[0])
    optimum = batch_solve(unbounded[0])
    assert batch.error == pytest.approx(optimum.error, rel=1e-6)
    assert np.allclose(batch.trajectory()[:, :3, 3], optimum.trajectory()[:, :3, 3], atol=1e-4)


def test_whole_estimate_has_every_pose_and_landmark_under_its_own_key(bounded):
    s = bounded[0]
    values = s.estimate()
    assert values.size() == s.n_steps + s.landmarks_added
    assert all(values.exists(X(t)) for t in range(s.n_steps))
    assert all(values.exists(L(j)) for j in s.landmark_ids())
    assert not any(gtsam.Symbol(k).chr() == ord(RE_ENTERED) for k in values.keys())


def test_a_landmark_that_left_comes_back_under_a_new_key_at_its_estimate():
    w = StereoWindow(max_factors=5, min_poses=1)
    assert w.landmark_key(3) == (L(3), True)
    factors = gtsam.NonlinearFactorGraph()
    noise = gtsam.noiseModel.Isotropic.Sigma(3, 1.0)
    for _ in range(6):
        factors.add(gtsam.PriorFactorPoint3(L(3), gtsam.Point3(1, 2, 3), noise))
    values = gtsam.Values()
    values.insert(L(3), gtsam.Point3(1, 2, 3))
    values.insert(X(0), gtsam.Pose3())
    factors.add(gtsam.PriorFactorPose3(X(0), gtsam.Pose3(), gtsam.noiseModel.Isotropic.Sigma(6, 1.0)))
    w.entered(0, factors, values, {3: L(3)})
    assert w.landmark_key(3) == (L(3), False)
    one = gtsam.NonlinearFactorGraph()
    one.add(gtsam.PriorFactorPose3(X(1), gtsam.Pose3(), gtsam.noiseModel.Isotropic.Sigma(6, 1.0)))
    pose = gtsam.Values()
    pose.insert(X(1), gtsam.Pose3())
    w.entered(1, one, pose, {})
    assert w.due() and w.leaving() == ([0], [L(3)])
    estimate = gtsam.Values(values)
    estimate.insert(X(1), gtsam.Pose3())
    estimate.update(L(3), gtsam.Point3(1.5, 2, 3))
    w.commit(w.slide(estimate), estimate)
    key, new = w.landmark_key(3)
    assert new and key == gtsam.symbol(RE_ENTERED, 0)
    assert np.allclose(w.left_estimate(3), [1.5, 2, 3])
    assert w.held_factors == 1 and w.slides == 1


def test_finish_lets_go_of_isam2_and_keeps_what_is_read_after_it(unbounded):
    # the Bayes tree's memory goes to the batch solve and the verdict that follow a run
    s, _ = unbounded
    assert s._isam is None
    assert s.estimate().size() == s.n_steps + s.landmarks_added
    assert len(s.smoothed_trajectory()) == s.n_steps and s.error() > 0.0
