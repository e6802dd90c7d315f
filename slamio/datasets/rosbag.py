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
from dataclasses import dataclass
from typing import Any

import numpy as np

from slamio.datasets.mrclam_motion import CommandOdometryNoise, interpolate_pose
from slamio.datasets.rosbag_export import export_rosbag
from slamio.datasets.rosbag_messages import (
    APRILTAG_DETECTION_ARRAY_MSG, APRILTAG_DETECTION_MSG, DETECTIONS_TOPIC, LANDMARKS_TOPIC, ODOMETRY_TOPIC,
    RUN_LOG_TOPIC, T_ROBOT_OPTICAL, TRUTH_TOPIC, MessageFactory, _rosbags, apriltag_typestore, compose_jacobians,
    tag_observation_geometry,
)
from slamio.datasets.rosbag_read import BagFormatError, Messages, bag_paths, read_bag
from slamio.errors import FgslamError
from slamio.geometry import between_pose, wrap_angle
from slamio.log import Header, Observation, Odometry, Record, TruthPose, as_matrix3
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
) -> tuple[Header, list[Record]]:
    """Convert a ROS 1 ``.bag`` file or a ROS 2 bag folder into a run-log header and records.

    A bag written by :func:`export_rosbag` (it has ``/fgslam/run_log``) gives back the
    exported log exactly, whatever topics are named, unless ``standard_topics_only``.
    Otherwise ``odom_topic`` is required and the other topics are optional; see the module
    docstring for every conversion rule and option. Write the result with
    ``slamio.log.write_log``.

    Raises :class:`BagFormatError` (a
    :class:`~slamio.datasets.victoria_park.DatasetFormatError`) naming the topic and what
    was expected for a missing topic, a wrong message type or an unusable message, and
    :class:`~slamio.errors.FgslamError` for an unreadable bag or a bad option.
    """
    _rosbags()
    path = os.fspath(path)
    bag, ros_version = bag_paths(path)
    _check_options(tag_normal_axis, start_from, truth_topic, odom_min_period_s,
                   sigma_range_m=sigma_range_m, sigma_bearing_rad=sigma_bearing_rad,
                   sigma_tag_yaw_rad=sigma_tag_yaw_rad, sigma_height_m=sigma_height_m, max_truth_gap_s=max_truth_gap_s)
    o = _Options(
        path, ros_version, odom_topic, detections_topic, tag_pose_topic, truth_topic,  # type: ignore[arg-type]
        _robot_camera_transform(T_robot_camera), tag_normal_axis, sigma_range_m, sigma_bearing_rad, sigma_tag_yaw_rad,
        with_height, sigma_height_m, odometry_noise if odometry_noise is not None else CommandOdometryNoise(),
        covariance_from_message, odom_min_period_s, interpolate_detections, max_truth_gap_s, start_from,
    )
    messages = read_bag(path, bag, ros_version, odom_topic, detections_topic, tag_pose_topic, truth_topic,
                        use_header_stamps, standard_topics_only)
    if not isinstance(messages, Messages):  # a bag fgslam exported: its run log, as it was
        return messages
    if not messages.odometry:
        raise BagFormatError(path, odom_topic, "has no messages; expected nav_msgs/Odometry poses of the robot")
    n_odometry_messages = len(messages.odometry)
    odometry = _thinned(messages.odometry, odom_min_period_s)
    at_pose, inside = _observations_by_pose(o, messages.sightings, [m[0] for m in odometry], messages.dropped)
    truth = _Truth(messages.truth, odometry[0][0], max_truth_gap_s)
    start_pose = _start_pose(o, odometry, truth)
    records, counts = _pose_records(o, odometry, at_pose, inside, truth)
    header = _header(o, messages, start_pose, odometry[0][0], n_odometry_messages, counts,
                     sum(isinstance(r, Observation) for r in records))
    return header, list(check_records(path, header, records))  # never a log the reader refuses


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


def _observations_by_pose(o: _Options, sightings, odo_times: list[int], dropped: dict[str, int]):
    """The sightings as observations, grouped by the pose they belong to: ``at_pose``
    (odometry index → observations) and ``inside`` (interval end index → {time: observations})."""
    t0 = odo_times[0]
    normal_sign = 1.0 if o.tag_normal_axis == "+z" else -1.0
    at_pose: dict[int, list[Observation]] = {}
    inside: dict[int, dict[int, list[Observation]]] = {}
    for t, tag_id, position, quaternion in sightings:
        if t < odo_times[0]:
            dropped["before_first_odometry"] += 1
            continue
        if t > odo_times[-1]:
            dropped["after_last_odometry"] += 1
            continue
        range_m, bearing_rad, yaw, height = tag_observation_geometry(position, quaternion, o.T_rc, normal_sign)
        if not range_m > 0.0:
            dropped["zero_range"] += 1
            continue
        obs = Observation(
            (t - t0) / 1e9, tag_id, range_m, bearing_rad, o.sigma_range_m, o.sigma_bearing_rad,
            height_m=height if o.with_height else None,
            sigma_height_m=o.sigma_height_m if o.with_height else None,
            tag_yaw_rad=yaw, sigma_tag_yaw_rad=o.sigma_tag_yaw_rad if yaw is not None else None,
        )
        k = bisect.bisect_right(odo_times, t) - 1
        if odo_times[k] == t or not o.interpolate_detections:
            at_pose.setdefault(k, []).append(obs)
        else:
            inside.setdefault(k + 1, {}).setdefault(t, []).append(obs)
    return at_pose, inside


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
        raise BagFormatError(o.path, o.truth_topic, "has no ground truth at the first odometry message, so start_from='truth' cannot be used")
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
            "observation": {
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
