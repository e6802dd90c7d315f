"""The pieces of a ROS bag that the importer and the exporter share.

The topics :func:`~slamio.datasets.rosbag_export.export_rosbag` writes and
:func:`~slamio.datasets.rosbag.import_rosbag` knows, apriltag_ros's detection messages, the
camera frame of exported tag detections, the rosbags typestore with those messages added,
the message builder (:class:`MessageFactory`, for either ROS version; tests write ROS 1 bags
with it), and the geometry between a tag's pose in the camera frame and the run log's range,
bearing, tag yaw and height.
"""

from __future__ import annotations

import math
from typing import Any, Iterable

import numpy as np

from slamio.errors import FgslamError
from slamio.se3 import quaternion_from_rotation, rotation_from_quaternion

RUN_LOG_TOPIC = "/fgslam/run_log"
ODOMETRY_TOPIC = "/fgslam/odometry"
TRUTH_TOPIC = "/fgslam/truth_pose"
DETECTIONS_TOPIC = "/fgslam/tag_detections"
LANDMARKS_TOPIC = "/fgslam/truth_landmarks"
WORLD_FRAME, ROBOT_FRAME, CAMERA_FRAME = "world", "base_link", "camera_optical"

#: apriltag_ros's detection messages (ROS 1 apriltag_ros 3.x; the same fields in its ROS 2
#: ports). Fields only: comments do not change the message hash.
APRILTAG_DETECTION_MSG = """int32[] id
float64[] size
geometry_msgs/PoseWithCovarianceStamped pose
"""
APRILTAG_DETECTION_ARRAY_MSG = """std_msgs/Header header
AprilTagDetection[] detections
"""
_DETECTION_TYPE = "apriltag_ros/msg/AprilTagDetection"
_DETECTION_ARRAY_TYPE = "apriltag_ros/msg/AprilTagDetectionArray"

