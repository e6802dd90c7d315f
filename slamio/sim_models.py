"""The simulator's robot and sensor: their models, and the pure maths that uses them.

The differential-drive Create (wheel speeds, the Create's wheel reading, the first-order
odometry covariance of wheel noise and slip) and the range-bearing landmark sensor (its
σ over range, which landmarks a pose sees). :mod:`slamio.sim` drives these through a
scenario (:mod:`slamio.sim_worlds`) and writes the log; its docstring says how one run is
made, step by step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from slamio.geometry import wrap_angle
from slamio.obstacles import Obstacles, ray_cast_m

WHEEL_BASE_M = 0.235  # iRobot Create (Open Interface spec)
MAX_WHEEL_SPEED_M_S = 0.5  # Drive Direct accepts ±500 mm/s per wheel


@dataclass(frozen=True)
class MotionModel:
    """How the simulated Create drives its path (see the module docstring, step 3)."""

    dt_s: float
    speed_m_s: float
    max_turn_rate_rad_s: float
    turn_gain_per_s: float
    lookahead_m: float


@dataclass(frozen=True)
class WheelSlipNoise:
    """Generative odometry noise: relative wheel error per step and slip per step."""

    k_wheel: float
    slip_sigma_x_m: float
    slip_sigma_y_m: float
    slip_sigma_theta_rad: float

    @property
    def slip_covariance(self) -> np.ndarray:
        return np.diag([self.slip_sigma_x_m**2, self.slip_sigma_y_m**2, self.slip_sigma_theta_rad**2])


@dataclass(frozen=True)
class SensorModel:
    """A range-bearing landmark sensor at the robot's centre, looking along robot x.

    ``sigma_range_m``, ``sigma_range_per_m`` and ``sigma_range_per_m2`` are a, b, c of
    σ_r(r) = a + b·r + c·r². ``facing_limit_rad`` is set for AprilTags only;
    ``sigma_height_m`` for landmarks with a height, ``sigma_tag_yaw_rad`` for tags.
    """

    landmark_kind: str
    fov_rad: float
    min_range_m: float
    max_range_m: float
    sigma_range_m: float
    sigma_range_per_m: float
    sigma_range_per_m2: float
    sigma_bearing_rad: float
    sigma_height_m: float | None = None
    sigma_tag_yaw_rad: float | None = None
    facing_limit_rad: float | None = None


def observation_sigmas(noise) -> dict[str, float]:
    """The σ of a range-bearing noise model — a :class:`SensorModel` or a camera front end's
    :class:`slamio.camera.detect.NoiseModel` — as a log header's ``observation`` states them:
    a, b, c of σ_r(r) = a + b·r + c·r², the bearing's σ, then the height's and the tag
    yaw's when the model has them."""
    out = {
        "sigma_range_m": noise.sigma_range_m,
        "sigma_range_per_m": noise.sigma_range_per_m,
        "sigma_range_per_m2": noise.sigma_range_per_m2,
        "sigma_bearing_rad": noise.sigma_bearing_rad,
    }
    if noise.sigma_height_m is not None:
        out["sigma_height_m"] = noise.sigma_height_m
    if noise.sigma_tag_yaw_rad is not None:
        out["sigma_tag_yaw_rad"] = noise.sigma_tag_yaw_rad
    return out


@dataclass(frozen=True)
class World:
    """Landmarks: (N, 2) positions; heights and facing yaws (N,) or None; ``obstacles`` (a
    :class:`slamio.obstacles.Obstacles`, or None) hide the landmarks behind them."""

    landmarks_xy: np.ndarray
    heights_m: np.ndarray | None = None
    yaws_rad: np.ndarray | None = None
    obstacles: Obstacles | None = None



# --------------------------------------------------------------------------- pure maths


def wheel_speeds_m_s(speed_m_s: float, turn_rate_rad_s: float, wheel_base_m: float = WHEEL_BASE_M,
                     max_wheel_speed_m_s: float = MAX_WHEEL_SPEED_M_S) -> tuple[float, float]:
    """(left, right) wheel speeds for a unicycle command, scaled down together if needed.

    ``v_left = v − ω·b/2``, ``v_right = v + ω·b/2``. If either exceeds the wheel limit both
    are multiplied by the same factor, so the curvature ω/v (the arc) is kept.
    """
    left = speed_m_s - 0.5 * turn_rate_rad_s * wheel_base_m
    right = speed_m_s + 0.5 * turn_rate_rad_s * wheel_base_m
    fastest = max(abs(left), abs(right))
    if fastest > max_wheel_speed_m_s:
        scale = max_wheel_speed_m_s / fastest
        left, right = left * scale, right * scale
    return left, right


