"""Whole-graph solves: the batch Levenberg–Marquardt ("smoothed ground truth") and the
Gauss–Newton steps that end every smoother run (:meth:`.Isam2Smoother.finish`).

Both start from iSAM2's answer: batch LM started from odometry gets stuck in a local
minimum on real data; started from iSAM2 it converges (DESIGN.md).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

import gtsam
import numpy as np

from fgslam.smoother.variables import heights_of, landmarks_of, poses_of, yaws_of
from slamio.errors import FgslamError

if TYPE_CHECKING:
    from fgslam.smoother.isam2 import Isam2Smoother


@dataclass(frozen=True, eq=False)
class BatchResult:
    """The batch Levenberg–Marquardt solution of a smoother's whole graph.

    ``trajectory`` is (n, 3) (x_m, y_m, theta_rad); ``landmarks`` id → (x_m, y_m);
    ``landmark_heights`` id → m and ``landmark_yaws`` tag id → rad (None when there are none);
    ``initial_error``/``final_error`` are ``graph.error`` (χ²/2) at the start (iSAM2's
    estimate) and at the end; ``time_s`` is the wall time of the optimisation alone.
    """

    trajectory: np.ndarray
    landmarks: dict[int, tuple[float, float]]
    time_s: float
    initial_error: float
    final_error: float
    iterations: int
    landmark_heights: dict[int, float] | None = None
    landmark_yaws: dict[int, float] | None = None


@dataclass(frozen=True, eq=False)
class Polished:
    """What :func:`gauss_newton_steps` ended with: the values, the steps taken and kept,
    ``graph.error`` (χ²/2) there, and GTSAM's message if a step met a singular system."""

    values: gtsam.Values
    iterations: int
    error: float
    failure: str | None = None


def gauss_newton_steps(graph: gtsam.NonlinearFactorGraph, start: gtsam.Values, max_iterations: int,
                       tolerance: float) -> Polished:
    """Up to ``max_iterations`` Gauss–Newton steps on the whole ``graph`` from ``start``,
    until χ²/2 drops by at most ``tolerance`` relative to its new value.

    A step that raises the error (or makes it NaN) is undone and ends the steps; so does a
    singular system (``failure`` then holds GTSAM's message). Each step linearises every
    factor at the current values and solves the whole linear system (GTSAM's
    ``GaussNewtonOptimizer``, COLAMD ordering).

    Why a batch step and not iSAM2's own (an update with ``force_relinearize`` and
    ``forceFullSolve``, the same step): measured on the default ``isam2``'s graphs
    (one BLAS thread), iSAM2's full relinearisation took 21–59 ms a step on MRCLAM
    Dataset 6 robots 1, 3 and 5, 120–136 ms on Victoria Park and 250–255 ms on Plaza1, and
    each needed a full back-substitution (``calculateBestEstimate``, 2–36 ms) to test
    the error; the batch step took 10–31 ms, 46–57 ms and 81–107 ms, and has its values
    at hand. It rebuilds no Bayes tree, and the run is over, so iSAM2 need not hold the
    result (docs/performance.md).
    """
    optimizer = gtsam.GaussNewtonOptimizer(graph, start, gtsam.GaussNewtonParams())
    values, error, iterations = start, float(optimizer.error()), 0  # the error at start
    for _ in range(int(max_iterations)):
        try:
            optimizer.iterate()
        except RuntimeError as exc:  # gtsam.IndeterminantLinearSystemException: keep what we have
            return Polished(values, iterations, error, str(exc))
        new_error = float(optimizer.error())
        if not new_error <= error:  # worse, or NaN: Gauss–Newton overshot; keep the values before
            break
        decrease = error - new_error
        values, error = gtsam.Values(optimizer.values()), new_error
        iterations += 1
        if not decrease > tolerance * new_error:
            break
    return Polished(values, iterations, error)


def batch_solve(smoother: "Isam2Smoother", *, max_iterations: int = 100) -> BatchResult:
    """Levenberg–Marquardt on the smoother's whole graph, started from its current estimate.

    This is the "smoothed ground truth" when a run has no real ground truth. It stops when
    the error's relative decrease falls below 1e-10 (or its absolute decrease below 1e-12),
    or after ``max_iterations``.
    """
    if smoother.num_poses == 0:
        raise FgslamError("batch_solve: the smoother has no poses yet; feed it steps first")
    graph = smoother.graph()
    initial = smoother.estimate()
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(int(max_iterations))
    params.setRelativeErrorTol(1e-10)
    params.setAbsoluteErrorTol(1e-12)
    optimizer = gtsam.LevenbergMarquardtOptimizer(graph, initial, params)
    start = time.perf_counter()
    result = optimizer.optimize()
    elapsed = time.perf_counter() - start
    return BatchResult(
        trajectory=poses_of(result, smoother.num_poses),
        landmarks=landmarks_of(result, sorted(smoother.landmarks()), smoother._landmarks.tag_ids),
        landmark_heights=heights_of(result, smoother._landmarks.height_ids) or None,
        landmark_yaws=yaws_of(result, smoother._landmarks.tag_ids) or None,
        time_s=elapsed,
        initial_error=float(graph.error(initial)),
        final_error=float(graph.error(result)),
        iterations=int(optimizer.iterations()),
    )
