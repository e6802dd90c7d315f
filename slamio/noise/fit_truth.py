"""Fit a :class:`~slamio.noise.model.NoiseModel` from run logs that have ground truth.

``fgslam calibrate LOG... --out noise.json`` calls :func:`fit_noise_model`. Any log with
truth poses (motion capture, a simulator) and, for the observation model, truth
landmarks will do; several logs are pooled into one model, so a model fitted on some runs
can be scored on others (never on the runs it was fitted on).

What is fitted, and how (every step is least squares on residuals against the truth):

1. **Odometry lag and scale.** The log's odometry is composed into a dead-reckoned chain
   whose pose can be read at any time (within one increment at constant velocity:
   :class:`~slamio.noise.dead_reckoning.DeadReckoning`). Over
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
   the outliers. Where the sensor sits on the robot is fitted from the bearings' parallax
   (:mod:`slamio.noise.mount_fit`) and reported; with ``fit_mount`` it is used for all of the
   above and carried by the model.
4. **Readings' error in time.** Two readings of one landmark taken close together err
   alike. The residuals divided by their σ are paired per landmark and run, binned by the
   time between them, and ``ρ·exp(−Δt/τ)`` is fitted to the bins' correlations
   (:func:`slamio.noise.fitting.fit_reading_correlation`): the model's ``correlated_share`` ρ and
   ``correlation_time_s`` τ.

Robust statistics (median absolute deviation, 5σ gate) keep misread barcodes and motion
capture glitches out of the fit; their share is the model's ``outlier_rate``. They, and the
reading of a log against its truth, are :mod:`slamio.noise.fitting`'s.

A truth that measures position only (GPS: ``truth_pose`` without ``theta_rad``) can fit a
range-only model (ranging radios, :mod:`slamio.noise.range`) but not the odometry, whose turns
need the true heading: the model then carries the default odometry part, and its
``fit_report["odometry"]`` says it was not fitted. Bearings against such a truth are refused.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Sequence

import numpy as np

from slamio.geometry import wrap_angle
from slamio.log import RunLog
from slamio.noise.dead_reckoning import turn_rate_radps
from slamio.noise.errors import NoiseModelError
from slamio.noise.fitting import (GATE_SIGMAS, TruthData, fit_reading_correlation, line_fit, mad_sigma, nnls_rates,
                                  residuals_about_own_lines, truth_at, truth_data)
from slamio.noise.model import NoiseModel, ObservationModel, OdometryModel, OdometryNoiseRates
from slamio.noise.mount_fit import MountFit, determined, sensor_poses
from slamio.noise.mount_fit import fit_mount as fit_sensor_mount
from slamio.noise.range import fit_range_only

__all__ = ["fit_noise_model", "true_range_bearing"]

#: Floor of the per-second variance rates (they must be > 0): 1 mm, 1 mrad per √s.
MIN_RATE_PER_S = 1e-6
#: Length of the windows over which the odometry lag is fitted, seconds.
LAG_WINDOW_S = 0.5


def _between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """b expressed in a's frame (x, y, θ), θ unwrapped difference."""
    c, s = math.cos(a[2]), math.sin(a[2])
    dx, dy = b[0] - a[0], b[1] - a[1]
    return np.array([c * dx + s * dy, -s * dx + c * dy, b[2] - a[2]])


# --------------------------------------------------------------------------- odometry fit


def _windows(data: TruthData, window_s: float) -> list[tuple[float, float, np.ndarray]]:
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


def _odometry_increments(data: TruthData, windows, lag_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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


def _fit_lag(datas: Sequence[TruthData], lag_grid_s: np.ndarray, window_s: float) -> float:
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
        raise NoiseModelError("too few windows of motion with truth at both ends to fit the odometry")
    return best[1]


def _fit_odometry(datas: Sequence[TruthData], window_s: float, lag_grid_s: np.ndarray) -> tuple[OdometryModel, dict]:
    lag = _fit_lag(datas, lag_grid_s, LAG_WINDOW_S)
    windows = [_windows(d, window_s) for d in datas]
    parts = [_odometry_increments(d, w, lag) for d, w in zip(datas, windows)]
    odo, true = np.vstack([p[0] for p in parts]), np.vstack([p[1] for p in parts])
    if len(odo) < 20:
        raise NoiseModelError("too few windows of motion with truth at both ends to fit the odometry")
    fx, ft, c = _scales(odo, true)
    dts = np.concatenate([p[2] for p in parts])
    res = _residuals(odo, true, fx, ft, c)
    dist = np.abs(fx * odo[:, 0])
    turn = np.abs(ft * odo[:, 2])
    f_rates = nnls_rates(res[:, 0], np.column_stack([dist, dts]))
    l_rates = nnls_rates(res[:, 1], np.column_stack([dist, dts]))
    h_rates = nnls_rates(res[:, 2], np.column_stack([turn, dist, dts]))
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
              "residual_mad": [round(mad_sigma(res[:, j]), 6) for j in range(3)]}
    model = OdometryModel(lag_s=lag, forward_scale=fx, turn_scale=ft, turn_per_m_rad=c, noise=noise)
    return model, report


