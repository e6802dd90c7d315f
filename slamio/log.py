"""Run-log format v1: one JSON Lines file per run (specified in docs/log-format.md).

Line 1 is a header; every later line is one record with a ``"type"``:

* ``odometry``        — an SE(2) increment since the previous reading (and, optionally, the
                        Create's raw distance/angle reading it came from), with covariance;
* ``observation``     — one landmark seen from the current pose: range, bearing, optional
                        height and tag yaw, and their standard deviations;
* ``truth_pose``      — optional ground truth of the current pose;
* ``truth_landmark``  — optional ground truth of one landmark;
* ``live_step``       — written by ``fgslam live``: the smoother's wall time for one pose.

Pose 0 is the header's start pose. Every odometry record starts a new pose; observations
and truth poses belong to the latest pose (see :meth:`RunLog.steps`).

Records are frozen dataclasses. :func:`read_log` validates every line and raises
:class:`LogFormatError` naming ``file:line``, what is wrong and how to fix it; the error
carries everything read before the bad line. A last line cut off mid-way (a recording that
was interrupted) is not an error: the log is returned without it and says so in
:attr:`RunLog.truncated`.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from typing import IO, Any, Iterable, Iterator, Union

import numpy as np

from slamio.errors import FgslamError

FORMAT_NAME = "fgslam-run-log"
FORMAT_VERSION = 1
UNITS = {"length": "m", "angle": "rad", "time": "s"}


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
    """

    stamp_s: float
    start_pose: tuple[float, float, float]
    start_sigma: tuple[float, float, float]
    robot: dict[str, Any]
    sensor: dict[str, Any]
    noise: dict[str, Any]
    source: dict[str, Any] = field(default_factory=dict)
    version: int = FORMAT_VERSION


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


Record = Union[Odometry, Observation, TruthPose, TruthLandmark, LiveStep]

_TYPE_OF = {
    Odometry: "odometry",
    Observation: "observation",
    TruthPose: "truth_pose",
    TruthLandmark: "truth_landmark",
    LiveStep: "live_step",
}
_CLASS_OF = {name: cls for cls, name in _TYPE_OF.items()}


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
class RunLog:
    """A log as read: header, records in file order, and a note if the end was cut off."""

    path: str
    header: Header
    records: tuple[Record, ...]
    truncated: str | None = None

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
    """Group records into steps: pose 0 at the header's start, one new pose per odometry."""
    steps: list[Step] = []
    stamp, odometry, observations, truth = header.stamp_s, None, [], None
    for record in records:
        if isinstance(record, Odometry):
            steps.append(Step(len(steps), stamp, odometry, tuple(observations), truth))
            stamp, odometry, observations, truth = record.stamp_s, record, [], None
        elif isinstance(record, Observation):
            observations.append(record)
        elif isinstance(record, TruthPose):
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
        "start": {
            "stamp_s": header.stamp_s,
            "pose": list(header.start_pose),
            "sigma": list(header.start_sigma),
        },
        "robot": header.robot,
        "sensor": header.sensor,
        "noise": header.noise,
        "source": header.source,
    }


def record_to_dict(record: Record) -> dict[str, Any]:
    out: dict[str, Any] = {"type": _TYPE_OF[type(record)]}
    for name in record.__dataclass_fields__:
        value = getattr(record, name)
        if name == "covariance":
            value = [list(row) for row in value]
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


def _reject_constant(name: str) -> float:
    raise _BadLine(f"{name} is not a number; write a finite number (or leave the optional field out)")


