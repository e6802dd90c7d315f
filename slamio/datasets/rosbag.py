"""ROS bags (ROS 1 and ROS 2) ⇄ run logs, through the pure-Python ``rosbags`` package.

No ROS installation is needed: ``rosbags`` reads and writes ROS 1 ``.bag`` files and ROS 2
bag folders (sqlite3 or MCAP storage) and (de)serialises messages from their definitions.

Import (:func:`import_rosbag`)
------------------------------
The caller names the topics; nothing is guessed.

* ``odom_topic`` — ``nav_msgs/Odometry``. Every message is a pose ``(x, y, yaw)`` of the
  robot in the odometry frame; each message after the first becomes an ``odometry`` record
  holding the SE(2) increment from the previous message's pose, in the previous pose's
  frame (``slamio.geometry.between_pose``). ``odom_min_period_s`` thins a fast topic.
  **Covariance:** the (x, y, yaw) block of the messages' pose covariance describes the
  *accumulated* uncertainty of the pose, so an increment's covariance is the part of its
  growth that propagating the previous covariance does not explain:
  ``Q = J₂⁻¹ (P_k − J₁ P_{k−1} J₁ᵀ) J₂⁻ᵀ`` with ``J₁``, ``J₂`` the Jacobians of
  ``P_{k−1} ⊕ δ``. That is exact for a driver that propagates its covariance (and for
  bags written by :func:`export_rosbag`). When it is not positive definite — a driver that
  publishes zeros (most do) or a constant covariance — the importer uses the documented
  default model instead, :class:`slamio.datasets.mrclam.CommandOdometryNoise` with
  ``Δs = |(dx, dy)|``, ``Δθ = |dθ|`` and ``dt`` the time between the messages (at least
  1 ms). ``covariance_from_message=False`` always uses the default model. How many
  increments took which source is in ``header.source["odometry_covariance"]``.
* ``detections_topic`` — ``apriltag_ros/AprilTagDetectionArray`` (ROS 1 apriltag_ros and
  its ROS 2 ports): ``detections[].id[]``, ``.size[]`` and ``.pose``
  (``PoseWithCovarianceStamped``, the tag's pose in the camera frame). The definitions are
  read from the bag itself; :func:`apriltag_typestore` registers them for writing and for
  old ROS 2 bags that do not store definitions. A tag *bundle* (``len(id) > 1``) has the
  bundle's pose, not a tag's: it is skipped and counted. (The ROS 2 ``apriltag_msgs``
  detections of christianrauch/apriltag_ros carry no pose — that node puts poses on /tf —
  so they are refused with that explanation.)
* ``tag_pose_topic`` — ``geometry_msgs/PoseStamped`` (or ``PoseWithCovarianceStamped``),
  **one topic per tag**: ``tag_pose_topic`` is the common prefix and the tag id is the
  integer that ends each topic name (``/tags/tag_`` reads ``/tags/tag_0``, ``/tags/tag_17``,
  …). A topic per tag is chosen over "frame_id = tag id" because a PoseStamped's frame_id
  must name the frame the pose is expressed in (the camera), and viewers rely on that.
* ``truth_topic`` — optional ground truth (``PoseStamped``, ``PoseWithCovarianceStamped``
  or ``nav_msgs/Odometry``): a ``truth_pose`` at every pose, interpolated like MRCLAM's
  (linear, heading along the shorter arc, not across gaps longer than ``max_truth_gap_s``).

**Camera to robot.** Tag poses are in the camera's optical frame (x right, y down,
z forward). ``T_robot_camera`` (4×4, optical frame → robot frame x forward, y left, z up)
places the camera; the default is the optical frame at the robot's origin looking forward
(:data:`T_ROBOT_OPTICAL`). A tag position ``p`` becomes ``p_robot = R p + t``;
``range_m = |(x, y)|`` and ``bearing_rad = atan2(y, x)`` on the floor plane. **Tag yaw**
is the direction of the tag's face normal projected on the floor, counter-clockwise from
the robot's x axis (the project's convention, slamio.camera.apriltag): the face normal is
the tag frame's +z axis (``tag_normal_axis="+z"``, apriltag_ros's convention; ``"-z"`` for
detectors whose z points into the tag). A normal within 30° of vertical (a tag on the
floor or ceiling) has no meaningful yaw: the observation then has no tag yaw.
Sigmas are options (``sigma_range_m``, ``sigma_bearing_rad``, ``sigma_tag_yaw_rad``); the
covariance in the detection messages is ignored (apriltag_ros leaves it zero).

**Time.** Every message's time is its header stamp, or the bag's receive time when the
stamp is zero or ``use_header_stamps=False``. Log stamps are seconds since the first
odometry message (``header.source["time_origin_ns"]``). A detection between two odometry
messages gets a pose of its own, interpolated between them (the log's rule: observations
belong to the latest odometry record), with the increment's covariance split in proportion
to time; ``interpolate_detections=False`` attaches it to the earlier pose instead.
Detections before the first or after the last odometry message are dropped and counted.
Pose 0 is the first odometry pose (``start_from="odom"``), the ground truth at that time
(``"truth"``, so the estimate is in the truth's frame) or ``(0, 0, 0)`` (``"zero"``).

Export, the exact round trip and the topics an exported bag holds: :mod:`slamio.datasets.rosbag_export`
(:func:`export_rosbag` is importable from here too). What both share (topic names, message
definitions, the typestore, :class:`MessageFactory`, tag geometry): :mod:`slamio.datasets.rosbag_messages`.

**Options of a rig's own bag.** Tag corners (``apriltag_msgs/ApriltagArrayStamped`` on ``detections_topic``) need a
camera (``camera``: a :class:`~slamio.camera.model.CameraModel`, or ``camera_info_topic``)
and tag sizes (``tag_sizes``: a :class:`~slamio.datasets.tagslam_files.TagsFile`, and/or
``tag_size_m`` for every tag it does not list); ``pixel_sigma_px`` is the corners' noise
(default: the tags file's ``pixel_noise``, else 1 px). ``level`` and ``level_threshold_deg``:
:mod:`slamio.datasets.rosbag_level`. ``truth_bag``: read ``truth_topic`` from that bag
instead (``truth_pose_of="camera"`` when its poses are the camera's), with its /tf tag
map as truth landmarks. ``truth_frames`` ``(parent, child)``: the truth is the chain of
transforms on /tf from ``parent`` to ``child`` instead of a topic (in ``truth_bag``, else
in this bag; :func:`~slamio.datasets.rosbag_read.read_tf_poses`).

**Images.** ``image_topic`` (``sensor_msgs/Image`` mono8/bgr8/rgb8 or ``CompressedImage``
jpeg/png): tags are found in every frame by fgslam's own detector and take the corners' path
above (:mod:`slamio.datasets.rosbag_images`; depth images are refused); ``tag_family``
(default tag36h11); ``progress(done, total, "images")`` after each frame. With a tag size
and no detection topic, the bag's only image topic is read.

**Several cameras.** ``detections_topic`` and ``image_topic`` take lists: one camera per
topic (detections first, then images), named ``camera_names`` (default cam0, cam1, ...);
``camera``, ``camera_info_topic`` and ``T_robot_camera`` then take one entry per camera
(None: its camera_info / ``/tf_static`` chain to its messages' frame_id). Each detection is
placed through its own camera's mount: :mod:`slamio.datasets.rosbag_cameras`.
"""

