"""From a bag's messages to observations, the camera's mount and the truth, with every
assumption said: the rig-level pieces of :func:`slamio.datasets.rosbag.import_rosbag`.

- **Mount** (:func:`camera_mount`): ``T_robot_camera`` given (``--camera-pose`` or a camera
  poses file), else the chain from the odometry's body frame (its ``child_frame_id``) to the
  detections' frame (their ``header.frame_id``) on ``/tf_static``, else the optical frame at
  the body's origin looking forward — with a warning naming what was assumed.
- **Observations** (:func:`sighting_observations`): tag poses (apriltag_ros, one PoseStamped
  per tag) and tag corners (apriltag_msgs, :mod:`slamio.datasets.rosbag_corners`), each
  placed through the mount *and* the body's roll and pitch at its time
  (:meth:`~slamio.datasets.rosbag_level.Attitudes.tilt_at`).
- **Truth from a second bag** (:func:`truth_from_bag`): its 3-D poses as the body's planar
  poses (``truth_pose_of="camera"`` when the reference tracks the camera, as TagSLAM's
  ``/tagslam/odom/body_rig`` of a rig whose body is the camera), and the tag map on its
  ``/tf`` (frames ``tag_<id>``) as ``truth_landmark`` records.
"""

from __future__ import annotations

import math
import re
from typing import Any

import numpy as np

from slamio.datasets.rosbag_corners import corner_observation
from slamio.datasets.rosbag_messages import T_ROBOT_OPTICAL, tag_observation_geometry
from slamio.log import Observation, TruthLandmark

__all__ = ["camera_mount", "sighting_observations", "tag_map_from_tf", "truth_from_bag"]


def _chain(tf: dict[tuple[str, str], np.ndarray], parent: str, child: str) -> np.ndarray | None:
    """T_parent_child from the static transforms (either direction, any depth), or None."""
    edges: dict[str, list[tuple[str, np.ndarray]]] = {}
    for (a, b), T in tf.items():
        edges.setdefault(a, []).append((b, T))
        edges.setdefault(b, []).append((a, np.linalg.inv(T)))
    seen, stack = {parent}, [(parent, np.eye(4))]
    while stack:
        frame, T = stack.pop()
        if frame == child:
            return T
        for nxt, step in edges.get(frame, []):
            if nxt not in seen:
                seen.add(nxt)
                stack.append((nxt, T @ step))
    return None


def camera_mount(given: np.ndarray | None, tf_static: dict, body_frame: str | None, camera_frame: str | None,
                 warnings: list[str]) -> tuple[np.ndarray, str]:
    """(T_robot_camera, where it came from); appends a warning when it had to be assumed."""
    if given is not None:
        return given, "given (--camera-pose or a camera poses file)"
    if tf_static and body_frame and camera_frame:
        T = _chain(tf_static, body_frame.lstrip("/"), camera_frame.lstrip("/"))
        if T is not None:
            return T, f"/tf_static: {body_frame} -> {camera_frame}"
    why = ("the bag has no /tf_static" if not tf_static else
           f"/tf_static has no chain from {body_frame!r} to {camera_frame!r}")
    warnings.append(f"camera mount: {why} and no --camera-pose was given; assumed the camera's optical frame at the "
                    "odometry body's origin (0, 0, 0 m) looking along its x axis. If the camera sits elsewhere give "
                    "--camera-pose x,y,z,qx,qy,qz,qw (the camera's optical frame in the odometry's body frame)")
    return T_ROBOT_OPTICAL.copy(), "assumed: optical frame at the body's origin, looking forward"


