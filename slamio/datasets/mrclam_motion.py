"""The maths of an MRCLAM import, on arrays: commands integrated into odometry with its
covariance (:func:`integrate_commands`), the logging's zero-command blips filled
(:func:`fill_zero_blips`), stale repeated readings found (:func:`is_stale_repeat`), the
ground truth interpolated (:func:`interpolate_pose`) and the pose times chosen
(:func:`pose_times`). The rosbag and Plaza importers use them too.
"""

from __future__ import annotations

import bisect
import math

import numpy as np

from slamio.geometry import wrap_angle
from slamio.noise.model import OdometryNoiseRates

__all__ = [
    "CommandOdometryNoise", "fill_zero_blips", "integrate_commands", "interpolate_pose", "is_stale_repeat",
    "pose_times",
]

#: The odometry noise model of integrated commands (module docstring); one class with
#: :class:`slamio.noise.model.OdometryNoiseRates`, which ``fgslam calibrate`` fits.
CommandOdometryNoise = OdometryNoiseRates


def _arc(distance_m: float, angle_rad: float) -> tuple[float, float]:
    """(dx, dy) of a circular arc (the arc model of slamio.geometry.arc_increment)."""
    if abs(angle_rad) < 1e-4:
        a2 = angle_rad * angle_rad
        return distance_m * (1.0 - a2 / 6.0), distance_m * (angle_rad / 2.0 - angle_rad * a2 / 24.0)
    return (
        distance_m * math.sin(angle_rad) / angle_rad,
        distance_m * (1.0 - math.cos(angle_rad)) / angle_rad,
    )


def integrate_commands(
    times_s: np.ndarray,
    forward_mps: np.ndarray,
    angular_radps: np.ndarray,
    t_from_s: float,
    t_to_s: float,
    noise: CommandOdometryNoise,
    *,
    first_index: int = 0,
) -> tuple[tuple[float, float, float], np.ndarray, float, float, int]:
    """Integrate zero-order-hold velocity commands over ``[t_from_s, t_to_s]``.

    Command ``k`` holds from ``times_s[k]`` to ``times_s[k+1]``; ``times_s`` is
    non-decreasing and ``times_s[0] ≤ t_from_s ≤ t_to_s ≤ times_s[-1]``. Each stretch is an
    exact circular arc; the arcs are composed in the frame of the pose at ``t_from_s``.

    Returns ``((dx_m, dy_m, dtheta_rad), covariance, distance_m, angle_rad, index)``:
    the increment (``dtheta_rad`` unwrapped), its 3×3 covariance under ``noise``, the
    commanded travel ``Σ v·dt`` and turn ``Σ ω·dt``, and the index of the command active at
    ``t_to_s`` (pass it back as ``first_index`` to continue without searching).
    """
    x = y = th = 0.0
    P = np.zeros((3, 3))
    distance = angle = 0.0
    k = max(first_index, 0)
    n = len(times_s)
    # the command active at t_from_s: the last k with times_s[k] <= t_from_s
    while k + 1 < n and times_s[k + 1] <= t_from_s:
        k += 1
    t = t_from_s
    while t < t_to_s and k < n - 1:
        t_next = min(t_to_s, float(times_s[k + 1]))
        dt = t_next - t
        if dt > 0.0:
            ds = float(forward_mps[k]) * dt
            dth = float(angular_radps[k]) * dt
            dx, dy = _arc(ds, dth)
            c, s = math.cos(th), math.sin(th)
            # first-order propagation through T ⊕ δ: J1 wrt T, J2 wrt δ
            J1 = np.array([[1.0, 0.0, -s * dx - c * dy], [0.0, 1.0, c * dx - s * dy], [0.0, 0.0, 1.0]])
            J2 = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
            P = J1 @ P @ J1.T + J2 @ noise.stretch_covariance(ds, dth, dt) @ J2.T
            x, y, th = x + c * dx - s * dy, y + s * dx + c * dy, th + dth
            distance += ds
            angle += dth
        t = t_next
        if t_next >= float(times_s[k + 1]):
            k += 1
    while k + 1 < n and times_s[k + 1] <= t_to_s:
        k += 1
    P = 0.5 * (P + P.T)
    return (x, y, th), P, distance, angle, k


