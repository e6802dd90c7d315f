"""Run-log format v1 and v2: one JSON Lines file per run (specified in docs/log-format.md).

Line 1 is a header; every later line is one record with a ``"type"``. A planar log
(version 1, or version 2 with a planar start pose) holds:

* ``odometry``        — an SE(2) increment since the previous reading (and, optionally, the
                        Create's raw distance/angle reading it came from), with covariance;
* ``observation``     — one landmark seen from the current pose: range, bearing, optional
                        height and tag yaw, and their standard deviations;
* ``truth_pose``      — optional ground truth of the current pose;
* ``truth_landmark``  — optional ground truth of one landmark;
* ``live_step``       — written by ``fgslam live``: the smoother's wall time for one pose.

A **3-D log** (version 2, start pose ``pose3``) holds ``velocity_odometry``,
``stereo_observation``, ``truth_pose3``, ``truth_landmark3`` and ``live_step`` records
instead (:mod:`slamio.log3d`); the reader refuses planar records in it and 3-D records in a
planar log. Writers write version 1 for a planar log, so older readers still read it.

Pose 0 is the header's start pose. Every odometry record starts a new pose; observations
and truth poses belong to the latest pose (see :meth:`RunLog.steps`).

Records are frozen dataclasses. :func:`read_log` validates every line and raises
:class:`LogFormatError` naming ``file:line``, what is wrong and how to fix it; the error
carries everything read before the bad line. Numbers must lie within physical bounds (the
constants below, explained in docs/log-format.md "Bounds"). Two things are not errors:

* a last line that is not valid JSON and has no final newline (a recording that was
  interrupted mid-line): the log is returned without it and says so in
  :attr:`RunLog.truncated`;
* an observation whose range the header's sensor cannot produce (outside
  ``sensor.min_range_m``/``max_range_m`` by more than 5 of its σ, or below half the
  minimum): it is left out of the records, so no estimator sees it, and counted in
  :attr:`RunLog.rejected`.
"""

from __future__ import annotations

import json
import math
import os
import sys
from dataclasses import dataclass, field
from typing import IO, Any, Iterable, Union

import numpy as np

from slamio.errors import FgslamError

FORMAT_NAME = "fgslam-run-log"
#: The newest version this reader reads; version 2 added the 3-D logs (slamio.log3d).
FORMAT_VERSION = 2
#: Every version it reads. A planar log is written as version 1.
VERSIONS = (1, 2)
PLANAR_VERSION = 1
UNITS = {"length": "m", "angle": "rad", "time": "s"}

# Bounds the reader enforces (docs/log-format.md, "Bounds"). Each is a physical limit with
# a wide margin, and keeps every square and inverse the estimators compute far from float
# overflow, underflow and singular matrices.

#: Landmark ids (and pose indices) are 0 ≤ id ≤ MAX_ID: a GTSAM key is an 8-bit letter
#: and a 56-bit index (``L(id)``, ``X(k)``).
MAX_ID = 2**56 - 1
#: Standard deviations of lengths (m): none finer than 1 µm (no odometer, range sensor or
#: camera resolves it), none coarser than 1 km (it says nothing at a ground robot's scale).
SIGMA_LENGTH_M = (1e-6, 1e3)
#: Standard deviations of angles (rad): none finer than 1 µrad (0.2 arc seconds), none
#: coarser than a full turn (2π says nothing about an angle).
SIGMA_ANGLE_RAD = (1e-6, 2.0 * math.pi)
#: Ranges (m): from 1 µm to 10 km, further than any landmark sensor on a ground robot sees.
RANGE_M = (1e-6, 1e4)
#: Odometry covariance: smallest eigenvalue (1 µm or 1 µrad squared) and largest variances
#: of (dx, dy) (σ of 1 km) and of dtheta (σ of a full turn).
MIN_COVARIANCE_EIGENVALUE = SIGMA_LENGTH_M[0] ** 2
MAX_POSITION_VARIANCE_M2 = SIGMA_LENGTH_M[1] ** 2
MAX_HEADING_VARIANCE_RAD2 = SIGMA_ANGLE_RAD[1] ** 2
#: An observation is rejected when its range is further outside the sensor's
#: [min_range_m, max_range_m] than this many of its own σ (noise puts a real one just
#: outside now and then; 5σ happens once in 1.7 million draws) — and below the minimum,
#: by never more than half of it (a working sensor's noise does not halve a range).
SENSOR_LIMIT_SIGMAS = 5.0
#: How deeply the header's free-form objects may nest (lists and objects inside each other).
MAX_NESTING = 64