from __future__ import annotations

import dataclasses
import os
from typing import Any, Callable

import numpy as np

from slamio.datasets.mrclam_motion import CommandOdometryNoise
from slamio.datasets.rosbag_export import export_rosbag
from slamio.datasets.rosbag_header import level_odometry, make_header, warn_counts
from slamio.datasets.rosbag_messages import (
    APRILTAG_DETECTION_ARRAY_MSG, APRILTAG_DETECTION_MSG, DETECTIONS_TOPIC, LANDMARKS_TOPIC, ODOMETRY_TOPIC,
    RUN_LOG_TOPIC, T_ROBOT_OPTICAL, TRUTH_TOPIC, MessageFactory, _rosbags, apriltag_typestore,
)
from slamio.datasets.rosbag_corners import DEFAULT_MAX_REPROJECTION_PX
from slamio.datasets.rosbag_level import DEFAULT_LEVEL_THRESHOLD_DEG
from slamio.datasets.rosbag_cameras import (
    camera_mounts, camera_names as names_of_cameras, per_camera, require_image_cameras, resolve_cameras,
)
from slamio.datasets.rosbag_images import BagImageTags
from slamio.datasets.rosbag_observe import sighting_observations, surveyed_tag_map, tag_map_from_tf, truth_from_bag
from slamio.datasets.rosbag_options import (
    DEFAULT_MAX_TRUTH_GAP_S, DEFAULT_SIGMA_BEARING_RAD, DEFAULT_SIGMA_HEIGHT_M, DEFAULT_SIGMA_RANGE_M,
    DEFAULT_SIGMA_TAG_YAW_RAD, ImportOptions, check_level_and_truth, check_options, corner_inputs,
    require_tag_sizes, robot_camera_transform,
)
from slamio.datasets.rosbag_read import (BagFormatError, CameraTopics, Messages, bag_paths, read_bag, read_pose_topic,
                                         read_tf_poses)
