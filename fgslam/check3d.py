"""``fgslam check`` on a 3-D log (seed 003's stereo camera + IMU): what is measured.

:func:`fgslam.check.check_estimator` reads the log and, for a 3-D one, asks
:func:`score_3d` for the figures; the tolerances and the verdict are the planar check's.

* The reference is the log's ground truth (``--against truth``: the poses that have a
  ``truth_pose3``, at least half of them and at least 10) or the smoothed solution: batch
  Levenberg–Marquardt on the stereo factor graph of ``isam2-3d`` (:mod:`fgslam.smoother3d`),
  started from iSAM2's result, exactly as ``fgslam run`` computes it.
* The ATE is the RMSE of the 3-D positions of the final trajectory over the scored poses,
  without alignment (every estimator starts at the IMU's first pose, the world frame).
* The NEES is the pose NEES on SE(3) (right perturbation, χ²₆, 95 % band [1.24, 14.45]) of
  each online pose with the covariance the estimator stated for it.

A smoothed solution whose graph holds no landmark seen twice is no better than the IMU
alone and is refused, as in 2-D.
"""

from __future__ import annotations

import numpy as np

from fgslam.runner import UnusableReferenceError
from fgslam.runner3d import (
    POSE_DOF,
    make_estimator_3d,
    noise_of,
    pose_nees_series,
    position_rmse_m,
    run_estimator_3d,
    truth_reference_3d,
)
from slamio.datasets.seed003_log import log_to_drive

__all__ = ["DEFAULT_ESTIMATOR_3D", "score_3d"]

#: The estimator ``fgslam check`` checks on a 3-D log when none is named: the consistent joint EKF.
DEFAULT_ESTIMATOR_3D = "ekf-vio-fej"


def score_3d(log, log_path, estimator: str, against: str):
    """The :class:`fgslam.check.Score` of ``estimator`` (a name of
    :data:`fgslam.runner3d.ESTIMATORS_3D`) on the 3-D ``log`` against ``against``."""
    from fgslam.check import Score, require_enough_truth
    from fgslam.smoother3d import batch_solve

    drive = log_to_drive(log)
    noise = noise_of(log)
    run = None
    if against == "truth":
        reference = truth_reference_3d(log)
        require_enough_truth(log_path, 0 if reference is None else reference.poses_with_truth, drive.n_steps)
        reference_poses, has_pose = reference.trajectory, reference.mask
    else:
        graph = make_estimator_3d("isam2-3d", drive, noise)
        # checking isam2-3d itself: its one run (with covariances) also gives the graph
        graph_run = run_estimator_3d(graph, drive, covariances=estimator == "isam2-3d")
        require_landmarks_seen_twice(graph, log_path)
        if estimator == "isam2-3d":
            run = graph_run
        reference_poses = batch_solve(graph).trajectory()
        has_pose = np.ones(drive.n_steps, dtype=bool)
    if run is None:
        run = run_estimator_3d(make_estimator_3d(estimator, drive, noise), drive)
    ate = position_rmse_m(run.final, reference_poses, 3, has_pose)
    values = None
    if run.covariances is not None and np.any(np.isfinite(run.covariances)):
        values = pose_nees_series(run.online, run.covariances, reference_poses)[has_pose]
    dofs = None if values is None else np.full(len(values), POSE_DOF)
    return Score(ate, values, dofs, int(np.count_nonzero(has_pose)), drive.n_steps)


def require_landmarks_seen_twice(graph, log_path) -> None:
    """Refuse a smoothed solution that no landmark constrains beyond the IMU: every stereo
    factor is then a landmark's only one."""
    if graph.stereo_factors <= len(graph.landmark_ids()):
        raise UnusableReferenceError(
            f"{log_path}: the smoothed solution is the IMU dead reckoning (no landmark is seen twice with a "
            f"usable disparity: {graph.stereo_factors} stereo factors on {len(graph.landmark_ids())} landmarks); "
            "check against the truth (--against truth) or record a log whose tracks last"
        )
