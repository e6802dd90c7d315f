"""Hand-built logs for the smoother's tests: a robot driving laps of a circle among a handful
of landmarks, with exact or seeded-noisy odometry and observations whose sigmas are written
in the records; and the bad readings the failure tests add to them."""

from __future__ import annotations

import math

import numpy as np

from builders import minimal_header
from slamio.geometry import arc_increment, compose_pose, wrap_angle
from slamio.log import Header, Observation, Odometry, Step, TruthPose, as_matrix3, group_steps

SIGMA_ODO = (0.02, 0.01, 0.01)  # dx_m, dy_m, dtheta_rad — anisotropic on purpose
SIGMA_RANGE = 0.05
SIGMA_BEARING = 0.02
LANDMARKS = {
    0: (0.0, 0.0),
    1: (4.5, 1.0),
    2: (-4.5, -1.0),
    3: (1.0, 4.5),
    4: (-1.0, -4.5),
    5: (0.5, -1.0),
}


def make_header(start_pose=(3.0, 0.0, math.pi / 2), start_sigma=(1e-3, 1e-3, 1e-3)) -> Header:
    return minimal_header(start_pose=start_pose, start_sigma=start_sigma)


def observe(pose, landmark, stamp, lid, rng=None, max_range=4.5, fov=math.radians(100)):
    """An Observation of a world landmark from a true pose, or None when out of view."""
    dx, dy = landmark[0] - pose[0], landmark[1] - pose[1]
    rng_m = math.hypot(dx, dy)
    bearing = wrap_angle(math.atan2(dy, dx) - pose[2])
    if rng_m > max_range or abs(bearing) > fov:
        return None
    if rng is not None:
        rng_m += rng.normal(0.0, SIGMA_RANGE)
        bearing = wrap_angle(bearing + rng.normal(0.0, SIGMA_BEARING))
    return Observation(stamp, lid, rng_m, bearing, SIGMA_RANGE, SIGMA_BEARING)


def make_loop_log(n_steps=200, steps_per_lap=100, radius=3.0, seed=None, unknown_every=0):
    """Header, steps, true poses (n, 3) and true landmarks for laps around a circle.

    ``seed`` None makes exact data; otherwise odometry and observations get Gaussian
    noise with exactly the covariances written in the records. ``unknown_every`` > 0
    adds an observation with ``landmark_id=None`` every that many steps.
    """
    step_angle = 2 * math.pi / steps_per_lap
    increments = [arc_increment(radius * step_angle, step_angle)] * (n_steps - 1)
    return make_log(increments, seed=seed, unknown_every=unknown_every)


def make_log(increments, seed=None, unknown_every=0):
    """Like :func:`make_loop_log` for any list of true SE(2) increments."""
    n_steps = len(increments) + 1
    rng = None if seed is None else np.random.default_rng(seed)
    header = make_header()
    Q = np.diag(np.square(SIGMA_ODO))
    poses = [header.start_pose]
    records = []
    stamp = 0.0

    def observations_at(k, pose):
        out = []
        for lid, lm in LANDMARKS.items():
            obs = observe(pose, lm, stamp, lid, rng)
            if obs is not None:
                out.append(obs)
        if unknown_every and k % unknown_every == 0:
            out.append(Observation(stamp, None, 2.0, 0.1, SIGMA_RANGE, SIGMA_BEARING))
        return out

    records += observations_at(0, poses[0])
    for k, true_increment in enumerate(increments, start=1):
        stamp += 0.1
        pose = compose_pose(poses[-1], true_increment)
        poses.append(pose)
        measured = np.array(true_increment)
        if rng is not None:
            measured = measured + rng.multivariate_normal(np.zeros(3), Q)
        records.append(Odometry(stamp, *map(float, measured), covariance=as_matrix3(Q)))
        records.append(TruthPose(stamp, *pose))
        records += observations_at(k, pose)
    steps = group_steps(header, records)
    assert len(steps) == n_steps
    return header, steps, np.array(poses), dict(LANDMARKS)


def pose_difference(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """Max position difference (m) and max heading difference (rad) between trajectories."""
    pos = np.max(np.hypot(a[:, 0] - b[:, 0], a[:, 1] - b[:, 1]))
    ang = np.max(np.abs(wrap_angle(a[:, 2] - b[:, 2])))
    return float(pos), float(ang)


def junk(step: Step, landmark_id: int) -> Observation:
    """An observation at (practically) zero range: GTSAM's linear system becomes singular."""
    return Observation(step.stamp_s, landmark_id, 1e-300, 0.0, SIGMA_RANGE, SIGMA_BEARING)


def with_extra(step: Step, *extra: Observation) -> Step:
    return Step(step.index, step.stamp_s, step.odometry, step.observations + extra, step.truth)