# --------------------------------------------------------------------------- observation fit


def _readings_at_truth(data: TruthData, latency_s: float) -> tuple[np.ndarray, ...]:
    """(the robot's true pose at each picture (n, 3), measured range, measured bearing, picture
    time, landmark position (n, 2)) of the readings whose picture time the truth brackets."""
    if not data.observations:
        empty = np.zeros(0)
        return np.zeros((0, 3)), empty, empty, empty, np.zeros((0, 2))
    obs = data.observations
    t = np.array([o[0] for o in obs]) - latency_s
    poses, ok = truth_at(data, t)
    rm = np.array([o[1] for o in obs])
    bm = np.array([o[2] for o in obs])
    lm = np.array([o[3] for o in obs])
    return poses[ok], rm[ok], bm[ok], t[ok], lm[ok]


def true_range_bearing(data: TruthData, latency_s: float) -> tuple[np.ndarray, ...]:
    """(measured range, measured bearing, true range, true bearing, picture times, landmark
    positions (n, 2)) of the readings with truth, the truth as the sensor sees it: from its
    pose on the robot (:func:`slamio.noise.mount_fit.sensor_poses`; the centre without one)."""
    poses, rm, bm, t, lm = _readings_at_truth(data, latency_s)
    mount = (0.0, 0.0, 0.0) if data.mount is None else data.mount
    sensor = sensor_poses(poses, mount)
    dx, dy = lm[:, 0] - sensor[:, 0], lm[:, 1] - sensor[:, 1]
    return rm, bm, np.hypot(dx, dy), wrap_angle(np.arctan2(dy, dx) - sensor[:, 2]), t, lm


def _mount(datas: Sequence[TruthData], latency_s: float, adopt: bool) -> tuple[list[TruthData], MountFit | None]:
    """The sensor's pose on the robot fitted from the bearings (:mod:`slamio.noise.mount_fit`),
    and ``datas`` seen from it when ``adopt`` and the data determine it (else as the headers
    state)."""
    readings = [_readings_at_truth(d, latency_s) for d in datas]
    if sum(len(bm) for _, _, bm, _, _ in readings) < 20:  # too few to place the sensor: the observation fit says so
        return list(datas), None
    start = next((d.mount for d in datas if d.mount is not None), (0.0, 0.0, 0.0))
    fit = fit_sensor_mount(np.vstack([p for p, *_ in readings]), np.vstack([lm for *_, lm in readings]),
                           np.concatenate([bm for _, _, bm, _, _ in readings]), start)
    return ([replace(d, mount=fit.pose) for d in datas] if adopt and determined(fit) else list(datas)), fit