class LogFormatError(FgslamError):
    """A run log that cannot be read past some line.

    ``partial`` is the :class:`RunLog` of everything before the bad line (``None`` when
    the header itself is bad), so a caller can still use the good part.
    """

    def __init__(self, path: str, line: int, message: str, partial: "RunLog | None" = None):
        super().__init__(f"{path}:{line}: {message}")
        self.path = path
        self.line = line
        self.partial = partial


# --------------------------------------------------------------------------- records

Matrix3 = tuple[tuple[float, float, float], tuple[float, float, float], tuple[float, float, float]]


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
    """One landmark seen from the current pose, in the robot frame.

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
    """Ground truth of the current pose (simulation, motion capture)."""

    stamp_s: float
    x_m: float
    y_m: float
    theta_rad: float


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


Record = Union[Odometry, Observation, TruthPose, TruthLandmark, LiveStep, Any]  # Any: the 3-D records (slamio.log3d)

_TYPE_OF = {
    Odometry: "odometry",
    Observation: "observation",
    TruthPose: "truth_pose",
    TruthLandmark: "truth_landmark",
    LiveStep: "live_step",
}
_CLASS_OF = {name: cls for cls, name in _TYPE_OF.items()}
#: Record types of a planar log and of a 3-D log (live_step is in both).
_PLANAR_TYPES = ("odometry", "observation", "truth_pose", "truth_landmark", "live_step")
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
        if not self.rejected:
            return None
        by_reason: dict[str, list[int]] = {}
        for r in self.rejected:
            by_reason.setdefault(r.reason, []).append(r.line)
        parts = []
        for reason, lines in by_reason.items():
            where = f"line {lines[0]}" if len(lines) == 1 else f"lines {lines[0]}, ..., {lines[-1]}"
            parts.append(f"{len(lines)} {reason} ({where})")
        n = len(self.rejected)
        return (
            f"{self.path}: {n} observation{'s' if n != 1 else ''} rejected and kept from the estimators: "
            + "; ".join(parts)
        )

    def steps(self) -> list[Step]:
        """Group the records into per-pose steps (see :class:`Step`)."""
        return group_steps(self.header, self.records)

    def truth_landmarks(self) -> dict[int, TruthLandmark]:
        return {r.landmark_id: r for r in self.records if isinstance(r, TruthLandmark)}

    def has_full_truth(self) -> bool:
        """True when every pose has a ground-truth pose."""
        steps = self.steps()
        return bool(steps) and all(s.truth is not None for s in steps)


def group_steps(header: Header, records: Iterable[Record]) -> list[Step]:
    """Group records into steps: pose 0 at the header's start, one new pose per odometry.

    In a 3-D log ``velocity_odometry`` starts a pose, ``stereo_observation`` records are
    its observations and ``truth_pose3`` its truth.
    """
    from slamio.log3d import StereoObservation, TruthPose3, VelocityOdometry

    steps: list[Step] = []
    stamp, odometry, observations, truth = header.stamp_s, None, [], None
    for record in records:
        if isinstance(record, (Odometry, VelocityOdometry)):
            steps.append(Step(len(steps), stamp, odometry, tuple(observations), truth))
            stamp, odometry, observations, truth = record.stamp_s, record, [], None
        elif isinstance(record, (Observation, StereoObservation)):
            observations.append(record)
        elif isinstance(record, (TruthPose, TruthPose3)):
            truth = record
    steps.append(Step(len(steps), stamp, odometry, tuple(observations), truth))
    return steps


# --------------------------------------------------------------------------- writing


_ALWAYS_WRITTEN = {"landmark_id"}  # null means "unknown landmark", not "field absent"


def _drop_none(d: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in d.items() if v is not None or k in _ALWAYS_WRITTEN}


def header_to_dict(header: Header) -> dict[str, Any]:
    return {
        "type": "header",
        "format": FORMAT_NAME,
        "version": header.version,
        "units": dict(UNITS),
        "start": (
            {"stamp_s": header.stamp_s, "pose3": list(header.start_pose3), "sigma3": list(header.start_sigma3)}
            if header.is_3d
            else {"stamp_s": header.stamp_s, "pose": list(header.start_pose), "sigma": list(header.start_sigma)}
        ),
        "robot": header.robot,
        "sensor": header.sensor,
        "noise": header.noise,
        "source": header.source,
    }


def record_to_dict(record: Record) -> dict[str, Any]:
    from slamio.log3d import TYPE_OF_3D

    kind = _TYPE_OF.get(type(record)) or TYPE_OF_3D[type(record)]
    out: dict[str, Any] = {"type": kind}
    for name in record.__dataclass_fields__:
        value = getattr(record, name)
        if name == "covariance":
            value = [list(row) for row in value]
        elif isinstance(value, tuple):
            value = list(value)
        out[name] = value
    return _drop_none(out)


def format_line(obj: Header | Record) -> str:
    """One log line (without the newline). Floats are written so they read back exactly."""
    d = header_to_dict(obj) if isinstance(obj, Header) else record_to_dict(obj)
    try:
        return json.dumps(d, allow_nan=False, separators=(", ", ": "))
    except ValueError as exc:
        raise FgslamError(f"cannot write {d.get('type')} record {d!r}: {exc} (NaN or infinity)") from exc


class LogWriter:
    """Streams a log to a file: header first, then one record per line, flushed as written.

    Use as a context manager so a run that crashes still leaves every line it wrote::

        with LogWriter(path, header) as log:
            log.write(record)
    """

    def __init__(self, path: str | os.PathLike[str], header: Header):
        self.path = os.fspath(path)
        self._file: IO[str] = open(self.path, "w", encoding="utf-8")
        self._file.write(format_line(header) + "\n")

    def write(self, record: Record) -> None:
        self._file.write(format_line(record) + "\n")

    def flush(self) -> None:
        self._file.flush()

    def close(self) -> None:
        if not self._file.closed:
            self._file.close()

    def __enter__(self) -> "LogWriter":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def write_log(path: str | os.PathLike[str], header: Header, records: Iterable[Record]) -> None:
    with LogWriter(path, header) as log:
        for record in records:
            log.write(record)


# --------------------------------------------------------------------------- reading


class _BadLine(Exception):
    """Internal: what is wrong with one line and how to fix it."""


class _NotJson(_BadLine):
    """Internal: the line is not JSON at all (a cut-off last line may be one)."""


def _reject_constant(name: str) -> float:
    raise _BadLine(f"{name} is not a number; write a finite number (or leave the optional field out)")


def _number(d: dict, key: str, *, optional: bool = False, label: str | None = None) -> float | None:
    """``d[key]`` as a finite float (None when optional and absent); ``label`` names it in messages."""
    label = label or f"field '{key}'"
    if key not in d or d[key] is None:
        if optional:
            return None
        raise _BadLine(f"missing field '{key}'; add it (units are in the name)")
    value = d[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise _BadLine(f"{label} must be a number, got {_show(value)}")
    try:
        value = float(value)
    except OverflowError:
        raise _BadLine(
            f"{label} is {_show(value)}, too large for a number; write the value in SI units "
            "(is the line corrupted?)"
        ) from None
    if not math.isfinite(value):
        raise _BadLine(f"{label} must be finite")
    return value


def _finite(d: dict, key: str, *, optional: bool = False, positive: bool = False) -> float | None:
    value = _number(d, key, optional=optional)
    if value is not None and positive and not value > 0.0:
        raise _BadLine(f"field '{key}' must be > 0, got {value!r}")
    return value


def _within(key: str, value: float | None, bounds: tuple[float, float], unit: str, why: str) -> float | None:
    """``value`` if it lies in ``bounds`` (inclusive), else a _BadLine saying why it must."""
    if value is None:
        return None
    lo, hi = bounds
    if value <= 0.0 and lo > 0.0:
        raise _BadLine(f"field '{key}' must be > 0, got {value!r}")
    if not lo <= value <= hi:
        raise _BadLine(f"field '{key}' is {value!r}, outside {lo:g}..{hi:g} {unit}: {why}")
    return value


_WHY_SIGMA_LENGTH = (
    "no sensor resolves less than 1 µm, and a σ above 1 km says nothing at a robot's scale; "
    "write the measurement's real standard deviation in metres"
)
_WHY_SIGMA_ANGLE = (
    "no sensor resolves less than 1 µrad, and a σ above 2π (a full turn) says nothing about an angle; "
    "write the real standard deviation in radians (degrees written as radians?)"
)
_WHY_RANGE = "no landmark sensor measures a range below 1 µm or beyond 10 km; write the range in metres"


def _sigma_length(d: dict, key: str, *, optional: bool = False) -> float | None:
    return _within(key, _number(d, key, optional=optional), SIGMA_LENGTH_M, "m", _WHY_SIGMA_LENGTH)


def _sigma_angle(d: dict, key: str, *, optional: bool = False) -> float | None:
    return _within(key, _number(d, key, optional=optional), SIGMA_ANGLE_RAD, "rad", _WHY_SIGMA_ANGLE)


def _angle(d: dict, key: str, *, optional: bool = False) -> float | None:
    """An angle in [-π, π]."""
    value = _number(d, key, optional=optional)
    if value is not None and abs(value) > math.pi:
        raise _BadLine(
            f"field '{key}' is {value!r} rad, outside [-π, π]: degrees written as radians? "
            "write radians and wrap the angle into [-π, π]"
        )
    return value


def _integer(d: dict, key: str, *, optional: bool = False, id_range: bool = False) -> int | None:
    if key not in d or d[key] is None:
        if optional:
            return None
        raise _BadLine(f"missing field '{key}'")
    value = d[key]
    if isinstance(value, bool) or not isinstance(value, int):
        raise _BadLine(f"field '{key}' must be an integer, got {_show(value)}")
    if id_range and not 0 <= value <= MAX_ID:
        raise _BadLine(
            f"field '{key}' is {_show(value)}, outside 0..2^56-1: ids are integers 0 ≤ id < 2^56 "
            "(a GTSAM key holds a 56-bit index); renumber the landmarks"
        )
    return value


def _show(value: Any) -> str:
    """A JSON value for a message, shortened (a 400-digit number or a long list stays readable)."""
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) >= 10**30:
        return f"an integer of {len(str(abs(value)))} digits"
    try:
        text = json.dumps(value)
    except (RecursionError, ValueError):  # nested about as deeply as json.loads allows
        return "a deeply nested " + ("list" if isinstance(value, list) else "object")
    return text if len(text) <= 60 else text[:57] + "..."


def _free_form(value: Any, what: str) -> None:
    """A header object's free-form content: nested at most MAX_NESTING deep, numbers finite."""
    stack = [(value, 1)]
    while stack:
        v, depth = stack.pop()
        if depth > MAX_NESTING:
            raise _BadLine(
                f"header field '{what}' is nested more than {MAX_NESTING} levels deep; "
                "describe the hardware in a flat object (see docs/log-format.md)"
            )
        if isinstance(v, dict):
            stack.extend((x, depth + 1) for x in v.values())
        elif isinstance(v, list):
            stack.extend((x, depth + 1) for x in v)
        elif isinstance(v, float) and not math.isfinite(v):
            raise _BadLine(
                f"header field '{what}' holds a number too large for a float (it reads as infinity); "
                "write a finite number"
            )


