"""The options of :func:`slamio.datasets.rosbag.import_rosbag`, checked before the bag is
converted: the σ and modes the caller gives (:func:`check_options`, :func:`check_level_and_truth`),
the camera's mount as a rigid 4×4 (:func:`robot_camera_transform`), the camera and corner noise
that tag corners need (:func:`corner_inputs`), and all of them as the conversion uses them
(:class:`ImportOptions`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from slamio.datasets.mrclam_motion import CommandOdometryNoise
from slamio.datasets.rosbag_corners import DEFAULT_MAX_REPROJECTION_PX
from slamio.datasets.rosbag_level import LEVEL_MODES
from slamio.datasets.rosbag_messages import T_ROBOT_OPTICAL
from slamio.datasets.rosbag_read import CORNERS_TYPE, BagFormatError, CameraTopics, Messages
from slamio.errors import FgslamError

__all__ = ["DEFAULT_MAX_TRUTH_GAP_S", "DEFAULT_SIGMA_BEARING_RAD", "DEFAULT_SIGMA_HEIGHT_M", "DEFAULT_SIGMA_RANGE_M",
           "DEFAULT_SIGMA_TAG_YAW_RAD", "ImportOptions", "check_level_and_truth", "check_options", "corner_inputs",
           "require_tag_sizes", "robot_camera_transform"]

DEFAULT_SIGMA_RANGE_M = 0.05
DEFAULT_SIGMA_BEARING_RAD = 0.02
DEFAULT_SIGMA_TAG_YAW_RAD = 0.1
DEFAULT_SIGMA_HEIGHT_M = 0.05
DEFAULT_MAX_TRUTH_GAP_S = 0.5


def check_options(tag_normal_axis: str, start_from: str, truth_topic: str | None, odom_min_period_s: float,
                   **positive: float) -> None:
    """:func:`import_rosbag`'s options that the bag does not decide; ``positive``: the σ and gaps."""
    if tag_normal_axis not in ("+z", "-z"):
        raise FgslamError(f"tag_normal_axis must be '+z' or '-z', got {tag_normal_axis!r}")
    if start_from not in ("odom", "truth", "zero"):
        raise FgslamError(f"start_from must be 'odom', 'truth' or 'zero', got {start_from!r}")
    if start_from == "truth" and truth_topic is None:
        raise FgslamError("start_from='truth' needs a truth_topic")
    for name, value in positive.items():
        if not (math.isfinite(value) and value > 0.0):
            raise FgslamError(f"{name} must be a positive number, got {value!r}")
    if not (math.isfinite(odom_min_period_s) and odom_min_period_s >= 0.0):
        raise FgslamError(f"odom_min_period_s must be >= 0, got {odom_min_period_s!r}")


def robot_camera_transform(T_robot_camera: Any) -> np.ndarray:
    """The camera's pose on the robot as a checked 4×4 (default: :data:`T_ROBOT_OPTICAL`)."""
    T_rc = T_ROBOT_OPTICAL.copy() if T_robot_camera is None else np.asarray(T_robot_camera, dtype=float)
    if T_rc.shape != (4, 4) or not np.allclose(T_rc[:3, :3] @ T_rc[:3, :3].T, np.eye(3), atol=1e-6) \
            or not np.allclose(T_rc[3], [0, 0, 0, 1]) or np.linalg.det(T_rc[:3, :3]) < 0:
        raise FgslamError("T_robot_camera must be a 4x4 rigid transform (orthonormal rotation, det +1, last row 0 0 0 1)")
    return T_rc


def check_level_and_truth(level: str, truth_pose_of: str, truth_bag, truth_topic, truth_frames=None) -> None:
    if level not in LEVEL_MODES:
        raise FgslamError(f"level must be one of {', '.join(LEVEL_MODES)}, got {level!r}")
    if truth_pose_of not in ("body", "camera"):
        raise FgslamError(f"truth_pose_of must be 'body' or 'camera', got {truth_pose_of!r}")
    if truth_frames is not None and truth_topic is not None:
        raise FgslamError("--truth-topic and --truth-frames both give the truth; give one of them")
    if truth_frames is not None and (len(truth_frames) != 2 or not all(truth_frames)):
        raise FgslamError(f"truth frames must be two frame names (--truth-frames map:rig), got {truth_frames!r}")
    if truth_bag is not None and truth_topic is None and truth_frames is None:
        raise FgslamError("a truth bag needs its truth topic (--truth-topic) or the /tf frames of the truth "
                          "(--truth-frames PARENT:CHILD)")


