"""Log records → GTSAM factors and noise models: the maths of the factor graph's terms.

The pure functions here say which covariance each factor needs (GTSAM's error frames are
not the log's; see each docstring) and which robust kernel a landmark factor gets.
:class:`FactorBuilder` turns one record into its factor, sharing noise models between
records; :class:`PendingObservation` is an observation's factor on its way into iSAM2
(with what the gates of :mod:`fgslam.smoother.pending` need to check it). Nothing here
holds iSAM2 or decides when a factor goes in.
"""

from __future__ import annotations

import math

import gtsam
import numpy as np
from gtsam.symbol_shorthand import H, L, T, X

from slamio.errors import FgslamError
from slamio.log import Header, Observation, Odometry

#: The robust kernels :class:`~fgslam.smoother.isam2.Isam2Smoother` offers for landmark factors.
ROBUST_KERNELS = ("huber", "cauchy", "tukey", "dcs")

#: ``X(k)`` is ``X0 + k``: a key is its symbol's character in the top 8 bits and its index
#: below (gtsam.Symbol); the sum costs a tenth of the ``X(k)`` call, made at every step.
X0 = X(0)
L0 = L(0)  # the same for point landmarks
_COVARIANCE = gtsam.noiseModel.Gaussian.Covariance

#: Default kernel widths k, in whitened units (σ of the factor's whole 2-D residual).
#:
#: GTSAM's robust noise model applies the kernel to the *norm* r of the factor's whitened
#: residual (bearing/σ_b, range/σ_r) — one weight per factor, not one per component. For
#: an inlier r is Rayleigh-distributed (χ with 2 degrees of freedom), not |N(0, 1)|.
#:
#: * Huber, k = 1.345 (the classical 95 %-efficiency constant). Huber never rejects: an
#:   outlier keeps pulling with force k (in σ), and misdetections are one-sided (a range
#:   drawn over the sensor's whole span is mostly beyond a near landmark), so the bias
#:   they leave grows with k. On arena-octagon seeds 1–8 with 10 % outliers k = 1.345
#:   gave a lower ATE than k = 2.448 (= √χ²₂(0.95), all inliers on the quadratic part) on
#:   6 of 8 seeds (seed 3: 0.020 vs 0.028 m; outlier-free 0.008 m). It still puts about
#:   40 % of the inliers on the linear part, a small loss on clean logs.
#: * Cauchy, k = √χ²₂(0.999) ≈ 3.717: 99.9 % of inliers have r < k, so they keep weight
#:   1/(1 + r²/k²) ≥ 0.5; a misdetection, typically 20–100σ off in the simulated logs,
#:   gets weight < 0.035 and its pull fades to zero (redescending). Measured on the
#:   same seeds, k from 3 to 5 is within noise of iSAM2 on the log with the outliers
#:   removed by an oracle; k = 1.5–2.4 down-weights too many inliers (up to +30 % ATE).
#: * DCS (dynamic covariance scaling, Agarwal et al. ICRA 2013), k = √χ²₂(0.999) ≈ 3.717,
#:   passed to GTSAM as Φ = k²: weight exactly 1 for r ≤ k — good observations are plain
#:   least squares — and (2Φ/(Φ + r²))² beyond (a misdetection 20σ off: 0.004). On the grid,
#:   where re-weighting good observations visibly moves the map (see docs/performance.md),
#:   it is the only kernel within 1.2× of the outlier-free ATE.
#: * Tukey, k = 2·√χ²₂(0.999) ≈ 7.43: weight (1 − r²/k²)² inside k (≥ 0.56 for 99.9 % of
#:   inliers), exactly zero beyond — a misdetection has no pull at all. Non-convex, so it
#:   needs a landmark seeded from good observations: without the first-sighting check of
#:   :meth:`~fgslam.smoother.pending.PendingObservations.confirm_first_sightings` it ended up to 5× the oracle's ATE.
DEFAULT_ROBUST_K = {
    "huber": 1.345,
    "cauchy": math.sqrt(-2.0 * math.log(0.001)),
    "tukey": 2.0 * math.sqrt(-2.0 * math.log(0.001)),
    "dcs": math.sqrt(-2.0 * math.log(0.001)),
}