from slamio.datasets.rosbag_records import (
    TruthTrack, default_increment_covariance, increment_covariance_from_poses, interpolate_se2, observations_by_pose,
    pose_records, start_pose_of, thinned,
)
from slamio.log import Header, Observation, Record, TruthLandmark
from slamio.log.read import check_records
from slamio.se3 import quaternion_from_rotation, rotation_from_quaternion, yaw_from_quaternion

__all__ = [
    "APRILTAG_DETECTION_ARRAY_MSG",
    "APRILTAG_DETECTION_MSG",
    "BagFormatError",
    "DETECTIONS_TOPIC",
    "LANDMARKS_TOPIC",
    "MessageFactory",
    "ODOMETRY_TOPIC",
    "RUN_LOG_TOPIC",
    "TRUTH_TOPIC",
    "T_ROBOT_OPTICAL",
    "apriltag_typestore",
    "default_increment_covariance",
    "export_rosbag",
    "import_rosbag",
    "increment_covariance_from_poses",
    "interpolate_se2",
    "quaternion_from_rotation",
    "rotation_from_quaternion",
    "yaw_from_quaternion",
]


def import_rosbag(
    path: str | os.PathLike[str],
    *,
    odom_topic: str | None = None,
    detections_topic: str | list[str] | None = None,
    tag_pose_topic: str | None = None,
    truth_topic: str | None = None,
    T_robot_camera: Any = None,
    tag_normal_axis: str = "+z",
    sigma_range_m: float = DEFAULT_SIGMA_RANGE_M,
    sigma_bearing_rad: float = DEFAULT_SIGMA_BEARING_RAD,
    sigma_tag_yaw_rad: float = DEFAULT_SIGMA_TAG_YAW_RAD,
    with_height: bool = False,
    sigma_height_m: float = DEFAULT_SIGMA_HEIGHT_M,
    odometry_noise: CommandOdometryNoise | None = None,
    covariance_from_message: bool = True,
    odom_min_period_s: float = 0.0,
    interpolate_detections: bool = True,
    use_header_stamps: bool = True,
    max_truth_gap_s: float = DEFAULT_MAX_TRUTH_GAP_S,
    start_from: str = "odom",
    standard_topics_only: bool = False,
    camera: Any = None,
    camera_info_topic: str | list[str | None] | None = None,
    tag_sizes: Any = None,
    tag_size_m: float | None = None,
    pixel_sigma_px: float | None = None,
    max_reprojection_px: float = DEFAULT_MAX_REPROJECTION_PX,
    level: str = "auto",
    level_threshold_deg: float = DEFAULT_LEVEL_THRESHOLD_DEG,
    truth_bag: str | os.PathLike[str] | None = None,
    truth_pose_of: str = "body",
    truth_frames: tuple[str, str] | None = None,
    image_topic: str | list[str] | None = None,
    camera_names: list[str] | None = None,
    tag_family: str = "tag36h11",
    progress: Callable[[int, int, str], None] | None = None,
) -> tuple[Header, list[Record]]:
    """Convert a ROS 1 ``.bag`` file or a ROS 2 bag folder into a run-log header and records.

    A bag written by :func:`export_rosbag` (it has ``/fgslam/run_log``) gives back the exported
    log exactly, unless ``standard_topics_only``. Otherwise ``odom_topic`` is required; every
    conversion rule and option: the module docstring ("Options of a rig's own bag": corners,
    images, several cameras, levelling, truth). Write the result with ``write_log``.

    Raises :class:`BagFormatError` naming the topic (and message) and what was expected,
    :class:`~slamio.errors.FgslamError` for an unreadable bag or a bad option. What was
    assumed is in ``header.source["warnings"]``."""
    _rosbags()
    bag, ros_version = bag_paths(path := os.fspath(path))
    check_options(tag_normal_axis, start_from, truth_topic or (truth_frames and ":".join(truth_frames)),
                  odom_min_period_s, sigma_range_m=sigma_range_m, sigma_bearing_rad=sigma_bearing_rad,
                  sigma_tag_yaw_rad=sigma_tag_yaw_rad, sigma_height_m=sigma_height_m, max_truth_gap_s=max_truth_gap_s)
    check_level_and_truth(level, truth_pose_of, truth_bag, truth_topic, truth_frames)
    topics = _camera_topics(detections_topic, image_topic, camera_info_topic)
    warnings: list[str] = []
    images = _ImageStep(path, camera, tag_sizes, tag_size_m, tag_family, progress, warnings)
    messages = read_bag(path, bag, ros_version, odom_topic, topics, tag_pose_topic,
                        truth_topic if truth_bag is None else None, use_header_stamps, standard_topics_only,
                        images, find_images=tag_sizes is not None or tag_size_m is not None)
    if not isinstance(messages, Messages):  # a bag fgslam exported: its run log, as it was
        return messages
    if not messages.odometry:
        raise BagFormatError(path, odom_topic, "has no messages; expected nav_msgs/Odometry poses of the robot")
    names, cameras, mounts, mount_sources = _rig(path, messages, images, camera, camera_names, T_robot_camera,
                                                 warnings)
    pixel_sigma_px = corner_inputs(path, messages, cameras or [None], tag_sizes, tag_size_m, pixel_sigma_px, warnings)
    _warn_unused_images(messages, warnings)
    o = ImportOptions(
        path, ros_version, odom_topic, messages.cameras, tag_pose_topic, truth_topic,  # type: ignore[arg-type]
        tuple(mounts), tag_normal_axis, sigma_range_m, sigma_bearing_rad, sigma_tag_yaw_rad,
        with_height, sigma_height_m, odometry_noise if odometry_noise is not None else CommandOdometryNoise(),
        covariance_from_message, odom_min_period_s, interpolate_detections, max_truth_gap_s, start_from,
        tuple(cameras or [None]), tag_sizes, tag_size_m, pixel_sigma_px or 1.0, max_reprojection_px,
        tuple(mount_sources), names,
    )
    header, records = _convert(o, messages, warnings, level, level_threshold_deg, truth_bag, truth_pose_of, truth_frames)
    header.source.update({"images": images.tags.summary()} if images.tags is not None else {})
    return header, records


