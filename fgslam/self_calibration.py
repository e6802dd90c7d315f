"""Noise learned from the run itself (``fgslam calibrate LOG... --without-truth``, ``fgslam run
LOG --noise self``): variance-component estimation on the batch solution.

First the odometry's lag, from the readings alone: consecutive readings of one landmark are
predicted from each other through the odometry's motion shifted by a lag, and the lag whose
bearings miss least is the one the camera saw (:func:`slamio.noise.fit_self.lag_from_readings`;
on the five MRCLAM Dataset 6 robots it finds 0.24–0.28 s, where Vicon says 0.26 s). The
odometry is re-read with it (:mod:`slamio.noise.apply`).

Then for each planar log: one run of the default ``isam2`` gives the initial estimate and the
landmark each reading was paired with (the log's ids, or the smoother's association for
readings without one), and with the components θ of :data:`COMPONENTS` (the variance terms
of :class:`~slamio.noise.model.NoiseModel`):

1. build the factor graph with every row's σ² = q·θ (:class:`RunGraph`): a prior on the start
   pose, one ``BetweenFactorPose2`` per odometry record (rows dx, dy, dθ; ``q`` its distance,
   turn and duration), one ``BearingRangeFactor2D`` per reading (rows bearing, range; ``q``
   1 and ω² for the bearing, 1 and r² for the range; a ``RangeFactor2D`` for a range-only
   reading);
2. solve it (Levenberg–Marquardt from the last solution), readings beyond the 5σ gate left
   out (they are the outliers: their share is ``outlier_rate``);
3. update θ with a Fisher-scoring step of the variance components
   (:mod:`slamio.noise.fit_self`), pooled over the logs;

until every determined component moves by less than 1 % (at most :data:`MAX_ITERATIONS`).

Then the camera's range model, from the whole run (:func:`profile_range_model`): whether its
"range" is the Euclidean range or the depth along its axis (``r·cos b``: a camera that sizes
the landmark's image measures depth), and its bias, chosen by the readings' likelihood at the
batch solution with θ held; then θ again, in turn, until the range model settles. On the
five MRCLAM Dataset 6 robots it finds depth on every one (Vicon: depth, +4.7 cm with scale
1.024) and the median anchored ATE of iSAM2 falls from 0.30 to 0.16 m
(docs/results-datasets.md, "Noise learned without truth").
The readings' correlation in time is not learned: estimated from the residuals at the
solution (which absorb a landmark's lasting error into its position) it came out ρ ≈ 0.5–0.7
with τ ≈ 3–6 s on MRCLAM (Vicon: 0.56, 16 s) and made the EKF worse on two robots of five
(docs/results-datasets.md), so the model keeps white readings.

With ``odometry_window_s`` the odometry's variance components are learned from its steps
chained over stretches of that many seconds against the batch solution
(:mod:`slamio.noise.odometry_windows`) rather than step by step; off by default (on MRCLAM
Dataset 6, 15 s windows lifted NEES in band a little and made the online anchored ATE
worse: docs/results-datasets.md).

On a range-only log (ranging radios) the range scale is profiled instead
(:func:`fgslam.self_profiles.profile_range_scale`), the odometry as read taken as the measure
of distance: Plaza1 and Plaza2 each give 1.065–1.068 alone, where GPS says 1.069–1.070.

What it does not learn: a camera's range scale (the gauge: only the odometry's scale against
it shows), the odometry's scales (:func:`profile_scales` can, ``scales=True``: it recovers a
simulated robot's and comes close to Vicon's on MRCLAM, but made the MRCLAM estimates worse:
iSAM2 final median 0.161 → 0.258 m, so it is off), the bearing's
scale and bias, the camera's latency — they keep the model's default (scale 1, bias 0) and
are listed in the fit report as ``not determined without truth``, with the components the
data could not separate (relative standard deviation ≥ 0.5).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import gtsam
import numpy as np
from gtsam.symbol_shorthand import L, X

from fgslam.linearized import whitened_system
from fgslam.registry import build
from fgslam.runner import run_estimator
from slamio.log import Observation, RunLog
from slamio.noise.apply import apply_noise_model
from slamio.noise.dead_reckoning import DeadReckoning, odometry_arrays, turn_rate_radps
from slamio.noise.errors import NoiseModelError
from slamio.noise.fit_self import (
    LAG_GRID_S, LagFromReadings, component_shares, hat_traces, hat_traces_projected, lag_from_readings, pair_weights,
    ranges_from_readings, relative_std, scoring_step,
)
from slamio.noise.model import NoiseModel, ObservationModel, OdometryModel, OdometryNoiseRates
from slamio.noise.odometry_windows import window_bounds, window_maps, window_residuals, window_sums

from fgslam.self_profiles import PROFILE_ROUNDS, profile_range_model, profile_range_scale, profile_scales, settled

__all__ = ["COMPONENTS", "RunGraph", "SelfCalibration", "fit_without_truth", "profile_range_model", "profile_scales"]

#: The variance components, in the order of θ: the odometry's variance rates (as in
#: :class:`OdometryNoiseRates`) and the readings' variances (σ² of ``range_sigma_m``,
#: ``range_sigma_per_m``, ``bearing_sigma_rad``, ``bearing_sigma_s``).
COMPONENTS = (
    "forward_m2_per_m", "forward_m2_per_s", "lateral_m2_per_m", "lateral_m2_per_s",
    "heading_rad2_per_rad", "heading_rad2_per_m", "heading_rad2_per_s",
    "range_sigma_m", "range_sigma_per_m", "bearing_sigma_rad", "bearing_sigma_s",
)
ODOMETRY_COMPONENTS = 7
#: The noise group of each component (what the verdict of a run reports on).
GROUP = ("odometry",) * ODOMETRY_COMPONENTS + ("range", "range", "bearing", "bearing")
#: Where the iterations start: the default model's round numbers, with the range and bearing
#: growth terms at small non-zero values (a multiplicative update cannot leave zero).
START = np.array([0.01, 1e-6, 0.0025, 1e-6, 0.01, 0.0025, 1e-6, 0.1**2, 0.01**2, 0.05**2, 0.01**2])
MAX_ITERATIONS = 60
TOLERANCE = 0.01
#: A reading is an outlier when either of its whitened residuals exceeds this (the 5σ gate
#: ``outlier_rate`` is defined by).
GATE_SIGMA = 5.0
#: A component with a relative standard deviation at least this large is reported as not
#: separable from the others by this data.
UNDETERMINED_RELATIVE_STD = 0.5
NOT_DETERMINED_WITHOUT_TRUTH = (
    "odometry.forward_scale", "odometry.turn_scale", "odometry.turn_per_m_rad",
    "observation.range_is_depth", "observation.range_scale", "observation.range_bias_m",
    "observation.bearing_scale", "observation.bearing_bias_rad", "observation.camera_latency_s",
    "observation.correlated_share", "observation.correlation_time_s",
)


@dataclass(frozen=True)
class Reading:
    stamp_s: float
    pose: int
    landmark: int
    bearing_rad: float | None  # None: a range-only reading
    range_m: float
    turn_rate_radps: float
    range_read_m: float = math.nan  # the range as read (range_m is corrected by a range model)
    range_sigma_factor: float = 1.0  # the read range's σ times this is range_m's


class RunGraph:
    """One planar log's measurements, with the landmark each reading was paired with; builds
    its factor graph for any θ (the measurements never change, only their σ)."""

    def __init__(self, log: RunLog, window_s: float | None = None):
        self.path = log.path
        self.window_s = window_s
        steps = log.steps()
        if log.header.is_3d:
            raise NoiseModelError(f"{log.path}: a 3-D log; calibrate --without-truth writes a planar noise model. "
                                  "For a stereo + IMU log, fgslam run LOG --noise self learns its sigma and runs")
        smoother = build("isam2", 2, log.header)
        run_estimator(smoother, steps, covariances=False)
        trajectory = np.asarray(smoother.trajectory(), dtype=float)
        if len(trajectory) != len(steps):
            raise NoiseModelError(f"{log.path}: the smoother kept {len(trajectory)} of {len(steps)} poses; "
                                  "fit without truth needs one pose per step")
        self.header = log.header
        self.stamps_s, self.increments = odometry_arrays(steps)
        self.windows = window_bounds(self.stamps_s, window_s) if window_s and len(steps) > 1 else None
        self.read_increments = self.increments
        self.set_increments(self.increments)
        chain = DeadReckoning(self.stamps_s, self.increments) if len(steps) > 1 else None
        paired = smoother.associations()
        self.readings: list[Reading] = []
        self.unpaired = 0
        k = 0
        for t, step in enumerate(steps):
            for o in step.observations:
                landmark = paired[k] if k < len(paired) else o.landmark_id
                k += 1
                if landmark is None:
                    self.unpaired += 1
                    continue
                rate = 0.0 if chain is None else float(turn_rate_radps(chain, np.array([o.stamp_s]))[0])
                self.readings.append(Reading(o.stamp_s, t, int(landmark), o.bearing_rad, float(o.range_m), rate,
                                             float(o.range_m)))
        self.values = gtsam.Values()
        for t, pose in enumerate(trajectory):
            self.values.insert(X(t), gtsam.Pose2(*pose))
        for landmark, xy in smoother.landmarks().items():
            if any(r.landmark == landmark for r in self.readings):
                self.values.insert(L(int(landmark)), gtsam.Point2(*np.asarray(xy, dtype=float)[:2]))
        self.readings = [r for r in self.readings if self.values.exists(L(r.landmark))]
        self.inlier = np.ones(len(self.readings), dtype=bool)

    def set_increments(self, increments: np.ndarray, variance_scale=None) -> None:
        """The odometry factors' increments (re-read with other scales), with their ``q``;
        with ``variance_scale`` ``q`` stays as it was and the variances are multiplied by it
        (:func:`profile_scales`)."""
        self.increments = np.asarray(increments, dtype=float)
        self.variance_scale = np.ones(3) if variance_scale is None else np.asarray(variance_scale, dtype=float)
        if variance_scale is not None:
            return
        dt = np.maximum(np.diff(self.stamps_s), 0.0)
        distance = np.hypot(self.increments[:, 0], self.increments[:, 1])
        turn = np.abs(self.increments[:, 2])
        self.odometry_q = np.zeros((len(dt), 3, len(COMPONENTS)))
        self.odometry_q[:, 0, 0], self.odometry_q[:, 0, 1] = distance, dt
        self.odometry_q[:, 1, 2], self.odometry_q[:, 1, 3] = distance, dt
        self.odometry_q[:, 2, 4], self.odometry_q[:, 2, 5], self.odometry_q[:, 2, 6] = turn, distance, dt

    def odometry_windows(self, theta: np.ndarray, rows: int):
        """``(U, Q, Σ, residuals)`` of the odometry windows at the current solution
        (:mod:`slamio.noise.odometry_windows`; the odometry's rows follow the prior's three)."""
        q = self.odometry_q * self.variance_scale[None, :, None]
        variances = np.maximum(self.odometry_q @ theta, 1e-18) * self.variance_scale
        U, Q, S = window_maps(self.increments, q, variances, self.windows, lambda k: rows if k is None else 3 + 3 * k)
        poses = np.array([[p.x(), p.y(), p.theta()] for p in (self.values.atPose2(X(t))
                                                              for t in range(len(self.increments) + 1))])
        return U, Q, S, window_residuals(poses, self.increments, self.windows)

    def chi2_half(self, theta: np.ndarray) -> float:
        """Half the whitened χ² of the batch solution for θ."""
        graph, _, _ = self.solve(theta)
        return float(graph.error(self.values))

    def set_range_model(self, range_is_depth: bool, range_bias_m: float) -> None:
        """Every range re-read under a camera range model (:func:`ranges_from_readings`);
        range-only readings keep theirs."""
        for i, r in enumerate(self.readings):
            if r.bearing_rad is None:
                continue
            rng, factor = ranges_from_readings(np.array([r.range_read_m]), np.array([r.bearing_rad]),
                                               range_is_depth, range_bias_m)
            self.readings[i] = dataclasses.replace(r, range_m=max(float(rng[0]), 1e-3),
                                                   range_sigma_factor=float(factor[0]))

    def set_range_scale(self, scale: float) -> None:
        """Every range-only reading re-read as ``range / scale`` (σ likewise: a radio that
        reads long by ``scale``); camera readings keep theirs."""
        for i, r in enumerate(self.readings):
            if r.bearing_rad is None:
                self.readings[i] = dataclasses.replace(r, range_m=max(r.range_read_m / scale, 1e-3),
                                                       range_sigma_factor=1.0 / scale)

    def range_model_cost(self, theta: np.ndarray) -> float:
        """−log p of the readings as read (up to a constant) at the batch solution under the
        current range model: half the χ² plus the log of each inlier range's σ as read (its
        σ after correction is that times the correction's derivative, which cancels)."""
        total = self.chi2_half(theta)
        for reading, inlier in zip(self.readings, self.inlier):
            if inlier:
                total += 0.5 * math.log(self.reading_q(reading)[-1] @ theta)
        return total

    def reading_q(self, reading: Reading) -> list[np.ndarray]:
        rows = []
        if reading.bearing_rad is not None:
            q = np.zeros(len(COMPONENTS))
            q[9], q[10] = 1.0, reading.turn_rate_radps**2
            rows.append(q)
        q = np.zeros(len(COMPONENTS))
        q[7], q[8] = 1.0, reading.range_m**2
        rows.append(q)
        return rows

    def reading_factor(self, reading: Reading, theta: np.ndarray):
        q_rows = self.reading_q(reading)
        sigmas = np.sqrt([q @ theta for q in q_rows])
        sigmas[-1] *= reading.range_sigma_factor
        model = gtsam.noiseModel.Diagonal.Sigmas(sigmas)
        if reading.bearing_rad is None:
            return gtsam.RangeFactor2D(X(reading.pose), L(reading.landmark), reading.range_m, model)
        return gtsam.BearingRangeFactor2D(X(reading.pose), L(reading.landmark), gtsam.Rot2(reading.bearing_rad),
                                          reading.range_m, model)

    def graph(self, theta: np.ndarray) -> tuple[gtsam.NonlinearFactorGraph, np.ndarray, np.ndarray]:
        """(graph, q (rows, C), group of each row) for θ, the inlier readings only."""
        graph = gtsam.NonlinearFactorGraph()
        start_sigma = np.asarray(self.header.start_sigma, dtype=float)
        graph.add(gtsam.PriorFactorPose2(X(0), gtsam.Pose2(*self.header.start_pose),
                                         gtsam.noiseModel.Diagonal.Sigmas(start_sigma)))
        q_rows = [np.zeros((3, len(COMPONENTS)))]
        groups = [np.array(["", "", ""])]
        for k, (inc, q) in enumerate(zip(self.increments, self.odometry_q)):
            variances = np.maximum(q @ theta, 1e-18) * self.variance_scale
            graph.add(gtsam.BetweenFactorPose2(X(k), X(k + 1), gtsam.Pose2(*inc),
                                               gtsam.noiseModel.Diagonal.Variances(variances)))
            q_rows.append(q)
            groups.append(np.array(["odometry"] * 3))
        for reading, inlier in zip(self.readings, self.inlier):
            if not inlier:
                continue
            graph.add(self.reading_factor(reading, theta))
            rows = self.reading_q(reading)
            q_rows.append(np.array(rows))
            groups.append(np.array((["bearing"] if len(rows) == 2 else []) + ["range"]))
        return graph, np.concatenate(q_rows), np.concatenate(groups)

    def solve(self, theta: np.ndarray) -> tuple[gtsam.NonlinearFactorGraph, np.ndarray, np.ndarray]:
        graph, q, groups = self.graph(theta)
        params = gtsam.LevenbergMarquardtParams()
        params.setMaxIterations(50)
        params.setRelativeErrorTol(1e-6)
        self.values = gtsam.LevenbergMarquardtOptimizer(graph, self.values, params).optimize()
        return graph, q, groups

    def regate(self, theta: np.ndarray) -> None:
        """Mark the readings beyond the 5σ gate at the current solution (every reading, those
        left out before too: one that fits again comes back)."""
        for i, reading in enumerate(self.readings):
            e = np.asarray(self.reading_factor(reading, theta).whitenedError(self.values))
            self.inlier[i] = bool(np.all(np.abs(e) <= GATE_SIGMA))


