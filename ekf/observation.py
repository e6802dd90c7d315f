"""One observation in EKF-SLAM's terms: its covariance R, its model and Jacobians with an
optional landmark height, the inverse model that places a new landmark, and its NIS.

These wrap the range-bearing functions of :mod:`ekf.models` for the landmark states
:class:`ekf.slam.EkfSlam` keeps: ``(x, y)``, or ``(x, y, h)`` for a landmark first seen by
an observation with a height (seed 002). The height is measured directly, so it adds one
row ``[0 0 0 | 0 0 1]`` to the Jacobian and never correlates with anything else.
"""

from __future__ import annotations

import numpy as np

from ekf.models import (
    ROBOT_DIM,
    landmark_from_range_bearing,
    landmark_init_jacobians,
    range_bearing,
    range_bearing_jacobians,
    range_bearing_nis,
    range_nis,
)
from slamio.log import Observation

__all__ = [
    "measurement_covariance",
    "observation_nis",
    "has_height",
    "observation_model",
    "observation_jacobians",
    "landmark_from_observation",
    "landmark_from_observation_jacobians",
]


def measurement_covariance(observation: Observation, with_height: bool = False) -> np.ndarray:
    """R = diag(σ_range², σ_bearing²) from the observation's own standard deviations;
    with ``with_height``, diag(σ_range², σ_bearing², σ_height²)."""
    if with_height:
        return np.diag([observation.sigma_range_m**2, observation.sigma_bearing_rad**2, observation.sigma_height_m**2])
    return np.diag([observation.sigma_range_m**2, observation.sigma_bearing_rad**2])


def observation_nis(pose, landmark_xy, joint_covariance, observation: Observation) -> float:
    """NIS of one observation of a mapped landmark, given the 5×5 joint covariance of the
    pose and the landmark: :func:`ekf.models.range_nis` (1 degree of freedom) for a
    range-only reading, else :func:`ekf.models.range_bearing_nis` with
    :func:`measurement_covariance`. Every estimator's ``predicted_nis`` asks it."""
    if observation.range_only:
        return range_nis(pose, landmark_xy, joint_covariance, observation.range_m, observation.sigma_range_m)
    return range_bearing_nis(pose, landmark_xy, joint_covariance, observation.range_m, observation.bearing_rad,
                             measurement_covariance(observation))


def has_height(observation: Observation) -> bool:
    """True when the observation carries a usable height (a value and a positive σ)."""
    return (
        observation.height_m is not None
        and observation.sigma_height_m is not None
        and observation.sigma_height_m > 0.0
    )


def observation_model(pose, landmark) -> np.ndarray:
    """Predicted measurement of a landmark state: ``(range, bearing)`` for ``(x, y)``,
    ``(range, bearing, height)`` for ``(x, y, h)`` — the height is measured directly."""
    r, b = range_bearing(pose, landmark[:2])
    if len(landmark) == 3:
        return np.array([r, b, float(landmark[2])])
    return np.array([r, b])


def observation_jacobians(pose, landmark) -> tuple[np.ndarray, np.ndarray]:
    """Jacobians of :func:`observation_model`: ``(H_pose m×3, H_landmark m×m)``, m = len(landmark).

    The height row is ``[0 0 0 | 0 0 1]``: the height depends on nothing but h.
    """
    H_pose, H_landmark = range_bearing_jacobians(pose, landmark[:2])
    if len(landmark) == 3:
        H_pose = np.vstack([H_pose, np.zeros((1, ROBOT_DIM))])
        H_landmark = np.block([[H_landmark, np.zeros((2, 1))], [np.zeros((1, 2)), np.ones((1, 1))]])
    return H_pose, H_landmark


def landmark_from_observation(pose, range_m: float, bearing_rad: float, height_m: float | None = None) -> np.ndarray:
    """Inverse observation model: ``(x, y)``, or ``(x, y, h)`` with ``h = height_m`` when given."""
    x, y = landmark_from_range_bearing(pose, range_m, bearing_rad)
    return np.array([x, y] if height_m is None else [x, y, float(height_m)])


def landmark_from_observation_jacobians(
    pose, range_m: float, bearing_rad: float, with_height: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """Jacobians of :func:`landmark_from_observation`: ``(G_pose k×3, G_measurement k×k)``.

    Without a height these are :func:`ekf.models.landmark_init_jacobians`. With one, the
    height row of ``G_pose`` is zero and ``G_measurement`` gets a 1 for the height, so a new
    landmark's h has variance σ_h² and no correlation with anything else.
    """
    G_pose, G_measurement = landmark_init_jacobians(pose, range_m, bearing_rad)
    if with_height:
        G_pose = np.vstack([G_pose, np.zeros((1, ROBOT_DIM))])
        G_measurement = np.block([[G_measurement, np.zeros((2, 1))], [np.zeros((1, 2)), np.ones((1, 1))]])
    return G_pose, G_measurement
