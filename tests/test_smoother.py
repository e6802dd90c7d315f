"""Tests of fgslam.smoother against real GTSAM, checked with independent numpy references.

The logs come from tests/loop_logs.py (laps of a circle among a handful of landmarks); the
robust kernels' tests are in test_smoother_robust.py.
"""

from __future__ import annotations

import math

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import L, T, X

from fgslam.smoother import FAST_SETTINGS, BatchResult, Isam2Smoother, batch_solve
from slamio.errors import FgslamError
from slamio.geometry import arc_increment, between_pose, compose_pose, wrap_angle
from slamio.log import Observation, Odometry, Step, as_matrix3
from builders import run_smoother
from loop_logs import SIGMA_ODO, junk, make_header, make_log, make_loop_log, observe, pose_difference, with_extra


run = run_smoother


def numpy_half_chi2(header, steps, trajectory, landmarks) -> float:
    """Independent χ²/2 of the log at an estimate: additive odometry residuals, wrapped bearings."""
    total = 0.0
    r0 = np.array(trajectory[0]) - np.array(header.start_pose)
    r0[2] = wrap_angle(r0[2])
    total += 0.5 * np.sum((r0 / np.array(header.start_sigma)) ** 2)
    for step in steps:
        k = step.index
        if step.odometry is not None:
            o = step.odometry
            predicted = between_pose(trajectory[k - 1], trajectory[k])
            r = np.array(predicted) - np.array([o.dx_m, o.dy_m, o.dtheta_rad])
            r[2] = wrap_angle(r[2])
            total += 0.5 * r @ np.linalg.solve(np.array(o.covariance), r)
        for obs in step.observations:
            if obs.landmark_id is None:
                continue
            x, y, th = trajectory[k]
            lx, ly = landmarks[obs.landmark_id]
            rb = wrap_angle(math.atan2(ly - y, lx - x) - th - obs.bearing_rad)
            rr = math.hypot(lx - x, ly - y) - obs.range_m
            total += 0.5 * ((rb / obs.sigma_bearing_rad) ** 2 + (rr / obs.sigma_range_m) ** 2)
    return float(total)


# ---------------------------------------------------------------------------- fixtures


@pytest.fixture(scope="module")
def noisy():
    header, steps, truth, truth_lm = make_loop_log(n_steps=200, seed=7)
    smoother = run(header, steps)
    batch = batch_solve(smoother)
    return header, steps, truth, truth_lm, smoother, batch


# ---------------------------------------------------------------------------- tests


def test_noise_free_log_recovers_the_truth():
    header, steps, truth, truth_lm = make_loop_log(n_steps=150)
    smoother = Isam2Smoother(header)
    assert smoother.name == "isam2"
    for step in steps:
        smoother.step(step)
        online = np.array(smoother.current_pose())
        assert np.allclose(online[:2], truth[step.index, :2], atol=1e-6)
        assert abs(wrap_angle(online[2] - truth[step.index, 2])) < 1e-6
    smoother.finish()
    traj = smoother.trajectory()
    assert traj.shape == (len(steps), 3)
    pos, ang = pose_difference(traj, truth)
    assert pos < 1e-6 and ang < 1e-6
    est_lm = smoother.landmarks()
    assert set(est_lm) == set(truth_lm)
    for lid, (x, y) in truth_lm.items():
        assert est_lm[lid] == pytest.approx((x, y), abs=1e-6)
    assert smoother.error() < 1e-9
    assert numpy_half_chi2(header, steps, traj, est_lm) < 1e-9