@dataclass(frozen=True)
class ImportOptions:
    """:func:`import_rosbag`'s options, checked, as the conversion uses them."""

    path: str
    ros_version: int
    odom_topic: str
    camera_topics: CameraTopics
    tag_pose_topic: str | None
    truth_topic: str | None
    mounts: tuple  # T_robot_camera (4×4) of each camera
    tag_normal_axis: str
    sigma_range_m: float
    sigma_bearing_rad: float
    sigma_tag_yaw_rad: float
    with_height: bool
    sigma_height_m: float
    noise: CommandOdometryNoise
    covariance_from_message: bool
    odom_min_period_s: float
    interpolate_detections: bool
    max_truth_gap_s: float
    start_from: str
    cameras: tuple = (None,)  # the CameraModel of each camera (None: not known)
    tag_sizes: Any = None
    tag_size_m: float | None = None
    pixel_sigma_px: float = 1.0
    max_reprojection_px: float = DEFAULT_MAX_REPROJECTION_PX
    mount_sources: tuple = ("",)
    camera_names: tuple = ("cam0",)

    @property
    def T_rc(self) -> np.ndarray:
        """The first camera's mount (the camera a truth of ``truth_pose_of="camera"`` tracks)."""
        return self.mounts[0]

    @property
    def detections_topic(self):
        """The detection topic (one), their list (several) or None."""
        topics = self.camera_topics.detections
        return topics[0] if len(topics) == 1 else (list(topics) if topics else None)

    def tag_size_of(self, tag_id: int) -> float | None:
        listed = self.tag_sizes.sizes_m.get(tag_id) if self.tag_sizes is not None else None
        if listed is not None:
            return listed
        if self.tag_size_m is not None:
            return self.tag_size_m
        return self.tag_sizes.default_size_m if self.tag_sizes is not None else None


def require_tag_sizes(path: str, topic: str, tag_sizes: Any, tag_size_m: float | None, what: str) -> None:
    if tag_sizes is None and tag_size_m is None:
        raise BagFormatError(path, topic, f"holds {what} and no tag size was given: give --tags FILE "
                             "(TagSLAM's tagslam.yaml or default_tag_size/tags) or --tag-size M")


def corner_inputs(path: str, messages: Messages, cameras: list, tag_sizes: Any, tag_size_m: float | None,
                  pixel_sigma_px: float | None, warnings: list[str]) -> float | None:
    """The corner σ for tag-corner detections (refusing a camera with corners and no
    calibration, or no tag size), with warnings for what was assumed."""
    if not messages.corners:
        return pixel_sigma_px
    for k in sorted({k for *_, k in messages.corners}):
        topic = messages.cameras.topics[k]
        if cameras[k] is None:
            raise BagFormatError(path, topic, f"holds tag corners ({CORNERS_TYPE}) and no camera was given: give "
                                 "--camera FILE (a Kalibr cameras.yaml or ROS camera_info YAML) or --camera-info-topic")
        require_tag_sizes(path, topic, tag_sizes, tag_size_m, "tag corners")
    if pixel_sigma_px is None:
        from_file = tag_sizes.pixel_noise_px if tag_sizes is not None else None
        pixel_sigma_px = from_file if from_file is not None else 1.0
        if from_file is None:
            warnings.append("corner noise: assumed 1.0 px per corner coordinate (no --pixel-sigma, no pixel_noise in "
                            "a tags file); each tag's range, bearing and yaw sigma follow from it")
    ids = sorted({i for _, i, *_ in messages.corners})
    unsized = [i for i in ids if (tag_sizes is None or i not in tag_sizes.sizes_m)]
    if unsized:
        default = tag_size_m if tag_size_m is not None else (tag_sizes.default_size_m if tag_sizes else None)
        warnings.append(f"tag size: tags {', '.join(map(str, unsized))} are not listed in a tags file; "
                        + (f"used {default:g} m for them" if default is not None else "their detections are dropped"))
    return pixel_sigma_px