def _object(d: dict, key: str, required_keys: tuple[str, ...] = ()) -> dict:
    value = d.get(key)
    if not isinstance(value, dict):
        raise _BadLine(f"header field '{key}' must be a JSON object")
    for k in required_keys:
        if k not in value:
            raise _BadLine(f"header field '{key}' lacks '{k}'; see docs/log-format.md")
    _free_form(value, key)
    return value


def _vector3(value: Any, what: str) -> tuple[float, float, float]:
    if not (isinstance(value, list) and len(value) == 3):
        raise _BadLine(f"{what} must be a list of 3 numbers")
    return tuple(_number({"v": v}, "v", label=f"each entry of {what}") for v in value)  # type: ignore[return-value]


def _check_fields(d: dict, allowed: Iterable[str], kind: str) -> None:
    unknown = sorted(set(d) - set(allowed) - {"type"})
    if unknown:
        raise _BadLine(
            f"unknown field(s) {', '.join(unknown)} in this {kind} record; "
            f"allowed: {', '.join(sorted(allowed))}"
        )


def _paired(value: float | None, sigma: float | None, value_key: str, sigma_key: str) -> None:
    if (value is None) != (sigma is None):
        raise _BadLine(f"'{value_key}' and '{sigma_key}' go together: give both or neither")