def _as_tuple(topics) -> tuple[str, ...]:
    return () if topics is None else (topics,) if isinstance(topics, str) else tuple(topics)


def _camera_topics(detections_topic, image_topic, camera_info_topic) -> CameraTopics:
    detections, images = _as_tuple(detections_topic), _as_tuple(image_topic)
    infos = per_camera(camera_info_topic, len(detections + images), "camera_info topic", lambda v: isinstance(v, str))
    return CameraTopics(detections, images, tuple(infos))


def _rig(path: str, messages: Messages, images: "_ImageStep", camera, camera_names, T_robot_camera,
         warnings: list[str]):
    """(names, calibrations, mounts, where each mount came from) of the cameras read
    (:mod:`slamio.datasets.rosbag_cameras`)."""
    names = names_of_cameras(messages.cameras, camera_names)
    cameras = images.cameras if images.cameras is not None else resolve_cameras(
        path, messages.cameras, per_camera(camera, len(messages.cameras.topics), "camera", _is_camera),
        messages.camera_infos, warnings)
    given_mounts = [None if T is None else robot_camera_transform(T)
                    for T in per_camera(T_robot_camera, len(names), "camera pose", _is_matrix)]
    mounts, sources = camera_mounts(given_mounts, messages, names, warnings)
    return names, cameras, mounts, sources


def _is_matrix(value) -> bool:
    return isinstance(value, np.ndarray) or (isinstance(value, (list, tuple)) and len(value) == 4
                                             and all(isinstance(row, (list, tuple, np.ndarray)) for row in value))


def _is_camera(value) -> bool:
    return hasattr(value, "K") and hasattr(value, "width_px")


