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
"""

from __future__ import annotations

import bisect
import dataclasses
import math
import os
from dataclasses import dataclass
from typing import Any

import numpy as np

from slamio.datasets.mrclam_motion import CommandOdometryNoise, interpolate_pose
from slamio.datasets.rosbag_export import export_rosbag
from slamio.datasets.rosbag_messages import (
    APRILTAG_DETECTION_ARRAY_MSG, APRILTAG_DETECTION_MSG, DETECTIONS_TOPIC, LANDMARKS_TOPIC, ODOMETRY_TOPIC,
    RUN_LOG_TOPIC, T_ROBOT_OPTICAL, TRUTH_TOPIC, MessageFactory, _rosbags, apriltag_typestore, compose_jacobians,
)
from slamio.datasets.rosbag_corners import DEFAULT_MAX_REPROJECTION_PX
from slamio.datasets.rosbag_level import DEFAULT_LEVEL_THRESHOLD_DEG, LEVEL_MODES, Attitudes, levelling_rotation, out_of_plane
from slamio.datasets.rosbag_observe import camera_mount, sighting_observations, tag_map_from_tf, truth_from_bag
from slamio.datasets.rosbag_read import (CORNERS_TYPE, BagFormatError, Messages, bag_paths, read_bag, read_pose_topic,
                                         read_tf_poses)
from slamio.errors import FgslamError
from slamio.geometry import between_pose, wrap_angle
from slamio.log import Header, Observation, Odometry, Record, TruthLandmark, TruthPose, as_matrix3
from slamio.log.mount import camera_mount_fields
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
    "export_rosbag",
    "import_rosbag",
    "quaternion_from_rotation",
    "rotation_from_quaternion",
    "yaw_from_quaternion",
]

DEFAULT_SIGMA_RANGE_M = 0.05
DEFAULT_SIGMA_BEARING_RAD = 0.02
DEFAULT_SIGMA_TAG_YAW_RAD = 0.1
DEFAULT_SIGMA_HEIGHT_M = 0.05
DEFAULT_MAX_TRUTH_GAP_S = 0.5
#: The default model's shortest time per increment (keeps duplicate stamps positive definite).
MIN_INCREMENT_DT_S = 1e-3

# --------------------------------------------------------------------------- pure maths


def increment_covariance_from_poses(P_prev: np.ndarray, P_next: np.ndarray, pose_prev, increment) -> np.ndarray | None:
    """The increment covariance that grows ``P_prev`` into ``P_next``, or None if not SPD.

    Inverts the first-order propagation ``P_next = J₁ P_prev J₁ᵀ + J₂ Q J₂ᵀ``.
    """
    J1, J2 = compose_jacobians(pose_prev, increment)
    J2_inv = J2.T  # a rotation
    Q = J2_inv @ (P_next - J1 @ P_prev @ J1.T) @ J2_inv.T
    Q = 0.5 * (Q + Q.T)
    try:
        np.linalg.cholesky(Q)
    except np.linalg.LinAlgError:
        return None
    if not np.all(np.isfinite(Q)):
        return None
    return Q


def default_increment_covariance(increment, dt_s: float, noise: CommandOdometryNoise) -> np.ndarray:
    """The default model's covariance of one increment (see the module docstring)."""
    return noise.stretch_covariance(math.hypot(increment[0], increment[1]), increment[2], max(dt_s, MIN_INCREMENT_DT_S))


def interpolate_se2(pose_a, pose_b, fraction: float) -> tuple[float, float, float]:
    """Linear in x, y; heading along the shorter arc."""
    return (
        pose_a[0] + fraction * (pose_b[0] - pose_a[0]),
        pose_a[1] + fraction * (pose_b[1] - pose_a[1]),
        float(wrap_angle(pose_a[2] + fraction * wrap_angle(pose_b[2] - pose_a[2]))),
    )

# --------------------------------------------------------------------------- import