def wheel_reading(left_m, right_m, wheel_base_m: float = WHEEL_BASE_M):
    """The Create's reading from wheel distances: (distance_m, angle_rad).

    ``distance_m = (dL + dR)/2`` (the centre's travel), ``angle_rad = (dR − dL)/b``
    (counter-clockwise). Works on floats or numpy arrays.
    """
    return 0.5 * (left_m + right_m), (right_m - left_m) / wheel_base_m


def _arc_jacobians(distance_m: np.ndarray, angle_rad: np.ndarray) -> np.ndarray:
    """(n, 3, 2) Jacobians of ``arc_increment`` w.r.t. (distance, angle); vectorised.

    Same formulas (and the same small-angle series) as
    :func:`slamio.geometry.arc_increment_jacobian`.
    """
    a = np.asarray(angle_rad, dtype=float)
    s = np.asarray(distance_m, dtype=float)
    small = np.abs(a) < 1e-4
    safe = np.where(small, 1.0, a)
    sinc = np.where(small, 1.0 - a * a / 6.0, np.sin(safe) / safe)
    cosc = np.where(small, a / 2.0 - a**3 / 24.0, (1.0 - np.cos(safe)) / safe)
    d_sinc = np.where(small, -a / 3.0, (safe * np.cos(safe) - np.sin(safe)) / (safe * safe))
    d_cosc = np.where(small, 0.5 - a * a / 8.0, (safe * np.sin(safe) - (1.0 - np.cos(safe))) / (safe * safe))
    jac = np.zeros(a.shape + (3, 2))
    jac[..., 0, 0] = sinc
    jac[..., 0, 1] = s * d_sinc
    jac[..., 1, 0] = cosc
    jac[..., 1, 1] = s * d_cosc
    jac[..., 2, 1] = 1.0
    return jac


def odometry_covariance(left_m, right_m, noise: WheelSlipNoise, wheel_base_m: float = WHEEL_BASE_M) -> np.ndarray:
    """Covariance over (dx, dy, dθ) of one odometry increment, from the true wheel distances.

    First-order propagation of the wheel noise ``σ = k_wheel·|d|`` per wheel through
    wheels → (ΔS, Δθ) → arc increment, plus the slip covariance rotated by the arc's turn
    (slip acts in the frame at the arc's end). Accepts floats (→ 3×3) or equal-length
    arrays (→ (n, 3, 3)). The result is exactly symmetric.
    """
    left = np.asarray(left_m, dtype=float)
    right = np.asarray(right_m, dtype=float)
    distance, angle = wheel_reading(left, right, wheel_base_m)
    wheels = np.zeros(left.shape + (2, 2))
    wheels[..., 0, 0] = (noise.k_wheel * left) ** 2
    wheels[..., 1, 1] = (noise.k_wheel * right) ** 2
    A = np.array([[0.5, 0.5], [-1.0 / wheel_base_m, 1.0 / wheel_base_m]])
    J = _arc_jacobians(distance, angle) @ A  # (…, 3, 2): wheels → increment
    c, s = np.cos(angle), np.sin(angle)
    R = np.zeros(angle.shape + (3, 3))
    R[..., 0, 0], R[..., 0, 1], R[..., 1, 0], R[..., 1, 1], R[..., 2, 2] = c, -s, s, c, 1.0
    cov = J @ wheels @ np.swapaxes(J, -1, -2) + R @ noise.slip_covariance @ np.swapaxes(R, -1, -2)
    return 0.5 * (cov + np.swapaxes(cov, -1, -2))


def range_sigma_m(range_m, sensor: SensorModel):
    """σ of a range measurement at true range ``range_m``: a + b·r + c·r² (floats or arrays)."""
    return sensor.sigma_range_m + sensor.sigma_range_per_m * range_m + sensor.sigma_range_per_m2 * range_m * range_m


@dataclass(frozen=True)
class Sightings:
    """Every (pose, landmark) pair in view, sorted by pose then landmark, with exact values."""

    pose_index: np.ndarray
    landmark_id: np.ndarray
    range_m: np.ndarray
    bearing_rad: np.ndarray
    tag_yaw_rad: np.ndarray | None  # tag yaw relative to the robot's x axis