def _finite(d: dict, key: str, *, optional: bool = False, positive: bool = False) -> float | None:
    if key not in d or d[key] is None:
        if optional:
            return None
        raise _BadLine(f"missing field '{key}'; add it (units are in the name)")
    value = d[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise _BadLine(f"field '{key}' must be a number, got {json.dumps(value)}")
    value = float(value)
    if not math.isfinite(value):
        raise _BadLine(f"field '{key}' must be finite")
    if positive and not value > 0.0:
        raise _BadLine(f"field '{key}' must be > 0, got {value!r}")
    return value


def _integer(d: dict, key: str, *, optional: bool = False) -> int | None:
    if key not in d or d[key] is None:
        if optional:
            return None
        raise _BadLine(f"missing field '{key}'")
    value = d[key]
    if isinstance(value, bool) or not isinstance(value, int):
        raise _BadLine(f"field '{key}' must be an integer, got {json.dumps(value)}")
    return value


def _object(d: dict, key: str, required_keys: tuple[str, ...] = ()) -> dict:
    value = d.get(key)
    if not isinstance(value, dict):
        raise _BadLine(f"header field '{key}' must be a JSON object")
    for k in required_keys:
        if k not in value:
            raise _BadLine(f"header field '{key}' lacks '{k}'; see docs/log-format.md")
    return value


def _vector3(value: Any, what: str) -> tuple[float, float, float]:
    if not (isinstance(value, list) and len(value) == 3):
        raise _BadLine(f"{what} must be a list of 3 numbers")
    return tuple(_finite({"v": v}, "v") for v in value)  # type: ignore[return-value]


def _check_fields(d: dict, allowed: Iterable[str], kind: str) -> None:
    unknown = sorted(set(d) - set(allowed) - {"type"})
    if unknown:
        raise _BadLine(
            f"unknown field(s) {', '.join(unknown)} in this {kind} record; "
            f"allowed: {', '.join(sorted(allowed))}"
        )


def _paired(d: dict, value_key: str, sigma_key: str) -> tuple[float | None, float | None]:
    value = _finite(d, value_key, optional=True)
    sigma = _finite(d, sigma_key, optional=True, positive=True)
    if (value is None) != (sigma is None):
        raise _BadLine(f"'{value_key}' and '{sigma_key}' go together: give both or neither")
    return value, sigma


def _covariance(value: Any) -> Matrix3:
    if not (isinstance(value, list) and len(value) == 3):
        raise _BadLine("'covariance' must be a 3×3 list of lists over (dx, dy, dtheta)")
    rows = tuple(_vector3(row, "each covariance row") for row in value)
    m = np.array(rows)
    if not np.allclose(m, m.T, rtol=1e-9, atol=1e-15):
        raise _BadLine("'covariance' must be symmetric")
    try:
        np.linalg.cholesky(m)
    except np.linalg.LinAlgError:
        raise _BadLine(
            "'covariance' must be positive definite (every motion has some uncertainty; "
            "put a small variance on each diagonal entry)"
        ) from None
    return rows  # type: ignore[return-value]


def parse_header(d: dict) -> Header:
    if d.get("type") != "header" or d.get("format") != FORMAT_NAME:
        raise _BadLine(
            f"the first line must be the header, {{\"type\": \"header\", \"format\": \"{FORMAT_NAME}\", ...}}; "
            "is this an fgslam run log?"
        )
    version = d.get("version")
    if version != FORMAT_VERSION:
        raise _BadLine(
            f"format version {version!r} is not supported; this fgslam reads version "
            f"{FORMAT_VERSION} (upgrade fgslam to read newer logs)"
        )
    _check_fields(d, ("format", "version", "units", "start", "robot", "sensor", "noise", "source"), "header")
    if d.get("units") != UNITS:
        raise _BadLine(f"header 'units' must be {json.dumps(UNITS)}: convert at the edge, store SI")
    start = _object(d, "start", ("stamp_s", "pose", "sigma"))
    sigma = _vector3(start["sigma"], "start.sigma")
    if min(sigma) <= 0.0:
        raise _BadLine("start.sigma must be > 0 (a tiny value such as 1e-6 pins the start pose)")
    return Header(
        stamp_s=_finite(start, "stamp_s"),  # type: ignore[arg-type]
        start_pose=_vector3(start["pose"], "start.pose"),
        start_sigma=sigma,
        robot=_object(d, "robot", ("name",)),
        sensor=_object(d, "sensor", ("kind",)),
        noise=_object(d, "noise", ("odometry", "observation")),
        source=_object(d, "source") if "source" in d else {},
        version=version,
    )


def parse_record(d: dict) -> Record:
    kind = d.get("type")
    cls = _CLASS_OF.get(kind)  # type: ignore[arg-type]
    if cls is None:
        raise _BadLine(
            f"unknown record type {json.dumps(kind)}; expected one of {', '.join(sorted(_CLASS_OF))}"
        )
    _check_fields(d, cls.__dataclass_fields__, kind)
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
        height, sigma_height = _paired(d, "height_m", "sigma_height_m")
        yaw, sigma_yaw = _paired(d, "tag_yaw_rad", "sigma_tag_yaw_rad")
        bearing, sigma_bearing = _paired(d, "bearing_rad", "sigma_bearing_rad")
        if bearing is None and yaw is not None:
            raise _BadLine("a range-only observation (no 'bearing_rad') cannot have a tag yaw")
        return Observation(
            stamp_s=_finite(d, "stamp_s"),
            landmark_id=_integer(d, "landmark_id", optional=True),
            range_m=_finite(d, "range_m", positive=True),
            bearing_rad=bearing,
            sigma_range_m=_finite(d, "sigma_range_m", positive=True),
            sigma_bearing_rad=sigma_bearing,
            height_m=height,
            sigma_height_m=sigma_height,
            tag_yaw_rad=yaw,
            sigma_tag_yaw_rad=sigma_yaw,
            truth_landmark_id=_integer(d, "truth_landmark_id", optional=True),
        )  # type: ignore[arg-type]
    if cls is LiveStep:
        index = _integer(d, "pose_index")
        latency = _finite(d, "latency_s")
        if index < 0 or latency < 0:
            raise _BadLine("'pose_index' and 'latency_s' must be >= 0")
        return LiveStep(stamp_s=_finite(d, "stamp_s"), pose_index=index, latency_s=latency)  # type: ignore[arg-type]
    if cls is TruthPose:
        return TruthPose(
            stamp_s=_finite(d, "stamp_s"),
            x_m=_finite(d, "x_m"),
            y_m=_finite(d, "y_m"),
            theta_rad=_finite(d, "theta_rad"),
        )  # type: ignore[arg-type]
    return TruthLandmark(
        landmark_id=_integer(d, "landmark_id"),
        x_m=_finite(d, "x_m"),
        y_m=_finite(d, "y_m"),
        height_m=_finite(d, "height_m", optional=True),
        yaw_rad=_finite(d, "yaw_rad", optional=True),
    )  # type: ignore[arg-type]


def _loads(text: str) -> dict:
    try:
        d = json.loads(text, parse_constant=_reject_constant)
    except json.JSONDecodeError as exc:
        raise _BadLine(f"not valid JSON ({exc.msg} at column {exc.colno}); each line must be one JSON object") from None
    if not isinstance(d, dict):
        raise _BadLine("each line must be one JSON object {...}")
    return d


def _lines(f: IO[str]) -> Iterator[tuple[int, str, bool]]:
    """Yield (line number, text without newline, ended with a newline)."""
    for number, raw in enumerate(f, start=1):
        ended = raw.endswith("\n")
        yield number, raw.rstrip("\r\n"), ended


def read_log(path: str | os.PathLike[str]) -> RunLog:
    """Read and validate a run log.

    Raises :class:`LogFormatError` at the first bad line, carrying the records before it
    in ``partial``. A last line without a newline that does not parse (a recording cut
    off mid-line) is dropped and reported in :attr:`RunLog.truncated` instead.
    """
    path = os.fspath(path)
    try:
        f = open(path, encoding="utf-8")
    except OSError as exc:
        raise FgslamError(f"{path}: cannot open the log ({exc.strerror})") from None
    header: Header | None = None
    records: list[Record] = []
    last_stamp = -math.inf
    truncated: str | None = None
    with f:
        try:
            lines = list(_lines(f))
        except UnicodeDecodeError as exc:
            raise LogFormatError(path, 1, f"not UTF-8 text ({exc.reason}); is this a run log?") from None
    if not lines:
        raise LogFormatError(path, 1, "the file is empty; a run log starts with a header line")
    for number, text, ended in lines:
        try:
            if not text.strip():
                raise _BadLine("empty line; remove it (every line must be one JSON object)")
            d = _loads(text)
            if header is None:
                header = parse_header(d)
                last_stamp = header.stamp_s
                continue
            if d.get("type") == "header":
                raise _BadLine("a second header; a log holds one run — split the file")
            record = parse_record(d)
            stamp = getattr(record, "stamp_s", None)
            if stamp is not None:
                if stamp < last_stamp:
                    raise _BadLine(
                        f"stamp_s {stamp!r} goes back in time (previous {last_stamp!r}); "
                        "records must be written in time order"
                    )
                last_stamp = stamp
            records.append(record)
        except _BadLine as bad:
            is_last = number == len(lines)
            if is_last and not ended and header is not None:
                truncated = (
                    f"{path}:{number}: the last line is cut off (recording interrupted?); "
                    f"using the {number - 1} complete lines before it"
                )
                break
            partial = None if header is None else RunLog(path, header, tuple(records))
            raise LogFormatError(path, number, str(bad), partial) from None
    assert header is not None
    return RunLog(path, header, tuple(records), truncated)


def as_matrix3(m: Any) -> Matrix3:
    """A 3×3 array-like as the nested tuple of floats that records hold."""
    a = np.asarray(m, dtype=float)
    if a.shape != (3, 3):
        raise ValueError(f"expected a 3×3 matrix, got shape {a.shape}")
    return tuple(tuple(float(v) for v in row) for row in a)  # type: ignore[return-value]