@dataclass
class SelfCalibration:
    """The result of :func:`fit_without_truth`."""

    model: NoiseModel
    theta: np.ndarray
    ratio: np.ndarray  # (C,) of the last iteration (1 at convergence)
    redundancy: np.ndarray
    relative_std: np.ndarray
    iterations: int
    converged: bool
    outlier_rate: float
    readings: int
    unpaired: int
    report: dict = field(default_factory=dict)


def _iteration(graphs: list[RunGraph], theta: np.ndarray):
    """Solve every log's graph at θ, then one step of θ from the sums pooled over the logs."""
    C = len(COMPONENTS)
    shown, redundancy = np.zeros(C), np.zeros(C)
    pair_sums, pair_hat = np.zeros(C * C), np.zeros(C * C)
    weights_all = []
    for run in graphs:
        graph, q, _ = run.solve(theta)
        A, b = whitened_system(graph, run.values)
        _, w = component_shares(theta, q)
        weights_all.append(w)
        if run.windows:  # the odometry's components from its windows, the readings' from their rows
            w = w.copy()
            w[3:3 + 3 * len(run.increments)] = 0.0
            pairs = pair_weights(w)
            U, Q, S, residuals = run.odometry_windows(theta, A.shape[0])
            hat, M = hat_traces_projected(A, np.hstack([w, pairs]), U, columns_ordered=True)
            sums = window_sums(theta, residuals, Q, S, M)
        else:
            pairs = pair_weights(w)
            hat = hat_traces(A, np.hstack([w, pairs]), columns_ordered=True)
            sums = (0.0, 0.0, 0.0, 0.0)
        shown += w.T @ (b * b) + sums[0]
        redundancy += w.sum(axis=0) - hat[:C] + sums[1]
        pair_sums += pairs.sum(axis=0) + sums[2]
        pair_hat += hat[C:] + sums[3]
        run.regate(theta)
    return scoring_step(theta, shown, redundancy, pair_sums, pair_hat), np.concatenate(weights_all)


