"""Incremental smoothing with GTSAM's iSAM2, and the batch solve used as "smoothed ground truth".

The factor graph
----------------
* ``X(i)``  — robot pose *i* (``gtsam.Pose2``); pose 0 is the log header's start pose.
* ``L(id)`` — landmark ``id`` (``gtsam.Point2``, world frame).
* A ``PriorFactorPose2`` pins ``X(0)`` at ``header.start_pose`` with standard deviations
  ``header.start_sigma`` (world frame; see :func:`start_prior_covariance`).
* Each odometry record adds ``BetweenFactorPose2(X(k-1), X(k))`` with the logged increment
  and covariance (see :func:`odometry_noise_covariance` for the frame).
* Each observation with a known id adds ``BearingRangeFactor2D(X(k), L(id))``. GTSAM
  orders that measurement **bearing first, then range**, so its noise sigmas are
  ``[sigma_bearing_rad, sigma_range_m]``.
* ``T(id)`` — with ``tags=True``, a landmark whose first observation carries a tag yaw
  (seed 004's AprilTags) is a tag: a ``gtsam.Pose2`` (centre and the world direction its
  face points to). Each observation with a yaw adds ``BetweenFactorPose2(X(k), T(id))``
  with the measured relative pose (r·cos b, r·sin b, yaw) and the covariance propagated
  from (σ_r, σ_b, σ_yaw) (:func:`tag_noise_covariance`); one without a yaw adds
  ``BearingRangeFactorPose2`` to the tag's centre. Without ``tags`` yaws are unused.
* ``H(id)`` — a landmark's height (seed 002), a scalar, when observations carry one: each
  adds ``PriorFactorDouble(H(id), height, σ_h)``. Nothing else touches a height, so it is
  the information-weighted mean of the heights measured, as in the EKF.
* With ``robust="huber"`` or ``"cauchy"`` (see :class:`Isam2Smoother`) every landmark
  factor's noise model is ``noiseModel.Robust`` wrapping its Gaussian model; the prior,
  the odometry and the height factors stay Gaussian.

How :class:`Isam2Smoother` runs
-------------------------------
One ``ISAM2.update`` per step (by default; ``update_every`` and ``update_on`` can hold
steps and update less often) with that step's new factors and new variables. A new pose
is seeded from the *current iSAM2 estimate* of the previous pose composed with the
odometry increment (seeding from dead reckoning makes iSAM2 diverge on real data, see
DESIGN.md); a landmark seen for the first time is seeded from that seed pose and the
observation (in robust mode only once two observations agree, see
:meth:`Isam2Smoother._confirm_first_sightings`). After the update only the newest pose is
read back (``calculateEstimatePose2``); the full estimate is computed on demand.
:meth:`Isam2Smoother.finish` ends with full Gauss–Newton steps on the whole graph, so the
final estimate is the batch optimum whatever the settings (docs/performance.md) — to
first order with ``keyframes``, where the poses between keyframes are rebuilt
(:class:`_Chain`).

Everything accepted into iSAM2 is also kept in one ``NonlinearFactorGraph`` plus the
initial ``Values``, so :func:`batch_solve` can run Levenberg–Marquardt on the same
problem, started from iSAM2's answer (batch LM started from odometry gets stuck in a
local minimum on real data; started from iSAM2 it converges — DESIGN.md).

When an update fails
--------------------
GTSAM raises ``IndeterminantLinearSystemException`` (a ``RuntimeError`` in Python) when a
linear system it has to factor is singular — for example a landmark observed at a range
of practically zero, whose bearing says nothing about where it is. iSAM2 adds the new
variables and factors to its internal state *before* it factors, so an ``ISAM2`` object
that has thrown is left inconsistent and must not be used again. The smoother therefore:

1. counts the failure (``update_failures``, message in ``last_failure``);
2. withholds the update's observations of the landmark GTSAM names in the exception (or
   all of the update's observations when it names a pose or nothing);
3. rebuilds a fresh ``ISAM2`` from every factor accepted so far plus the rest of the
   update, seeded from the failed object's linearisation point (a plain copy of its
   values); if that fails too — relinearisation may itself have moved a variable to a
   degenerate place — from the initial values every variable entered with, and then
   without any of the update's observations. A rebuild costs one batch factorisation, so
   it is only for the rare failure; it is the only time a step runs more than one update;
4. keeps the withheld observations pending. A pending observation is retried only once
   it can be checked against something trustworthy: the current estimate of its landmark
   if the landmark is in the map, otherwise a fresh observation of that landmark (until
   then it waits — a landmark seen once tells nothing about the poses, so waiting costs
   the trajectory nothing). If it is more than about 7σ off
   (``½‖whitened residual‖² > PENDING_GATE``) it is dropped instead of retried: it was
   probably the cause, and accepting it would drag the whole map. An observation that
   has failed ``1 + max_retries`` updates is dropped too. Both count in
   ``dropped_observations``; observations still waiting at the end are in
   ``pending_observations``.

If the rebuild without any of the step's observations fails from both seeds, the odometry
or the prior itself is degenerate and :class:`~slamio.errors.FgslamError` is raised.
"""

from __future__ import annotations

import math
import re
import time
from dataclasses import dataclass

import gtsam
import numpy as np
from gtsam.symbol_shorthand import H, L, T, X

from ekf.models import range_bearing_nis
from ekf.range_only import DelayedInitRule, try_initialise
from ekf.slam import has_height  # the same rule as the EKF's for a usable height
from slamio.errors import FgslamError
from slamio.log import Header, Observation, Odometry, Step

__all__ = [
    "Isam2Smoother",
    "BatchResult",
    "batch_solve",
    "odometry_noise_covariance",
    "start_prior_covariance",
    "ROBUST_KERNELS",
    "DEFAULT_ROBUST_K",
    "robust_estimator",
    "FAST_SETTINGS",
]

#: The robust kernels :class:`Isam2Smoother` offers for landmark factors.
ROBUST_KERNELS = ("huber", "cauchy", "tukey", "dcs")

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
#:   :meth:`Isam2Smoother._confirm_first_sightings` it ended up to 5× the oracle's ATE.
DEFAULT_ROBUST_K = {
    "huber": 1.345,
    "cauchy": math.sqrt(-2.0 * math.log(0.001)),
    "tukey": 2.0 * math.sqrt(-2.0 * math.log(0.001)),
    "dcs": math.sqrt(-2.0 * math.log(0.001)),
}


