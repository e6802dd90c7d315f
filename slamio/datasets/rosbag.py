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
"""

from __future__ import annotations

import bisect
import math
import os
import re
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from slamio.datasets.mrclam import CommandOdometryNoise, interpolate_pose
from slamio.datasets.rosbag_export import export_rosbag
from slamio.datasets.rosbag_messages import (
    _DETECTION_ARRAY_TYPE,
    _STRING_TYPE,
    APRILTAG_DETECTION_ARRAY_MSG,
    APRILTAG_DETECTION_MSG,
    DETECTIONS_TOPIC,
    LANDMARKS_TOPIC,
    ODOMETRY_TOPIC,
    RUN_LOG_TOPIC,
    T_ROBOT_OPTICAL,
    TRUTH_TOPIC,
    MessageFactory,
    _rosbags,
    apriltag_typestore,
    compose_jacobians,
    tag_observation_geometry,
)
from slamio.datasets.victoria_park import DatasetFormatError
from slamio.errors import FgslamError, InputFileError
from slamio.geometry import between_pose, wrap_angle
from slamio.log import (
    Header,
    LogFormatError,
    Observation,
    Odometry,
    Record,
    TruthPose,
    as_matrix3,
    read_log,
)
from slamio.log.read import check_records
from slamio.safe_input import MAX_TEXT_BYTES, check_regular
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

_ODOMETRY_TYPES = ("nav_msgs/msg/Odometry",)
_POSE_TYPES = ("geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/PoseWithCovarianceStamped")
_TRUTH_TYPES = _POSE_TYPES + _ODOMETRY_TYPES


class BagFormatError(DatasetFormatError):
    """A bag that cannot be converted: ``bag: topic T [message N]: what is wrong; what was expected``.

    ``line`` is the 1-based message number on the topic (0 when the topic as a whole is wrong).
    """

    def __init__(self, path: str, topic: str, message: str, index: int = 0):
        where = f"{path}: topic {topic}" + (f" message {index}" if index else "")
        FgslamError.__init__(self, f"{where}: {message}")
        self.path = path
        self.line = index
        self.topic = topic


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


def _bag_paths(path: str) -> tuple[Path, int]:
    p = Path(path)
    if not os.path.lexists(p):
        raise InputFileError(f"{path}: no such file or folder; give a ROS 1 .bag file or a ROS 2 bag folder")
    if p.is_dir():
        _check_bag_folder(p)
        return p, 2
    check_regular(p, "bag file")  # a FIFO would make the reader wait forever
    if p.suffix == ".bag":
        return p, 1
    if p.suffix in (".db3", ".mcap") or p.name == "metadata.yaml":
        _check_bag_folder(p.parent)
        return p.parent, 2
    raise InputFileError(
        f"{path}: not a ROS bag; give a ROS 1 .bag file or a ROS 2 bag folder (with metadata.yaml)"
    )


def _check_bag_folder(folder: Path) -> None:
    """Every entry of a ROS 2 bag folder that the reader opens is a regular file (a FIFO or
    /dev/zero linked in would make it wait or read forever), metadata.yaml of a sane size."""
    for entry in sorted(folder.iterdir()):
        if entry.name == "metadata.yaml" or entry.suffix in (".db3", ".mcap", ".zstd"):
            check_regular(entry, "bag file")
    metadata = folder / "metadata.yaml"
    if metadata.is_file() and metadata.stat().st_size > MAX_TEXT_BYTES:
        raise InputFileError(f"{metadata}: {metadata.stat().st_size} bytes, larger than any bag's metadata; "
                             "is it the right folder?")


def _stamp_ns(msg, bag_time_ns: int, use_header_stamps: bool) -> int:
    header = getattr(msg, "header", None)
    if use_header_stamps and header is not None:
        ns = int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)
        if ns != 0:
            return ns
    return int(bag_time_ns)


def _pose_of(msg):
    """geometry_msgs/Pose inside a PoseStamped, PoseWithCovarianceStamped or Odometry."""
    pose = msg.pose
    return pose.pose if hasattr(pose, "pose") else pose


def _planar(pose_msg) -> tuple[float, float, float]:
    q = pose_msg.orientation
    return float(pose_msg.position.x), float(pose_msg.position.y), yaw_from_quaternion(q.x, q.y, q.z, q.w)


def _topics_of_type(topics, accepted) -> list[str]:
    return sorted(name for name, info in topics.items() if info.msgtype in accepted)


def _check_topic(path: str, topics, topic: str, accepted: tuple[str, ...], what: str) -> None:
    if topic not in topics:
        candidates = _topics_of_type(topics, accepted)
        hint = f"topics of that type here: {', '.join(candidates)}" if candidates else f"the bag's topics: {', '.join(sorted(topics)) or '(none)'}"
        raise BagFormatError(path, topic, f"not in the bag; expected {what} ({' or '.join(accepted)}); {hint}")
    msgtype = topics[topic].msgtype
    if msgtype not in accepted:
        raise BagFormatError(path, topic, f"has type {msgtype}, expected {what} ({' or '.join(accepted)})")


def _read_run_log(path: str, reader, connections) -> tuple[Header, list[Record]]:
    lines: list[str] = []
    for connection, _, raw in reader.messages(connections=connections):
        msg = reader.deserialize(raw, connection.msgtype)
        lines.append(msg.data)
    if not lines:
        raise BagFormatError(path, RUN_LOG_TOPIC, "has no messages; expected the run log's header line first")
    with tempfile.TemporaryDirectory() as tmp:
        log_path = os.path.join(tmp, "run_log.jsonl")
        with open(log_path, "w", encoding="utf-8") as f:
            for line in lines:
                f.write(line + "\n")
        try:
            log = read_log(log_path)
        except LogFormatError as exc:
            message = str(exc)[len(f"{exc.path}:{exc.line}: "):]
            raise BagFormatError(path, RUN_LOG_TOPIC, f"{message} (each message is one run-log line)", exc.line) from None
    return log.header, list(log.records)


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


def _checked_topics(path: str, topics, odom_topic: str, detections_topic: str | None, tag_pose_topic: str | None,
                    truth_topic: str | None) -> dict[str, int]:
    """Check that every topic asked for is in the bag with a type we read; the tag pose
    topics found under ``tag_pose_topic`` with their tag ids."""
    _check_topic(path, topics, odom_topic, _ODOMETRY_TYPES, "the robot's odometry")
    if detections_topic is not None:
        # any package's AprilTagDetectionArray with apriltag_ros's fields (forks add fields)
        msgtype = topics[detections_topic].msgtype if detections_topic in topics else None
        accepted = (msgtype,) if msgtype and msgtype.endswith("/AprilTagDetectionArray") else (_DETECTION_ARRAY_TYPE,)
        _check_topic(path, topics, detections_topic, accepted, "tag detections")
    tag_topics: dict[str, int] = {}
    if tag_pose_topic is not None:
        pattern = re.compile(re.escape(tag_pose_topic) + r"\D*?(\d+)\Z")
        for name in sorted(topics):
            m = pattern.match(name)
            if m:
                _check_topic(path, topics, name, _POSE_TYPES, "one tag's pose in the camera frame")
                tag_topics[name] = int(m.group(1))
        if not tag_topics:
            raise BagFormatError(
                path, tag_pose_topic + "<id>",
                "no topic starts with this prefix and ends in a tag id; expected one "
                f"geometry_msgs/PoseStamped topic per tag such as {tag_pose_topic}0; the bag's topics: "
                f"{', '.join(sorted(topics))}",
            )
    if truth_topic is not None:
        _check_topic(path, topics, truth_topic, _TRUTH_TYPES, "ground-truth poses")
    named = {"odometry": odom_topic, "detections": detections_topic, "truth": truth_topic}
    given = [(role, topic) for role, topic in named.items() if topic is not None]
    for i, (role, topic) in enumerate(given):
        for other, same in given[i + 1:]:
            if same == topic:
                raise FgslamError(
                    f"{path}: {topic} is named as both the {role} topic and the {other} topic; each topic "
                    "is read as one thing: name a different topic for one of them"
                )
    return tag_topics


@dataclass
class _Messages:
    """What a bag's topics hold, in time order (stamps in ns)."""

    odometry: list[tuple[int, tuple[float, float, float], np.ndarray]]  # (stamp, pose, 3×3 covariance of x, y, yaw)
    truth: list[tuple[int, tuple[float, float, float]]]
    sightings: list[tuple[int, int, Any, Any]]  # (stamp, tag id, position, quaternion) in the camera frame
    dropped: dict[str, int]


