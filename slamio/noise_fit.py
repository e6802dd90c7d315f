"""Fit a :class:`~slamio.noise_model.NoiseModel` from run logs that have ground truth.

``fgslam calibrate LOG... --out noise.json`` calls :func:`fit_noise_model`. Any log with
truth poses (motion capture, a simulator) and, for the observation model, truth
landmarks will do; several logs are pooled into one model, so a model fitted on some runs
can be scored on others (never on the runs it was fitted on).

What is fitted, and how (every step is least squares on residuals against the truth):

1. **Odometry lag and scale.** The log's odometry is composed into a dead-reckoned chain
   whose pose can be read at any time (within one increment at constant velocity). Over
   windows of about ``window_s`` between two poses with truth, the true motion is compared
   with the chain's motion over the same window shifted ``lag_s`` earlier. For each lag on
   a grid, the forward and turn scales are closed-form least squares
   (``Δx_true ≈ forward_scale·Δx_odo``, ``Δθ_true ≈ turn_scale·Δθ_odo +
   turn_per_m_rad·forward_scale·Δx_odo``); the lag with the
   smallest normalised residual wins.
2. **Odometry variance rates.** With that lag and those scales, each window's residual
   (forward, sideways, heading, in the window's start frame) is squared and regressed on
   the window's distance, turn and duration with non-negative least squares: the
   ``OdometryNoiseRates`` that make the window residuals' variance right.
3. **Observation model.** Each observation of a landmark with truth is compared with the
   range and bearing computed from the truth pose at the picture's time. Per camera latency
   on a grid, the bearing's scale and bias are fitted; the latency with the smallest robust
   bearing spread wins. The range is fitted both as Euclidean range and as depth
   (``r·cos b``) with a scale and a bias; the one with the smaller robust spread wins.
   The scales and biases are pooled over the logs; the σ are fitted to the scatter of each
   log about its *own* scale and bias (a run's own calibration error is common to all its
   readings: it moves that run's map rather than its innovations, which is what the
   filter's σ must describe). σ² of range is regressed on ``[1, r²]`` and σ² of bearing on
   ``[1, ω²]`` (ω, the odometry's turn rate at the picture), after a 5σ gate that counts
   the outliers.
4. **Readings' error in time.** Two readings of one landmark taken close together err
   alike. The residuals divided by their σ are paired per landmark and run, binned by the
   time between them, and ``ρ·exp(−Δt/τ)`` is fitted to the bins' correlations
   (:func:`fit_reading_correlation`): the model's ``correlated_share`` ρ and
   ``correlation_time_s`` τ.

Robust statistics (median absolute deviation, 5σ gate) keep misread barcodes and motion
capture glitches out of the fit; their share is the model's ``outlier_rate``.

A truth that measures position only (GPS: ``truth_pose`` without ``theta_rad``) can fit a
range-only model (ranging radios, :mod:`slamio.range_fit`) but not the odometry, whose turns
need the true heading: the model then carries the default odometry part, and its
``fit_report["odometry"]`` says it was not fitted. Bearings against such a truth are refused.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Sequence

import numpy as np
from scipy.optimize import curve_fit, nnls

from slamio.errors import FgslamError
from slamio.geometry import wrap_angle
from slamio.log import RunLog
from slamio.noise_model import NoiseModel, ObservationModel, OdometryModel, OdometryNoiseRates, carries_fitted_model

__all__ = ["CalibrationError", "OdometryChain", "ReadingCorrelation", "fit_noise_model", "fit_reading_correlation", "turn_rate_radps"]

#: Floor of the per-second variance rates (they must be > 0): 1 mm, 1 mrad per √s.
MIN_RATE_PER_S = 1e-6
#: Residuals beyond this many robust σ are outliers.
GATE_SIGMAS = 5.0
#: Half width of the window over which the turn rate at a time is read, seconds.
TURN_RATE_HALF_WINDOW_S = 0.1
#: Length of the windows over which the odometry lag is fitted, seconds.
LAG_WINDOW_S = 0.5


class CalibrationError(FgslamError):
    """The logs cannot support a fit (no truth, too little motion, ...)."""


def _mad_sigma(x: np.ndarray) -> float:
    """Robust σ: 1.4826 × median absolute deviation from the median."""
    return float(1.4826 * np.median(np.abs(x - np.median(x)))) if len(x) else math.nan


# --------------------------------------------------------------------------- the odometry chain


class OdometryChain:
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


def turn_rate_radps(chain: OdometryChain, t_s: np.ndarray, half_window_s: float = TURN_RATE_HALF_WINDOW_S) -> np.ndarray:
    """|ω| of the odometry at each time: heading change over ±``half_window_s``, rad/s."""
    t = np.asarray(t_s, float)
    return np.abs(chain.heading_at(t + half_window_s) - chain.heading_at(t - half_window_s)) / (2 * half_window_s)


def _between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """b expressed in a's frame (x, y, θ), θ unwrapped difference."""
    c, s = math.cos(a[2]), math.sin(a[2])
    dx, dy = b[0] - a[0], b[1] - a[1]
    return np.array([c * dx + s * dy, -s * dx + c * dy, b[2] - a[2]])


