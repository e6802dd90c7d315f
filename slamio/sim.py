"""Deterministic simulator: world + iRobot Create + landmark sensor → a run log with truth.

``simulate(scenario, seed)`` returns ``(Header, records)`` ready for
:func:`slamio.log.write_log`. The same seed gives exactly the same records; all randomness
comes from ``numpy.random.default_rng(seed)`` (split into one stream for the motion and one
for the sensor, so changing the sensor never changes the trajectory; a third stream, used
only when ``outliers`` > 0, draws the outliers).

This module drives the robot and writes the log; the robot and sensor models and their
maths are in :mod:`slamio.sim_models`, the scenarios (worlds, paths, settings) in
:mod:`slamio.sim_worlds`. Everything is imported from here.

How one run is made
===================

1. **World.** Landmarks (id 0..N−1) with a floor position, and for AprilTags the direction
   their face points (``yaw_rad``) and for tags/cylinders a height.
2. **Path.** A closed polygon of waypoints, driven ``laps`` times and ending back at the
   first waypoint (so the run closes a loop). The robot starts exactly on waypoint 0,
   facing waypoint 1.
3. **Robot.** A differential-drive Create, wheel base ``b = 0.235 m``. Every ``dt_s`` a
   waypoint follower picks (v, ω) from the *true* pose (a perfect localiser the
   estimators never see), so the true path stays on the polygon despite slip:

   - it aims at a "carrot" ``lookahead_m`` ahead along the current segment (clamped to the
     segment's end) and turns at ``ω = clip(turn_gain_per_s · heading_error,
     ±max_turn_rate_rad_s)``;
   - it drives at ``v = speed_m_s · max(0, cos(heading_error))²``: full speed when lined
     up, an arc at a 45° corner (octagon), turning in place at a 90° corner (square);
   - the wheel speeds ``v ∓ ω·b/2`` are scaled down together (curvature kept) when one
     would exceed the Create's 0.5 m/s;
   - a segment is done when less than half a nominal step of it remains.

   True wheel distances ``dL, dR = wheel speed · dt``; true centre distance
   ``ΔS = (dL + dR)/2`` and heading change ``Δθ = (dR − dL)/b``. The true pose moves by
   the arc increment and then by a small **slip** ``s ~ N(0, diag(σ_slip_x², σ_slip_y²,
   σ_slip_θ²))`` in the frame of the arc's end::

       T_next = T_prev ⊕ arc_increment(ΔS, Δθ) ⊕ s

4. **Odometry.** Each wheel is measured with a relative error per step,
   ``d_meas = d_true · (1 + ε)``, ``ε ~ N(0, k_wheel²)``. The record carries the
   Create's own reading ``distance_m = (dL_meas + dR_meas)/2``,
   ``angle_rad = (dR_meas − dL_meas)/b`` and the increment
   ``arc_increment(distance_m, angle_rad)``. Its covariance over (dx, dy, dθ) is the
   first-order propagation of the generative noise (see :func:`odometry_covariance`)::

       Σ = J_arc · A · diag((k·dL)², (k·dR)²) · Aᵀ · J_arcᵀ + R(Δθ) Σ_slip R(Δθ)ᵀ

   with ``A = [[½, ½], [−1/b, 1/b]]`` (wheels → (ΔS, Δθ)), ``J_arc`` the Jacobian of the
   arc model and ``R(Δθ)`` the rotation by the arc's turn (slip happens at the arc's end),
   all evaluated at the *true* wheel distances: it is exactly the noise that was used.
   The error ``e = increment_meas − between(T_prev, T_next)`` (angle wrapped) has this
   covariance to first order.

5. **Sensor.** Mounted at the robot's centre, looking along x. A landmark is observed when
   ``min_range_m ≤ range ≤ max_range_m`` and ``|bearing| ≤ fov_rad/2``; an AprilTag also
   only when it faces the camera: the angle between the tag's face normal and the
   tag→robot direction is below ``facing_limit_rad`` (70°). Measurements::

       range_m     = range + σ_r(range)·n,   σ_r(r) = a + b·r + c·r²  (per scenario)
       bearing_rad = wrap(bearing + σ_b·n)
       height_m    = height + σ_h·n                         (cylinders)
       tag_yaw_rad = wrap(tag yaw − robot θ + σ_yaw·n)      (tags)

   Every record carries the σ actually used (σ_r at the true range).

``noise_scale`` multiplies every random draw (wheel error, slip, measurement noise) but not
the written covariances/sigmas: ``noise_scale=0`` gives exact measurements with the nominal
uncertainty (estimator tests), ``noise_scale=2`` a log whose stated noise is too optimistic.

6. **Outliers** (``outliers`` = p, default 0). Each observation independently, with
   probability p, is replaced by a *misdetection with a valid id*: the front-end reports
   the right landmark id at a wrong place, as a camera does when a tag is decoded off a
   reflection or a colour blob is found on the wrong object. Its range and bearing are
   drawn uniformly over what the sensor can report::

       range_m     ~ U(min_range_m, max_range_m)
       bearing_rad ~ U(−fov_rad/2, fov_rad/2)

   independently of the true geometry (so an outlier may by chance land near the truth;
   with the arena camera fewer than 1 % do within 3σ). Height and tag yaw keep their
   ordinary noisy values, and the record's sigmas stay the nominal ones (σ_r at the true
   range): the front-end does not know it erred, and nothing in the record marks an
   outlier. ``noise_scale`` does not touch outliers. The draws come from a third random
   stream, spawned after the motion and sensor streams, which are therefore unchanged:
   with the same seed a log with outliers has the same trajectory, odometry and inlier
   measurements as the log without, and a larger p gives a superset of the outliers
   (each observation draws u ~ U(0, 1) and is an outlier when u < p). With p = 0 nothing
   is drawn and the log is byte-identical to one made before outliers existed; p > 0 is
   recorded in ``header.source["outliers"]``.

   With ``outlier_mode="add"`` (``fgslam sim --outlier-mode add``) nothing is replaced:
   each observation is followed, with probability p/(1 − p), by a misdetection drawn as
   above (same id, sigmas, height and tag yaw), so a share p of all observations are
   outliers and the log minus its outliers is exactly the outlier-free log — the
   comparison "ATE with outliers vs without" then measures the estimator alone, not the
   information the replaced observations took with them. Recorded as
   ``header.source["outlier_mode"] = "add"``.

Scenarios and their numbers
===========================

``arena-square``, ``arena-octagon`` (seed 004)
    A 10 ft × 10 ft arena, corners (0, 0)–(3.048, 3.048) m. Eight AprilTags, two per wall at
    1/3 and 2/3 along it, facing into the arena, centre height 0.20 m; ids 0–1 south wall
    (y = 0), 2–3 east (x = 3.048), 4–5 north, 6–7 west (counter-clockwise).
    Paths centred in the arena: a 1.829 m (6 ft) square, or a regular octagon with the same
    width across flats (side 0.758 m). Default 2 laps (about 820 and 660 steps).
    Robot: 0.2 m/s, dt 0.1 s, turns at most 0.8 rad/s (gain 2/s), lookahead 0.25 m.
    Odometry: k_wheel 0.05; slip σ 0.5 mm, 0.5 mm, 1 mrad per step (heading random walk
    ≈ 0.043 rad per √m driven).
    Camera: FOV 1.2 rad (69°), range 0.15–3.5 m, tags seen up to 70° off their normal;
    σ_r = 0.01 m + 0.005 m⁻¹·r² (pose-from-tag-size error grows with r²),
    σ_b = 0.01 rad, σ_tag_yaw = 0.05 rad. With ``tag_noise="measured"`` instead: each
    observation's σ from :data:`ARENA_TAG_NOISE` (slamio/camera/tag_noise.py: a 0.16 m tag,
    fx 468 px, corner σ 0.46 px; range σ ∝ r², yaw σ largest head on and far away).

``cylinders`` (seed 000)
    A 5 m × 5 m room with three coloured cylinders: red (id 0, height 0.40 m), green
    (id 1, 0.60 m), blue (id 2, 0.80 m). The path is an equilateral triangle (side 2.25 m,
    centred in the room) and each cylinder stands 1.0 m beyond the end of one leg, on
    its line: every leg drives straight at a cylinder from 3.25 m to 1.0 m, inside the
    Kinect's depth range. Default 3 laps (about 1 170 steps).
    Robot and odometry as in the arena. Kinect: FOV 57° (0.995 rad), depth 0.8–4.0 m;
    σ_r = 0.01 m + 1.425e-3 m⁻¹·r² (blob-centre floor plus the Kinect's depth noise,
    Khoshelham & Elberink 2012), σ_b = 0.01 rad, σ_h = 0.02 m.

``grid`` (``landmarks`` = N)
    N point landmarks on a square-ish grid, 3 m spacing (``grid_spacing_m`` changes it, and
    the lanes with it): C = ⌈√N⌉ columns, id i at
    (3·(i mod C), 3·(i div C)). The robot mows lanes between landmark rows, every third gap
    (y = 1.5, 10.5, 19.5, … m: every landmark is within 4.5 m of a lane), each lane
    running 2 m past the outer columns, then drives straight back to the start (for a single
    lane, around the first row instead). Default 2 laps. N = 200: about 6 600 steps.
    Robot: 0.5 m/s, dt 0.2 s, turns at most 1.0 rad/s, lookahead 1.0 m.
    Odometry: k_wheel 0.01 (steps are five times longer than the arena's, so this is a
    heading random walk of ≈ 0.019 rad per √m); slip σ 2 mm, 2 mm, 1 mrad per step.
    Sensor: FOV 120° (2.094 rad), range 0.3–6.0 m; σ_r = 0.03 m + 0.01·r, σ_b = 0.02 rad.

``clutter`` (issue 44)
    :func:`slamio.clutter.clutter_world` of seed 0 (whatever the simulator's seed): a 6 m ×
    6 m room, boxes and cylinders kept 0.42 m off the path, a 3 m square 1.5 m in from the
    walls (default 2 laps). Landmarks: its 14 AprilTags (0.20 m up, 12 on the walls, 2 on
    boxes), seen as in the arena but with the Kinect's FOV 57° and range 0.15–4.0 m, and
    only when no wall, box or cylinder stands between (``World.obstacles``). docs/clutter.md.

The odometry noise makes dead reckoning drift clearly while a landmark is in view nearly
all the time, so an EKF's heading uncertainty stays small and its linearisation sound.
Measured when this was written with seed 1 and ``fgslam run`` (ATE in metres), dead
reckoning vs EKF / iSAM2: arena-square 0.080 vs 0.011 / 0.011, arena-octagon 0.067 vs 0.011 / 0.008,
cylinders 0.054 vs 0.026 / 0.016 (0.10–0.19 vs 0.014–0.033 for seeds 2–4),
grid (N = 200) 11.4 vs 0.40 / 0.19.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from dataclasses import dataclass
from typing import Any

import numpy as np

from slamio.camera.tag_noise import view_angle_rad
from slamio.errors import FgslamError
from slamio.geometry import arc_increment, compose_pose, wrap_angle
from slamio.log import Header, Observation, Odometry, Record, TruthLandmark, TruthPose
from slamio.sim_models import (  # re-exported (__all__): slamio.sim is the simulator's public face
    MAX_WHEEL_SPEED_M_S,
    WHEEL_BASE_M,
    MotionModel,
    SensorModel,
    Sightings,
    WheelSlipNoise,
    World,
    observation_sigmas,
    odometry_covariance,
    range_sigma_m,
    visible_landmarks,
    wheel_reading,
    wheel_speeds_m_s,
)
from slamio.sim_worlds import (  # re-exported too
    ARENA_PATH_WIDTH_M,
    ARENA_SIDE_M,
    ARENA_TAG_NOISE,
    GRID_SPACING_M,
    SCENARIOS,
    TAG_HEIGHT_M,
    Scenario,
    arena_tags,
    cylinder_world,
    grid_landmarks_xy,
    grid_path,
    polygon_path,
    scenario as _scenario,
)


__all__ = [
    "SCENARIOS",
    "WHEEL_BASE_M",
    "MAX_WHEEL_SPEED_M_S",
    "MAX_GRID_LANDMARKS",
    "simulate",
    "wheel_speeds_m_s",
    "wheel_reading",
    "odometry_covariance",
    "range_sigma_m",
    "visible_landmarks",
    "arena_tags",
    "polygon_path",
    "cylinder_world",
    "grid_landmarks_xy",
    "grid_path",
    "World",
    "WheelSlipNoise",
    "ARENA_SIDE_M",
    "ARENA_PATH_WIDTH_M",
    "TAG_HEIGHT_M",
]

TAG_NOISE_MODELS = ("nominal", "measured")
MAX_GRID_LANDMARKS = 20_000  # a guard against a typo that would simulate for hours
START_SIGMA = (1e-3, 1e-3, 1e-3)
SIMULATOR_VERSION = 1


def _observation_sigmas(seen: Sightings, sensor: SensorModel, tag_noise: str):
    """Per-observation σ of range, bearing and tag yaw (None without tags) at the true values."""
    if tag_noise == "measured":
        view = view_angle_rad(seen.bearing_rad, seen.tag_yaw_rad)
        return (ARENA_TAG_NOISE.sigma_range_m(seen.range_m, view), ARENA_TAG_NOISE.sigma_bearing_rad(seen.range_m),
                ARENA_TAG_NOISE.sigma_tag_yaw_rad(seen.range_m, view))
    count = len(seen.range_m)
    yaw = None if sensor.sigma_tag_yaw_rad is None else np.full(count, sensor.sigma_tag_yaw_rad)
    return range_sigma_m(seen.range_m, sensor), np.full(count, sensor.sigma_bearing_rad), yaw


# --------------------------------------------------------------------------- driving


@dataclass(frozen=True)
class _Drive:
    """The outcome of driving the path: true poses and wheel distances per step."""

    poses: np.ndarray  # (T+1, 3) true poses, pose 0 = start
    left_true_m: np.ndarray  # (T,)
    right_true_m: np.ndarray
    left_meas_m: np.ndarray
    right_meas_m: np.ndarray


def _command(pose: tuple[float, float, float], start: np.ndarray, end: np.ndarray,
             motion: MotionModel) -> tuple[float, float, float]:
    """(v, ω, remaining_m) of the waypoint follower on the segment start→end."""
    x, y, theta = pose
    seg = end - start
    length = math.hypot(seg[0], seg[1])
    ux, uy = seg[0] / length, seg[1] / length
    along = (x - start[0]) * ux + (y - start[1]) * uy
    carrot = min(along + motion.lookahead_m, length)
    tx, ty = start[0] + carrot * ux, start[1] + carrot * uy
    error = wrap_angle(math.atan2(ty - y, tx - x) - theta)
    turn = max(-motion.max_turn_rate_rad_s, min(motion.max_turn_rate_rad_s, motion.turn_gain_per_s * error))
    speed = motion.speed_m_s * max(0.0, math.cos(error)) ** 2
    return speed, turn, length - along


def _drive(scenario: Scenario, laps: int, noise_scale: float, rng: np.random.Generator) -> _Drive:
    """Drive the path ``laps`` times from waypoint 0 back to it, with slip and wheel noise."""
    motion, noise = scenario.motion, scenario.odometry
    loop = scenario.waypoints_xy
    route = [loop[i % len(loop)] for i in range(laps * len(loop) + 1)]
    first_leg = route[1] - route[0]
    pose = (float(route[0][0]), float(route[0][1]), math.atan2(first_leg[1], first_leg[0]))
    poses = [pose]
    left_true: list[float] = []
    right_true: list[float] = []
    left_meas: list[float] = []
    right_meas: list[float] = []
    done_within_m = 0.5 * motion.speed_m_s * motion.dt_s
    route_m = sum(math.dist(a, b) for a, b in zip(route, route[1:]))
    max_steps = int(10 * route_m / (motion.speed_m_s * motion.dt_s)) + 10_000
    slip_sigma = (noise.slip_sigma_x_m, noise.slip_sigma_y_m, noise.slip_sigma_theta_rad)
    draws = np.zeros((0, 5))
    segment = 0
    while segment < len(route) - 1:
        speed, turn, remaining = _command(pose, route[segment], route[segment + 1], motion)
        if remaining <= done_within_m:
            segment += 1
            continue
        if len(left_true) >= max_steps:
            raise RuntimeError(f"simulator bug: the robot did not finish the {scenario.name} path in {max_steps} steps")
        k = len(left_true) % 4096
        if k == 0:
            draws = (noise_scale * rng.standard_normal((4096, 5))).tolist()
        e_left, e_right, sx, sy, sth = draws[k]
        v_left, v_right = wheel_speeds_m_s(speed, turn)
        d_left, d_right = v_left * motion.dt_s, v_right * motion.dt_s
        distance, angle = wheel_reading(d_left, d_right)
        slip = (sx * slip_sigma[0], sy * slip_sigma[1], sth * slip_sigma[2])
        pose = compose_pose(compose_pose(pose, arc_increment(distance, angle)), slip)
        poses.append(pose)
        left_true.append(d_left)
        right_true.append(d_right)
        left_meas.append(d_left * (1.0 + noise.k_wheel * e_left))
        right_meas.append(d_right * (1.0 + noise.k_wheel * e_right))
    return _Drive(np.array(poses), np.array(left_true), np.array(right_true), np.array(left_meas), np.array(right_meas))


# --------------------------------------------------------------------------- the log


def _check_arguments(scenario: Any, seed: Any, landmarks: Any, laps: Any, noise_scale: Any, outliers: Any = 0.0) -> None:
    if scenario not in SCENARIOS:
        raise FgslamError(f"unknown scenario {scenario!r}; choose one of: {', '.join(SCENARIOS)}")
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or seed < 0:
        raise FgslamError(f"seed must be a non-negative integer, got {seed!r}")
    if isinstance(landmarks, bool) or not isinstance(landmarks, numbers.Integral) or not 1 <= landmarks <= MAX_GRID_LANDMARKS:
        raise FgslamError(
            f"landmarks must be an integer from 1 to {MAX_GRID_LANDMARKS} (used by the grid scenario), got {landmarks!r}"
        )
    if laps is not None and (isinstance(laps, bool) or not isinstance(laps, numbers.Integral) or laps < 1):
        raise FgslamError(f"laps must be an integer ≥ 1, or None for the scenario's default, got {laps!r}")
    if (
        isinstance(noise_scale, bool)
        or not isinstance(noise_scale, numbers.Real)
        or not math.isfinite(noise_scale)
        or noise_scale < 0
    ):
        raise FgslamError(f"noise_scale must be a finite number ≥ 0 (0 = exact measurements, 1 = nominal), got {noise_scale!r}")
    if (
        isinstance(outliers, bool)
        or not isinstance(outliers, numbers.Real)
        or not math.isfinite(outliers)
        or not 0.0 <= outliers < 1.0
    ):
        raise FgslamError(
            f"outliers must be a fraction 0 ≤ outliers < 1 of the observations to replace by misdetections, got {outliers!r}"
        )


def _header(sc: Scenario, start_pose: tuple[float, float, float], seed: int, laps: int, noise_scale: float,
            command: str | None) -> Header:
    m, o, s = sc.motion, sc.odometry, sc.sensor
    sensor: dict[str, Any] = {
        "kind": "range-bearing",
        "landmark_kind": s.landmark_kind,
        "fov_rad": s.fov_rad,
        "min_range_m": s.min_range_m,
        "max_range_m": s.max_range_m,
        "mount": "at the robot's centre, looking along robot x",
    }
    if s.facing_limit_rad is not None:
        sensor["facing_limit_rad"] = s.facing_limit_rad
    sensor.update(sc.extra_sensor_info)
    observation: dict[str, Any] = {
        "model": "range-bearing, additive Gaussian; sigma_range = sigma_range_m + sigma_range_per_m*r + sigma_range_per_m2*r^2 at the true range r",
        **observation_sigmas(s),
    }
    return Header(
        stamp_s=0.0,
        start_pose=start_pose,
        start_sigma=START_SIGMA,
        robot={
            "name": "simulated iRobot Create",
            "drive": "differential",
            "wheel_base_m": WHEEL_BASE_M,
            "max_wheel_speed_m_s": MAX_WHEEL_SPEED_M_S,
            "speed_m_s": m.speed_m_s,
            "max_turn_rate_rad_s": m.max_turn_rate_rad_s,
            "dt_s": m.dt_s,
        },
        sensor=sensor,
        noise={
            "odometry": {
                "model": "wheel-proportional plus slip: d_meas = d_true*(1 + N(0, k_wheel^2)) per wheel per step; "
                "true pose = pose + arc(true) + N(0, diag(slip_sigma^2)) in the arc's end frame; "
                "covariance = first-order propagation at the true wheel distances",
                "k_wheel": o.k_wheel,
                "slip_sigma_x_m": o.slip_sigma_x_m,
                "slip_sigma_y_m": o.slip_sigma_y_m,
                "slip_sigma_theta_rad": o.slip_sigma_theta_rad,
                "wheel_base_m": WHEEL_BASE_M,
                "dt_s": m.dt_s,
            },
            "observation": observation,
            "noise_scale": noise_scale,
        },
        source={
            "generator": "slamio.sim",
            "simulator_version": SIMULATOR_VERSION,
            "scenario": sc.name,
            "seed": int(seed),
            "landmarks": int(len(sc.world.landmarks_xy)),
            "laps": int(laps),
            "noise_scale": noise_scale,
            "command": command,
        },
    )


def simulate(
    scenario: str,
    seed: int,
    *,
    landmarks: int = 200,
    laps: int | None = None,
    noise_scale: float = 1.0,
    hide_ids: bool = False,
    command: str | None = None,
    outliers: float = 0.0,
    outlier_mode: str = "replace",
    tag_noise: str = "nominal",
    grid_spacing_m: float = GRID_SPACING_M,
) -> tuple[Header, list[Record]]:
    """Simulate one run of ``scenario`` and return its log ``(header, records)``.

    ``scenario`` is one of :data:`SCENARIOS`; ``seed`` a non-negative integer (the only
    source of randomness); ``landmarks`` the number of landmarks of the ``grid`` scenario
    (ignored by the others); ``laps`` overrides the scenario's default number of laps;
    ``noise_scale`` multiplies every random error (0 = exact measurements) while the
    records keep the nominal covariances and sigmas; ``command`` is kept in
    ``header.source["command"]``. ``hide_ids`` writes every observation with
    ``landmark_id`` null (the estimator must associate it) and the true id in
    ``truth_landmark_id``, for scoring the association. ``outliers`` (0 ≤ p < 1) replaces
    each observation with probability p by a misdetection of the same landmark at a
    uniformly random range and bearing within the sensor's limits (module docstring,
    step 6); the records do not say which. ``outlier_mode="add"`` keeps every observation
    and adds the misdetections instead (each observation is followed by one with
    probability p/(1 − p), so that a share p of all observations are outliers).
    ``tag_noise="measured"`` (AprilTag scenarios only) draws each tag observation's range,
    bearing and yaw noise from :data:`ARENA_TAG_NOISE`, which depends on the range and the
    viewing angle, and writes that observation's own σ into its record.
    ``grid_spacing_m`` sets the ``grid`` scenario's landmark spacing (and its lanes with it).

    Record order: a ``TruthLandmark`` per landmark (ids 0..N−1); ``TruthPose`` of pose 0
    and its observations; then per step ``Odometry``, ``TruthPose`` and the observations at
    the new pose, all with the same stamp (k·dt). Raises :class:`FgslamError` on a bad
    argument.
    """
    _check_arguments(scenario, seed, landmarks, laps, noise_scale, outliers)
    if outlier_mode not in ("replace", "add"):
        raise FgslamError(f"outlier_mode must be 'replace' or 'add', got {outlier_mode!r}")
    if tag_noise not in TAG_NOISE_MODELS:
        raise FgslamError(f"tag_noise must be one of {', '.join(TAG_NOISE_MODELS)}, got {tag_noise!r}")
    noise_scale = float(noise_scale)
    outliers = float(outliers)
    if not (isinstance(grid_spacing_m, numbers.Real) and math.isfinite(grid_spacing_m) and grid_spacing_m > 0):
        raise FgslamError(f"grid_spacing_m must be a positive number of metres, got {grid_spacing_m!r}")
    sc = _scenario(scenario, int(landmarks), float(grid_spacing_m))
    laps = sc.default_laps if laps is None else int(laps)
    # spawn(3)'s first two children are spawn(2)'s: the motion and sensor streams do not
    # depend on whether outliers are drawn.
    motion_rng, sensor_rng, outlier_rng = np.random.default_rng(int(seed)).spawn(3)

    drive = _drive(sc, laps, noise_scale, motion_rng)
    start_pose = tuple(float(v) for v in drive.poses[0])
    if tag_noise == "measured" and sc.sensor.facing_limit_rad is None:
        raise FgslamError(f"tag_noise='measured' is for the AprilTag scenarios (arena-*), not {scenario!r}")
    header = _header(sc, start_pose, int(seed), laps, noise_scale, command)
    if tag_noise == "measured":
        noise = {**header.noise, "observation": ARENA_TAG_NOISE.describe()}
        header = dataclasses.replace(header, noise=noise, source={**header.source, "tag_noise": "measured"})
    if hide_ids:
        header = dataclasses.replace(header, source={**header.source, "hide_ids": True})
    if outliers > 0.0:
        header = dataclasses.replace(header, source={**header.source, "outliers": outliers})
        if outlier_mode == "add":
            header = dataclasses.replace(header, source={**header.source, "outlier_mode": "add"})

    # Observations: exact values for every landmark in view, then noise.
    seen = visible_landmarks(drive.poses, sc.world, sc.sensor)
    measured = _measure(seen, sc, noise_scale, tag_noise, outliers, outlier_mode, sensor_rng, outlier_rng)
    return header, _records(sc, drive, seen, measured, hide_ids)


@dataclass
class _Measured:
    """Every observation's measured values and σ (lists, one entry per row of the sightings)."""

    ranges: list[float]
    bearings: list[float]
    sigmas_r: list[float]
    sigmas_b: list[float]
    sigmas_yaw: list[float] | None
    heights: list[float] | None
    yaws: list[float] | None
    extra: list[bool] | None = None  # add mode: whether observation j is followed by a misdetection
    range_out: list[float] | None = None  # add mode: the misdetections' values
    bearing_out: list[float] | None = None


