"""scripts/mrclam_models_tried.py: the EKF variant's odometry self-calibration states against
numerical differentiation."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from builders import load_script


@pytest.fixture(scope="module")
def script():
    return load_script("mrclam_models_tried")


def test_the_turn_calibration_jacobian_matches_finite_differences(script):
    """Pose after one step as a function of the turn-scale correction (state 5) and the
    curvature bias (state 6): the cross-covariance the prediction builds from a unit
    covariance on those states is its Jacobian."""
    odometry = SimpleNamespace(dx_m=0.12, dy_m=0.01, dtheta_rad=0.3, covariance=np.zeros((3, 3)))
    x = np.array([1.0, -2.0, 0.7, 0.0, 0.0, 0.02, -0.04])
    P = np.zeros((7, 7))
    P[5:7, 5:7] = np.eye(2)
    _, predicted = script._predict(x, P, odometry, 0.0)
    numeric = np.empty((3, 2))
    for j, state in enumerate((5, 6)):
        h = 1e-6
        up, down = x.copy(), x.copy()
        up[state] += h
        down[state] -= h
        numeric[:, j] = (script._predict(up, P, odometry, 0.0)[0][:3] - script._predict(down, P, odometry, 0.0)[0][:3]) / (2 * h)
    np.testing.assert_allclose(predicted[:3, 5:7], numeric, atol=1e-8)
    # the turn itself: dθ·(1 + s) + c·d
    moved = script._predict(x, P, odometry, 0.0)[0]
    assert moved[2] == pytest.approx(0.7 + 0.3 * 1.02 - 0.04 * np.hypot(0.12, 0.01))


def test_the_batch_calibrated_odometry_factor_is_a_between_factor_on_the_corrected_turn(script):
    """With the calibration (s, c) held, the custom factor is GTSAM's BetweenFactorPose2 on
    the increment whose turn is dθ·(1 + s) + c·d: same error, same pose Jacobians; its
    calibration Jacobian is that of the measured turn."""
    import gtsam
    from gtsam.symbol_shorthand import D, X

    odometry = SimpleNamespace(dx_m=0.3, dy_m=0.02, dtheta_rad=0.25)
    unit = gtsam.noiseModel.Unit.Create(3)
    factor = gtsam.CustomFactor(unit, [X(0), X(1), D(0)], script._calibrated_odometry_error(odometry))
    values = gtsam.Values()
    values.insert(X(0), gtsam.Pose2(1.0, 2.0, 0.4))
    values.insert(X(1), gtsam.Pose2(1.25, 2.2, 0.7))
    calibration = np.array([0.04, -0.06])
    values.insert(D(0), calibration)
    turn = 0.25 * 1.04 - 0.06 * np.hypot(0.3, 0.02)
    reference = gtsam.BetweenFactorPose2(X(0), X(1), gtsam.Pose2(0.3, 0.02, turn), unit)
    np.testing.assert_allclose(factor.unwhitenedError(values), reference.unwhitenedError(values), atol=1e-12)
    ours, theirs = factor.linearize(values).jacobian()[0], reference.linearize(values).jacobian()[0]
    np.testing.assert_allclose(ours[:, :6], theirs, atol=1e-7)
    # d(error)/d(measured turn) by the same factor with the turn moved, times d(turn)/d(s, c)
    h = 1e-6
    moved = [gtsam.BetweenFactorPose2(X(0), X(1), gtsam.Pose2(0.3, 0.02, turn + sign * h), unit).unwhitenedError(values)
             for sign in (1, -1)]
    d_turn = (moved[0] - moved[1]) / (2 * h)
    np.testing.assert_allclose(ours[:, 6:], np.outer(d_turn, [0.25, np.hypot(0.3, 0.02)]), atol=1e-6)


def test_standing_still_gives_only_zero_odometry_the_floor_variance(script):
    """On a real excerpt (robot 1, MRCLAM): a record whose increment is exactly zero gets
    floor·dt in each component, every other record and the header are untouched."""
    import os

    from slamio.datasets.mrclam import import_mrclam
    from slamio.log import Odometry, RunLog

    folder = os.path.join(os.path.dirname(__file__), "data", "mrclam_excerpt")
    log = RunLog("robot1", *import_mrclam(folder, 1))
    still = script.standing_still(log, floor_per_s=1e-7)
    assert still.header == log.header and len(still.records) == len(log.records)
    changed = previous = 0
    stamps = [r.stamp_s for r in log.records if isinstance(r, Odometry)]
    for before, after in zip(log.records, still.records):
        if not isinstance(before, Odometry):
            assert after is before
            continue
        if before.stamp_s != stamps[0] and before.dx_m == before.dy_m == before.dtheta_rad == 0.0:
            dt = before.stamp_s - previous
            np.testing.assert_allclose(after.covariance, np.diag([1e-7 * dt] * 3), rtol=1e-12)
            assert np.trace(np.asarray(before.covariance)) > np.trace(np.asarray(after.covariance))
            changed += 1
        else:
            assert after == before
        previous = before.stamp_s
    assert changed > 0  # the excerpt has standing stretches
