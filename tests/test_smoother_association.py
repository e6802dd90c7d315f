"""The smoother's own data association (fgslam/smoother/association.py) on logs without ids,
scored against the simulator's truth_landmark_id, and the refusal of a smoothed reference
that is no better than dead reckoning."""

from __future__ import annotations

import math

import gtsam
import numpy as np
import pytest

from fgslam.check import check_estimator
from fgslam.compare import ate_rmse_m
from fgslam.runner import (
    ESTIMATORS,
    UnusableReferenceError,
    require_usable_reference,
    run_estimator,
    truth_trajectory,
    unused_observations,
)
from fgslam.smoother import Isam2Smoother
from fgslam.smoother.association import FIRST_ASSOCIATED_ID, SmootherAssociation, association_problem
from slamio.log import Observation, RunLog, write_log
from slamio.sim import simulate


def _steps(scenario: str, seed: int, hide_ids: bool):
    header, records = simulate(scenario, seed, hide_ids=hide_ids)
    return header, RunLog(path="sim", header=header, records=tuple(records)).steps()


def _smoother_run(scenario: str, seed: int, hide_ids: bool, **kwargs):
    header, steps = _steps(scenario, seed, hide_ids)
    run, smoother = run_estimator(Isam2Smoother(header, **kwargs), steps, covariances=False)
    truth, has = truth_trajectory(steps)
    return run, smoother, ate_rmse_m(run.final, truth, has_pose=has), steps


@pytest.mark.parametrize("scenario", ["arena-octagon", "cylinders"])
def test_hidden_ids_are_associated_as_well_as_the_ids_themselves(scenario):
    with_ids, _, ate_ids, _ = _smoother_run(scenario, 1, False)
    hidden, smoother, ate_hidden, _ = _smoother_run(scenario, 1, True)
    score = hidden.association
    assert with_ids.association is None  # the log's ids were used: nothing to score
    assert score.observations > 700
    # measured: none wrong; every one right with an iSAM2 update per 10 steps, and with the
    # default's updates by information one of 1 064 rejected as ambiguous on cylinders
    assert score.wrong == 0 and score.observations - score.correct <= score.observations // 500
    assert score.landmarks_created == {"arena-octagon": 8, "cylinders": 3}[scenario]
    assert not score.duplicate_keys
    assert ate_hidden <= 1.01 * ate_ids
    # the map is re-keyed by the true ids (as for the EKF) and the smoother's own keys are far above them
    assert sorted(hidden.landmarks) == sorted(with_ids.landmarks)
    assert all(k >= FIRST_ASSOCIATED_ID for k in smoother.landmarks())
    assert smoother.association_counts["skipped"] == 0


def test_without_association_the_observations_are_skipped_and_the_reference_is_refused():
    run, smoother, _, steps = _smoother_run("arena-octagon", 1, True, associate=False)
    assert run.landmarks == {}
    assert smoother.skipped_unknown_observations == sum(len(s.observations) for s in steps)
    assert unused_observations(smoother)["skipped"] == smoother.skipped_unknown_observations
    with pytest.raises(UnusableReferenceError, match="maps no landmark.*without a landmark id.*Fix:"):
        require_usable_reference(smoother, steps, "hid.jsonl")


def test_a_reference_that_maps_landmarks_is_accepted():
    _, smoother, _, steps = _smoother_run("arena-octagon", 1, True)
    require_usable_reference(smoother, steps, "hid.jsonl")  # does not raise


def _observation(range_m, bearing_rad, truth=None):
    return Observation(0.0, None, range_m, bearing_rad, 0.05, 0.02, truth_landmark_id=truth)


def test_a_single_sighting_never_makes_a_landmark_and_agreeing_ones_do():
    assoc = SmootherAssociation(max_wait_steps=5, min_sightings=2)  # the default is 3
    pose = gtsam.Pose2(0.0, 0.0, 0.0)
    no_marginal = lambda ids: None  # noqa: E731  (no landmark yet: never asked)

    first = [_observation(2.0, 0.0)]
    assoc.begin_step(first)
    decision = assoc.associate(0, pose, list(enumerate(first)), None, no_marginal, [])
    assert decision.paired == {} and decision.confirmed == {} and len(assoc.waiting) == 1

    far = [_observation(2.0, 1.0)]  # disagrees: (1.08, 1.68) vs (2, 0)
    assoc.begin_step(far)
    assert assoc.associate(1, pose, list(enumerate(far)), None, no_marginal, []).paired == {}

    again = [_observation(2.03, 0.01)]
    assoc.begin_step(again)
    decision = assoc.associate(2, pose, list(enumerate(again)), None, no_marginal, [])
    assert decision.paired == {0: FIRST_ASSOCIATED_ID}
    assert [s.pose_index for s in decision.confirmed[FIRST_ASSOCIATED_ID]] == [0]
    assert assoc.keys() == [FIRST_ASSOCIATED_ID, None, FIRST_ASSOCIATED_ID]

    for k in range(3, 10):  # the lone sighting at pose 1 expires
        assoc.begin_step([])
        assoc.associate(k, pose, [], None, no_marginal, [])
    assoc.finish()
    assert assoc.unconfirmed == 1 and assoc.created == 1


