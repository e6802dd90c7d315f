"""Dead reckoning: the baseline every SLAM estimator must beat.

The pose is the start pose composed with every odometry increment; observations never
correct it. So that a map error can still be computed, each landmark is placed once, at
its first sighting, from the dead-reckoned pose of that moment, and never moved again.
The pose covariance is propagated as well (it only grows), so that consistency metrics can
be computed for the baseline too.
"""

from __future__ import annotations

import numpy as np

from ekf.models import landmark_from_range_bearing, motion_jacobians, predict_pose
from slamio.geometry import wrap_angle
from slamio.log import Header, Step

__all__ = ["DeadReckoning"]


class DeadReckoning:
    """Odometry-only estimator (implements ``slamio.estimator.Estimator``).

    Built from the log header (start pose and its standard deviations). Counters:
    ``skipped_unknown_id`` (observations without a landmark id, ignored).
    """

    name = "dead_reckoning"

    def __init__(self, header: Header):
        x, y, th = (float(v) for v in header.start_pose)
        self._pose = np.array([x, y, wrap_angle(th)])
        self._cov = np.diag(np.square(np.asarray(header.start_sigma, dtype=float)))
        self._landmarks: dict[int, tuple[float, float]] = {}
        self._trajectory: list[tuple[float, float, float]] = []
        self.skipped_unknown_id = 0

    def step(self, step: Step) -> None:
        """Compose the odometry increment (if any); place landmarks seen for the first time."""
        if step.odometry is not None:
            odometry = step.odometry
            increment = (odometry.dx_m, odometry.dy_m, odometry.dtheta_rad)
            F_pose, F_increment = motion_jacobians(self._pose, increment)
            Q = F_increment @ np.asarray(odometry.covariance, dtype=float) @ F_increment.T
            self._pose = predict_pose(self._pose, increment)
            self._cov = F_pose @ self._cov @ F_pose.T + Q
        for observation in step.observations:
            if observation.landmark_id is None:
                self.skipped_unknown_id += 1
            elif observation.landmark_id not in self._landmarks and not observation.range_only:
                self._landmarks[observation.landmark_id] = landmark_from_range_bearing(
                    self._pose, observation.range_m, observation.bearing_rad
                )
        self._trajectory.append(self.current_pose())

    def current_pose(self) -> tuple[float, float, float]:
        """The dead-reckoned pose ``(x_m, y_m, theta_rad)``."""
        x, y, th = self._pose
        return float(x), float(y), float(th)

    def current_covariance(self) -> np.ndarray:
        """3×3 covariance of the dead-reckoned pose (a copy)."""
        return self._cov.copy()

    def finish(self) -> None:
        """Nothing to do."""

    def trajectory(self) -> np.ndarray:
        """(n, 3) array of the dead-reckoned pose after each step."""
        return np.array(self._trajectory, dtype=float).reshape(-1, 3)

    def landmarks(self) -> dict[int, tuple[float, float]]:
        """Landmark id → ``(x_m, y_m)`` where it was placed at its first sighting."""
        return dict(self._landmarks)