def test_noisy_loop_isam2_matches_batch(noisy):
    header, steps, truth, truth_lm, smoother, batch = noisy
    assert isinstance(batch, BatchResult)
    traj = smoother.trajectory()
    pos, ang = pose_difference(traj, batch.trajectory)
    assert pos <= 1e-3 and ang <= 1e-3
    isam_error = smoother.error()
    assert batch.initial_error == pytest.approx(isam_error, rel=1e-12)
    assert abs(isam_error - batch.final_error) <= 0.01 * batch.final_error
    assert set(batch.landmarks) == set(truth_lm)
    for lid in truth_lm:
        assert np.hypot(*np.subtract(smoother.landmarks()[lid], batch.landmarks[lid])) <= 1e-3
    # Sanity against the truth the noise was drawn around (not a tight bound).
    assert pose_difference(batch.trajectory, truth)[0] < 0.3
    # χ²/2 at the optimum is about half the degrees of freedom (residuals minus unknowns);
    # its standard deviation is √(dof/2) ≈ 22 here, so ±10 % of dof/2 is a 2σ band.
    dof = 3 * len(steps) + 2 * sum(len(s.observations) for s in steps) - 3 * len(steps) - 2 * len(truth_lm)
    assert 0.45 * dof < batch.final_error < 0.55 * dof


def test_an_isam_wrapper_sees_every_update_and_changes_nothing(noisy):
    """``isam_wrapper`` (what the benchmarks time GTSAM through) wraps the smoother's ISAM2:
    every update passes through it, and the estimate is the unwrapped one's."""
    header, steps, _, _, plain, _ = noisy
    updates = []

    class Counting:
        def __init__(self, isam):
            self.isam = isam

        def update(self, *args):
            updates.append(len(args))
            return self.isam.update(*args)

        def __getattr__(self, name):
            return getattr(self.isam, name)

    wrapped = run_smoother(header, steps, isam_wrapper=Counting)
    assert len(updates) >= wrapped.updates > 0
    assert np.array_equal(wrapped.trajectory(), plain.trajectory())


def test_graph_error_matches_independent_numpy_error(noisy):
    """GTSAM's error at the solution equals a numpy χ²/2 written from the log's definitions.

    numpy uses additive odometry residuals, GTSAM the Lie-group ones; they agree to first
    order in the (small) residuals (measured: 2e-5 relative), so the tolerance is 1e-3.
    """
    header, steps, _, _, smoother, batch = noisy
    reference = numpy_half_chi2(header, steps, batch.trajectory, batch.landmarks)
    assert batch.final_error == pytest.approx(reference, rel=1e-3)


def test_batch_never_increases_the_error(noisy):
    header, steps, _, _, smoother, batch = noisy
    assert batch.final_error <= batch.initial_error
    assert 1 <= batch.iterations <= 100
    assert batch.time_s >= 0.0
    # Also mid-run, before finish(), where iSAM2 is further from converged.
    partial = Isam2Smoother(header, relinearize_threshold=0.1, relinearize_skip=10)
    for step in steps[:120]:
        partial.step(step)
        if step.index in (30, 60, 119):
            result = batch_solve(partial, max_iterations=50)
            assert result.final_error <= result.initial_error
            assert result.trajectory.shape == (step.index + 1, 3)


def test_bearing_range_factor_convention():
    """Bearing first, range second: error zero at the truth, ½Σ(Δ/σ)² when perturbed."""
    pose = (1.0, -2.0, 0.7)
    landmark = (3.0, 1.5)
    sb, sr = 0.03, 0.2  # different, so a swapped order gives a different number
    true_range = math.hypot(landmark[0] - pose[0], landmark[1] - pose[1])
    true_bearing = wrap_angle(math.atan2(landmark[1] - pose[1], landmark[0] - pose[0]) - pose[2])
    values = gtsam.Values()
    values.insert(X(0), gtsam.Pose2(*pose))
    values.insert(L(9), gtsam.Point2(*landmark))

    def factor_error(bearing, rng_m):
        smoother = Isam2Smoother(make_header(start_pose=pose))
        smoother.step(Step(0, 0.0, None, (Observation(0.0, 9, rng_m, bearing, sr, sb),), None))
        graph = smoother.graph()
        assert graph.size() == 2  # prior + bearing-range
        assert graph.at(0).error(values) == pytest.approx(0.0, abs=1e-15)
        return graph.at(1).error(values)

    assert factor_error(true_bearing, true_range) == pytest.approx(0.0, abs=1e-20)
    db, dr = 0.02, 0.15
    expected = 0.5 * ((db / sb) ** 2 + (dr / sr) ** 2)
    swapped = 0.5 * ((db / sr) ** 2 + (dr / sb) ** 2)
    got = factor_error(true_bearing + db, true_range + dr)
    assert got == pytest.approx(expected, rel=1e-9)
    assert abs(got - swapped) > 0.1 * expected