def robust_estimator(robust: str, k: float | None = None):
    """GTSAM's m-estimator ``robust`` ("huber" or "cauchy") with width ``k`` (None: default).

    Its ``loss(r)`` of a whitened residual norm r is Huber ``r²/2`` for r ≤ k, else
    ``k·r − k²/2``; Cauchy ``k²/2 · ln(1 + r²/k²)``; Tukey ``k²/6 · (1 − (1 − r²/k²)³)`` for
    r ≤ k, else ``k²/6``; DCS (Φ = k²) ``r²/2`` for r ≤ k, else ``3Φ/2 − 2Φ²/(Φ + r²)``.
    """
    if robust not in ROBUST_KERNELS:
        raise FgslamError(f"robust kernel must be one of {', '.join(ROBUST_KERNELS)} (or None), got {robust!r}")
    k = DEFAULT_ROBUST_K[robust] if k is None else float(k)
    if not (math.isfinite(k) and k > 0):
        raise FgslamError(f"robust_k must be a finite number > 0 (whitened units), got {k!r}")
    if robust == "huber":
        return gtsam.noiseModel.mEstimator.Huber.Create(k)
    if robust == "tukey":
        return gtsam.noiseModel.mEstimator.Tukey.Create(k)
    if robust == "dcs":
        return gtsam.noiseModel.mEstimator.DCS.Create(k * k)
    return gtsam.noiseModel.mEstimator.Cauchy.Create(k)


def odometry_noise_covariance(odometry: Odometry) -> np.ndarray:
    """The covariance GTSAM's ``BetweenFactorPose2`` needs for one odometry record.

    The log's covariance is over the increment's numbers (dx, dy, dtheta) — additive noise,
    as an EKF uses it. GTSAM's between-factor error is ``Log(measured⁻¹ · predicted)``,
    i.e. expressed in the frame at the *end* of the measured increment. To first order an
    additive error (n_x, n_y, n_θ) on the increment is the error (R(dθ)ᵀ·(n_x, n_y), n_θ)
    there, so the covariance is rotated by the increment's own turn dθ. For an isotropic
    translation covariance (σx = σy, no cross terms) this changes nothing; otherwise it
    keeps iSAM2 and the EKF modelling exactly the same noise.
    """
    return _end_frame_covariance(odometry.covariance, odometry.dtheta_rad)


def _end_frame_covariance(Q, dtheta_rad: float) -> np.ndarray:
    """blockdiag(R(dθ)ᵀ, 1) · Q · blockdiag(R(dθ), 1) for a symmetric 3×3 ``Q`` over
    (dx, dy, dθ): the covariance of a relative pose's additive noise expressed, as GTSAM's
    ``BetweenFactorPose2`` error is, in the frame at the end of the relative pose."""
    xx, xy, xt, yy, yt, f = end_frame_covariance_entries(Q, dtheta_rad)
    return np.array([[xx, xy, xt], [xy, yy, yt], [xt, yt, f]])


def end_frame_covariance_entries(Q, dtheta_rad: float) -> tuple[float, float, float, float, float, float]:
    """The upper triangle ``(xx, xy, xθ, yy, yθ, θθ)`` of :func:`_end_frame_covariance`, as floats."""
    (a, b, c), (_, d, e), (_, _, f) = Q  # upper triangle
    cos, sin = math.cos(dtheta_rad), math.sin(dtheta_rad)
    # blockdiag(R(dθ)ᵀ, 1) · Q · blockdiag(R(dθ), 1), written out (this runs once per step)
    xx = cos * cos * a + 2.0 * cos * sin * b + sin * sin * d
    yy = sin * sin * a - 2.0 * cos * sin * b + cos * cos * d
    xy = cos * sin * (d - a) + (cos * cos - sin * sin) * b
    xt = cos * c + sin * e
    yt = -sin * c + cos * e
    return xx, xy, xt, yy, yt, f


def _covariance_of(entries) -> gtsam.noiseModel.Gaussian:
    """``Gaussian.Covariance`` of the 3×3 covariance whose upper triangle is ``entries``
    (``(xx, xy, xθ, yy, yθ, θθ)``, :func:`end_frame_covariance_entries`)."""
    xx, xy, xt, yy, yt, f = entries
    return _COVARIANCE(np.array((xx, xy, xt, xy, yy, yt, xt, yt, f)).reshape(3, 3))


def tag_relative_pose(observation: Observation) -> gtsam.Pose2:
    """The tag's pose in the robot frame: (r·cos b, r·sin b, tag yaw)."""
    r, b = observation.range_m, observation.bearing_rad
    return gtsam.Pose2(r * math.cos(b), r * math.sin(b), observation.tag_yaw_rad)


