"""Run-log format v2: the 3-D records (specified in docs/log-format.md, "3-D logs").

A **3-D log** has a version-2 header whose ``start`` gives ``pose3`` (the IMU's pose 0 in
the world, ``[x_m, y_m, z_m, qx, qy, qz, qw]``) and ``sigma3`` instead of the planar
``pose``/``sigma``, and a ``sensor`` of kind ``"stereo"`` holding the calibration. Its
records are:

* ``velocity_odometry`` — the IMU's body twist (v, ω) held for ``dt_s`` from the previous
  pose to a new one (``T_new = T_prev · exp(dt_s · û)``), with its 6×6 covariance; like
  ``odometry`` in a planar log it starts a new pose;
* ``stereo_observation`` — one feature track seen now at rectified stereo pixels
  (u_L, v_L, u_R, v_R), with one σ ``sigma_px`` on each or a 4×4 ``covariance_px2``;
* ``truth_pose3``       — optional ground truth of the current pose (world_T_imu);
* ``truth_landmark3``   — optional ground truth of one landmark (a world point);
* ``live_step``         — as in a planar log.

This module holds the records and their parsers; :mod:`slamio.log` reads and writes every
log, dispatching here for these types, and refuses to mix planar and 3-D records. Import
them from ``slamio.log``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from slamio.errors import FgslamError
import slamio.log.fields as _fields  # the package's own bounds checks (fields imports nothing of it)

if TYPE_CHECKING:  # numpy and slamio.se3 load when used: reading and validating a planar log needs neither
    import numpy as np

__all__ = [
    "RECORDS_3D",
    "TYPE_OF_3D",
    "StereoCalibration",
    "StereoObservation",
    "TruthLandmark3",
    "TruthPose3",
    "VelocityOdometry",
    "pose3_from_matrix",
    "pose3_matrix",
    "stereo_calibration",
]

Vector3 = tuple[float, float, float]
#: A pose as written: ``(x_m, y_m, z_m, qx, qy, qz, qw)`` (TUM's order).
Pose3 = tuple[float, float, float, float, float, float, float]
Matrix6 = tuple[tuple[float, ...], ...]
Matrix4 = tuple[tuple[float, ...], ...]

#: A quaternion's norm may differ from 1 by at most this (a written unit quaternion reads
#: back within 1e-15; more means it was never normalised, or is not a rotation at all).
QUATERNION_NORM_TOLERANCE = 1e-6
#: Pixel coordinates: |u|, |v| ≤ 1e6 px (no sensor has a million pixels on a side).
MAX_PIXEL_PX = 1e6
#: σ of a pixel coordinate: 1e-6 px to 1e4 px (finer than any sub-pixel detector, coarser
#: than any image).
SIGMA_PIXEL_PX = (1e-6, 1e4)
#: The stereo baseline and the IMU's offset from the camera: within ±1 km (a vehicle is smaller).
MAX_MOUNT_M = 1e3
#: A velocity record's interval: 0 < dt_s ≤ 1e3 s.
MAX_DT_S = 1e3
#: Largest speed component (m/s) and turn rate component (rad/s): far beyond any vehicle.
MAX_SPEED_MPS = 1e4
MAX_TURN_RATE_RADPS = 1e4
#: The twist covariance: entries ≤ 1e6, smallest eigenvalue ≥ 1e-12 (as for planar odometry).
MAX_TWIST_VARIANCE = 1e6
MIN_TWIST_EIGENVALUE = 1e-12
#: The pixel covariance: entries ≤ (1e4 px)², smallest eigenvalue ≥ (1e-6 px)² (the bounds of
#: ``sigma_px`` squared).
MAX_PIXEL_VARIANCE_PX2 = SIGMA_PIXEL_PX[1] ** 2
MIN_PIXEL_EIGENVALUE_PX2 = SIGMA_PIXEL_PX[0] ** 2


# --------------------------------------------------------------------------- records


@dataclass(frozen=True)
class VelocityOdometry:
    """The IMU's twist over ``dt_s`` ending at ``stamp_s``; starts a new pose.

    ``v_mps`` and ``w_radps`` are the linear and angular velocity in the IMU (body) frame,
    held from the previous pose to the new one: ``T_new = T_prev · exp(dt_s · û)`` with
    ``u = (v, ω)``. ``covariance`` is the 6×6 covariance of ``u`` (translation first; m²/s²
    and rad²/s²).
    """

    stamp_s: float
    dt_s: float
    v_mps: Vector3
    w_radps: Vector3
    covariance: Matrix6

    def twist(self) -> np.ndarray:
        """``u = (v, ω)`` as a 6-vector."""
        import numpy as np

        return np.array(self.v_mps + self.w_radps, dtype=float)


@dataclass(frozen=True)
class StereoObservation:
    """Feature track ``track_id`` seen from the current pose at rectified stereo pixels.

    (u, v) in the left and right images, origin at the top-left pixel, u right, v down.
    The noise is one of: ``sigma_px``, the standard deviation of each of the four coordinates
    (independent), or ``covariance_px2``, their 4×4 covariance over (u_L, v_L, u_R, v_R) in px²
    (rectified stereo: v_L and v_R are read on one row, so strongly correlated, and u and v
    need not share a σ). A record holds exactly one of the two. A track id is the landmark's
    id (one physical point per track).
    """

    stamp_s: float
    track_id: int
    u_left_px: float
    v_left_px: float
    u_right_px: float
    v_right_px: float
    sigma_px: float | None = None
    covariance_px2: Matrix4 | None = None

    def __post_init__(self) -> None:
        if (self.sigma_px is None) == (self.covariance_px2 is None):
            raise ValueError("a stereo observation holds exactly one of sigma_px and covariance_px2")

    def pixels(self) -> np.ndarray:
        """``(u_L, v_L, u_R, v_R)`` as a 4-vector."""
        import numpy as np

        return np.array([self.u_left_px, self.v_left_px, self.u_right_px, self.v_right_px])

    def pixel_covariance(self) -> np.ndarray:
        """4×4 covariance of :meth:`pixels` (px²): ``covariance_px2``, or σ² I."""
        import numpy as np

        if self.covariance_px2 is not None:
            return np.array(self.covariance_px2, dtype=float)
        return float(self.sigma_px) ** 2 * np.eye(4)  # type: ignore[arg-type]


@dataclass(frozen=True)
class TruthPose3:
    """Ground truth of the current pose: world_T_imu as position and unit quaternion."""

    stamp_s: float
    x_m: float
    y_m: float
    z_m: float
    qx: float
    qy: float
    qz: float
    qw: float

    def matrix(self) -> np.ndarray:
        """The 4×4 world_T_imu."""
        return pose3_matrix((self.x_m, self.y_m, self.z_m, self.qx, self.qy, self.qz, self.qw))


@dataclass(frozen=True)
class TruthLandmark3:
    """Ground truth of one landmark: a point in the world frame."""

    landmark_id: int
    x_m: float
    y_m: float
    z_m: float


#: Record type name → class, for the 3-D records.
RECORDS_3D = {
    "velocity_odometry": VelocityOdometry,
    "stereo_observation": StereoObservation,
    "truth_pose3": TruthPose3,
    "truth_landmark3": TruthLandmark3,
}
TYPE_OF_3D = {cls: name for name, cls in RECORDS_3D.items()}


@dataclass(frozen=True)
class StereoCalibration:
    """A 3-D log's camera: left intrinsics, baseline, and the IMU's pose in the left optical frame."""

    K: np.ndarray  # (3, 3)
    baseline_m: float
    cam_T_imu: np.ndarray  # (4, 4)


# --------------------------------------------------------------------------- poses


def pose3_matrix(pose: Pose3) -> np.ndarray:
    """4×4 transform of ``(x, y, z, qx, qy, qz, qw)`` (the quaternion normalised first)."""
    import numpy as np

    from slamio.se3 import rotation_from_quaternion

    T = np.eye(4)
    T[:3, :3] = rotation_from_quaternion(*pose[3:])
    T[:3, 3] = pose[:3]
    return T


def pose3_from_matrix(T: Any) -> Pose3:
    """``(x, y, z, qx, qy, qz, qw)`` of a 4×4 rigid transform (qw ≥ 0)."""
    import numpy as np

    from slamio.se3 import quaternion_from_rotation

    T = np.asarray(T, dtype=float)
    q = np.array(quaternion_from_rotation(T[:3, :3]))
    q /= np.linalg.norm(q)
    if q[3] < 0.0:
        q = -q
    return tuple(float(v) for v in (*T[:3, 3], *q))  # type: ignore[return-value]


def top_view(pose: Pose3) -> tuple[float, float, float]:
    """``(x, y, yaw)`` of a 3-D pose seen from above (yaw of the body x axis): the entries (1, 0)
    and (0, 0) of :func:`pose3_matrix`'s rotation, by the same arithmetic as
    :func:`slamio.se3.rotation_from_quaternion` (so the same bits), without numpy."""
    x, y, z, w = pose[3:]
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if not n > 1e-12:  # no rotation: what the matrix says of it
        R = pose3_matrix(pose)[:3, :3]
        return float(pose[0]), float(pose[1]), math.atan2(R[1, 0], R[0, 0])
    x, y, z, w = x / n, y / n, z / n, w / n
    return float(pose[0]), float(pose[1]), math.atan2(2 * (x * y + z * w), 1 - 2 * (y * y + z * z))


# --------------------------------------------------------------------------- parsing

_Bad = _fields._BadLine


def _vector(value: Any, n: int, what: str) -> tuple[float, ...]:
    if not (isinstance(value, list) and len(value) == n):
        raise _Bad(f"{what} must be a list of {n} numbers")
    return tuple(_fields._number({"v": v}, "v", label=f"each entry of {what}") for v in value)  # type: ignore[misc]


def _bounded(values: tuple[float, ...], limit: float, what: str, unit: str) -> tuple[float, ...]:
    if max(abs(v) for v in values) > limit:
        raise _Bad(f"{what} {list(values)!r} has a component beyond ±{limit:g} {unit}; write SI units ({unit})")
    return values


def check_quaternion(q: tuple[float, ...], what: str) -> None:
    """A unit quaternion (x, y, z, w), within :data:`QUATERNION_NORM_TOLERANCE`."""
    norm = math.sqrt(sum(v * v for v in q))
    if abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE:
        raise _Bad(
            f"{what} (qx, qy, qz, qw) has norm {norm:.9g}, not 1: write a unit quaternion "
            "(divide each component by the norm)"
        )


def parse_pose3(value: Any, what: str) -> Pose3:
    pose = _vector(value, 7, what + " [x_m, y_m, z_m, qx, qy, qz, qw]")
    _bounded(pose[:3], _fields.COORDINATE_M, what + "'s position", "m")
    check_quaternion(pose[3:], what)
    return pose  # type: ignore[return-value]


def parse_sigma3(value: Any, what: str) -> tuple[float, ...]:
    sigma = _vector(value, 6, what + " [x, y, z in m; rotation x, y, z in rad]")
    bounds = [_fields.SIGMA_LENGTH_M] * 3 + [_fields.SIGMA_ANGLE_RAD] * 3
    for v, (lo, hi) in zip(sigma, bounds):
        if not lo <= v <= hi:
            raise _Bad(
                f"{what} {list(sigma)!r} is outside {_fields.SIGMA_LENGTH_M[0]:g}..{_fields.SIGMA_LENGTH_M[1]:g} m for the "
                f"position and {_fields.SIGMA_ANGLE_RAD[0]:g}..{_fields.SIGMA_ANGLE_RAD[1]:.4g} rad for the rotation; "
                "1e-6 pins the start pose"
            )
    return sigma


def _matrix(value: Any, n: int, what: str) -> np.ndarray:
    import numpy as np

    if not (isinstance(value, list) and len(value) == n):
        raise _Bad(f"{what} must be a {n}×{n} list of lists")
    return np.array([_vector(row, n, f"each row of {what}") for row in value])


def _twist_covariance(value: Any) -> Matrix6:
    return _spd_matrix(
        value, 6, "covariance", MAX_TWIST_VARIANCE, MIN_TWIST_EIGENVALUE,
        "write variances of (v, ω) in m²/s² and rad²/s² (a σ of 1000 m/s says nothing)",
        "no IMU is that certain; put a realistic variance on each diagonal entry",
    )


def _pixel_covariance(value: Any) -> Matrix4:
    return _spd_matrix(
        value, 4, "covariance_px2", MAX_PIXEL_VARIANCE_PX2, MIN_PIXEL_EIGENVALUE_PX2,
        "write variances of (u_L, v_L, u_R, v_R) in px² (a σ of 1e4 px is wider than any image)",
        "no detector is that certain (σ ≥ 1e-6 px); put a realistic variance on each diagonal entry",
    )


def checked_pixel_covariance(value: Any) -> Matrix4:
    """A 4×4 pixel covariance (rows of lists, px²) checked as the log's ``covariance_px2`` is;
    ``ValueError`` says what is wrong (for callers outside the log reader, e.g. a command line
    option)."""
    try:
        return _pixel_covariance(value)
    except _Bad as bad:
        raise ValueError(str(bad)) from None


def _spd_matrix(value: Any, n: int, key: str, largest_allowed: float, smallest_allowed: float,
                why_large: str, why_small: str) -> tuple[tuple[float, ...], ...]:
    """An n×n symmetric matrix with entries ≤ ``largest_allowed`` and its smallest eigenvalue
    ≥ ``smallest_allowed`` (field ``key``), as nested tuples."""
    import numpy as np

    m = _matrix(value, n, f"'{key}'")
    largest = float(np.max(np.abs(m)))
    if largest > largest_allowed:
        raise _Bad(f"'{key}' holds {largest!r}, above {largest_allowed:g}: {why_large}")
    if not np.allclose(m, m.T, rtol=1e-9, atol=1e-15):
        raise _Bad(f"'{key}' must be symmetric")
    smallest = float(np.linalg.eigvalsh(m)[0])
    if not smallest >= smallest_allowed:
        raise _Bad(
            f"'{key}' must be positive definite with its smallest eigenvalue ≥ {smallest_allowed:g} "
            f"(got {smallest:.3g}): {why_small}"
        )
    return tuple(tuple(float(v) for v in row) for row in m)


def _pixel(d: dict, key: str) -> float:
    value = _fields._number(d, key)
    if abs(value) > MAX_PIXEL_PX:  # type: ignore[arg-type]
        raise _Bad(f"field '{key}' is {value!r}, beyond ±{MAX_PIXEL_PX:g} px: write pixel coordinates")
    return value  # type: ignore[return-value]


def parse_record3(kind: str, d: dict):
    """The 3-D record of type ``kind`` from its JSON object (fields already checked for unknowns)."""
    if kind == "velocity_odometry":
        dt = _fields._finite(d, "dt_s", positive=True)
        if dt > MAX_DT_S:  # type: ignore[operator]
            raise _Bad(f"field 'dt_s' is {dt!r}, above {MAX_DT_S:g} s: a velocity is not held that long")
        if "covariance" not in d:
            raise _Bad("missing field 'covariance' (6×6 over vx, vy, vz, wx, wy, wz)")
        for key in ("v_mps", "w_radps"):
            if key not in d:
                raise _Bad(f"missing field '{key}' (a list of 3 numbers, IMU frame)")
        return VelocityOdometry(
            stamp_s=_fields._stamp(d),  # type: ignore[arg-type]
            dt_s=dt,  # type: ignore[arg-type]
            v_mps=_bounded(_vector(d["v_mps"], 3, "'v_mps'"), MAX_SPEED_MPS, "'v_mps'", "m/s"),  # type: ignore[arg-type]
            w_radps=_bounded(_vector(d["w_radps"], 3, "'w_radps'"), MAX_TURN_RATE_RADPS, "'w_radps'", "rad/s"),  # type: ignore[arg-type]
            covariance=_twist_covariance(d["covariance"]),
        )
    if kind == "stereo_observation":
        return StereoObservation(
            stamp_s=_fields._stamp(d),  # type: ignore[arg-type]
            track_id=_fields._integer(d, "track_id", id_range=True),  # type: ignore[arg-type]
            u_left_px=_pixel(d, "u_left_px"),
            v_left_px=_pixel(d, "v_left_px"),
            u_right_px=_pixel(d, "u_right_px"),
            v_right_px=_pixel(d, "v_right_px"),
            **_pixel_noise(d),
        )
    if kind == "truth_pose3":
        values = {k: _fields._finite(d, k) for k in ("qx", "qy", "qz", "qw")}
        values.update(stamp_s=_fields._stamp(d), **{k: _coordinate(d, k) for k in ("x_m", "y_m", "z_m")})
        check_quaternion(tuple(values[k] for k in ("qx", "qy", "qz", "qw")), "truth_pose3's quaternion")  # type: ignore[misc]
        return TruthPose3(**values)  # type: ignore[arg-type]
    return TruthLandmark3(
        landmark_id=_fields._integer(d, "landmark_id", id_range=True),  # type: ignore[arg-type]
        x_m=_coordinate(d, "x_m"),
        y_m=_coordinate(d, "y_m"),
        z_m=_coordinate(d, "z_m"),
    )


def _pixel_noise(d: dict) -> dict:
    """A stereo observation's ``sigma_px`` or ``covariance_px2`` (exactly one of them)."""
    has_sigma = d.get("sigma_px") is not None
    has_covariance = d.get("covariance_px2") is not None
    if has_sigma == has_covariance:
        raise _Bad(
            ("both 'sigma_px' and 'covariance_px2' are given: keep one" if has_sigma else "missing field 'sigma_px'")
            + " ('sigma_px': one σ in px on each of u_L, v_L, u_R, v_R; or 'covariance_px2': their 4×4 "
            "covariance in px²)"
        )
    if has_covariance:
        return {"covariance_px2": _pixel_covariance(d["covariance_px2"])}
    return {"sigma_px": _fields._within(
        "sigma_px", _fields._number(d, "sigma_px"), SIGMA_PIXEL_PX, "px",
        "no detector resolves below 1e-6 px and no image is 1e4 px wide; write σ in pixels",
    )}


