"""Deterministic 3-D stereo + IMU simulator: a car on a closed loop among facade points.

``simulate_drive(seed, ...)`` returns a :class:`slamio.datasets.seed003.StereoImuDrive` in
seed 003's layout, with the truth (``truth_world_T_imu``, ``truth_landmarks_m``);
``save_drive`` writes it as the seed's npz. All randomness comes from
``numpy.random.default_rng(seed)``, split into independent streams for the world, the
IMU noise and the camera noise.

How a drive is made
===================

1. **Path.** A rounded rectangle (``straight_m`` × ``side_m`` straights joined by four
   quarter turns of radius ``turn_radius_m``) driven once at ``speed_mps``, so the drive
   returns to its start. The body twist of step t is constant over [t, t + 1]:
   forward speed, yaw rate from the path's curvature, plus small roll/pitch wobbles
   (``wobble_rad``) and a gentle vertical velocity (the road is not flat), so the
   trajectory is genuinely 3-D. Truth: ``T_{t+1} = T_t exp(τ û_t)`` exactly (slamio.se3).
2. **World.** Points on both sides of the road every ``landmark_spacing_m`` of path
   length, ``road_half_width_m`` + U(0, ``facade_depth_m``) to the side and
   U(−1, ``max_height_m``) m above the IMU.
3. **IMU.** The recorded velocities are the true twist plus white noise
   N(0, σ_v²) and N(0, σ_ω²) per axis (``StereoImuNoise``).
4. **Camera.** KITTI-like calibration (fx = fy = 707.09 px, 1241 × 376 px, baseline
   0.537 m, camera 1.14 m ahead of the IMU, ``cam_T_imu`` a pure axis change plus that
   offset). A point is seen when both pixels are inside the image and its depth is in
   [``min_depth_m``, ``max_depth_m``] (5 px from the border), is dropped with probability ``dropout``, and at most
   ``max_features`` are kept per step (those with the longest running tracks first, so
   tracks stay contiguous like the seed's). Each of u_L, v_L, u_R, v_R gets independent
   N(0, σ_px²) noise, or with ``noise.pixel_covariance`` the four get correlated noise
   N(0, Σ) (drawn as L·n, L the Cholesky factor of Σ, n four standard normals); with ``outlier_rate`` > 0 that fraction of the measurements is moved
   by U(±``outlier_px``) in all four pixels (a wrong track; a value may then leave the
   image, as a bad track can). Measurements with a non-positive noisy disparity are kept
   (the seed's data has them too).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from slamio.datasets.seed003 import StereoImuDrive, StereoImuNoise
from slamio.se3 import exp_se3, inverse
from slamio.stereo import stereo_matrix, stereo_pixels

__all__ = ["KITTI_LIKE_CAM_T_IMU", "KITTI_LIKE_K", "STEREO_LOOP", "DriveScenario", "simulate_drive"]

#: The scenario's name in ``fgslam sim`` and ``fgslam bench``.
STEREO_LOOP = "stereo-loop"

KITTI_LIKE_K = np.array([[707.09, 0.0, 601.89], [0.0, 707.09, 183.11], [0.0, 0.0, 1.0]])
KITTI_LIKE_BASELINE_M = 0.537
IMAGE_WIDTH_PX, IMAGE_HEIGHT_PX = 1241, 376
EDGE_PX = 5.0  # margin: pixel noise never pushes a seen point off the image (or onto the −1 marker)
# optical x = −IMU y, optical y = −IMU z, optical z = IMU x; the camera 1.14 m ahead of the IMU
KITTI_LIKE_CAM_T_IMU = np.array(
    [[0.0, -1.0, 0.0, 0.0], [0.0, 0.0, -1.0, 0.0], [1.0, 0.0, 0.0, -1.14], [0.0, 0.0, 0.0, 1.0]]
)


@dataclass(frozen=True)
class DriveScenario:
    """Geometry and sensing of a simulated drive (defaults: a 1-minute city loop)."""

    straight_m: float = 120.0
    side_m: float = 60.0
    turn_radius_m: float = 12.0
    speed_mps: float = 8.0
    dt_s: float = 0.1
    wobble_rad: float = 0.02
    climb_mps: float = 0.3
    landmark_spacing_m: float = 2.0
    road_half_width_m: float = 5.0
    facade_depth_m: float = 10.0
    max_height_m: float = 8.0
    min_depth_m: float = 2.0
    max_depth_m: float = 40.0
    dropout: float = 0.1
    max_features: int = 12
    outlier_rate: float = 0.0
    outlier_px: float = 30.0


def _curvature_profile(sc: DriveScenario) -> tuple[np.ndarray, float]:
    """Curvature (1/m) per unit of path length, sampled every metre step, and the loop length."""
    quarter = 0.5 * math.pi * sc.turn_radius_m
    pieces = []
    for straight in (sc.straight_m, sc.side_m, sc.straight_m, sc.side_m):
        pieces += [(straight, 0.0), (quarter, 1.0 / sc.turn_radius_m)]
    length = sum(p[0] for p in pieces)
    return pieces, length


def _curvature_at(pieces, s_m: float) -> float:
    for piece_length, kappa in pieces:
        if s_m < piece_length:
            return kappa
        s_m -= piece_length
    return 0.0


def _true_twists_and_poses(sc: DriveScenario, pieces, length_m: float, n_steps: int, rng_world
                           ) -> tuple[np.ndarray, np.ndarray]:
    """The true body twists (n, 6) and poses (n, 4, 4) along the curvature profile, with the
    seeded roll / pitch wobble and climb."""
    tau = sc.dt_s
    phase = rng_world.uniform(0.0, 2.0 * math.pi, size=3)
    twists = np.zeros((n_steps, 6))
    poses = np.zeros((n_steps, 4, 4))
    T = np.eye(4)
    for t in range(n_steps):
        poses[t] = T
        s_mid = (t + 0.5) * sc.speed_mps * tau
        yaw_rate = sc.speed_mps * _curvature_at(pieces, s_mid)
        w = 2.0 * math.pi * t * tau
        roll_rate = sc.wobble_rad * 0.5 * math.cos(0.5 * w + phase[0])
        pitch_rate = sc.wobble_rad * 0.3 * math.cos(0.3 * w + phase[1])
        climb = sc.climb_mps * math.sin(2.0 * math.pi * s_mid / length_m + phase[2])
        twists[t] = [sc.speed_mps, 0.0, climb, roll_rate, pitch_rate, yaw_rate]
        T = T @ exp_se3(tau * twists[t])
    return twists, poses


def _facade_landmarks(sc: DriveScenario, poses: np.ndarray, rng_world) -> np.ndarray:
    """Facade points (m, 3) on both sides of the path, one pair every ``landmark_spacing_m``."""
    positions = poses[:, :3, 3]
    landmarks = []
    for t in range(0, len(poses), max(1, int(round(sc.landmark_spacing_m / (sc.speed_mps * sc.dt_s))))):
        R = poses[t, :3, :3]
        for side in (1.0, -1.0):
            lateral = side * (sc.road_half_width_m + rng_world.uniform(0.0, sc.facade_depth_m))
            ahead = rng_world.uniform(-sc.landmark_spacing_m, sc.landmark_spacing_m)
            up = rng_world.uniform(-1.0, sc.max_height_m)
            landmarks.append(positions[t] + R @ np.array([ahead, lateral, up]))
    return np.array(landmarks)


def simulate_drive(seed: int, scenario: DriveScenario = DriveScenario(), noise: StereoImuNoise = StereoImuNoise()) -> StereoImuDrive:
    """One simulated drive with truth (see the module docstring)."""
    sc = scenario
    rng_world, rng_imu, rng_cam = (np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(3))
    pieces, length_m = _curvature_profile(sc)
    n_steps = int(round(length_m / (sc.speed_mps * sc.dt_s))) + 1
    tau = sc.dt_s
    stamps = np.arange(n_steps) * tau

    twists, poses = _true_twists_and_poses(sc, pieces, length_m, n_steps, rng_world)
    landmarks = _facade_landmarks(sc, poses, rng_world)
    n_landmarks = landmarks.shape[0]

    # ---- IMU
    measured = twists.copy()
    measured[:, :3] += rng_imu.normal(0.0, noise.sigma_v_mps, size=(n_steps, 3))
    measured[:, 3:] += rng_imu.normal(0.0, noise.sigma_w_radps, size=(n_steps, 3))

    # ---- camera
    M = stereo_matrix(KITTI_LIKE_K, KITTI_LIKE_BASELINE_M)
    pixel_factor = None if noise.pixel_covariance is None else np.linalg.cholesky(noise.pixel_cov())
    features = np.full((n_steps, n_landmarks, 4), np.nan)
    track_length = np.zeros(n_landmarks, dtype=int)
    homogeneous = np.hstack([landmarks, np.ones((n_landmarks, 1))])
    for t in range(n_steps):
        q = (KITTI_LIKE_CAM_T_IMU @ inverse(poses[t]) @ homogeneous.T).T
        depth = q[:, 2]
        candidates = []
        for j in np.flatnonzero((depth >= sc.min_depth_m) & (depth <= sc.max_depth_m)):
            z = stereo_pixels(M, q[j])
            inside = EDGE_PX <= min(z[0], z[2]) and max(z[0], z[2]) < IMAGE_WIDTH_PX - EDGE_PX and EDGE_PX <= z[1] < IMAGE_HEIGHT_PX - EDGE_PX
            if inside and rng_cam.random() >= sc.dropout:
                candidates.append((j, z))
        candidates.sort(key=lambda jz: -track_length[jz[0]])
        kept = candidates[: sc.max_features]
        seen_now = np.zeros(n_landmarks, dtype=bool)
        for j, z in kept:
            if pixel_factor is None:
                z = z + rng_cam.normal(0.0, noise.sigma_px, size=4)
            else:
                z = z + pixel_factor @ rng_cam.standard_normal(4)
            if sc.outlier_rate > 0.0 and rng_cam.random() < sc.outlier_rate:
                z = np.abs(z + rng_cam.uniform(-sc.outlier_px, sc.outlier_px, size=4))
            features[t, j] = z
            seen_now[j] = True
        track_length = np.where(seen_now, track_length + 1, 0)

    return StereoImuDrive(
        stamps_s=stamps,
        features_px=features,
        linear_velocity_mps=measured[:, :3],
        angular_velocity_radps=measured[:, 3:],
        K=KITTI_LIKE_K.copy(),
        baseline_m=KITTI_LIKE_BASELINE_M,
        cam_T_imu=KITTI_LIKE_CAM_T_IMU.copy(),
        truth_world_T_imu=poses,
        truth_landmarks_m=landmarks,
        source=f"slamio.sim3d.simulate_drive(seed={seed})",
    )
