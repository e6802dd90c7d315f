"""ekf: the independent reference estimators — EKF-SLAM and dead reckoning, numpy only.

This package never imports gtsam, so it can check the factor-graph estimators
independently. Estimators here are pure: they consume ``slamio.log.Step`` objects and
return estimates; they never print, plot or read files.
"""

from ekf.dead_reckoning import DeadReckoning
from ekf.models import (
    landmark_from_range_bearing,
    landmark_init_jacobians,
    motion_jacobians,
    predict_pose,
    range_bearing,
    range_bearing_jacobians,
)
from ekf.slam import EkfSlam, joseph_update, kalman_gain

__all__ = [
    "DeadReckoning",
    "EkfSlam",
    "joseph_update",
    "kalman_gain",
    "landmark_from_range_bearing",
    "landmark_init_jacobians",
    "motion_jacobians",
    "predict_pose",
    "range_bearing",
    "range_bearing_jacobians",
]