def _covariance(value: Any) -> Matrix3:
    if not (isinstance(value, list) and len(value) == 3):
        raise _BadLine("'covariance' must be a 3×3 list of lists over (dx, dy, dtheta)")
    rows = tuple(_vector3(row, "each covariance row") for row in value)
    largest = max(abs(v) for row in rows for v in row)
    if largest > MAX_POSITION_VARIANCE_M2:
        raise _BadLine(
            f"'covariance' holds {largest!r}, above {MAX_POSITION_VARIANCE_M2:g}: variances are at most "
            f"{MAX_POSITION_VARIANCE_M2:g} m² for dx, dy (σ of 1 km) and {MAX_HEADING_VARIANCE_RAD2:.4g} rad² "
            "for dtheta (σ of a full turn); write variances in m² and rad²"
        )
    m = np.array(rows)
    if not np.allclose(m, m.T, rtol=1e-9, atol=1e-15):
        raise _BadLine("'covariance' must be symmetric")
    for i, name, hi, unit in ((0, "dx", MAX_POSITION_VARIANCE_M2, "m²"), (1, "dy", MAX_POSITION_VARIANCE_M2, "m²"),
                              (2, "dtheta", MAX_HEADING_VARIANCE_RAD2, "rad²")):
        if m[i, i] > hi:
            raise _BadLine(
                f"'covariance' gives {name} a variance of {m[i, i]!r} {unit}, above {hi:.4g} "
                f"(σ of {'1 km' if i < 2 else 'a full turn'}): such an increment says nothing; "
                "write the real variance (degrees written as radians?)"
            )
    try:
        np.linalg.cholesky(m)
    except np.linalg.LinAlgError:
        raise _BadLine(
            "'covariance' must be positive definite (every motion has some uncertainty; "
            "put a small variance on each diagonal entry)"
        ) from None
    smallest = float(np.linalg.eigvalsh(m)[0])
    if smallest < MIN_COVARIANCE_EIGENVALUE:
        raise _BadLine(
            f"'covariance' is nearly singular: its smallest eigenvalue {smallest:.3g} is below "
            f"{MIN_COVARIANCE_EIGENVALUE:g} (a σ of 1 µm or 1 µrad in some direction); no odometry is that "
            "certain and the solvers cannot invert it — put a realistic variance on each diagonal entry"
        )
    return rows  # type: ignore[return-value]