# --------------------------------------------------------------------------- per-log data


@dataclass
class _LogData:
    name: str
    chain: OdometryChain
    truth_stamps_s: np.ndarray  # stamps of poses with truth
    truth_poses: np.ndarray  # (n, 3), heading unwrapped (NaN: the truth has no heading)
    observations: list[tuple[float, float, float, tuple[float, float]]]  # (stamp, range, bearing, landmark xy)
    ranges: list[tuple[float, float, int, tuple[float, float]]] = field(default_factory=list)  # range-only: (stamp, range, id, landmark xy)


def _log_data(log: RunLog) -> _LogData:
    steps = log.steps()
    if carries_fitted_model(log.header.noise):
        raise CalibrationError(
            f"{log.path}: this log was imported with a fitted noise model already; calibrate on "
            "logs imported without --noise (the fit is relative to the raw odometry and readings)"
        )
    stamps = np.array([s.stamp_s for s in steps])
    increments = np.array([[s.odometry.dx_m, s.odometry.dy_m, s.odometry.dtheta_rad] for s in steps[1:]])  # type: ignore[union-attr]
    truth = [(s.stamp_s, s.truth.x_m, s.truth.y_m, math.nan if s.truth.theta_rad is None else s.truth.theta_rad)
             for s in steps if s.truth is not None]
    if len(truth) < 10 or len(steps) < 10:
        raise CalibrationError(
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
    return _LogData(log.path, OdometryChain(stamps, increments), tr[:, 0], tr[:, 1:], observations, ranges)


def _truth_at(data: _LogData, t_s: np.ndarray, max_gap_s: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """Truth poses interpolated at ``t_s`` and a mask of those bracketed within ``max_gap_s``."""
    st = data.truth_stamps_s
    t = np.asarray(t_s, float)
    i = np.clip(np.searchsorted(st, t, side="right"), 1, len(st) - 1)
    ok = (t >= st[0]) & (t <= st[-1]) & (st[i] - st[i - 1] <= max_gap_s)
    poses = np.column_stack([np.interp(t, st, data.truth_poses[:, j]) for j in range(3)])
    return poses, ok


# --------------------------------------------------------------------------- odometry fit


def _windows(data: _LogData, window_s: float) -> list[tuple[float, float, np.ndarray]]:
    """Non-overlapping (t_start, t_end, true increment) between truth poses ~window_s apart."""
    st, poses = data.truth_stamps_s, data.truth_poses
    out = []
    i = 0
    while i < len(st) - 1:
        j = int(np.searchsorted(st, st[i] + window_s - 1e-9, side="left"))
        if j >= len(st):
            break
        if st[j] - st[i] <= 2.0 * window_s:
            out.append((float(st[i]), float(st[j]), _between(poses[i], poses[j])))
        i = j
    return out


def _odometry_increments(data: _LogData, windows, lag_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(odometry increments, true increments, durations) of the windows the chain covers."""
    odo, true, dts = [], [], []
    for t0, t1, d_true in windows:
        a, b = data.chain.pose_at(t0 - lag_s), data.chain.pose_at(t1 - lag_s)
        if a is None or b is None:
            continue
        odo.append(_between(a, b))
        true.append(d_true)
        dts.append(t1 - t0)
    return np.array(odo).reshape(-1, 3), np.array(true).reshape(-1, 3), np.array(dts)


def _scales(odo: np.ndarray, true: np.ndarray) -> tuple[float, float, float]:
    """Least squares ``Δx_true ≈ fx·Δx_odo`` and ``Δθ_true ≈ ft·Δθ_odo + c·fx·Δx_odo``.

    ``c`` (rad per metre) is the turn the robot makes per metre when told to go straight:
    wheels of slightly different diameter.
    """
    fx = float(odo[:, 0] @ true[:, 0]) / max(float(odo[:, 0] @ odo[:, 0]), 1e-12)
    A = np.column_stack([odo[:, 2], fx * odo[:, 0]])
    (ft, c), *_ = np.linalg.lstsq(A, true[:, 2], rcond=None)
    return fx, float(ft), float(c)


def _residuals(odo: np.ndarray, true: np.ndarray, fx: float, ft: float, c: float) -> np.ndarray:
    return np.column_stack([
        true[:, 0] - fx * odo[:, 0],
        true[:, 1] - fx * odo[:, 1],
        true[:, 2] - ft * odo[:, 2] - c * fx * odo[:, 0],
    ])


def _nnls_rates(residual: np.ndarray, regressors: np.ndarray) -> np.ndarray:
    """Non-negative variance rates: residual² ≈ regressors @ rates, after a 5σ gate."""
    y = residual**2
    keep = np.abs(residual - np.median(residual)) <= GATE_SIGMAS * max(_mad_sigma(residual), 1e-9)
    scale = np.maximum(regressors[keep].max(axis=0), 1e-12)  # conditioning
    rates, _ = nnls(regressors[keep] / scale, y[keep])
    return rates / scale


def _fit_lag(datas: Sequence[_LogData], lag_grid_s: np.ndarray, window_s: float) -> float:
    """The lag whose shifted odometry turns most like the truth (least squares on Δθ).

    The turn is the strong signal (the robots spin); short windows resolve the lag.
    """
    windows = [_windows(d, window_s) for d in datas]
    best = None
    for lag in lag_grid_s:
        parts = [_odometry_increments(d, w, float(lag)) for d, w in zip(datas, windows)]
        odo, true = np.vstack([p[0] for p in parts]), np.vstack([p[1] for p in parts])
        if len(odo) < 20:
            continue
        fx, ft, c = _scales(odo, true)
        cost = float(np.mean(_residuals(odo, true, fx, ft, c)[:, 2] ** 2))
        if best is None or cost < best[0]:
            best = (cost, float(lag))
    if best is None:
        raise CalibrationError("too few windows of motion with truth at both ends to fit the odometry")
    return best[1]


def _fit_odometry(datas: Sequence[_LogData], window_s: float, lag_grid_s: np.ndarray) -> tuple[OdometryModel, dict]:
    lag = _fit_lag(datas, lag_grid_s, LAG_WINDOW_S)
    windows = [_windows(d, window_s) for d in datas]
    parts = [_odometry_increments(d, w, lag) for d, w in zip(datas, windows)]
    odo, true = np.vstack([p[0] for p in parts]), np.vstack([p[1] for p in parts])
    if len(odo) < 20:
        raise CalibrationError("too few windows of motion with truth at both ends to fit the odometry")
    fx, ft, c = _scales(odo, true)
    dts = np.concatenate([p[2] for p in parts])
    res = _residuals(odo, true, fx, ft, c)
    dist = np.abs(fx * odo[:, 0])
    turn = np.abs(ft * odo[:, 2])
    f_rates = _nnls_rates(res[:, 0], np.column_stack([dist, dts]))
    l_rates = _nnls_rates(res[:, 1], np.column_stack([dist, dts]))
    h_rates = _nnls_rates(res[:, 2], np.column_stack([turn, dist, dts]))
    noise = OdometryNoiseRates(
        forward_m2_per_m=float(f_rates[0]),
        forward_m2_per_s=max(float(f_rates[1]), MIN_RATE_PER_S),
        lateral_m2_per_m=float(l_rates[0]),
        lateral_m2_per_s=max(float(l_rates[1]), MIN_RATE_PER_S),
        heading_rad2_per_rad=float(h_rates[0]),
        heading_rad2_per_m=float(h_rates[1]),
        heading_rad2_per_s=max(float(h_rates[2]), MIN_RATE_PER_S),
    )
    report = {"windows": int(len(odo)), "window_s": window_s,
              "residual_mad": [round(_mad_sigma(res[:, j]), 6) for j in range(3)]}
    model = OdometryModel(lag_s=lag, forward_scale=fx, turn_scale=ft, turn_per_m_rad=c, noise=noise)
    return model, report


# --------------------------------------------------------------------------- observation fit


def _true_range_bearing(data: _LogData, latency_s: float) -> tuple[np.ndarray, ...]:
    """(measured range, measured bearing, true range, true bearing, picture times, landmark
    positions (n, 2)) of the readings with truth."""
    if not data.observations:
        empty = np.zeros(0)
        return empty, empty, empty, empty, empty, np.zeros((0, 2))
    obs = data.observations
    t = np.array([o[0] for o in obs]) - latency_s
    poses, ok = _truth_at(data, t)
    lm = np.array([o[3] for o in obs])
    dx, dy = lm[:, 0] - poses[:, 0], lm[:, 1] - poses[:, 1]
    r = np.hypot(dx, dy)
    b = wrap_angle(np.arctan2(dy, dx) - poses[:, 2])
    rm = np.array([o[1] for o in obs])
    bm = np.array([o[2] for o in obs])
    return rm[ok], bm[ok], r[ok], b[ok], t[ok], lm[ok]


def _line_fit(x: np.ndarray, y: np.ndarray) -> tuple[float, float, np.ndarray]:
    """Robust y ≈ scale·x + bias: least squares, then again inside the 5σ gate."""
    keep = np.ones(len(x), bool)
    for _ in range(3):
        A = np.column_stack([x[keep], np.ones(keep.sum())])
        (scale, bias), *_ = np.linalg.lstsq(A, y[keep], rcond=None)
        res = y - (scale * x + bias)
        keep = np.abs(res) <= GATE_SIGMAS * max(_mad_sigma(res), 1e-9)
    return float(scale), float(bias), res


def _residuals_about_own_lines(x: np.ndarray, y: np.ndarray, own: np.ndarray, pooled: tuple[float, float]) -> np.ndarray:
    """Each log's residuals about its own :func:`_line_fit` (``own``: the log of each
    reading); a log with fewer than 10 readings about the ``pooled`` (scale, bias) line.
    A run's own scale and bias error is common to all its readings, so it moves that run's
    map, not its innovations: σ are fitted to this scatter."""
    residual = np.empty(len(x))
    for j in np.unique(own):
        m = own == j
        residual[m] = _line_fit(x[m], y[m])[2] if m.sum() >= 10 else y[m] - (pooled[0] * x[m] + pooled[1])
    return residual


def _fit_observations(datas: Sequence[_LogData], odometry: OdometryModel, latency_grid_s: np.ndarray) -> tuple[ObservationModel, dict]:
    best = None
    for latency in latency_grid_s:
        parts = [_true_range_bearing(d, float(latency)) for d in datas]
        bm = np.concatenate([p[1] for p in parts])
        b = np.concatenate([p[3] for p in parts])
        if len(b) < 20:
            raise CalibrationError(
                "fewer than 20 observations of landmarks with truth; the observation fit needs "
                "truth_landmark records and observations with landmark ids"
            )
        _, _, res = _line_fit(b, wrap_angle(bm))
        spread = _mad_sigma(res)
        if best is None or spread < best[0]:
            best = (spread, float(latency))
    latency = best[1]
    parts = [_true_range_bearing(d, latency) for d in datas]
    rm, bm, r, b, t = (np.concatenate([p[j] for p in parts]) for j in range(5))
    landmark = np.unique(np.vstack([p[5] for p in parts]), axis=0, return_inverse=True)[1].ravel()
    omega = np.concatenate([
        odometry.turn_scale * turn_rate_radps(d.chain, p[4] - odometry.lag_s) for d, p in zip(datas, parts)  # |ω|
    ])
    bearing_scale, bearing_bias, _ = _line_fit(b, bm)
    fits = {}
    for name, along in (("range", r), ("depth", r * np.cos(b))):
        scale, bias, res = _line_fit(along, rm)
        fits[name] = (_mad_sigma(res), scale, bias)
    is_depth = fits["depth"][0] < fits["range"][0]
    _, range_scale, range_bias = fits["depth" if is_depth else "range"]
    # σ from the scatter about each log's own line (:func:`_residuals_about_own_lines`)
    own = np.concatenate([np.full(len(p[0]), j) for j, p in enumerate(parts)])
    res_r = _residuals_about_own_lines(r * np.cos(b) if is_depth else r, rm, own, (range_scale, range_bias))
    res_b = _residuals_about_own_lines(b, bm, own, (bearing_scale, bearing_bias))
    gate_r = GATE_SIGMAS * _mad_sigma(res_r)
    gate_b = GATE_SIGMAS * _mad_sigma(res_b)
    inlier = (np.abs(res_r) <= gate_r) & (np.abs(res_b) <= gate_b)
    r_rates = _nnls_rates(res_r[inlier], np.column_stack([np.ones(inlier.sum()), r[inlier] ** 2]))
    b_rates = _nnls_rates(res_b[inlier], np.column_stack([np.ones(inlier.sum()), omega[inlier] ** 2]))
    white = ObservationModel(
        range_is_depth=bool(is_depth),
        range_scale=range_scale,
        range_bias_m=range_bias,
        range_sigma_m=max(math.sqrt(r_rates[0]), 1e-3),
        range_sigma_per_m=math.sqrt(r_rates[1]),
        bearing_scale=bearing_scale,
        bearing_bias_rad=bearing_bias,
        bearing_sigma_rad=max(math.sqrt(b_rates[0]), 1e-4),
        bearing_sigma_s=math.sqrt(b_rates[1]),
        camera_latency_s=latency,
        outlier_rate=float(1.0 - inlier.mean()),
    )
    # normalised by the model's own σ (with its floors), as the estimators will see them
    sigma_r = np.array([white.sigma_range_m(float(v)) for v in r])
    sigma_b = np.array([white.sigma_bearing_rad(float(w)) for w in omega])
    normalised = np.column_stack([res_r / sigma_r, res_b / sigma_b])
    correlation = fit_reading_correlation(t[inlier], (own * (landmark.max() + 1) + landmark)[inlier], normalised[inlier])
    model = replace(white, correlated_share=correlation.share, correlation_time_s=correlation.time_s)
    report = {
        "observations": int(len(r)),
        "outliers": int((~inlier).sum()),
        "range_residual_mad_m": {"range": round(fits["range"][0], 6), "depth": round(fits["depth"][0], 6)},
        "bearing_residual_mad_rad": round(_mad_sigma(res_b), 6),
        "reading_correlation": correlation.report(),
    }
    return model, report


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


# --------------------------------------------------------------------------- entry point


def fit_noise_model(
    logs: Sequence[RunLog],
    *,
    window_s: float = 1.0,
    lag_grid_s: np.ndarray | None = None,
    latency_grid_s: np.ndarray | None = None,
) -> NoiseModel:
    """Fit one :class:`NoiseModel` to all ``logs`` pooled (see the module docstring).

    ``window_s`` is the length of the odometry windows (the variance rates are right at
    that scale); ``lag_grid_s`` (default −0.1…0.6 s by 10 ms) and ``latency_grid_s``
    (default 0…0.1 s by 10 ms) are the candidate odometry lags and camera latencies.
    Raises :class:`CalibrationError` when the logs have no truth or too little data.
    """
    if not logs:
        raise CalibrationError("no logs to fit; give one or more logs with ground truth")
    lag_grid = np.round(np.arange(-0.1, 0.6001, 0.01), 3) if lag_grid_s is None else np.asarray(lag_grid_s, float)
    latency_grid = np.round(np.arange(0.0, 0.1001, 0.01), 3) if latency_grid_s is None else np.asarray(latency_grid_s, float)
    datas = [_log_data(log) for log in logs]
    headless = [d.name for d in datas if not np.all(np.isfinite(d.truth_poses[:, 2]))]
    if headless and any(d.observations for d in datas):
        raise CalibrationError(f"{headless[0]}: its truth has no heading (GPS), which the camera's bearings and the "
                               "odometry's turns are fitted against; calibrate on logs whose truth has a heading")
    if headless:  # ranging radios against GPS: the range model only
        odometry, odo_report = OdometryModel(), {"not_fitted": "the truth has no heading: the defaults, not a fit"}
    else:
        odometry, odo_report = _fit_odometry(datas, window_s, lag_grid)
    if any(d.observations for d in datas):
        observation, obs_report = _fit_observations(datas, odometry, latency_grid)
    elif any(d.ranges for d in datas):  # ranging radios: range-only readings (slamio.range_fit)
        from slamio.range_fit import fit_range_only

        observation, obs_report = fit_range_only(datas)
    else:
        raise CalibrationError(
            "no observation of a landmark with truth in these logs; the fit needs truth_landmark records"
        )
    return NoiseModel(
        odometry, observation, tuple(log.path for log in logs),
        {"odometry": odo_report, "observation": obs_report},
    )