def test_association_problem_matches_a_numerical_jacobian():
    pose = np.array([0.3, -0.2, 0.4])
    landmarks = [np.array([2.0, 1.0]), np.array([-1.0, 2.5])]
    obs = [_observation(2.0, 0.1), _observation(2.6, 1.9)]
    P = np.eye(7)
    nu, H, R = association_problem(pose, P, landmarks, obs)
    state = np.concatenate([pose, *landmarks])

    def innovation(x, i, j):
        n, _, _ = association_problem(x[:3], P, [x[3:5], x[5:7]], [obs[i]])
        return n[0, j]

    for i in range(2):
        for j in range(2):
            numeric = np.empty((2, 7))
            for c in range(7):
                d = np.zeros(7)
                d[c] = 1e-6
                numeric[:, c] = (innovation(state + d, i, j) - innovation(state - d, i, j)) / 2e-6
            # nu = z − h(x), so ∂nu/∂x = −H
            np.testing.assert_allclose(-numeric, H[i, j], atol=1e-6)
    assert R.shape == (2, 2, 2) and math.isclose(R[0, 0, 0], 0.05**2)


@pytest.fixture(scope="module")
def hidden_log(tmp_path_factory):
    header, records = simulate("arena-octagon", 1, hide_ids=True)
    path = tmp_path_factory.mktemp("hidden") / "hid.jsonl"
    write_log(path, header, records)
    return path


def test_check_on_a_hidden_id_log_passes_the_ekf_and_fails_a_mistuned_one(hidden_log):
    assert check_estimator(hidden_log, estimator="ekf", against="smoothed").passed
    # seed 004's paper EKF (constant, far too small noise) fails against the smoothed reference
    assert not check_estimator(hidden_log, estimator="ekf-s004", against="smoothed").passed


def test_both_estimators_are_scored_on_a_hidden_id_log():
    header, steps = _steps("cylinders", 2, True)
    for name in ("ekf", "isam2"):
        run, _ = run_estimator(ESTIMATORS[name](header), steps[:300], covariances=False)
        assert run.association is not None and run.association.wrong == 0
        assert run.unused_observations is not None


def _two_landmarks(separation_m: float, sigma_m: float):
    """iSAM2 holding two landmarks the association created, each with a prior of σ ``sigma_m``
    ``separation_m`` apart, and a third far away."""
    from gtsam.symbol_shorthand import L

    a, b, c = FIRST_ASSOCIATED_ID, FIRST_ASSOCIATED_ID + 1, FIRST_ASSOCIATED_ID + 2
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    noise = gtsam.noiseModel.Isotropic.Sigma(2, sigma_m)
    for key, xy in ((a, (1.0, 2.0)), (b, (1.0 + separation_m, 2.0)), (c, (5.0, 2.0))):
        graph.add(gtsam.PriorFactorPoint2(L(key), np.array(xy), noise))
        values.insert(L(key), np.array(xy))
    isam = gtsam.ISAM2()
    isam.update(graph, values)
    return isam, (a, b, c)


def test_a_landmark_mapped_twice_is_merged_only_when_the_data_do_not_resolve_the_two():
    """Two keys whose difference is inside the 0.999 joint gate are one landmark (the one with
    fewer readings is the duplicate); resolved ones (0.18 m apart, each known to 2 cm:
    d² = 0.18² / (2·0.02²) = 40.5 > 13.8), or two seen in one frame, are two landmarks."""
    for separation_m, merged in ((0.05, True), (0.18, False)):  # d² 3.1 and 40.5 against 13.8
        isam, (a, b, c) = _two_landmarks(separation_m, 0.02)
        association = SmootherAssociation()
        uses = {a: 5, b: 2, c: 7}
        got = association.unresolved_duplicates(isam, [a, b, c], uses)
        assert got == ({b: a} if merged else {})
    association = SmootherAssociation()
    association._keys = [a, b]
    association._frames = {3: range(0, 2)}  # one frame saw both
    assert association.unresolved_duplicates(_two_landmarks(0.05, 0.02)[0], [a, b, c], {a: 5, b: 2, c: 7}) == {}


