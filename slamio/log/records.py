"""The run log's records as frozen dataclasses, and how they group into per-pose steps.

The format is specified in docs/log-format.md; :mod:`slamio.log` has the overview.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Iterable, Iterator, Union

from slamio.log.fields import Matrix3
from slamio.log.records3d import StereoObservation, TruthPose3, VelocityOdometry

FORMAT_NAME = "fgslam-run-log"
#: The newest version this reader reads; version 2 added the 3-D logs (slamio.log.records3d).
FORMAT_VERSION = 2
#: Every version it reads. A planar log is written as version 1.
VERSIONS = (1, 2)
PLANAR_VERSION = 1
UNITS = {"length": "m", "angle": "rad", "time": "s"}


@dataclass(frozen=True)
class Header:
    """First line of a log: what produced it and the models needed to interpret it.

    ``start_pose`` is pose 0 in the world frame (x_m, y_m, theta_rad) and ``start_sigma``
    the standard deviations of the prior on it; a real run usually starts at (0, 0, 0),
    which defines the world frame. ``robot``, ``sensor`` and ``noise`` describe the
    hardware and the noise models in JSON objects (required keys in docs/log-format.md);
    ``source`` says how the log was made (command line, seed, recorder version).

    A 3-D log (version 2) has ``start_pose3`` = ``(x_m, y_m, z_m, qx, qy, qz, qw)`` of
    world_T_imu at pose 0 and ``start_sigma3`` (3 lengths in m, 3 rotation angles in rad,
    a right perturbation); its ``start_pose`` and ``start_sigma`` then hold the top view
    ``(x, y, yaw)`` and ``(σx, σy, σ_rz)`` for code that only needs a planar summary.
    """

    stamp_s: float
    start_pose: tuple[float, float, float]
    start_sigma: tuple[float, float, float]
    robot: dict[str, Any]
    sensor: dict[str, Any]
    noise: dict[str, Any]
    source: dict[str, Any] = field(default_factory=dict)
    version: int = PLANAR_VERSION
    start_pose3: tuple[float, ...] | None = None
    start_sigma3: tuple[float, ...] | None = None

    @property
    def is_3d(self) -> bool:
        """True for a 3-D log (SE(3) poses, stereo observations, velocity odometry)."""
        return self.start_pose3 is not None


@dataclass(frozen=True)
class Odometry:
    """Motion since the previous odometry reading, ending a step and starting a new pose.

    ``dx_m, dy_m, dtheta_rad`` is the SE(2) increment expressed in the frame of the
    previous pose (x forward, y left). ``covariance`` is its 3×3 covariance over
    (dx, dy, dtheta). ``distance_m``/``angle_rad`` optionally keep the Create's own reading
    (distance travelled by the centre and heading change, counter-clockwise) that the
    increment was computed from with the arc model.
    """

    stamp_s: float
    dx_m: float
    dy_m: float
    dtheta_rad: float
    covariance: Matrix3
    distance_m: float | None = None
    angle_rad: float | None = None


@dataclass(frozen=True)
class Observation:
    """One landmark seen from the current pose, in the robot frame (in the sensor's frame when
    the header states ``sensor.pose_on_robot``; :func:`group_steps` moves it to the robot's centre).

    ``landmark_id`` is ``None`` when the front-end cannot tell which landmark it is.
    ``bearing_rad`` is counter-clockwise from the robot's x (forward) axis. ``height_m`` is
    the landmark's height above the floor (seed 002); ``tag_yaw_rad`` the direction the
    tag's face points to, relative to the robot's x axis (seed 004). Each measured value
    carries its standard deviation.

    A **range-only** observation (a ranging radio, Plaza) has ``bearing_rad`` and
    ``sigma_bearing_rad`` None (:attr:`range_only`); it needs a ``landmark_id``-aware
    estimator that can place a landmark from ranges alone (delayed initialisation).

    ``truth_landmark_id`` is ground truth, not a measurement: which landmark this really
    is, kept when ``landmark_id`` is hidden (``fgslam sim --hide-ids``) so that data
    association can be scored. Estimators must never read it.
    """

    stamp_s: float
    landmark_id: int | None
    range_m: float
    bearing_rad: float | None
    sigma_range_m: float
    sigma_bearing_rad: float | None
    height_m: float | None = None
    sigma_height_m: float | None = None
    tag_yaw_rad: float | None = None
    sigma_tag_yaw_rad: float | None = None
    truth_landmark_id: int | None = None

    @property
    def range_only(self) -> bool:
        """True for a range-only observation (no bearing)."""
        return self.bearing_rad is None


@dataclass(frozen=True)
class TruthPose:
    """Ground truth of the current pose (simulation, motion capture, GPS).

    ``theta_rad`` is None when the truth measures position only (GPS gives no heading): such
    a pose is scored on its position, and its NEES is over (x, y) alone (2 degrees of freedom).
    """

    stamp_s: float
    x_m: float
    y_m: float
    theta_rad: float | None = None


@dataclass(frozen=True)
class TruthLandmark:
    """Ground truth of one landmark: position, optional height and facing direction."""

    landmark_id: int
    x_m: float
    y_m: float
    height_m: float | None = None
    yaw_rad: float | None = None


@dataclass(frozen=True)
class LiveStep:
    """How long the live loop's smoother took for one pose (``fgslam live``).

    Written by the live loop after the smoother consumed pose ``pose_index``;
    ``latency_s`` is the wall-clock time of that smoother step. Estimators ignore it.
    """

    stamp_s: float
    pose_index: int
    latency_s: float


#: What an ``event`` record reports (:class:`Event`).
EVENT_KINDS = ("bump", "cliff", "wheel-drop")
#: Which side of the robot an event was on.
EVENT_SIDES = ("left", "right", "both")


@dataclass(frozen=True)
class Event:
    """Something that happened to the robot at ``stamp_s``: a bumper pressed (``bump``), the
    robot at a drop (``cliff``) or a wheel dropped (``wheel-drop``), one of
    :data:`EVENT_KINDS` (written by the recorder, :mod:`slamio.create.record`).

    ``pose_index`` is the pose the event belongs to: the number of odometry records before
    it (0 before the first), as observations belong to the latest pose. ``side`` is
    ``left``, ``right`` or ``both`` when the robot tells (the bumpers, the wheel drops).
    Estimators ignore events.
    """

    stamp_s: float
    kind: str
    pose_index: int
    side: str | None = None


Record = Union[Odometry, Observation, TruthPose, TruthLandmark, LiveStep, Event, Any]  # Any: the 3-D records (slamio.log.records3d)

_TYPE_OF = {
    Odometry: "odometry",
    Observation: "observation",
    TruthPose: "truth_pose",
    TruthLandmark: "truth_landmark",
    LiveStep: "live_step",
    Event: "event",
}
_CLASS_OF = {name: cls for cls, name in _TYPE_OF.items()}
#: Record types of a planar log and of a 3-D log (live_step is in both).
_PLANAR_TYPES = ("odometry", "observation", "truth_pose", "truth_landmark", "live_step", "event")
_TYPES_3D = ("velocity_odometry", "stereo_observation", "truth_pose3", "truth_landmark3", "live_step")


# --------------------------------------------------------------------------- steps


@dataclass(frozen=True)
class Step:
    """Everything an estimator consumes at one pose.

    Step 0 is the start pose (``odometry`` is None); step k ≥ 1 begins with the k-th
    odometry record. ``observations`` and ``truth`` are those logged while this pose was
    the latest one.
    """

    index: int
    stamp_s: float
    odometry: Odometry | None
    observations: tuple[Observation, ...]
    truth: TruthPose | None


@dataclass(frozen=True)
class Rejected:
    """An observation the reader left out of :attr:`RunLog.records` (see :func:`read_log`).

    ``line`` is its line in the file, ``reason`` a short key for counting (the same for
    every observation rejected for the same reason), ``message`` the full
    ``file:line: ...`` explanation and ``record`` the observation itself.
    """

    line: int
    reason: str
    message: str
    record: Observation


@dataclass(frozen=True)
class RunLog:
    """A log as read: header, records in file order, and notes on what was not used.

    ``truncated`` says when the last line was cut off and dropped; ``rejected`` lists the
    observations left out of ``records`` because the sensor cannot have made them (so no
    estimator sees them); :meth:`rejection_summary` puts them in one line.
    """

    path: str
    header: Header
    records: tuple[Record, ...]
    truncated: str | None = None
    rejected: tuple[Rejected, ...] = ()

    def rejection_summary(self) -> str | None:
        """One line counting the rejected observations by reason, or None when there are none."""
        return summarise_rejections(self.path, self.rejected)

    def steps(self) -> list[Step]:
        """Group the records into per-pose steps (see :class:`Step`)."""
        return group_steps(self.header, self.records)

    def has_motion(self) -> bool:
        """True when a record starts a pose after pose 0 (:func:`group_steps`' odometry, in a
        3-D log ``velocity_odometry``): without one the log is its start pose alone."""
        return any(isinstance(r, (Odometry, VelocityOdometry)) for r in self.records)

    def truth_landmarks(self) -> dict[int, TruthLandmark]:
        return {r.landmark_id: r for r in self.records if isinstance(r, TruthLandmark)}

    def has_full_truth(self) -> bool:
        """True when every pose has a ground-truth pose."""
        steps = self.steps()
        return bool(steps) and all(s.truth is not None for s in steps)


def summarise_rejections(path: str, rejected: Iterable[Rejected]) -> str | None:
    """:meth:`RunLog.rejection_summary` of the observations ``rejected`` from the log at ``path``."""
    by_reason: dict[str, tuple[int, int, int]] = {}
    for r in rejected:
        count, first, _ = by_reason.get(r.reason, (0, r.line, r.line))
        by_reason[r.reason] = (count + 1, first, r.line)
    return rejection_line(path, by_reason)


def rejection_line(path: str, by_reason: dict[str, tuple[int, int, int]]) -> str | None:
    """One line counting rejected observations, from ``reason -> (count, first line, last line)``
    (:meth:`RunLog.rejection_summary`; ``fgslam validate`` counts them as it streams)."""
    if not by_reason:
        return None
    parts = []
    for reason, (count, first, last) in by_reason.items():
        where = f"line {first}" if count == 1 else f"lines {first}, ..., {last}"
        parts.append(f"{count} {reason} ({where})")
    n = sum(count for count, _, _ in by_reason.values())
    return f"{path}: {n} observation{'s' if n != 1 else ''} rejected and kept from the estimators: " + "; ".join(parts)


def group_steps(header: Header, records: Iterable[Record], *, at_robot_centre: bool = True) -> list[Step]:
    """Group records into steps: pose 0 at the header's start, one new pose per odometry.

    In a 3-D log ``velocity_odometry`` starts a pose, ``stereo_observation`` records are
    its observations and ``truth_pose3`` its truth. In a planar log whose header says where
    the sensor sits (``sensor.pose_on_robot``), each observation is moved to the robot's
    centre (:mod:`slamio.log.mount`), what every estimator expects; ``at_robot_centre=False``
    keeps them as the sensor took them (a fit against truth that models the sensor itself).
    """
    return list(iter_steps(header, records, at_robot_centre=at_robot_centre))


def iter_steps(header: Header, records: Iterable[Record], *, at_robot_centre: bool = True) -> Iterator[Step]:
    """:func:`group_steps` one step at a time, each as soon as the record that ends it (the
    next pose's odometry, or the end of ``records``) is read: a streamed log is grouped
    without holding it."""
    from slamio.log.mount import moved_to_robot_centre, pose_on_robot

    mount = pose_on_robot(header.sensor) if at_robot_centre and not header.is_3d else None
    index, stamp, odometry, observations, truth = 0, header.stamp_s, None, [], None
    for record in records:
        if isinstance(record, (Odometry, VelocityOdometry)):
            yield Step(index, stamp, odometry, tuple(observations), truth)
            index, stamp, odometry, observations, truth = index + 1, record.stamp_s, record, [], None
        elif isinstance(record, Observation):
            observations.append(record if mount is None else moved_to_robot_centre(record, mount))
        elif isinstance(record, StereoObservation):
            observations.append(record)
        elif isinstance(record, (TruthPose, TruthPose3)):
            truth = record
    yield Step(index, stamp, odometry, tuple(observations), truth)


def event_counts(records: Iterable[Record]) -> dict[str, int]:
    """How many ``event`` records of each kind (kinds in :data:`EVENT_KINDS` order; none: ``{}``)."""
    counts: dict[str, int] = {}
    for record in records:
        if type(record) is Event:
            counts[record.kind] = counts.get(record.kind, 0) + 1
    return in_event_kind_order(counts)


def in_event_kind_order(counts: dict[str, int]) -> dict[str, int]:
    """``counts`` (event kind -> count) with its kinds in :data:`EVENT_KINDS` order."""
    return {kind: counts[kind] for kind in EVENT_KINDS if kind in counts}


def as_matrix3(m: Any) -> Matrix3:
    """A 3×3 array-like as the nested tuple of floats that records hold."""
    import numpy as np

    a = np.asarray(m, dtype=float)
    if a.shape != (3, 3):
        raise ValueError(f"expected a 3×3 matrix, got shape {a.shape}")
    return tuple(tuple(float(v) for v in row) for row in a)  # type: ignore[return-value]
