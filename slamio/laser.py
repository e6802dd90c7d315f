"""A 2-D laser scanner, if one is attached: its scans from a file, or simulated by ray casting.

The file (``read_scan_file``) is JSON Lines, one scan a line, the fields of a ROS
``sensor_msgs/LaserScan``::

    {"t": 12.30, "angle_min": -2.0944, "angle_increment": 0.00613, "range_min": 0.02,
     "range_max": 5.6, "ranges": [1.23, 1.25, null, ...]}

``t`` seconds; angles radians in the robot frame (0 ahead, counter-clockwise positive: mount
the scanner at the robot's centre, facing forward, or convert first); ``ranges`` metres, in
order of increasing angle. As in ROS, a range above ``range_max`` (or ``Infinity``) is free,
and one below ``range_min``, ``null``, ``NaN`` or ``0`` is no reading (unknown)
(:func:`slamio.scan.scan_from_ranges`). ``range_min`` is optional (0). Blank lines and
lines starting with ``#`` are skipped.
"""

from __future__ import annotations

import json
import math
import os

import numpy as np

from slamio.errors import InputFileError, read_text
from slamio.obstacles import Obstacles
from slamio.scan import Scan, ray_cast_scan, scan_from_ranges

__all__ = ["read_scan_file", "laser_scan"]

_REQUIRED = ("t", "angle_min", "angle_increment", "range_max", "ranges")


def _number(path, line_no: int, record: dict, key: str) -> float:
    value = record.get(key)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise InputFileError(f"{path}:{line_no}: {key!r} must be a finite number, got {value!r}")
    return float(value)


def _scan(path, line_no: int, record) -> tuple[float, Scan]:
    if not isinstance(record, dict):
        raise InputFileError(f"{path}:{line_no}: a scan is a JSON object with {', '.join(_REQUIRED)}")
    missing = [key for key in _REQUIRED if key not in record]
    if missing:
        raise InputFileError(f"{path}:{line_no}: missing {', '.join(missing)} (a scan needs {', '.join(_REQUIRED)})")
    t = _number(path, line_no, record, "t")
    angle_min = _number(path, line_no, record, "angle_min")
    step = _number(path, line_no, record, "angle_increment")
    range_max = _number(path, line_no, record, "range_max")
    range_min = _number(path, line_no, record, "range_min") if "range_min" in record else 0.0
    ranges = record["ranges"]
    if not isinstance(ranges, list) or not ranges:
        raise InputFileError(f"{path}:{line_no}: 'ranges' must be a non-empty list of numbers (null: no reading)")
    if any(r is not None and (isinstance(r, bool) or not isinstance(r, (int, float))) for r in ranges):
        raise InputFileError(f"{path}:{line_no}: 'ranges' must hold numbers or null only")
    if len(ranges) > 1 and not step > 0:
        raise InputFileError(f"{path}:{line_no}: 'angle_increment' must be > 0 (angles increase), got {step}")
    if not range_max > range_min >= 0:
        raise InputFileError(f"{path}:{line_no}: need 0 <= range_min < range_max; got {range_min}, {range_max}")
    values = np.array([np.nan if r is None else r for r in ranges], dtype=float)
    angles = angle_min + step * np.arange(len(values))
    return t, scan_from_ranges(angles, values, range_max, range_min)


def read_scan_file(path: str | os.PathLike[str]) -> list[tuple[float, Scan]]:
    """Every ``(t_s, Scan)`` of a laser scan file (module docstring), in file order; an
    :class:`~slamio.errors.InputFileError` naming the file and line on bad input."""
    scans = []
    text_all = read_text(path, "laser scan file", "JSON Lines, one LaserScan-like object per line")
    for line_no, line in enumerate(text_all.splitlines(), start=1):
        text = line.strip()
        if not text or text.startswith("#"):
            continue
        try:
            record = json.loads(text)
        except json.JSONDecodeError as exc:
            raise InputFileError(f"{path}:{line_no}: not JSON ({exc.msg}); one scan object per line") from None
        scans.append(_scan(path, line_no, record))
    return scans


def laser_scan(obstacles: Obstacles, pose, *, field_of_view_rad: float = math.radians(240.0), rays: int = 683,
               max_range_m: float = 5.6, scan_height_m: float = 0.1) -> Scan:
    """A simulated laser at the robot's centre, ``scan_height_m`` above the floor (it sees
    obstacles at least that tall): by default a Hokuyo URG-04LX's 240° in 683 rays to 5.6 m."""
    return ray_cast_scan(obstacles, pose, field_of_view_rad, rays, max_range_m, min_height_m=scan_height_m)
