"""The factor-graph twin of ``ekf-vio`` for seed 003's stereo + IMU drives (GTSAM).

The factor graph
----------------
* ``X(t)`` — the IMU pose ``world_T_imu`` at step t (``gtsam.Pose3``); a
  ``PriorFactorPose3`` pins ``X(0)`` at the identity (the world is the IMU frame at the
  first step, as in the seed) with σ = ``start_sigma``.
* ``BetweenFactorPose3(X(t−1), X(t), exp(τ u^))`` from the IMU twist u = (v, ω) held over
  τ, with the covariance ``G Σ_u Gᵀ``, ``G = τ J_r(τ u)`` — exactly ``ekf-vio``'s process
  noise — reordered to GTSAM's tangent order (rotation first).
* ``L(j)`` — landmark j (``gtsam.Point3``, world), created at the first sighting whose
  disparity is ≥ ``min_disparity_px`` (back-projected from the current estimate of the
  pose: the same rule as ``ekf-vio``); sightings of a landmark not created yet are unused.
  A ``PriorFactorPoint3`` at that first guess with σ = ``landmark_prior_sigma_m`` (1 km:
  10⁻⁶ of the information of one stereo pixel at 100 m) keeps the linear system
  determinate when a landmark's only factors say nothing (a point estimated behind the
  camera gets zero Jacobians from GTSAM's stereo factor) — on the seed's real drives
  iSAM2 otherwise stops with ``IndeterminantLinearSystemException``. Without the robust
  kernel it is not enough when tracks have outliers: ``robust="none"`` on a simulated drive
  with 5 % outliers still stops with the 1 km prior (a 10 m prior lets it finish, at 2.1 m
  ATE against Huber's 0.10 m); the exception then propagates.
* ``GenericStereoFactor3D(StereoPoint2(u_L, u_R, v), X(t), L(j), Cal3_S2Stereo, body_P_sensor
  = imu_T_cam)`` for every sighting of a created landmark (the first one included). GTSAM's
  rectified model has one v; the seed's data has v_L and v_R with independent noise, so
  ``v = (v_L + v_R)/2`` with σ/√2 carries exactly their information (with a 4×4 pixel
  covariance Σ: ``A Σ Aᵀ``, :func:`fgslam.noise3d.stereo_factor_noise`). With ``robust="huber"``
  (default) the stereo noise model is ``noiseModel.Robust(Huber(huber_k), Gaussian)``.

How it runs
-----------
:class:`StereoIsam2` makes one ``ISAM2.update`` per step with that step's factors; the new
pose is seeded from iSAM2's current estimate of the previous pose composed with the IMU
increment. After the update only the newest pose is read back (the online trajectory).
:meth:`StereoIsam2.finish` ends with Levenberg–Marquardt on the whole graph from iSAM2's
estimate, so its final estimate is the optimum of the graph (as the planar smoother's final
Gauss–Newton steps make its own).
Everything is also kept in one ``NonlinearFactorGraph`` and the initial ``Values``;
:func:`batch_solve` runs Levenberg–Marquardt on it from iSAM2's full estimate — the
smoothed reference.

Bounded on long drives: once iSAM2 holds more than ``max_held_factors`` factors
(:data:`MAX_HELD_FACTORS`), the old poses and the landmarks only they saw are marginalised
out of it into a fresh iSAM2 (:mod:`fgslam.window3d`), so its memory and its steps stay
bounded however long the drive. A run that never reaches the bound (the seed's real drives)
is exactly the unbounded one, and :meth:`StereoIsam2.finish` still ends at the whole graph's
optimum; after a slide the final estimate is the fixed-lag one (the window's estimate, and
what left at its estimate then), and only the batch solve, which always sees the whole
graph, refines it.
"""

from __future__ import annotations

import time

import gtsam
import numpy as np
from gtsam.symbol_shorthand import L, X

