"""Reading a ROS bag for :func:`slamio.datasets.rosbag.import_rosbag`: where the bag is
(:func:`bag_paths`: a ROS 1 ``.bag`` file or a ROS 2 folder, every file in it regular), the
topics checked against the message types read, and every message of them decoded into
planar poses and tag sightings (:func:`read_bag`, :class:`Messages`). A bag that cannot be
used is a :class:`BagFormatError` naming the topic and message.
"""

from __future__ import annotations

import math
import os
import re
import tempfile
import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from slamio.datasets.rosbag_messages import _DETECTION_ARRAY_TYPE, _STRING_TYPE, RUN_LOG_TOPIC, apriltag_typestore
from slamio.datasets.victoria_park import DatasetFormatError
from slamio.errors import MAX_TEXT_BYTES, FgslamError, InputFileError, check_regular
from slamio.log import Header, LogFormatError, Record, read_log
from slamio.se3 import yaw_from_quaternion

__all__ = ["BagFormatError", "CORNERS_TYPE", "CameraTopics", "IMAGE_TYPES", "Messages", "bag_paths", "read_bag",
           "read_extras", "read_pose_topic"]

_ODOMETRY_TYPES = ("nav_msgs/msg/Odometry",)
_POSE_TYPES = ("geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/PoseWithCovarianceStamped")
_TRUTH_TYPES = _POSE_TYPES + _ODOMETRY_TYPES
#: The MIT / KumarRobotics detector's messages: per tag an id and four pixel corners, no pose.
CORNERS_TYPE = "apriltag_msgs/msg/ApriltagArrayStamped"
CAMERA_INFO_TYPES = ("sensor_msgs/msg/CameraInfo",)
TF_TYPES = ("tf2_msgs/msg/TFMessage", "tf/msg/tfMessage")
IMAGE_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")


@dataclass(frozen=True)
class CameraTopics:
    """The camera topics asked for: one camera per topic, detections first then images, in the
    order given (camera k is ``topics[k]``); ``camera_info[k]`` the CameraInfo topic of camera k
    (None: the sibling ``camera_info`` of its topic's namespace, when the bag has one)."""

    detections: tuple[str, ...] = ()
    images: tuple[str, ...] = ()
    camera_info: tuple[str | None, ...] = ()

    @property
    def topics(self) -> tuple[str, ...]:
        return (*self.detections, *self.images)

    def info_topic(self, k: int) -> str | None:
        return self.camera_info[k] if k < len(self.camera_info) else None


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


def bag_paths(path: str) -> tuple[Path, int]:
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


def _pose3(pose_msg) -> tuple[tuple[float, float, float], tuple[float, float, float, float]]:
    p, q = pose_msg.position, pose_msg.orientation
    return (float(p.x), float(p.y), float(p.z)), (float(q.x), float(q.y), float(q.z), float(q.w))


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


#: Topics a camera gives: images, camera info and tag detections (with or without a pose).
_CAMERA_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage", "sensor_msgs/msg/CameraInfo",
                 CORNERS_TYPE, _DETECTION_ARRAY_TYPE)


def no_odometry_error(path: str, topics, asked: str | None) -> BagFormatError:
    """The refusal of a bag with no odometry topic (a camera-only bag): what is missing, what
    the bag has instead, and what to do."""
    camera = sorted(n for n, i in topics.items() if i.msgtype in _CAMERA_TYPES or i.msgtype.endswith("DetectionArray"))
    poses = _topics_of_type(topics, _POSE_TYPES)
    listed = ", ".join(sorted(topics)[:12]) + (" ..." if len(topics) > 12 else "") or "(none)"
    return BagFormatError(
        path, asked or "(odometry)",
        ("not in the bag, and " if asked else "") + "the bag has no odometry: no nav_msgs/msg/Odometry topic"
        + (f" (it has camera topics {', '.join(camera)}: a camera-only bag)" if camera else "")
        + f"; its topics: {listed}. The estimators need the robot's motion between camera frames as well as the "
        "landmark sightings. Record or merge the rig's odometry into the bag (wheel odometry, or a VIO such as a "
        "RealSense T265's /camera/odom/sample) and name it with --odom-topic"
        + (f"; the pose topics here ({', '.join(poses)}) are not read as odometry: republish one as "
           "nav_msgs/msg/Odometry" if poses else "")
        + ". A bag fgslam export wrote needs no topic (it carries /fgslam/run_log). Camera-only bags: "
        "docs/datasets-mrclam-rosbag.md, 'Camera-only bags'")


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



