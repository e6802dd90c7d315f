"""Where the landmark sensor sits on the robot, fitted from its bearings against ground truth.

A sensor that is not at the robot's centre sees each landmark from a point ``(x, y)`` ahead
of or beside the centre, looking along ``yaw``: the header's ``sensor.pose_on_robot``
(:mod:`slamio.log.mount`). When the header leaves it out or states it wrong, every reading
is off by a parallax that depends on where the landmark is (a 20 cm offset moves a landmark
1 m to the side by 0.2 rad), which no σ can describe. ``fgslam calibrate`` fits it.

The fit uses the bearings only. With truth poses and truth landmarks, the bearing a sensor
at ``(x, y, yaw)`` would measure is known; the parallax changes with the landmark's range
and direction, which is what makes ``x`` and ``y`` observable, and ``yaw`` is the bearing's
constant offset. The ranges are left out on purpose: whether they are Euclidean or depth,
and their scale and bias, are fitted afterwards (:mod:`slamio.noise.fit_truth`), and a
range bias looks like a forward offset. A fourth parameter, the bearing scale (a focal
length slightly off), is fitted alongside because it also bends bearings away from the
axis. Robust least squares (soft-L1, at the bearings' robust σ) keeps misread landmarks out.

The result carries its standard deviations (from the Jacobian at the solution, scaled by the
residuals' robust σ); :func:`determined` says whether the data pins the offset down.

Pure functions of arrays.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from slamio.geometry import wrap_angle
from slamio.noise.fitting import mad_sigma

__all__ = ["MountFit", "determined", "fit_mount", "sensor_bearings_rad", "sensor_poses"]

#: The offset is taken as determined when its σ is below this (metres) and the yaw's below
#: :data:`MAX_YAW_SIGMA_RAD`: a fit that cannot place the sensor within 2 cm says nothing.
MAX_OFFSET_SIGMA_M = 0.02
MAX_YAW_SIGMA_RAD = 0.01


@dataclass(frozen=True)
class MountFit:
    """The sensor's pose on the robot (x_m, y_m, yaw_rad) and its standard deviations."""

    pose: tuple[float, float, float]
    sigma: tuple[float, float, float]
    bearing_scale: float
    readings: int
    residual_sigma_rad: float

    def report(self) -> dict:
        return {
            "pose_on_robot": [round(v, 4) for v in self.pose],
            "sigma": [round(v, 4) for v in self.sigma],
            "bearing_scale": round(self.bearing_scale, 5),
            "readings": self.readings,
            "residual_sigma_rad": round(self.residual_sigma_rad, 5),
        }


def sensor_poses(poses: np.ndarray, mount: tuple[float, float, float]) -> np.ndarray:
    """(n, 3): where a sensor at ``mount`` on the robot is, and the direction it looks, when
    the robot is at ``poses`` (n, 3: x, y, θ)."""
    mx, my, myaw = mount
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    return np.column_stack([poses[:, 0] + c * mx - s * my, poses[:, 1] + s * mx + c * my, poses[:, 2] + myaw])


def sensor_bearings_rad(poses: np.ndarray, landmarks: np.ndarray, mount: tuple[float, float, float]) -> np.ndarray:
    """Bearing of each landmark (n, 2) from a sensor at ``mount`` on the robot at ``poses``
    (n, 3: x, y, θ), counter-clockwise from the sensor's axis."""
    sensor = sensor_poses(poses, mount)
    return wrap_angle(np.arctan2(landmarks[:, 1] - sensor[:, 1], landmarks[:, 0] - sensor[:, 0]) - sensor[:, 2])


def fit_mount(poses: np.ndarray, landmarks: np.ndarray, bearings_rad: np.ndarray,
              start: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> MountFit:
    """The mount that makes the measured ``bearings_rad`` of ``landmarks`` seen from the true
    ``poses`` most likely (module docstring), starting from ``start`` (the header's)."""
    poses, landmarks = np.asarray(poses, float), np.asarray(landmarks, float)
    measured = np.asarray(bearings_rad, float)
    if len(measured) < 10:
        raise ValueError(f"{len(measured)} bearings of landmarks with truth; the mount fit needs at least 10")

    def residual(p: np.ndarray) -> np.ndarray:
        return wrap_angle(measured - p[3] * sensor_bearings_rad(poses, landmarks, (p[0], p[1], p[2])))

    p0 = np.array([*start, 1.0])
    scale = max(mad_sigma(residual(p0)), 1e-4)
    for _ in range(2):  # the robust σ at the start may be a parallax's; once more at the solution's
        solution = least_squares(residual, p0, loss="soft_l1", f_scale=scale, x_scale=[0.1, 0.1, 0.1, 0.1])
        p0, scale = solution.x, max(mad_sigma(solution.fun), 1e-5)
    J = solution.jac
    try:
        cov = np.linalg.inv(J.T @ J) * scale**2
        sigma = tuple(float(math.sqrt(max(v, 0.0))) for v in np.diag(cov)[:3])
    except np.linalg.LinAlgError:
        sigma = (math.inf, math.inf, math.inf)
    x, y, yaw, k = (float(v) for v in solution.x)
    return MountFit((x, y, float(wrap_angle(yaw))), sigma, k, len(measured), scale)  # type: ignore[arg-type]


def determined(fit: MountFit) -> bool:
    """Whether the data places the sensor: offset σ ≤ 2 cm on both axes, yaw σ ≤ 0.01 rad."""
    return (fit.sigma[0] <= MAX_OFFSET_SIGMA_M and fit.sigma[1] <= MAX_OFFSET_SIGMA_M
            and fit.sigma[2] <= MAX_YAW_SIGMA_RAD)
