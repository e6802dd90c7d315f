"""ekf.vio's bounded state: marginalising landmarks that left the view (issue 43 part 5).

The bounded filter must be the unbounded one exactly when nothing is marginalised, and
marginalising must leave the rest of the state's mean and covariance as they were (the
Gaussian marginal), checked against the information form as an independent reference.
"""

import dataclasses

import numpy as np
import pytest

from ekf.drive3d import run_drive
from ekf.vio import VioEkf
from slamio.sim3d import DriveScenario, simulate_drive

SMALL = DriveScenario(straight_m=40.0, side_m=20.0, turn_radius_m=8.0)


@pytest.fixture(scope="module")
def drive():
    return simulate_drive(3, SMALL)


def _contiguous(drive):
    """The drive with each track cut after its first run of sightings: no id is seen again
    once it has left the view (as in seed 003's real drives)."""
    seen = ~np.isnan(drive.features_px[:, :, 0])
    features = drive.features_px.copy()
    for j in range(drive.n_landmarks):
        t = np.flatnonzero(seen[:, j])
        if len(t):
            breaks = np.flatnonzero(np.diff(t) > 1)
            if len(breaks):
                features[t[breaks[0] + 1]:, j] = np.nan
    return dataclasses.replace(drive, features_px=features)


def _filter(drive, **options):
    return VioEkf(drive.K, drive.baseline_m, drive.cam_T_imu, **options)


@pytest.mark.parametrize("first_estimates", [False, True])
def test_a_window_longer_than_the_drive_is_the_unbounded_filter_exactly(drive, first_estimates):
    unbounded = run_drive(_filter(drive, first_estimates=first_estimates, marginalise_after=None,
                                  max_landmarks=None), drive)
    windowed = run_drive(_filter(drive, first_estimates=first_estimates, marginalise_after=drive.n_steps + 1,
                                 max_landmarks=drive.n_landmarks + 1), drive)
    assert windowed.marginalised == 0 and unbounded.landmarks_added > 50
    assert np.array_equal(windowed.trajectory(), unbounded.trajectory())
    assert np.array_equal(windowed.state_covariance(), unbounded.state_covariance())
    assert windowed.state_landmark_ids() == unbounded.state_landmark_ids()
    a, b = windowed.landmarks(), unbounded.landmarks()
    assert a.keys() == b.keys() and all(np.array_equal(a[j], b[j]) for j in a)
    assert np.array_equal(windowed.nis(), unbounded.nis())


def test_marginalising_leaves_the_rest_as_the_gaussian_marginal(drive):
    f = run_drive(_filter(drive, marginalise_after=None, max_landmarks=None), drive, n_steps=60)
    ids = f.state_landmark_ids()
    P, pose, means = f.state_covariance(), f.current_pose(), f.landmarks()
    rng = np.random.default_rng(43)
    drop = sorted(int(j) for j in rng.choice(ids, size=len(ids) // 3, replace=False))
    f.marginalise(drop)
    kept = [j for j in ids if j not in drop]
    assert f.state_landmark_ids() == kept and f.marginalised == len(drop)
    # the rest of the mean: unchanged; the dropped landmarks are still reported
    assert np.array_equal(f.current_pose(), pose)
    after = f.landmarks()
    assert after.keys() == means.keys() and all(np.array_equal(after[j], means[j]) for j in means)
    # the covariance: the block of the kept variables, exactly
    slot = {j: i for i, j in enumerate(ids)}
    keep = np.concatenate([np.arange(6)] + [6 + 3 * slot[j] + np.arange(3) for j in kept])
    assert np.array_equal(f.state_covariance(), P[np.ix_(keep, keep)])
    # independent reference: the marginal in information form, Λ_aa − Λ_ab Λ_bb⁻¹ Λ_ba, inverted
    info = np.linalg.inv(P)
    gone = np.setdiff1d(np.arange(P.shape[0]), keep)
    schur = info[np.ix_(keep, keep)] - info[np.ix_(keep, gone)] @ np.linalg.solve(info[np.ix_(gone, gone)],
                                                                                   info[np.ix_(gone, keep)])
    reference = np.linalg.inv(schur)
    assert np.allclose(f.state_covariance(), reference, rtol=1e-6, atol=1e-9 * np.abs(reference).max())


@pytest.mark.parametrize("first_estimates", [False, True])
def test_landmarks_that_never_come_back_are_marginalised_without_changing_the_estimate(drive, first_estimates):
    """Once a track has ended, the filter that drops it estimates the pose and every other
    landmark as the one that keeps it (to rounding: the matrices differ in size)."""
    cut = _contiguous(drive)
    unbounded = _filter(cut, first_estimates=first_estimates, marginalise_after=None, max_landmarks=None)
    bounded = _filter(cut, first_estimates=first_estimates, marginalise_after=1, max_landmarks=None)
    run_drive(unbounded, cut)
    run_drive(bounded, cut)
    assert bounded.marginalised > 0.8 * bounded.landmarks_added
    assert len(bounded.state_landmark_ids()) < 0.2 * len(unbounded.state_landmark_ids())
    assert np.allclose(bounded.trajectory(), unbounded.trajectory(), rtol=0.0, atol=1e-8)
    assert np.allclose(bounded.current_covariance(), unbounded.current_covariance(), rtol=1e-7, atol=1e-14)
    # the landmarks still in the state; a marginalised one keeps the estimate it left with,
    # which the unbounded filter goes on refining through its correlation with the pose
    a, b = bounded.landmarks(), unbounded.landmarks()
    kept = bounded.state_landmark_ids()
    assert a.keys() == b.keys() and kept and all(np.allclose(a[j], b[j], rtol=0.0, atol=1e-8) for j in kept)


def test_the_cap_keeps_the_most_recently_seen(drive):
    f = _filter(drive, marginalise_after=None, max_landmarks=15)
    largest = 0
    for args in _steps(drive):
        f.step(*args)
        state = set(f.state_landmark_ids())
        largest = max(largest, len(state))
        seen_now = {int(j) for j in args[2]} & f.landmarks().keys()  # seen now and in the map
        assert len(seen_now) > 15 or seen_now <= state  # the landmarks seen now are the last to go
    assert largest == 15 and f.marginalised > 0
    # the estimate stays useful with so few landmarks
    assert np.all(np.isfinite(f.trajectory()))


def _steps(drive):
    from ekf.drive3d import steps_of

    return steps_of(drive)


def test_a_landmark_seen_again_after_it_left_starts_afresh(drive):
    f = run_drive(_filter(drive, marginalise_after=2, max_landmarks=None), drive)
    assert f.marginalised > 0
    # more landmarks were added than there are ids: some came back and were re-initialised
    assert f.landmarks_added > len(f.landmarks())


@pytest.mark.parametrize("option", ["marginalise_after", "max_landmarks"])
def test_a_window_below_one_is_refused(drive, option):
    with pytest.raises(ValueError, match=option):
        _filter(drive, **{option: 0})