def fill_zero_blips(
    times_s: np.ndarray, forward_mps: np.ndarray, angular_radps: np.ndarray, max_blip_s: float
) -> tuple[np.ndarray, np.ndarray, int]:
    """Replace zero commands held shorter than ``max_blip_s`` by the command before them.

    The MRCLAM odometry files have a burst of ``0 0`` lines about once a second, 10–50 ms
    long, between equal non-zero commands. The robots do not execute them: over all five
    robots of Dataset 6, Vicon shows them keeping 93–98 % of their speed through a zero
    run shorter than 60 ms (and slowing to 7–26 % through runs of 0.2 s or longer, which
    are real stops). Integrating the blips makes the odometry read ~1 % short in distance
    and turn. Returns the filled ``(forward, angular)`` and the number of blips filled.
    """
    v, w = forward_mps.copy(), angular_radps.copy()
    zero = (v == 0.0) & (w == 0.0)
    n, i, filled = len(v), 0, 0
    while i < n:
        if not zero[i]:
            i += 1
            continue
        j = i
        while j < n and zero[j]:
            j += 1
        if 0 < i and j < n and times_s[j] - times_s[i] < max_blip_s:
            v[i:j], w[i:j] = v[i - 1], w[i - 1]
            filled += 1
        i = j
    return v, w, filled


def is_stale_repeat(previous, t_s, range_m, bearing_rad, times_s, travel) -> bool:
    """A reading equal to the digit to the previous one of the same barcode while the robot moved.

    The MRCLAM camera sometimes re-reports its last reading of a barcode (1–2 % of the
    lines; median 0.24 s later): a moving robot cannot see a landmark at exactly the same
    range and bearing twice, so the repeat is not a new measurement, and counting it twice
    would make the estimators over-confident. ``travel`` is the cumulative commanded
    motion at ``times_s``.
    """
    if previous is None or (previous[1], previous[2]) != (range_m, bearing_rad):
        return False
    moved = np.interp([previous[0], t_s], times_s, travel)
    return bool(moved[1] - moved[0] > 1e-6)


def interpolate_pose(
    times_s: np.ndarray, poses: np.ndarray, t_s: float, max_gap_s: float
) -> tuple[float, float, float] | None:
    """Ground-truth pose at ``t_s``: linear in x, y; heading along the shorter arc.

    ``poses`` is (N, 3) of (x_m, y_m, theta_rad) at the non-decreasing ``times_s``.
    Returns None when ``t_s`` is outside the samples or the two samples around it are more
    than ``max_gap_s`` apart.
    """
    n = len(times_s)
    if n == 0 or t_s < times_s[0] or t_s > times_s[-1]:
        return None
    i = bisect.bisect_right(times_s, t_s) - 1  # times_s[i] <= t_s
    if times_s[i] == t_s:
        x, y, th = poses[i]
        return float(x), float(y), float(wrap_angle(float(th)))
    t0, t1 = float(times_s[i]), float(times_s[i + 1])
    if t1 - t0 > max_gap_s:
        return None
    a = (t_s - t0) / (t1 - t0)
    x0, y0, th0 = (float(v) for v in poses[i])
    x1, y1, th1 = (float(v) for v in poses[i + 1])
    return (
        x0 + a * (x1 - x0),
        y0 + a * (y1 - y0),
        float(wrap_angle(th0 + a * wrap_angle(th1 - th0))),
    )


def pose_times(
    start_s: float, end_s: float, measurement_times_s: list[float], max_step_s: float | None
) -> list[float]:
    """Times of poses 1, 2, …: every measurement time, plus fillers so gaps ≤ ``max_step_s``.

    ``measurement_times_s`` are sorted, distinct and in ``(start_s, end_s]``; pose 0 is at
    ``start_s`` and is not in the result. Fillers split a long gap into equal parts; the
    run's end gets a pose too when fillers are on.
    """
    anchors = list(measurement_times_s)
    if max_step_s is not None and (not anchors or anchors[-1] < end_s):
        anchors.append(end_s)
    out: list[float] = []
    previous = start_s
    for t in anchors:
        if max_step_s is not None:
            gap = t - previous
            parts = math.ceil(gap / max_step_s - 1e-9) if gap > 0 else 1
            for j in range(1, parts):
                out.append(previous + gap * j / parts)
        out.append(t)
        previous = t
    return out