#: The ``isam2-fast`` preset: settings tuned on Victoria Park (docs/performance.md), for long
#: runs and large maps where one update per step costs too much. Only steps with
#: observations become iSAM2 variables (keyframes; the odometry between them is folded into
#: one factor, and the poses in between are rebuilt on demand); steps are held and go to
#: iSAM2 in one update at the first step with observations once 50 are waiting; iSAM2
#: relinearises every 20th update, a variable whose step exceeds 1 m or 0.05 rad; the
#: online pose is read back with a loose wildfire threshold. ``finish()`` then runs full
#: Gauss–Newton steps. On Victoria Park the final χ²/2 of the whole graph is 0.08 % above
#: the batch optimum; the price is the online estimate between updates (dead-reckoned from
#: the last update), not the final one.
FAST_SETTINGS = {
    "keyframes": True,
    "relinearize_threshold": (1.0, 0.05),
    "relinearize_skip": 20,
    "update_every": 50,
    "update_on": "observations",
    "wildfire_threshold": 1.0,
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
    (a, b, c), (_, d, e), (_, _, f) = Q  # upper triangle
    cos, sin = math.cos(dtheta_rad), math.sin(dtheta_rad)
    # blockdiag(R(dθ)ᵀ, 1) · Q · blockdiag(R(dθ), 1), written out (this runs once per step)
    xx = cos * cos * a + 2.0 * cos * sin * b + sin * sin * d
    yy = sin * sin * a - 2.0 * cos * sin * b + cos * cos * d
    xy = cos * sin * (d - a) + (cos * cos - sin * sin) * b
    xt = cos * c + sin * e
    yt = -sin * c + cos * e
    return np.array([[xx, xy, xt], [xy, yy, yt], [xt, yt, f]])


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


@dataclass
class _PendingObservation:
    """An observation factor not (yet) accepted into iSAM2."""

    landmark_id: int
    key: int  # the landmark's variable: L(id) for a point, T(id) for a tag
    pose_index: int
    factor: gtsam.NonlinearFactor
    gate_factor: gtsam.NonlinearFactor  # the same with the plain Gaussian noise (for the gate)
    landmark_guess: np.ndarray | gtsam.Pose2  # the landmark implied by the observation and its seed pose
    seed_pose: gtsam.Pose2  # the robot pose the observation was made from, as seeded then
    attempts: int = 0  # failed updates it took part in


def _add_links(graph: gtsam.NonlinearFactorGraph, chain: "_Chain") -> None:
    """One ``BetweenFactorPose2`` per odometry link of ``chain``."""
    for j, (z, cov) in enumerate(chain.links):
        a = chain.start + j
        graph.add(gtsam.BetweenFactorPose2(X(a), X(a + 1), z, gtsam.noiseModel.Gaussian.Covariance(cov)))


class _Chain:
    """Odometry links folded into one compound factor (``Isam2Smoother(keyframes=True)``).

    Each link is an increment z_j with covariance Σ_j in GTSAM's convention (the error
    Log(z_j⁻¹ · T_{j−1}⁻¹ T_j) lives in the frame at the link's end). The compound
    z = z_1 ⋯ z_m carries Σ = Σ_j A_j Σ_j A_jᵀ with A_j = Ad((z_{j+1} ⋯ z_m)⁻¹), which moves
    link j's error to the frame at the chain's end: the first-order marginal of the poses
    in between, which only the chain constrains.
    """

    def __init__(self, start: int):
        self.start = start  # pose index the chain starts from (a keyframe)
        self.links: list[tuple[gtsam.Pose2, np.ndarray]] = []
        self.compound = gtsam.Pose2()
        self._cov = np.zeros((3, 3))

    def extended(self, increment: gtsam.Pose2, covariance: np.ndarray) -> tuple[gtsam.Pose2, np.ndarray]:
        """(compound, covariance) of this chain with one more link, the chain unchanged."""
        A = increment.inverse().AdjointMap()
        return self.compound.compose(increment), A @ self._cov @ A.T + covariance

    def append(self, increment: gtsam.Pose2, covariance: np.ndarray) -> None:
        self.compound, self._cov = self.extended(increment, covariance)
        self.links.append((increment, covariance))

    def covariance(self) -> np.ndarray:
        return 0.5 * (self._cov + self._cov.T)

    def dead_reckoned(self, start: gtsam.Pose2) -> np.ndarray:
        """(m, 3): the poses after ``start``, composed link by link."""
        out, pose = np.empty((len(self.links), 3)), start
        for j, (z, _) in enumerate(self.links):
            pose = pose.compose(z)
            out[j] = (pose.x(), pose.y(), pose.theta())
        return out

    def poses(self, start: gtsam.Pose2, end: gtsam.Pose2) -> np.ndarray:
        """(m − 1, 3): the interior poses, given the estimates of both ends.

        The chain's residual ξ = Log(z⁻¹ · start⁻¹ · end) is split over the links by least
        squares: ε_j = Σ_j A_jᵀ Σ⁻¹ ξ (the most probable link errors that add up to ξ), and
        pose i = start · z_1 Exp(ε_1) ⋯ z_i Exp(ε_i). With ε_j so chosen the links' cost
        Σ ε_jᵀ Σ_j⁻¹ ε_j equals ξᵀ Σ⁻¹ ξ, the compound factor's.
        """
        xi = gtsam.Pose2.Logmap(self.compound.between(start.between(end)))
        weight = np.linalg.solve(self.covariance(), xi)  # Σ⁻¹ ξ
        suffix = gtsam.Pose2()  # z_{j+1} ⋯ z_m, built from the end
        eps = [None] * len(self.links)
        for j in range(len(self.links) - 1, -1, -1):
            z, cov = self.links[j]
            A = suffix.inverse().AdjointMap()
            eps[j] = cov @ (A.T @ weight)
            suffix = z.compose(suffix)
        out, pose = np.empty((len(self.links) - 1, 3)), start
        for j in range(len(self.links) - 1):
            pose = pose.compose(self.links[j][0]).compose(gtsam.Pose2.Expmap(eps[j]))
            out[j] = (pose.x(), pose.y(), pose.theta())
        return out


_NEAR_VARIABLE = re.compile(r"near variable\s+(\d+)")


def _key_named_in(exc: BaseException) -> int | None:
    """The variable GTSAM's IndeterminantLinearSystemException names, if any."""
    match = _NEAR_VARIABLE.search(str(exc))
    return int(match.group(1)) if match else None


class Isam2Smoother:
    """Online landmark SLAM with iSAM2 (implements :class:`slamio.estimator.Estimator`).

    Parameters
    ----------
    header:
        The run log's header (start pose and its prior sigmas).
    relinearize_threshold:
        iSAM2 relinearises a variable when its pending update exceeds this (radians or
        metres, per component). Default 0.01 (GTSAM's own default is 0.1). A pair
        ``(metres, radians)`` sets the translation and rotation thresholds apart (GTSAM's
        per-variable-type threshold map; a landmark's height counts as metres).
    relinearize_skip:
        Check for relinearisation every this many updates. Default 10 (GTSAM's too).

        Why these defaults, measured: with 0.01 a desk-sized robot's centimetre errors
        still trigger relinearisation (GTSAM's 0.1 lost the online ATE on the bundled
        octagon log: 0.01105 vs the EKF's 0.01099 m). Checking every update instead of
        every 10th changed nothing measurable — arena-octagon seeds 1–20 gave identical
        ATEs, grid 200 (seed 1) online ATE 0.3082 vs 0.3083 m — but cost 2.2× the time on
        grid 200 (35 vs 15.6 s) and 2.7× on grid 500: each check can relinearise a large
        part of the map after a loop closure. Very aggressive settings are where DESIGN.md
        saw IndeterminantLinearSystem failures on real data; those are recovered from
        (module docstring).
    final_updates:
        Extra plain ``isam.update()`` calls (no new factors) at the start of
        :meth:`finish`, letting a pending relinearisation check happen. Cheap; the full
        Gauss–Newton steps of ``final_iterations`` that follow do the real work.
    max_retries:
        How many further updates a withheld observation is retried with before it is
        dropped (see the module docstring).
    update_every, update_on, max_held_steps:
        When steps go to iSAM2. By default every step runs one update. With
        ``update_every=K`` steps are held until K are waiting; with
        ``update_on="observations"`` only a step with observations triggers the update;
        ``max_held_steps`` bounds the wait. While steps are held, :meth:`current_pose` is
        the last iSAM2 estimate composed with the odometry since (a live robot's view).
        Measured effects are in docs/performance.md.
    final_iterations, final_tolerance:
        In :meth:`finish`, after ``final_updates``: up to this many Gauss–Newton steps on
        the whole graph, until the error drops by less than ``final_tolerance``
        (relative). Each is an update with ``force_relinearize`` and ``forceFullSolve``:
        iSAM2 then solves the exact delta and relinearises *every* variable (measured:
        without ``forceFullSolve`` only variables whose wildfire delta exceeds the
        threshold move, and on Victoria Park it stalled 34 % above the optimum). The final estimate is then read with
        ``calculateBestEstimate`` (a full back-substitution; ``calculateEstimate`` skips
        changes below the wildfire threshold).
    partial_relinearization_check, cache_linearized_factors, factorization, wildfire_threshold:
        Passed to GTSAM's ``ISAM2Params`` (``factorization`` is "cholesky" or "qr").
    robust:
        ``None`` (default): every factor is Gaussian (least squares). ``"huber"``,
        ``"cauchy"``, ``"tukey"`` or ``"dcs"``: landmark factors get that robust kernel through
        ``gtsam.noiseModel.Robust`` around their diagonal noise, so observations far
        from the rest (misdetections with a valid id) lose their pull; odometry and the
        prior stay Gaussian. The graph kept for :func:`batch_solve` holds the same robust
        factors, so the batch solve is robust too, and :meth:`error` is the robust cost.
        ``name`` becomes ``"isam2-huber"``, ``"isam2-cauchy"``, ``"isam2-tukey"`` or ``"isam2-dcs"``.
    robust_k:
        The kernel width in whitened units (σ of the 2-D residual norm); None takes
        :data:`DEFAULT_ROBUST_K` (Huber 1.345, Cauchy 3.72, Tukey 7.43, DCS 3.72; why
        there). Only with ``robust``.

        A robust kernel cannot repair a landmark *seeded* from a misdetection, so in
        robust mode a landmark enters the map only once two of its observations agree
        (:meth:`_confirm_first_sightings`). Measured on arena-octagon seeds 1–10 with 10 %
        outliers, ATE relative to iSAM2 on the log with exactly the outliers removed (an
        oracle; the simulator *replaces* observations, so the outlier-free log has 10 %
        more information and even the oracle is up to 1.4× its ATE): DCS max 1.06×, mean
        1.01×; Cauchy max 1.10×, mean 0.99×; Tukey max 1.07×, mean 0.99×; Huber max 1.32×,
        mean 1.05× (Huber never stops pulling). Without the first-sighting check: Cauchy
        1.08×, Huber 3.3×, Tukey 5.3× at worst. Use DCS: on the 200-landmark grid the
        others move the map even on a clean log (docs/performance.md has the tables).

    tags:
        ``False`` (default): every landmark is a point, as in the EKF. ``True``: a landmark
        whose first observation carries a tag yaw is a ``Pose2`` tag observed through
        relative-pose factors (module docstring), so its facing direction is estimated
        too (:meth:`landmark_yaws`), and the yaw also constrains the robot's heading.
        ``name`` becomes ``"isam2-tags"``.

    Attributes
    ----------
    skipped_unknown_observations:
        Observations ignored because their ``landmark_id`` was None.
    update_failures:
        Steps whose iSAM2 update raised (each recovered from by a rebuild).
    dropped_observations:
        Observations withheld after a failed update and then abandoned (gated out, or
        failed ``1 + max_retries`` times).
    last_failure:
        The message of the most recent failed update, or None.
    pending_observations:
        Observations withheld after a failed update and not yet retried or dropped.
    rejected_first_sightings:
        Robust mode only: observations of a landmark not yet in the map that no later
        observation agreed with (see :meth:`_confirm_first_sightings`); dropped.
    """

    name = "isam2"

    #: A pending observation whose ½‖whitened residual‖² at the current estimate exceeds
    #: this (≈ 7σ in one component) is dropped instead of retried.
    PENDING_GATE = 25.0

    #: Robust mode: first sightings of a landmark kept waiting for one that agrees.
    MAX_UNCONFIRMED = 10

    def __init__(
        self,
        header: Header,
        *,
        relinearize_threshold: float | tuple[float, float] = 0.01,
        relinearize_skip: int = 10,
        update_every: int = 1,
        update_on: str = "any",
        max_held_steps: int = 50,
        final_updates: int = 2,
        final_iterations: int = 10,
        final_tolerance: float = 1e-4,
        partial_relinearization_check: bool = False,
        cache_linearized_factors: bool = True,
        factorization: str = "cholesky",
        wildfire_threshold: float = 0.001,
        max_retries: int = 3,
        robust: str | None = None,
        robust_k: float | None = None,
        tags: bool = False,
        keyframes: bool = False,
        max_keyframe_gap: int = 50,
    ):
        threshold = _relinearize_threshold(relinearize_threshold)
        if relinearize_skip < 1 or final_updates < 0 or max_retries < 0:
            raise FgslamError(
                "Isam2Smoother: need relinearize_skip >= 1, final_updates >= 0 and max_retries >= 0"
            )
        if update_every < 1 or max_held_steps < 1 or final_iterations < 0 or not final_tolerance >= 0:
            raise FgslamError(
                "Isam2Smoother: need update_every >= 1, max_held_steps >= 1, final_iterations >= 0 "
                "and final_tolerance >= 0"
            )
        if update_on not in ("any", "observations"):
            raise FgslamError(f"Isam2Smoother: update_on must be 'any' or 'observations', got {update_on!r}")
        if factorization.lower() not in ("cholesky", "qr"):
            raise FgslamError(f"Isam2Smoother: factorization must be 'cholesky' or 'qr', got {factorization!r}")
        if not wildfire_threshold >= 0:
            raise FgslamError("Isam2Smoother: wildfire_threshold must be >= 0")
        self.update_every = int(update_every)
        self.update_on = update_on
        self.max_held_steps = int(max_held_steps)
        self.final_iterations = int(final_iterations)
        self.final_tolerance = float(final_tolerance)
        self.partial_relinearization_check = bool(partial_relinearization_check)
        self.cache_linearized_factors = bool(cache_linearized_factors)
        self.factorization = factorization.lower()
        self.wildfire_threshold = float(wildfire_threshold)
        self.updates = 0  # iSAM2 updates run by step()/flushes (not counting finish or rebuilds)
        self.final_iterations_run = 0  # forced full relinearisations finish() ran
        if robust is None:
            if robust_k is not None:
                raise FgslamError("Isam2Smoother: robust_k needs a robust kernel (robust='huber' or 'cauchy')")
            self._robust = None
        else:
            self._robust = robust_estimator(robust, robust_k)
        self.tags = bool(tags)
        if max_keyframe_gap < 1:
            raise FgslamError("Isam2Smoother: need max_keyframe_gap >= 1")
        self.keyframes = bool(keyframes)
        self.max_keyframe_gap = int(max_keyframe_gap)
        self.name = "-".join(["isam2"] + (["tags"] if self.tags else []) + ([robust] if robust else []))
        self.robust = robust
        self.robust_k = None if robust is None else (DEFAULT_ROBUST_K[robust] if robust_k is None else float(robust_k))
        self.header = header
        self.relinearize_threshold = threshold
        self.relinearize_skip = int(relinearize_skip)
        self.final_updates = int(final_updates)
        self.max_retries = int(max_retries)

        self.skipped_unknown_observations = 0
        self.update_failures = 0
        self.dropped_observations = 0
        self.last_failure: str | None = None

        self._isam = gtsam.ISAM2(self._params())
        self._graph = gtsam.NonlinearFactorGraph()  # every factor accepted into iSAM2
        self._initial = gtsam.Values()  # the initial guess of every variable in iSAM2
        self._landmark_ids: list[int] = []  # landmarks in iSAM2, in order of entry
        self._known_landmarks: set[int] = set()
        self._tag_ids: set[int] = set()  # landmarks in iSAM2 that are tags (Pose2 T(id))
        self._is_tag_landmark: dict[int, bool] = {}  # every landmark seen: tag or point (first sight decides)
        self._height_ids: set[int] = set()  # landmarks with a height variable H(id) (in iSAM2 or held)
        self._pending: list[_PendingObservation] = []
        self._unconfirmed: dict[int, list[_PendingObservation]] = {}  # robust: first sightings waiting
        self.rejected_first_sightings = 0
        self._num_poses = 0
        self._pose: gtsam.Pose2 | None = None  # latest pose: iSAM2's after an update, else ⊕ odometry
        self._estimate_cache: gtsam.Values | None = None
        self._noise_cache: dict = {}  # noise models shared between records (see _odometry_noise)
        # Steps taken but not yet given to iSAM2: their odometry/prior factors, pose seeds
        # and observation entries, run in one update later (see update_every / update_on).
        self._held_core = gtsam.NonlinearFactorGraph()
        self._held_values = gtsam.Values()
        self._held_entries: list[_PendingObservation] = []
        self._held_ranges: list[_PendingObservation] = []  # range factors of initialised landmarks
        # range-only landmarks (see ekf.range_only): buffered ranges until they pin the landmark
        # down, then every one becomes a RangeFactor2D with the trilateration as the seed
        self.range_rule = DelayedInitRule()
        self._range_buffer: dict[int, list[tuple[int, gtsam.Pose2, Observation]]] = {}
        self._range_seed: dict[int, np.ndarray] = {}  # initialised range-only landmark → trilateration
        self._held_steps = 0
        self._held_observed = False
        # Keyframes (see ``keyframes``): pose indices with a variable X(k), the odometry
        # chain folded into each keyframe's compound factor, and the open chain since the
        # last keyframe.
        self._key_indices: list[int] = []
        self._chains: dict[int, _Chain] = {}  # keyframe b → the chain from the keyframe before
        self._open = _Chain(0)
        # odometry records since the newest pose in iSAM2 (X(_since_isam_start)), for the
        # online covariance; kept raw, so a step costs one list append
        self._since_isam_start = 0
        self._since_isam: list[tuple[gtsam.Pose2, Odometry]] = []
        # current_covariance() is asked at every step (NEES): the marginal is kept until
        # iSAM2 changes, and the held odometry is propagated only once per record
        self._marginal: np.ndarray | None = None
        self._since_chain = _Chain(0)

    # ------------------------------------------------------------------ Estimator protocol

    def step(self, step: Step) -> None:
        """Add pose ``step.index`` (and its observations); run an iSAM2 update when one is due.

        With ``update_every`` > 1 or ``update_on="observations"`` the step may be held: its
        factors wait for the next update, and :meth:`current_pose` is the last iSAM2
        estimate composed with the odometry since (what a live robot would act on).
        """
        k = step.index
        if k != self._num_poses:
            raise FgslamError(f"Isam2Smoother: expected step {self._num_poses}, got step {k}; feed steps in order")
        if k == 0:
            if step.odometry is not None:
                raise FgslamError("Isam2Smoother: step 0 is the start pose and cannot have odometry")
            seed = gtsam.Pose2(*self.header.start_pose)
            prior_noise = gtsam.noiseModel.Gaussian.Covariance(start_prior_covariance(self.header))
            self._held_core.add(gtsam.PriorFactorPose2(X(0), seed, prior_noise))
        else:
            odo = step.odometry
            if odo is None:
                raise FgslamError(f"Isam2Smoother: step {k} has no odometry; every step after 0 starts with one")
            increment = gtsam.Pose2(odo.dx_m, odo.dy_m, odo.dtheta_rad)
            assert self._pose is not None
            # latest iSAM2 estimate ⊕ the increments since, not dead reckoning from the start
            seed = self._pose.compose(increment)
            self._since_isam.append((increment, odo))
            if self.keyframes:
                self._open.append(increment, odometry_noise_covariance(odo))
                observed = any(o.landmark_id is not None for o in step.observations)
                if observed or len(self._open.links) >= self.max_keyframe_gap:
                    # a keyframe: the chain since the last one becomes one compound factor
                    chain, self._open = self._open, _Chain(k)
                    self._chains[k] = chain
                    noise = gtsam.noiseModel.Gaussian.Covariance(chain.covariance())
                    self._held_core.add(gtsam.BetweenFactorPose2(X(chain.start), X(k), chain.compound, noise))
            else:
                self._held_core.add(gtsam.BetweenFactorPose2(X(k - 1), X(k), increment, self._odometry_noise(odo)))
        if not self._open.links:  # a variable of its own (always, without keyframes)
            self._held_values.insert(X(k), seed)
            self._key_indices.append(k)
            self._add_observations(k, seed, step.observations)
        else:  # folded into the open chain; it saw no landmark id
            self.skipped_unknown_observations += len(step.observations)
        self._held_steps += 1
        self._num_poses = k + 1
        self._pose = seed
        if self._due(k):
            self._flush()

    def _add_observations(self, k: int, seed: gtsam.Pose2, observations) -> None:
        """Hold the factors of pose ``k``'s observations (and their heights)."""
        for obs in observations:
            if obs.landmark_id is None:
                self.skipped_unknown_observations += 1
                continue
            if obs.range_only:
                self._add_range(k, seed, obs)
                self._held_observed = True
                continue
            if has_height(obs):
                self._add_height(obs)
            self._held_entries.append(self._observation_entry(k, seed, obs))
            self._held_observed = True

    def _range_entry(self, k: int, seed: gtsam.Pose2, obs: Observation, guess: np.ndarray) -> _PendingObservation:
        noise = self._noise_cache.get(("r", obs.sigma_range_m))
        if noise is None:
            noise = self._noise_cache[("r", obs.sigma_range_m)] = gtsam.noiseModel.Isotropic.Sigma(1, obs.sigma_range_m)
        factor = gtsam.RangeFactor2D(X(k), L(obs.landmark_id), obs.range_m, noise)
        return _PendingObservation(obs.landmark_id, L(obs.landmark_id), k, factor, factor, guess, seed)

    def _add_range(self, k: int, seed: gtsam.Pose2, obs: Observation) -> None:
        """A range-only observation: a ``RangeFactor2D`` once its landmark is placed;
        before that it is buffered until :func:`ekf.range_only.try_initialise` (the EKF's
        rule, on the robot positions estimated online at each range) places the landmark,
        and then all buffered ranges become factors, seeded at the trilateration."""
        lid = obs.landmark_id
        self._is_tag_landmark.setdefault(lid, False)
        if lid in self._range_seed:
            self._held_ranges.append(self._range_entry(k, seed, obs, self._range_seed[lid]))
            return
        buffer = self._range_buffer.setdefault(lid, [])
        buffer.append((k, seed, obs))
        del buffer[: -self.range_rule.max_buffer]
        positions = np.array([[pose.x(), pose.y()] for _, pose, _ in buffer])
        ranges = np.array([o.range_m for _, _, o in buffer])
        sigmas = np.array([o.sigma_range_m for _, _, o in buffer])
        fit = try_initialise(positions, ranges, sigmas, self.range_rule)
        if fit is None:
            return
        for j, pose, o in buffer:
            self._held_ranges.append(self._range_entry(j, pose, o, fit.xy))
        del self._range_buffer[lid]
        self._range_seed[lid] = fit.xy

    def _folded_chain(self, factor) -> "_Chain | None":
        """The chain a compound odometry factor of iSAM2's graph stands for (None otherwise)."""
        if not isinstance(factor, gtsam.BetweenFactorPose2):
            return None
        a, b = (gtsam.Symbol(key) for key in factor.keys())
        if chr(a.chr()) != "x" or chr(b.chr()) != "x":
            return None
        chain = self._chains.get(int(b.index()))
        if chain is None or chain.start != int(a.index()) or len(chain.links) < 2:
            return None
        return chain

    def _insert_open_chain(self, values: gtsam.Values) -> None:
        """Add the poses after the last keyframe: its value ⊕ the odometry since."""
        if self._open.links:
            last = self._key_indices[-1]
            for j, pose in enumerate(self._open.dead_reckoned(values.atPose2(X(last)))):
                values.insert(X(last + 1 + j), gtsam.Pose2(*pose))

    def _latest_pose(self, last_key_pose: gtsam.Pose2) -> gtsam.Pose2:
        """The newest pose from its keyframe's estimate (⊕ the open chain, with keyframes)."""
        return last_key_pose.compose(self._open.compound) if self._open.links else last_key_pose

    def _due(self, k: int) -> bool:
        """Whether the held steps go to iSAM2 now (see ``update_every`` / ``update_on``)."""
        if k == 0 or self._held_steps >= self.max_held_steps:
            return True
        if self._held_steps < self.update_every:
            return False
        return self.update_on == "any" or self._held_observed

    def _flush(self) -> None:
        """Give every held step to iSAM2 in one update; read back the newest pose."""
        if self._held_steps == 0:
            return
        core, core_values, fresh = self._held_core, self._held_values, self._held_entries
        self._held_core, self._held_values, self._held_entries = gtsam.NonlinearFactorGraph(), gtsam.Values(), []
        ranges, self._held_ranges = self._held_ranges, []
        self._held_steps, self._held_observed = 0, False
        fresh = self._confirm_first_sightings(fresh)
        entries = self._screen_pending(fresh) + fresh + ranges
        self._update_with_recovery(core, core_values, entries)
        self.updates += 1
        self._pose = self._latest_pose(self._isam.calculateEstimatePose2(X(self._key_indices[-1])))
        # the newest pose in iSAM2 is the last keyframe; only the open chain's steps follow it
        self._since_isam_start = self._key_indices[-1]
        self._since_isam = self._since_isam[len(self._since_isam) - len(self._open.links) :] if self._open.links else []
        self._since_chain = _Chain(self._since_isam_start)
        self._marginal = None

    def current_pose(self) -> tuple[float, float, float]:
        """The online estimate of the latest pose (x_m, y_m, theta_rad).

        iSAM2's estimate when the latest step ran an update; otherwise the last iSAM2
        estimate composed with the odometry of the steps held since.
        """
        if self._pose is None:
            raise FgslamError("Isam2Smoother: no step yet")
        return (self._pose.x(), self._pose.y(), self._pose.theta())

    def finish(self) -> None:
        """Flush held steps, then refine: ``final_updates`` plain updates, then up to
        ``final_iterations`` Gauss–Newton steps on the whole graph until the error's
        relative decrease is below ``final_tolerance``."""
        if self._num_poses == 0:
            return
        self._flush()
        self._estimate_cache = None
        self._marginal = None  # the final updates below change iSAM2
        for _ in range(self.final_updates):
            try:
                self._isam.update()
            except RuntimeError as exc:  # relinearisation hit a singular system: rebuild
                self._recover(exc, gtsam.NonlinearFactorGraph(), gtsam.Values(), [])
        if self.final_iterations:
            previous = float(self._graph.error(self._isam.calculateBestEstimate()))
            for _ in range(self.final_iterations):
                # One Gauss–Newton step on the whole graph: with forceFullSolve the forced
                # relinearisation takes the exact delta and relinearises every variable.
                update_params = gtsam.ISAM2UpdateParams()
                update_params.force_relinearize = True
                update_params.forceFullSolve = True
                try:
                    self._isam.update(gtsam.NonlinearFactorGraph(), gtsam.Values(), update_params)
                except RuntimeError as exc:
                    self._recover(exc, gtsam.NonlinearFactorGraph(), gtsam.Values(), [])
                    break
                self.final_iterations_run += 1
                current = float(self._graph.error(self._isam.calculateBestEstimate()))
                if not previous - current > self.final_tolerance * current:
                    break
                previous = current
        # The full back-substitution: calculateEstimate() skips delta changes below the
        # wildfire threshold, which on Victoria Park left χ²/2 25 % above the optimum.
        self._estimate_cache = self._isam.calculateBestEstimate()
        self._pose = self._latest_pose(self._estimate_cache.atPose2(X(self._key_indices[-1])))

    def trajectory(self) -> np.ndarray:
        """(n, 3) array of every pose (x_m, y_m, theta_rad) as estimated now."""
        return self.trajectory_of(self._estimate())

    def trajectory_of(self, values: gtsam.Values) -> np.ndarray:
        """(n, 3) array of every pose for the keyframe (or all-pose) estimate ``values``.

        Without keyframes, the poses in ``values``. With them, each pose between two
        keyframes a and b is rebuilt from the odometry folded into their compound factor
        and its least-squares share of that factor's residual (:meth:`_Chain.poses`); poses
        after the last keyframe are its estimate ⊕ the odometry since (nothing else
        constrains them).
        """
        if not self.keyframes:
            return _poses_of(values, self._num_poses)
        out = np.empty((self._num_poses, 3))
        for k in self._key_indices:
            p = values.atPose2(X(k))
            out[k] = (p.x(), p.y(), p.theta())
        for b, chain in self._chains.items():
            if len(chain.links) > 1:
                start, end = values.atPose2(X(chain.start)), values.atPose2(X(b))
                out[chain.start + 1 : b] = chain.poses(start, end)
        if self._open.links:
            last = self._key_indices[-1]
            out[last + 1 :] = self._open.dead_reckoned(values.atPose2(X(last)))
        return out

    def landmarks(self) -> dict[int, tuple[float, float]]:
        """Landmark id → estimated world (x_m, y_m), for landmarks accepted into iSAM2
        (a tag's position is its centre)."""
        return _landmarks_of(self._estimate(), self._landmark_ids, self._tag_ids)

    def landmark_yaws(self) -> dict[int, float]:
        """Tag id → estimated world direction its face points to (rad); tags only (``tags=True``)."""
        return _yaws_of(self._estimate(), self._tag_ids)

    def landmark_heights(self) -> dict[int, float]:
        """Landmark id → estimated height (m), for landmarks observed with a height."""
        return _heights_of(self._estimate(), self._height_ids)

    # ------------------------------------------------------------------ extras

    @property
    def num_poses(self) -> int:
        return self._num_poses

    def current_covariance(self, frame: str = "world") -> np.ndarray:
        """3×3 covariance of :meth:`current_pose`, the online estimate.

        iSAM2's marginal of the newest pose it holds (``isam.marginalCovariance``, which
        uses the Bayes tree and does not recompute the whole graph's marginals), carried
        through the odometry of any steps held since (first order: Σ ← Ad(z⁻¹) Σ Ad(z⁻¹)ᵀ + Σ_z
        per increment z), so asking does not change when iSAM2 updates. GTSAM expresses a
        Pose2's uncertainty in the robot's own frame (a perturbation ``pose ⊕ δ``). With
        ``frame="world"`` (the default) it is rotated into world (x, y, theta) coordinates,
        the same coordinates as the EKF's covariance and as a world-frame pose error, which
        is what NEES needs; ``frame="body"`` returns GTSAM's own.
        """
        if self._num_poses == 0:
            raise FgslamError("Isam2Smoother: no step yet")
        if frame not in ("world", "body"):
            raise FgslamError(f"current_covariance: frame must be 'world' or 'body', got {frame!r}")
        chain = self._caught_up_since_chain()
        if self._marginal is None:
            self._marginal = np.asarray(self._isam.marginalCovariance(X(chain.start)), dtype=float)
        cov = self._marginal
        if chain.links:
            A = chain.compound.inverse().AdjointMap()
            cov = A @ cov @ A.T + chain.covariance()
        if frame == "world":
            J = _body_to_world(self._pose.theta())
            cov = J @ cov @ J.T
        return 0.5 * (cov + cov.T)

    def _caught_up_since_chain(self) -> "_Chain":
        """The odometry since the newest iSAM2 pose, with the records held since the last call."""
        chain = self._since_chain
        for increment, odo in self._since_isam[len(chain.links) :]:
            chain.append(increment, odometry_noise_covariance(odo))
        return chain

    def landmark_covariances(self) -> dict[int, np.ndarray]:
        """Landmark id → 2×2 marginal covariance of its (x, y) in the world frame
        (``isam.marginalCovariance``; for a tag, the position block of its Pose2 marginal
        rotated from the tag's frame). Flushes held steps."""
        self._flush()
        out = {}
        for lid in self._landmark_ids:
            if lid in self._tag_ids:
                cov = np.asarray(self._isam.marginalCovariance(T(lid)), dtype=float)[:2, :2]
                th = self._isam.calculateEstimatePose2(T(lid)).theta()
                c, s = math.cos(th), math.sin(th)
                rot = np.array([[c, -s], [s, c]])
                out[lid] = rot @ cov @ rot.T
            else:
                out[lid] = np.asarray(self._isam.marginalCovariance(L(lid)), dtype=float)
        return out

    def predicted_nis(self, step: Step) -> list[float | None]:
        """NIS of each observation of ``step`` against the smoother's prediction, before
        the step is added (nothing is changed; call it before :meth:`step`).

        The same question the EKF answers (:meth:`ekf.EkfSlam.predicted_nis`): the joint
        marginal of the newest iSAM2 pose and the observed landmarks
        (``isam.jointMarginalCovariance``), the pose carried through the odometry held since
        and this step's (Σ ← A Σ Aᵀ + Σ_z, cross-covariance ← A Σ_pl, A = Ad(z⁻¹)), rotated
        into world (x, y, θ), then :func:`ekf.models.range_bearing_nis`. None for an
        observation without an id, of a landmark iSAM2 does not hold yet, or of a tag, and
        for every observation of the step when iSAM2 cannot form the marginal (an
        indeterminate system, which real data with gross outliers can produce).
        """
        out: list[float | None] = [None] * len(step.observations)
        if self._pose is None or step.odometry is None:
            return out
        wanted = [
            (j, o) for j, o in enumerate(step.observations)
            if o.landmark_id is not None and not o.range_only and o.landmark_id not in self._tag_ids
            and self._isam.valueExists(L(o.landmark_id))
        ]
        if not wanted:
            return out
        chain = self._caught_up_since_chain()
        odo = step.odometry
        increment = gtsam.Pose2(odo.dx_m, odo.dy_m, odo.dtheta_rad)
        compound, moved_cov = chain.extended(increment, odometry_noise_covariance(odo))
        A = compound.inverse().AdjointMap()
        pose = self._pose.compose(increment)
        to_world = _body_to_world(pose.theta())  # body → world at the new pose
        J = to_world @ A  # perturbation of the newest iSAM2 pose → world perturbation of the new pose
        x_key = X(chain.start)
        ids = list(dict.fromkeys(o.landmark_id for _, o in wanted))
        try:
            joint = self._isam.jointMarginalCovariance(gtsam.KeyVector([x_key] + [L(i) for i in ids]))
        except RuntimeError:  # gtsam.IndeterminateSystemException: no marginal, so no NIS
            return out
        pose_cov = J @ joint.at(x_key, x_key) @ J.T + to_world @ moved_cov @ to_world.T
        mean = np.array([pose.x(), pose.y(), pose.theta()])
        for j, o in wanted:
            key = L(o.landmark_id)
            cov = np.empty((5, 5))
            cov[:3, :3] = pose_cov
            cov[:3, 3:] = J @ joint.at(x_key, key)
            cov[3:, :3] = cov[:3, 3:].T
            cov[3:, 3:] = joint.at(key, key)
            landmark = self._isam.calculateEstimatePoint2(key)
            out[j] = range_bearing_nis(
                mean, landmark, cov, o.range_m, o.bearing_rad, np.diag([o.sigma_range_m**2, o.sigma_bearing_rad**2])
            )
        return out

    def graph(self) -> gtsam.NonlinearFactorGraph:
        """The whole problem: every factor accepted into iSAM2 (pending observations
        excluded), with a variable for every pose.

        Held steps are given to iSAM2 first, so the graph covers every step taken. With
        keyframes, each compound odometry factor iSAM2 holds is expanded back into its
        per-step factors, so this is the same graph as without keyframes."""
        self._flush()
        if not self.keyframes:
            return gtsam.NonlinearFactorGraph(self._graph)
        out = gtsam.NonlinearFactorGraph()
        for i in range(self._graph.size()):
            factor = self._graph.at(i)
            chain = self._folded_chain(factor)
            if chain is None:
                out.add(factor)
                continue
            _add_links(out, chain)
        _add_links(out, self._open)  # the steps after the last keyframe (not in iSAM2 yet)
        return out

    def initial_values(self) -> gtsam.Values:
        """A copy of the initial guess of every variable of :meth:`graph` (held steps flushed
        first; with keyframes, poses between keyframes dead-reckoned from the keyframe's)."""
        self._flush()
        values = gtsam.Values(self._initial)
        if self.keyframes:
            for b, chain in self._chains.items():
                for j, pose in enumerate(chain.dead_reckoned(values.atPose2(X(chain.start)))[:-1]):
                    values.insert(X(chain.start + 1 + j), gtsam.Pose2(*pose))
            self._insert_open_chain(values)
        return values

    def estimate(self) -> gtsam.Values:
        """A copy of iSAM2's current estimate of every variable of :meth:`graph` (one
        ``calculateEstimate``; with keyframes, the poses between them as in :meth:`trajectory`)."""
        values = gtsam.Values(self._estimate())
        if self.keyframes:
            trajectory = self.trajectory_of(values)
            keyframes = set(self._key_indices)
            for i in range(self._num_poses):
                if i not in keyframes:
                    values.insert(X(i), gtsam.Pose2(*trajectory[i]))
        return values

    def error(self) -> float:
        """:meth:`graph`'s error at :meth:`estimate` (χ²/2, like ``graph.error``)."""
        if self.keyframes:
            return float(self.graph().error(self.estimate()))
        return float(self._graph.error(self._estimate()))

    @property
    def pending_observations(self) -> int:
        """Observations withheld after a failed update, still to be retried."""
        return len(self._pending)

    @property
    def unconfirmed_observations(self) -> int:
        """Robust mode: first sightings of landmarks still waiting for a second that agrees."""
        return sum(len(q) for q in self._unconfirmed.values())

    # ------------------------------------------------------------------ internals

    def _params(self) -> gtsam.ISAM2Params:
        params = gtsam.ISAM2Params()
        if isinstance(self.relinearize_threshold, tuple):
            metres, radians = self.relinearize_threshold
            per_type = gtsam.ISAM2ThresholdMap()
            per_type.insert(("x", np.array([metres, metres, radians])))  # Pose2 tangent: x, y, theta
            per_type.insert(("l", np.array([metres, metres])))
            per_type.insert(("t", np.array([metres, metres, radians])))
            per_type.insert(("h", np.array([metres])))
            params.setRelinearizeThreshold(per_type)
        else:
            params.setRelinearizeThreshold(self.relinearize_threshold)
        params.relinearizeSkip = self.relinearize_skip
        params.enablePartialRelinearizationCheck = self.partial_relinearization_check
        params.cacheLinearizedFactors = self.cache_linearized_factors
        params.setFactorization("QR" if self.factorization == "qr" else "CHOLESKY")
        gauss_newton = gtsam.ISAM2GaussNewtonParams()
        gauss_newton.setWildfireThreshold(self.wildfire_threshold)
        params.setOptimizationParams(gauss_newton)
        return params

    def _estimate(self) -> gtsam.Values:
        self._flush()
        if self._estimate_cache is None:
            self._estimate_cache = self._isam.calculateEstimate()
        return self._estimate_cache

    def _confirm_first_sightings(self, fresh: list[_PendingObservation]) -> list[_PendingObservation]:
        """With a robust kernel, a new landmark enters the map only once two of its
        observations agree; returns the observations to use now.

        A robust kernel cannot repair a landmark *seeded* from a misdetection: its good
        observations then all look like outliers and are down-weighted (Cauchy leaves it
        stuck there). So the observations of a landmark not yet in the map wait. Each new
        one is checked against those waiting (its gate factor at its own seed pose and the
        waiting observation's landmark guess, ½‖whitened residual‖² ≤ ``PENDING_GATE``);
        at the first agreement both enter, seeded from the newer, and the rest that waited
        are gated against the landmark's estimate like withheld observations (kept when
        they fit, dropped when not). Nothing good is thrown away on the way: dropping a
        good first sighting made from the precisely known start pose doubled the ATE of
        an arena run. A landmark seen once tells nothing about the poses, so the wait
        costs the trajectory nothing. At most ``MAX_UNCONFIRMED`` observations wait per
        landmark; older ones are dropped (``rejected_first_sightings``).
        """
        if self._robust is None:
            return fresh
        accepted: list[_PendingObservation] = []
        confirmed_now: set[int] = set()
        for e in fresh:
            if e.landmark_id in self._known_landmarks:
                accepted.append(e)
                continue
            if e.landmark_id in confirmed_now:  # entering in this update: gate it, do not seed from it
                self._pending.append(e)
                continue
            waiting = self._unconfirmed.setdefault(e.landmark_id, [])
            match = next((w for w in reversed(waiting) if self._agree(w, e)), None)
            if match is None:
                waiting.append(e)
                if len(waiting) > self.MAX_UNCONFIRMED:
                    waiting.pop(0)
                    self.rejected_first_sightings += 1
                continue
            accepted += [match, e]
            self._pending += [w for w in waiting if w is not match]  # gated at the next screening
            del self._unconfirmed[e.landmark_id]
            confirmed_now.add(e.landmark_id)
        return accepted

    def _agree(self, earlier: _PendingObservation, later: _PendingObservation) -> bool:
        values = gtsam.Values()
        values.insert(X(later.pose_index), later.seed_pose)
        values.insert(later.key, earlier.landmark_guess)
        error = later.gate_factor.error(values)
        return math.isfinite(error) and error <= self.PENDING_GATE

    def _screen_pending(self, fresh: list[_PendingObservation]) -> list[_PendingObservation]:
        """The pending observations to retry in this update; others wait or are dropped."""
        retry, wait = [], []
        for e in self._pending:
            if e.attempts > self.max_retries:
                self.dropped_observations += 1
                continue
            if e.landmark_id in self._known_landmarks:
                if e.landmark_id in self._tag_ids:
                    landmark = self._isam.calculateEstimatePose2(T(e.landmark_id))
                else:
                    landmark = self._isam.calculateEstimatePoint2(L(e.landmark_id))
            else:
                seen_now = [o for o in fresh if o.landmark_id == e.landmark_id]
                if not seen_now:  # nothing trustworthy to check it against yet
                    wait.append(e)
                    continue
                landmark = seen_now[-1].landmark_guess
            values = gtsam.Values()
            pose_key = X(e.pose_index)  # a pose held in this very batch is not in iSAM2 yet
            pose = self._isam.calculateEstimatePose2(pose_key) if self._isam.valueExists(pose_key) else e.seed_pose
            values.insert(pose_key, pose)
            values.insert(e.key, landmark)
            error = e.gate_factor.error(values)
            if math.isfinite(error) and error <= self.PENDING_GATE:
                retry.append(e)
            else:
                self.dropped_observations += 1
        self._pending = wait
        return retry

    def _odometry_noise(self, odo: Odometry):
        """The odometry factor's noise model (see :func:`odometry_noise_covariance`).

        When the rotation there changes nothing (isotropic translation, no x/y–theta
        correlation) records with equal covariances share one model: logs usually repeat
        a handful of covariances, and building a model is a third of a step's Python cost.
        """
        Q = odo.covariance
        shareable = Q[0][0] == Q[1][1] and Q[0][1] == 0 and Q[0][2] == 0 and Q[1][2] == 0
        noise = self._noise_cache.get(Q) if shareable else None
        if noise is None:
            noise = gtsam.noiseModel.Gaussian.Covariance(odometry_noise_covariance(odo))
            if shareable and len(self._noise_cache) < 10_000:
                self._noise_cache[Q] = noise
        return noise

    def _observation_noise(self, obs: Observation):
        """(Gaussian, as-used) noise models for an observation's bearing-range factor."""
        key = (obs.sigma_bearing_rad, obs.sigma_range_m)
        models = self._noise_cache.get(key)
        if models is None:
            noise = gtsam.noiseModel.Diagonal.Sigmas(np.array([obs.sigma_bearing_rad, obs.sigma_range_m]))
            used = noise if self._robust is None else gtsam.noiseModel.Robust.Create(self._robust, noise)
            models = (noise, used)
            if len(self._noise_cache) < 10_000:
                self._noise_cache[key] = models
        return models

    def _observation_entry(self, k: int, seed: gtsam.Pose2, obs: Observation) -> _PendingObservation:
        lid = obs.landmark_id
        noise, used = self._observation_noise(obs)
        bearing = gtsam.Rot2(obs.bearing_rad)
        p_robot = np.array([obs.range_m * math.cos(obs.bearing_rad), obs.range_m * math.sin(obs.bearing_rad)])
        if lid not in self._is_tag_landmark:  # the first sighting decides: tag or point
            self._is_tag_landmark[lid] = self.tags and has_tag_yaw(obs)
        if not self._is_tag_landmark[lid]:
            factor = gtsam.BearingRangeFactor2D(X(k), L(lid), bearing, obs.range_m, used)
            gate_factor = factor
            if used is not noise:
                gate_factor = gtsam.BearingRangeFactor2D(X(k), L(lid), bearing, obs.range_m, noise)
            guess = np.asarray(seed.transformFrom(p_robot), dtype=float)
            return _PendingObservation(lid, L(lid), k, factor, gate_factor, guess, seed)
        if has_tag_yaw(obs):  # the tag's whole pose relative to the robot
            measured = tag_relative_pose(obs)
            gaussian = gtsam.noiseModel.Gaussian.Covariance(tag_noise_covariance(obs))
            factor = gate_factor = gtsam.BetweenFactorPose2(X(k), T(lid), measured, gaussian)
            if self._robust is not None:
                robust_noise = gtsam.noiseModel.Robust.Create(self._robust, gaussian)
                factor = gtsam.BetweenFactorPose2(X(k), T(lid), measured, robust_noise)
            guess = seed.compose(measured)
        else:  # a tag seen without its yaw: bearing and range to its centre
            factor = gtsam.BearingRangeFactorPose2(X(k), T(lid), bearing, obs.range_m, used)
            gate_factor = factor
            if used is not noise:
                gate_factor = gtsam.BearingRangeFactorPose2(X(k), T(lid), bearing, obs.range_m, noise)
            # seed: the tag faces the camera
            guess = seed.compose(gtsam.Pose2(p_robot[0], p_robot[1], obs.bearing_rad + math.pi))
        return _PendingObservation(lid, T(lid), k, factor, gate_factor, guess, seed)

    def _add_height(self, obs: Observation) -> None:
        """Hold a height observation: ``PriorFactorDouble(H(id), height, σ_h)``.

        A landmark's height is a scalar variable nothing else touches, so iSAM2 keeps it in
        a tree of its own and its estimate is the information-weighted mean of the heights
        measured (exactly the EKF's scalar filter, see ekf/slam.py).
        """
        key = H(obs.landmark_id)
        noise = self._noise_cache.get(("h", obs.sigma_height_m))
        if noise is None:
            noise = self._noise_cache[("h", obs.sigma_height_m)] = gtsam.noiseModel.Isotropic.Sigma(
                1, obs.sigma_height_m
            )
        self._held_core.add(gtsam.PriorFactorDouble(key, float(obs.height_m), noise))
        if obs.landmark_id not in self._height_ids:
            self._held_values.insert(key, float(obs.height_m))
            self._height_ids.add(obs.landmark_id)

    def _new_landmark_values(self, entries: list[_PendingObservation]) -> gtsam.Values:
        """Seeds for landmarks not yet in iSAM2: the latest of the observations that took
        part in the fewest failed updates (a fresh observation beats a withheld one)."""
        best: dict[int, _PendingObservation] = {}
        for e in entries:
            if e.landmark_id in self._known_landmarks:
                continue
            if e.landmark_id not in best or e.attempts <= best[e.landmark_id].attempts:
                best[e.landmark_id] = e
        values = gtsam.Values()
        for e in best.values():
            values.insert(e.key, e.landmark_guess)
        return values

    def _accept(self, factors: gtsam.NonlinearFactorGraph, values: gtsam.Values) -> None:
        self._graph.push_back(factors)
        self._initial.insert(values)
        for key in values.keys():
            symbol = gtsam.Symbol(key)
            if chr(symbol.chr()) in "lt":
                lid = int(symbol.index())
                self._known_landmarks.add(lid)
                self._landmark_ids.append(lid)
                if chr(symbol.chr()) == "t":
                    self._tag_ids.add(lid)

    @staticmethod
    def _combine(core: gtsam.NonlinearFactorGraph, core_values: gtsam.Values, entries, landmark_values):
        factors = gtsam.NonlinearFactorGraph(core)
        for e in entries:
            factors.add(e.factor)
        values = gtsam.Values(core_values)
        values.insert(landmark_values)
        return factors, values

    def _update_with_recovery(self, core, core_values, entries: list[_PendingObservation]) -> None:
        self._estimate_cache = None
        factors, values = self._combine(core, core_values, entries, self._new_landmark_values(entries))
        try:
            self._isam.update(factors, values)
        except RuntimeError as exc:
            self._recover(exc, core, core_values, entries)
            return
        self._accept(factors, values)

    def _recover(self, exc: RuntimeError, core, core_values, entries: list[_PendingObservation]) -> None:
        """Replace the broken iSAM2 by a fresh one holding everything but withheld observations."""
        self.update_failures += 1
        self.last_failure = str(exc)
        seeds = []
        try:  # the failed object's values are a plain copy: usually a good linearisation point
            seeds.append(self._isam.getLinearizationPoint())
        except RuntimeError:
            pass
        seeds.append(self._initial)
        blamed = _key_named_in(exc)
        blamed_ids = {e.landmark_id for e in entries if e.key == blamed}
        innocent = [e for e in entries if e.landmark_id not in blamed_ids]
        plans = [innocent, []] if blamed_ids and innocent else [[]]
        for kept in plans:
            kept_ids = {id(e) for e in kept}
            withheld = [e for e in entries if id(e) not in kept_ids]
            factors, values = self._combine(core, core_values, kept, self._new_landmark_values(kept))
            everything = gtsam.NonlinearFactorGraph(self._graph)
            everything.push_back(factors)
            for seed in seeds:
                isam = gtsam.ISAM2(self._params())
                try:
                    isam.update(everything, _reseeded(self._initial, values, seed))
                except RuntimeError as again:
                    self.last_failure = str(again)
                    continue
                self._isam = isam
                self._accept(factors, values)
                for e in withheld:
                    e.attempts += 1
                self._pending.extend(withheld)
                return
        raise FgslamError(
            f"Isam2Smoother: the graph is singular even without this step's observations "
            f"(pose {self._num_poses}); check the odometry covariance and the start sigmas. "
            f"GTSAM said: {self.last_failure}"
        )


def _body_to_world(theta_rad: float) -> np.ndarray:
    """3×3 map of a Pose2 perturbation in the robot's frame (GTSAM's convention) to world
    (x, y, θ) at heading ``theta_rad``."""
    c, s = math.cos(theta_rad), math.sin(theta_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _relinearize_threshold(value) -> float | tuple[float, float]:
    """Validate ``relinearize_threshold``: one number, or a (metres, radians) pair."""
    if isinstance(value, (tuple, list)):
        if len(value) != 2 or not all(isinstance(v, (int, float)) and math.isfinite(v) and v >= 0 for v in value):
            raise FgslamError(
                f"Isam2Smoother: relinearize_threshold pair must be (metres >= 0, radians >= 0), got {value!r}"
            )
        return (float(value[0]), float(value[1]))
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
        raise FgslamError(f"Isam2Smoother: relinearize_threshold must be a number >= 0 or a pair, got {value!r}")
    return float(value)


def _reseeded(initial: gtsam.Values, new_values: gtsam.Values, seed: gtsam.Values) -> gtsam.Values:
    """Initial values for a rebuild: old variables at ``seed`` where it has them, new ones as given."""
    out = gtsam.Values()
    for key in initial.keys():
        source = seed if seed.exists(key) else initial
        kind = chr(gtsam.Symbol(key).chr())
        if kind in "xt":
            out.insert(key, source.atPose2(key))
        elif kind == "h":
            out.insert(key, source.atDouble(key))
        else:
            out.insert(key, source.atPoint2(key))
    out.insert(new_values)
    return out


def _poses_of(values: gtsam.Values, n: int) -> np.ndarray:
    out = np.empty((n, 3))
    for i in range(n):
        p = values.atPose2(X(i))
        out[i] = (p.x(), p.y(), p.theta())
    return out


def _landmarks_of(values: gtsam.Values, ids, tag_ids) -> dict[int, tuple[float, float]]:
    out = {}
    for lid in ids:
        if lid in tag_ids:
            pose = values.atPose2(T(lid))
            out[lid] = (pose.x(), pose.y())
        else:
            p = values.atPoint2(L(lid))
            out[lid] = (float(p[0]), float(p[1]))
    return out


def _yaws_of(values: gtsam.Values, tag_ids) -> dict[int, float]:
    return {lid: values.atPose2(T(lid)).theta() for lid in sorted(tag_ids)}


def _heights_of(values: gtsam.Values, height_ids) -> dict[int, float]:
    return {lid: values.atDouble(H(lid)) for lid in sorted(height_ids)}


# ---------------------------------------------------------------------------- batch


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


def batch_solve(smoother: Isam2Smoother, *, max_iterations: int = 100) -> BatchResult:
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
        trajectory=_poses_of(result, smoother.num_poses),
        landmarks=_landmarks_of(result, sorted(smoother.landmarks()), smoother._tag_ids),
        landmark_heights=_heights_of(result, smoother._height_ids) or None,
        landmark_yaws=_yaws_of(result, smoother._tag_ids) or None,
        time_s=elapsed,
        initial_error=float(graph.error(initial)),
        final_error=float(graph.error(result)),
        iterations=int(optimizer.iterations()),
    )