from slamio.se3 import exp_se3, inverse
from slamio.stereo import point_from_stereo
from ekf.vio import right_jacobian_se3
from slamio.datasets.seed003 import StereoImuNoise
from fgslam.window3d import StereoWindow
from fgslam.noise3d import stereo_factor_noise

__all__ = ["BatchResult", "StereoIsam2", "batch_solve", "gtsam_covariance", "imu_increment_covariance"]

ROBUST = ("huber", "none")
#: :meth:`StereoIsam2.finish` restarts Levenberg–Marquardt at most this many times: with the
#: robust stereo kernel one run can stop where its damping tops out while a fresh one goes on
#: (seed 003 drive 0042 with the noise learned from it: 372 089 after one run, 349 899 after more).
MAX_RESTARTS = 10
#: iSAM2 holds at most about this many factors (:class:`fgslam.window3d.StereoWindow`): the
#: seed's real drives (≤ 4 800 factors) and the default simulated stereo loop (~7 400) stay
#: whole, so their final estimate is the batch optimum as before; the long dense simulated
#: drive (45 000) is bounded (docs/performance.md, "A bounded isam2-3d").
MAX_HELD_FACTORS = 12000


def gtsam_covariance(cov_rho_phi) -> np.ndarray:
    """Reorder a 6×6 covariance over (ρ, φ) into GTSAM's Pose3 tangent order (φ, ρ)."""
    order = [3, 4, 5, 0, 1, 2]
    c = np.asarray(cov_rho_phi, dtype=float)
    return c[np.ix_(order, order)]


def imu_increment_covariance(tau_s: float, twist, velocity_cov) -> np.ndarray:
    """6×6 (ρ, φ) covariance of the increment exp(τ u^) from white velocity noise: G Σ_u Gᵀ."""
    G = tau_s * right_jacobian_se3(tau_s * np.asarray(twist, dtype=float))
    return G @ np.asarray(velocity_cov, dtype=float) @ G.T


