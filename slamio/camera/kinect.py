"""The Kinect's depth encodings as metres (:func:`depth_from_mm`, :func:`depth_from_scaled`,
:func:`depth_from_kinect_raw`; NaN where there is no reading), and the bearing and height
formulas of seeds 000 and 002 (:func:`linear_bearing_rad`, :func:`gheight_seed002`) beside
the pinhole's (:func:`exact_bearing_rad`). :mod:`slamio.camera.colour` measures with them.
"""

from __future__ import annotations

import math

import numpy as np

from slamio.camera.model import CameraModel

__all__ = [
    "GHEIGHT_VFOV_DEG", "KINECT_HFOV_RAD", "KINECT_RAW_MISSING", "depth_from_kinect_raw", "depth_from_mm",
    "depth_from_scaled", "exact_bearing_rad", "gheight_seed002", "linear_bearing_error_rad", "linear_bearing_rad",
]

# Kinect v1 raw 11-bit disparity → metres (N. Burrus's fit); 2047 = no reading.
KINECT_RAW_MISSING = 2047
_KINECT_A = -0.0030711016
_KINECT_B = 3.3309495161

#: Seed 000/002's nominal Kinect fields of view.
KINECT_HFOV_RAD = math.radians(57.0)
GHEIGHT_VFOV_DEG = 47.0  # seed 002's gHeight uses 47° over 480 rows


# --------------------------------------------------------------------------- depth encodings


def depth_from_mm(depth_mm: np.ndarray) -> np.ndarray:
    """Registered depth in millimetres (OpenNI2, libfreenect DEPTH_REGISTERED; 0 = missing) → metres."""
    d = np.asarray(depth_mm).astype(np.float32) / 1000.0
    d[np.asarray(depth_mm) == 0] = np.nan
    return d


def depth_from_scaled(depth_png: np.ndarray, scale_per_m: float = 5000.0) -> np.ndarray:
    """16-bit depth PNG with ``scale_per_m`` units per metre (TUM RGB-D: 5000; 0 = missing) → metres."""
    d = np.asarray(depth_png).astype(np.float32) / float(scale_per_m)
    d[np.asarray(depth_png) == 0] = np.nan
    return d


def depth_from_kinect_raw(raw: np.ndarray) -> np.ndarray:
    """Kinect v1 raw 11-bit disparity (2047 = missing) → metres (Burrus's fit)."""
    r = np.asarray(raw).astype(np.float64)
    with np.errstate(divide="ignore"):
        d = 1.0 / (_KINECT_A * r + _KINECT_B)
    d[(np.asarray(raw) >= KINECT_RAW_MISSING) | ~(d > 0)] = np.nan
    return d.astype(np.float32)


# --------------------------------------------------------------------------- pure maths


def linear_bearing_rad(u_px: float, width_px: int, hfov_rad: float = KINECT_HFOV_RAD) -> float:
    """Seed 000's bearing: linear in the column, 0 at the image centre, +hfov/2 at the left edge."""
    cx = 0.5 * (width_px - 1)
    return (cx - u_px) * hfov_rad / width_px


def exact_bearing_rad(u_px: float, camera: CameraModel) -> float:
    """Bearing of a column through the pinhole (camera looking along robot x, no distortion)."""
    return math.atan2(camera.cx - u_px, camera.fx)


def linear_bearing_error_rad(u_px: float, camera: CameraModel, hfov_rad: float = KINECT_HFOV_RAD) -> float:
    """Seed 000's linear map minus the pinhole bearing of the same column."""
    return linear_bearing_rad(u_px, camera.width_px, hfov_rad) - exact_bearing_rad(u_px, camera)


def gheight_seed002(d1: float, d2: float, pd_px: float, vfov_deg: float = GHEIGHT_VFOV_DEG,
                    rows: int = 480) -> float:
    """Seed 002's ``gHeight(d1, d2, pd)``, as written (any length unit in, same unit out).

    ``theta = pd·47/480`` degrees; ``db1 = ds·cos θ``; ``db2 = db − db1``;
    ``dp = sqrt(ds² − db1²)``; ``h = sqrt(db2² + dp²)`` with ds, db the smaller and larger
    depth. Algebraically this is the law of cosines, h² = ds² + db² − 2·ds·db·cos θ: the
    distance between the two points — exact if d1 and d2 were distances *along the rays*
    and θ the true angle between them. The Kinect gives depth along the optical axis and
    the angle is not linear in the row, which is where its error comes from.
    """
    ds, db = min(d1, d2), max(d1, d2)
    theta = math.radians(pd_px * vfov_deg / rows)
    db1 = ds * math.cos(theta)
    db2 = db - db1
    dp = math.sqrt(max(ds * ds - db1 * db1, 0.0))
    return math.sqrt(db2 * db2 + dp * dp)
