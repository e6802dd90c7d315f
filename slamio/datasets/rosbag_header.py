"""What :func:`slamio.datasets.rosbag.import_rosbag` says about a converted bag: the odometry
levelled and the report of it (:func:`level_odometry`), the warnings with their numbers
(:func:`warn_counts`), and the run log's header (:func:`make_header`).
"""

from __future__ import annotations

from typing import Any

from slamio.datasets.rosbag_level import Attitudes, levelling_rotation, out_of_plane
from slamio.datasets.rosbag_options import ImportOptions
from slamio.datasets.rosbag_read import Messages
from slamio.log import Header
from slamio.log.mount import camera_mount_fields

__all__ = ["corner_noise", "level_odometry", "make_header", "warn_counts"]


def level_odometry(o: ImportOptions, messages: Messages, level: str, threshold_deg: float, warnings: list[str]):
    """The levelled attitudes, their planar poses put into ``messages.odometry``, and the report."""
    R_level, tilt0, levelled = levelling_rotation(messages.odometry_3d[0][2], level, threshold_deg)
    attitudes = Attitudes(messages.odometry_3d, R_level)
    messages.odometry = [(t, attitudes.planar(i), C) for i, (t, _, C) in enumerate(messages.odometry)]
    plane = out_of_plane(attitudes)
    if levelled:
        warnings.append(f"levelling: the odometry frame is not level: the first pose's z axis is {tilt0:.1f} deg from "
                        f"the frame's z (above {threshold_deg:g} deg); every pose was turned by {tilt0:.1f} deg so that "
                        "axis points up (--level none keeps the frame as it is), and the messages' covariance "
                        "was not used")
    elif tilt0 > 1.0:
        warnings.append(f"levelling: the first pose is tilted {tilt0:.1f} deg from the odometry frame's z (at most "
                        f"{threshold_deg:g} deg: taken as the body's own tilt on a level frame, not levelled; "
                        "--level first-pose levels it)")
    if plane["max_abs_dz_m"] > 0.05 or plane["max_tilt_deg"] > 5.0:
        warnings.append(f"3-D motion: the body's height changed by up to {plane['max_abs_dz_m']:.2f} m and it tilted "
                        f"by up to {plane['max_tilt_deg']:.1f} deg (mean {plane['mean_tilt_deg']:.1f} deg); the log "
                        "is planar: heights are dropped, and every detection was turned by the body's roll and pitch "
                        "at its time before its floor range and bearing were taken")
    return attitudes, {"mode": level, "first_pose_tilt_deg": round(tilt0, 3), "levelled": levelled, **{
        k: round(v, 4) for k, v in plane.items()}}


def warn_counts(o: ImportOptions, messages: Messages, counts: dict, n_observations: int, warnings: list[str]) -> None:
    """Warnings for default noise and dropped detections, with the numbers."""
    n_default = counts["covariance"]["default_model"]
    if n_default:
        warnings.append(f"odometry noise: {n_default} of {n_default + counts['covariance']['from_message']} increments "
                        "use the default model (the messages' covariance does not grow like a propagated one: "
                        f"{dict(o.noise.__dict__)}); give a fitted model with `fgslam calibrate`")
    if messages.sightings:
        warnings.append(f"tag pose noise: constant sigmas for the {len(messages.sightings)} tag poses (range "
                        f"{o.sigma_range_m:g} m, bearing {o.sigma_bearing_rad:g} rad, yaw {o.sigma_tag_yaw_rad:g} rad)")
    refused = {k: v for k, v in messages.dropped.items() if k.startswith("corners_") and v}
    if refused:
        total = len(messages.corners)
        warnings.append(f"tag corners: {sum(refused.values())} of {total} detections dropped ("
                        + ", ".join(f"{k[8:]} {v}" for k, v in sorted(refused.items()))
                        + f"; reprojection bound {o.max_reprojection_px:g} px)")
    lost = messages.dropped.get("before_first_odometry", 0) + messages.dropped.get("after_last_odometry", 0)
    if lost:
        warnings.append(f"time: {lost} detections fall outside the odometry's time span and were dropped")


