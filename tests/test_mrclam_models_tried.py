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