def _checked_topics(path: str, topics, odom_topic: str, cameras: CameraTopics, tag_pose_topic: str | None,
                    truth_topic: str | None) -> dict[str, int]:
    """Check that every topic asked for is in the bag with a type we read; the tag pose
    topics found under ``tag_pose_topic`` with their tag ids."""
    if odom_topic not in topics and not _topics_of_type(topics, _ODOMETRY_TYPES):
        raise no_odometry_error(path, topics, odom_topic)
    _check_topic(path, topics, odom_topic, _ODOMETRY_TYPES, "the robot's odometry")
    for detections_topic in cameras.detections:
        # any package's AprilTagDetectionArray with apriltag_ros's fields (forks add fields)
        msgtype = topics[detections_topic].msgtype if detections_topic in topics else None
        accepted = (msgtype,) if msgtype and msgtype.endswith("/AprilTagDetectionArray") else (_DETECTION_ARRAY_TYPE,)
        accepted = accepted + (CORNERS_TYPE,)
        _check_topic(path, topics, detections_topic, accepted, "tag detections")
    for image_topic in cameras.images:
        _check_topic(path, topics, image_topic, IMAGE_TYPES, "camera images")
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
    named = [("odometry", odom_topic), *(("detections", t) for t in cameras.detections),
             *(("image", t) for t in cameras.images), ("truth", truth_topic)]
    given = [(role, topic) for role, topic in named if topic is not None]
    for i, (role, topic) in enumerate(given):
        for other, same in given[i + 1:]:
            if same == topic:
                raise FgslamError(
                    f"{path}: {topic} is named as both the {role} topic and the {other} topic; each topic "
                    "is read as one thing: name a different topic for one of them"
                )
    return tag_topics


@dataclass
class Messages:
    """What a bag's topics hold, in time order (stamps in ns)."""

    odometry: list[tuple[int, tuple[float, float, float], np.ndarray]]  # (stamp, pose, 3×3 covariance of x, y, yaw)
    truth: list[tuple[int, tuple[float, float, float]]]
    sightings: list[tuple[int, int, Any, Any, int]]  # (stamp, tag id, position, quaternion in camera k's frame, k)
    dropped: dict[str, int]
    tag_topics: dict[str, int]  # tag pose topic -> tag id
    odometry_3d: list[tuple[int, Any, Any]] = dataclasses.field(default_factory=list)  # (stamp, position, quaternion)
    corners: list[tuple[int, int, np.ndarray, int]] = dataclasses.field(default_factory=list)  # (stamp, id, 4×2 px, k)
    camera_infos: dict[int, tuple[str, Any]] = dataclasses.field(default_factory=dict)  # k -> (topic, CameraInfo)
    tf_static: dict[tuple[str, str], np.ndarray] = dataclasses.field(default_factory=dict)  # (parent, child) -> 4×4
    frames: dict[int, str] = dataclasses.field(default_factory=dict)  # camera k -> its messages' header frame_id
    body_frame: str | None = None  # the odometry's child_frame_id
    cameras: CameraTopics = CameraTopics()  # the camera topics read (one camera each)
    unused_images: tuple[str, ...] = ()  # image topics the bag has and nobody asked for