def test_odometry_factor_uses_the_logged_covariance():
    """A translation error n on an increment that turns costs exactly ½ nᵀ Q⁻¹ n."""
    Q = np.array([[4e-4, 1e-4, 2e-5], [1e-4, 1e-4, -1e-5], [2e-5, -1e-5, 2.5e-4]])
    increment = (0.3, 0.05, 0.4)
    start = (0.5, 0.2, -1.0)
    end = compose_pose(start, increment)
    n = np.array([0.01, -0.02, 0.0])
    header = make_header(start_pose=start)
    odo = Odometry(0.1, *(np.array(increment) + n), covariance=as_matrix3(Q))
    smoother = Isam2Smoother(header)
    smoother.step(Step(0, 0.0, None, (), None))
    smoother.step(Step(1, 0.1, odo, (), None))
    values = gtsam.Values()
    values.insert(X(0), gtsam.Pose2(*start))
    values.insert(X(1), gtsam.Pose2(*end))
    between = smoother.graph().at(1)
    assert between.error(values) == pytest.approx(0.5 * n @ np.linalg.solve(Q, n), rel=1e-9)


def test_step0_observations_unknown_ids_and_length():
    header, steps, truth, _ = make_loop_log(n_steps=40, unknown_every=5)
    assert steps[0].observations, "the log should observe landmarks from the start pose"
    unknown = sum(1 for s in steps for o in s.observations if o.landmark_id is None)
    assert unknown == 8
    smoother = Isam2Smoother(header, associate=False)  # id-less observations skipped and counted
    smoother.step(steps[0])
    seen_at_0 = {o.landmark_id for o in steps[0].observations if o.landmark_id is not None}
    assert set(smoother.landmarks()) == seen_at_0
    for step in steps[1:]:
        smoother.step(step)
    smoother.finish()
    assert smoother.skipped_unknown_observations == unknown
    assert smoother.trajectory().shape == (len(steps), 3)
    assert smoother.num_poses == len(steps)
    assert pose_difference(smoother.trajectory(), truth)[0] < 1e-6
    assert smoother.update_failures == 0
    # by default they are associated; these (the same range and bearing from poses along a
    # circle) fit no landmark and no fixed point, so none is used and no landmark is made
    associating = Isam2Smoother(header)
    for step in steps:
        associating.step(step)
    associating.finish()
    counts = associating.association_counts
    assert counts["skipped"] == 0 and counts["paired"] + counts["rejected"] + counts["unconfirmed"] == unknown
    assert counts["unconfirmed"] == unknown and counts["created"] == 0
    assert set(associating.landmarks()) == set(smoother.landmarks())


def test_steps_must_come_in_order():
    header, steps, _, _ = make_loop_log(n_steps=5)
    smoother = Isam2Smoother(header)
    with pytest.raises(FgslamError):
        smoother.step(steps[1])
    with pytest.raises(FgslamError):
        smoother.current_pose()


