"""A seed-003 drive (:class:`StereoImuDrive`) as a 3-D run log.

``drive_to_log`` writes step 0 at the header's start (the world frame is the IMU at step
0, so ``start.pose3`` is the identity, or the truth's first pose for a simulated drive) and
one ``velocity_odometry`` record per later step t: the twist measured at step t − 1, held
over ``dt_s = stamp_t − stamp_{t−1}``, exactly what the seed's prediction uses. The stereo
observations and truth of step t follow it. The drive's last twist acts after its last
stamp and is not written.

The estimators never see the drive's arrays: ``fgslam run`` reads the log and feeds its typed
steps (``fgslam.runner3d.prepare_log3d``); a test checks that those inputs equal the drive's
own (``ekf.drive3d.steps_of``) except for that unused last twist.
"""

from __future__ import annotations

import numpy as np

from slamio.datasets.seed003 import StereoImuDrive, StereoImuNoise
from slamio.log import (
    Header,
    StereoObservation,
    TruthLandmark3,
    TruthPose3,
    VelocityOdometry,
    pose3_from_matrix,
    stereo_sensor,
)

__all__ = ["drive_to_log"]

#: σ of the start pose: pinned (the world frame is defined by pose 0).
START_SIGMA3 = (1e-6,) * 6


def drive_to_log(drive: StereoImuDrive, noise: StereoImuNoise = StereoImuNoise(), source: dict | None = None):
    """``(Header, records)`` of a 3-D run log holding ``drive``, with ``noise`` as every record's σ
    (its 4×4 ``pixel_covariance`` as every stereo observation's ``covariance_px2`` when given)."""
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
            "observation": (
                {"model": "white noise on each stereo pixel coordinate", "sigma_px": noise.sigma_px}
                if noise.pixel_covariance is None else
                {"model": "white noise on the stereo pixels (u_L, v_L, u_R, v_R), correlated",
                 "covariance_px2": [list(row) for row in noise.pixel_covariance]}
            ),
        },
        source=dict(source or {}),
        version=2,
        start_pose3=pose3_from_matrix(start),
        start_sigma3=START_SIGMA3,
    )
    covariance = tuple(tuple(float(v) for v in row) for row in noise.velocity_cov())
    pixel_noise: dict = (
        {"sigma_px": noise.sigma_px} if noise.pixel_covariance is None
        else {"covariance_px2": tuple(tuple(float(v) for v in row) for row in noise.pixel_covariance)}
    )
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
            records.append(StereoObservation(stamp, int(landmark_id), u_l, v_l, u_r, v_r, **pixel_noise))
        if drive.truth_world_T_imu is not None:
            records.append(TruthPose3(stamp, *pose3_from_matrix(drive.truth_world_T_imu[t])))
    return header, records