def _read_messages(path: str, reader, odom_topic: str, cameras: CameraTopics, truth_topic: str | None,
                   tag_topics: dict[str, int], use_header_stamps: bool, image_corners=None) -> Messages:
    """Decode every message of the topics used; a message that cannot be used is a
    :class:`BagFormatError` naming its topic and index. ``image_corners(topic, index, msg)``
    gives the tags of an image message as (id, 4×2 corners in the MIT order)."""
    camera_of = {t: k for k, t in enumerate(cameras.topics)}
    wanted = {odom_topic, truth_topic, *camera_of, *tag_topics} - {None}
    connections = [c for c in reader.connections if c.topic in wanted]
    odometry: list[tuple[int, tuple[float, float, float], np.ndarray]] = []
    truth: list[tuple[int, tuple[float, float, float]]] = []
    sightings: list[tuple[int, int, Any, Any]] = []  # (stamp, tag id, position, quaternion)
    dropped = {"tag_bundles": 0, "zero_range": 0, "before_first_odometry": 0, "after_last_odometry": 0}
    counts = {t: 0 for t in wanted}
    odometry_3d: list = []
    corners: list = []
    body_frame = None
    frames: dict[int, str] = {}
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
            odometry_3d.append((stamp, *_pose3(msg.pose.pose)))
            body_frame = str(msg.child_frame_id)
            C = np.asarray(msg.pose.covariance, dtype=float).reshape(6, 6)[np.ix_((0, 1, 5), (0, 1, 5))]
            if not all(math.isfinite(v) for v in pose):
                raise BagFormatError(path, topic, f"pose {pose} is not finite", index)
            odometry.append((stamp, pose, C))
        elif topic == truth_topic:
            truth.append((stamp, _planar(_pose_of(msg))))
        elif topic in camera_of and connection.msgtype in IMAGE_TYPES:
            k = camera_of[topic]
            frames.setdefault(k, str(msg.header.frame_id))
            corners.extend((stamp, i, c, k) for i, c in image_corners(topic, index, msg))
        elif topic in camera_of and connection.msgtype == CORNERS_TYPE:
            k = camera_of[topic]
            frames.setdefault(k, str(msg.header.frame_id))
            for tag in msg.apriltags:
                corners.append((stamp, int(tag.id), np.array([[c.x, c.y] for c in tag.corners], dtype=float), k))
        elif topic in camera_of:
            k = camera_of[topic]
            frames.setdefault(k, str(msg.header.frame_id))
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
                                  (p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w), k))
        else:
            p = _pose_of(msg)
            sightings.append((stamp, tag_topics[topic], (p.position.x, p.position.y, p.position.z),
                              (p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w), 0))
    for messages in (odometry, truth, sightings, odometry_3d, corners):
        messages.sort(key=lambda m: m[0])
    bad = [i for i, (_, p, q) in enumerate(odometry_3d) if not np.all(np.isfinite(p + q)) or abs(np.linalg.norm(q) - 1) > 0.01]
    if bad:
        raise BagFormatError(path, odom_topic, f"orientation {odometry_3d[bad[0]][2]} is not a unit quaternion",
                             bad[0] + 1)
    return Messages(odometry, truth, sightings, dropped, tag_topics, odometry_3d, corners,
                    frames=frames, body_frame=body_frame, cameras=cameras)


def sibling_camera_info(topics, topic: str) -> str | None:
    """The ``sensor_msgs/CameraInfo`` topic next to a camera topic (``/cam1/image_raw`` or
    ``/cam1/image_raw/compressed`` → ``/cam1/camera_info``), when the bag has it."""
    parts = topic.rstrip("/").split("/")
    for cut in (1, 2):
        candidate = "/".join(parts[:-cut]) + "/camera_info"
        if len(parts) > cut and candidate in topics and topics[candidate].msgtype in CAMERA_INFO_TYPES:
            return candidate
    return None


def read_extras(path: str, reader, cameras: CameraTopics) -> tuple[dict[int, tuple[str, Any]], dict]:
    """The first ``sensor_msgs/CameraInfo`` of each camera k (its ``camera_info`` topic asked for,
    else its sibling's, :func:`sibling_camera_info`; k -> (topic, message)) and every transform on
    ``/tf_static`` (``(parent, child) -> 4×4``; empty when the bag has none)."""
    topics = reader.topics
    infos: dict[int, tuple[str, Any]] = {}
    for k, camera_topic in enumerate(cameras.topics):
        info_topic = cameras.info_topic(k)
        if info_topic is not None:
            _check_topic(path, topics, info_topic, CAMERA_INFO_TYPES, "the camera's calibration")
        else:
            info_topic = sibling_camera_info(topics, camera_topic)
        for connection, _, raw in (reader.messages(connections=[c for c in reader.connections
                                                                if c.topic == info_topic]) if info_topic else ()):
            infos[k] = (info_topic, reader.deserialize(raw, connection.msgtype))
            break
    tf: dict[tuple[str, str], np.ndarray] = {}
    connections = [c for c in reader.connections if c.topic == "/tf_static" and c.msgtype in TF_TYPES]
    for connection, _, raw in (reader.messages(connections=connections) if connections else ()):  # [] = all
        tf.update(_transforms(path, "/tf_static", reader.deserialize(raw, connection.msgtype)))
    return infos, tf