def test_covariance_matches_independent_propagation_on_a_chain():
    """With odometry only, the latest pose's marginal is the EKF-propagated covariance."""
    rng = np.random.default_rng(3)
    start = (0.2, -0.1, 0.3)
    start_sigma = (0.05, 0.02, 0.03)
    header = make_header(start_pose=start, start_sigma=start_sigma)
    Q = np.array([[4e-4, 5e-5, 1e-5], [5e-5, 1e-4, 0.0], [1e-5, 0.0, 2.5e-4]])
    smoother = Isam2Smoother(header)
    smoother.step(Step(0, 0.0, None, (), None))
    P = np.diag(np.square(start_sigma))
    pose = start
    for k in range(1, 30):
        u = (0.2 + 0.05 * rng.standard_normal(), 0.02 * rng.standard_normal(), 0.3 * rng.standard_normal())
        smoother.step(Step(k, 0.1 * k, Odometry(0.1 * k, *u, covariance=as_matrix3(Q)), (), None))
        # Jacobians of compose_pose(pose, u) w.r.t. pose and u, world (x, y, theta)
        c, s = math.cos(pose[2]), math.sin(pose[2])
        F = np.array([[1, 0, -s * u[0] - c * u[1]], [0, 1, c * u[0] - s * u[1]], [0, 0, 1]])
        G = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
        P = F @ P @ F.T + G @ Q @ G.T
        pose = compose_pose(pose, u)
    cov = smoother.current_covariance()
    assert np.allclose(cov, P, rtol=1e-6, atol=1e-12)
    body = smoother.current_covariance(frame="body")
    c, s = math.cos(pose[2]), math.sin(pose[2])
    R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    assert np.allclose(R @ body @ R.T, cov, rtol=1e-9, atol=1e-15)


def test_covariance_is_spd_and_shrinks_on_reobservation():
    header = make_header(start_pose=(0.0, 0.0, 0.0))
    Q = as_matrix3(np.diag(np.square(SIGMA_ODO)))
    lm = (2.0, 1.0)
    smoother = Isam2Smoother(header)
    smoother.step(Step(0, 0.0, None, (observe((0.0, 0.0, 0.0), lm, 0.0, 1),), None))
    pose = (0.0, 0.0, 0.0)
    traces = []
    for k in range(1, 11):  # drive blind: the latest pose's uncertainty grows
        pose = compose_pose(pose, (0.1, 0.0, 0.0))
        smoother.step(Step(k, 0.1 * k, Odometry(0.1 * k, 0.1, 0.0, 0.0, Q), (), None))
        cov = smoother.current_covariance()
        assert np.allclose(cov, cov.T)
        assert np.all(np.linalg.eigvalsh(cov) > 0)
        traces.append(np.trace(cov))
    assert all(b > a for a, b in zip(traces, traces[1:]))
    pose = compose_pose(pose, (0.1, 0.0, 0.0))
    seen = observe(pose, lm, 1.1, 1)
    smoother.step(Step(11, 1.1, Odometry(1.1, 0.1, 0.0, 0.0, Q), (seen,), None))
    after = smoother.current_covariance()
    assert np.all(np.linalg.eigvalsh(after) > 0)
    assert np.trace(after) < traces[-1]


def good_observation_count(steps) -> int:
    return sum(o.landmark_id is not None for s in steps for o in s.observations)


def test_indeterminate_update_is_recovered_and_good_observations_kept():
    header, steps, truth, truth_lm = make_loop_log(n_steps=60)
    bad_at = 20
    assert steps[bad_at].observations, "good observations should ride along with the bad one"
    smoother = Isam2Smoother(header)
    for step in steps:
        if step.index == bad_at:
            step = with_extra(step, junk(step, 99))
        smoother.step(step)
        if step.index == bad_at:
            assert smoother.update_failures == 1
            assert "Indeterminate" in smoother.last_failure
            assert smoother.pending_observations == 1
    smoother.finish()
    # Landmark 99 is never seen again: its observation waits, nothing is dropped.
    assert smoother.update_failures == 1
    assert smoother.pending_observations == 1
    assert smoother.dropped_observations == 0
    assert set(smoother.landmarks()) == set(truth_lm)
    pos, ang = pose_difference(smoother.trajectory(), truth)
    assert pos < 1e-6 and ang < 1e-6
    # Every good observation (including those of the failed step) made it into the graph.
    assert smoother.graph().size() == 1 + (len(steps) - 1) + good_observation_count(steps)
    assert batch_solve(smoother).final_error < 1e-9


