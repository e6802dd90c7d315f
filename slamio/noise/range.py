"""Fit the noise model of range-only readings (ranging radios) against ground truth.

``fgslam calibrate LOG...`` calls :func:`fit_range_only` when the logs' readings are ranges
without a bearing (Plaza). Each reading is compared with the distance from the true robot
position at its time to the landmark's true position, and

    measured = range_scale · distance + range_bias_m + error

is fitted (least squares, then again inside a 5σ gate, as for the camera:
:func:`slamio.noise.fitting.line_fit`). The scale and bias are pooled over the logs; the σ are
fitted to the scatter of each log about its own line, σ² regressed on ``[1, distance²]``
(``range_sigma_m``, ``range_sigma_per_m``); readings beyond the gate are the outlier rate;
the correlation in time of the normalised errors, per landmark and log, gives
``correlated_share`` and ``correlation_time_s`` (:func:`slamio.noise.fitting.fit_reading_correlation`).
The bearing fields keep their defaults (there is no bearing).

The report keeps what a reader needs to judge the model: the constant-offset fit
(median of ``measured − distance``) beside the scale fit, each landmark's own scale, and
the residuals' spread by distance.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Sequence

import numpy as np

from slamio.noise.fitting import (GATE_SIGMAS, TruthData, fit_reading_correlation, line_fit, mad_sigma, nnls_rates,
                                  residuals_about_own_lines, truth_at)
from slamio.noise.model import ObservationModel

__all__ = ["fit_range_only"]

#: Distance bins (m) of the report's residual table.
DISTANCE_BINS_M = (0.0, 10.0, 20.0, 30.0, 45.0, 90.0)


def _truth_ranges(data: TruthData) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(stamps, measured, true distance, landmark id)`` of a log's ranges with truth."""
    if not data.ranges:
        empty = np.zeros(0)
        return empty, empty, empty, np.zeros(0, dtype=int)
    t = np.array([o[0] for o in data.ranges])
    measured = np.array([o[1] for o in data.ranges])
    landmark = np.array([o[2] for o in data.ranges], dtype=int)
    landmark_xy = np.array([o[3] for o in data.ranges])
    poses, ok = truth_at(data, t)
    distance = np.hypot(landmark_xy[:, 0] - poses[:, 0], landmark_xy[:, 1] - poses[:, 1])
    return t[ok], measured[ok], distance[ok], landmark[ok]


def fit_range_only(datas: Sequence[TruthData]) -> tuple[ObservationModel, dict]:
    """The range-only :class:`ObservationModel` of the logs' readings and a report (module docstring)."""
    parts = [_truth_ranges(d) for d in datas]
    t, measured, distance = (np.concatenate([p[j] for p in parts]) for j in range(3))
    own = np.concatenate([np.full(len(p[0]), j) for j, p in enumerate(parts)])
    landmark = np.concatenate([p[3] for p in parts])
    series = np.unique(np.column_stack([own, landmark]), axis=0, return_inverse=True)[1].ravel()  # per landmark and log
    scale, bias, _ = line_fit(distance, measured)
    residual = residuals_about_own_lines(distance, measured, own, (scale, bias))  # module docstring
    inlier = np.abs(residual) <= GATE_SIGMAS * mad_sigma(residual)
    rates = nnls_rates(residual[inlier], np.column_stack([np.ones(inlier.sum()), distance[inlier] ** 2]))
    white = ObservationModel(
        range_scale=scale, range_bias_m=bias,
        range_sigma_m=max(float(np.sqrt(rates[0])), 1e-3), range_sigma_per_m=float(np.sqrt(rates[1])),
        outlier_rate=float(1.0 - inlier.mean()),
    )
    sigma = np.array([white.sigma_range_m(float(d)) for d in distance])  # the model's own σ, as estimators see it
    correlation = fit_reading_correlation(t[inlier], series[inlier], (residual / sigma)[inlier, None])
    model = replace(white, correlated_share=correlation.share, correlation_time_s=correlation.time_s)
    offset = measured - distance
    per_landmark = {}
    for lid in np.unique(landmark):
        m = landmark == lid
        per_landmark[str(int(lid))] = {
            "readings": int(m.sum()),
            "median_offset_m": round(float(np.median(offset[m])), 3),
            "own_scale": round(float(line_fit(distance[m], measured[m])[0]), 5),
        }
    by_distance = []
    for lo, hi in zip(DISTANCE_BINS_M[:-1], DISTANCE_BINS_M[1:]):
        m = (distance >= lo) & (distance < hi)
        if m.any():
            by_distance.append({"distance_m": [lo, hi], "readings": int(m.sum()),
                                "median_offset_m": round(float(np.median(offset[m])), 3),
                                "residual_mean_m": round(float(residual[m].mean()), 3),
                                "residual_std_m": round(float(residual[m].std()), 3)})
    report = {
        "observations": int(len(t)),
        "outliers": int((~inlier).sum()),
        "constant_offset_fit": {"median_offset_m": round(float(np.median(offset)), 3),
                                "robust_spread_m": round(mad_sigma(offset), 3)},
        "range_residual_mad_m": round(mad_sigma(residual), 4),
        "largest_residual_sigmas": round(float(np.max(np.abs(residual) / sigma)), 2) if len(t) else None,
        "per_landmark": per_landmark,
        "by_distance": by_distance,
        "reading_correlation": correlation.report(),
    }
    return model, report
