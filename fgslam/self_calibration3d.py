"""Noise learned from a 3-D run itself (``fgslam run LOG --noise self`` on a stereo + IMU log).

The three variance components of the 3-D estimators' noise (:class:`StereoImuNoise`): the
stereo pixel variance σ_px² (when the log states a 4×4 pixel covariance, the factor that
scales it: its correlations and σ_u : σ_v are kept, its size is fitted), and the IMU's speed and turn-rate variances σ_v², σ_ω² (the
same on the three axes of each). Each IMU factor's 6×6 covariance is linear in the last two,
``Σ_k = σ_v² Q_v,k + σ_ω² Q_ω,k`` (``fgslam.smoother3d.imu_increment_covariance`` of the twist
held over the step), so in the factor's whitened coordinates each component owns a block
``S_c,k = R_k (θ_c Q_c,k) R_kᵀ`` (``R_kᵀ R_k = Σ_k⁻¹``; the blocks of a row sum to I). Förstner's
update of :mod:`slamio.noise.fit_self` in its block form:

    θ_c ← θ_c · Σ_k ẽ_kᵀ S_c,k ẽ_k / (Σ_k tr S_c,k − tr(S_c H)),

with the hat matrix traces by Hutchinson's estimator (:func:`hat_traces_blocks`), each
iteration on the batch solution of ``isam2-3d``'s graph rebuilt with the current θ, until
every component moves by less than 2 %. The fitted noise replaces the σ of every record
(:func:`with_noise`), so the run that follows sees it as if the log had stated it.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import gtsam
import numpy as np
import scipy.sparse as sp

from fgslam.runner3d import Log3d, run_estimator_3d
from fgslam.linearized import whitened_system
from fgslam.smoother3d import batch_solve, gtsam_covariance, imu_increment_covariance
from slamio.datasets.seed003 import StereoImuNoise
from slamio.log import RunLog, StereoObservation, VelocityOdometry
from slamio.noise.errors import NoiseModelError
from slamio.noise.fit_self import hat_traces_blocks, vce_from_sums

__all__ = ["COMPONENTS_3D", "SelfCalibration3d", "fit_without_truth_3d", "with_noise"]

COMPONENTS_3D = ("sigma_px", "sigma_v_mps", "sigma_w_radps")
MAX_ITERATIONS = 20
TOLERANCE = 0.02
#: A stereo observation is an outlier beyond this many robust σ of the reprojection errors.
GATE = 5.0
#: The gate has settled when an iteration leaves out at most this share of the observations.
NEW_OUTLIERS_SETTLED = 0.002
V_PART = np.diag([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])
W_PART = np.diag([0.0, 0.0, 0.0, 1.0, 1.0, 1.0])


@dataclass(frozen=True)
class SelfCalibration3d:
    noise: StereoImuNoise
    ratio: np.ndarray  # (3,) of the last iteration: 1 at convergence
    redundancy: np.ndarray
    iterations: int
    converged: bool
    outlier_rate: float = 0.0  # share of the stereo observations left out beyond the gate


def _noise(theta: np.ndarray, shape: np.ndarray | None = None) -> StereoImuNoise:
    """The noise of the components ``theta``; with a pixel covariance ``shape`` (trace 4) the
    stereo component scales it (θ_px · shape: the log's correlations kept, its size fitted)."""
    sigmas = [float(math.sqrt(v)) for v in theta]
    if shape is None:
        return StereoImuNoise(*sigmas)
    pixels = tuple(tuple(float(theta[0] * v) for v in row) for row in shape)
    return StereoImuNoise(*sigmas, pixel_covariance=pixels)


def _pixel_shape(noise: StereoImuNoise) -> np.ndarray | None:
    """The log's 4×4 pixel covariance scaled to trace 4 (RMS σ 1 px); None for one σ."""
    if noise.pixel_covariance is None:
        return None
    cov = noise.pixel_cov()
    return cov * (4.0 / float(np.trace(cov)))


def _component_blocks(graph: gtsam.NonlinearFactorGraph, inputs, theta: np.ndarray) -> list[sp.csr_matrix]:
    """The block-diagonal S_c of every component over the rows of ``graph`` (see the module
    docstring): identity blocks on the stereo rows for σ_px, R Q R^T blocks on the IMU rows."""
    rows = {c: ([], [], []) for c in range(3)}
    offset = 0
    between = 0
    twists = [(a.dt_s, a.twist) for a in inputs[1:]]  # the k-th IMU factor is step k + 1's input
    for i in range(graph.size()):
        factor = graph.at(i)
        dim = int(factor.dim())
        if isinstance(factor, gtsam.GenericStereoFactor3D):
            r, c, v = rows[0]
            r += list(range(offset, offset + dim))
            c += list(range(offset, offset + dim))
            v += [1.0] * dim
        elif isinstance(factor, gtsam.BetweenFactorPose3):
            dt_s, twist = twists[between]
            between += 1
            R = np.asarray(factor.noiseModel().R())
            for comp, part in ((1, V_PART), (2, W_PART)):
                Q = gtsam_covariance(imu_increment_covariance(float(dt_s), twist, part))
                block = theta[comp] * (R @ Q @ R.T)
                ii, jj = np.meshgrid(np.arange(dim), np.arange(dim), indexing="ij")
                r, c, v = rows[comp]
                r += list((offset + ii).ravel())
                c += list((offset + jj).ravel())
                v += list(block.ravel())
        offset += dim
    return [sp.csr_matrix((v, (r, c)), shape=(offset, offset)) for r, c, v in (rows[0], rows[1], rows[2])]


def fit_without_truth_3d(ready: Log3d, progress=None) -> SelfCalibration3d:
    """σ_px, σ_v and σ_ω learned from the 3-D log ``ready`` alone (module docstring), starting
    from the round defaults (the σ the log states are not read); stereo observations beyond
    the gate (:func:`_outliers`) are left out of the following iterations.
    ``progress(done, total, label)`` after each iteration."""
    start = StereoImuNoise()  # the round defaults, not the log's σ: a σ stated far too small
    # would leave its component too small a share of the residuals to be updated
    theta = np.array([start.sigma_px**2, start.sigma_v_mps**2, start.sigma_w_radps**2])
    shape = _pixel_shape(ready.noise)  # a stated 4×4 keeps its shape; θ_px scales it
    inputs = list(ready.inputs)
    observations = sum(len(a.ids) for a in ready.inputs)
    dropped: set[tuple[int, int]] = set()
    step, converged, iteration = None, False, 0
    for iteration in range(1, MAX_ITERATIONS + 1):
        smoother = _smoother(ready, _noise(theta, shape))
        try:
            run_estimator_3d(smoother, inputs, covariances=False)
        except RuntimeError as exc:  # gtsam: an indeterminate system at these σ
            raise NoiseModelError(f"the 3-D graph cannot be solved at stereo {math.sqrt(theta[0]):.3g} px, "
                                  f"IMU {math.sqrt(theta[1]):.3g} m/s, {math.sqrt(theta[2]):.3g} rad/s "
                                  f"(iteration {iteration}): {str(exc).strip().splitlines()[0]}") from None
        batch = batch_solve(smoother)
        A, b = whitened_system(smoother.graph, batch.values)
        blocks = _component_blocks(smoother.graph, inputs, theta)
        shown = np.array([float(b @ (S @ b)) for S in blocks])
        redundancy = np.array([float(S.diagonal().sum()) for S in blocks]) - hat_traces_blocks(A, blocks, columns_ordered=True)
        step = vce_from_sums(theta, shown, redundancy)
        theta = step.theta
        new = _outliers(smoother.graph, batch.values, math.sqrt(theta[0])) - dropped
        if new:
            dropped |= new
            inputs = _without(ready.inputs, dropped)
        change = float(np.max(np.abs(np.log(np.where(step.determined, step.ratio, 1.0)))))
        # settled: the σ stopped moving and the gate took (almost) nothing new
        converged = change < math.log1p(TOLERANCE) and len(new) <= NEW_OUTLIERS_SETTLED * observations
        if progress is not None:
            progress(MAX_ITERATIONS if converged else iteration, MAX_ITERATIONS, "noise fit: iterations")
        if converged:
            break
    assert step is not None
    return SelfCalibration3d(_noise(theta, shape), step.ratio, step.redundancy, iteration, converged,
                             len(dropped) / max(observations, 1))


def _outliers(graph: gtsam.NonlinearFactorGraph, values: gtsam.Values, sigma_px: float) -> set[tuple[int, int]]:
    """``(step, track id)`` of the stereo observations whose reprojection error exceeds
    :data:`GATE` σ in any coordinate, σ the larger of the current ``sigma_px`` and the robust
    σ of the errors (1.4826 × their median absolute value): a drive's mismatched tracks
    cannot inflate it, and a σ shrinking as the gate tightens cannot cascade."""
    keyed, errors = [], []
    for i in range(graph.size()):
        factor = graph.at(i)
        if isinstance(factor, gtsam.GenericStereoFactor3D):
            x, landmark = factor.keys()
            keyed.append((int(gtsam.Symbol(x).index()), int(gtsam.Symbol(landmark).index())))
            errors.append(np.asarray(factor.unwhitenedError(values), dtype=float))
    if not errors:
        return set()
    e = np.abs(np.array(errors))
    sigma = max(1.4826 * float(np.median(e)), sigma_px)
    return {k for k, row in zip(keyed, e) if np.max(row) > GATE * sigma}


def _without(inputs, dropped: set[tuple[int, int]]):
    """The step inputs without the ``(step, track id)`` observations of ``dropped``."""
    out = []
    for t, a in enumerate(inputs):
        keep = np.array([(t, int(j)) not in dropped for j in a.ids], dtype=bool)
        out.append(a if keep.all() else a._replace(ids=a.ids[keep], pixels=a.pixels[keep]))
    return out


def _smoother(ready: Log3d, noise: StereoImuNoise):
    from fgslam.smoother3d import StereoIsam2

    rig = ready.rig
    smoother = StereoIsam2(rig.K, rig.baseline_m, rig.cam_T_imu, noise)
    smoother.name = "isam2-3d"
    return smoother


def with_noise(log: RunLog, noise: StereoImuNoise) -> RunLog:
    """``log`` with every stereo observation's pixel noise (σ, or the 4×4 covariance) and every
    velocity record's covariance replaced by ``noise``'s."""
    cov = tuple(tuple(float(v) for v in row) for row in noise.velocity_cov())
    pixels = ({"sigma_px": noise.sigma_px, "covariance_px2": None} if noise.pixel_covariance is None
              else {"sigma_px": None, "covariance_px2": noise.pixel_covariance})
    records = tuple(
        dataclasses.replace(r, **pixels) if isinstance(r, StereoObservation)
        else dataclasses.replace(r, covariance=cov) if isinstance(r, VelocityOdometry) else r
        for r in log.records)
    header_noise = {**log.header.noise, "learned_without_truth": {
        "sigma_px": noise.sigma_px, "sigma_v_mps": noise.sigma_v_mps, "sigma_w_radps": noise.sigma_w_radps,
        **({} if noise.pixel_covariance is None else {"covariance_px2": [list(row) for row in noise.pixel_covariance]}),
        "method": "fgslam.self_calibration3d (variance components on the batch solution)"}}
    return dataclasses.replace(log, header=dataclasses.replace(log.header, noise=header_noise), records=records)
