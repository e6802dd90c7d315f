"""ekf.fej.FejEkfSlam (``ekf-fej``): first-estimates Jacobians, checked against the
observability analysis they come from (Huang, Mourikis and Roumeliotis, ISER 2008).

The independent reference is the nonlinear system's null space: shifting every position,
or rotating everything about the origin, leaves every range and bearing unchanged. At the
linearisation points of time 0 those directions are
``N = [[1, 0, 0, 1, 0], [0, 1, 0, 0, 1], [−y_R, x_R, 1, −y_L, x_L]]ᵀ`` over
(robot x, y, θ, landmark x, y). The linearised system must keep them unobservable:
``H_k Φ(k, 0) N = 0`` for every measurement Jacobian ``H_k`` and the product ``Φ(k, 0)``
of the propagation Jacobians the filter used.
"""

from __future__ import annotations

import numpy as np
import pytest

import ekf.fej
import ekf.slam
from builders import minimal_header
from ekf import EkfSlam, FejEkfSlam
from ekf.models import motion_jacobians, predict_pose, range_bearing
from slamio.log import Observation, Odometry, Step, as_matrix3

ODO_COV = as_matrix3(np.diag([0.02, 0.01, 0.01]) ** 2)
LANDMARK = np.array([4.0, 2.0])


def _drive(steps: int, seed: int = 3) -> list[Step]:
    """A robot driving an arc past one landmark (id 1), noisy odometry and readings."""
    rng = np.random.default_rng(seed)
    pose = np.array([0.0, 0.0, 0.0])
    out = []
    for k in range(steps):
        odometry = None
        if k > 0:
            true_increment = np.array([0.3, 0.0, 0.15])
            pose = predict_pose(pose, true_increment)
            measured = true_increment + rng.normal(0.0, [0.02, 0.01, 0.01])
            odometry = Odometry(float(k), *map(float, measured), covariance=ODO_COV)
        r, b = range_bearing(pose, LANDMARK)
        observation = Observation(float(k), 1, r + rng.normal(0.0, 0.05), b + rng.normal(0.0, 0.02), 0.05, 0.02)
        out.append(Step(k, float(k), odometry, (observation,), None))
    return out


def _record_jacobians(monkeypatch, fej: bool):
    """Run a filter over :func:`_drive` and keep the Jacobians it used, in order:
    ('F', 3×3 pose propagation) and ('H', 2×5 over robot and landmark)."""
    used: list[tuple[str, np.ndarray]] = []
    original_h = ekf.slam.range_bearing_jacobians

    def h(pose, landmark):
        H_pose, H_landmark = original_h(pose, landmark)
        used.append(("H", np.hstack([H_pose, H_landmark])))
        return H_pose, H_landmark

    monkeypatch.setattr(ekf.slam, "range_bearing_jacobians", h)
    if fej:
        original_f = ekf.fej.fej_motion_jacobian

        def f(prior_xy, predicted_xy):
            F = original_f(prior_xy, predicted_xy)
            used.append(("F", F))
            return F

        monkeypatch.setattr(ekf.fej, "fej_motion_jacobian", f)
        estimator = FejEkfSlam(minimal_header(start_sigma=(1e-3, 1e-3, 1e-3)))
    else:
        original_m = ekf.slam.motion_jacobians

        def m(pose, increment):
            F_pose, F_increment = original_m(pose, increment)
            used.append(("F", F_pose))
            return F_pose, F_increment

        monkeypatch.setattr(ekf.slam, "motion_jacobians", m)
        estimator = EkfSlam(minimal_header(start_sigma=(1e-3, 1e-3, 1e-3)))
    steps = _drive(12)
    estimator.step(steps[0])  # step 0: the landmark is initialised (no update, no Jacobian recorded)
    first_landmark = estimator.landmarks()[1]
    for step in steps[1:]:
        estimator.step(step)
    return used, np.array(first_landmark)


def _null_space_residuals(used, start_xy, landmark_xy) -> np.ndarray:
    """max |H_k Φ(k, 0) N| per null direction (translation x, translation y, rotation)."""
    N = np.array([
        [1.0, 0.0, 0.0, 1.0, 0.0],
        [0.0, 1.0, 0.0, 0.0, 1.0],
        [-start_xy[1], start_xy[0], 1.0, -landmark_xy[1], landmark_xy[0]],
    ]).T
    Phi = np.eye(5)
    worst = np.zeros(3)
    for kind, J in used:
        if kind == "F":
            step = np.eye(5)
            step[:3, :3] = J
            Phi = step @ Phi
        else:
            worst = np.maximum(worst, np.abs(J @ Phi @ N).max(axis=0))
    return worst


