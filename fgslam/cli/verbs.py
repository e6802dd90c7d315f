"""Every ``fgslam`` verb: its name, the module of :mod:`fgslam.cli` that implements it, and its
one line of help — all ``fgslam --help`` needs, so listing the verbs imports none of them
(each verb module uses its line from here: one text in both places).

Importing this module costs nothing: it holds only these strings.
"""

from __future__ import annotations

#: verb -> (module of fgslam.cli, one line of help), in the order ``fgslam --help`` lists them.
VERBS: dict[str, tuple[str, str]] = {
    "sim": ("sim", "simulate a run and write its log (with ground truth)"),
    "run": ("run", "run the estimators on a log and write the comparison"),
    "import": ("import_", "convert a dataset from elsewhere into a run log"),
    "export": ("export", "write a run log in another format (a ROS 2 bag)"),
    "validate": ("validate", "check a run log line by line and summarise it"),
    "check": ("check", "regression check: one estimator against the smoothed solution or the truth (exit 0/1)"),
    "bench": ("bench", "Monte Carlo: many seeded simulations, average NEES per step against its chi-square band"),
    "detect": ("detect",
               "camera frames -> landmark observations (AprilTags or Kinect colour cylinders) in a run log"),
    "tune-colours": ("tune_colours",
                     "fit the colour-landmark file's HSV ranges to your frames; write masks and detections to "
                     "look at"),
    "record": ("record", "drive an iRobot Create (or the simulated one) and record its odometry to a run log"),
    "calibrate": ("calibrate",
                  "learn the odometry and reading noise: a noise model fitted to logs with ground truth "
                  "(LOG.jsonl...), or seed 001's covariances from measured trials (TRIALS.csv); "
                  "not the camera (calibrate-camera)"),
    "calibrate-camera": ("calibrate_camera",
                         "camera intrinsics and lens distortion from chessboard pictures -> camera_info YAML"),
    "live": ("live", "drive the Create on the iSAM2 pose with the camera in the loop; record it all"),
}


def help_of(verb: str) -> str:
    """The one line of help of ``verb`` (what ``fgslam --help`` lists)."""
    return VERBS[verb][1]