def _measure(seen: Sightings, sc: Scenario, noise_scale: float, tag_noise: str, outliers: float, outlier_mode: str,
             sensor_rng: np.random.Generator, outlier_rng: np.random.Generator) -> _Measured:
    """The noise and the misdetections (module docstring, step 6) on the exact sightings."""
    s = sc.sensor
    n = noise_scale * sensor_rng.standard_normal((len(seen.pose_index), 4))
    sigma_range, sigma_bearing, sigma_yaw = _observation_sigmas(seen, s, tag_noise)
    range_meas = seen.range_m + sigma_range * n[:, 0]
    bearing_meas = wrap_angle(seen.bearing_rad + sigma_bearing * n[:, 1])
    extra = range_out = bearing_out = None
    if outliers > 0.0:
        # Misdetections with a valid id (step 6); drawn for every observation so that the
        # values do not depend on p, and a larger p only adds outliers.
        count = len(seen.pose_index)
        u = outlier_rng.random(count)
        range_out = outlier_rng.uniform(s.min_range_m, s.max_range_m, count)
        bearing_out = outlier_rng.uniform(-0.5 * s.fov_rad, 0.5 * s.fov_rad, count)
        if outlier_mode == "replace":
            is_outlier = u < outliers
            range_meas = np.where(is_outlier, range_out, range_meas)
            bearing_meas = np.where(is_outlier, bearing_out, bearing_meas)
            range_out = bearing_out = None
        else:
            extra = (u < outliers / (1.0 - outliers)).tolist()
            range_out, bearing_out = range_out.tolist(), bearing_out.tolist()
    height_meas = None
    if s.sigma_height_m is not None:
        height_meas = (sc.world.heights_m[seen.landmark_id] + s.sigma_height_m * n[:, 2]).tolist()
    yaw_meas = None
    if sigma_yaw is not None:
        yaw_meas = wrap_angle(seen.tag_yaw_rad + sigma_yaw * n[:, 3]).tolist()
    return _Measured(range_meas.tolist(), bearing_meas.tolist(), sigma_range.tolist(), sigma_bearing.tolist(),
                     None if sigma_yaw is None else sigma_yaw.tolist(), height_meas, yaw_meas,
                     extra, range_out, bearing_out)