def test_pending_observation_is_gated_when_the_landmark_is_seen_properly():
    header, steps, truth, _ = make_loop_log(n_steps=30)
    far_landmark = (20.0, 20.0)
    smoother = Isam2Smoother(header)
    for step in steps:
        if step.index == 10:
            step = with_extra(step, junk(step, 42))
        elif step.index == 11:
            step = with_extra(step, observe(truth[11], far_landmark, step.stamp_s, 42, max_range=100, fov=math.pi))
        smoother.step(step)
    smoother.finish()
    assert smoother.update_failures == 1
    assert smoother.dropped_observations == 1  # the junk one, ~400σ off the fresh one
    assert smoother.pending_observations == 0
    assert smoother.landmarks()[42] == pytest.approx(far_landmark, abs=1e-6)
    pos, ang = pose_difference(smoother.trajectory(), truth)
    assert pos < 1e-6 and ang < 1e-6
    assert smoother.error() < 1e-9


def test_repeatedly_failing_observation_is_dropped_after_max_retries():
    """Junk of one new landmark at steps 10, 11, 12 while the robot stands still.

    Standing still, each junk observation agrees with the next one (so passes the gate)
    and every retry is singular again. 10: junk10 fails.  11: junk10 retried with junk11,
    fails.  12: junk10 has failed 1 + max_retries = 2 times → dropped; junk11 retried with
    junk12, fails.  13: junk11 dropped; junk12 waits for a fresh observation that never
    comes.
    """
    step_angle = 2 * math.pi / 100
    move = arc_increment(3.0 * step_angle, step_angle)
    increments = [move] * 10 + [(0.0, 0.0, 0.0)] * 2 + [move] * 17
    header, steps, truth, truth_lm = make_log(increments)
    assert np.allclose(truth[10], truth[12])
    smoother = Isam2Smoother(header, max_retries=1)
    for step in steps:
        if step.index in (10, 11, 12):
            step = with_extra(step, junk(step, 77))
        smoother.step(step)
    smoother.finish()
    assert smoother.update_failures == 3
    assert smoother.dropped_observations == 2
    assert smoother.pending_observations == 1
    assert 77 not in smoother.landmarks()
    pos, ang = pose_difference(smoother.trajectory(), truth)
    assert pos < 1e-6 and ang < 1e-6
    assert smoother.graph().size() == 1 + (len(steps) - 1) + good_observation_count(steps)


class _FailsOnEmptyUpdate:
    """Wraps a real ISAM2; its first update with no new factors raises like GTSAM does."""

    def __init__(self, isam):
        self._isam = isam
        self.raised = False

    def update(self, *args):
        if not args and not self.raised:
            self.raised = True
            raise RuntimeError("Indeterminate linear system detected while working near variable\n1 (Symbol: x1).")
        return self._isam.update(*args)

    def __getattr__(self, name):
        return getattr(self._isam, name)


def test_failure_during_finish_is_recovered():
    """Injected (GTSAM cannot be made to fail here cheaply): finish() rebuilds and goes on."""
    header, steps, truth, truth_lm = make_loop_log(n_steps=40)
    smoother = Isam2Smoother(header)
    for step in steps:
        smoother.step(step)
    stub = _FailsOnEmptyUpdate(smoother._isam)
    smoother._isam = stub
    smoother.finish()
    assert stub.raised and smoother._isam is not stub
    assert smoother.update_failures == 1
    assert pose_difference(smoother.trajectory(), truth)[0] < 1e-6
    assert set(smoother.landmarks()) == {lid for s in steps for o in s.observations if (lid := o.landmark_id) is not None}


# ---------------------------------------------------------------------------- tuning knobs


def test_update_every_k_ends_where_every_step_ends(noisy):
    header, steps, _, _, smoother, batch = noisy
    for kwargs in ({"update_every": 5}, {"update_every": 3, "update_on": "observations"}):
        held = run(header, steps, **kwargs)
        assert held.updates < len(steps)
        pos, ang = pose_difference(held.trajectory(), smoother.trajectory())
        assert pos <= 1e-3 and ang <= 1e-3, kwargs
        assert abs(held.error() - batch.final_error) <= 1e-3 * batch.final_error, kwargs


