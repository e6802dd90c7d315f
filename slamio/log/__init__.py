"""Run-log format v1 and v2: one JSON Lines file per run (specified in docs/log-format.md).

Line 1 is a header; every later line is one record with a ``"type"``. A planar log
(version 1, or version 2 with a planar start pose) holds:

* ``odometry``        — an SE(2) increment since the previous reading (and, optionally, the
                        Create's raw distance/angle reading it came from), with covariance;
* ``observation``     — one landmark seen from the current pose: range, bearing, optional
                        height and tag yaw, and their standard deviations;
* ``truth_pose``      — optional ground truth of the current pose;
* ``truth_landmark``  — optional ground truth of one landmark (at most one per id);
* ``live_step``       — written by ``fgslam live``: the smoother's wall time for one pose;
* ``event``           — a bump, a cliff or a wheel drop the robot met, and at which pose.

A **3-D log** (version 2, start pose ``pose3``) holds ``velocity_odometry``,
``stereo_observation``, ``truth_pose3``, ``truth_landmark3`` and ``live_step`` records
instead (:mod:`slamio.log.records3d`); the reader refuses planar records in it and 3-D records in a
planar log. Writers write version 1 for a planar log, so older readers still read it.

Pose 0 is the header's start pose. Every odometry record starts a new pose; observations
and truth poses belong to the latest pose (see :meth:`RunLog.steps`).

Records are frozen dataclasses. :func:`read_log` validates every line and raises
:class:`LogFormatError` naming ``file:line``, what is wrong and how to fix it; the error
carries everything read before the bad line. Two lines that contradict each other (a stamp
earlier than the previous one, two different truths of one landmark) are reported at the
earlier one, naming both. Numbers must lie within physical bounds (the
constants in :mod:`slamio.log.fields`, explained in docs/log-format.md "Bounds"). Two things are not errors:

* a last line that is not valid JSON and has no final newline (a recording that was
  interrupted mid-line): the log is returned without it and says so in
  :attr:`RunLog.truncated`;
* an observation whose range the header's sensor cannot produce (outside
  ``sensor.min_range_m``/``max_range_m`` by more than 5 of its σ, or below half the
  minimum): it is left out of the records, so no estimator sees it, and counted in
  :attr:`RunLog.rejected`.

The package, one responsibility per file: :mod:`~slamio.log.records` (the records, steps and
:class:`RunLog`), :mod:`~slamio.log.fields` (one field validated against its bounds),
:mod:`~slamio.log.records3d` (the 3-D records, their parsers and the stereo calibration),
:mod:`~slamio.log.read` (:func:`read_log`, :func:`iter_log`: the file streamed, each line through the fast path :mod:`~slamio.log.fast` and, when that does not accept it, the slow path :mod:`~slamio.log.parse`), :mod:`~slamio.log.columns` (a planar log streamed into columns of numbers, its steps built when read: what ``fgslam run`` holds instead of the records) and :mod:`~slamio.log.write` (:class:`LogWriter`,
:func:`write_log`). Import everything from ``slamio.log``.
"""

from slamio.log.fields import (
    COORDINATE_M,
    INCREMENT_M,
    INCREMENT_RAD,
    MAX_HEADING_VARIANCE_RAD2,
    MAX_ID,
    MAX_NESTING,
    MAX_POSE_INDEX,
    MAX_POSITION_VARIANCE_M2,
    MIN_COVARIANCE_EIGENVALUE,
    RANGE_M,
    SENSOR_LIMIT_SIGMAS,
    SIGMA_ANGLE_RAD,
    SIGMA_LENGTH_M,
    STAMP_S,
    WORLD_ANGLE_RAD,
)
from slamio.log.read import (
    DT_TOLERANCE_S, LogFormatError, LogStream, iter_log, parse_header, parse_record, read_log, sensor_range_limits,
)
from slamio.log.records import (
    EVENT_KINDS,
    EVENT_SIDES,
    FORMAT_NAME,
    FORMAT_VERSION,
    PLANAR_VERSION,
    UNITS,
    VERSIONS,
    Event,
    Header,
    LiveStep,
    Matrix3,
    Observation,
    Odometry,
    Record,
    Rejected,
    RunLog,
    Step,
    TruthLandmark,
    TruthPose,
    as_matrix3,
    event_counts,
    group_steps,
)
from slamio.log.records3d import (
    MAX_MOUNT_M,
    MAX_PIXEL_PX,
    MAX_SPEED_MPS,
    MAX_TURN_RATE_RADPS,
    RECORDS_3D,
    SIGMA_PIXEL_PX,
    TYPE_OF_3D,
    StereoCalibration,
    StereoObservation,
    TruthLandmark3,
    TruthPose3,
    VelocityOdometry,
    pose3_from_matrix,
    pose3_matrix,
    stereo_calibration,
    stereo_sensor,
    top_view,
)
from slamio.log.write import LogWriter, format_line, header_to_dict, record_to_dict, write_log

__all__ = [
    "COORDINATE_M", "INCREMENT_M", "INCREMENT_RAD", "WORLD_ANGLE_RAD",
    "DT_TOLERANCE_S", "EVENT_KINDS", "EVENT_SIDES", "FORMAT_NAME", "FORMAT_VERSION", "MAX_HEADING_VARIANCE_RAD2", "MAX_ID", "MAX_NESTING", "MAX_POSE_INDEX", "STAMP_S",
    "MAX_POSITION_VARIANCE_M2", "MIN_COVARIANCE_EIGENVALUE", "PLANAR_VERSION", "RANGE_M", "SENSOR_LIMIT_SIGMAS",
    "SIGMA_ANGLE_RAD", "SIGMA_LENGTH_M", "UNITS", "VERSIONS",
    "Event", "Header", "LiveStep", "LogFormatError", "LogWriter", "Matrix3", "Observation", "Odometry", "Record", "Rejected",
    "RunLog", "Step", "TruthLandmark", "TruthPose",
    "as_matrix3", "event_counts", "format_line", "group_steps", "header_to_dict", "iter_log", "LogStream", "parse_header", "parse_record", "read_log",
    "record_to_dict", "sensor_range_limits", "write_log",
    # the 3-D records (slamio.log.records3d)
    "MAX_MOUNT_M", "MAX_PIXEL_PX", "MAX_SPEED_MPS", "MAX_TURN_RATE_RADPS", "RECORDS_3D", "SIGMA_PIXEL_PX", "TYPE_OF_3D",
    "StereoCalibration", "StereoObservation", "TruthLandmark3", "TruthPose3", "VelocityOdometry",
    "pose3_from_matrix", "pose3_matrix", "stereo_calibration", "stereo_sensor", "top_view",
]
