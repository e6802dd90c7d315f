"""The rectified stereo camera of seed 003: projection, its Jacobian and back-projection.

Pixels are stacked ``z = (u_L, v_L, u_R, v_R)`` — the order of the seed's data and of the
rows of its stereo matrix M (eq. 1). Points are in the left camera's *optical* frame
(x right, y down, z forward), homogeneous ``q = (x, y, z, 1)`` where a 4-vector is asked for.

    M = [[fs_u, 0, c_u, 0], [0, fs_v, c_v, 0], [fs_u, 0, c_u, −fs_u b], [0, fs_v, c_v, 0]]
    z = M π(q),   π(q) = q / q_z                                     (eq. 1 with π)
    d = u_L − u_R = fs_u b / z  ⇒  z = fs_u b / (u_L − u_R)          (eqs. 2–3)
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "MEAN_ROW",
    "disparity_depth_m",
    "mean_row_covariance",
    "rms_sigma_px",
    "rectified_pixel_covariance",
    "point_from_stereo",
    "point_from_stereo_jacobian",
    "projection",
    "projection_jacobian",
    "stereo_matrix",
    "stereo_pixels",
]


def stereo_matrix(K, baseline_m: float) -> np.ndarray:
    """Seed 003's 4×4 stereo matrix M (eq. 1) from the left intrinsics K and the baseline."""
    K = np.asarray(K, dtype=float)
    fsu, fsv, cu, cv = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    return np.array(
        [
            [fsu, 0.0, cu, 0.0],
            [0.0, fsv, cv, 0.0],
            [fsu, 0.0, cu, -fsu * float(baseline_m)],
            [0.0, fsv, cv, 0.0],
        ]
    )


def projection(q) -> np.ndarray:
    """π(q) = q / q_z for a homogeneous optical-frame point (4-vector)."""
    q = np.asarray(q, dtype=float)
    return q / q[2]


def projection_jacobian(q) -> np.ndarray:
    """4×4 dπ/dq = (1/q_z) [[1, 0, −x/z, 0], [0, 1, −y/z, 0], [0, 0, 0, 0], [0, 0, −w/z, 1]]."""
    x, y, z, w = (float(c) for c in q)
    return np.array(
        [
            [1.0, 0.0, -x / z, 0.0],
            [0.0, 1.0, -y / z, 0.0],
            [0.0, 0.0, 0.0, 0.0],
            [0.0, 0.0, -w / z, 1.0],
        ]
    ) / z


def stereo_pixels(M, q) -> np.ndarray:
    """(u_L, v_L, u_R, v_R) of the optical-frame point q (3- or 4-vector): M π(q)."""
    q = np.asarray(q, dtype=float)
    if q.shape == (3,):
        q = np.append(q, 1.0)
    return np.asarray(M, dtype=float) @ projection(q)


def disparity_depth_m(u_left_px, u_right_px, fsu_px: float, baseline_m: float):
    """Depth from disparity, eq. 3 with its parentheses: ``fs_u b / (u_L − u_R)``."""
    return fsu_px * baseline_m / (np.asarray(u_left_px, dtype=float) - np.asarray(u_right_px, dtype=float))


def point_from_stereo(z, K, baseline_m: float) -> np.ndarray:
    """Optical-frame point (x, y, z) seen at pixels ``z = (u_L, v_L, u_R, v_R)``.

    Depth from the disparity (eq. 3), then ``depth · K⁻¹ (u_L, v_L, 1)`` (eq. 19 before
    the frames). v_R is not used (rectified images: it repeats v_L).
    """
    K = np.asarray(K, dtype=float)
    uL, vL, uR = float(z[0]), float(z[1]), float(z[2])
    fsu, fsv, cu, cv = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    depth = disparity_depth_m(uL, uR, fsu, baseline_m)
    return np.array([(uL - cu) * depth / fsu, (vL - cv) * depth / fsv, depth])


def point_from_stereo_jacobian(z, K, baseline_m: float) -> np.ndarray:
    """3×4 derivative of :func:`point_from_stereo` with respect to (u_L, v_L, u_R, v_R)."""
    K = np.asarray(K, dtype=float)
    uL, vL, uR = float(z[0]), float(z[1]), float(z[2])
    fsu, fsv, cu, cv = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    d = uL - uR
    depth = fsu * baseline_m / d
    dz_duL = -depth / d  # ∂depth/∂u_L; ∂depth/∂u_R = +depth/d
    J = np.zeros((3, 4))
    J[2, 0], J[2, 2] = dz_duL, -dz_duL
    J[0, 0] = depth / fsu + (uL - cu) / fsu * dz_duL
    J[0, 2] = (uL - cu) / fsu * (-dz_duL)
    J[1, 1] = depth / fsv
    J[1, 0] = (vL - cv) / fsv * dz_duL
    J[1, 2] = (vL - cv) / fsv * (-dz_duL)
    return J


#: A: (u_L, v_L, u_R, v_R) → (u_L, u_R, (v_L + v_R)/2), what a one-row stereo model (GTSAM's
#: ``StereoPoint2``) measures.
MEAN_ROW = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.5, 0.0, 0.5]])


def mean_row_covariance(pixel_cov) -> np.ndarray:
    """3×3 covariance of (u_L, u_R, v) with v = (v_L + v_R)/2, from the 4×4 covariance of
    (u_L, v_L, u_R, v_R) in px²: ``A Σ Aᵀ`` (:data:`MEAN_ROW`). With Σ = σ² I it is diag(σ², σ², σ²/2).

    The difference d = v_L − v_R is 0 whatever the point (rectified rows): the mean row keeps
    all the information of the four pixels when d is uncorrelated with (u_L, u_R, v) — equal
    variances of v_L and v_R and no u–v correlation, the usual case. Otherwise the part of
    their errors that d would reveal (conditioning on it) is given up: the model stays
    consistent, only slightly less precise than the full 4-D one.
    """
    return MEAN_ROW @ np.asarray(pixel_cov, dtype=float) @ MEAN_ROW.T


def rms_sigma_px(pixel_cov) -> float:
    """One σ (px) summing up a 4×4 pixel covariance: √(trace / 4), the σ of an isotropic noise
    of the same total variance."""
    return float(np.sqrt(np.trace(np.asarray(pixel_cov, dtype=float)) / 4.0))


def rectified_pixel_covariance(sigma_u_px: float, sigma_v_px: float, row_correlation: float,
                               column_correlation: float = 0.0) -> np.ndarray:
    """4×4 covariance of (u_L, v_L, u_R, v_R) in px² for rectified stereo: σ_u on both u, σ_v
    on both v, v_L and v_R correlated ``row_correlation`` (read on one row), u_L and u_R
    ``column_correlation``; u and v uncorrelated."""
    if not (sigma_u_px > 0.0 and sigma_v_px > 0.0 and abs(row_correlation) < 1.0 and abs(column_correlation) < 1.0):
        raise ValueError(f"need σ_u, σ_v > 0 and correlations in (−1, 1), got {sigma_u_px}, {sigma_v_px}, "
                         f"{row_correlation}, {column_correlation}")
    u, v = sigma_u_px**2, sigma_v_px**2
    return np.array([
        [u, 0.0, column_correlation * u, 0.0],
        [0.0, v, 0.0, row_correlation * v],
        [column_correlation * u, 0.0, u, 0.0],
        [0.0, row_correlation * v, 0.0, v],
    ])