class StereoIsam2:
    """Online iSAM2 on the stereo + IMU graph (implements the ``ekf.drive3d`` step protocol).

    ``StereoIsam2(K, baseline_m, cam_T_imu, noise=StereoImuNoise(), robust="huber",
    huber_k=1.345, min_disparity_px=4.0, start_sigma=1e-6, landmark_prior_sigma_m=1000.0,
    max_held_factors=MAX_HELD_FACTORS)`` (None: iSAM2 keeps every variable).
    Counters: ``landmarks_added``, ``stereo_factors``, ``skipped_small_disparity``;
    ``update_seconds`` lists the wall time of each ``ISAM2.update`` (a slide of the window
    included); ``window`` (:class:`fgslam.window3d.StereoWindow`) has ``slides``, ``re_entered``.
    """

    name = "isam2-vio"

    def __init__(
        self,
        K,
        baseline_m: float,
        cam_T_imu,
        noise: StereoImuNoise = StereoImuNoise(),
        *,
        robust: str = "huber",
        huber_k: float = 1.345,
        min_disparity_px: float = 4.0,
        start_sigma: float = 1e-6,
        landmark_prior_sigma_m: float = 1000.0,
        max_held_factors: int | None = MAX_HELD_FACTORS,
    ):
        if robust not in ROBUST:
            raise ValueError(f"robust must be one of {ROBUST}, got {robust!r}")
        K = np.asarray(K, dtype=float)
        self.K = K
        self.baseline_m = float(baseline_m)
        self.cam_T_imu = np.asarray(cam_T_imu, dtype=float)
        self.noise = noise
        self.min_disparity_px = float(min_disparity_px)
        self._calibration = gtsam.Cal3_S2Stereo(K[0, 0], K[1, 1], K[0, 1], K[0, 2], K[1, 2], self.baseline_m)
        self._imu_T_cam = inverse(self.cam_T_imu)
        self._body_P_sensor = gtsam.Pose3(self._imu_T_cam)
        gaussian = stereo_factor_noise(noise)  # σ, σ, σ/√2; or A Σ Aᵀ of a 4×4 pixel covariance
        self._stereo_noise = (
            gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Huber.Create(huber_k), gaussian)
            if robust == "huber"
            else gaussian
        )
        self._landmark_prior = gtsam.noiseModel.Isotropic.Sigma(3, landmark_prior_sigma_m)
        self._isam = gtsam.ISAM2(gtsam.ISAM2Params())
        self.graph = gtsam.NonlinearFactorGraph()
        self.initial = gtsam.Values()
        self._t = -1
        self._pose = np.eye(4)
        self._landmarks: set[int] = set()
        self._trajectory: list[np.ndarray] = []
        self._start_sigma = start_sigma
        self.landmarks_added = 0
        self.stereo_factors = 0
        self.skipped_small_disparity = 0
        self.update_seconds: list[float] = []
        self._final: gtsam.Values | None = None  # finish()'s estimate
        self.rebuilds = 0  # times iSAM2 was started again after an update it could not solve
        # what iSAM2 holds, bounded (fgslam/window3d.py); None: every variable stays in it
        self.window = None if max_held_factors is None else StereoWindow(max_held_factors)

    # ------------------------------------------------------------------ protocol

    def step(self, dt_s, twist, ids, pixels) -> None:
        factors = gtsam.NonlinearFactorGraph()  # for the whole graph
        values = gtsam.Values()
        self._t += 1
        t = self._t
        if t == 0:
            prior = gtsam.noiseModel.Isotropic.Sigma(6, self._start_sigma)
            factors.add(gtsam.PriorFactorPose3(X(0), gtsam.Pose3(), prior))
            seed = np.eye(4)
        else:
            u = np.asarray(twist, dtype=float)
            increment = exp_se3(float(dt_s) * u)
            cov = gtsam_covariance(imu_increment_covariance(float(dt_s), u, self.noise.velocity_cov()))
            factors.add(
                gtsam.BetweenFactorPose3(X(t - 1), X(t), gtsam.Pose3(increment), gtsam.noiseModel.Gaussian.Covariance(cov))
            )
            seed = self._pose @ increment
        values.insert(X(t), gtsam.Pose3(seed))
        held, held_values, seen = self._sightings(t, seed, ids, pixels, factors, values)
        start = time.perf_counter()
        try:
            self._isam.update(held, held_values)
        except RuntimeError:  # gtsam.IndeterminantLinearSystemException: start iSAM2 again (_rebuild)
            self._rebuild(held, held_values)
        if self.window is not None:
            self.window.entered(t, held, held_values, seen)
            if self.window.due():
                self._slide()
        self.update_seconds.append(time.perf_counter() - start)
        self.graph.push_back(factors)
        self.initial.insert(values)
        self._pose = self._isam.calculateEstimatePose3(X(t)).matrix()
        self._trajectory.append(self._pose.copy())

    def _sightings(self, t: int, seed, ids, pixels, factors, values):
        """Add step ``t``'s stereo factors (and new landmarks) to ``factors`` / ``values``, the
        whole graph's. Returns what iSAM2 is to take (the same graph without a window; with
        one, a landmark that left iSAM2 enters again under a new key) and, for the window,
        each sighted landmark's key in iSAM2."""
        if self.window is None:
            held, held_values = factors, values
        else:
            held, held_values = gtsam.NonlinearFactorGraph(), gtsam.Values()
            held.push_back(factors)
            held_values.insert(values)
        seen: dict[int, int] = {}
        for lid, z in zip(np.asarray(ids, dtype=int), np.asarray(pixels, dtype=float).reshape(-1, 4)):
            lid = int(lid)
            if lid not in self._landmarks:
                if not z[0] - z[2] >= self.min_disparity_px:
                    self.skipped_small_disparity += 1
                    continue
                p_cam = np.append(point_from_stereo(z, self.K, self.baseline_m), 1.0)
                m = (seed @ self._imu_T_cam @ p_cam)[:3]
                values.insert(L(lid), gtsam.Point3(m))
                factors.add(gtsam.PriorFactorPoint3(L(lid), gtsam.Point3(m), self._landmark_prior))
                self._landmarks.add(lid)
                self.landmarks_added += 1
                if held is not factors:
                    held_values.insert(L(lid), gtsam.Point3(m))
                    held.add(factors.at(factors.size() - 1))
                    seen[lid] = L(lid)
            elif held is not factors and lid not in seen:
                seen[lid] = self._held_key(lid, held, held_values)
            measured = gtsam.StereoPoint2(z[0], z[2], 0.5 * (z[1] + z[3]))
            factor = gtsam.GenericStereoFactor3D(
                measured, self._stereo_noise, X(t), L(lid), self._calibration, self._body_P_sensor
            )
            factors.add(factor)
            if held is not factors:
                key = seen[lid]
                held.add(factor if key == L(lid) else gtsam.GenericStereoFactor3D(
                    measured, self._stereo_noise, X(t), key, self._calibration, self._body_P_sensor))
            self.stereo_factors += 1
        return held, held_values, seen

    def _held_key(self, lid: int, held, held_values) -> int:
        """Landmark ``lid``'s key in iSAM2; one that left it enters again (at the estimate it
        left with, the same weak prior) under a new key."""
        key, new = self.window.landmark_key(lid)
        if new:
            point = self.window.left_estimate(lid)
            held_values.insert(key, point)
            held.add(gtsam.PriorFactorPoint3(key, point, self._landmark_prior))
        return key

    def _slide(self) -> None:
        """Marginalise the old poses and the landmarks only they saw out of iSAM2 into a
        fresh one (:class:`fgslam.window3d.StereoWindow`). If the fresh iSAM2 cannot take it,
        the old one goes on and nothing leaves any more (``window.stopped``)."""
        estimate = self._isam.calculateEstimate()
        kept = self.window.slide(estimate)
        fresh = gtsam.ISAM2(gtsam.ISAM2Params())
        try:
            fresh.update(kept.factors, kept.values)
        except RuntimeError:  # gtsam.IndeterminantLinearSystemException
            self.window.stopped = True
            return
        self.window.commit(kept, estimate)
        self._isam = fresh

    def _rebuild(self, factors: gtsam.NonlinearFactorGraph, values: gtsam.Values) -> None:
        """After an update iSAM2 could not solve (a step's linear system singular under its
        relinearisation): Levenberg–Marquardt (damped, so it solves what Gauss–Newton cannot)
        on what iSAM2 held (the whole graph, or the window's) with this step's factors, from
        their first guesses and this step's, then a new iSAM2 holding that graph at that
        solution. Counted in ``rebuilds``."""
        held = self.graph if self.window is None else self.window.factors
        graph = gtsam.NonlinearFactorGraph(held)
        graph.push_back(factors)
        start = gtsam.Values(self.initial if self.window is None else self.window.values)
        start.insert(values)
        solved = levenberg_marquardt(graph, start, 50)
        self._isam = gtsam.ISAM2(gtsam.ISAM2Params())
        self._isam.update(graph, solved)
        self.rebuilds += 1

    def finish(self, *, max_iterations: int = 100) -> None:
        """Refine the whole graph to its optimum: Levenberg–Marquardt from iSAM2's estimate
        (:func:`levenberg_marquardt`, as the batch reference), the 3-D counterpart of the
        planar smoother's final Gauss–Newton steps. iSAM2's own full relinearisations were
        not enough: with the robust stereo kernel a Gauss–Newton step can raise the error,
        and on seed 003 drive 0020 the final error stayed 6.7× the optimum. The online
        trajectory is left as it was; ``estimate()`` is the refined one. LM is restarted
        until a restart no longer lowers the error (:data:`MAX_RESTARTS`). Once the window has
        slid, the final estimate is the fixed-lag one (the whole graph's solve is the batch's)."""
        if self._t < 0:
            return
        if self.window is not None and self.window.slides > 0:  # bounded: the fixed-lag estimate
            self._final = self.estimate()
        else:
            values = self._isam.calculateEstimate()
            error = self.graph.error(values)
            for _ in range(MAX_RESTARTS):  # LM gives up when its damping tops out; a fresh start may go on
                values = levenberg_marquardt(self.graph, values, max_iterations)
                previous, error = error, self.graph.error(values)
                if previous - error <= 1e-6 * max(previous, 1e-12):
                    break
            self._final = values
        self._isam = None  # its Bayes tree is not read again: its memory goes to the batch solve and the verdict

    @property
    def n_steps(self) -> int:
        """Steps consumed so far (= poses in the graph)."""
        return self._t + 1

    def landmark_ids(self) -> list[int]:
        return sorted(self._landmarks)

    def current_pose(self) -> np.ndarray:
        return self._pose.copy()

    def current_covariance(self) -> np.ndarray:
        """6×6 marginal covariance of the newest pose, in the (ρ, φ) order of ``ekf-vio``."""
        cov = self._isam.marginalCovariance(X(self._t))
        order = [3, 4, 5, 0, 1, 2]
        return cov[np.ix_(order, order)]

    def trajectory(self) -> np.ndarray:
        """The online trajectory: each pose as iSAM2 estimated it right after its step."""
        return np.array(self._trajectory).reshape(-1, 4, 4)

    def estimate(self) -> gtsam.Values:
        """The estimate of every variable (``X(t)``, ``L(id)``): iSAM2's (with a window, what
        it holds and what left it at their estimate then), or after :meth:`finish` the final one."""
        if self._final is not None:
            return self._final
        held = self._isam.calculateEstimate()
        if self.window is None or self.window.slides == 0:
            return held
        return self.window.whole_estimate(held, self.n_steps, self.landmark_ids())

    def smoothed_trajectory(self) -> np.ndarray:
        values = self.estimate()
        return np.array([values.atPose3(X(t)).matrix() for t in range(self.n_steps)])

    def landmarks(self) -> dict[int, np.ndarray]:
        values = self.estimate()
        return {lid: np.asarray(values.atPoint3(L(lid))) for lid in sorted(self._landmarks)}

    def error(self, values: gtsam.Values | None = None) -> float:
        """The graph's error ½ Σ‖r‖² (robust where robust) at ``values`` (iSAM2's by default)."""
        return float(self.graph.error(self.estimate() if values is None else values))