def _warn_unused_images(messages: Messages, warnings: list[str]) -> None:
    if messages.unused_images and not messages.cameras.topics and not messages.sightings:
        warnings.append(f"images: the bag has image topics ({', '.join(messages.unused_images)}) and no detections "
                        "were read: give --image-topic T and --tag-size M (or --tags FILE) to detect tags in them")


class _ImageStep:
    """What :func:`~slamio.datasets.rosbag_read.read_bag` calls once the camera topics and their
    CameraInfo are known: the cameras resolved, tag sizes checked, and the image detector made."""

    def __init__(self, path, camera, tag_sizes, tag_size_m, family, progress, warnings):
        self.path, self.camera, self.tag_sizes, self.tag_size_m = path, camera, tag_sizes, tag_size_m
        self.family, self.progress, self.warnings = family, progress, warnings
        self.cameras: list | None = None
        self.tags: BagImageTags | None = None

    def __call__(self, topics: CameraTopics, infos: dict, reader) -> BagImageTags:
        given = per_camera(self.camera, len(topics.topics), "camera", _is_camera)
        self.cameras = resolve_cameras(self.path, topics, given, infos, self.warnings)
        for topic in topics.images:
            require_tag_sizes(self.path, topic, self.tag_sizes, self.tag_size_m, "images to detect tags in")
        total = sum(c.msgcount for c in reader.connections if c.topic in topics.images)
        self.tags = BagImageTags(self.path, require_image_cameras(self.path, topics, self.cameras), self.family,
                                 total, self.progress)
        return self.tags




def _convert(o: ImportOptions, messages: Messages, warnings: list[str], level: str, level_threshold_deg: float,
             truth_bag, truth_pose_of: str, truth_frames=None) -> tuple[Header, list[Record]]:
    """:func:`import_rosbag` once the bag is read and the options checked: level the
    odometry, place the detections, read the truth, and make the header and records."""
    attitudes, level_report = level_odometry(o, messages, level, level_threshold_deg, warnings)
    if level_report["levelled"]:
        o = dataclasses.replace(o, covariance_from_message=False)  # the messages' covariance is in the old frame
    n_odometry_messages = len(messages.odometry)
    odometry = thinned(messages.odometry, o.odom_min_period_s)
    observed = sighting_observations(o, messages, attitudes, odometry[0][0], messages.dropped)
    at_pose, inside = observations_by_pose(o, observed, [m[0] for m in odometry], messages.dropped)
    landmarks: list[TruthLandmark] = []
    if truth_frames is not None or truth_bag is not None:  # a /tf chain (this bag or the truth bag), or a topic
        poses, frame, tf = (read_tf_poses(os.fspath(truth_bag or o.path), *truth_frames) if truth_frames
                            else read_pose_topic(os.fspath(truth_bag), o.truth_topic))  # type: ignore[arg-type]
        messages.truth = truth_from_bag(poses, truth_pose_of, o.T_rc)
        landmarks = tag_map_from_tf(tf, frame)
    landmarks_from = "tf" if landmarks else None
    surveyed = getattr(o.tag_sizes, "surveyed", None)
    if not landmarks and surveyed:  # the tags file's surveyed tags, in the same map frame as a truth from TagSLAM
        landmarks, landmarks_from = surveyed_tag_map(surveyed), "tags file (surveyed poses)"
    truth = TruthTrack(messages.truth, odometry[0][0], o.max_truth_gap_s)
    start_pose = start_pose_of(o, odometry, truth)
    records, counts = pose_records(o, odometry, at_pose, inside, truth)
    n_observations = sum(isinstance(r, Observation) for r in records)
    warn_counts(o, messages, counts, n_observations, warnings)
    header = make_header(o, messages, start_pose, odometry[0][0], n_odometry_messages, counts, n_observations)
    header.source.update({"warnings": warnings, "levelling": level_report, "camera_mount": o.mount_sources[0] if len(o.mount_sources) == 1
                          else dict(zip(o.camera_names, o.mount_sources)),
                          **({"truth_bag": os.fspath(truth_bag), "truth_pose_of": truth_pose_of} if truth_bag else {}),
                          **({"truth_frames": ":".join(truth_frames), "truth_pose_of": truth_pose_of}
                             if truth_frames else {}),
                          **({"truth_landmarks": landmarks_from} if landmarks_from else {})})
    return header, list(check_records(o.path, header, [*landmarks, *records]))  # never a log the reader refuses
