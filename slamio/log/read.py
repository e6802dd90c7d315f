"""Reading a run log: every line validated, the first bad one reported as ``file:line``
with how to fix it, everything good before it kept (:class:`LogFormatError`'s ``partial``).

Two lines that contradict each other (a stamp earlier than the previous one, two different
truths of one landmark) are reported at the earlier of the two, naming both: either may be
the wrong one, so only the lines before it are known good.
"""

from __future__ import annotations

import json
import math
import os
import sys
from typing import Any

from slamio.errors import FgslamError, InputFileError, read_bytes
from slamio.log.fields import (
    _WHY_COORDINATE, _WHY_INCREMENT, _WHY_WORLD_ANGLE, COORDINATE_M, INCREMENT_M, INCREMENT_RAD, WORLD_ANGLE_RAD,
    _magnitude, _WHY_RANGE, MAX_POSE_INDEX, RANGE_M, STAMP_S, SENSOR_LIMIT_SIGMAS, SIGMA_ANGLE_RAD, SIGMA_LENGTH_M,
    _angle, _BadLine,
    _check_fields, _covariance, _integer, _NotJson, _number, _object, _paired, _reject_constant, _show,
    _sigma_angle, _sigma_length, _stamp, _vector3, _within,
)
from slamio.log.records import (
    _CLASS_OF, _PLANAR_TYPES, _TYPES_3D, FORMAT_NAME, UNITS, VERSIONS, Header, LiveStep, Observation, Odometry,
    Record, Rejected, RunLog, TruthLandmark, TruthPose,
)
import slamio.log.records3d as log3d
from slamio.log.mount import pose_on_robot

#: The largest run log read (it is read whole): 1 GiB, about five million records — more
#: than a day of a robot's odometry at 50 Hz. Split a longer recording.
MAX_LOG_BYTES = 2**30


class LogFormatError(InputFileError):
    """A run log that cannot be read past some line.

    ``line`` is the first line that may be wrong: the bad line, or the earlier of two lines
    that contradict each other (the message names both). ``partial`` is the :class:`RunLog`
    of everything before it (``None`` when that is the header), so a caller can still use the
    good part.
    """

    def __init__(self, path: str, line: int, message: str, partial: "RunLog | None" = None):
        super().__init__(f"{path}:{line}: {message}")
        self.path = path
        self.line = line
        self.partial = partial


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
    try:
        pose_on_robot(sensor)
    except ValueError as bad:
        raise _BadLine(str(bad)) from None
    low, high = _sensor_limit(sensor, "min_range_m"), _sensor_limit(sensor, "max_range_m")
    if low is not None and high is not None and not low < high:
        raise _BadLine(f"header field 'sensor.min_range_m' ({low!r}) must be below 'sensor.max_range_m' ({high!r})")
    return Header(
        stamp_s=_stamp(start),  # type: ignore[arg-type]
        start_pose=_start_pose(start["pose"]),
        start_sigma=sigma,
        robot=_object(d, "robot", ("name",)),
        sensor=sensor,
        noise=_object(d, "noise", ("odometry", "observation")),
        source=_object(d, "source") if "source" in d else {},
        version=version,
    )


def _start_pose(value: Any) -> tuple[float, float, float]:
    """``start.pose``: x, y within :data:`COORDINATE_M`, theta within :data:`WORLD_ANGLE_RAD`."""
    pose = _vector3(value, "start.pose")
    if max(abs(pose[0]), abs(pose[1])) > COORDINATE_M or abs(pose[2]) > WORLD_ANGLE_RAD:
        raise _BadLine(
            f"start.pose {list(pose)!r} is beyond ±{COORDINATE_M:g} m for x, y or ±{WORLD_ANGLE_RAD:g} rad for "
            f"theta: {_WHY_COORDINATE}"
        )
    return pose