def test_updates_come_by_information():
    """The default's triggers, replayed from outside: an update runs exactly when a step
    sees a new landmark, when the held steps carry ``update_observations`` observations
    (and ``update_observations_min_steps`` steps), when an observation's innovation was unlikely (χ² tail below ``update_tail``) and
    ``update_tail_min_steps`` steps are held, or when ``update_every`` steps wait; steps
    without observations are held."""
    header, steps, _, _ = make_loop_log(n_steps=300, seed=5)
    for k in range(100, 200):  # a stretch without observations: held up to update_every
        steps[k] = Step(steps[k].index, steps[k].stamp_s, steps[k].odometry, (), steps[k].truth)
    smoother = Isam2Smoother(header, update_observations=12, update_every=40, update_tail=0.02,
                             update_tail_min_steps=3, update_observations_min_steps=4)
    tails: list[float] = []
    correct = smoother._corrector.correct

    def recording(*args):
        used = correct(*args)
        tails.append(smoother._corrector.last_tail)
        return used

    smoother._corrector.correct = recording
    seen: set[int] = set()
    held_steps = held_observations = 0
    unlikely = False
    reasons = set()
    for step in steps:
        before, tails[:] = smoother.updates, []
        smoother.step(step)
        ids = {o.landmark_id for o in step.observations}
        held_steps += 1
        held_observations += len(step.observations)
        unlikely |= any(t < 0.02 for t in tails)
        due = {
            "first": step.index == 0, "new landmark": not ids <= seen, "observations": held_observations >= 12 and held_steps >= 4,
            "unlikely": unlikely and held_steps >= 3, "steps": held_steps >= 40,
        }
        seen |= ids
        updated = smoother.updates > before
        assert updated == any(due.values()), (step.index, due)
        if updated:
            reasons |= {name for name, value in due.items() if value}
            held_steps = held_observations = 0
            unlikely = False
    assert reasons == {"first", "new landmark", "observations", "unlikely", "steps"}
    assert smoother.updates < len(steps) / 5


def test_current_pose_between_updates_is_last_estimate_plus_odometry():
    header, steps, _, _ = make_loop_log(n_steps=60, seed=3)
    # without the online correction (tests/test_online_correction.py checks it), between
    # updates the online pose is dead-reckoned from the last update
    smoother = Isam2Smoother(header, update_every=4, max_held_steps=4, online_correction=False)
    expected = None
    for step in steps:
        before = smoother.updates
        smoother.step(step)
        pose = smoother.current_pose()
        if smoother.updates > before:  # this step ran an update: iSAM2's own estimate
            expected = smoother._isam.calculateEstimatePose2(X(step.index))
        else:
            o = step.odometry
            expected = expected.compose(gtsam.Pose2(o.dx_m, o.dy_m, o.dtheta_rad))
        assert np.allclose(pose, (expected.x(), expected.y(), expected.theta()), atol=1e-12)
    assert smoother.updates == 1 + (len(steps) - 1) // 4
    # queries flush the held steps: every step is in the graph and the trajectory
    assert smoother.trajectory().shape == (len(steps), 3)
    assert smoother.graph().size() == len(steps) + good_observation_count(steps)


def test_final_iterations_are_full_gauss_newton_steps(noisy):
    """With forceFullSolve every variable is relinearised, so finish() ends at the batch
    optimum even when the run's own relinearisation lagged (loose threshold, long skip)."""
    header, steps, _, _, _, batch = noisy
    kwargs = dict(relinearize_threshold=(1.0, 0.2), relinearize_skip=50, final_updates=0)
    polished = run(header, steps, final_iterations=10, **kwargs)
    none = run(header, steps, final_iterations=0, **kwargs)
    assert polished.final_iterations_run >= 1 and none.final_iterations_run == 0
    assert none.error() > 1.001 * batch.final_error  # the lag is real ...
    assert abs(polished.error() - batch.final_error) <= 1e-6 * batch.final_error  # ... and gone