def _coordinate(d: dict, key: str) -> float:
    """A world coordinate (m) within ±:data:`~slamio.log.fields.COORDINATE_M`."""
    return _fields._magnitude(d, key, _fields.COORDINATE_M, "m", _fields._WHY_COORDINATE)  # type: ignore[return-value]


_STEREO_KEYS = ("fx_px", "fy_px", "cx_px", "cy_px", "baseline_m", "cam_T_imu")


def parse_stereo_sensor(sensor: dict) -> StereoCalibration:
    """The calibration in a 3-D header's ``sensor`` (kind ``"stereo"``)."""
    import numpy as np

    if sensor.get("kind") != "stereo":
        raise _Bad(
            f"a 3-D log's header field 'sensor.kind' must be \"stereo\", got {_fields._show(sensor.get('kind'))} "
            "(the 3-D records are stereo observations)"
        )
    missing = [k for k in _STEREO_KEYS if k not in sensor]
    if missing:
        raise _Bad(f"header field 'sensor' lacks {', '.join(repr(k) for k in missing)}: a stereo sensor needs {', '.join(_STEREO_KEYS)}")
    values = {k: _fields._number(sensor, k, label=f"header field 'sensor.{k}'") for k in _STEREO_KEYS[:5]}
    for k in ("fx_px", "fy_px", "baseline_m"):
        if not values[k] > 0.0:  # type: ignore[operator]
            raise _Bad(f"header field 'sensor.{k}' must be > 0, got {values[k]!r}")
    for k, limit, unit in (("fx_px", MAX_PIXEL_PX, "px"), ("fy_px", MAX_PIXEL_PX, "px"), ("cx_px", MAX_PIXEL_PX, "px"),
                           ("cy_px", MAX_PIXEL_PX, "px"), ("baseline_m", MAX_MOUNT_M, "m")):
        _bounded((values[k],), limit, f"header field 'sensor.{k}'", unit)  # type: ignore[arg-type]
    T = _matrix(sensor["cam_T_imu"], 4, "header field 'sensor.cam_T_imu'")
    _bounded(tuple(T[:3, 3]), MAX_MOUNT_M, "header field 'sensor.cam_T_imu''s translation", "m")
    R = T[:3, :3]
    if not (np.allclose(T[3], [0, 0, 0, 1], atol=1e-9) and np.allclose(R @ R.T, np.eye(3), atol=1e-6)
            and np.linalg.det(R) > 0.0):
        raise _Bad(
            "header field 'sensor.cam_T_imu' must be a rigid 4×4 transform (rotation block with RᵀR = I and "
            "det +1, last row [0, 0, 0, 1])"
        )
    K = np.array([[values["fx_px"], 0.0, values["cx_px"]], [0.0, values["fy_px"], values["cy_px"]], [0.0, 0.0, 1.0]])
    return StereoCalibration(K=K, baseline_m=float(values["baseline_m"]), cam_T_imu=T)  # type: ignore[arg-type]