class BatchResult:
    """Levenberg–Marquardt's solution of a :class:`StereoIsam2` graph."""

    def __init__(self, values: gtsam.Values, n_poses: int, landmark_ids, error: float, seconds: float):
        self.values = values
        self.error = error
        self.seconds = seconds
        self._n = n_poses
        self._ids = sorted(landmark_ids)

    def trajectory(self) -> np.ndarray:
        return np.array([self.values.atPose3(X(t)).matrix() for t in range(self._n)])

    def landmarks(self) -> dict[int, np.ndarray]:
        return {lid: np.asarray(self.values.atPoint3(L(lid))) for lid in self._ids}


def levenberg_marquardt(graph: gtsam.NonlinearFactorGraph, start: gtsam.Values, max_iterations: int) -> gtsam.Values:
    """Levenberg–Marquardt on ``graph`` from ``start`` to a relative decrease of 1e-10."""
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(max_iterations)
    params.setRelativeErrorTol(1e-10)
    params.setAbsoluteErrorTol(1e-10)
    return gtsam.LevenbergMarquardtOptimizer(graph, start, params).optimize()


def batch_solve(smoother: StereoIsam2, *, max_iterations: int = 100) -> BatchResult:
    """Batch LM on the smoother's whole graph, started from its estimate (after
    :meth:`StereoIsam2.finish`, the refined one: it then confirms the optimum)."""
    start = time.perf_counter()
    values = levenberg_marquardt(smoother.graph, smoother.estimate(), max_iterations)
    seconds = time.perf_counter() - start
    return BatchResult(values, smoother.n_steps, smoother.landmark_ids(), float(smoother.graph.error(values)), seconds)