def test_first_estimates_keep_all_three_unobservable_directions(monkeypatch):
    used, first = _record_jacobians(monkeypatch, fej=True)
    assert sum(kind == "H" for kind, _ in used) == 11 and sum(kind == "F" for kind, _ in used) == 11
    np.testing.assert_allclose(_null_space_residuals(used, (0.0, 0.0), first), 0.0, atol=1e-12)


def test_the_textbook_filter_observes_the_heading_it_cannot_know(monkeypatch):
    """The reason for ekf-fej: with Jacobians at the latest estimates the translations stay
    unobservable but the rotation does not (the filter gains spurious heading information)."""
    used, first = _record_jacobians(monkeypatch, fej=False)
    translation_x, translation_y, rotation = _null_space_residuals(used, (0.0, 0.0), first)
    assert translation_x < 1e-12 and translation_y < 1e-12
    assert rotation > 1e-3


def test_without_updates_the_fej_propagation_is_the_textbook_one():
    pose = np.array([1.0, -2.0, 0.7])
    increment = (0.4, 0.05, -0.2)
    predicted = predict_pose(pose, increment)
    np.testing.assert_allclose(ekf.fej.fej_motion_jacobian(pose[:2], predicted[:2]), motion_jacobians(pose, increment)[0],
                               atol=1e-15)


def test_dead_reckoning_alone_is_the_same_filter():
    """No landmark, no update: the prior is the posterior, so both filters agree exactly."""
    steps = [Step(k, float(k), None if k == 0 else Odometry(float(k), 0.3, 0.01, 0.1, covariance=ODO_COV), (), None)
             for k in range(20)]
    a, b = EkfSlam(minimal_header()), FejEkfSlam(minimal_header())
    for step in steps:
        a.step(step)
        b.step(step)
    np.testing.assert_allclose(b.trajectory(), a.trajectory(), atol=1e-15)
    np.testing.assert_allclose(b.current_covariance(), a.current_covariance(), atol=1e-15)


def test_the_innovation_still_uses_the_latest_estimate():
    """Only the Jacobians move: a reading that agrees exactly with the current estimate
    leaves the mean where it is, in both filters."""
    for cls in (EkfSlam, FejEkfSlam):
        estimator = cls(minimal_header())
        estimator.step(Step(0, 0.0, None, (Observation(0.0, 1, 5.0, 0.3, 0.05, 0.02),), None))
        estimator.step(Step(1, 1.0, Odometry(1.0, 0.5, 0.0, 0.1, covariance=ODO_COV), (), None))
        pose, landmark = np.array(estimator.current_pose()), np.array(estimator.landmarks()[1])
        r, b = range_bearing(pose, landmark)
        estimator.step(Step(2, 2.0, None, (Observation(2.0, 1, r, b, 0.05, 0.02),), None))
        np.testing.assert_allclose(estimator.current_pose(), pose, atol=1e-12)
        np.testing.assert_allclose(estimator.landmarks()[1], landmark, atol=1e-12)


@pytest.mark.parametrize("association, name", [("jcbb", "ekf-fej"), ("nn", "ekf-fej-nn"), (None, "ekf-fej-ids")])
def test_names(association, name):
    assert FejEkfSlam(minimal_header(), association=association).name == name


@pytest.mark.parametrize("scenario, seed", [("arena-octagon", 1), ("cylinders", 1)])
def test_it_associates_hidden_ids_as_the_textbook_filter_does(scenario, seed):
    """Association is ``ekf``'s: on simulated runs without ids no reading is paired with the
    wrong landmark, at most 0.5 % are left unpaired (ekf and ekf-fej both leave one of 1 064
    on the cylinders), and no landmark is mapped twice."""
    from fgslam.compare import score_associations
    from slamio.log import group_steps
    from slamio.sim import simulate

    header, records = simulate(scenario, seed, hide_ids=True)
    steps = group_steps(header, records)
    estimator = FejEkfSlam(header)
    keys, true_ids = [], []
    for step in steps:
        estimator.step(step)
        keys += estimator.step_associations()
        true_ids += [o.truth_landmark_id for o in step.observations]
    score = score_associations(true_ids, keys)
    assert score.correct + score.rejected == score.observations
    assert score.correct >= 0.995 * score.observations
    assert len(estimator.landmarks()) == len({i for i in true_ids if i is not None})