def _sensor_limit(sensor: dict, key: str) -> float | None:
    if key not in sensor or sensor[key] is None:
        return None
    value = sensor[key]
    # a 400-digit integer is a number too, but no float: float() would raise OverflowError
    metres = float(value) if isinstance(value, float) or (isinstance(value, int) and abs(value) < 1e300) else None
    if isinstance(value, bool) or metres is None or not math.isfinite(metres) or metres < 0:
        raise _BadLine(
            f"header field 'sensor.{key}' must be a number of metres ≥ 0, got {_show(value)}; "
            "it bounds the ranges the sensor reports (leave it out if there is no limit)"
        )
    return metres


def sensor_range_limits(header: Header) -> tuple[float | None, float | None]:
    """The header sensor's ``(min_range_m, max_range_m)``; None where the header has none."""
    sensor = header.sensor if isinstance(header.sensor, dict) else {}
    try:
        return _sensor_limit(sensor, "min_range_m"), _sensor_limit(sensor, "max_range_m")
    except _BadLine as bad:
        raise FgslamError(str(bad)) from None


def parse_header(d: dict) -> Header:
    if d.get("type") != "header" or d.get("format") != FORMAT_NAME:
        raise _BadLine(
            f"the first line must be the header, {{\"type\": \"header\", \"format\": \"{FORMAT_NAME}\", ...}}; "
            "is this an fgslam run log?"
        )
    version = d.get("version")
    if isinstance(version, bool) or not isinstance(version, int):
        raise _BadLine(
            f"header field 'version' must be the integer 1 or 2, got {_show(version)}"
        )
    if version not in VERSIONS:
        raise _BadLine(
            f"format version {_show(version)} is not supported; this fgslam reads versions "
            f"{' and '.join(str(v) for v in VERSIONS)} (upgrade fgslam to read newer logs)"
        )
    _check_fields(d, ("format", "version", "units", "start", "robot", "sensor", "noise", "source"), "header")
    if d.get("units") != UNITS:
        raise _BadLine(f"header 'units' must be {json.dumps(UNITS)}: convert at the edge, store SI")
    if isinstance(d.get("start"), dict) and "pose3" in d["start"]:
        return _parse_header3(d, version)
    start = _object(d, "start", ("stamp_s", "pose", "sigma"))
    sigma = _vector3(start["sigma"], "start.sigma")
    if min(sigma) <= 0.0:
        raise _BadLine("start.sigma must be > 0 (a tiny value such as 1e-6 pins the start pose)")
    for value, (lo, hi), unit in zip(sigma, (SIGMA_LENGTH_M, SIGMA_LENGTH_M, SIGMA_ANGLE_RAD), ("m", "m", "rad")):
        if not lo <= value <= hi:
            raise _BadLine(
                f"start.sigma {list(sigma)!r} is outside {SIGMA_LENGTH_M[0]:g}..{SIGMA_LENGTH_M[1]:g} m for x, y "
                f"and {SIGMA_ANGLE_RAD[0]:g}..{SIGMA_ANGLE_RAD[1]:.4g} rad for theta; 1e-6 pins the start pose, "
                "a larger σ says how well it is known"
            )
    sensor = _object(d, "sensor", ("kind",))
    low, high = _sensor_limit(sensor, "min_range_m"), _sensor_limit(sensor, "max_range_m")
    if low is not None and high is not None and not low < high:
        raise _BadLine(f"header field 'sensor.min_range_m' ({low!r}) must be below 'sensor.max_range_m' ({high!r})")
    return Header(
        stamp_s=_finite(start, "stamp_s"),  # type: ignore[arg-type]
        start_pose=_vector3(start["pose"], "start.pose"),
        start_sigma=sigma,
        robot=_object(d, "robot", ("name",)),
        sensor=sensor,
        noise=_object(d, "noise", ("odometry", "observation")),
        source=_object(d, "source") if "source" in d else {},
        version=version,
    )


