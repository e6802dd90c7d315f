"""Whole-graph solves: the batch Levenberg–Marquardt ("smoothed ground truth") and the
Gauss–Newton steps that end every smoother run (:meth:`.Isam2Smoother.finish`).

Both start from iSAM2's answer: batch LM started from odometry gets stuck in a local
minimum on real data; started from iSAM2 it converges (docs/datasets.md, Victoria Park).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Protocol

import gtsam
import numpy as np

from fgslam.smoother.variables import LandmarkRegistry, heights_of, landmarks_of, poses_of, yaws_of
from slamio.errors import FgslamError


class WholeGraphSmoother(Protocol):
    """What :func:`batch_solve` reads of a smoother (:class:`~fgslam.smoother.isam2.Isam2Smoother`;
    named here, not imported, so this module does not import the smoother that imports it)."""

    num_poses: int
    _landmarks: LandmarkRegistry

    def graph(self) -> gtsam.NonlinearFactorGraph: ...

    def estimate(self) -> gtsam.Values: ...

    def landmarks(self) -> dict[int, tuple[float, float]]: ...


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
    #: every variable at the optimum (what :mod:`fgslam.verdict` evaluates the graph at)
    values: gtsam.Values | None = field(default=None, repr=False, compare=False)


@dataclass(frozen=True, eq=False)
class Polished:
    """What :func:`gauss_newton_steps` ended with: the values, the steps taken and kept,
    ``graph.error`` (χ²/2) there, GTSAM's message if a step met a singular system, and the
    graph's COLAMD ordering the steps eliminated in (for the marginals at the values after)."""

    values: gtsam.Values
    iterations: int
    error: float
    failure: str | None = None
    ordering: gtsam.Ordering | None = field(default=None, repr=False, compare=False)


def extrapolated_step_scale(step, previous_step, min_ratio: float = 0.2, max_ratio: float = 0.95) -> float:
    """Aitken's Δ² extrapolation for an iteration that converges linearly: the factor β by
    which to carry on along ``step`` (a ``gtsam.VectorValues``, the last Gauss–Newton step).

    When each step is about ρ times the previous one in the same direction, the steps still
    to come sum to ρ/(1 − ρ) times the last; ρ is the last step projected on the previous one,
    ⟨s, s₋₁⟩ / ⟨s₋₁, s₋₁⟩. Returns 0 (do not extrapolate) unless ``min_ratio`` ≤ ρ <
    ``max_ratio``: below, the iteration converges faster than linearly (Gauss–Newton without
    a robust kernel: ρ falls toward 0) and the steps left sum to under a quarter of the last,
    not worth an extra error evaluation (on Victoria Park ρ was 0.03–0.07 and the
    extrapolation saved no step); near 1 a noisy ρ would throw the estimate far.
    """
    norm = float(previous_step.squaredNorm())
    if step.size() != previous_step.size() or not norm > 0.0:  # two steps of one graph: the same variables
        return 0.0
    ratio = float(step.dot(previous_step)) / norm
    return ratio / (1.0 - ratio) if min_ratio <= ratio < max_ratio else 0.0


def gauss_newton_steps(graph: gtsam.NonlinearFactorGraph, start: gtsam.Values, max_iterations: int,
                       tolerance: float, *, extrapolate: bool = True) -> Polished:
    """Up to ``max_iterations`` Gauss–Newton steps on the whole ``graph`` from ``start``,
    until χ²/2 drops by at most ``tolerance`` relative to its new value.

    A step that raises the error (or makes it NaN) is undone and ends the steps; so does a
    singular system (``failure`` then holds GTSAM's message). Each step linearises every
    factor at the current values and solves the whole linear system (multifrontal Cholesky,
    as GTSAM's ``GaussNewtonOptimizer``; the COLAMD ordering computed once).

    With ``extrapolate`` (default), each step after the first is carried on by
    :func:`extrapolated_step_scale` when that lowers the error further. Why: with a robust
    kernel GTSAM linearises each factor with its current IRLS weight, so Gauss–Newton
    converges only linearly (LM and Dogleg move the same); measured on MRCLAM Dataset 6
    robot 2 (DCS), χ²/2 was 5.0e-4 above the optimum after 4 plain steps and 5.8e-6 with
    the extrapolation, and the run's final steps fell from 7 to 5 (docs/performance.md).
    Without a kernel Gauss–Newton converges quadratically, the ratio of its steps falls
    toward 0 and :func:`extrapolated_step_scale` declines.

    Why a batch step and not iSAM2's own (an update with ``force_relinearize`` and
    ``forceFullSolve``, the same step): measured on the default ``isam2``'s graphs
    (one BLAS thread), iSAM2's full relinearisation took 21–59 ms a step on MRCLAM
    Dataset 6 robots 1, 3 and 5, 120–136 ms on Victoria Park and 250–255 ms on Plaza1, and
    each needed a full back-substitution (``calculateBestEstimate``, 2–36 ms) to test
    the error; the batch step took 10–31 ms, 46–57 ms and 81–107 ms, and has its values
    at hand. It rebuilds no Bayes tree, and the run is over, so iSAM2 need not hold the
    result (docs/performance.md).
    """
    ordering = graph.orderingCOLAMD()  # the graph's structure does not change between steps
    values, error, iterations = start, float(graph.error(start)), 0  # the error at start
    previous_step = None
    for _ in range(int(max_iterations)):
        try:
            step = graph.linearize(values).optimize(ordering)
        except RuntimeError as exc:  # gtsam.IndeterminantLinearSystemException: keep what we have
            return Polished(values, iterations, error, str(exc), ordering)
        new_values = values.retract(step)
        new_error = float(graph.error(new_values))
        if not new_error <= error:  # worse, or NaN: Gauss–Newton overshot; keep the values before
            break
        if extrapolate and previous_step is not None:
            scale = extrapolated_step_scale(step, previous_step)
            if scale > 0.0:
                further = new_values.retract(step.scale(scale))  # tangent at values, applied at new_values
                further_error = float(graph.error(further))
                if further_error < new_error:
                    new_values, new_error = further, further_error
        previous_step = step
        decrease = error - new_error
        values, error = new_values, new_error
        iterations += 1
        if not decrease > tolerance * new_error:
            break
    return Polished(values, iterations, error, ordering=ordering)


def batch_solve(smoother: WholeGraphSmoother, *, max_iterations: int = 100) -> BatchResult:
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
        values=result,
    )
