"""A seed-003 drive (:class:`StereoImuDrive`) as a 3-D run log, and back.

``drive_to_log`` writes step 0 at the header's start (the world frame is the IMU at step
0, so ``start.pose3`` is the identity, or the truth's first pose for a simulated drive) and
one ``velocity_odometry`` record per later step t: the twist measured at step t − 1, held
over ``dt_s = stamp_t − stamp_{t−1}``, exactly what the seed's prediction uses. The stereo
observations and truth of step t follow it. The drive's last twist acts after its last
stamp and is not written.

``log_to_drive`` rebuilds the arrays every 3-D estimator consumes (``ekf.drive3d``). The
round trip is exact except for that unused last twist (zero after it).
"""

from __future__ import annotations

import numpy as np

from slamio.datasets.seed003 import StereoImuDrive, StereoImuNoise
from slamio.errors import FgslamError
from slamio.log import (
    Header,
    RunLog,
    StereoObservation,
    TruthLandmark3,
    TruthPose3,
    VelocityOdometry,
    group_steps,
    pose3_from_matrix,
    pose3_matrix,
    stereo_calibration,
    stereo_sensor,
)

__all__ = ["drive_to_log", "log_to_drive"]

#: σ of the start pose: pinned (the world frame is defined by pose 0).
START_SIGMA3 = (1e-6,) * 6


def drive_to_log(drive: StereoImuDrive, noise: StereoImuNoise = StereoImuNoise(), source: dict | None = None):
    """``(Header, records)`` of a 3-D run log holding ``drive``, with ``noise`` as every record's σ."""
    start = np.eye(4) if drive.truth_world_T_imu is None else drive.truth_world_T_imu[0]
    header = Header(
        stamp_s=float(drive.stamps_s[0]),
        start_pose=(0.0, 0.0, 0.0),  # replaced by the top view of pose3 when read
        start_sigma=(1e-6, 1e-6, 1e-6),
        robot={"name": "car with a stereo camera and an IMU (seed 003)"},
        sensor=stereo_sensor(drive.K, drive.baseline_m, drive.cam_T_imu),
        noise={
            "odometry": {"model": "white noise on each axis of the IMU twist",
                         "sigma_v_mps": noise.sigma_v_mps, "sigma_w_radps": noise.sigma_w_radps},
            "observation": {"model": "white noise on each stereo pixel coordinate", "sigma_px": noise.sigma_px},
        },
        source=dict(source or {}),
        version=2,
        start_pose3=pose3_from_matrix(start),
        start_sigma3=START_SIGMA3,
    )
    covariance = tuple(tuple(float(v) for v in row) for row in noise.velocity_cov())
    records: list = []
    if drive.truth_landmarks_m is not None:
        ids = drive.ids(np.arange(drive.n_landmarks))
        records += [TruthLandmark3(int(j), *(float(v) for v in p)) for j, p in zip(ids, drive.truth_landmarks_m)]
    for t in range(drive.n_steps):
        stamp = float(drive.stamps_s[t])
        if t > 0:
            records.append(VelocityOdometry(
                stamp_s=stamp,
                dt_s=drive.dt_s(t - 1),
                v_mps=tuple(float(v) for v in drive.linear_velocity_mps[t - 1]),  # type: ignore[arg-type]
                w_radps=tuple(float(v) for v in drive.angular_velocity_radps[t - 1]),  # type: ignore[arg-type]
                covariance=covariance,
            ))
        columns = drive.seen(t)
        for j, landmark_id in zip(columns, drive.ids(columns)):
            u_l, v_l, u_r, v_r = (float(v) for v in drive.features_px[t, j])
            records.append(StereoObservation(stamp, int(landmark_id), u_l, v_l, u_r, v_r, noise.sigma_px))
        if drive.truth_world_T_imu is not None:
            records.append(TruthPose3(stamp, *pose3_from_matrix(drive.truth_world_T_imu[t])))
    return header, records


def log_to_drive(log: RunLog, steps=None) -> StereoImuDrive:
    """The drive arrays of a 3-D run log (truth when every pose and landmark has one);
    ``steps``: the log's steps when the caller has grouped them already."""
    header = log.header
    if not header.is_3d:
        raise FgslamError(f"{log.path}: a planar log; the 3-D estimators need a 3-D log (start.pose3, stereo observations)")
    calibration = stereo_calibration(header)
    steps = group_steps(header, log.records) if steps is None else steps
    truth_landmarks = {r.landmark_id: r for r in log.records if isinstance(r, TruthLandmark3)}
    # one column per landmark the log names, in id order: never one per possible id (an id
    # may be up to 2^31 - 1)
    ids = sorted({o.track_id for s in steps for o in s.observations} | set(truth_landmarks))
    column = {landmark_id: j for j, landmark_id in enumerate(ids)}
    T = len(steps)
    features = np.full((T, len(ids), 4), np.nan)
    linear, angular = np.zeros((T, 3)), np.zeros((T, 3))
    stamps = np.array([s.stamp_s for s in steps])
    for t, step in enumerate(steps):
        for o in step.observations:
            features[t, column[o.track_id]] = o.pixels()
        if t > 0:
            linear[t - 1], angular[t - 1] = step.odometry.v_mps, step.odometry.w_radps
    truth_poses = None
    if all(s.truth is not None for s in steps):
        truth_poses = np.array([s.truth.matrix() for s in steps])
    truth_points = None
    if truth_landmarks and all(j in truth_landmarks for j in ids):
        truth_points = np.array([[truth_landmarks[j].x_m, truth_landmarks[j].y_m, truth_landmarks[j].z_m]
                                 for j in ids])
    if truth_poses is None and not np.allclose(pose3_matrix(header.start_pose3), np.eye(4), atol=1e-9):
        raise FgslamError(
            f"{log.path}: start.pose3 is not the identity; the 3-D estimators put the world frame at the IMU's "
            "first pose (write start.pose3 as [0, 0, 0, 0, 0, 0, 1])"
        )
    return StereoImuDrive(
        stamps_s=stamps,
        features_px=features,
        linear_velocity_mps=linear,
        angular_velocity_radps=angular,
        K=calibration.K,
        baseline_m=calibration.baseline_m,
        cam_T_imu=calibration.cam_T_imu,
        truth_world_T_imu=truth_poses,
        truth_landmarks_m=truth_points,
        source=log.path,
        landmark_ids=np.array(ids, dtype=np.int64),
    )