def _parse_header3(d: dict, version: int) -> Header:
    """The header of a 3-D log: ``start.pose3``/``sigma3`` and a stereo ``sensor``."""
    from slamio import log3d

    if version < 2:
        raise _BadLine("'start.pose3' (a 3-D log) needs \"version\": 2; version 1 logs are planar")
    start = _object(d, "start", ("stamp_s", "pose3", "sigma3"))
    _check_fields(start, ("stamp_s", "pose3", "sigma3"), "header 'start' of a 3-D log")
    pose3 = log3d.parse_pose3(start["pose3"], "start.pose3")
    sigma3 = log3d.parse_sigma3(start["sigma3"], "start.sigma3")
    sensor = _object(d, "sensor", ("kind",))
    log3d.parse_stereo_sensor(sensor)
    return Header(
        stamp_s=_finite(start, "stamp_s"),  # type: ignore[arg-type]
        start_pose=log3d.top_view(pose3),
        start_sigma=(sigma3[0], sigma3[1], sigma3[5]),
        robot=_object(d, "robot", ("name",)),
        sensor=sensor,
        noise=_object(d, "noise", ("odometry", "observation")),
        source=_object(d, "source") if "source" in d else {},
        version=version,
        start_pose3=pose3,
        start_sigma3=sigma3,
    )


def parse_record(d: dict) -> Record:
    kind = d.get("type")
    if not isinstance(kind, str):
        raise _BadLine(
            f"field 'type' must be a string naming the record type, got {_show(kind)}; "
            f"expected one of {', '.join(sorted(_CLASS_OF))}"
        )
    from slamio import log3d

    cls = _CLASS_OF.get(kind) or log3d.RECORDS_3D.get(kind)
    if cls is None:
        raise _BadLine(
            f"unknown record type {_show(kind)}; expected one of {', '.join(sorted(_PLANAR_TYPES + _TYPES_3D[:-1]))}"
        )
    _check_fields(d, cls.__dataclass_fields__, kind)
    if kind in log3d.RECORDS_3D:
        return log3d.parse_record3(kind, d)
    if cls is Odometry:
        distance, angle = _finite(d, "distance_m", optional=True), _finite(d, "angle_rad", optional=True)
        if (distance is None) != (angle is None):
            raise _BadLine("'distance_m' and 'angle_rad' (the Create's reading) go together: give both or neither")
        if "covariance" not in d:
            raise _BadLine("missing field 'covariance' (3×3 over dx, dy, dtheta)")
        return Odometry(
            stamp_s=_finite(d, "stamp_s"),
            dx_m=_finite(d, "dx_m"),
            dy_m=_finite(d, "dy_m"),
            dtheta_rad=_finite(d, "dtheta_rad"),
            covariance=_covariance(d["covariance"]),
            distance_m=distance,
            angle_rad=angle,
        )  # type: ignore[arg-type]
    if cls is Observation:
        if "landmark_id" not in d:
            raise _BadLine("missing field 'landmark_id' (an integer, or null when unknown)")
        height, sigma_height = _finite(d, "height_m", optional=True), _sigma_length(d, "sigma_height_m", optional=True)
        _paired(height, sigma_height, "height_m", "sigma_height_m")
        yaw, sigma_yaw = _angle(d, "tag_yaw_rad", optional=True), _sigma_angle(d, "sigma_tag_yaw_rad", optional=True)
        _paired(yaw, sigma_yaw, "tag_yaw_rad", "sigma_tag_yaw_rad")
        bearing, sigma_bearing = _angle(d, "bearing_rad", optional=True), _sigma_angle(d, "sigma_bearing_rad", optional=True)
        _paired(bearing, sigma_bearing, "bearing_rad", "sigma_bearing_rad")
        if bearing is None and yaw is not None:
            raise _BadLine("a range-only observation (no 'bearing_rad') cannot have a tag yaw")
        return Observation(
            stamp_s=_finite(d, "stamp_s"),
            landmark_id=_integer(d, "landmark_id", optional=True, id_range=True),
            range_m=_within("range_m", _number(d, "range_m"), RANGE_M, "m", _WHY_RANGE),
            bearing_rad=bearing,
            sigma_range_m=_sigma_length(d, "sigma_range_m"),
            sigma_bearing_rad=sigma_bearing,
            height_m=height,
            sigma_height_m=sigma_height,
            tag_yaw_rad=yaw,
            sigma_tag_yaw_rad=sigma_yaw,
            truth_landmark_id=_integer(d, "truth_landmark_id", optional=True, id_range=True),
        )  # type: ignore[arg-type]
    if cls is LiveStep:
        index = _integer(d, "pose_index")
        latency = _finite(d, "latency_s")
        if index < 0 or latency < 0:  # type: ignore[operator]
            raise _BadLine("'pose_index' and 'latency_s' must be >= 0")
        if index > MAX_ID:  # type: ignore[operator]
            raise _BadLine(f"'pose_index' is {_show(index)}, above 2^56-1 (a GTSAM key holds a 56-bit index)")
        return LiveStep(stamp_s=_finite(d, "stamp_s"), pose_index=index, latency_s=latency)  # type: ignore[arg-type]
    if cls is TruthPose:
        return TruthPose(
            stamp_s=_finite(d, "stamp_s"),
            x_m=_finite(d, "x_m"),
            y_m=_finite(d, "y_m"),
            theta_rad=_finite(d, "theta_rad"),
        )  # type: ignore[arg-type]
    return TruthLandmark(
        landmark_id=_integer(d, "landmark_id", id_range=True),
        x_m=_finite(d, "x_m"),
        y_m=_finite(d, "y_m"),
        height_m=_finite(d, "height_m", optional=True),
        yaw_rad=_finite(d, "yaw_rad", optional=True),
    )  # type: ignore[arg-type]


