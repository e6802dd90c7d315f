"""What the fits of a noise model against ground truth share.

:mod:`slamio.noise.fit_truth` (odometry and camera) and :mod:`slamio.noise.range` (ranging
radios) both read a log against its truth (:class:`TruthData`, :func:`truth_at`) and fit
with the same robust statistics: the median-absolute-deviation σ (:func:`mad_sigma`), the
5σ gate (:data:`GATE_SIGMAS`), a gated line fit (:func:`line_fit`) and each log's scatter
about its own line (:func:`residuals_about_own_lines`), non-negative variance rates
(:func:`nnls_rates`) and the correlation in time of a landmark's readings
(:func:`fit_reading_correlation`). Keeping them here, below both, is what keeps the two fits
from importing each other.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import curve_fit, nnls

from slamio.log import RunLog, group_steps
from slamio.log.mount import pose_on_robot
from slamio.noise.dead_reckoning import DeadReckoning, odometry_arrays
from slamio.noise.errors import NoiseModelError
from slamio.noise.model import carries_fitted_model

__all__ = [
    "GATE_SIGMAS",
    "ReadingCorrelation",
    "TruthData",
    "fit_reading_correlation",
    "line_fit",
    "mad_sigma",
    "nnls_rates",
    "residuals_about_own_lines",
    "truth_at",
    "truth_data",
]

# --------------------------------------------------------------------------- robust statistics

#: Residuals beyond this many robust σ are outliers.
GATE_SIGMAS = 5.0


def mad_sigma(x: np.ndarray) -> float:
    """Robust σ: 1.4826 × median absolute deviation from the median."""
    return float(1.4826 * np.median(np.abs(x - np.median(x)))) if len(x) else math.nan


def nnls_rates(residual: np.ndarray, regressors: np.ndarray) -> np.ndarray:
    """Non-negative variance rates: residual² ≈ regressors @ rates, after a 5σ gate."""
    y = residual**2
    keep = np.abs(residual - np.median(residual)) <= GATE_SIGMAS * max(mad_sigma(residual), 1e-9)
    scale = np.maximum(regressors[keep].max(axis=0), 1e-12)  # conditioning
    rates, _ = nnls(regressors[keep] / scale, y[keep])
    return rates / scale


def line_fit(x: np.ndarray, y: np.ndarray) -> tuple[float, float, np.ndarray]:
    """Robust y ≈ scale·x + bias: least squares, then again inside the 5σ gate."""
    keep = np.ones(len(x), bool)
    for _ in range(3):
        A = np.column_stack([x[keep], np.ones(keep.sum())])
        (scale, bias), *_ = np.linalg.lstsq(A, y[keep], rcond=None)
        res = y - (scale * x + bias)
        keep = np.abs(res) <= GATE_SIGMAS * max(mad_sigma(res), 1e-9)
    return float(scale), float(bias), res


def residuals_about_own_lines(x: np.ndarray, y: np.ndarray, own: np.ndarray, pooled: tuple[float, float]) -> np.ndarray:
    """Each log's residuals about its own :func:`line_fit` (``own``: the log of each
    reading); a log with fewer than 10 readings about the ``pooled`` (scale, bias) line.
    A run's own scale and bias error is common to all its readings, so it moves that run's
    map, not its innovations: σ are fitted to this scatter."""
    residual = np.empty(len(x))
    for j in np.unique(own):
        m = own == j
        residual[m] = line_fit(x[m], y[m])[2] if m.sum() >= 10 else y[m] - (pooled[0] * x[m] + pooled[1])
    return residual


# --------------------------------------------------------------------------- a log against its truth


@dataclass
class TruthData:
    """One log's odometry, readings and truth, as the fits read them (:func:`truth_data`)."""

    name: str
    chain: DeadReckoning
    truth_stamps_s: np.ndarray  # stamps of poses with truth
    truth_poses: np.ndarray  # (n, 3), heading unwrapped (NaN: the truth has no heading)
    observations: list[tuple[float, float, float, tuple[float, float]]]  # (stamp, range, bearing, landmark xy)
    ranges: list[tuple[float, float, int, tuple[float, float]]] = field(default_factory=list)  # range-only: (stamp, range, id, landmark xy)
    #: the header's ``sensor.pose_on_robot`` (x, y, yaw): the readings are the sensor's own,
    #: and the truth they are fitted against is seen from there (None: the robot's centre)
    mount: tuple[float, float, float] | None = None


def truth_data(log: RunLog) -> TruthData:
    """``log``'s :class:`TruthData`; :class:`NoiseModelError` when it carries a fitted model
    already or has fewer than 10 poses with truth."""
    steps = group_steps(log.header, log.records, at_robot_centre=False)  # the readings as the sensor took them
    if carries_fitted_model(log.header.noise):
        raise NoiseModelError(
            f"{log.path}: this log was imported with a fitted noise model already; calibrate on "
            "logs imported without --noise (the fit is relative to the raw odometry and readings)"
        )
    stamps, increments = odometry_arrays(steps)
    truth = [(s.stamp_s, s.truth.x_m, s.truth.y_m, math.nan if s.truth.theta_rad is None else s.truth.theta_rad)
             for s in steps if s.truth is not None]
    if len(truth) < 10 or len(steps) < 10:
        raise NoiseModelError(
            f"{log.path}: {len(truth)} poses with ground truth; the fit needs a log with truth "
            "poses (motion capture or simulation) over a run of at least 10 poses"
        )
    tr = np.array(truth)
    if np.all(np.isfinite(tr[:, 3])):  # GPS truth has no heading: NaN, and no odometry fit (fit_noise_model)
        tr[:, 3] = np.unwrap(tr[:, 3])
    landmarks = {i: (t.x_m, t.y_m) for i, t in log.truth_landmarks().items()}
    observations = [
        (s.stamp_s, o.range_m, o.bearing_rad, landmarks[o.landmark_id])
        for s in steps
        for o in s.observations
        if o.bearing_rad is not None and o.landmark_id in landmarks
    ]
    ranges = [
        (s.stamp_s, o.range_m, o.landmark_id, landmarks[o.landmark_id])
        for s in steps
        for o in s.observations
        if o.range_only and o.landmark_id in landmarks
    ]
    return TruthData(log.path, DeadReckoning(stamps, increments), tr[:, 0], tr[:, 1:], observations, ranges,
                     pose_on_robot(log.header.sensor))