def check_stereo_sensor(sensor: dict) -> None:
    """:func:`parse_stereo_sensor`'s checks, for the reader: without numpy when the sensor is
    surely accepted (:func:`_clearly_stereo`), else by :func:`parse_stereo_sensor` itself (its
    messages)."""
    if not _clearly_stereo(sensor):
        parse_stereo_sensor(sensor)


#: How far inside :func:`parse_stereo_sensor`'s tolerances (``allclose``'s ``atol`` of 1e-9
#: and 1e-6) the numpy-free check accepts a rigid transform: far from any rounding.
_RIGID_MARGIN = 0.5


def _clearly_stereo(sensor: dict) -> bool:
    """True when :func:`parse_stereo_sensor` surely accepts ``sensor``: every value within its
    bounds and ``cam_T_imu`` rigid within half the tolerances (RRᵀ = I by sums of products
    here, by numpy there: they differ by rounding, ~1e-16); False for anything it may refuse."""
    if sensor.get("kind") != "stereo" or any(k not in sensor for k in _STEREO_KEYS):
        return False
    T = sensor["cam_T_imu"]
    try:
        fx, fy, cx, cy, baseline = (_fields._number(sensor, k) for k in _STEREO_KEYS[:5])
        rows = [_vector(row, 4, "") for row in T] if isinstance(T, list) and len(T) == 4 else None
    except _Bad:
        return False
    if rows is None or not (fx > 0.0 and fy > 0.0 and baseline > 0.0):  # type: ignore[operator]
        return False
    if max(abs(fx), abs(fy), abs(cx), abs(cy)) > MAX_PIXEL_PX or baseline > MAX_MOUNT_M:  # type: ignore[arg-type]
        return False
    if max(abs(rows[i][3]) for i in range(3)) > MAX_MOUNT_M:
        return False
    if any(abs(v - e) > _RIGID_MARGIN * 1e-9 for v, e in zip(rows[3], (0.0, 0.0, 0.0, 1.0))):
        return False
    R = [row[:3] for row in rows[:3]]
    if any(abs(sum(R[i][k] * R[j][k] for k in range(3)) - (i == j)) > _RIGID_MARGIN * 1e-6
           for i in range(3) for j in range(3)):
        return False
    det = (R[0][0] * (R[1][1] * R[2][2] - R[1][2] * R[2][1]) - R[0][1] * (R[1][0] * R[2][2] - R[1][2] * R[2][0])
           + R[0][2] * (R[1][0] * R[2][1] - R[1][1] * R[2][0]))
    return det > 0.5  # a rotation's is 1


def stereo_sensor(K: Any, baseline_m: float, cam_T_imu: Any, **extra: Any) -> dict:
    """A 3-D header's ``sensor`` object from the calibration (``extra`` keys are kept)."""
    import numpy as np

    K = np.asarray(K, dtype=float)
    return {
        "kind": "stereo",
        "fx_px": float(K[0, 0]),
        "fy_px": float(K[1, 1]),
        "cx_px": float(K[0, 2]),
        "cy_px": float(K[1, 2]),
        "baseline_m": float(baseline_m),
        "cam_T_imu": [[float(v) for v in row] for row in np.asarray(cam_T_imu, dtype=float)],
        **extra,
    }


def stereo_calibration(header) -> StereoCalibration:
    """The stereo calibration of a 3-D log's header (validated when the log was read)."""
    try:
        return parse_stereo_sensor(header.sensor)
    except _Bad as bad:
        raise FgslamError(str(bad)) from None