def _check_options(tag_normal_axis: str, start_from: str, truth_topic: str | None, odom_min_period_s: float,
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


def _robot_camera_transform(T_robot_camera: Any) -> np.ndarray:
    """The camera's pose on the robot as a checked 4×4 (default: :data:`T_ROBOT_OPTICAL`)."""
    T_rc = T_ROBOT_OPTICAL.copy() if T_robot_camera is None else np.asarray(T_robot_camera, dtype=float)
    if T_rc.shape != (4, 4) or not np.allclose(T_rc[:3, :3] @ T_rc[:3, :3].T, np.eye(3), atol=1e-6) \
            or not np.allclose(T_rc[3], [0, 0, 0, 1]) or np.linalg.det(T_rc[:3, :3]) < 0:
        raise FgslamError("T_robot_camera must be a 4x4 rigid transform (orthonormal rotation, det +1, last row 0 0 0 1)")
    return T_rc



def import_rosbag(
    path: str | os.PathLike[str],
    *,
    odom_topic: str | None = None,
    detections_topic: str | None = None,
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
    camera_info_topic: str | None = None,
    tag_sizes: Any = None,
    tag_size_m: float | None = None,
    pixel_sigma_px: float | None = None,
    max_reprojection_px: float = DEFAULT_MAX_REPROJECTION_PX,
    level: str = "auto",
    level_threshold_deg: float = DEFAULT_LEVEL_THRESHOLD_DEG,
    truth_bag: str | os.PathLike[str] | None = None,
    truth_pose_of: str = "body",
    truth_frames: tuple[str, str] | None = None,
) -> tuple[Header, list[Record]]:
    """Convert a ROS 1 ``.bag`` file or a ROS 2 bag folder into a run-log header and records.

    A bag written by :func:`export_rosbag` (it has ``/fgslam/run_log``) gives back the
    exported log exactly, whatever topics are named, unless ``standard_topics_only``.
    Otherwise ``odom_topic`` is required and the other topics are optional; see the module
    docstring for every conversion rule and option. Write the result with ``write_log``.

    Raises :class:`BagFormatError` naming the topic and what was expected (a missing topic,
    a wrong message type, an unusable message), :class:`~slamio.errors.FgslamError` for an
    unreadable bag or a bad option.

    Tag corners, levelling, truth from a second bag or /tf: the module docstring's "Options
    of a rig's own bag". What was assumed is in ``header.source["warnings"]``.
    """
    _rosbags()
    path = os.fspath(path)
    bag, ros_version = bag_paths(path)
    _check_options(tag_normal_axis, start_from, truth_topic or (truth_frames and ":".join(truth_frames)),
                   odom_min_period_s,
                   sigma_range_m=sigma_range_m, sigma_bearing_rad=sigma_bearing_rad,
                   sigma_tag_yaw_rad=sigma_tag_yaw_rad, sigma_height_m=sigma_height_m, max_truth_gap_s=max_truth_gap_s)
    _check_level_and_truth(level, truth_pose_of, truth_bag, truth_topic, truth_frames)
    messages = read_bag(path, bag, ros_version, odom_topic, detections_topic, tag_pose_topic,
                        truth_topic if truth_bag is None else None, use_header_stamps, standard_topics_only,
                        camera_info_topic)
    if not isinstance(messages, Messages):  # a bag fgslam exported: its run log, as it was
        return messages
    if not messages.odometry:
        raise BagFormatError(path, odom_topic, "has no messages; expected nav_msgs/Odometry poses of the robot")
    warnings: list[str] = []
    T_rc, mount_source = camera_mount(None if T_robot_camera is None else _robot_camera_transform(T_robot_camera),
                                      messages.tf_static, messages.body_frame, messages.detections_frame, warnings)
    camera, pixel_sigma_px = _corner_inputs(path, detections_topic, messages, camera, camera_info_topic, tag_sizes,
                                            tag_size_m, pixel_sigma_px, warnings)
    o = _Options(
        path, ros_version, odom_topic, detections_topic, tag_pose_topic, truth_topic,  # type: ignore[arg-type]
        T_rc, tag_normal_axis, sigma_range_m, sigma_bearing_rad, sigma_tag_yaw_rad,
        with_height, sigma_height_m, odometry_noise if odometry_noise is not None else CommandOdometryNoise(),
        covariance_from_message, odom_min_period_s, interpolate_detections, max_truth_gap_s, start_from,
        camera, tag_sizes, tag_size_m, pixel_sigma_px or 1.0, max_reprojection_px, mount_source,
    )
    return _convert(o, messages, warnings, level, level_threshold_deg, truth_bag, truth_pose_of, truth_frames)


def _check_level_and_truth(level: str, truth_pose_of: str, truth_bag, truth_topic, truth_frames=None) -> None:
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


def _convert(o: "_Options", messages: Messages, warnings: list[str], level: str, level_threshold_deg: float,
             truth_bag, truth_pose_of: str, truth_frames=None) -> tuple[Header, list[Record]]:
    """:func:`import_rosbag` once the bag is read and the options checked: level the
    odometry, place the detections, read the truth, and make the header and records."""
    attitudes, level_report = _level(o, messages, level, level_threshold_deg, warnings)
    if level_report["levelled"]:
        o = dataclasses.replace(o, covariance_from_message=False)  # the messages' covariance is in the old frame
    n_odometry_messages = len(messages.odometry)
    odometry = _thinned(messages.odometry, o.odom_min_period_s)
    observed = sighting_observations(o, messages, attitudes, odometry[0][0], messages.dropped)
    at_pose, inside = _observations_by_pose(o, observed, [m[0] for m in odometry], messages.dropped)
    landmarks: list[TruthLandmark] = []
    if truth_frames is not None or truth_bag is not None:  # a /tf chain (this bag or the truth bag), or a topic
        poses, frame, tf = (read_tf_poses(os.fspath(truth_bag or o.path), *truth_frames) if truth_frames
                            else read_pose_topic(os.fspath(truth_bag), o.truth_topic))  # type: ignore[arg-type]
        messages.truth = truth_from_bag(poses, truth_pose_of, o.T_rc)
        landmarks = tag_map_from_tf(tf, frame)
    truth = _Truth(messages.truth, odometry[0][0], o.max_truth_gap_s)
    start_pose = _start_pose(o, odometry, truth)
    records, counts = _pose_records(o, odometry, at_pose, inside, truth)
    n_observations = sum(isinstance(r, Observation) for r in records)
    _warn_counts(o, messages, counts, n_observations, warnings)
    header = _header(o, messages, start_pose, odometry[0][0], n_odometry_messages, counts, n_observations)
    header.source.update({"warnings": warnings, "levelling": level_report, "camera_mount": o.mount_source,
                          **({"truth_bag": os.fspath(truth_bag), "truth_pose_of": truth_pose_of} if truth_bag else {}),
                          **({"truth_frames": ":".join(truth_frames), "truth_pose_of": truth_pose_of}
                             if truth_frames else {})})
    return header, list(check_records(o.path, header, [*landmarks, *records]))  # never a log the reader refuses


@dataclass(frozen=True)
class _Options:
    """:func:`import_rosbag`'s options, checked, as the conversion uses them."""

    path: str
    ros_version: int
    odom_topic: str
    detections_topic: str | None
    tag_pose_topic: str | None
    truth_topic: str | None
    T_rc: np.ndarray
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
    camera: Any = None
    tag_sizes: Any = None
    tag_size_m: float | None = None
    pixel_sigma_px: float = 1.0
    max_reprojection_px: float = DEFAULT_MAX_REPROJECTION_PX
    mount_source: str = ""

    def tag_size_of(self, tag_id: int) -> float | None:
        listed = self.tag_sizes.sizes_m.get(tag_id) if self.tag_sizes is not None else None
        if listed is not None:
            return listed
        if self.tag_size_m is not None:
            return self.tag_size_m
        return self.tag_sizes.default_size_m if self.tag_sizes is not None else None


def _thinned(odometry: list, min_period_s: float) -> list:
    """The odometry messages at least ``min_period_s`` apart (the first and last always kept)."""
    if not min_period_s > 0.0:
        return odometry
    thinned = [odometry[0]]
    for m in odometry[1:-1]:
        if m[0] - thinned[-1][0] >= min_period_s * 1e9:
            thinned.append(m)
    if len(odometry) > 1:
        thinned.append(odometry[-1])
    return thinned


def _observations_by_pose(o: _Options, observed: list, odo_times: list[int], dropped: dict[str, int]):
    """The observations (stamp ns, observation), grouped by the pose they belong to: ``at_pose``
    (odometry index → observations) and ``inside`` (interval end index → {time: observations})."""
    at_pose: dict[int, list[Observation]] = {}
    inside: dict[int, dict[int, list[Observation]]] = {}
    for t, obs in observed:
        if t < odo_times[0]:
            dropped["before_first_odometry"] += 1
            continue
        if t > odo_times[-1]:
            dropped["after_last_odometry"] += 1
            continue
        k = bisect.bisect_right(odo_times, t) - 1
        if odo_times[k] == t or not o.interpolate_detections:
            at_pose.setdefault(k, []).append(obs)
        else:
            inside.setdefault(k + 1, {}).setdefault(t, []).append(obs)
    return at_pose, inside


def _corner_inputs(path: str, topic: str | None, messages: Messages, camera: Any, camera_info_topic: str | None,
                   tag_sizes: Any, tag_size_m: float | None, pixel_sigma_px: float | None, warnings: list[str]):
    """The camera and the corner σ for tag-corner detections (refusing what is missing)."""
    if camera is None and messages.camera_info is not None:
        from slamio.camera.camera_files import camera_from_camera_info_message

        camera = camera_from_camera_info_message(messages.camera_info, f"{path}: topic {camera_info_topic}")
    if not messages.corners:
        return camera, pixel_sigma_px
    if camera is None:
        raise BagFormatError(path, topic, f"holds tag corners ({CORNERS_TYPE}) and no camera was given: give "
                             "--camera FILE (a Kalibr cameras.yaml or ROS camera_info YAML) or --camera-info-topic")
    if tag_sizes is None and tag_size_m is None:
        raise BagFormatError(path, topic, "holds tag corners and no tag size was given: give --tags FILE "
                             "(TagSLAM's tagslam.yaml or default_tag_size/tags) or --tag-size M")
    if pixel_sigma_px is None:
        from_file = tag_sizes.pixel_noise_px if tag_sizes is not None else None
        pixel_sigma_px = from_file if from_file is not None else 1.0
        if from_file is None:
            warnings.append("corner noise: assumed 1.0 px per corner coordinate (no --pixel-sigma, no pixel_noise in "
                            "a tags file); each tag's range, bearing and yaw sigma follow from it")
    ids = sorted({i for _, i, _ in messages.corners})
    unsized = [i for i in ids if (tag_sizes is None or i not in tag_sizes.sizes_m)]
    if unsized:
        default = tag_size_m if tag_size_m is not None else (tag_sizes.default_size_m if tag_sizes else None)
        warnings.append(f"tag size: tags {', '.join(map(str, unsized))} are not listed in a tags file; "
                        + (f"used {default:g} m for them" if default is not None else "their detections are dropped"))
    return camera, pixel_sigma_px


def _level(o: _Options, messages: Messages, level: str, threshold_deg: float, warnings: list[str]):
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


def _warn_counts(o: _Options, messages: Messages, counts: dict, n_observations: int, warnings: list[str]) -> None:
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


class _Truth:
    """The ground-truth messages, interpolated at a log stamp (None where there is none)."""

    def __init__(self, truth: list, t0: int, max_gap_s: float):
        self.any = bool(truth)
        self.times_s = [(t - t0) / 1e9 for t, _ in truth]
        self.poses = np.array([p for _, p in truth]) if truth else np.zeros((0, 3))
        self.max_gap_s = max_gap_s

    def at(self, stamp_s: float):
        return interpolate_pose(self.times_s, self.poses, stamp_s, self.max_gap_s) if self.any else None


def _start_pose(o: _Options, odometry: list, truth: _Truth) -> tuple[float, float, float]:
    if o.start_from == "odom":
        return odometry[0][1]
    if o.start_from == "zero":
        return (0.0, 0.0, 0.0)
    start_pose = truth.at(0.0)
    if start_pose is None:
        raise BagFormatError(o.path, o.truth_topic or "/tf", "has no ground truth at the first odometry message, so start_from='truth' cannot be used")
    return start_pose


def _pose_records(o: _Options, odometry: list, at_pose, inside, truth: _Truth) -> tuple[list[Record], dict[str, Any]]:
    """The records of every pose (odometry, truth, observations), and the counts of poses,
    of poses with a truth and of the increments' covariance sources."""
    t0 = odometry[0][0]
    records: list[Record] = []
    counts: dict[str, Any] = {"poses": 1, "poses_with_truth": 0,
                              "covariance": {"from_message": 0, "default_model": 0}}

    def add_pose_records(t_ns: int, observations: list[Observation]) -> None:
        tp = truth.at((t_ns - t0) / 1e9)
        if tp is not None:
            records.append(TruthPose((t_ns - t0) / 1e9, *tp))
            counts["poses_with_truth"] += 1
        records.extend(observations)

    add_pose_records(t0, at_pose.get(0, []))
    for i in range(1, len(odometry)):
        (ta, pa, Ca), (tb, pb, Cb) = odometry[i - 1], odometry[i]
        delta = between_pose(pa, pb)
        Q = increment_covariance_from_poses(Ca, Cb, pa, delta) if o.covariance_from_message else None
        if Q is None:
            Q = default_increment_covariance(delta, (tb - ta) * 1e-9, o.noise)
            counts["covariance"]["default_model"] += 1
        else:
            counts["covariance"]["from_message"] += 1
        # poses inside the interval (detections between two odometry messages), then the end
        nodes = [(t, interpolate_se2(pa, pb, (t - ta) / (tb - ta)), obs) for t, obs in sorted(inside.get(i, {}).items())]
        nodes.append((tb, pb, at_pose.get(i, [])))
        previous_t, previous_pose = ta, pa
        for t, pose, obs in nodes:
            fraction = (t - previous_t) / (tb - ta) if tb > ta else 1.0
            d = between_pose(previous_pose, pose)
            records.append(Odometry((t - t0) / 1e9, d[0], d[1], d[2], as_matrix3(Q * fraction)))
            add_pose_records(t, obs)
            previous_t, previous_pose = t, pose
            counts["poses"] += 1
    return records, counts


def _header(o: _Options, messages: Messages, start_pose, t0: int, n_odometry_messages: int,
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
            **camera_mount_fields(o.T_rc),  # each tag placed through the camera's mount: at the robot's centre
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
            "observation": _corner_noise(o, messages) if messages.corners else {
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


def _corner_noise(o: _Options, messages: Messages) -> dict:
    return {
        "model": "tag corners: each corner coordinate known to pixel_sigma_px; the pose's covariance from the "
                 "corner residuals' Jacobian through the lens model, propagated to range, bearing, tag yaw and "
                 "height (slamio.datasets.rosbag_corners); each observation carries its own sigmas",
        "pixel_sigma_px": o.pixel_sigma_px,
        "max_reprojection_px": o.max_reprojection_px,
        "camera": {"name": o.camera.name, "width_px": o.camera.width_px, "height_px": o.camera.height_px,
                   "K": [[float(v) for v in row] for row in o.camera.K], "distortion_model": o.camera.distortion_model,
                   "dist_coeffs": [float(v) for v in o.camera.dist_coeffs]},
        "tag_sizes_m": {str(i): o.tag_size_of(i) for i in sorted({i for _, i, _ in messages.corners})},
    }
