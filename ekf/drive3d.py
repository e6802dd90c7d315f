"""How a 3-D stereo + IMU estimator consumes a drive, one step at a time.

Every estimator of seed 003's drives (``ekf.stereo_imu_ekf.EkfS003``, ``ekf.vio.VioEkf``,
``fgslam.smoother3d``) implements::

    step(dt_s, twist, ids, pixels)   # predict with the previous step's twist over dt_s
                                     # (None at the first step), then use the stereo
                                     # pixels (n, 4) of landmarks ``ids`` (n,) seen now
    current_pose() -> (4, 4)         # world_T_imu right after the last step
    trajectory()   -> (T, 4, 4)      # its estimate of every step so far (filter: online)
    landmarks()    -> {id: (3,)}     # world points

The world frame is the IMU frame at the first step (pose 0 = identity), as in the seed.

A run log's typed steps become these inputs through :func:`step_inputs` (what ``fgslam run``,
``check`` and ``bench`` feed); a drive's arrays (seed 003's npz, the 3-D simulator) through
:func:`steps_of`, and :func:`run_drive` feeds a whole drive. Nothing here prints or reads files.
"""

from __future__ import annotations

from typing import Iterable, Iterator, NamedTuple

import numpy as np

__all__ = ["StepInput", "position_errors_m", "run_drive", "step_inputs", "steps_of"]


class StepInput(NamedTuple):
    """The arguments of one ``step``: ``dt_s`` and ``twist`` are None at the first step."""

    dt_s: float | None
    twist: np.ndarray | None  # (6,) the IMU's (v, ω) over dt_s, translation first
    ids: np.ndarray  # (n,) int64, ascending
    pixels: np.ndarray  # (n, 4) u_L, v_L, u_R, v_R


def step_inputs(steps: Iterable) -> Iterator[StepInput]:
    """One :class:`StepInput` per step of a 3-D run log (``slamio.log.Step`` whose odometry
    is a ``VelocityOdometry`` and whose observations are ``StereoObservation``).

    The observations of a step are fed in ascending track id; a track seen twice in one
    step keeps its last reading.
    """
    for step in steps:
        seen = {o.track_id: o for o in step.observations}
        ids = np.array(sorted(seen), dtype=np.int64)
        pixels = np.array([seen[j].pixels() for j in ids], dtype=float).reshape(len(ids), 4)
        odometry = step.odometry
        if odometry is None:
            yield StepInput(None, None, ids, pixels)
        else:
            twist = np.array([*odometry.v_mps, *odometry.w_radps], dtype=float)
            yield StepInput(float(odometry.dt_s), twist, ids, pixels)


def steps_of(drive):
    """Yield ``(dt_s, twist, ids, pixels)`` for every step of ``drive``."""
    for t in range(drive.n_steps):
        columns = drive.seen(t)
        ids, pixels = drive.ids(columns), drive.features_px[t, columns]
        if t == 0:
            yield None, None, ids, pixels
        else:
            yield drive.dt_s(t - 1), drive.twist(t - 1), ids, pixels


def run_drive(estimator, drive, n_steps: int | None = None):
    """Feed the first ``n_steps`` (all by default) steps of ``drive``; return the estimator."""
    for t, (dt, twist, ids, pixels) in enumerate(steps_of(drive)):
        if n_steps is not None and t >= n_steps:
            break
        estimator.step(dt, twist, ids, pixels)
    return estimator


def position_errors_m(estimate, truth) -> tuple[float, float]:
    """(3-D RMSE, top-view 2-D RMSE) of the positions of two (T, 4, 4) pose sequences.

    Both start at the same known first pose (the world frame is the IMU at step 0), so no
    alignment is done.
    """
    d = np.asarray(estimate)[:, :3, 3] - np.asarray(truth)[:, :3, 3]
    return float(np.sqrt(np.mean(np.sum(d**2, axis=1)))), float(np.sqrt(np.mean(np.sum(d[:, :2] ** 2, axis=1))))

