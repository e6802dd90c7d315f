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
