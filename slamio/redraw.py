"""The same run with fresh noise: a log's readings redrawn about its truth from the σ it states.

A log with ground truth at every pose says, record by record, how noisy its odometry and
its landmark readings are (each odometry record's covariance, each observation's σ). If
those statements are right, the log is one draw from a known distribution, and
:func:`redraw_noise` makes more draws from it: every odometry increment becomes the true
increment between the two true poses plus Gaussian noise of the record's covariance (the
additive increment model every estimator here assumes), every reading the true range,
bearing, height and tag yaw from the true pose plus Gaussian noise of its σ. Poses,
stamps, which landmark is seen when, and the header stay as they are.

What this is for (:mod:`fgslam.consistency`): the distribution of a statistic over a whole
run — such as the run's mean NEES, whose poses share one map error and are far from
independent — under the hypothesis that the log's stated noise is the truth. A real run
whose statistic falls outside that distribution's band states the wrong noise (or the
estimator is inconsistent); one inside it is as consistent as one run can show.

Pure: takes a :class:`~slamio.log.RunLog` and a seeded generator, returns a new one.
``live_step`` records (wall times) are left out.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from slamio.errors import FgslamError
from slamio.geometry import between_pose, wrap_angle
from slamio.log import Observation, Odometry, RunLog, TruthLandmark

__all__ = ["redraw_noise"]


def redraw_noise(log: RunLog, rng: np.random.Generator) -> RunLog:
    """``log`` with every odometry increment and landmark reading redrawn (module docstring).

    Raises :class:`~slamio.errors.FgslamError` when a pose has no truth, or no true heading
    (GPS truth), or a seen landmark has no surveyed position: without them there is nothing
    to draw about."""
    steps = log.steps()
    missing = [s.index for s in steps if s.truth is None]
    if missing:
        raise FgslamError(f"{log.path}: {len(missing)} of {len(steps)} poses have no truth (first: pose "
                          f"{missing[0]}); redrawing the noise needs the true pose at every step")
    headless = [s.index for s in steps if s.truth.theta_rad is None]
    if headless:
        raise FgslamError(f"{log.path}: the truth of {len(headless)} of {len(steps)} poses has no heading (first: "
                          f"pose {headless[0]}); redrawing the noise needs the true heading at every step")
    landmarks = log.truth_landmarks()
    records: list = []
    previous = None
    for step in steps:
        pose = (step.truth.x_m, step.truth.y_m, step.truth.theta_rad)
        if step.odometry is not None:
            records.append(_redrawn_odometry(step.odometry, previous, pose, rng))
        records.append(step.truth)
        for o in step.observations:
            records.append(_redrawn_observation(o, pose, _landmark_of(o, landmarks, log.path), rng))
        previous = pose
    records.extend(landmarks.values())
    return dataclasses.replace(log, records=tuple(records), truncated=None, rejected=())


def _redrawn_odometry(record: Odometry, from_pose, to_pose, rng) -> Odometry:
    true_increment = np.asarray(between_pose(from_pose, to_pose), dtype=float)
    noise = rng.multivariate_normal(np.zeros(3), np.asarray(record.covariance, dtype=float))
    dx, dy, dtheta = true_increment + noise
    return dataclasses.replace(record, dx_m=float(dx), dy_m=float(dy), dtheta_rad=float(wrap_angle(dtheta)),
                               distance_m=None, angle_rad=None)


def _landmark_of(o: Observation, landmarks: dict[int, TruthLandmark], path: str) -> TruthLandmark:
    key = o.landmark_id if o.landmark_id is not None else o.truth_landmark_id
    if key is None or key not in landmarks:
        raise FgslamError(f"{path}: an observation at {o.stamp_s:.3f} s is of landmark {key}, which has no "
                          "truth_landmark record; redrawing the noise needs every seen landmark's position")
    return landmarks[key]


def _redrawn_observation(o: Observation, pose, landmark: TruthLandmark, rng) -> Observation:
    x, y, theta = pose
    dx, dy = landmark.x_m - x, landmark.y_m - y
    changes = {"range_m": max(math.hypot(dx, dy) + rng.normal(0.0, o.sigma_range_m), 1e-3)}
    if not o.range_only:
        changes["bearing_rad"] = float(wrap_angle(math.atan2(dy, dx) - theta + rng.normal(0.0, o.sigma_bearing_rad)))
    if o.height_m is not None and o.sigma_height_m is not None and landmark.height_m is not None:
        changes["height_m"] = landmark.height_m + rng.normal(0.0, o.sigma_height_m)
    if o.tag_yaw_rad is not None and o.sigma_tag_yaw_rad is not None and landmark.yaw_rad is not None:
        changes["tag_yaw_rad"] = float(wrap_angle(landmark.yaw_rad - theta + rng.normal(0.0, o.sigma_tag_yaw_rad)))
    return dataclasses.replace(o, **changes)