def _read_messages(path: str, reader, odom_topic: str, detections_topic: str | None, truth_topic: str | None,
                   tag_topics: dict[str, int], use_header_stamps: bool) -> _Messages:
    """Decode every message of the topics used; a message that cannot be used is a
    :class:`BagFormatError` naming its topic and index."""
    wanted = {odom_topic, detections_topic, truth_topic, *tag_topics} - {None}
    connections = [c for c in reader.connections if c.topic in wanted]
    odometry: list[tuple[int, tuple[float, float, float], np.ndarray]] = []
    truth: list[tuple[int, tuple[float, float, float]]] = []
    sightings: list[tuple[int, int, Any, Any]] = []  # (stamp, tag id, position, quaternion)
    dropped = {"tag_bundles": 0, "zero_range": 0, "before_first_odometry": 0, "after_last_odometry": 0}
    counts = {t: 0 for t in wanted}
    for connection, bag_time, raw in reader.messages(connections=connections):
        topic = connection.topic
        counts[topic] += 1
        index = counts[topic]
        try:
            msg = reader.deserialize(raw, connection.msgtype)
        except Exception as exc:
            raise BagFormatError(path, topic, f"cannot be decoded as {connection.msgtype} ({exc})", index) from None
        stamp = _stamp_ns(msg, bag_time, use_header_stamps)
        if topic == odom_topic:
            pose = _planar(msg.pose.pose)
            C = np.asarray(msg.pose.covariance, dtype=float).reshape(6, 6)[np.ix_((0, 1, 5), (0, 1, 5))]
            if not all(math.isfinite(v) for v in pose):
                raise BagFormatError(path, topic, f"pose {pose} is not finite", index)
            odometry.append((stamp, pose, C))
        elif topic == truth_topic:
            truth.append((stamp, _planar(_pose_of(msg))))
        elif topic == detections_topic:
            detections = getattr(msg, "detections", None)
            if detections is None or (detections and not hasattr(detections[0], "pose")):
                raise BagFormatError(
                    path, topic,
                    f"{connection.msgtype} has no detections[].pose; expected apriltag_ros's "
                    "AprilTagDetectionArray (id[], size[], pose). The ROS 2 apriltag_msgs detections "
                    "carry no pose (that node puts tag poses on /tf): record one PoseStamped per tag "
                    "and use tag_pose_topic",
                    index,
                )
            for d in detections:
                ids = [int(i) for i in d.id]
                if len(ids) != 1:
                    dropped["tag_bundles"] += 1
                    continue
                p = d.pose.pose.pose
                sightings.append((stamp, ids[0], (p.position.x, p.position.y, p.position.z),
                                  (p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w)))
        else:
            p = _pose_of(msg)
            sightings.append((stamp, tag_topics[topic], (p.position.x, p.position.y, p.position.z),
                              (p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w)))
    for messages in (odometry, truth, sightings):
        messages.sort(key=lambda m: m[0])
    return _Messages(odometry, truth, sightings, dropped)


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
) -> tuple[Header, list[Record]]:
    """Convert a ROS 1 ``.bag`` file or a ROS 2 bag folder into a run-log header and records.

    A bag written by :func:`export_rosbag` (it has ``/fgslam/run_log``) gives back the
    exported log exactly, whatever topics are named, unless ``standard_topics_only``.
    Otherwise ``odom_topic`` is required and the other topics are optional; see the module
    docstring for every conversion rule and option. Write the result with
    ``slamio.log.write_log``.

    Raises :class:`BagFormatError` (a :class:`DatasetFormatError`) naming the topic and
    what was expected for a missing topic, a wrong message type or an unusable message,
    and :class:`~slamio.errors.FgslamError` for an unreadable bag or a bad option.
    """
    _rosbags()
    from rosbags.highlevel import AnyReader

    path = os.fspath(path)
    bag, ros_version = _bag_paths(path)
    _check_options(tag_normal_axis, start_from, truth_topic, odom_min_period_s,
                   sigma_range_m=sigma_range_m, sigma_bearing_rad=sigma_bearing_rad,
                   sigma_tag_yaw_rad=sigma_tag_yaw_rad, sigma_height_m=sigma_height_m, max_truth_gap_s=max_truth_gap_s)
    T_rc = _robot_camera_transform(T_robot_camera)
    noise = odometry_noise if odometry_noise is not None else CommandOdometryNoise()
    normal_sign = 1.0 if tag_normal_axis == "+z" else -1.0

    try:
        reader = AnyReader([bag], default_typestore=apriltag_typestore(ros_version))
        reader.open()
    except FgslamError:
        raise
    except Exception as exc:  # rosbags raises several kinds for a damaged or foreign file
        raise InputFileError(f"{path}: cannot read as a ROS {ros_version} bag ({type(exc).__name__}: {exc})") from None
    try:
        topics = reader.topics
        if not standard_topics_only and RUN_LOG_TOPIC in topics:
            _check_topic(path, topics, RUN_LOG_TOPIC, (_STRING_TYPE,), "the run log's JSON lines")
            connections = [c for c in reader.connections if c.topic == RUN_LOG_TOPIC]
            return _read_run_log(path, reader, connections)
        if odom_topic is None:
            candidates = _topics_of_type(topics, _ODOMETRY_TYPES)
            raise BagFormatError(
                path, "(odometry)",
                f"no {RUN_LOG_TOPIC} topic (the bag was not written by fgslam export), so name the "
                f"odometry topic (nav_msgs/Odometry); candidates: {', '.join(candidates) or '(none)'}",
            )
        tag_topics = _checked_topics(path, topics, odom_topic, detections_topic, tag_pose_topic, truth_topic)
        messages = _read_messages(path, reader, odom_topic, detections_topic, truth_topic, tag_topics, use_header_stamps)
    finally:
        reader.close()

    odometry, truth, sightings, dropped = messages.odometry, messages.truth, messages.sightings, messages.dropped
    if not odometry:
        raise BagFormatError(path, odom_topic, "has no messages; expected nav_msgs/Odometry poses of the robot")
    if odom_min_period_s > 0.0:
        thinned = [odometry[0]]
        for m in odometry[1:-1]:
            if m[0] - thinned[-1][0] >= odom_min_period_s * 1e9:
                thinned.append(m)
        if len(odometry) > 1:
            thinned.append(odometry[-1])
        n_odometry_messages = len(odometry)
        odometry = thinned
    else:
        n_odometry_messages = len(odometry)

    t0 = odometry[0][0]
    odo_times = [m[0] for m in odometry]
    truth_times_s = [(t - t0) / 1e9 for t, _ in truth]
    truth_poses = np.array([p for _, p in truth]) if truth else np.zeros((0, 3))

    def stamp_s(t_ns: int) -> float:
        return (t_ns - t0) / 1e9

    # observations, grouped by the pose they belong to
    def observation(t_ns: int, tag_id: int, position, quaternion) -> Observation | None:
        range_m, bearing_rad, yaw, height = tag_observation_geometry(position, quaternion, T_rc, normal_sign)
        if not range_m > 0.0:
            dropped["zero_range"] += 1
            return None
        return Observation(
            stamp_s(t_ns), tag_id, range_m, bearing_rad, sigma_range_m, sigma_bearing_rad,
            height_m=height if with_height else None,
            sigma_height_m=sigma_height_m if with_height else None,
            tag_yaw_rad=yaw, sigma_tag_yaw_rad=sigma_tag_yaw_rad if yaw is not None else None,
        )

    at_pose: dict[int, list[Observation]] = {}  # odometry index -> observations at that pose
    inside: dict[int, dict[int, list[Observation]]] = {}  # interval end index -> {time: observations}
    for t, tag_id, position, quaternion in sightings:
        if t < odo_times[0]:
            dropped["before_first_odometry"] += 1
            continue
        if t > odo_times[-1]:
            dropped["after_last_odometry"] += 1
            continue
        obs = observation(t, tag_id, position, quaternion)
        if obs is None:
            continue
        k = bisect.bisect_right(odo_times, t) - 1
        if odo_times[k] == t or not interpolate_detections:
            at_pose.setdefault(k, []).append(obs)
        else:
            inside.setdefault(k + 1, {}).setdefault(t, []).append(obs)

    # start pose
    if start_from == "odom":
        start_pose = odometry[0][1]
    elif start_from == "zero":
        start_pose = (0.0, 0.0, 0.0)
    else:
        start_pose = interpolate_pose(truth_times_s, truth_poses, 0.0, max_truth_gap_s) if truth else None
        if start_pose is None:
            raise BagFormatError(path, truth_topic, "has no ground truth at the first odometry message, so start_from='truth' cannot be used")

    records: list[Record] = []
    n_truth = 0
    covariance_sources = {"from_message": 0, "default_model": 0}

    def add_pose_records(t_ns: int, observations: list[Observation]) -> None:
        nonlocal n_truth
        if truth:
            tp = interpolate_pose(truth_times_s, truth_poses, stamp_s(t_ns), max_truth_gap_s)
            if tp is not None:
                records.append(TruthPose(stamp_s(t_ns), *tp))
                n_truth += 1
        records.extend(observations)

    add_pose_records(t0, at_pose.get(0, []))
    n_poses = 1
    for i in range(1, len(odometry)):
        (ta, pa, Ca), (tb, pb, Cb) = odometry[i - 1], odometry[i]
        delta = between_pose(pa, pb)
        Q = increment_covariance_from_poses(Ca, Cb, pa, delta) if covariance_from_message else None
        if Q is None:
            Q = default_increment_covariance(delta, (tb - ta) * 1e-9, noise)
            covariance_sources["default_model"] += 1
        else:
            covariance_sources["from_message"] += 1
        # poses inside the interval (detections between two odometry messages), then the end
        nodes = [(t, interpolate_se2(pa, pb, (t - ta) / (tb - ta)), obs) for t, obs in sorted(inside.get(i, {}).items())]
        nodes.append((tb, pb, at_pose.get(i, [])))
        previous_t, previous_pose = ta, pa
        for t, pose, obs in nodes:
            fraction = (t - previous_t) / (tb - ta) if tb > ta else 1.0
            d = between_pose(previous_pose, pose)
            records.append(Odometry(stamp_s(t), d[0], d[1], d[2], as_matrix3(Q * fraction)))
            add_pose_records(t, obs)
            previous_t, previous_pose = t, pose
            n_poses += 1

    n_observations = sum(isinstance(r, Observation) for r in records)
    header = Header(
        stamp_s=0.0,
        start_pose=tuple(float(v) for v in start_pose),  # type: ignore[arg-type]
        start_sigma=(1e-3, 1e-3, 1e-3),
        robot={"name": "robot of a ROS bag", "odometry_topic": odom_topic, "odometry_type": "nav_msgs/Odometry"},
        sensor={
            "kind": "range-bearing",
            "landmark_kind": "apriltag",
            "detections_topic": detections_topic,
            "tag_pose_topics": sorted(tag_topics),
            "T_robot_camera": [[float(v) for v in row] for row in T_rc],
            "tag_normal_axis": tag_normal_axis,
        },
        noise={
            "odometry": {
                "model": (
                    "from the growth of the messages' (x, y, yaw) pose covariance, Q = J2^-1 (P_k - J1 P_k-1 J1^T) "
                    "J2^-T, when positive definite; otherwise slamio.datasets.mrclam.CommandOdometryNoise "
                    "with ds = |(dx, dy)|, dtheta = |dtheta|, dt = time between messages (>= 1 ms); "
                    "split in proportion to time where a detection adds a pose"
                ),
                "covariance_from_message": covariance_from_message,
                "default_model": dict(noise.__dict__),
            },
            "observation": {
                "model": "constant sigmas (options of the importer); the detections' covariance is ignored",
                "sigma_range_m": sigma_range_m,
                "sigma_bearing_rad": sigma_bearing_rad,
                "sigma_tag_yaw_rad": sigma_tag_yaw_rad,
                **({"sigma_height_m": sigma_height_m} if with_height else {}),
            },
        },
        source={
            "dataset": "rosbag",
            "bag": path,
            "ros_version": ros_version,
            "converted_by": "fgslam import rosbag",
            "topics": {"odometry": odom_topic, "detections": detections_topic, "tag_pose_prefix": tag_pose_topic, "truth": truth_topic},
            "time_origin_ns": t0,
            "stamps": "seconds since the first odometry message (header stamps, or bag time when zero)",
            "start_from": start_from,
            "odometry_messages": n_odometry_messages,
            "odometry_min_period_s": odom_min_period_s,
            "odometry_covariance": covariance_sources,
            "poses": n_poses,
            "poses_with_truth": n_truth,
            "observations": n_observations,
            "interpolate_detections": interpolate_detections,
            "dropped": dropped,
        },
    )
    return header, list(check_records(path, header, records))  # never a log the reader refuses