def _readings_of_two_points(b_offset_m: float, as_a: int, landmark_sigma_m: float = 0.005, frames: int = 6):
    """iSAM2 holding ``frames`` poses on the x axis (tight priors) and three landmarks the
    association created: a at (3, 0), b at (3, ``b_offset_m``), c far away, each known to
    ``landmark_sigma_m``. Each frame reads one landmark exactly (σ 1 cm, 2 mrad): the first
    ``as_a`` frames a, the others b. Returns the association, iSAM2, the joint-marginal
    callback and the keys."""
    from gtsam.symbol_shorthand import L, X

    from fgslam.smoother.online import world_joint_marginal
    from fgslam.smoother.chain import OdometryChain

    a, b, c = FIRST_ASSOCIATED_ID, FIRST_ASSOCIATED_ID + 1, FIRST_ASSOCIATED_ID + 2
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    landmark_noise = gtsam.noiseModel.Isotropic.Sigma(2, landmark_sigma_m)
    for key, xy in ((a, (3.0, 0.0)), (b, (3.0, b_offset_m)), (c, (3.0, 4.0))):
        graph.add(gtsam.PriorFactorPoint2(L(key), np.array(xy), landmark_noise))
        values.insert(L(key), np.array(xy))
    pose_noise = gtsam.noiseModel.Diagonal.Sigmas(np.array([0.005, 0.005, 0.001]))
    association = SmootherAssociation()
    for p in range(frames):
        pose = gtsam.Pose2(0.1 * p, 0.0, 0.0)
        graph.add(gtsam.PriorFactorPose2(X(p), pose, pose_noise))
        values.insert(X(p), pose)
        y = 0.0 if p < as_a else b_offset_m
        reading = Observation(stamp_s=float(p), landmark_id=None, range_m=math.hypot(3.0 - 0.1 * p, y),
                              bearing_rad=math.atan2(y, 3.0 - 0.1 * p), sigma_range_m=0.01, sigma_bearing_rad=0.002)
        association._frames[p] = range(len(association._keys), len(association._keys) + 1)
        association._keys.append(a if p < as_a else b)
        association._observations.append(reading)
    association.spread_m.update({a: 0.05, b: 0.05, c: 0.05})
    isam = gtsam.ISAM2()
    isam.update(graph, values)

    def joint_marginal_at(p, pose, ids):
        return world_joint_marginal(isam, OdometryChain(p), pose, ids)

    return association, isam, joint_marginal_at, (a, b, c)


def test_a_created_landmark_the_others_explain_is_retired_at_the_end():
    """Left out of the map, a landmark whose readings pair safely with another is redundant.
    With b 3 cm from a, each known to 5 mm, the two landmarks are told apart (d² of their
    difference ≈ 18 > 13.8, so they are no duplicates by their marginals) but no single
    reading tells them apart (its d² against the other ≈ 10, inside the 0.999 gate): one of
    them is not needed, and the one with fewer readings goes. b 0.5 m away is a landmark of
    its own (its readings cannot pair with a: d² in the thousands), and so is b 3 cm away
    once a frame saw both."""
    association, isam, marginal, (a, b, c) = _readings_of_two_points(0.03, as_a=2)
    assert association.unresolved_duplicates(isam, [a, b, c], {a: 2, b: 4}) == {}
    assert association.redundant_landmark(isam, marginal, [a, b, c], {a: 2, b: 4}) == a
    association, isam, marginal, (a, b, c) = _readings_of_two_points(0.03, as_a=4)
    assert association.redundant_landmark(isam, marginal, [a, b, c], {a: 4, b: 2}) == b
    association, isam, marginal, (a, b, c) = _readings_of_two_points(0.5, as_a=2)
    assert association.redundant_landmark(isam, marginal, [a, b, c], {a: 2, b: 4}) is None
    # one frame that saw both: two landmarks, whatever their readings say
    association, isam, marginal, (a, b, c) = _readings_of_two_points(0.03, as_a=2)
    association._frames[99] = range(len(association._keys), len(association._keys) + 2)
    association._keys += [a, b]
    association._observations += association._observations[:2]
    assert association.redundant_landmark(isam, marginal, [a, b, c], {a: 3, b: 5}) is None


def test_retired_landmarks_stay_out_of_later_re_decisions():
    """redecide leaves a retired landmark out of the map it pairs against: b's readings move
    to a but one (a landmark keeps a factor), and b is not offered again."""
    association, isam, marginal, (a, b, c) = _readings_of_two_points(0.03, as_a=4)
    changes = association.redecide(isam, marginal, [a, b, c])
    assert association.retired == {b}
    assert [(ch.old, ch.new) for ch in changes] == [(b, a)]
    association.apply(changes)
    assert association.redecide(isam, marginal, [a, b, c]) == []
    assert association.retired == {b}


def test_the_smoother_counts_the_landmarks_it_retired():
    """association_counts carries the redundancy test's outcome (nothing to retire on a
    simulated run whose landmarks are all told apart)."""
    header, steps = _steps("cylinders", 2, True)
    smoother = Isam2Smoother(header)
    run_estimator(smoother, steps[:300], covariances=False)
    assert smoother.association_counts["retired"] == 0
    smoother._association.retired.add(FIRST_ASSOCIATED_ID)  # as redecide does when one goes
    assert smoother.association_counts["retired"] == 1