def fit_without_truth(logs: list[RunLog], progress=None, *,
                      lags_s: tuple[float, ...] = LAG_GRID_S, scales: bool = False,
                      range_model: bool = True, pinned: dict[str, float] | None = None,
                      odometry_window_s: float | None = None) -> SelfCalibration:
    """Fit the odometry's lag among ``lags_s``, the variance terms of a :class:`NoiseModel`
    and (``range_model``) the camera's range model on ``logs`` alone (module docstring). The
    lag comes first, from the readings' bearings (:func:`slamio.noise.fit_self.lag_from_readings`,
    pooled over the logs); the variances are fitted on the odometry re-read with it, in turn
    with the range model (:func:`profile_range_model`) and, with ``scales``, the odometry's
    scales (:func:`profile_scales`). ``progress(done, total, label)``
    (:class:`fgslam.cli.progress.Progress`) after each iteration. ``pinned``: odometry scales
    measured otherwise (:meth:`slamio.noise.trials.TrialCalibration.odometry_scales`: a taped
    distance and turns in place), held while the rest is learned around them.
    ``odometry_window_s``: the odometry's variance rates learned from its increments chained
    over stretches of that many seconds (:mod:`slamio.noise.odometry_windows`) instead of
    step by step: the white noise that is as large as the odometry's error over the stretch."""
    range_only = all(o.range_only for log in logs for o in log.records if isinstance(o, Observation))
    motion = None if range_only else pooled_lag(logs, lags_s)
    lag = 0.0 if motion is None else motion.lag_s
    odometry = OdometryModel(lag_s=lag, **(pinned or {}))
    reread = motion is not None or bool(pinned)
    lagged = [apply_noise_model(log, NoiseModel(odometry))[0] if reread else log for log in logs]
    graphs, theta, step, weights, iterations, converged = _fit_variances(lagged, progress, "noise fit: iterations",
                                                                         odometry_window_s)
    radio_scale = range_model and range_only
    range_model = range_model and not range_only
    found, camera, costs = None, {}, {}
    for _ in range(PROFILE_ROUNDS if (scales or range_model or radio_scale) else 0):
        last = (dict(found or {}), dict(camera))
        if range_model:
            depth, bias, costs = profile_range_model(graphs, theta)
            camera = {"range_is_depth": depth, "range_bias_m": bias}
        if radio_scale:
            scale, cost = profile_range_scale(graphs, theta, progress)
            camera, costs = {"range_scale": scale}, {"range": (scale, cost)}
        if scales:
            found = profile_scales(graphs, theta, found)
        theta, step, weights, more, converged = _vce(graphs, theta, progress, "noise fit: iterations")
        iterations += more
        if settled(last, (found or {}, camera)):
            break
    if found:
        odometry = dataclasses.replace(odometry, **found)
    rel = relative_std(theta, weights)
    readings = sum(len(g.readings) for g in graphs)
    outliers = sum(int(np.count_nonzero(~g.inlier)) for g in graphs)
    result = _result(logs, theta, step, rel, iterations, converged, outliers / max(readings, 1), readings,
                     sum(g.unpaired for g in graphs), odometry)
    if camera:
        result.model = dataclasses.replace(result.model,
                                           observation=dataclasses.replace(result.model.observation, **camera))
        found_key = "range_scale" if radio_scale else "range_bias_m"
        result.report["range_model_from_readings"] = {
            **camera, "negative_log_likelihood": {k: {found_key: v[0], "cost": v[1]} for k, v in costs.items()}}
        learned = {f"observation.{name}" for name in camera}
        result.report["not_determined_without_truth"] = [n for n in NOT_DETERMINED_WITHOUT_TRUTH if n not in learned]
    if found:
        result.report["odometry_scales_from_the_run"] = dict(found)
    if pinned:
        result.report["odometry_scales_pinned"] = dict(pinned)
        result.report["not_determined_without_truth"] = [
            n for n in result.report["not_determined_without_truth"] if n.split(".")[-1] not in pinned]
    result.report["range_only"] = range_only
    result.report["odometry_window_s"] = odometry_window_s
    result.report["lag_from_readings"] = None if motion is None else {
        "lag_s": lag, "pairs": motion.pairs, "lags_tried_s": [float(v) for v in lags_s],
        "median_squared_bearing_miss_rad2": [float(c) if np.isfinite(c) else None for c in motion.cost]}
    return result