def test_fast_preset_ends_at_the_batch_optimum(noisy):
    header, steps, _, _, _, batch = noisy
    fast = run(header, steps, **FAST_SETTINGS)
    assert fast.updates < len(steps) / 10
    assert abs(fast.error() - batch.final_error) <= 1e-6 * batch.final_error


def test_per_type_relinearisation_threshold(noisy):
    """A (metres, radians) pair becomes GTSAM's per-variable-type threshold map."""
    header, steps, _, _, smoother, _ = noisy
    pair = run(header, steps, relinearize_threshold=(0.01, 0.01))
    assert pose_difference(pair.trajectory(), smoother.trajectory())[0] <= 1e-6
    for bad in [(0.1,), (0.1, -1.0), (0.1, float("nan")), -0.1, "0.1"]:
        with pytest.raises(FgslamError, match="relinearize_threshold"):
            Isam2Smoother(header, relinearize_threshold=bad)


@pytest.mark.parametrize(
    "kwargs", [{"update_every": 0}, {"max_held_steps": 0}, {"update_on": "sometimes"}, {"final_iterations": -1},
               {"factorization": "lu"}, {"wildfire_threshold": -1.0}]
)
def test_bad_tuning_arguments_raise(kwargs):
    with pytest.raises(FgslamError):
        Isam2Smoother(make_header(), **kwargs)


@pytest.mark.parametrize("kwargs", [{"factorization": "qr"}, {"partial_relinearization_check": True},
                                    {"cache_linearized_factors": False}, {"wildfire_threshold": 0.0}])
def test_isam2_params_options_keep_the_answer(noisy, kwargs):
    header, steps, _, _, smoother, _ = noisy
    other = run(header, steps, **kwargs)
    assert pose_difference(other.trajectory(), smoother.trajectory())[0] <= 1e-4


def test_poses_of_reads_the_same_numbers_in_one_call_or_pose_by_pose():
    """The trajectory read in one extractPose2 call is each X(i)'s own x(), y(), theta(), bit
    for bit, with tags and landmarks among the values; a pose beyond n falls back to reading
    pose by pose, with the same result."""
    from fgslam.smoother.variables import poses_of

    rng = np.random.default_rng(3)
    for n, extra in ((500, False), (40, True)):
        values = gtsam.Values()
        for i in range(n):
            values.insert(X(i), gtsam.Pose2(*(rng.normal(size=3) * [10.0, 10.0, 3.0])))
        for i in range(20):
            values.insert(L(i), rng.normal(size=2))
        values.insert(T(7), gtsam.Pose2(1.0, 2.0, 0.3))
        if extra:
            values.insert(X(n + 5), gtsam.Pose2())
        one_by_one = np.array([[values.atPose2(X(i)).x(), values.atPose2(X(i)).y(), values.atPose2(X(i)).theta()]
                               for i in range(n)])
        np.testing.assert_array_equal(poses_of(values, n), one_by_one)


def test_a_point_landmarks_guess_is_the_seed_pose_and_the_reading():
    """The guess computed when first asked for: seed ⊕ (r cos b, r sin b), GTSAM's transformFrom."""
    from fgslam.smoother.factors import FactorBuilder

    seed = gtsam.Pose2(1.0, -2.0, 0.7)
    obs = Observation(0.0, 4, 2.5, -0.4, 0.1, 0.05)
    entry = FactorBuilder().observation(3, seed, obs, False)
    expected = np.asarray(seed.transformFrom(np.array([2.5 * math.cos(-0.4), 2.5 * math.sin(-0.4)])))
    np.testing.assert_array_equal(entry.landmark_guess, expected)
    c, s = math.cos(0.7), math.sin(0.7)
    np.testing.assert_allclose(entry.landmark_guess, [1.0 + c * 2.5 * math.cos(-0.4) - s * 2.5 * math.sin(-0.4),
                                                      -2.0 + s * 2.5 * math.cos(-0.4) + c * 2.5 * math.sin(-0.4)])
    assert entry.key == L(4) and entry.pose_index == 3 and entry.seed_pose is seed