def _sightings_block(poses: np.ndarray, pose_ids: np.ndarray, lm_ids: np.ndarray, world: World,
                     sensor: SensorModel) -> tuple[np.ndarray, ...]:
    """Visibility and exact measurements for every pose in ``pose_ids`` × landmark in ``lm_ids``."""
    px, py, pth = (poses[pose_ids, i][:, None] for i in range(3))
    lx = world.landmarks_xy[lm_ids, 0][None, :]
    ly = world.landmarks_xy[lm_ids, 1][None, :]
    dx, dy = lx - px, ly - py
    rng_m = np.hypot(dx, dy)
    bearing = wrap_angle(np.arctan2(dy, dx) - pth)
    seen = (rng_m >= sensor.min_range_m) & (rng_m <= sensor.max_range_m) & (np.abs(bearing) <= 0.5 * sensor.fov_rad)
    tag_yaw = None
    if sensor.facing_limit_rad is not None:
        yaw = world.yaws_rad[lm_ids][None, :]
        # cos of the angle between the tag's face normal and the tag→robot direction
        cos_facing = -(np.cos(yaw) * dx + np.sin(yaw) * dy) / np.maximum(rng_m, 1e-12)
        seen &= cos_facing >= math.cos(sensor.facing_limit_rad)
        tag_yaw = wrap_angle(yaw - pth)
    rows, cols = np.nonzero(seen)
    if world.obstacles is not None and len(rows):
        keep = _unoccluded(world.obstacles, poses[pose_ids[rows], :2], world.landmarks_xy[lm_ids[cols]])
        rows, cols = rows[keep], cols[keep]
    return (
        pose_ids[rows],
        lm_ids[cols],
        rng_m[rows, cols],
        bearing[rows, cols],
        None if tag_yaw is None else tag_yaw[rows, cols],
    )


def _unoccluded(obstacles: Obstacles, from_xy: np.ndarray, to_xy: np.ndarray) -> np.ndarray:
    """Whether each (from, to) pair sees across the obstacles (:func:`slamio.obstacles.line_of_sight`,
    one ray cast per distinct origin): a landmark on an obstacle's face is seen from its front."""
    offset = to_xy - from_xy
    distance = np.hypot(offset[:, 0], offset[:, 1])
    angles = np.arctan2(offset[:, 1], offset[:, 0])
    keep = np.ones(len(from_xy), dtype=bool)
    origins, which = np.unique(from_xy, axis=0, return_inverse=True)
    for k, origin in enumerate(origins):
        pairs = np.nonzero(which.reshape(-1) == k)[0]
        keep[pairs] = ray_cast_m(obstacles, origin, angles[pairs]) >= distance[pairs] - 1e-6
    return keep


def visible_landmarks(poses: np.ndarray, world: World, sensor: SensorModel) -> Sightings:
    """Which landmarks each pose sees, with exact range, bearing (and tag yaw); vectorised.

    ``poses`` is (T, 3). Landmarks are bucketed into square cells one ``max_range_m`` wide,
    and each pose is tested only against the landmarks of its own and the 8 neighbouring
    cells, so thousands of landmarks cost little.
    """
    poses = np.asarray(poses, dtype=float)
    cell = sensor.max_range_m
    lm_cells = np.floor(world.landmarks_xy / cell).astype(np.int64)
    buckets: dict[tuple[int, int], list[int]] = {}
    for i, (cx, cy) in enumerate(lm_cells.tolist()):
        buckets.setdefault((cx, cy), []).append(i)
    pose_cells = np.floor(poses[:, :2] / cell).astype(np.int64)
    unique_cells, inverse = np.unique(pose_cells, axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    order = np.argsort(inverse, kind="stable")
    bounds = np.searchsorted(inverse[order], np.arange(len(unique_cells) + 1))
    parts = []
    for k, (cx, cy) in enumerate(unique_cells.tolist()):
        candidates = [i for ox in (-1, 0, 1) for oy in (-1, 0, 1) for i in buckets.get((cx + ox, cy + oy), ())]
        if not candidates:
            continue
        pose_ids = order[bounds[k]:bounds[k + 1]]
        parts.append(_sightings_block(poses, pose_ids, np.array(sorted(candidates)), world, sensor))
    has_yaw = sensor.facing_limit_rad is not None
    if not parts:
        empty_i, empty_f = np.zeros(0, dtype=np.int64), np.zeros(0)
        return Sightings(empty_i, empty_i, empty_f, empty_f, empty_f if has_yaw else None)
    cols = [np.concatenate([p[j] for p in parts]) for j in range(4)]
    yaw = np.concatenate([p[4] for p in parts]) if has_yaw else None
    sort = np.lexsort((cols[1], cols[0]))
    return Sightings(
        cols[0][sort], cols[1][sort], cols[2][sort], cols[3][sort], None if yaw is None else yaw[sort]
    )