def pooled_lag(logs: list[RunLog], lags_s: tuple[float, ...]) -> LagFromReadings | None:
    """The lag :func:`lag_from_readings` finds on the logs together (their costs weighted by
    their pairs); None without 20 pairs of readings."""
    total, pairs = None, 0
    for log in logs:
        steps = log.steps()
        if len(steps) < 2:
            continue
        stamps, increments = odometry_arrays(steps)
        readings = [(o.stamp_s, o.landmark_id, o.range_m, o.bearing_rad) for s in steps for o in s.observations
                    if o.landmark_id is not None and o.bearing_rad is not None]
        found = lag_from_readings(DeadReckoning(stamps, increments), readings, lags_s)
        if found.pairs >= 20 and np.all(np.isfinite(found.cost)):
            total = found.pairs * found.cost if total is None else total + found.pairs * found.cost
            pairs += found.pairs
    if total is None:
        return None
    return LagFromReadings(float(lags_s[int(np.argmin(total))]), total / pairs, pairs)


def _fit_variances(logs: list[RunLog], progress, label: str, window_s: float | None = None):
    """The VCE iterations on ``logs``: ``(graphs, θ, last step, weights, iterations, converged)``."""
    graphs = [RunGraph(log, window_s) for log in logs]
    if not any(run.readings for run in graphs):
        raise NoiseModelError("no reading could be paired with a landmark: nothing to learn the noise from")
    return (graphs,) + _vce(graphs, START.copy(), progress, label)


