"""A rig's cameras in a bag: one camera per detection or image topic, each with its own
calibration and its own mount on the robot, for :func:`slamio.datasets.rosbag.import_rosbag`.

Camera ``k`` is the k-th topic of :class:`~slamio.datasets.rosbag_read.CameraTopics`
(detection topics first, then image topics, in the order given), named ``names[k]``
(``cam0``, ``cam1``, ... unless the caller names them).

- **Calibration** (:func:`resolve_cameras`): the camera given for k (a camera file), else the
  first ``sensor_msgs/CameraInfo`` of its ``camera_info`` topic, named or the sibling of its topic
  (``/cam1/image_raw`` → ``/cam1/camera_info``, said in a warning).
- **Mount** (:func:`camera_mounts`): the transform given for k (``--camera-pose NAME=...`` or a
  camera poses file), else ``/tf_static`` from the odometry's body frame to the frame_id of k's
  messages, else the optical frame at the body's origin looking forward (a warning; with
  several cameras that is wrong for all but one of them at most).

Every detection is placed in the robot frame through its own camera's mount, so the log's
readings are the robot centre's (the header states no ``pose_on_robot``; it lists each
camera's ``T_robot_camera`` under ``sensor.cameras``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from slamio.datasets.rosbag_observe import camera_mount
from slamio.datasets.rosbag_read import BagFormatError, CameraTopics
from slamio.errors import FgslamError

__all__ = ["camera_mounts", "camera_names", "default_camera_names", "per_camera", "resolve_cameras"]


def default_camera_names(n: int) -> tuple[str, ...]:
    """cam0, cam1, ...: the names of a rig's n cameras, as Kalibr and TagSLAM's files call them."""
    return tuple(f"cam{k}" for k in range(n))


def camera_names(cameras: CameraTopics, names: Any = None) -> tuple[str, ...]:
    """The name of each camera (``names`` given, else cam0, cam1, ...); at least one (the
    camera of tag pose topics when no camera topic is named)."""
    n = max(1, len(cameras.topics))
    if names is None:
        return default_camera_names(n)
    names = tuple(str(v) for v in names)
    if len(names) != n or len(set(names)) != n:
        raise FgslamError(f"camera names {list(names)} must be {n} different names, one per camera topic "
                          f"({', '.join(cameras.topics) or 'the tag pose topics'})")
    return names


def per_camera(value: Any, n: int, what: str, is_one=lambda v: False) -> list:
    """``value`` as one entry per camera: a list/tuple of ``n`` (None entries allowed), one
    value for a single camera (``is_one(value)``), or None for none given."""
    if value is None:
        return [None] * n
    if is_one(value):
        if n != 1:
            raise FgslamError(f"one {what} was given for {n} cameras: give one per camera, in the order of their topics "
                              "(on the command line NAME=... for each)")
        return [value]
    values = list(value)
    if len(values) != n:
        raise FgslamError(f"{len(values)} {what}s were given for {n} cameras; give one per camera (None where not known)")
    return values


def resolve_cameras(path: str, cameras: CameraTopics, given: list, infos: dict[int, tuple[str, Any]],
                    warnings: list[str]) -> list:
    """The calibration of each camera (module docstring), None where there is none."""
    from slamio.camera.camera_files import camera_from_camera_info_message

    out = []
    for k, topic in enumerate(cameras.topics):
        camera = given[k] if k < len(given) else None
        if camera is None and k in infos:
            info_topic, msg = infos[k]
            camera = camera_from_camera_info_message(msg, f"{path}: topic {info_topic}")
            if cameras.info_topic(k) is None:
                warnings.append(f"camera of {topic}: its calibration read from {info_topic} (the camera_info topic "
                                "next to it; give --camera FILE or --camera-info-topic to use another)")
        out.append(camera)
    return out


def require_image_cameras(path: str, cameras: CameraTopics, resolved: list) -> dict:
    """image topic → camera, refusing an image topic with no calibration."""
    out = {}
    for k, topic in enumerate(cameras.topics):
        if topic not in cameras.images:
            continue
        if resolved[k] is None:
            raise BagFormatError(path, topic, "holds images and its camera's calibration is not known: give --camera "
                                 "FILE (a Kalibr cameras.yaml or ROS camera_info YAML; one per camera, or one Kalibr "
                                 "file naming each) or --camera-info-topic, or record its camera_info topic")
        out[topic] = resolved[k]
    return out


def camera_mounts(given: list, messages: Any, names: tuple[str, ...], warnings: list[str]
                  ) -> tuple[list[np.ndarray], list[str]]:
    """(T_robot_camera of each camera, where it came from); warnings for assumed ones."""
    mounts, sources = [], []
    several = len(names) > 1
    for k, name in enumerate(names):
        said: list[str] = []
        T, source = camera_mount(given[k], messages.tf_static, messages.body_frame, messages.frames.get(k), said)
        if several:
            said = [f"{name} ({messages.cameras.topics[k]}): {w}".replace("--camera-pose x,", f"--camera-pose {name}=x,")
                    for w in said]
        warnings.extend(said)
        mounts.append(T)
        sources.append(source)
    if several:
        assumed = [n for n, s in zip(names, sources) if s.startswith("assumed")]
        if len(assumed) > 1:
            warnings.append(f"camera mount: cameras {', '.join(assumed)} are all assumed at the body's origin looking "
                            "forward: at most one of them can be; their detections disagree until each is placed")
    return mounts, sources
