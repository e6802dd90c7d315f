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
  ``[sigma_bearing_rad, sigma_range_m]``. Heights and tag yaws are not used: landmarks
  are points in the plane.
* With ``robust="huber"`` or ``"cauchy"`` (see :class:`Isam2Smoother`) every
  bearing-range factor's noise model is ``noiseModel.Robust`` wrapping that diagonal
  model; the prior and the odometry factors stay Gaussian.

How :class:`Isam2Smoother` runs
-------------------------------
One ``ISAM2.update`` per step (by default; ``update_every`` and ``update_on`` can hold
steps and update less often) with that step's new factors and new variables. A new pose
is seeded from the *current iSAM2 estimate* of the previous pose composed with the
odometry increment (seeding from dead reckoning makes iSAM2 diverge on real data, see
DESIGN.md); a landmark seen for the first time is seeded from that seed pose and the
observation. After the update only the newest pose is read back
(``calculateEstimatePose2``), which is cheap; the full estimate is computed on demand.

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
from gtsam.symbol_shorthand import L, X

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
]

#: The robust kernels :class:`Isam2Smoother` offers for landmark factors.
ROBUST_KERNELS = ("huber", "cauchy")

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
DEFAULT_ROBUST_K = {"huber": 1.345, "cauchy": math.sqrt(-2.0 * math.log(0.001))}