def _vce(graphs: list[RunGraph], theta: np.ndarray, progress, label: str):
    """VCE iterations from θ: ``(θ, last step, weights, iterations, converged)``."""
    converged = False
    step = weights = None
    iteration = 0
    for iteration in range(1, MAX_ITERATIONS + 1):
        step, weights = _iteration(graphs, theta)
        theta = step.theta
        # converged when every component the data determine has stopped moving (those they
        # cannot separate drift slowly along the ridge and would never settle)
        separable = step.determined & (relative_std(theta, weights) < UNDETERMINED_RELATIVE_STD)
        change = float(np.max(np.abs(np.log(np.where(separable, step.ratio, 1.0)))))
        converged = change < math.log1p(TOLERANCE)
        if progress is not None:
            progress(MAX_ITERATIONS if converged else iteration, MAX_ITERATIONS, label)
        if converged:
            break
    return theta, step, weights, iteration, converged


def _result(logs, theta, step, rel, iterations, converged, outlier_rate, readings, unpaired,
            odometry: OdometryModel | None = None) -> SelfCalibration:
    rates = OdometryNoiseRates(**{name: float(v) for name, v in zip(COMPONENTS[:ODOMETRY_COMPONENTS], theta)})
    sigma = np.sqrt(theta[ODOMETRY_COMPONENTS:])
    observation = ObservationModel(range_sigma_m=float(sigma[0]), range_sigma_per_m=float(sigma[1]),
                                   bearing_sigma_rad=float(sigma[2]), bearing_sigma_s=float(sigma[3]),
                                   outlier_rate=float(outlier_rate))
    undetermined = [name for name, d, r in zip(COMPONENTS, step.determined, rel)
                    if not d or r >= UNDETERMINED_RELATIVE_STD]
    report = {
        "method": "without truth: variance-component estimation on the batch solution "
                  "(fgslam.self_calibration, slamio.noise.fit_self)",
        "iterations": iterations, "converged": converged,
        "components": {name: {"value": float(v), "relative_std": float(r) if math.isfinite(r) else None,
                              "redundancy": float(red)}
                       for name, v, r, red in zip(COMPONENTS, theta, rel, step.redundancy)},
        "not_separated_by_this_data": undetermined,
        "not_determined_without_truth": list(NOT_DETERMINED_WITHOUT_TRUTH),
        "readings": readings, "readings_unpaired": unpaired,
    }
    odometry = OdometryModel() if odometry is None else odometry
    model = NoiseModel(dataclasses.replace(odometry, noise=rates), observation, tuple(log.path for log in logs), report)
    return SelfCalibration(model, theta, step.ratio, step.redundancy, rel, iterations, converged, outlier_rate,
                           readings, unpaired, report)


