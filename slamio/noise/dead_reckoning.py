"""A log's odometry dead-reckoned into a chain of poses readable at any time.

Both fitting a noise model from truth (:mod:`slamio.noise.fit_truth`: the odometry lag and
scales, the turn rate at each reading) and applying one to a written log
(:mod:`slamio.noise.apply`: re-reading each increment ``lag_s`` earlier) read the odometry
between its stamps; this module is that reading, so applying does not depend on fitting.
Not the smoother's compound-factor :class:`fgslam.smoother.chain.OdometryChain`.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["DeadReckoning", "TURN_RATE_HALF_WINDOW_S", "odometry_arrays", "turn_rate_radps"]

#: Half width of the window over which the turn rate at a time is read, seconds.
TURN_RATE_HALF_WINDOW_S = 0.1


def odometry_arrays(steps) -> tuple[np.ndarray, np.ndarray]:
    """``(stamps (T,), increments (T − 1, 3))`` of a planar log's steps: each step's stamp and
    the ``(dx, dy, dθ)`` of its odometry record (step 0 has none)."""
    stamps = np.array([s.stamp_s for s in steps], dtype=float)
    increments = np.array([[s.odometry.dx_m, s.odometry.dy_m, s.odometry.dtheta_rad] for s in steps[1:]],
                          dtype=float).reshape(-1, 3)
    return stamps, increments


class DeadReckoning:
    """A log's odometry composed into poses at the step stamps, readable at any time.

    Between two stamps the robot is taken to move at constant velocity along the
    increment (a fraction ``f`` of the increment is ``f·(dx, dy, dθ)``, exact to first
    order for the short increments of a log).
    """

    def __init__(self, stamps_s: np.ndarray, increments: np.ndarray):
        self.stamps_s = np.asarray(stamps_s, float)
        self.increments = np.asarray(increments, float).reshape(-1, 3)  # increments[k]: stamp k -> k+1
        poses = np.zeros((len(self.stamps_s), 3))
        for k, (dx, dy, dth) in enumerate(self.increments):
            x, y, th = poses[k]
            c, s = math.cos(th), math.sin(th)
            poses[k + 1] = (x + c * dx - s * dy, y + s * dx + c * dy, th + dth)  # heading unwrapped
        self.poses = poses

    def pose_at(self, t_s: float) -> np.ndarray | None:
        """Chain pose (x, y, unwrapped θ) at ``t_s``; None outside the stamps."""
        st = self.stamps_s
        if not (st[0] <= t_s <= st[-1]):
            return None
        k = min(int(np.searchsorted(st, t_s, side="right")) - 1, len(st) - 2)
        span = st[k + 1] - st[k]
        f = (t_s - st[k]) / span if span > 0 else 0.0
        dx, dy, dth = f * self.increments[k]
        x, y, th = self.poses[k]
        c, s = math.cos(th), math.sin(th)
        return np.array([x + c * dx - s * dy, y + s * dx + c * dy, th + dth])

    def heading_at(self, t_s: np.ndarray) -> np.ndarray:
        """Unwrapped chain heading at each time (clamped to the run's span)."""
        st = self.stamps_s
        t = np.clip(np.asarray(t_s, float), st[0], st[-1])
        return np.interp(t, st, self.poses[:, 2])


def turn_rate_radps(chain: DeadReckoning, t_s: np.ndarray, half_window_s: float = TURN_RATE_HALF_WINDOW_S) -> np.ndarray:
    """|ω| of the odometry at each time: heading change over ±``half_window_s``, rad/s."""
    t = np.asarray(t_s, float)
    return np.abs(chain.heading_at(t + half_window_s) - chain.heading_at(t - half_window_s)) / (2 * half_window_s)