def make_header(o: ImportOptions, messages: Messages, start_pose, t0: int, n_odometry_messages: int,
            counts: dict[str, Any], n_observations: int) -> Header:
    return Header(
        stamp_s=0.0,
        start_pose=tuple(float(v) for v in start_pose),  # type: ignore[arg-type]
        start_sigma=(1e-3, 1e-3, 1e-3),
        robot={"name": "robot of a ROS bag", "odometry_topic": o.odom_topic, "odometry_type": "nav_msgs/Odometry"},
        sensor={
            "kind": "range-bearing",
            "landmark_kind": "apriltag",
            "detections_topic": o.detections_topic,
            "tag_pose_topics": sorted(messages.tag_topics),
            **camera_fields(o),  # each tag placed through its camera's mount: at the robot's centre
            "tag_normal_axis": o.tag_normal_axis,
        },
        noise={
            "odometry": {
                "model": (
                    "from the growth of the messages' (x, y, yaw) pose covariance, Q = J2^-1 (P_k - J1 P_k-1 J1^T) "
                    "J2^-T, when positive definite; otherwise slamio.datasets.mrclam.CommandOdometryNoise "
                    "with ds = |(dx, dy)|, dtheta = |dtheta|, dt = time between messages (>= 1 ms); "
                    "split in proportion to time where a detection adds a pose"
                ),
                "covariance_from_message": o.covariance_from_message,
                "default_model": dict(o.noise.__dict__),
            },
            "observation": corner_noise(o, messages) if messages.corners else {
                "model": "constant sigmas (options of the importer); the detections' covariance is ignored",
                "sigma_range_m": o.sigma_range_m,
                "sigma_bearing_rad": o.sigma_bearing_rad,
                "sigma_tag_yaw_rad": o.sigma_tag_yaw_rad,
                **({"sigma_height_m": o.sigma_height_m} if o.with_height else {}),
            },
        },
        source={
            "dataset": "rosbag",
            "bag": o.path,
            "ros_version": o.ros_version,
            "converted_by": "fgslam import rosbag",
            "tag_corner_detections": len(messages.corners),
            "topics": {"odometry": o.odom_topic, "detections": o.detections_topic,
                       **({"images": list(o.camera_topics.images)} if o.camera_topics.images else {}),
                       "tag_pose_prefix": o.tag_pose_topic, "truth": o.truth_topic},
            "time_origin_ns": t0,
            "stamps": "seconds since the first odometry message (header stamps, or bag time when zero)",
            "start_from": o.start_from,
            "odometry_messages": n_odometry_messages,
            "odometry_min_period_s": o.odom_min_period_s,
            "odometry_covariance": counts["covariance"],
            "poses": counts["poses"],
            "poses_with_truth": counts["poses_with_truth"],
            "observations": n_observations,
            "interpolate_detections": o.interpolate_detections,
            "dropped": messages.dropped,
        },
    )


def corner_noise(o: ImportOptions, messages: Messages) -> dict:
    return {
        "model": "tag corners: each corner coordinate known to pixel_sigma_px; the pose's covariance from the "
                 "corner residuals' Jacobian through the lens model, propagated to range, bearing, tag yaw and "
                 "height (slamio.datasets.rosbag_corners); each observation carries its own sigmas",
        "pixel_sigma_px": o.pixel_sigma_px,
        "max_reprojection_px": o.max_reprojection_px,
        **({"camera": _camera_dict(o.cameras[0])} if len(o.cameras) == 1 else
           {"cameras": {name: _camera_dict(c) for name, c in zip(o.camera_names, o.cameras) if c is not None}}),
        "tag_sizes_m": {str(i): o.tag_size_of(i) for i in sorted({i for _, i, *_ in messages.corners})},
    }


def _camera_dict(camera) -> dict:
    return {"name": camera.name, "width_px": camera.width_px, "height_px": camera.height_px,
            "K": [[float(v) for v in row] for row in camera.K], "distortion_model": camera.distortion_model,
            "dist_coeffs": [float(v) for v in camera.dist_coeffs]}


#: The header's ``sensor.readings_at`` of a rig of several cameras.
READINGS_AT_EACH_CAMERA = ("the robot's centre: each detection is placed through its own camera's T_robot_camera "
                           "(sensor.cameras), so the header states no pose_on_robot")


def camera_fields(o: ImportOptions) -> dict:
    """The header ``sensor`` fields of the cameras: one camera as ``fgslam detect`` states it
    (``T_robot_camera``, ``readings_at``), and every camera by name with its topic, mount and
    where the mount came from (``cameras``)."""
    topics = o.camera_topics.topics
    listed = [{"name": name, "topic": topics[k], "T_robot_camera": [[round(float(v), 9) for v in row] for row in T],
               "mount": o.mount_sources[k]} for k, (name, T) in enumerate(zip(o.camera_names, o.mounts))
              if k < len(topics)]
    if len(o.mounts) == 1:
        return {**camera_mount_fields(o.T_rc), **({"cameras": listed} if listed else {})}
    return {"cameras": listed, "readings_at": READINGS_AT_EACH_CAMERA}