def truth_at(data: TruthData, t_s: np.ndarray, max_gap_s: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """Truth poses interpolated at ``t_s`` and a mask of those bracketed within ``max_gap_s``."""
    st = data.truth_stamps_s
    t = np.asarray(t_s, float)
    i = np.clip(np.searchsorted(st, t, side="right"), 1, len(st) - 1)
    ok = (t >= st[0]) & (t <= st[-1]) & (st[i] - st[i - 1] <= max_gap_s)
    poses = np.column_stack([np.interp(t, st, data.truth_poses[:, j]) for j in range(3)])
    return poses, ok


# --------------------------------------------------------------------------- readings' error in time


@dataclass(frozen=True)
class ReadingCorrelation:
    """ρ·exp(−Δt/τ) fitted to the correlation of two readings of one landmark Δt apart."""

    share: float  # ρ, 0 when the readings look white (or there are too few pairs)
    time_s: float  # τ
    lags_s: tuple[float, ...] = ()  # mean Δt of each bin
    correlations: tuple[float, ...] = ()  # measured correlation of each bin
    pairs: tuple[int, ...] = ()

    def report(self) -> dict:
        return {
            "share": round(self.share, 4), "time_s": round(self.time_s, 3),
            "lag_s": [round(v, 3) for v in self.lags_s], "correlation": [round(v, 4) for v in self.correlations],
            "pairs": list(self.pairs),
        }


#: Edges (s) of the Δt bins over which reading-error correlations are measured.
CORRELATION_BINS_S = (0.0, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0)
#: Readings whose errors correlate less than this over the shortest lag measured are white.
WHITE_CORRELATION = 0.05
#: Pairs per reading: each reading is paired with at most this many later readings of its landmark.
MAX_PAIRS_PER_READING = 80


def fit_reading_correlation(stamps_s: np.ndarray, landmark: np.ndarray, normalised: np.ndarray) -> ReadingCorrelation:
    """Fit the Gauss–Markov part of the reading errors.

    ``normalised`` (n, k) are residuals divided by their σ (range and bearing: k = 2), each
    run's own bias already removed; ``landmark`` (n,) says which series a reading belongs
    to (one per landmark and run), ``stamps_s`` when it was taken. For every pair of
    readings of one series less than 64 s apart, the product of their residuals is binned
    by Δt; each bin's correlation (averaged over the k components) is fitted by
    ``ρ·exp(−Δt/τ)`` (least squares on the bins, weighted by their pair counts; τ at least
    the first bin's mean Δt). A correlation at most 0.05 over the first bin, or fewer than
    100 pairs there, means white readings (ρ = 0).
    """
    edges = np.asarray(CORRELATION_BINS_S)
    sums = np.zeros((len(edges) - 1, normalised.shape[1]))
    square_a = np.zeros_like(sums)
    square_b = np.zeros_like(sums)
    lag_sum = np.zeros(len(edges) - 1)
    count = np.zeros(len(edges) - 1, dtype=int)
    order = np.lexsort((stamps_s, landmark))
    t, series, z = stamps_s[order], landmark[order], normalised[order]
    for shift in range(1, MAX_PAIRS_PER_READING + 1):
        if shift >= len(t):
            break
        same = series[shift:] == series[:-shift]
        dt = t[shift:] - t[:-shift]
        ok = same & (dt < edges[-1])
        if not ok.any():
            break
        bins = np.searchsorted(edges, dt[ok], side="right") - 1
        a, b = z[:-shift][ok], z[shift:][ok]
        np.add.at(sums, bins, a * b)
        np.add.at(square_a, bins, a * a)
        np.add.at(square_b, bins, b * b)
        np.add.at(lag_sum, bins, dt[ok])
        np.add.at(count, bins, 1)
    used = count > 0
    lags = lag_sum[used] / count[used]
    corr = (sums[used] / np.sqrt(np.maximum(square_a[used] * square_b[used], 1e-300))).mean(axis=1)
    white = ReadingCorrelation(0.0, 0.0, tuple(lags), tuple(corr), tuple(int(c) for c in count[used]))
    if used.sum() < 3 or count[0] < 100 or corr[0] <= WHITE_CORRELATION:
        return white
    try:  # τ no shorter than the first bin's lag: nothing shorter is measured
        (rho, tau), _ = curve_fit(lambda x, r, s: r * np.exp(-x / s), lags, corr, p0=(corr[0], 10.0),
                                  sigma=1.0 / np.sqrt(count[used]), bounds=([0.0, lags[0]], [0.95, 1e4]))
    except (RuntimeError, ValueError):
        return white
    if rho * math.exp(-lags[0] / tau) <= WHITE_CORRELATION:
        return white
    return ReadingCorrelation(float(rho), float(tau), tuple(lags), tuple(corr), tuple(int(c) for c in count[used]))