def _outside_sensor(obs: Observation, low: float | None, high: float | None) -> tuple[str, str] | None:
    """(reason, message) when the sensor cannot have measured ``obs.range_m``, else None."""
    slack = SENSOR_LIMIT_SIGMAS * obs.sigma_range_m
    if low is not None and obs.range_m < low - min(slack, 0.5 * low):
        return (
            "with range_m below the sensor's min_range_m",
            f"range_m {obs.range_m!r} is below the header's sensor.min_range_m {low!r} by more than "
            f"{SENSOR_LIMIT_SIGMAS:g} σ ({obs.sigma_range_m!r} m) or half the minimum: the sensor cannot have "
            "measured it; the observation is left out (fix the front-end, or the header's limit if it is wrong)",
        )
    if high is not None and obs.range_m > high + slack:
        return (
            "with range_m above the sensor's max_range_m",
            f"range_m {obs.range_m!r} is above the header's sensor.max_range_m {high!r} by more than "
            f"{SENSOR_LIMIT_SIGMAS:g} σ ({obs.sigma_range_m!r} m): the sensor cannot have measured it; "
            "the observation is left out (fix the front-end, or the header's limit if it is wrong)",
        )
    return None


def _decode(raw: bytes, number: int) -> str:
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        message = (
            f"not UTF-8 text: byte 0x{raw[exc.start]:02x} at column {exc.start + 1} ({exc.reason}); "
            "a run log is UTF-8 — was the file damaged, or is this not a run log?"
        )
        try:  # complete JSON apart from the bad byte: an error, never a cut-off line
            json.loads(raw.decode("utf-8", errors="replace"))
        except (ValueError, RecursionError):
            raise _NotJson(message) from None
        raise _BadLine(message) from None
    if number == 1 and text.startswith("\ufeff"):
        raise _BadLine("the file starts with a byte-order mark (BOM); save it as UTF-8 without BOM")
    return text


def _loads(text: str) -> dict:
    if not text.strip():
        raise _NotJson("empty line; remove it (every line must be one JSON object)")
    try:
        d = json.loads(text, parse_constant=_reject_constant)
    except json.JSONDecodeError as exc:
        raise _NotJson(
            f"not valid JSON ({exc.msg} at column {exc.colno}); each line must be one JSON object"
        ) from None
    except RecursionError:
        raise _BadLine(
            "JSON nested too deeply to read (arrays or objects inside each other about a thousand levels "
            "deep); no field of a run log nests like that — is the line corrupted?"
        ) from None
    except ValueError as exc:
        if "digits" not in str(exc):
            raise _BadLine(f"not valid JSON ({exc}); each line must be one JSON object") from None
        raise _BadLine(  # Python's limit on the digits of an integer
            f"an integer with more than {sys.get_int_max_str_digits()} digits, more than Python reads; "
            "no field of a run log needs one — is the line corrupted?"
        ) from None
    if not isinstance(d, dict):
        raise _BadLine("each line must be one JSON object {...}")
    return d


def _lines(data: bytes) -> list[tuple[int, bytes, bool]]:
    """(line number, bytes without the line ending, whether a newline ended it)."""
    parts = data.split(b"\n")
    last_ended = parts[-1] == b""
    if last_ended:
        parts.pop()
    count = len(parts)
    return [
        (number, raw[:-1] if raw.endswith(b"\r") else raw, number < count or last_ended)
        for number, raw in enumerate(parts, start=1)
    ]


