"""The interface every estimator implements, so one runner can drive and time them all.

An estimator is pure: it is built from the log's header, consumes :class:`~slamio.log.Step`
objects in order, and answers questions about its estimate. It never prints, plots or
reads files. The runner (``fgslam.runner``) does the timing and the bookkeeping.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from slamio.log import Step


class Estimator(Protocol):
    """What ``fgslam.runner`` needs from an estimator (EKF, iSAM2, dead reckoning, ...)."""

    name: str

    def step(self, step: Step) -> None:
        """Consume one step: the odometry that created pose ``step.index`` (None for pose 0)
        and the observations made at that pose."""

    def current_pose(self) -> tuple[float, float, float]:
        """The estimate of the latest pose, as the robot would act on it now (online)."""

    def finish(self) -> None:
        """Work done once after the last step (for example extra smoother iterations)."""

    def trajectory(self) -> np.ndarray:
        """(n, 3) array of every pose so far as estimated now (final, after ``finish``)."""

    def landmarks(self) -> dict[int, tuple[float, float]]:
        """Landmark id → estimated (x_m, y_m) in the world frame."""
