"""Run log → ROS 2 bag: :func:`export_rosbag`.

Export (:func:`export_rosbag`) and the exact round trip
-------------------------------------------------------
:func:`export_rosbag` writes a ROS 2 bag of a run log, for ROS tools (rviz2, Foxglove,
PlotJuggler, ``ros2 bag``) and for the importer:

====================================  =======================================  ==========================
topic                                 type                                     what
====================================  =======================================  ==========================
``/fgslam/run_log``                   ``std_msgs/String``                      the header and every record, one exact JSON line per message, in file order
``/fgslam/odometry``                  ``nav_msgs/Odometry``                    the integrated odometry: pose 0 and every pose, with the propagated (x, y, yaw) covariance
``/fgslam/truth_pose``                ``geometry_msgs/PoseStamped``            the ``truth_pose`` records that have a heading
``/fgslam/tag_detections``            ``apriltag_ros/AprilTagDetectionArray``  the observations, as tag poses in the camera frame of :data:`T_ROBOT_OPTICAL`
``/fgslam/truth_landmarks``           ``geometry_msgs/PoseArray``              the ``truth_landmark`` records (for viewing)
====================================  =======================================  ==========================

Frames: ``world`` (the log's world frame), ``base_link`` (the robot), ``camera_optical``.
The importer prefers ``/fgslam/run_log`` when a bag has it, and then gives back exactly the
exported header and records (``standard_topics_only=True`` reads the standard topics
instead). The run-log messages get strictly increasing bag times (a record at the same
stamp as the one before is written 1 ns later) so their order is the file's order.
Observations without a bearing (range-only) or without a landmark id cannot be tag poses:
they are only on ``/fgslam/run_log`` (counted in the export summary). An observation
without tag yaw is written with its face normal pointing up, which the importer reads back
as "no tag yaw". The bag is rosbag2 format version 8 (ROS 2 Iron and later; sqlite3
storage by default, MCAP on request).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from slamio.datasets.rosbag_messages import (
    _DETECTION_ARRAY_TYPE, _STRING_TYPE, DETECTIONS_TOPIC, LANDMARKS_TOPIC, ODOMETRY_TOPIC, RUN_LOG_TOPIC,
    T_ROBOT_OPTICAL, TRUTH_TOPIC, MessageFactory, _rosbags, apriltag_typestore, compose_jacobians, tag_pose_in_camera,
)
from slamio.errors import FgslamError
from slamio.geometry import compose_pose
from slamio.log import Observation, Odometry, RunLog, TruthLandmark, TruthPose, format_line, read_log

__all__ = ["export_rosbag"]


def _ns(stamp_s: float) -> int:
    return int(round(stamp_s * 1e9))


def export_rosbag(
    log: str | os.PathLike[str] | RunLog,
    out_path: str | os.PathLike[str],
    *,
    storage: str = "sqlite3",
) -> dict[str, int]:
    """Write a run log (a path or a :class:`~slamio.log.RunLog`) as a ROS 2 bag folder.

    ``out_path`` must not exist (rosbags never overwrites). ``storage`` is ``"sqlite3"``
    (default; every ROS 2 release reads it) or ``"mcap"``. The topics are in the module
    docstring; :func:`import_rosbag` reads the bag back exactly. Returns the number of
    messages per topic, ``observations_not_on_detections`` (range-only or unidentified
    observations) and ``truth_poses_without_heading`` (GPS truth: a ``PoseStamped`` needs an
    orientation), which only ``/fgslam/run_log`` carries.
    """
    _rosbags()
    from rosbags.rosbag2 import StoragePlugin, Writer

    run = log if isinstance(log, RunLog) else read_log(log)
    header, records = run.header, run.records
    if header.stamp_s < 0.0:
        raise FgslamError(
            f"the log starts at stamp {header.stamp_s!r} s; ROS bags cannot hold negative times "
            "(shift the log's stamps to start at 0 or later)"
        )
    plugins = {"sqlite3": StoragePlugin.SQLITE3, "mcap": StoragePlugin.MCAP}
    if storage not in plugins:
        raise FgslamError(f"storage must be 'sqlite3' or 'mcap', got {storage!r}")
    out = Path(out_path)
    if out.exists():
        raise FgslamError(f"{out}: already exists; rosbags does not overwrite a bag: remove it or choose another name")
    store = apriltag_typestore(2)
    make = MessageFactory(store, 2)
    msgs = _topic_messages(header, records)
    summary = {RUN_LOG_TOPIC: len(records) + 1, ODOMETRY_TOPIC: len(msgs.odometry), TRUTH_TOPIC: len(msgs.truth),
               DETECTIONS_TOPIC: len(msgs.detection_groups), LANDMARKS_TOPIC: 1 if msgs.landmarks else 0}
    try:
        writer = Writer(out, version=8, storage_plugin=plugins[storage])
        writer.set_custom_data("fgslam.run_log_topic", RUN_LOG_TOPIC)
        writer.set_custom_data("fgslam.format", "fgslam-run-log version 1; see docs/log-format.md")
        writer.open()
    except Exception as exc:
        raise FgslamError(f"{out}: cannot create the bag ({exc})") from None
    try:
        conn = {
            RUN_LOG_TOPIC: writer.add_connection(RUN_LOG_TOPIC, _STRING_TYPE, typestore=store),
            ODOMETRY_TOPIC: writer.add_connection(ODOMETRY_TOPIC, "nav_msgs/msg/Odometry", typestore=store),
        }
        if msgs.truth:
            conn[TRUTH_TOPIC] = writer.add_connection(TRUTH_TOPIC, "geometry_msgs/msg/PoseStamped", typestore=store)
        if msgs.detection_groups:
            conn[DETECTIONS_TOPIC] = writer.add_connection(DETECTIONS_TOPIC, _DETECTION_ARRAY_TYPE, typestore=store)
        if msgs.landmarks:
            conn[LANDMARKS_TOPIC] = writer.add_connection(LANDMARKS_TOPIC, "geometry_msgs/msg/PoseArray", typestore=store)
        _write_run_log(writer, conn[RUN_LOG_TOPIC], make, header, records)
        _write_topics(writer, conn, make, header, msgs)
    except BaseException:
        writer.close()
        raise
    writer.close()
    summary["observations_not_on_detections"] = msgs.skipped
    summary["truth_poses_without_heading"] = msgs.truth_without_heading
    return summary


@dataclass
class _TopicMessages:
    """What the standard topics carry of a run log."""

    odometry: list[tuple[float, tuple, np.ndarray]]  # (stamp, integrated pose, its propagated covariance)
    truth: list[TruthPose] = field(default_factory=list)
    truth_without_heading: int = 0
    landmarks: list[TruthLandmark] = field(default_factory=list)
    detection_groups: dict[tuple[int, float], list[Observation]] = field(default_factory=dict)
    skipped: int = 0  # observations no detection message can carry
    tag_size_m: float = 0.0


def _topic_messages(header, records) -> _TopicMessages:
    """The pose of every step, integrated, and its propagated covariance; the truth poses
    with a heading, the landmarks and the tag observations grouped by step and stamp."""
    pose = tuple(header.start_pose)
    P = np.diag(np.square(header.start_sigma))
    msgs = _TopicMessages(odometry=[(header.stamp_s, pose, P)])
    step = 0
    for r in records:
        if isinstance(r, Odometry):
            delta = (r.dx_m, r.dy_m, r.dtheta_rad)
            J1, J2 = compose_jacobians(pose, delta)
            P = J1 @ P @ J1.T + J2 @ np.array(r.covariance) @ J2.T
            P = 0.5 * (P + P.T)
            pose = compose_pose(pose, delta)
            step += 1
            msgs.odometry.append((r.stamp_s, pose, P))
        elif isinstance(r, TruthPose):
            if r.theta_rad is None:  # a pose message needs an orientation: only /fgslam/run_log has it
                msgs.truth_without_heading += 1
            else:
                msgs.truth.append(r)
        elif isinstance(r, TruthLandmark):
            msgs.landmarks.append(r)
        elif isinstance(r, Observation):
            if getattr(r, "bearing_rad", None) is None or r.landmark_id is None:
                msgs.skipped += 1
            else:
                msgs.detection_groups.setdefault((step, r.stamp_s), []).append(r)
    tag_size_m = header.sensor.get("tag_size_m", 0.0)
    msgs.tag_size_m = (float(tag_size_m) if isinstance(tag_size_m, (int, float)) and not isinstance(tag_size_m, bool)
                       else 0.0)
    return msgs


def _write_run_log(writer, connection, make: MessageFactory, header, records) -> None:
    """The exact log: strictly increasing bag times keep the file order."""
    t_line = _ns(header.stamp_s)
    writer.write(connection, t_line, make.serialize(make.string(format_line(header))))
    for r in records:
        stamp = getattr(r, "stamp_s", None)
        t_line = max(_ns(stamp) if stamp is not None else t_line, t_line + 1)
        writer.write(connection, t_line, make.serialize(make.string(format_line(r))))


def _write_topics(writer, conn: dict, make: MessageFactory, header, msgs: _TopicMessages) -> None:
    for stamp, pose, P in msgs.odometry:
        t = _ns(stamp)
        writer.write(conn[ODOMETRY_TOPIC], t, make.serialize(make.odometry(t, pose, P)))
    for r in msgs.truth:
        t = _ns(r.stamp_s)
        writer.write(conn[TRUTH_TOPIC], t, make.serialize(make.pose_stamped(t, (r.x_m, r.y_m, r.theta_rad))))
    for (_, stamp), observations in msgs.detection_groups.items():
        t = _ns(stamp)
        tags = []
        for o in observations:
            position, quaternion = tag_pose_in_camera(o.range_m, o.bearing_rad, o.tag_yaw_rad, o.height_m, T_ROBOT_OPTICAL)
            tags.append(([o.landmark_id], [msgs.tag_size_m], position, quaternion))
        writer.write(conn[DETECTIONS_TOPIC], t, make.serialize(make.detection_array(t, tags)))
    if msgs.landmarks:
        t = _ns(header.stamp_s)
        poses = [
            make.pose(
                (lm.x_m, lm.y_m, lm.height_m or 0.0),
                (0.0, 0.0, math.sin((lm.yaw_rad or 0.0) / 2.0), math.cos((lm.yaw_rad or 0.0) / 2.0)),
            )
            for lm in msgs.landmarks
        ]
        writer.write(conn[LANDMARKS_TOPIC], t, make.serialize(make.pose_array(t, poses)))