def tag_noise_covariance(observation: Observation) -> np.ndarray:
    """The covariance GTSAM's ``BetweenFactorPose2(X, T)`` needs for a tag observation.

    The camera measures range, bearing and the tag's yaw with independent noise
    (σ_r, σ_b, σ_ψ). To first order the relative pose (r·cos b, r·sin b, ψ) then has the
    covariance J·diag(σ_r², σ_b², σ_ψ²)·Jᵀ with J = ∂(x, y, ψ)/∂(r, b, ψ) =
    [[cos b, −r·sin b, 0], [sin b, r·cos b, 0], [0, 0, 1]]; as for odometry, GTSAM's error
    is in the frame at the end of the relative pose (the tag's), so it is rotated by ψ.
    """
    r, b = observation.range_m, observation.bearing_rad
    J = np.array([[math.cos(b), -r * math.sin(b), 0.0], [math.sin(b), r * math.cos(b), 0.0], [0.0, 0.0, 1.0]])
    S = np.diag([observation.sigma_range_m**2, observation.sigma_bearing_rad**2, observation.sigma_tag_yaw_rad**2])
    Q = J @ S @ J.T
    return _end_frame_covariance(0.5 * (Q + Q.T), observation.tag_yaw_rad)


def has_tag_yaw(observation: Observation) -> bool:
    """True when the observation carries a usable tag yaw (a value and a positive σ)."""
    return (
        observation.tag_yaw_rad is not None
        and observation.sigma_tag_yaw_rad is not None
        and observation.sigma_tag_yaw_rad > 0.0
    )


def start_prior_covariance(header: Header) -> np.ndarray:
    """The covariance GTSAM's ``PriorFactorPose2`` on pose 0 needs for the header's sigmas.

    ``header.start_sigma`` are world-frame standard deviations of (x, y, theta). GTSAM's
    prior error ``Log(prior⁻¹ · pose)`` is in the start pose's own frame, so the
    translation part is rotated by −theta₀. With theta₀ = 0 or σx = σy this is simply
    ``diag(start_sigma²)``.
    """
    S = np.diag(np.square(np.asarray(header.start_sigma, dtype=float)))
    th = header.start_pose[2]
    c, s = math.cos(th), math.sin(th)
    A = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])  # blockdiag(R(θ₀)ᵀ, 1)
    cov = A @ S @ A.T
    return 0.5 * (cov + cov.T)


class PendingObservation:
    """An observation factor not (yet) accepted into iSAM2.

    ``landmark_guess`` is the landmark implied by the observation and its seed pose: a
    point (``numpy`` array) or a tag's ``Pose2``. Only a landmark iSAM2 does not hold yet
    needs it (its seed, and the gates of :mod:`fgslam.smoother.pending`), so a point's is
    computed on first use from ``seed_pose`` and the reading kept in ``polar``
    ``(range_m, bearing_rad)``: most observations are of landmarks already in the map.
    """

    __slots__ = ("landmark_id", "key", "pose_index", "factor", "gate_factor", "seed_pose", "attempts",
                 "awaiting_estimate", "_guess", "_polar")

    def __init__(self, landmark_id: int, key: int, pose_index: int, factor: gtsam.NonlinearFactor,
                 gate_factor: gtsam.NonlinearFactor, landmark_guess: np.ndarray | gtsam.Pose2 | None,
                 seed_pose: gtsam.Pose2, attempts: int = 0, polar: tuple[float, float] | None = None):
        self.landmark_id = landmark_id
        self.key = key  # the landmark's variable: L(id) for a point, T(id) for a tag
        self.pose_index = pose_index
        self.factor = factor
        self.gate_factor = gate_factor  # the same with the plain Gaussian noise (for the gate)
        self.seed_pose = seed_pose  # the robot pose the observation was made from, as seeded then
        self.attempts = attempts  # failed updates it took part in
        self.awaiting_estimate = False  # failed the gate at a fresh guess: judged again once its landmark is in iSAM2
        self._guess = landmark_guess
        self._polar = polar  # (range_m, bearing_rad) of a point's reading, when its guess waits

    @property
    def landmark_guess(self) -> np.ndarray | gtsam.Pose2:
        """The landmark implied by the observation and its seed pose."""
        if self._guess is None:
            r, b = self._polar
            self._guess = np.asarray(self.seed_pose.transformFrom(np.array([r * math.cos(b), r * math.sin(b)])),
                                     dtype=float)
        return self._guess