def read_pose_topic(path: str, topic: str, use_header_stamps: bool = True
                    ) -> tuple[list[tuple[int, Any, Any]], str, dict[tuple[str, str], np.ndarray]]:
    """Every pose on ``topic`` (Odometry, PoseStamped or PoseWithCovarianceStamped) of the bag
    at ``path`` as (stamp ns, position, quaternion), in time order: ground truth from a
    second bag; with the poses' frame_id and the last value of every transform on its /tf
    and /tf_static (the reference's tag map)."""
    from rosbags.highlevel import AnyReader

    bag, ros_version = bag_paths(path)
    try:
        reader = AnyReader([bag], default_typestore=apriltag_typestore(ros_version))
        reader.open()
    except FgslamError:
        raise
    except Exception as exc:
        raise InputFileError(f"{path}: cannot read as a ROS {ros_version} bag ({type(exc).__name__}: {exc})") from None
    try:
        _check_topic(path, reader.topics, topic, _TRUTH_TYPES, "ground-truth poses")
        out = []
        for i, (connection, bag_time, raw) in enumerate(
                reader.messages(connections=[c for c in reader.connections if c.topic == topic])):
            msg = reader.deserialize(raw, connection.msgtype)
            p, q = _pose3(_pose_of(msg))
            if not np.all(np.isfinite(p + q)) or abs(np.linalg.norm(q) - 1) > 0.01:
                raise BagFormatError(path, topic, f"pose {p} {q} is not finite or not a unit quaternion", i + 1)
            out.append((_stamp_ns(msg, bag_time, use_header_stamps), p, q))
            frame = str(msg.header.frame_id).lstrip("/")
        tf: dict[tuple[str, str], np.ndarray] = {}
        connections = [c for c in reader.connections if c.topic in ("/tf", "/tf_static") and c.msgtype in TF_TYPES]
        for connection, _, raw in (reader.messages(connections=connections) if connections else ()):  # [] = all
            tf.update(_transforms(path, connection.topic, reader.deserialize(raw, connection.msgtype)))
    finally:
        reader.close()
    if not out:
        raise BagFormatError(path, topic, "has no messages; expected ground-truth poses")
    return sorted(out, key=lambda m: m[0]), frame, tf


def _transforms(path: str, topic: str, msg) -> dict[tuple[str, str], np.ndarray]:
    """A TFMessage's transforms as (parent, child) -> 4×4."""
    from slamio.se3 import rotation_from_quaternion

    tf = {}
    for x in msg.transforms:
        t, q = x.transform.translation, x.transform.rotation
        R = rotation_from_quaternion(q.x, q.y, q.z, q.w)
        if R is None:
            raise BagFormatError(path, topic, f"{x.header.frame_id} -> {x.child_frame_id}: rotation is not a quaternion")
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R, (t.x, t.y, t.z)
        tf[(str(x.header.frame_id).lstrip("/"), str(x.child_frame_id).lstrip("/"))] = T
    return tf


def read_bag(path: str, bag: Path, ros_version: int, odom_topic: str | None, cameras: CameraTopics,
             tag_pose_topic: str | None, truth_topic: str | None, use_header_stamps: bool,
             standard_topics_only: bool, image_detector=None, find_images: bool = False
             ) -> Messages | tuple[Header, list[Record]]:
    """The messages of the topics asked for (:class:`Messages`); or, for a bag fgslam
    exported (it has :data:`RUN_LOG_TOPIC`) unless ``standard_topics_only``, the run log it
    holds as (header, records). ``bag`` and ``ros_version`` are :func:`bag_paths`'s.

    ``image_detector(cameras, camera_infos, reader)`` makes the ``image_corners`` of
    :func:`_read_messages` once the camera topics and their CameraInfo are known. With
    ``find_images`` and no camera topic named, the bag's only image topic is read (more than
    one is an error listing them)."""
    from rosbags.highlevel import AnyReader

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
            if not candidates:
                raise no_odometry_error(path, topics, None)
            raise BagFormatError(
                path, "(odometry)",
                f"no {RUN_LOG_TOPIC} topic (the bag was not written by fgslam export), so name the "
                f"odometry topic (nav_msgs/Odometry); candidates: {', '.join(candidates) or '(none)'}",
            )
        images = _topics_of_type(topics, IMAGE_TYPES)
        if find_images and images and not cameras.topics and tag_pose_topic is None:
            cameras = dataclasses.replace(cameras, images=(_only_image_topic(path, images),))
        tag_topics = _checked_topics(path, topics, odom_topic, cameras, tag_pose_topic, truth_topic)
        infos, tf_static = read_extras(path, reader, cameras)
        image_corners = image_detector(cameras, infos, reader) if cameras.images else None
        messages = _read_messages(path, reader, odom_topic, cameras, truth_topic, tag_topics, use_header_stamps,
                                  image_corners)
        messages.camera_infos, messages.tf_static = infos, tf_static
        messages.unused_images = tuple(t for t in images if t not in cameras.images)
        return messages
    finally:
        reader.close()