def _records(sc: Scenario, drive: _Drive, seen: Sightings, m: _Measured, hide_ids: bool) -> list[Record]:
    """The run's records in the order :func:`simulate` gives."""
    records: list[Record] = []
    world = sc.world
    for i, (x, y) in enumerate(world.landmarks_xy.tolist()):
        records.append(TruthLandmark(
            i, x, y,
            None if world.heights_m is None else float(world.heights_m[i]),
            None if world.yaws_rad is None else float(world.yaws_rad[i]),
        ))

    # Odometry records: the Create's reading from the measured wheels, the arc increment,
    # and the covariance of the generative noise at the true wheel distances.
    distance_m, angle_rad = wheel_reading(drive.left_meas_m, drive.right_meas_m)
    covariances = odometry_covariance(drive.left_true_m, drive.right_true_m, sc.odometry).tolist()
    n_steps = len(drive.left_true_m)
    stamps = [round(k * sc.motion.dt_s, 9) for k in range(n_steps + 1)]
    bounds = np.searchsorted(seen.pose_index, np.arange(n_steps + 2)).tolist()
    ids = seen.landmark_id.tolist()
    sigma_h = sc.sensor.sigma_height_m
    poses = drive.poses.tolist()
    distances, angles = distance_m.tolist(), angle_rad.tolist()
    for k in range(n_steps + 1):
        stamp = stamps[k]
        if k > 0:
            dx, dy, dth = arc_increment(distances[k - 1], angles[k - 1])
            cov = covariances[k - 1]
            records.append(Odometry(
                stamp, dx, dy, dth, (tuple(cov[0]), tuple(cov[1]), tuple(cov[2])), distances[k - 1], angles[k - 1],
            ))
        records.append(TruthPose(stamp, *poses[k]))
        for j in range(bounds[k], bounds[k + 1]):
            observed = [(m.ranges[j], m.bearings[j])]
            if m.extra is not None and m.extra[j]:  # add mode: a misdetection after the real one
                observed.append((m.range_out[j], m.bearing_out[j]))  # type: ignore[index]
            for range_m, bearing_rad in observed:
                records.append(Observation(
                    stamp, None if hide_ids else ids[j], range_m, bearing_rad, m.sigmas_r[j], m.sigmas_b[j],
                    None if m.heights is None else m.heights[j],
                    sigma_h,
                    None if m.yaws is None else m.yaws[j],
                    None if m.sigmas_yaw is None else m.sigmas_yaw[j],
                    ids[j] if hide_ids else None,
                ))
    return records