class FactorBuilder:
    """Builds the factors of the records, with the landmark factors' robust kernel.

    Its only state is a cache of noise models: logs usually repeat a handful of
    covariances and sigmas, and building a model is a third of a step's Python cost.
    """

    def __init__(self, robust=None):
        self.robust = robust  # a gtsam m-estimator (see robust_estimator) or None
        self._noise_cache: dict = {}
        # odometry models by their end-frame covariance (odometry_noise); None once it has
        # shown itself useless on this log (fewer than 1 hit in 10 over its first lookups)
        self._frame_cache: dict | None = {}
        self._frame_lookups = self._frame_hits = 0

    def prior(self, header: Header) -> gtsam.PriorFactorPose2:
        """``PriorFactorPose2`` on ``X(0)`` at the header's start pose (:func:`start_prior_covariance`)."""
        prior_noise = gtsam.noiseModel.Gaussian.Covariance(start_prior_covariance(header))
        return gtsam.PriorFactorPose2(X(0), gtsam.Pose2(*header.start_pose), prior_noise)

    def odometry(self, k: int, odo: Odometry) -> gtsam.BetweenFactorPose2:
        """``BetweenFactorPose2(X(k − 1), X(k))`` for the odometry record ``odo``."""
        increment = gtsam.Pose2(odo.dx_m, odo.dy_m, odo.dtheta_rad)
        return gtsam.BetweenFactorPose2(X0 + k - 1, X0 + k, increment, self.odometry_noise(odo))

    def odometry_noise(self, odo: Odometry):
        """The odometry factor's noise model (see :func:`odometry_noise_covariance`).

        When the rotation there changes nothing (isotropic translation, no x/y–theta
        correlation) records with equal covariances share one model: logs usually repeat
        a handful of covariances, and building a model is a third of a step's Python cost.
        Otherwise (Victoria Park, Plaza1, MRCLAM: a covariance of its own at nearly every
        step) the model is built from :func:`end_frame_covariance_entries` directly, the same
        numbers as :func:`odometry_noise_covariance` in one flat array, and shared between
        records whose end-frame covariances are equal (Victoria Park: 538 distinct among
        6 968 records). On a log where they do not repeat (Plaza1, MRCLAM) that lookup stops
        after its first thousand.
        """
        Q = odo.covariance
        (a, b, c), (_, d, e), _ = Q
        if not (a == d and b == 0 and c == 0 and e == 0):
            entries = end_frame_covariance_entries(Q, odo.dtheta_rad)
            cache = self._frame_cache
            if cache is None:
                return _covariance_of(entries)
            noise = cache.get(entries)
            if noise is None:
                noise = _covariance_of(entries)
                if len(cache) < 10_000:
                    cache[entries] = noise
            else:
                self._frame_hits += 1
            self._frame_lookups += 1
            if self._frame_lookups == 1_000 and self._frame_hits < 100:
                self._frame_cache = None
            return noise
        noise = self._noise_cache.get(Q)
        if noise is None:
            noise = _COVARIANCE(odometry_noise_covariance(odo))
            if len(self._noise_cache) < 10_000:
                self._noise_cache[Q] = noise
        return noise

    def _observation_noise(self, obs: Observation):
        """(Gaussian, as-used) noise models for an observation's bearing-range factor."""
        key = (obs.sigma_bearing_rad, obs.sigma_range_m)
        models = self._noise_cache.get(key)
        if models is None:
            noise = gtsam.noiseModel.Diagonal.Sigmas(np.array([obs.sigma_bearing_rad, obs.sigma_range_m]))
            used = noise if self.robust is None else gtsam.noiseModel.Robust.Create(self.robust, noise)
            models = (noise, used)
            if len(self._noise_cache) < 10_000:
                self._noise_cache[key] = models
        return models

    def observation(self, k: int, seed: gtsam.Pose2, obs: Observation, is_tag: bool) -> PendingObservation:
        """The factor of an observation made from pose ``k`` (seeded at ``seed``) of a point
        landmark (``BearingRangeFactor2D`` to ``L(id)``) or, with ``is_tag``, of a tag
        (``BetweenFactorPose2`` to ``T(id)`` when it carries a yaw, else
        ``BearingRangeFactorPose2`` to the tag's centre)."""
        lid = obs.landmark_id
        noise, used = self._observation_noise(obs)
        bearing = gtsam.Rot2(obs.bearing_rad)
        if not is_tag:
            pose_key, key = X0 + k, L0 + lid
            factor = gtsam.BearingRangeFactor2D(pose_key, key, bearing, obs.range_m, used)
            gate_factor = factor
            if used is not noise:
                gate_factor = gtsam.BearingRangeFactor2D(pose_key, key, bearing, obs.range_m, noise)
            # the landmark's guess, seed ⊕ the reading, is computed when first asked for
            return PendingObservation(lid, key, k, factor, gate_factor, None, seed, 0, (obs.range_m, obs.bearing_rad))
        p_robot = np.array([obs.range_m * math.cos(obs.bearing_rad), obs.range_m * math.sin(obs.bearing_rad)])
        if has_tag_yaw(obs):  # the tag's whole pose relative to the robot
            measured = tag_relative_pose(obs)
            gaussian = gtsam.noiseModel.Gaussian.Covariance(tag_noise_covariance(obs))
            factor = gate_factor = gtsam.BetweenFactorPose2(X(k), T(lid), measured, gaussian)
            if self.robust is not None:
                robust_noise = gtsam.noiseModel.Robust.Create(self.robust, gaussian)
                factor = gtsam.BetweenFactorPose2(X(k), T(lid), measured, robust_noise)
            guess = seed.compose(measured)
        else:  # a tag seen without its yaw: bearing and range to its centre
            factor = gtsam.BearingRangeFactorPose2(X(k), T(lid), bearing, obs.range_m, used)
            gate_factor = factor
            if used is not noise:
                gate_factor = gtsam.BearingRangeFactorPose2(X(k), T(lid), bearing, obs.range_m, noise)
            # seed: the tag faces the camera
            guess = seed.compose(gtsam.Pose2(p_robot[0], p_robot[1], obs.bearing_rad + math.pi))
        return PendingObservation(lid, T(lid), k, factor, gate_factor, guess, seed)

    def range(self, k: int, seed: gtsam.Pose2, obs: Observation, guess: np.ndarray) -> PendingObservation:
        """``RangeFactor2D(X(k), L(id))`` for a range-only observation; ``guess`` seeds the landmark."""
        noise = self._noise_cache.get(("r", obs.sigma_range_m))
        if noise is None:
            noise = self._noise_cache[("r", obs.sigma_range_m)] = gtsam.noiseModel.Isotropic.Sigma(1, obs.sigma_range_m)
        factor = gtsam.RangeFactor2D(X(k), L(obs.landmark_id), obs.range_m, noise)
        return PendingObservation(obs.landmark_id, L(obs.landmark_id), k, factor, factor, guess, seed)

    def height(self, obs: Observation) -> gtsam.PriorFactorDouble:
        """``PriorFactorDouble(H(id), height, σ_h)`` for an observation with a height.

        A landmark's height is a scalar variable nothing else touches, so iSAM2 keeps it in
        a tree of its own and its estimate is the information-weighted mean of the heights
        measured (exactly the EKF's scalar filter, see ekf/slam.py).
        """
        noise = self._noise_cache.get(("h", obs.sigma_height_m))
        if noise is None:
            noise = self._noise_cache[("h", obs.sigma_height_m)] = gtsam.noiseModel.Isotropic.Sigma(
                1, obs.sigma_height_m
            )
        return gtsam.PriorFactorDouble(H(obs.landmark_id), float(obs.height_m), noise)


def update_batch(core: gtsam.NonlinearFactorGraph, core_values: gtsam.Values, entries: list[PendingObservation],
                 known_landmarks: set[int]) -> tuple[gtsam.NonlinearFactorGraph, gtsam.Values]:
    """The factors and new values of one iSAM2 update: ``core`` (prior, odometry, heights)
    and ``core_values`` (new poses, heights) plus the observation ``entries`` and a seed for
    each landmark not in ``known_landmarks``: the latest of its observations that took part
    in the fewest failed updates (a fresh observation beats a withheld one)."""
    factors = gtsam.NonlinearFactorGraph(core)
    add = factors.add
    for e in entries:
        add(e.factor)
    best: dict[int, PendingObservation] = {}
    for e in entries:
        if e.landmark_id in known_landmarks:
            continue
        if e.landmark_id not in best or e.attempts <= best[e.landmark_id].attempts:
            best[e.landmark_id] = e
    if not best:  # (most updates: no new landmark) the core's values, not a copy of them
        return factors, core_values
    values = gtsam.Values(core_values)
    for e in best.values():
        values.insert(e.key, e.landmark_guess)
    return factors, values
