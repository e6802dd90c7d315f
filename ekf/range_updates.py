"""The EKF's range-only landmarks: :class:`RangeOnlyUpdates`, the part of
:class:`ekf.slam.EkfSlam` that updates with a range to a landmark in the state and holds a
landmark not in it back until its ranges pin it down (delayed initialisation, the rule in
:mod:`ekf.range_only`).

A mixin: it works on the state :class:`ekf.slam.EkfSlam` sets up in its ``__init__``.
"""

from __future__ import annotations

import numpy as np

from ekf.covariance import augment_covariance, kalman_gain
from ekf.models import LANDMARK_DIM, ROBOT_DIM, range_bearing, range_bearing_jacobians
from ekf.range_only import try_initialise
from slamio.log import Observation


class RangeOnlyUpdates:
    """Range-only readings: a scalar update, or a buffered range until the landmark is placed."""

    def _update_range(self, key: int, observation: Observation) -> None:
        """One scalar EKF update with a range: ``H = [−e/r, 0 | e/r]`` over (x, y, θ, lx, ly)."""
        n = self._dim
        i = self._slot[key]
        mean = self._mean[:n]
        P = self._cov[:n, :n]
        pose, landmark = mean[:ROBOT_DIM], mean[i : i + 2]
        predicted_range, _ = range_bearing(pose, landmark)
        H_pose, H_landmark = range_bearing_jacobians(*self._linearisation_point(key, pose, landmark))
        cols = np.array([0, 1, 2, i, i + 1])
        H_cols = np.hstack([H_pose[:1], H_landmark[:1]])
        R = np.array([[observation.sigma_range_m**2]])
        K, _, _ = kalman_gain(P, cols, H_cols, R)
        self._correct(n, P, cols, H_cols, K, R, np.array([observation.range_m - predicted_range]))
        self.range_updates += 1

    def _buffer_range(self, key: int, observation: Observation) -> bool:
        """Keep a range to a landmark not in the state; add the landmark once its ranges pin
        it down (:func:`ekf.range_only.try_initialise`). True when it was added.

        The new landmark's mean is the trilateration from the robot positions estimated at
        the time of each range; its covariance is the trilateration's plus the current robot
        position covariance, with no cross-covariance (an approximation: the buffered
        ranges' link to the robot's past is not tracked). The buffered ranges are not
        applied again: their information is in that covariance.
        """
        buffer = self._range_buffer.setdefault(key, [])
        buffer.append((float(self._mean[0]), float(self._mean[1]), observation.range_m, observation.sigma_range_m))
        del buffer[: -self.range_rule.max_buffer]
        data = np.array(buffer)
        fit = try_initialise(data[:, :2], data[:, 2], data[:, 3], self.range_rule)
        if fit is None:
            return False
        n = self._dim
        self._reserve(n + LANDMARK_DIM)
        self._mean[n : n + 2] = fit.xy
        covariance = fit.covariance + self._cov[:2, :2]
        augment_covariance(self._cov, n, np.zeros((LANDMARK_DIM, ROBOT_DIM)), np.eye(LANDMARK_DIM), covariance)
        self._register_landmark(key, n, with_height=False)
        del self._range_buffer[key]
        self.range_landmarks_initialised += 1
        return True
