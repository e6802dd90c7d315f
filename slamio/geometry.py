"""SE(2) helpers shared by every package: one ``wrap_angle``, pose composition, the arc model.

Poses are ``(x_m, y_m, theta_rad)`` in a right-handed world frame, theta counter-clockwise
from the world x axis; the robot frame is x forward, y left.
"""

from __future__ import annotations

import math

import numpy as np


def wrap_angle(angle_rad):
    """Wrap an angle (a float or a numpy array) into [-pi, pi)."""
    if isinstance(angle_rad, np.ndarray):
        return (angle_rad + np.pi) % (2.0 * np.pi) - np.pi
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi


def compose_pose(T_world_a, T_a_b):
    """Return T_world_b = T_world_a ⊕ T_a_b for poses given as (x_m, y_m, theta_rad)."""
    x, y, th = T_world_a
    dx, dy, dth = T_a_b
    c, s = math.cos(th), math.sin(th)
    return (x + c * dx - s * dy, y + s * dx + c * dy, wrap_angle(th + dth))


def between_pose(T_world_a, T_world_b):
    """Return T_a_b = T_world_a⁻¹ ⊕ T_world_b (the increment that takes pose a to pose b)."""
    xa, ya, tha = T_world_a
    xb, yb, thb = T_world_b
    c, s = math.cos(tha), math.sin(tha)
    ex, ey = xb - xa, yb - ya
    return (c * ex + s * ey, -s * ex + c * ey, wrap_angle(thb - tha))


def _sin_over_x(x: float) -> float:
    """sin(x)/x, accurate near 0."""
    if abs(x) < 1e-4:
        return 1.0 - x * x / 6.0
    return math.sin(x) / x


def _one_minus_cos_over_x(x: float) -> float:
    """(1 - cos x)/x, accurate near 0."""
    if abs(x) < 1e-4:
        return x / 2.0 - x**3 / 24.0
    return (1.0 - math.cos(x)) / x


def arc_increment(distance_m: float, angle_rad: float):
    """SE(2) increment (dx_m, dy_m, dtheta_rad) in the robot frame for an arc.

    The Create reports odometry as the distance its centre travelled (mean of the two
    wheels) and the change of heading since the last reading. Seed 000 §3.3.2 turns that
    into a displacement by assuming the robot moved on a circular arc of radius
    r = ΔS/Δθ. Seed 000 writes it in its compass frame (0 = north, clockwise positive),
    with Δx' = r(1 − cos Δθ) sideways and Δy' = r sin Δθ forward, and a Δθ = 0 special
    case. In this project's frame (x forward, y left, θ counter-clockwise) the same arc is

        dx = ΔS · sin(Δθ)/Δθ,   dy = ΔS · (1 − cos Δθ)/Δθ,   dθ = Δθ,

    and the series forms above make the straight-line case (Δθ → 0) continuous instead
    of a branch.
    """
    return (
        distance_m * _sin_over_x(angle_rad),
        distance_m * _one_minus_cos_over_x(angle_rad),
        angle_rad,
    )


def arc_increment_jacobian(distance_m: float, angle_rad: float) -> np.ndarray:
    """3×2 Jacobian of ``arc_increment`` with respect to (distance_m, angle_rad)."""
    a = angle_rad
    if abs(a) < 1e-4:
        d_sinc = -a / 3.0  # d/da [sin a / a]
        d_cosc = 0.5 - a * a / 8.0  # d/da [(1 - cos a)/a]
    else:
        d_sinc = (a * math.cos(a) - math.sin(a)) / (a * a)
        d_cosc = (a * math.sin(a) - (1.0 - math.cos(a))) / (a * a)
    return np.array(
        [
            [_sin_over_x(a), distance_m * d_sinc],
            [_one_minus_cos_over_x(a), distance_m * d_cosc],
            [0.0, 1.0],
        ]
    )