def _level_camera(tilt: np.ndarray, T_rc: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = tilt @ T_rc[:3, :3]
    T[:3, 3] = tilt @ T_rc[:3, 3]
    return T


def sighting_observations(o: Any, messages: Any, attitudes: Any, t0_ns: int, dropped: dict[str, int]
                          ) -> list[tuple[int, Observation]]:
    """Every tag pose and tag-corner detection as (stamp ns, observation), σ from the options
    (poses) or from the corner geometry (corners), each placed through its own camera's mount
    (``o.mounts[k]``); refused corners are counted in ``dropped``."""
    normal_sign = 1.0 if o.tag_normal_axis == "+z" else -1.0
    out: list[tuple[int, Observation]] = []
    for t, tag_id, position, quaternion, k in messages.sightings:
        T = _level_camera(attitudes.tilt_at(t), o.mounts[k])
        range_m, bearing_rad, yaw, height = tag_observation_geometry(position, quaternion, T, normal_sign)
        if not range_m > 0.0:
            dropped["zero_range"] += 1
            continue
        out.append((t, Observation(
            (t - t0_ns) / 1e9, tag_id, range_m, bearing_rad, o.sigma_range_m, o.sigma_bearing_rad,
            height_m=height if o.with_height else None, sigma_height_m=o.sigma_height_m if o.with_height else None,
            tag_yaw_rad=yaw, sigma_tag_yaw_rad=o.sigma_tag_yaw_rad if yaw is not None else None)))
    for t, tag_id, corners, k in messages.corners:
        size = o.tag_size_of(tag_id)
        if size is None:
            dropped["corners_unknown_tag_size"] = dropped.get("corners_unknown_tag_size", 0) + 1
            continue
        T = _level_camera(attitudes.tilt_at(t), o.mounts[k])
        seen = corner_observation(corners, size, o.cameras[k], T, o.pixel_sigma_px, o.max_reprojection_px)
        if isinstance(seen, str):
            dropped[f"corners_{seen}"] = dropped.get(f"corners_{seen}", 0) + 1
            continue
        out.append((t, Observation(
            (t - t0_ns) / 1e9, tag_id, seen.range_m, seen.bearing_rad, max(seen.sigma_range_m, 1e-4),
            max(seen.sigma_bearing_rad, 1e-5),
            height_m=seen.height_m if o.with_height else None,
            sigma_height_m=max(seen.sigma_height_m, 1e-4) if o.with_height else None,
            tag_yaw_rad=seen.tag_yaw_rad,
            sigma_tag_yaw_rad=max(seen.sigma_tag_yaw_rad, 1e-4) if seen.tag_yaw_rad is not None else None)))
    out.sort(key=lambda m: m[0])
    return out


def truth_from_bag(poses: list, pose_of: str, T_rc: np.ndarray) -> list[tuple[int, tuple[float, float, float]]]:
    """Planar body poses (stamp ns, (x, y, yaw)) of a second bag's 3-D poses; ``pose_of``
    "camera": the poses are the camera's optical frame, moved to the body through the mount."""
    from scipy.spatial.transform import Rotation

    T_cam_body = np.linalg.inv(T_rc)
    out = []
    for t, p, q in poses:
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = Rotation.from_quat(q).as_matrix(), p
        if pose_of == "camera":
            T = T @ T_cam_body
        out.append((t, (float(T[0, 3]), float(T[1, 3]), math.atan2(T[1, 0], T[0, 0]))))
    return out


_TAG_FRAME = re.compile(r"\Atag_(\d+)\Z")


def tag_map_from_tf(transforms: dict[tuple[str, str], np.ndarray], root: str) -> list[TruthLandmark]:
    """Every frame ``tag_<id>`` reachable from ``root`` on a bag's /tf (last value of each
    transform) as a truth landmark: position, height, and the yaw of its face normal (+z)."""
    out = []
    children = sorted({c for _, c in transforms} | {p for p, _ in transforms})
    for frame in children:
        m = _TAG_FRAME.match(frame)
        if not m:
            continue
        T = _chain(transforms, root, frame)
        if T is None:
            continue
        out.append(truth_landmark_of_tag(int(m.group(1)), T))
    return out


def truth_landmark_of_tag(tag_id: int, T_map_tag: np.ndarray) -> TruthLandmark:
    """A tag's 4×4 pose in the map as a truth landmark: position, height, and the yaw of its
    face normal (+z; None when the tag faces up or down, more than 60° from the wall)."""
    n = T_map_tag[:3, 2]
    yaw = math.atan2(n[1], n[0]) if math.hypot(n[0], n[1]) >= 0.5 else None
    return TruthLandmark(int(tag_id), float(T_map_tag[0, 3]), float(T_map_tag[1, 3]), float(T_map_tag[2, 3]), yaw)


def surveyed_tag_map(surveyed: dict[int, np.ndarray]) -> list[TruthLandmark]:
    """The surveyed tag poses of a tags file (TagSLAM's static bodies) as truth landmarks."""
    return [truth_landmark_of_tag(tag_id, T) for tag_id, T in sorted(surveyed.items())]