def _only_image_topic(path: str, images: list[str]) -> str:
    """The bag's one image topic that is not depth by its name (tags are looked for in it)."""
    colour = [t for t in images if "depth" not in t.lower()]
    if len(colour) != 1:
        raise BagFormatError(path, "(images)", f"no detection topic was named, and the bag has {len(colour)} image "
                             f"topics ({', '.join(colour or images)}): name the one(s) to detect tags in with "
                             "--image-topic T (repeat it for each camera)")
    return colour[0]


def _path_keys(tf: dict[tuple[str, str], np.ndarray], parent: str, child: str) -> list[tuple[str, str]] | None:
    """The (parent, child) keys of ``tf`` on the chain between two frames (either direction), or None."""
    edges: dict[str, list[tuple[str, tuple[str, str]]]] = {}
    for a, b in tf:
        edges.setdefault(a, []).append((b, (a, b)))
        edges.setdefault(b, []).append((a, (a, b)))
    came: dict[str, tuple[str, tuple[str, str]] | None] = {parent: None}
    stack = [parent]
    while stack:
        frame = stack.pop()
        if frame == child:
            keys = []
            while came[frame] is not None:
                frame, key = came[frame]  # type: ignore[misc]
                keys.append(key)
            return keys
        for nxt, key in edges.get(frame, []):
            if nxt not in came:
                came[nxt] = (frame, key)
                stack.append(nxt)
    return None


def read_tf_poses(path: str, parent: str, child: str, use_header_stamps: bool = True
                  ) -> tuple[list[tuple[int, Any, Any]], str, dict[tuple[str, str], np.ndarray]]:
    """The pose of frame ``child`` in frame ``parent`` through the chain of transforms on the
    bag's /tf and /tf_static (``--truth-frames map:rig``): (stamp ns, position, quaternion),
    one each time a /tf message moves a transform of the chain, stamped with that
    transform's header stamp, the others held at their latest value; with ``parent`` and the
    last value of every transform (the tag map), as :func:`read_pose_topic` gives them. A chain that never joins the two frames is an error
    naming the frames the bag has."""
    from rosbags.highlevel import AnyReader

    from slamio.datasets.rosbag_observe import _chain
    from slamio.se3 import quaternion_from_rotation

    parent, child = parent.lstrip("/"), child.lstrip("/")
    bag, ros_version = bag_paths(path)
    try:
        reader = AnyReader([bag], default_typestore=apriltag_typestore(ros_version))
        reader.open()
    except Exception as exc:
        raise InputFileError(f"{path}: cannot read as a ROS {ros_version} bag ({type(exc).__name__}: {exc})") from None
    latest: dict[tuple[str, str], np.ndarray] = {}
    out: dict[int, tuple[Any, Any]] = {}
    try:
        connections = [c for c in reader.connections if c.topic in ("/tf", "/tf_static") and c.msgtype in TF_TYPES]
        if not connections:
            raise BagFormatError(path, "/tf", f"not in this bag; --truth-frames {parent}:{child} reads the truth "
                                 "from tf2_msgs/TFMessage on /tf (and /tf_static)")
        keys: list[tuple[str, str]] | None = None
        for connection, bag_time, raw in reader.messages(connections=connections):
            msg = reader.deserialize(raw, connection.msgtype)
            moved = _transforms(path, connection.topic, msg)
            grew = not set(moved) <= set(latest)
            latest.update(moved)
            if grew or keys is None:
                keys = _path_keys(latest, parent, child)
            on_chain = [x for x in msg.transforms if keys is not None
                        and (str(x.header.frame_id).lstrip("/"), str(x.child_frame_id).lstrip("/")) in keys]
            if not on_chain or connection.topic == "/tf_static":
                continue
            T = _chain({k: latest[k] for k in keys}, parent, child)  # type: ignore[union-attr]
            stamp = max(_stamp_ns(x, bag_time, use_header_stamps) for x in on_chain)
            out[stamp] = (tuple(float(v) for v in T[:3, 3]), tuple(quaternion_from_rotation(T[:3, :3])))
    finally:
        reader.close()
    if not out:
        frames = sorted({f for key in latest for f in key})
        raise BagFormatError(path, "/tf", f"has no chain of transforms from {parent!r} to {child!r} that moves "
                             f"(frames on /tf and /tf_static: {', '.join(frames[:12]) or 'none'}"
                             f"{' ...' if len(frames) > 12 else ''}); give --truth-frames PARENT:CHILD of two of them")
    return [(t, *out[t]) for t in sorted(out)], parent, latest
