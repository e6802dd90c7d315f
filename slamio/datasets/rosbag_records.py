"""Odometry messages and placed detections → the run log's records, for
:func:`slamio.datasets.rosbag.import_rosbag`: each odometry increment with its covariance (from
the messages' growing pose covariance, else the default model), a pose of its own for a
detection between two odometry messages, and the truth interpolated at every pose.
"""

from __future__ import annotations

import bisect
import math
from typing import Any

import numpy as np

from slamio.datasets.mrclam_motion import CommandOdometryNoise, interpolate_pose
from slamio.datasets.rosbag_messages import compose_jacobians
from slamio.datasets.rosbag_options import ImportOptions
from slamio.datasets.rosbag_read import BagFormatError
from slamio.geometry import between_pose, wrap_angle
from slamio.log import Observation, Odometry, Record, TruthPose, as_matrix3

__all__ = ["MIN_INCREMENT_DT_S", "TruthTrack", "default_increment_covariance", "increment_covariance_from_poses",
           "interpolate_se2", "observations_by_pose", "pose_records", "start_pose_of", "thinned"]

#: The default model's shortest time per increment (keeps duplicate stamps positive definite).
MIN_INCREMENT_DT_S = 1e-3


def increment_covariance_from_poses(P_prev: np.ndarray, P_next: np.ndarray, pose_prev, increment) -> np.ndarray | None:
    """The increment covariance that grows ``P_prev`` into ``P_next``, or None if not SPD.

    Inverts the first-order propagation ``P_next = J₁ P_prev J₁ᵀ + J₂ Q J₂ᵀ``.
    """
    J1, J2 = compose_jacobians(pose_prev, increment)
    J2_inv = J2.T  # a rotation
    Q = J2_inv @ (P_next - J1 @ P_prev @ J1.T) @ J2_inv.T
    Q = 0.5 * (Q + Q.T)
    try:
        np.linalg.cholesky(Q)
    except np.linalg.LinAlgError:
        return None
    if not np.all(np.isfinite(Q)):
        return None
    return Q


def default_increment_covariance(increment, dt_s: float, noise: CommandOdometryNoise) -> np.ndarray:
    """The default model's covariance of one increment (see the module docstring)."""
    return noise.stretch_covariance(math.hypot(increment[0], increment[1]), increment[2], max(dt_s, MIN_INCREMENT_DT_S))


def interpolate_se2(pose_a, pose_b, fraction: float) -> tuple[float, float, float]:
    """Linear in x, y; heading along the shorter arc."""
    return (
        pose_a[0] + fraction * (pose_b[0] - pose_a[0]),
        pose_a[1] + fraction * (pose_b[1] - pose_a[1]),
        float(wrap_angle(pose_a[2] + fraction * wrap_angle(pose_b[2] - pose_a[2]))),
    )


def thinned(odometry: list, min_period_s: float) -> list:
    """The odometry messages at least ``min_period_s`` apart (the first and last always kept)."""
    if not min_period_s > 0.0:
        return odometry
    thinned = [odometry[0]]
    for m in odometry[1:-1]:
        if m[0] - thinned[-1][0] >= min_period_s * 1e9:
            thinned.append(m)
    if len(odometry) > 1:
        thinned.append(odometry[-1])
    return thinned


def observations_by_pose(o: ImportOptions, observed: list, odo_times: list[int], dropped: dict[str, int]):
    """The observations (stamp ns, observation), grouped by the pose they belong to: ``at_pose``
    (odometry index → observations) and ``inside`` (interval end index → {time: observations})."""
    at_pose: dict[int, list[Observation]] = {}
    inside: dict[int, dict[int, list[Observation]]] = {}
    for t, obs in observed:
        if t < odo_times[0]:
            dropped["before_first_odometry"] += 1
            continue
        if t > odo_times[-1]:
            dropped["after_last_odometry"] += 1
            continue
        k = bisect.bisect_right(odo_times, t) - 1
        if odo_times[k] == t or not o.interpolate_detections:
            at_pose.setdefault(k, []).append(obs)
        else:
            inside.setdefault(k + 1, {}).setdefault(t, []).append(obs)
    return at_pose, inside


class TruthTrack:
    """The ground-truth messages, interpolated at a log stamp (None where there is none)."""

    def __init__(self, truth: list, t0: int, max_gap_s: float):
        self.any = bool(truth)
        self.times_s = [(t - t0) / 1e9 for t, _ in truth]
        self.poses = np.array([p for _, p in truth]) if truth else np.zeros((0, 3))
        self.max_gap_s = max_gap_s

    def at(self, stamp_s: float):
        return interpolate_pose(self.times_s, self.poses, stamp_s, self.max_gap_s) if self.any else None


def start_pose_of(o: ImportOptions, odometry: list, truth: TruthTrack) -> tuple[float, float, float]:
    if o.start_from == "odom":
        return odometry[0][1]
    if o.start_from == "zero":
        return (0.0, 0.0, 0.0)
    start_pose = truth.at(0.0)
    if start_pose is None:
        raise BagFormatError(o.path, o.truth_topic or "/tf", "has no ground truth at the first odometry message, so start_from='truth' cannot be used")
    return start_pose


def pose_records(o: ImportOptions, odometry: list, at_pose, inside, truth: TruthTrack) -> tuple[list[Record], dict[str, Any]]:
    """The records of every pose (odometry, truth, observations), and the counts of poses,
    of poses with a truth and of the increments' covariance sources."""
    t0 = odometry[0][0]
    records: list[Record] = []
    counts: dict[str, Any] = {"poses": 1, "poses_with_truth": 0,
                              "covariance": {"from_message": 0, "default_model": 0}}

    def add_pose_records(t_ns: int, observations: list[Observation]) -> None:
        tp = truth.at((t_ns - t0) / 1e9)
        if tp is not None:
            records.append(TruthPose((t_ns - t0) / 1e9, *tp))
            counts["poses_with_truth"] += 1
        records.extend(observations)

    add_pose_records(t0, at_pose.get(0, []))
    for i in range(1, len(odometry)):
        (ta, pa, Ca), (tb, pb, Cb) = odometry[i - 1], odometry[i]
        delta = between_pose(pa, pb)
        Q = increment_covariance_from_poses(Ca, Cb, pa, delta) if o.covariance_from_message else None
        if Q is None:
            Q = default_increment_covariance(delta, (tb - ta) * 1e-9, o.noise)
            counts["covariance"]["default_model"] += 1
        else:
            counts["covariance"]["from_message"] += 1
        # poses inside the interval (detections between two odometry messages), then the end
        nodes = [(t, interpolate_se2(pa, pb, (t - ta) / (tb - ta)), obs) for t, obs in sorted(inside.get(i, {}).items())]
        nodes.append((tb, pb, at_pose.get(i, [])))
        previous_t, previous_pose = ta, pa
        for t, pose, obs in nodes:
            fraction = (t - previous_t) / (tb - ta) if tb > ta else 1.0
            d = between_pose(previous_pose, pose)
            records.append(Odometry((t - t0) / 1e9, d[0], d[1], d[2], as_matrix3(Q * fraction)))
            add_pose_records(t, obs)
            previous_t, previous_pose = t, pose
            counts["poses"] += 1
    return records, counts
