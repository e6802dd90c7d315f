"""The 3-D estimators' noise (:class:`StereoImuNoise`): read from a 3-D run log, and the
stereo noise model of the factor graph.

:func:`noise_of` is the one noise level a log states (every stereo observation the same
pixel noise, every velocity record the same covariance). :func:`stereo_factor_noise` is the
Gaussian of GTSAM's stereo factor, which measures (u_L, u_R, v) with one v for both rows
(:func:`slamio.stereo.mean_row_covariance`).
"""

from __future__ import annotations

import math

import numpy as np

from slamio.datasets.seed003 import StereoImuNoise
from slamio.errors import FgslamError
from slamio.log import RunLog
from slamio.stereo import mean_row_covariance, rms_sigma_px

__all__ = ["noise_of", "stereo_factor_noise"]


def noise_of(log: RunLog, steps=None) -> StereoImuNoise:
    """The one noise level the 3-D estimators assume, read from the log's records.

    Every ``stereo_observation`` must carry the same pixel noise — one ``sigma_px``, or one
    4×4 ``covariance_px2`` — and every ``velocity_odometry`` the same covariance: any
    symmetric positive-definite 6×6, per axis or correlated, as the dataset states it
    (``fgslam import seed003`` and ``fgslam sim stereo-loop`` write one σ for the three linear
    and one for the three angular axes). ``steps``: the log's steps when the caller has
    grouped them already.
    """
    steps = log.steps() if steps is None else steps
    if hasattr(steps, "noise_levels"):  # a log read into columns: without building its steps
        pixel_noises, covs = steps.noise_levels()
    else:
        pixel_noises = {(o.sigma_px, o.covariance_px2) for s in steps for o in s.observations}
        covs = {s.odometry.covariance for s in steps if s.odometry is not None}
    if len(pixel_noises) > 1 or len(covs) > 1:
        raise FgslamError(
            f"{log.path}: the 3-D estimators assume one noise level, but the records carry {len(pixel_noises)} "
            f"different pixel noises ('sigma_px' or 'covariance_px2') and {len(covs)} velocity covariances; write "
            "the same pixel σ (or the same 4×4 pixel covariance) and the same velocity covariance on every record"
        )
    sigma_px, pixel_covariance = pixel_noises.pop() if pixel_noises else (StereoImuNoise().sigma_px, None)
    pixels = {"sigma_px": sigma_px} if pixel_covariance is None else {
        "sigma_px": rms_sigma_px(pixel_covariance),  # a summary only: the covariance rules
        "pixel_covariance": pixel_covariance,
    }
    if not covs:
        return StereoImuNoise(**pixels)
    cov = np.array(covs.pop())
    diag = np.diag(cov)
    if np.all(cov == np.diag(diag)) and np.ptp(diag[:3]) == 0 and np.ptp(diag[3:]) == 0:
        return StereoImuNoise(**pixels, sigma_v_mps=math.sqrt(diag[0]), sigma_w_radps=math.sqrt(diag[3]))
    if not np.allclose(cov, cov.T) or np.any(np.linalg.eigvalsh(0.5 * (cov + cov.T)) <= 0.0):
        raise FgslamError(f"{log.path}: the velocity covariance {cov.tolist()} is not symmetric positive definite")
    return StereoImuNoise(**pixels, velocity_covariance=tuple(tuple(float(v) for v in row) for row in cov))


def stereo_factor_noise(noise: StereoImuNoise):
    """The Gaussian noise model of ``GenericStereoFactor3D``'s (u_L, u_R, v), v = (v_L + v_R)/2:
    ``Diagonal.Sigmas(σ, σ, σ/√2)`` for one ``sigma_px``, else ``Gaussian.Covariance(A Σ Aᵀ)``
    of the 4×4 pixel covariance (:func:`slamio.stereo.mean_row_covariance`)."""
    import gtsam

    if noise.pixel_covariance is None:
        sigma = noise.sigma_px
        return gtsam.noiseModel.Diagonal.Sigmas(np.array([sigma, sigma, sigma / math.sqrt(2.0)]))
    return gtsam.noiseModel.Gaussian.Covariance(mean_row_covariance(noise.pixel_cov()))