#: The camera's optical frame (x right, y down, z forward) at the robot's origin, looking
#: forward: columns are the optical axes in the robot frame (x forward, y left, z up).
T_ROBOT_OPTICAL = np.array(
    [[0.0, 0.0, 1.0, 0.0], [-1.0, 0.0, 0.0, 0.0], [0.0, -1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
)
#: A face normal whose horizontal part is shorter than this (within 30° of vertical) has no yaw.
MIN_NORMAL_HORIZONTAL = 0.5
_STRING_TYPE = "std_msgs/msg/String"


# --------------------------------------------------------------------------- rosbags


def _rosbags():
    try:
        import rosbags.highlevel  # noqa: F401  (lazy: only the bag code needs rosbags)
        import rosbags.rosbag2  # noqa: F401
        import rosbags.typesys  # noqa: F401
    except ImportError as exc:  # pragma: no cover - rosbags is installed with fgslam
        raise FgslamError(f"ROS bags need the 'rosbags' package ({exc}); pip install rosbags") from None
    import rosbags

    return rosbags


def apriltag_typestore(ros_version: int = 2):
    """A rosbags typestore (ROS 2 Humble or ROS 1 Noetic) with apriltag_ros's messages added (and
    tf2_msgs/TFMessage to Noetic's, which lacks it)."""
    _rosbags()
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    if ros_version not in (1, 2):
        raise FgslamError(f"ros_version must be 1 or 2, got {ros_version!r}")
    store = get_typestore(Stores.ROS2_HUMBLE if ros_version == 2 else Stores.ROS1_NOETIC)
    types: dict[str, Any] = {}
    types.update(get_types_from_msg(APRILTAG_DETECTION_MSG, _DETECTION_TYPE))
    types.update(get_types_from_msg(APRILTAG_DETECTION_ARRAY_MSG, _DETECTION_ARRAY_TYPE))
    if "tf2_msgs/msg/TFMessage" not in store.types:  # rosbags' Noetic store lacks it (/tf, /tf_static)
        types.update(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
    store.register(types)
    return store


# --------------------------------------------------------------------------- pure maths


def compose_jacobians(pose, increment) -> tuple[np.ndarray, np.ndarray]:
    """Jacobians of ``compose_pose(pose, increment)`` with respect to pose and increment."""
    th = pose[2]
    dx, dy = increment[0], increment[1]
    c, s = math.cos(th), math.sin(th)
    J1 = np.array([[1.0, 0.0, -s * dx - c * dy], [0.0, 1.0, c * dx - s * dy], [0.0, 0.0, 1.0]])
    J2 = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return J1, J2

def tag_observation_geometry(
    position_camera, orientation_camera, T_robot_camera: np.ndarray, normal_sign: float = 1.0
) -> tuple[float, float, float | None, float]:
    """(range_m, bearing_rad, tag_yaw_rad or None, height_m) of a tag pose in the camera frame."""
    R_rc, t_rc = T_robot_camera[:3, :3], T_robot_camera[:3, 3]
    p = R_rc @ np.asarray(position_camera, dtype=float) + t_rc
    range_m = math.hypot(p[0], p[1])
    bearing_rad = math.atan2(p[1], p[0])
    yaw = None
    R_ct = rotation_from_quaternion(*orientation_camera)
    if R_ct is not None:
        normal = R_rc @ (normal_sign * R_ct[:, 2])
        if math.hypot(normal[0], normal[1]) >= MIN_NORMAL_HORIZONTAL:
            yaw = math.atan2(normal[1], normal[0])
    return range_m, bearing_rad, yaw, float(p[2])


def tag_pose_in_camera(
    range_m: float, bearing_rad: float, tag_yaw_rad: float | None, height_m: float | None, T_robot_camera: np.ndarray
) -> tuple[np.ndarray, tuple[float, float, float, float]]:
    """The inverse of :func:`tag_observation_geometry` for an upright tag (+z out of its face).

    Without a tag yaw the face normal points up (read back as "no tag yaw").
    """
    p_robot = np.array([range_m * math.cos(bearing_rad), range_m * math.sin(bearing_rad), height_m or 0.0])
    if tag_yaw_rad is None:
        R_robot_tag = np.eye(3)
    else:
        z = np.array([math.cos(tag_yaw_rad), math.sin(tag_yaw_rad), 0.0])
        y = np.array([0.0, 0.0, 1.0])
        R_robot_tag = np.column_stack([np.cross(y, z), y, z])
    R_rc, t_rc = T_robot_camera[:3, :3], T_robot_camera[:3, 3]
    p_camera = R_rc.T @ (p_robot - t_rc)
    return p_camera, quaternion_from_rotation(R_rc.T @ R_robot_tag)


# --------------------------------------------------------------------------- messages


class MessageFactory:
    """Builds the messages the exporter writes, for a typestore of either ROS version.

    Holds the typestore (state) and serialises with the matching wire format (CDR for
    ROS 2, ROS 1 serialisation for ROS 1). Tests use it to write ROS 1 bags too.
    """

    def __init__(self, store, ros_version: int):
        self.store = store
        self.ros_version = ros_version
        self.types = store.types
        self._has_seq = "seq" in self.types["std_msgs/msg/Header"].__dataclass_fields__

    def serialize(self, msg) -> bytes:
        if self.ros_version == 2:
            return bytes(self.store.serialize_cdr(msg, msg.__msgtype__))
        return bytes(self.store.serialize_ros1(msg, msg.__msgtype__))

    def header(self, stamp_ns: int, frame_id: str):
        T = self.types
        stamp = T["builtin_interfaces/msg/Time"](sec=stamp_ns // 1_000_000_000, nanosec=stamp_ns % 1_000_000_000)
        if self._has_seq:
            return T["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id=frame_id)
        return T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame_id)

    def pose(self, position, quaternion):
        T = self.types
        return T["geometry_msgs/msg/Pose"](
            position=T["geometry_msgs/msg/Point"](x=float(position[0]), y=float(position[1]), z=float(position[2])),
            orientation=T["geometry_msgs/msg/Quaternion"](
                x=float(quaternion[0]), y=float(quaternion[1]), z=float(quaternion[2]), w=float(quaternion[3])
            ),
        )

    def planar_pose(self, pose):
        x, y, th = pose
        return self.pose((x, y, 0.0), (0.0, 0.0, math.sin(th / 2.0), math.cos(th / 2.0)))

    def string(self, text: str):
        return self.types[_STRING_TYPE](data=text)

    def odometry(self, stamp_ns: int, pose, covariance_xy_yaw=None, frame_id=WORLD_FRAME, child_frame_id=ROBOT_FRAME):
        """nav_msgs/Odometry of a planar pose; the (x, y, yaw) block of the covariance filled."""
        T = self.types
        cov = np.zeros(36)
        if covariance_xy_yaw is not None:
            C = np.asarray(covariance_xy_yaw, dtype=float)
            for a, i in enumerate((0, 1, 5)):
                for b, j in enumerate((0, 1, 5)):
                    cov[6 * i + j] = C[a, b]
        zero3 = T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
        return T["nav_msgs/msg/Odometry"](
            header=self.header(stamp_ns, frame_id),
            child_frame_id=child_frame_id,
            pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=self.planar_pose(pose), covariance=cov),
            twist=T["geometry_msgs/msg/TwistWithCovariance"](
                twist=T["geometry_msgs/msg/Twist"](linear=zero3, angular=zero3), covariance=np.zeros(36)
            ),
        )

    def pose_stamped(self, stamp_ns: int, pose, frame_id=WORLD_FRAME):
        return self.types["geometry_msgs/msg/PoseStamped"](header=self.header(stamp_ns, frame_id), pose=self.planar_pose(pose))

    def pose_stamped_3d(self, stamp_ns: int, position, quaternion, frame_id=CAMERA_FRAME):
        return self.types["geometry_msgs/msg/PoseStamped"](header=self.header(stamp_ns, frame_id), pose=self.pose(position, quaternion))

    def detection_array(self, stamp_ns: int, tags: Iterable[tuple[list[int], list[float], Any, Any]], frame_id=CAMERA_FRAME):
        """AprilTagDetectionArray of (ids, sizes, position in camera, quaternion) tuples."""
        T = self.types
        detections = []
        for ids, sizes, position, quaternion in tags:
            detections.append(
                T[_DETECTION_TYPE](
                    id=np.asarray(ids, dtype=np.int32),
                    size=np.asarray(sizes, dtype=np.float64),
                    pose=T["geometry_msgs/msg/PoseWithCovarianceStamped"](
                        header=self.header(stamp_ns, frame_id),
                        pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=self.pose(position, quaternion), covariance=np.zeros(36)),
                    ),
                )
            )
        return T[_DETECTION_ARRAY_TYPE](header=self.header(stamp_ns, frame_id), detections=detections)

    def pose_array(self, stamp_ns: int, poses, frame_id=WORLD_FRAME):
        return self.types["geometry_msgs/msg/PoseArray"](header=self.header(stamp_ns, frame_id), poses=list(poses))
