"""The covariance arithmetic of EKF-SLAM over a growing state, each step O(n) or O(n²).

``P`` is the n×n joint covariance with the robot pose in rows and columns 0–2 and the
landmarks after it (:class:`ekf.slam.EkfSlam` holds it). Every function here is pure
arithmetic on numpy arrays; the ones named "in place" write into ``P`` (or the buffer that
holds it) instead of returning a new n×n matrix, because at n in the thousands that copy
would cost more than the step. Each is checked against the dense textbook formula in
``tests/test_ekf.py``.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import blas as _blas

from ekf.models import ROBOT_DIM

__all__ = [
    "predict_covariance",
    "augment_covariance",
    "kalman_gain",
    "joseph_factors",
    "joseph_update",
    "add_low_rank_in_place",
]


def predict_covariance(P: np.ndarray, F_pose: np.ndarray, Q: np.ndarray) -> None:
    """Propagate the covariance through the motion model, **in place**, in O(n).

    ``P`` is the n×n joint covariance with the robot in rows/columns 0–2. The motion
    Jacobian of the full state is ``blockdiag(F_pose, I)``, so only the robot rows and
    columns change::

        P_rr ← F P_rr Fᵀ + Q,    P_rm ← F P_rm,    P_mr ← P_rmᵀ
    """
    r = slice(0, ROBOT_DIM)
    m = slice(ROBOT_DIM, P.shape[0])
    P[r, r] = F_pose @ P[r, r] @ F_pose.T + Q
    P[r, m] = F_pose @ P[r, m]
    P[m, r] = P[r, m].T


def augment_covariance(
    P: np.ndarray, n: int, G_pose: np.ndarray, G_measurement: np.ndarray, R: np.ndarray
) -> None:
    """Fill rows/columns ``n … n+k−1`` of ``P`` for a new k-dimensional landmark, **in place**, in O(n).

    ``P[:n, :n]`` is the covariance before augmentation; ``P`` must have room for k more
    rows and columns (k = ``G_pose.shape[0]``: 2 for a point, 3 with a height). The new
    landmark l = g(pose, z) gets

        P_ll = G_p P_rr G_pᵀ + G_z R G_zᵀ     (own covariance)
        P_lx = G_p P_rx                        (with the robot and every old landmark)
    """
    new = slice(n, n + G_pose.shape[0])
    P_lx = G_pose @ P[:ROBOT_DIM, :n]  # 2×n
    P[new, :n] = P_lx
    P[:n, new] = P_lx.T
    P[new, new] = G_pose @ P[:ROBOT_DIM, :ROBOT_DIM] @ G_pose.T + G_measurement @ R @ G_measurement.T


def kalman_gain(
    P: np.ndarray, cols: np.ndarray, H_cols: np.ndarray, R: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Kalman gain for a measurement whose Jacobian H is zero outside the columns ``cols``.

    ``H_cols`` (m×k) holds the non-zero columns of the m×n Jacobian H. Returns
    ``(K n×m, S m×m, PHt n×m)`` with ``PHt = P Hᵀ``, ``S = H P Hᵀ + R`` and
    ``K = PHt S⁻¹``, all in O(n·k).
    """
    PHt = P[:, cols] @ H_cols.T
    S = H_cols @ PHt[cols, :] + R
    S = 0.5 * (S + S.T)
    K = np.linalg.solve(S, PHt.T).T
    return K, S, PHt


def joseph_factors(
    P: np.ndarray, cols: np.ndarray, H_cols: np.ndarray, K: np.ndarray, R: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Factors ``(X, Y)``, both n×4m, of the Joseph-form update: ``P_new = P + X Yᵀ``.

    The Joseph form ``P_new = (I − KH) P (I − KH)ᵀ + K R Kᵀ`` is valid for any gain K
    (not only the optimal one). H is given by its non-zero columns ``cols`` and their values
    ``H_cols`` (m×k, k = 5 for a landmark observation), which makes it O(n²) instead of
    the O(n³) of the dense formula:

    * ``A = (I − KH) P = P − K (P Hᵀ)ᵀ``; only A's columns ``cols`` are formed (n×k);
    * ``A (I − KH)ᵀ = A − (A Hᵀ) Kᵀ`` with ``A Hᵀ = A[:, cols] H_colsᵀ`` (n×m);
    * so ``P_new = P + U Vᵀ`` with ``U = [−K, K R − A Hᵀ]`` and ``V = [P Hᵀ, K]`` (n×2m).

    The increment is returned symmetrised, ``½(U Vᵀ + V Uᵀ) = X Yᵀ`` with
    ``X = ½[U, V]`` and ``Y = [V, U]``: for a symmetric P this *is* the symmetric part of
    ``P + U Vᵀ``, obtained without a pass over P (``P ← ½(P + Pᵀ)`` would cost two, one
    of them a cache-unfriendly transpose). P stays symmetric to round-off, without drift.
    Everything here is O(n·k); no n×n identity or n×n×n product is formed.
    """
    Pc = P[:, cols]  # n×k
    PHt = Pc @ H_cols.T  # n×m
    A_cols = Pc - K @ PHt[cols, :].T  # columns `cols` of A = (I − KH) P
    AHt = A_cols @ H_cols.T  # A Hᵀ
    U = np.hstack([-K, K @ R - AHt])  # n×2m
    V = np.hstack([PHt, K])  # n×2m
    return 0.5 * np.hstack([U, V]), np.hstack([V, U])


def joseph_update(
    P: np.ndarray, cols: np.ndarray, H_cols: np.ndarray, K: np.ndarray, R: np.ndarray
) -> None:
    """Joseph-form covariance update ``P ← (I − KH) P (I − KH)ᵀ + K R Kᵀ``, **in place**, O(n²).

    See :func:`joseph_factors` for the arithmetic; the result is symmetrised.
    """
    X, Y = joseph_factors(P, cols, H_cols, K, R)
    P += X @ Y.T


def add_low_rank_in_place(buffer: np.ndarray, n: int, X: np.ndarray, Y: np.ndarray) -> None:
    """``buffer[:n, :n] += X Yᵀ`` for n×r factors X, Y, without an n×n temporary.

    This is the single O(n²) pass of an EKF update, so it is worth doing well: when
    ``buffer`` is Fortran-ordered, its first n columns ``buffer[:, :n]`` are one contiguous
    block and BLAS ``dgemm`` accumulates into it directly (X is padded with zero rows to
    the buffer's height, so rows n and beyond get ``+= 0``). That is about 3× faster than
    numpy's ``P += X @ Y.T`` on a strided view, which writes and re-reads a temporary.
    Any other buffer takes the plain numpy path.
    """
    block = buffer[:, :n]
    if block.flags.f_contiguous and buffer.dtype == np.float64:
        X_padded = np.zeros((buffer.shape[0], X.shape[1]), order="F")
        X_padded[:n] = X
        out = _blas.dgemm(1.0, X_padded, Y, beta=1.0, c=block, trans_b=1, overwrite_c=1)
        if not np.shares_memory(out, block):  # the wrapper had to copy: write it back
            block[...] = out
    else:
        buffer[:n, :n] += X @ Y.T
