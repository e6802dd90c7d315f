"""What ``--estimators`` accepts, for the help texts (no estimator code is imported here)."""

from __future__ import annotations

#: name -> one line of help (fgslam.runner.ESTIMATORS; a test keeps the two in step).
ESTIMATOR_HELP = {
    "ekf": "textbook EKF-SLAM; JCBB data association for observations without an id",
    "ekf-nn": "the same EKF with Mahalanobis-gated nearest-neighbour association",
    "ekf-fej": "the same EKF with first-estimates Jacobians (the global heading stays unobservable)",
    "ekf-s000": "seed 000's linear KF (Trinity College, Create + Kinect), as written",
    "ekf-s001": "seed 001's EKF (GoPiGo, forward/rotate moves, nearest neighbour), as written",
    "ekf-s004": "seed 004's KF over robot and AprilTag poses, as written",
    "isam2": "GTSAM iSAM2 factor-graph smoother (the batch solve starts from its result)",
    "isam2-fast": "iSAM2 for long runs/large maps: keyframes, one update per 50 steps",
    "isam2-tags": "iSAM2 with AprilTags as Pose2 landmarks (relative-pose factors use the tag yaw)",
    "isam2-huber": "iSAM2 with a Huber kernel on landmark factors (robust to outliers)",
    "isam2-cauchy": "iSAM2 with a Cauchy kernel on landmark factors (robust to outliers)",
    "isam2-tukey": "iSAM2 with a Tukey kernel on landmark factors (misdetections get zero weight)",
    "isam2-dcs": "iSAM2 with dynamic covariance scaling: least squares within 3.7 sigma, outliers fade",
    "dead_reckoning": "odometry alone: the baseline",
}

#: The estimators of a 3-D log (fgslam.runner3d.ESTIMATORS_3D; a test keeps the two in step).
ESTIMATOR_HELP_3D = {
    "ekf-s003": "seed 003's EKF (stereo + IMU, pose from the IMU alone, per-landmark updates), as written",
    "ekf-s003-figures": "the same with eq. 16's and eq. 1's typos read as its figures require",
    "ekf-vio": "textbook visual-inertial EKF-SLAM on SE(3): pose and landmarks updated jointly",
    "ekf-vio-fej": "the same keeping the unobservable directions of its first estimates (FEJ, projected "
                   "Jacobians): NEES in band on most drives",
    "isam2-3d": "GTSAM iSAM2 on Pose3 + stereo factors + IMU between factors (the batch solve starts from it)",
}
