"""The slow path of the log reader: one parsed JSON line checked field by field, with a
message for each thing that can be wrong (what, and how to fix it). :mod:`slamio.log.read`
runs it on the header and on any line the fast path (:mod:`slamio.log.fast`) does not accept.
"""

from __future__ import annotations

import json
import math
from typing import Any

from slamio.errors import FgslamError, InputFileError
from slamio.log.fields import (
    _WHY_COORDINATE, _WHY_INCREMENT, _WHY_WORLD_ANGLE, COORDINATE_M, INCREMENT_M, INCREMENT_RAD, WORLD_ANGLE_RAD,
    _magnitude, _WHY_RANGE, MAX_POSE_INDEX, RANGE_M, STAMP_S, SIGMA_ANGLE_RAD, SIGMA_LENGTH_M,
    _angle, _BadLine, _choice,
    _check_fields, _covariance, _integer, _number, _object, _paired, _pose_index, _show,
    _sigma_angle, _sigma_length, _stamp, _vector3, _within,
)
from slamio.log.records import (
    _CLASS_OF, _PLANAR_TYPES, _TYPES_3D, EVENT_KINDS, EVENT_SIDES, FORMAT_NAME, UNITS, VERSIONS, Event, Header,
    LiveStep, Observation, Odometry, Record, TruthLandmark, TruthPose,
)
import slamio.log.records3d as log3d
from slamio.log.mount import pose_on_robot

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
    log3d.check_stereo_sensor(sensor)
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
        return _observation(d)
    if cls is LiveStep:
        return _live_step(d)
    if cls is Event:
        return Event(stamp_s=_stamp(d), kind=_choice(d, "kind", EVENT_KINDS), pose_index=_pose_index(d),
                     side=_choice(d, "side", EVENT_SIDES, optional=True))  # type: ignore[arg-type]
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


def _observation(d: dict) -> Observation:
    """An ``observation`` record's fields, checked."""
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


def _live_step(d: dict) -> LiveStep:
    """A ``live_step`` record's fields, checked."""
    index = _integer(d, "pose_index")
    latency = _magnitude(d, "latency_s", STAMP_S, "s", "a latency is the seconds one step took")
    if index < 0 or latency < 0:  # type: ignore[operator]
        raise _BadLine("'pose_index' and 'latency_s' must be >= 0")
    if index > MAX_POSE_INDEX:  # type: ignore[operator]
        raise _BadLine(f"'pose_index' is {_show(index)}, above 2^56-1 (a GTSAM key holds a 56-bit index)")
    return LiveStep(stamp_s=_stamp(d), pose_index=index, latency_s=latency)  # type: ignore[arg-type]


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