def _check_dimension(kind: Any, header: Header) -> None:
    """Planar records only in a planar log, 3-D records only in a 3-D log."""
    if header.is_3d and kind in _PLANAR_TYPES and kind not in _TYPES_3D:
        raise _BadLine(
            f"a {kind} record in a 3-D log (the header has start.pose3); a 3-D log holds "
            f"{', '.join(_TYPES_3D)}"
        )
    if not header.is_3d and kind in _TYPES_3D and kind not in _PLANAR_TYPES:
        raise _BadLine(
            f"a {kind} record in a planar log; 3-D records need a version-2 header with start.pose3 "
            "and a stereo sensor (docs/log-format.md, \"3-D logs\")"
        )


#: How far a velocity record's ``dt_s`` may differ from the time since the previous pose (s).
DT_TOLERANCE_S = 1e-6


def _check_interval(record: Record, pose_stamp: float) -> float:
    """A 3-D log's velocity record spans the time since the previous pose; the latest pose's stamp."""
    from slamio.log3d import VelocityOdometry

    if not isinstance(record, VelocityOdometry):
        return pose_stamp
    gap = record.stamp_s - pose_stamp
    if abs(record.dt_s - gap) > DT_TOLERANCE_S + 1e-15 * abs(record.stamp_s):  # + the stamps' rounding
        raise _BadLine(
            f"field 'dt_s' is {record.dt_s!r} s but the previous pose is {gap!r} s earlier: the velocity is "
            "held from the previous pose to this one, so dt_s must be the difference of their stamps"
        )
    return record.stamp_s


def read_log(path: str | os.PathLike[str]) -> RunLog:
    """Read and validate a run log.

    Raises :class:`LogFormatError` at the first bad line, carrying the records before it
    in ``partial``. A last line without a newline that is not valid JSON (a recording cut
    off mid-line) is dropped and reported in :attr:`RunLog.truncated` instead; a complete
    JSON object on that line is checked like any other. Observations the header's sensor
    cannot have made (range outside its limits by more than :data:`SENSOR_LIMIT_SIGMAS` σ,
    or below half its minimum) are left out of the records and listed in
    :attr:`RunLog.rejected`.
    """
    path = os.fspath(path)
    try:
        with open(path, "rb") as f:
            data = f.read()
    except OSError as exc:
        raise FgslamError(f"{path}: cannot open the log ({exc.strerror})") from None
    lines = _lines(data)
    del data
    if not lines:
        raise LogFormatError(path, 1, "the file is empty; a run log starts with a header line")
    header: Header | None = None
    records: list[Record] = []
    rejected: list[Rejected] = []
    limits: tuple[float | None, float | None] = (None, None)
    last_stamp = -math.inf
    truncated: str | None = None
    pose_stamp = -math.inf  # stamp of the latest pose (3-D logs: velocity_odometry.dt_s must span from it)
    for number, raw, ended in lines:
        try:
            d = _loads(_decode(raw, number))
            if header is None:
                header = parse_header(d)
                limits = sensor_range_limits(header)
                last_stamp = pose_stamp = header.stamp_s
                continue
            if d.get("type") == "header":
                raise _BadLine("a second header; a log holds one run — split the file")
            _check_dimension(d.get("type"), header)
            record = parse_record(d)
            stamp = getattr(record, "stamp_s", None)
            if stamp is not None:
                if stamp < last_stamp:
                    raise _BadLine(
                        f"stamp_s {stamp!r} goes back in time (previous {last_stamp!r}); "
                        "records must be written in time order"
                    )
                last_stamp = stamp
            if header.is_3d:
                pose_stamp = _check_interval(record, pose_stamp)
            if isinstance(record, Observation):
                outside = _outside_sensor(record, *limits)
                if outside is not None:
                    reason, message = outside
                    rejected.append(Rejected(number, reason, f"{path}:{number}: {message}", record))
                    continue
            records.append(record)
        except _BadLine as bad:
            if isinstance(bad, _NotJson) and number == len(lines) and not ended and header is not None:
                truncated = (
                    f"{path}:{number}: the last line is cut off (recording interrupted?); "
                    f"using the {number - 1} complete lines before it"
                )
                break
            partial = None if header is None else RunLog(path, header, tuple(records), None, tuple(rejected))
            raise LogFormatError(path, number, str(bad), partial) from None
    assert header is not None
    return RunLog(path, header, tuple(records), truncated, tuple(rejected))


def as_matrix3(m: Any) -> Matrix3:
    """A 3×3 array-like as the nested tuple of floats that records hold."""
    a = np.asarray(m, dtype=float)
    if a.shape != (3, 3):
        raise ValueError(f"expected a 3×3 matrix, got shape {a.shape}")
    return tuple(tuple(float(v) for v in row) for row in a)  # type: ignore[return-value]