def _parse_header3(d: dict, version: int) -> Header:
    """The header of a 3-D log: ``start.pose3``/``sigma3`` and a stereo ``sensor``."""
    if version < 2:
        raise _BadLine("'start.pose3' (a 3-D log) needs \"version\": 2; version 1 logs are planar")
    start = _object(d, "start", ("stamp_s", "pose3", "sigma3"))
    _check_fields(start, ("stamp_s", "pose3", "sigma3"), "header 'start' of a 3-D log")
    pose3 = log3d.parse_pose3(start["pose3"], "start.pose3")
    sigma3 = log3d.parse_sigma3(start["sigma3"], "start.sigma3")
    sensor = _object(d, "sensor", ("kind",))
    log3d.parse_stereo_sensor(sensor)
    return Header(
        stamp_s=_stamp(start),  # type: ignore[arg-type]
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
    cls = _CLASS_OF.get(kind) or log3d.RECORDS_3D.get(kind)
    if cls is None:
        raise _BadLine(
            f"unknown record type {_show(kind)}; expected one of {', '.join(sorted(_PLANAR_TYPES + _TYPES_3D[:-1]))}"
        )
    _check_fields(d, cls.__dataclass_fields__, kind)
    if kind in log3d.RECORDS_3D:
        return log3d.parse_record3(kind, d)
    if cls is Odometry:
        distance = _magnitude(d, "distance_m", INCREMENT_M, "m", _WHY_INCREMENT, optional=True)
        angle = _magnitude(d, "angle_rad", INCREMENT_RAD, "rad", _WHY_INCREMENT, optional=True)
        if (distance is None) != (angle is None):
            raise _BadLine("'distance_m' and 'angle_rad' (the Create's reading) go together: give both or neither")
        if "covariance" not in d:
            raise _BadLine("missing field 'covariance' (3×3 over dx, dy, dtheta)")
        return Odometry(
            stamp_s=_stamp(d),
            dx_m=_magnitude(d, "dx_m", INCREMENT_M, "m", _WHY_INCREMENT),
            dy_m=_magnitude(d, "dy_m", INCREMENT_M, "m", _WHY_INCREMENT),
            dtheta_rad=_magnitude(d, "dtheta_rad", INCREMENT_RAD, "rad", _WHY_INCREMENT),
            covariance=_covariance(d["covariance"]),
            distance_m=distance,
            angle_rad=angle,
        )  # type: ignore[arg-type]
    if cls is Observation:
        if "landmark_id" not in d:
            raise _BadLine("missing field 'landmark_id' (an integer, or null when unknown)")
        height = _magnitude(d, "height_m", COORDINATE_M, "m", _WHY_COORDINATE, optional=True)
        sigma_height = _sigma_length(d, "sigma_height_m", optional=True)
        _paired(height, sigma_height, "height_m", "sigma_height_m")
        yaw, sigma_yaw = _angle(d, "tag_yaw_rad", optional=True), _sigma_angle(d, "sigma_tag_yaw_rad", optional=True)
        _paired(yaw, sigma_yaw, "tag_yaw_rad", "sigma_tag_yaw_rad")
        bearing, sigma_bearing = _angle(d, "bearing_rad", optional=True), _sigma_angle(d, "sigma_bearing_rad", optional=True)
        _paired(bearing, sigma_bearing, "bearing_rad", "sigma_bearing_rad")
        if bearing is None and yaw is not None:
            raise _BadLine("a range-only observation (no 'bearing_rad') cannot have a tag yaw")
        return Observation(
            stamp_s=_stamp(d),
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
        latency = _magnitude(d, "latency_s", STAMP_S, "s", "a latency is the seconds one step took")
        if index < 0 or latency < 0:  # type: ignore[operator]
            raise _BadLine("'pose_index' and 'latency_s' must be >= 0")
        if index > MAX_POSE_INDEX:  # type: ignore[operator]
            raise _BadLine(f"'pose_index' is {_show(index)}, above 2^56-1 (a GTSAM key holds a 56-bit index)")
        return LiveStep(stamp_s=_stamp(d), pose_index=index, latency_s=latency)  # type: ignore[arg-type]
    if cls is TruthPose:
        return TruthPose(
            stamp_s=_stamp(d),
            x_m=_magnitude(d, "x_m", COORDINATE_M, "m", _WHY_COORDINATE),
            y_m=_magnitude(d, "y_m", COORDINATE_M, "m", _WHY_COORDINATE),
            theta_rad=_magnitude(d, "theta_rad", WORLD_ANGLE_RAD, "rad", _WHY_WORLD_ANGLE, optional=True),
        )  # type: ignore[arg-type]
    return TruthLandmark(
        landmark_id=_integer(d, "landmark_id", id_range=True),
        x_m=_magnitude(d, "x_m", COORDINATE_M, "m", _WHY_COORDINATE),
        y_m=_magnitude(d, "y_m", COORDINATE_M, "m", _WHY_COORDINATE),
        height_m=_magnitude(d, "height_m", COORDINATE_M, "m", _WHY_COORDINATE, optional=True),
        yaw_rad=_magnitude(d, "yaw_rad", WORLD_ANGLE_RAD, "rad", _WHY_WORLD_ANGLE, optional=True),
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


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict:
    """A JSON object as a dict, refusing a key given twice (plain ``json`` keeps the last one
    without a word, so a record could silently say something other than what was written)."""
    d = dict(pairs)
    if len(d) != len(pairs):
        seen: set[str] = set()
        twice = next(k for k, _ in pairs if k in seen or seen.add(k))
        raise _BadLine(f"field {twice!r} is given twice in one object; keep the one that is right and delete the other")
    return d


def _loads(text: str) -> dict:
    if not text.strip():
        raise _NotJson("empty line; remove it (every line must be one JSON object)")
    try:
        d = json.loads(text, parse_constant=_reject_constant, object_pairs_hook=_unique_keys)
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


class _Conflict(_BadLine):
    """Internal: this line contradicts an earlier one, and either may be wrong; the error is
    reported at ``line`` (the earlier one) with the ``records``/``rejected`` counts read
    before it."""

    def __init__(self, message: str, line: int, records: int, rejected: int):
        super().__init__(message)
        self.line, self.records, self.rejected = line, records, rejected


#: Record types that give the truth of one landmark: one record per ``landmark_id``.
_TRUTH_LANDMARK_TYPES = ("truth_landmark", "truth_landmark3")


def _landmark_conflict(kind: str, earlier: tuple[int, Record, int, int], number: int, record: Record) -> _BadLine:
    """The error for a second ``kind`` record of one landmark id, on line ``number``.

    An exact repeat is reported at the repeat (the first is good); a different truth at the
    first definition, since either line may be the wrong one.
    """
    line, first, n_records, n_rejected = earlier
    lid = record.landmark_id  # type: ignore[union-attr]
    if record == first:
        return _BadLine(
            f"line {number} repeats line {line}'s {kind} of landmark_id {lid} exactly; each landmark's truth "
            f"is given once: delete line {number}"
        )
    shown = [  # the position, and whatever else differs
        f for f in record.__dataclass_fields__
        if f in ("x_m", "y_m", "z_m") or (f != "landmark_id" and getattr(first, f) != getattr(record, f))
    ]

    def values(r: Record) -> str:
        return ", ".join(f"{f} {_show(getattr(r, f))}" for f in shown)

    return _Conflict(
        f"landmark_id {lid} has two {kind} records: line {line} gives {values(first)}, line {number} gives "
        f"{values(record)}; a landmark has one true place, so one of them is wrong (the map error would be "
        "measured against the last one): fix its landmark_id (one record per landmark) or delete it",
        line, n_records, n_rejected,
    )


#: How far a velocity record's ``dt_s`` may differ from the time since the previous pose (s).
DT_TOLERANCE_S = 1e-6


def _check_interval(record: Record, pose_stamp: float) -> float:
    """A 3-D log's velocity record spans the time since the previous pose; the latest pose's stamp."""
    if not isinstance(record, log3d.VelocityOdometry):
        return pose_stamp
    gap = record.stamp_s - pose_stamp
    if abs(record.dt_s - gap) > DT_TOLERANCE_S + 1e-15 * abs(record.stamp_s):  # + the stamps' rounding
        raise _BadLine(
            f"field 'dt_s' is {record.dt_s!r} s but the previous pose is {gap!r} s earlier: the velocity is "
            "held from the previous pose to this one, so dt_s must be the difference of their stamps"
        )
    return record.stamp_s


def check_records(source: str, header: Header, records) -> tuple[Record, ...]:
    """``records`` (made by an importer from the file ``source``), each checked by the rules
    :func:`read_log` applies to its line, so an import never writes a log the reader would
    refuse (a value beyond a bound, a 1e308 stamp). One :class:`InputFileError` naming the
    source, the record and the field at the first that fails."""
    from slamio.log.write import format_line

    records = tuple(records)
    for number, item in enumerate((header, *records)):
        d = json.loads(format_line(item))
        try:
            parse_header(d) if number == 0 else parse_record(d)
        except _BadLine as bad:
            what = "the header it makes" if number == 0 else f"record {number} it makes ({d.get('type')})"
            raise InputFileError(f"{source}: {what} is not valid: {bad}; the dataset holds a value no run log may "
                                 "(is the file corrupted?)") from None
    return records


def read_log(path: str | os.PathLike[str]) -> RunLog:
    """Read and validate a run log.

    The path must be a regular file of at most :data:`MAX_LOG_BYTES` (a FIFO, a device such
    as ``/dev/zero`` or a loop of symbolic links is one :class:`InputFileError` line, never
    a wait or a read without end: :mod:`slamio.safe_input`).

    Raises :class:`LogFormatError` at the first bad line, carrying the records before it
    in ``partial``. A last line without a newline that is not valid JSON (a recording cut
    off mid-line) is dropped and reported in :attr:`RunLog.truncated` instead; a complete
    JSON object on that line is checked like any other. Observations the header's sensor
    cannot have made (range outside its limits by more than :data:`SENSOR_LIMIT_SIGMAS` σ,
    or below half its minimum) are left out of the records and listed in
    :attr:`RunLog.rejected`.

    Stamps must not decrease, and each landmark has at most one ``truth_landmark`` (3-D:
    ``truth_landmark3``). When two lines contradict each other (a stamp earlier than the
    previous stamp; two different truths of one landmark id) the error is at the earlier
    line and names both, and ``partial`` holds only what precedes it; an exact repeat of a
    truth is an error at the repeat.
    """
    path = os.fspath(path)
    data = read_bytes(path, "run log", limit=MAX_LOG_BYTES)  # a regular file (never a FIFO or /dev/zero)
    lines = _lines(data)
    del data
    if not lines:
        raise LogFormatError(path, 1, "the file is empty; a run log starts with a header line")
    state = _ReadState(path)
    truncated: str | None = None
    for number, raw, ended in lines:
        try:
            state.take(number, _loads(_decode(raw, number)))
        except _BadLine as bad:
            if isinstance(bad, _NotJson) and number == len(lines) and not ended and state.header is not None:
                truncated = (
                    f"{path}:{number}: the last line is cut off (recording interrupted?); "
                    f"using the {number - 1} complete lines before it"
                )
                break
            raise state.error(number, bad) from None
    assert state.header is not None
    return RunLog(path, state.header, tuple(state.records), truncated, tuple(state.rejected))


class _ReadState:
    """What :func:`read_log` knows after each line: the header, the records and rejections so
    far, and what the next lines are checked against (the last stamp, the latest pose's
    stamp, the truths of landmarks seen)."""

    def __init__(self, path: str) -> None:
        self.path = path
        self.header: Header | None = None
        self.records: list[Record] = []
        self.rejected: list[Rejected] = []
        self.limits: tuple[float | None, float | None] = (None, None)
        self.last_stamp = -math.inf
        self.pose_stamp = -math.inf  # stamp of the latest pose (3-D logs: velocity_odometry.dt_s must span from it)
        self.stamp_at = (1, 0, 0)  # last_stamp's (line, records and rejections before it); line 1: the header's
        self.truth_at: dict[int, tuple[int, Record, int, int]] = {}  # landmark id -> (line, record, records, rejections)

    def take(self, number: int, d: dict) -> None:
        """Line ``number`` (parsed JSON ``d``): the header, or one record checked against the lines before."""
        if self.header is None:
            self.header = parse_header(d)
            self.limits = sensor_range_limits(self.header)
            self.last_stamp = self.pose_stamp = self.header.stamp_s
            return
        if d.get("type") == "header":
            raise _BadLine("a second header; a log holds one run — split the file")
        _check_dimension(d.get("type"), self.header)
        record = parse_record(d)
        self._check_stamp(number, record)
        if d.get("type") in _TRUTH_LANDMARK_TYPES:
            lid = record.landmark_id  # type: ignore[union-attr]
            if lid in self.truth_at:
                raise _landmark_conflict(d["type"], self.truth_at[lid], number, record)
            self.truth_at[lid] = (number, record, len(self.records), len(self.rejected))
        if self.header.is_3d:
            self.pose_stamp = _check_interval(record, self.pose_stamp)
        if isinstance(record, Observation):
            outside = _outside_sensor(record, *self.limits)
            if outside is not None:
                reason, message = outside
                self.rejected.append(Rejected(number, reason, f"{self.path}:{number}: {message}", record))
                return
        self.records.append(record)

    def _check_stamp(self, number: int, record: Record) -> None:
        """Stamps must not decrease: a conflict is reported at the earlier line."""
        stamp = getattr(record, "stamp_s", None)
        if stamp is None:
            return
        if stamp < self.last_stamp:
            raise _Conflict(
                f"line {number}'s stamp_s {stamp!r} is earlier than "
                + (f"line {self.stamp_at[0]}'s {self.last_stamp!r}" if self.stamp_at[0] > 1
                   else f"the header's start.stamp_s {self.last_stamp!r} (line 1)")
                + ": one of them is wrong; records must be written in time order (fix the wrong stamp "
                "or delete its line)",
                *self.stamp_at,
            )
        self.last_stamp, self.stamp_at = stamp, (number, len(self.records), len(self.rejected))

    def error(self, number: int, bad: _BadLine) -> LogFormatError:
        """The :class:`LogFormatError` of a bad line, carrying what precedes the line it is reported at."""
        line, kept, kept_rejected = number, len(self.records), len(self.rejected)
        if isinstance(bad, _Conflict):  # reported at the earlier line: only what precedes it is known good
            line, kept, kept_rejected = bad.line, bad.records, bad.rejected
        partial = (
            None if self.header is None or line == 1
            else RunLog(self.path, self.header, tuple(self.records[:kept]), None, tuple(self.rejected[:kept_rejected]))
        )
        return LogFormatError(self.path, line, str(bad), partial)
