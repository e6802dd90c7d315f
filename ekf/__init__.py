"""ekf: the independent reference estimators — EKF-SLAM, the seed papers' filters, dead reckoning.

``EkfSlam`` is the textbook EKF-SLAM (with NN/JCBB data association and optional 3-D
landmark heights), ``FejEkfSlam`` the same with first-estimates Jacobians, ``InvariantEkfSlam`` with the right-invariant error; ``EkfS000``, ``EkfS001``, ``EkfS003`` and ``EkfS004`` reproduce the seed
papers' filters as written, flaws included (docs/estimators.md); ``g_height`` is seed 002's
landmark-height formula. Each module is named for what the filter is: seed 000's linear KF
with a Kinect (``linear_kf_kinect``), seed 001's EKF with landmark signatures
(``signature_ekf``), seed 002's Kinect landmark heights (``kinect_height``), seed 003's
stereo + IMU EKF (``stereo_imu_ekf``), seed 004's AprilTag KF (``apriltag_kf``). ``VioEkf`` is the textbook stereo + IMU EKF-SLAM on SE(3) for
seed 003's drives (``ekf.drive3d`` feeds them; ``slamio.se3`` and ``slamio.stereo`` hold the maths).

This package never imports gtsam, so it can check the factor-graph estimators
independently. Estimators here are pure: they consume ``slamio.log.Step`` objects and
return estimates; they never print, plot or read files.
"""

from ekf.dead_reckoning import DeadReckoning
from ekf.fej import FejEkfSlam
from ekf.invariant import InvariantEkfSlam
from ekf.models import (
    landmark_from_range_bearing, landmark_init_jacobians, motion_jacobians, predict_pose, range_bearing,
    range_bearing_jacobians,
)
from ekf.linear_kf_kinect import EkfS000
from ekf.signature_ekf import EkfS001
from ekf.kinect_height import exact_height_m, g_height
from ekf.stereo_imu_ekf import EkfS003
from ekf.apriltag_kf import EkfS004
from ekf.covariance import joseph_update, kalman_gain
from ekf.slam import EkfSlam
from ekf.vio import VioEkf

__all__ = [
    "DeadReckoning",
    "EkfS000",
    "EkfS001",
    "EkfS003",
    "EkfS004",
    "EkfSlam",
    "FejEkfSlam",
    "InvariantEkfSlam",
    "exact_height_m",
    "g_height",
    "joseph_update",
    "kalman_gain",
    "landmark_from_range_bearing",
    "landmark_init_jacobians",
    "motion_jacobians",
    "predict_pose",
    "range_bearing",
    "range_bearing_jacobians",
    "VioEkf",
]