def robust_estimator(robust: str, k: float | None = None):
    """GTSAM's m-estimator ``robust`` ("huber" or "cauchy") with width ``k`` (None: default).

    Its ``loss(r)`` of a whitened residual norm r is Huber ``r²/2`` for r ≤ k, else
    ``k·r − k²/2``; Cauchy ``k²/2 · ln(1 + r²/k²)``.
    """
    if robust not in ROBUST_KERNELS:
        raise FgslamError(f"robust kernel must be one of {', '.join(ROBUST_KERNELS)} (or None), got {robust!r}")
    k = DEFAULT_ROBUST_K[robust] if k is None else float(k)
    if not (math.isfinite(k) and k > 0):
        raise FgslamError(f"robust_k must be a finite number > 0 (whitened units), got {k!r}")
    if robust == "huber":
        return gtsam.noiseModel.mEstimator.Huber.Create(k)
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
    Q = np.asarray(odometry.covariance, dtype=float)
    c, s = math.cos(odometry.dtheta_rad), math.sin(odometry.dtheta_rad)
    A = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])  # blockdiag(R(dθ)ᵀ, 1)
    cov = A @ Q @ A.T
    return 0.5 * (cov + cov.T)


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
    pose_index: int
    factor: gtsam.BearingRangeFactor2D
    gate_factor: gtsam.BearingRangeFactor2D  # the same with the plain Gaussian noise (for the gate)
    landmark_guess: np.ndarray  # world (x, y) implied by the observation and its seed pose
    attempts: int = 0  # failed updates it took part in


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
        metres, per component). Default 0.01 (GTSAM's own default is 0.1).
    relinearize_skip:
        Check for relinearisation every this many updates. Default 1 (GTSAM's is 10):
        a loop closure is absorbed at once instead of up to nine steps late, and the
        online pose is what the robot acts on.

        Why these two defaults, measured on a 200-step, 2-lap noisy test log (6
        landmarks, 492 observations): with 0.01/1 iSAM2 ends within 2e-4 m of the batch
        LM trajectory and 6e-7 (relative) of its error, at a median 0.26 ms per update;
        with GTSAM's 0.1/10 it is 1.8e-3 m and 1.7e-4 off at 0.15 ms. A desk-sized
        robot's errors are centimetres, so the millimetre matters more than 0.1 ms.
        Very aggressive settings are where DESIGN.md saw IndeterminantLinearSystem
        failures on real data; those are recovered from (module docstring).
    final_updates:
        Extra ``isam.update()`` calls (no new factors) in :meth:`finish`, letting pending
        relinearisation happen at the end of a run. Cheap (well under 1 ms each here).
        With the defaults above the estimate is already converged and two extra updates
        change the error by < 1e-6; they matter with a looser threshold or
        ``relinearize_skip`` > 1 only when an update lands on a relinearisation check.
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
        In :meth:`finish`, after ``final_updates``: up to this many updates with forced
        relinearisation until the error drops by less than ``final_tolerance``
        (relative). The final estimate is then read with ``calculateBestEstimate`` (a
        full back-substitution; ``calculateEstimate`` skips changes below the wildfire
        threshold).
    partial_relinearization_check, cache_linearized_factors, factorization, wildfire_threshold:
        Passed to GTSAM's ``ISAM2Params`` (``factorization`` is "cholesky" or "qr").
    robust:
        ``None`` (default): every factor is Gaussian (least squares). ``"huber"`` or
        ``"cauchy"``: landmark (bearing-range) factors get that robust kernel through
        ``gtsam.noiseModel.Robust`` around their diagonal noise, so observations far
        from the rest (misdetections with a valid id) lose their pull; odometry and the
        prior stay Gaussian. The graph kept for :func:`batch_solve` holds the same robust
        factors, so the batch solve is robust too, and :meth:`error` is the robust cost.
        ``name`` becomes ``"isam2-huber"`` / ``"isam2-cauchy"``.
    robust_k:
        The kernel width in whitened units (σ of the 2-D residual norm); None takes
        :data:`DEFAULT_ROBUST_K` (≈ 2.448 for both, why there). Only with ``robust``.

        Robust factors in iSAM2 are still one update per step, nothing else changes:
        a factor's weight is recomputed whenever iSAM2 relinearises one of its
        variables, which with the default threshold/skip happens as soon as the
        estimate moves. A landmark whose *first* observation is an outlier is seeded
        metres off; its later good observations then all disagree with it and are
        down-weighted alike, so it moves to them within a few steps (or, with Cauchy,
        when it is revisited). Measured: on arena-octagon seeds 1–3 with 10 % outliers
        (seed 3's first sighting of tag 2 is an outlier, 50σ off) and on a hand-made
        log whose first sightings are all outliers, robust iSAM2 ended where batch LM
        started from the *truth* ends (same error to 1e-6 relative), i.e. at the robust
        cost's optimum, not in a local minimum. Whatever remains is the kernel's own
        bias (Huber's, above all), not convergence.

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
    """

    name = "isam2"

    #: A pending observation whose ½‖whitened residual‖² at the current estimate exceeds
    #: this (≈ 7σ in one component) is dropped instead of retried.
    PENDING_GATE = 25.0

    def __init__(
        self,
        header: Header,
        *,
        relinearize_threshold: float = 0.01,
        relinearize_skip: int = 1,
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
    ):
        if relinearize_threshold < 0 or relinearize_skip < 1 or final_updates < 0 or max_retries < 0:
            raise FgslamError(
                "Isam2Smoother: need relinearize_threshold >= 0, relinearize_skip >= 1, "
                "final_updates >= 0 and max_retries >= 0"
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
            self.name = f"isam2-{robust}"
        self.robust = robust
        self.robust_k = None if robust is None else (DEFAULT_ROBUST_K[robust] if robust_k is None else float(robust_k))
        self.header = header
        self.relinearize_threshold = float(relinearize_threshold)
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
        self._pending: list[_PendingObservation] = []
        self._num_poses = 0
        self._pose: gtsam.Pose2 | None = None  # latest pose: iSAM2's after an update, else ⊕ odometry
        self._estimate_cache: gtsam.Values | None = None
        # Steps taken but not yet given to iSAM2: their odometry/prior factors, pose seeds
        # and observation entries, run in one update later (see update_every / update_on).
        self._held_core = gtsam.NonlinearFactorGraph()
        self._held_values = gtsam.Values()
        self._held_entries: list[_PendingObservation] = []
        self._held_steps = 0
        self._held_observed = False

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
        core = gtsam.NonlinearFactorGraph()
        core_values = gtsam.Values()
        if k == 0:
            if step.odometry is not None:
                raise FgslamError("Isam2Smoother: step 0 is the start pose and cannot have odometry")
            seed = gtsam.Pose2(*self.header.start_pose)
            prior_noise = gtsam.noiseModel.Gaussian.Covariance(start_prior_covariance(self.header))
            core.add(gtsam.PriorFactorPose2(X(0), seed, prior_noise))
        else:
            odo = step.odometry
            if odo is None:
                raise FgslamError(f"Isam2Smoother: step {k} has no odometry; every step after 0 starts with one")
            increment = gtsam.Pose2(odo.dx_m, odo.dy_m, odo.dtheta_rad)
            noise = gtsam.noiseModel.Gaussian.Covariance(odometry_noise_covariance(odo))
            core.add(gtsam.BetweenFactorPose2(X(k - 1), X(k), increment, noise))
            assert self._pose is not None
            # latest iSAM2 estimate ⊕ the increments since, not dead reckoning from the start
            seed = self._pose.compose(increment)
        core_values.insert(X(k), seed)

        for obs in step.observations:
            if obs.landmark_id is None:
                self.skipped_unknown_observations += 1
                continue
            self._held_entries.append(self._observation_entry(k, seed, obs))
            self._held_observed = True
        self._held_core.push_back(core)
        self._held_values.insert(core_values)
        self._held_steps += 1
        self._num_poses = k + 1
        self._pose = seed
        if self._due(k):
            self._flush()

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
        self._held_steps, self._held_observed = 0, False
        entries = self._screen_pending(fresh) + fresh
        self._update_with_recovery(core, core_values, entries)
        self.updates += 1
        self._pose = self._isam.calculateEstimatePose2(X(self._num_poses - 1))

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
        ``final_iterations`` forced full relinearisations (Gauss–Newton steps on the whole
        graph) until the error's relative decrease is below ``final_tolerance``."""
        if self._num_poses == 0:
            return
        self._flush()
        self._estimate_cache = None
        for _ in range(self.final_updates):
            try:
                self._isam.update()
            except RuntimeError as exc:  # relinearisation hit a singular system: rebuild
                self._recover(exc, gtsam.NonlinearFactorGraph(), gtsam.Values(), [])
        if self.final_iterations:
            previous = float(self._graph.error(self._isam.calculateBestEstimate()))
            for _ in range(self.final_iterations):
                update_params = gtsam.ISAM2UpdateParams()
                update_params.force_relinearize = True
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
        self._pose = self._estimate_cache.atPose2(X(self._num_poses - 1))

    def trajectory(self) -> np.ndarray:
        """(n, 3) array of every pose (x_m, y_m, theta_rad) as estimated now."""
        return _poses_of(self._estimate(), self._num_poses)

    def landmarks(self) -> dict[int, tuple[float, float]]:
        """Landmark id → estimated world (x_m, y_m), for landmarks accepted into iSAM2."""
        return _landmarks_of(self._estimate(), self._landmark_ids)

    # ------------------------------------------------------------------ extras

    @property
    def num_poses(self) -> int:
        return self._num_poses

    def current_covariance(self, frame: str = "world") -> np.ndarray:
        """3×3 marginal covariance of the latest pose (from ``isam.marginalCovariance``).

        GTSAM expresses a Pose2's uncertainty in the robot's own frame (a perturbation
        ``pose ⊕ δ``). With ``frame="world"`` (the default) it is rotated into world
        (x, y, theta) coordinates, the same coordinates as the EKF's covariance and as a
        world-frame pose error, which is what NEES needs; ``frame="body"`` returns GTSAM's
        own. Costs more than an update: call it when needed, not every step by default.
        """
        if self._num_poses == 0:
            raise FgslamError("Isam2Smoother: no step yet")
        if frame not in ("world", "body"):
            raise FgslamError(f"current_covariance: frame must be 'world' or 'body', got {frame!r}")
        self._flush()
        cov = np.asarray(self._isam.marginalCovariance(X(self._num_poses - 1)), dtype=float)
        if frame == "world":
            th = self._isam.calculateEstimatePose2(X(self._num_poses - 1)).theta()
            c, s = math.cos(th), math.sin(th)
            J = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
            cov = J @ cov @ J.T
        return 0.5 * (cov + cov.T)

    def graph(self) -> gtsam.NonlinearFactorGraph:
        """A copy of every factor accepted into iSAM2 (pending observations excluded).

        Held steps are given to iSAM2 first, so the graph covers every step taken."""
        self._flush()
        return gtsam.NonlinearFactorGraph(self._graph)

    def initial_values(self) -> gtsam.Values:
        """A copy of the initial guess each variable entered iSAM2 with (held steps flushed first)."""
        self._flush()
        return gtsam.Values(self._initial)

    def estimate(self) -> gtsam.Values:
        """A copy of iSAM2's current estimate of every variable (one ``calculateEstimate``)."""
        return gtsam.Values(self._estimate())

    def error(self) -> float:
        """The graph's error at iSAM2's current estimate (χ²/2, like ``graph.error``)."""
        return float(self._graph.error(self._estimate()))

    @property
    def pending_observations(self) -> int:
        """Observations withheld after a failed update, still to be retried."""
        return len(self._pending)

    # ------------------------------------------------------------------ internals

    def _params(self) -> gtsam.ISAM2Params:
        params = gtsam.ISAM2Params()
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

    def _screen_pending(self, fresh: list[_PendingObservation]) -> list[_PendingObservation]:
        """The pending observations to retry in this update; others wait or are dropped."""
        retry, wait = [], []
        for e in self._pending:
            if e.attempts > self.max_retries:
                self.dropped_observations += 1
                continue
            if e.landmark_id in self._known_landmarks:
                landmark = self._isam.calculateEstimatePoint2(L(e.landmark_id))
            else:
                seen_now = [o for o in fresh if o.landmark_id == e.landmark_id]
                if not seen_now:  # nothing trustworthy to check it against yet
                    wait.append(e)
                    continue
                landmark = seen_now[-1].landmark_guess
            values = gtsam.Values()
            values.insert(X(e.pose_index), self._isam.calculateEstimatePose2(X(e.pose_index)))
            values.insert(L(e.landmark_id), np.asarray(landmark, dtype=float))
            error = e.gate_factor.error(values)
            if math.isfinite(error) and error <= self.PENDING_GATE:
                retry.append(e)
            else:
                self.dropped_observations += 1
        self._pending = wait
        return retry

    def _observation_entry(self, k: int, seed: gtsam.Pose2, obs: Observation) -> _PendingObservation:
        noise = gtsam.noiseModel.Diagonal.Sigmas(np.array([obs.sigma_bearing_rad, obs.sigma_range_m]))
        bearing = gtsam.Rot2(obs.bearing_rad)
        factor = gtsam.BearingRangeFactor2D(X(k), L(obs.landmark_id), bearing, obs.range_m, noise)
        gate_factor = factor
        if self._robust is not None:
            robust_noise = gtsam.noiseModel.Robust.Create(self._robust, noise)
            factor = gtsam.BearingRangeFactor2D(X(k), L(obs.landmark_id), bearing, obs.range_m, robust_noise)
        p_robot = np.array([obs.range_m * math.cos(obs.bearing_rad), obs.range_m * math.sin(obs.bearing_rad)])
        guess = np.asarray(seed.transformFrom(p_robot), dtype=float)
        return _PendingObservation(obs.landmark_id, k, factor, gate_factor, guess)

    def _new_landmark_values(self, entries: list[_PendingObservation]) -> gtsam.Values:
        """Seeds for landmarks not yet in iSAM2: the latest of the observations that took
        part in the fewest failed updates (a fresh observation beats a withheld one)."""
        best: dict[int, _PendingObservation] = {}
        for e in entries:
            if e.landmark_id in self._known_landmarks:
                continue
            if e.landmark_id not in best or e.attempts <= best[e.landmark_id].attempts:
                best[e.landmark_id] = e
        guesses = {lid: e.landmark_guess for lid, e in best.items()}
        values = gtsam.Values()
        for lid, guess in guesses.items():
            values.insert(L(lid), guess)
        return values

    def _accept(self, factors: gtsam.NonlinearFactorGraph, values: gtsam.Values) -> None:
        self._graph.push_back(factors)
        self._initial.insert(values)
        for key in values.keys():
            symbol = gtsam.Symbol(key)
            if chr(symbol.chr()) == "l":
                lid = int(symbol.index())
                self._known_landmarks.add(lid)
                self._landmark_ids.append(lid)

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
        blamed_ids = {e.landmark_id for e in entries if L(e.landmark_id) == blamed}
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


def _reseeded(initial: gtsam.Values, new_values: gtsam.Values, seed: gtsam.Values) -> gtsam.Values:
    """Initial values for a rebuild: old variables at ``seed`` where it has them, new ones as given."""
    out = gtsam.Values()
    for key in initial.keys():
        source = seed if seed.exists(key) else initial
        if chr(gtsam.Symbol(key).chr()) == "x":
            out.insert(key, source.atPose2(key))
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


def _landmarks_of(values: gtsam.Values, ids) -> dict[int, tuple[float, float]]:
    out = {}
    for lid in ids:
        p = values.atPoint2(L(lid))
        out[lid] = (float(p[0]), float(p[1]))
    return out


# ---------------------------------------------------------------------------- batch


@dataclass(frozen=True, eq=False)
class BatchResult:
    """The batch Levenberg–Marquardt solution of a smoother's whole graph.

    ``trajectory`` is (n, 3) (x_m, y_m, theta_rad); ``landmarks`` id → (x_m, y_m);
    ``initial_error``/``final_error`` are ``graph.error`` (χ²/2) at the start (iSAM2's
    estimate) and at the end; ``time_s`` is the wall time of the optimisation alone.
    """

    trajectory: np.ndarray
    landmarks: dict[int, tuple[float, float]]
    time_s: float
    initial_error: float
    final_error: float
    iterations: int


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
        landmarks=_landmarks_of(result, sorted(smoother.landmarks())),
        time_s=elapsed,
        initial_error=float(graph.error(initial)),
        final_error=float(graph.error(result)),
        iterations=int(optimizer.iterations()),
    )
