"""Where the landmark sensor sits on the robot: the header's ``sensor.pose_on_robot``.

A planar log's readings are taken from the sensor, not from the robot's centre. When the
header's ``sensor`` says where the sensor sits — ``"pose_on_robot": [x_m, y_m, yaw_rad]``,
the sensor's origin in the robot frame (x forward, y left) and the direction of its x axis —
each range and bearing is measured from there, and every estimator gets it moved to the
robot's centre when the log's records are grouped into steps
(:func:`slamio.log.group_steps`): the landmark's point is exact, its σ are propagated to
first order and the range–bearing correlation that the move creates is dropped (at a 10 cm
offset and 1 m range it is below 0.05). A tag's facing direction turns with the sensor's
yaw. Range-only readings (a radio) keep their range: a range cannot be moved without a
bearing. Without the field the sensor is at the centre, as before.

Pure functions; the reader validates the field (:func:`pose_on_robot`).
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # numpy loads when used: the reader checks the header's mount without it
    import numpy as np

__all__ = ["MAX_MOUNT_OFFSET_M", "camera_mount_fields", "checked_mount", "moved_to_robot_centre", "pose_on_robot",
           "reading_in_robot_frame"]

#: What the header's ``sensor.readings_at`` says of a camera's detections: fgslam's camera
#: front-end places each one from the camera's 3-D mount, so they are the robot centre's.
READINGS_AT_ROBOT_CENTRE = ("the robot's centre: each detection is placed through T_robot_camera, the camera's mount "
                            "on the robot (its camera file's robot_mount), so the header states no pose_on_robot")

#: A sensor on a ground robot sits within this of its centre.
MAX_MOUNT_OFFSET_M = 10.0


def pose_on_robot(sensor: dict) -> tuple[float, float, float] | None:
    """The header sensor's ``pose_on_robot`` as ``(x_m, y_m, yaw_rad)``, None when absent or
    the identity. Raises ValueError with the rule broken (the reader turns it into a
    file:line error)."""
    value = sensor.get("pose_on_robot") if isinstance(sensor, dict) else None
    if value is None:
        return None
    x, y, yaw = checked_mount(value if isinstance(value, list) else None, "header field 'sensor.pose_on_robot'")
    if x == 0.0 and y == 0.0 and (yaw + math.pi) % (2.0 * math.pi) - math.pi == 0.0:  # wrap_angle(yaw), a float's
        return None
    return x, y, yaw


def checked_mount(value, field: str) -> tuple[float, float, float]:
    """``value`` as a sensor's pose on the robot ``(x_m, y_m, yaw_rad)``; ValueError naming
    ``field`` and the rule broken: three numbers, within :data:`MAX_MOUNT_OFFSET_M` of the
    centre, a yaw within ±2π."""
    if (not isinstance(value, (list, tuple)) or len(value) != 3
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)):
        raise ValueError(f"{field} must be [x_m, y_m, yaw_rad], three numbers: the "
                         "sensor's origin in the robot frame (x forward, y left) and the direction it looks")
    x, y, yaw = (float(v) for v in value)
    if not (abs(x) <= MAX_MOUNT_OFFSET_M and abs(y) <= MAX_MOUNT_OFFSET_M):
        raise ValueError(f"{field} puts the sensor {math.hypot(x, y):g} m from the "
                         f"robot's centre; a sensor on the robot sits within {MAX_MOUNT_OFFSET_M:g} m")
    if not abs(yaw) <= 2.0 * math.pi:
        raise ValueError(f"{field} yaw {yaw!r} must be an angle within ±2π rad")
    return x, y, yaw


def camera_mount_fields(T_robot_camera) -> dict:
    """The header ``sensor`` fields of a camera whose detections the front-end placed from its
    mount (``T_robot_camera``, 4×4): the mount, and that the readings are the centre's."""
    import numpy as np

    T = np.asarray(T_robot_camera, dtype=float)
    return {"T_robot_camera": [[round(float(v), 9) for v in row] for row in T], "readings_at": READINGS_AT_ROBOT_CENTRE}


def reading_in_robot_frame(range_m: float, bearing_rad: float, mount: tuple[float, float, float]
                           ) -> tuple[float, float, np.ndarray]:
    """``(range, bearing, J)``: a reading taken by a sensor at ``mount`` as seen from the
    robot's centre, and the Jacobian of (range, bearing) from the centre with respect to
    (range, bearing) from the sensor."""
    import numpy as np

    mx, my, myaw = mount
    c, s = math.cos(myaw + bearing_rad), math.sin(myaw + bearing_rad)
    px, py = mx + range_m * c, my + range_m * s
    r = math.hypot(px, py)
    if r <= 0.0:
        raise ValueError("the landmark is at the robot's centre: no bearing from there")
    ux, uy = px / r, py / r
    dp_dr = (c, s)
    dp_db = (-range_m * s, range_m * c)
    J = np.array([
        [ux * dp_dr[0] + uy * dp_dr[1], ux * dp_db[0] + uy * dp_db[1]],
        [(-uy * dp_dr[0] + ux * dp_dr[1]) / r, (-uy * dp_db[0] + ux * dp_db[1]) / r],
    ])
    return r, math.atan2(py, px), J


def moved_to_robot_centre(observation, mount: tuple[float, float, float]):
    """``observation`` (a planar :class:`~slamio.log.Observation`) as if taken at the robot's
    centre: range and bearing moved exactly, their σ by first-order propagation (module
    docstring); a range-only reading is returned as it is."""
    import numpy as np

    from slamio.geometry import wrap_angle

    if observation.bearing_rad is None:
        return observation
    r, b, J = reading_in_robot_frame(observation.range_m, observation.bearing_rad, mount)
    cov = J @ np.diag([observation.sigma_range_m ** 2, observation.sigma_bearing_rad ** 2]) @ J.T
    yaw = observation.tag_yaw_rad
    return dataclasses.replace(
        observation, range_m=r, bearing_rad=b, sigma_range_m=math.sqrt(cov[0, 0]),
        sigma_bearing_rad=math.sqrt(cov[1, 1]),
        tag_yaw_rad=None if yaw is None else float(wrap_angle(yaw + mount[2])),
    )
