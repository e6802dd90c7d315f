"""The batch solve: Levenberg–Marquardt on the smoother's whole graph ("smoothed ground truth").

Started from iSAM2's answer: batch LM started from odometry gets stuck in a local minimum
on real data; started from iSAM2 it converges (DESIGN.md).
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
