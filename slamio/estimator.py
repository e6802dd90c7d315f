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
        """Landmark key → estimated (x_m, y_m) in the world frame."""


class AssociatingEstimator(Estimator, Protocol):
    """An estimator that can say which landmark it used each observation as.

    Optional: the runner scores data association with it (against
    ``Observation.truth_landmark_id``, or ``landmark_id`` when the log has ids) and maps the
    estimator's landmark keys to true ids for the map error.

    Landmark keys: an observation with a ``landmark_id`` that the estimator trusts is keyed
    by that id (≥ 0). A landmark the estimator created itself from observations without an
    id is keyed by a negative integer (−1, −2, … in order of creation), so its keys never
    collide with the log's ids.
    """

    def step_associations(self) -> list[int | None]:
        """For each observation of the last step, in order: the landmark key it was used
        as (a new landmark's key when it created one), or None when it was not used
        (rejected by a gate, or ignored)."""


class ConsistencyReporting(Estimator, Protocol):
    """Optional: an estimator that states its uncertainty, for the consistency checks.

    The runner calls these outside the timed region when the estimator has them; each
    method is optional on its own (``hasattr``).
    """

    def current_covariance(self) -> np.ndarray:
        """3×3 covariance of :meth:`current_pose` over world (x_m, y_m, theta_rad), for NEES."""

    def predicted_nis(self, step: Step) -> list[float | None]:
        """Called *before* ``step(step)``, changing nothing: for each observation of
        ``step``, its NIS ``νᵀ S⁻¹ ν`` over (range, bearing) against the prediction from the
        estimate so far moved by ``step.odometry`` (S includes the pose-landmark
        cross-covariance), or None when the landmark is not in the map yet."""

    def landmark_covariances(self) -> dict[int, np.ndarray]:
        """Landmark key → 2×2 covariance of its final (x_m, y_m), for the report's ellipses."""