def _fit_observations(datas: Sequence[TruthData], odometry: OdometryModel, latency_grid_s: np.ndarray,
                      fit_mount: bool) -> tuple[ObservationModel, dict]:
    if sum(len(d.observations) for d in datas) < 20:
        raise NoiseModelError(
            "fewer than 20 observations of landmarks with truth; the observation fit needs "
            "truth_landmark records and observations with landmark ids"
        )
    stated = [d.mount for d in datas]
    if fit_mount:  # placed first, so the latency is chosen with the sensor placed
        datas, _ = _mount(datas, 0.0, True)
    best = None
    for latency in latency_grid_s:
        parts = [true_range_bearing(d, float(latency)) for d in datas]
        bm = np.concatenate([p[1] for p in parts])
        b = np.concatenate([p[3] for p in parts])
        if len(b) < 20:
            raise NoiseModelError(
                "fewer than 20 observations of landmarks with truth; the observation fit needs "
                "truth_landmark records and observations with landmark ids"
            )
        _, _, res = line_fit(b, wrap_angle(bm))
        spread = mad_sigma(res)
        if best is None or spread < best[0]:
            best = (spread, float(latency))
    latency = best[1]
    datas, mount = _mount([replace(d, mount=m) for d, m in zip(datas, stated)], latency, fit_mount)
    adopted = fit_mount and mount is not None and determined(mount)
    parts = [true_range_bearing(d, latency) for d in datas]
    rm, bm, r, b, t = (np.concatenate([p[j] for p in parts]) for j in range(5))
    landmark = np.unique(np.vstack([p[5] for p in parts]), axis=0, return_inverse=True)[1].ravel()
    omega = np.concatenate([
        odometry.turn_scale * turn_rate_radps(d.chain, p[4] - odometry.lag_s) for d, p in zip(datas, parts)  # |ω|
    ])
    bearing_scale, bearing_bias, _ = line_fit(b, bm)
    fits = {}
    for name, along in (("range", r), ("depth", r * np.cos(b))):
        scale, bias, res = line_fit(along, rm)
        fits[name] = (mad_sigma(res), scale, bias)
    is_depth = fits["depth"][0] < fits["range"][0]
    _, range_scale, range_bias = fits["depth" if is_depth else "range"]
    # σ from the scatter about each log's own line (:func:`residuals_about_own_lines`)
    own = np.concatenate([np.full(len(p[0]), j) for j, p in enumerate(parts)])
    res_r = residuals_about_own_lines(r * np.cos(b) if is_depth else r, rm, own, (range_scale, range_bias))
    res_b = residuals_about_own_lines(b, bm, own, (bearing_scale, bearing_bias))
    gate_r = GATE_SIGMAS * mad_sigma(res_r)
    gate_b = GATE_SIGMAS * mad_sigma(res_b)
    inlier = (np.abs(res_r) <= gate_r) & (np.abs(res_b) <= gate_b)
    r_rates = nnls_rates(res_r[inlier], np.column_stack([np.ones(inlier.sum()), r[inlier] ** 2]))
    b_rates = nnls_rates(res_b[inlier], np.column_stack([np.ones(inlier.sum()), omega[inlier] ** 2]))
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
        sensor_pose_on_robot=mount.pose if adopted else None,
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
        "bearing_residual_mad_rad": round(mad_sigma(res_b), 6),
        "reading_correlation": correlation.report(),
        "sensor_mount": {**({} if mount is None else mount.report()),
                         "determined": mount is not None and determined(mount), "adopted": adopted,
                         "stated_in_logs": [None if m is None else list(m) for m in stated]},
    }
    return model, report


# --------------------------------------------------------------------------- entry point


def fit_noise_model(
    logs: Sequence[RunLog],
    *,
    window_s: float = 1.0,
    lag_grid_s: np.ndarray | None = None,
    latency_grid_s: np.ndarray | None = None,
    fit_mount: bool = False,
) -> NoiseModel:
    """Fit one :class:`NoiseModel` to all ``logs`` pooled (see the module docstring).

    ``window_s`` is the length of the odometry windows (the variance rates are right at
    that scale); ``lag_grid_s`` (default −0.1…0.6 s by 10 ms) and ``latency_grid_s``
    (default 0…0.1 s by 10 ms) are the candidate odometry lags and camera latencies.
    The sensor's pose on the robot is always fitted and reported (``fit_report["observation"]
    ["sensor_mount"]``); with ``fit_mount`` the model carries it and the rest of the
    observation model is fitted from there (else the logs' headers stand).
    Raises :class:`NoiseModelError` when the logs have no truth or too little data.
    """
    if not logs:
        raise NoiseModelError("no logs to fit; give one or more logs with ground truth")
    lag_grid = np.round(np.arange(-0.1, 0.6001, 0.01), 3) if lag_grid_s is None else np.asarray(lag_grid_s, float)
    latency_grid = np.round(np.arange(0.0, 0.1001, 0.01), 3) if latency_grid_s is None else np.asarray(latency_grid_s, float)
    datas = [truth_data(log) for log in logs]
    headless = [d.name for d in datas if not np.all(np.isfinite(d.truth_poses[:, 2]))]
    if headless and any(d.observations for d in datas):
        raise NoiseModelError(f"{headless[0]}: its truth has no heading (GPS), which the camera's bearings and the "
                               "odometry's turns are fitted against; calibrate on logs whose truth has a heading")
    if headless:  # ranging radios against GPS: the range model only
        odometry, odo_report = OdometryModel(), {"not_fitted": "the truth has no heading: the defaults, not a fit"}
    else:
        odometry, odo_report = _fit_odometry(datas, window_s, lag_grid)
    if any(d.observations for d in datas):
        observation, obs_report = _fit_observations(datas, odometry, latency_grid, fit_mount)
    elif any(d.ranges for d in datas):  # ranging radios: range-only readings (slamio.noise.range)
        observation, obs_report = fit_range_only(datas)
    else:
        raise NoiseModelError(
            "no observation of a landmark with truth in these logs; the fit needs truth_landmark records"
        )
    return NoiseModel(
        odometry, observation, tuple(log.path for log in logs),
        {"odometry": odo_report, "observation": obs_report},
    )
