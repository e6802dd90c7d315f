"""One field of a log line, validated: a finite number within physical bounds, a σ, an
angle, an id, a covariance. Each failure raises ``_BadLine`` with what is wrong and how to
fix it; :func:`slamio.log.read.read_log` adds the file and line. The 3-D records
(:mod:`slamio.log.records3d`) use the same checks.
"""

from __future__ import annotations

import json
import math
from typing import Any, Iterable

#: A 3×3 covariance as written (rows of three floats).
Matrix3 = tuple[tuple[float, float, float], tuple[float, float, float], tuple[float, float, float]]

# Bounds the reader enforces (docs/log-format.md, "Bounds"). Each is a physical limit with
# a wide margin, and keeps every square and inverse the estimators compute far from float
# overflow, underflow and singular matrices.

#: Landmark ids (and 3-D track ids) are 0 ≤ id ≤ MAX_ID: a signed 32-bit integer, what
#: ROS's AprilTag messages (``int32[] id``) and every detector hand out. The estimators map
#: ids to their own dense indices, never allocating by the largest id.
MAX_ID = 2**31 - 1
#: Pose indices (``live_step.pose_index``) are 0 ≤ k ≤ MAX_POSE_INDEX: a GTSAM key is an
#: 8-bit letter and a 56-bit index (``X(k)``).
MAX_POSE_INDEX = 2**56 - 1
#: Stamps (s): within ±1e10 s. A stamp is Unix time (1.7e9 s in 2024; 1e10 s is the year
#: 2286) or time since a start; milliseconds or nanoseconds written as seconds go beyond it,
#: and 1e308 s overflows the first duration computed from it.
STAMP_S = 1e10
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
#: Odometry increments (m): ``dx_m``, ``dy_m`` and the Create's ``distance_m`` of one record
#: within ±1 km (100 m/s for 10 s; no ground robot moves that far between two readings).
INCREMENT_M = 1e3
#: Turn of one odometry record (rad): ``dtheta_rad`` and ``angle_rad`` within ±1000 rad
#: (160 turns between two readings).
INCREMENT_RAD = 1e3
#: World coordinates (m) of the start pose, truth poses and landmarks, and heights: within
#: ±10 000 km of the origin (a UTM northing is below that). Squares of them stay far from
#: float overflow, and a landmark placed 1 m from a robot there is still 1 m away in floats.
COORDINATE_M = 1e7
#: Headings and yaws in the world frame (rad): within ±10⁶ rad (unwrapped headings of the
#: longest runs stay far below).
WORLD_ANGLE_RAD = 1e6
#: An observation is rejected when its range is further outside the sensor's
#: [min_range_m, max_range_m] than this many of its own σ (noise puts a real one just
#: outside now and then; 5σ happens once in 1.7 million draws) — and below the minimum,
#: by never more than half of it (a working sensor's noise does not halve a range).
SENSOR_LIMIT_SIGMAS = 5.0
#: How deeply the header's free-form objects may nest (lists and objects inside each other).
MAX_NESTING = 64


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


def _magnitude(d: dict, key: str, limit: float, unit: str, why: str, *, optional: bool = False) -> float | None:
    """``d[key]`` as a finite float within ±``limit`` (None when optional and absent)."""
    value = _finite(d, key, optional=optional)
    if value is not None and abs(value) > limit:
        raise _BadLine(f"field '{key}' is {value!r}, beyond ±{limit:g} {unit}: {why}")
    return value


_WHY_INCREMENT = ("one odometry record is the motion between two readings, and no ground robot moves 1 km "
                  "or turns 1000 rad between two; is the record corrupted, or in other units?")
_WHY_COORDINATE = "no place on Earth is 10 000 km from a sensible origin; is the value corrupted, or in other units?"
_WHY_WORLD_ANGLE = "a heading or yaw of a million radians is no angle a run reaches; is the value corrupted?"


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
            f"field '{key}' is {_show(value)}, outside 0..2^31-1: ids are integers 0 ≤ id < 2^31 "
            "(a signed 32-bit integer, as ROS's AprilTag ids); renumber the landmarks"
        )
    return value


def _choice(d: dict, key: str, choices: tuple[str, ...], *, optional: bool = False) -> str | None:
    """``d[key]``, one of the strings ``choices`` (None when optional and absent)."""
    if key not in d or d[key] is None:
        if optional:
            return None
        raise _BadLine(f"missing field '{key}'; write one of {', '.join(choices)}")
    value = d[key]
    if not isinstance(value, str) or value not in choices:
        raise _BadLine(f"field '{key}' is {_show(value)}; write one of {', '.join(choices)}")
    return value


def _pose_index(d: dict, key: str = "pose_index") -> int:
    """A pose index, 0 ≤ k ≤ :data:`MAX_POSE_INDEX` (a GTSAM key's 56 bits)."""
    index = _integer(d, key)
    if index < 0:  # type: ignore[operator]
        raise _BadLine(f"field '{key}' is {_show(index)}; a pose index is >= 0 (pose 0 is the start)")
    if index > MAX_POSE_INDEX:  # type: ignore[operator]
        raise _BadLine(f"'{key}' is {_show(index)}, above 2^56-1 (a GTSAM key holds a 56-bit index)")
    return index  # type: ignore[return-value]


_WHY_STAMP = ("a stamp is seconds of Unix time (1.7e9 s today) or since the start of the run; "
              "milliseconds or nanoseconds written as seconds? (is the line corrupted?)")


def _stamp(d: dict, key: str = "stamp_s") -> float:
    """A stamp in seconds, finite and within ±:data:`STAMP_S`."""
    return _magnitude(d, key, STAMP_S, "s", _WHY_STAMP)  # type: ignore[return-value]


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
    import numpy as np

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
