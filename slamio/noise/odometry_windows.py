"""The odometry's variance learned over stretches of driving, without truth: variance-component
estimation on odometry increments chained over ``window_s`` seconds.

The odometry's error is correlated in time (MRCLAM: the turn scale measured over 10–60 s
windows varies by 0.10–0.14, docs/results-datasets.md): white per-step noise learned from each
step's residual is right at the step's own time scale and too tight over a stretch without
readings. With truth, ``fgslam calibrate --odometry-window S`` fits the rates on S-second
windows (:mod:`slamio.noise.fit_truth`). Without truth the same window is taken on the batch
solution: the steps of each window are composed into one increment ``Z_W = Π z_k``, and the
window's residual ``r_W = Log(Z_W⁻¹ · X_a⁻¹ X_b)`` (poses ``a``, ``b`` at its ends) is compared
with the variance the model's white per-step noise gives it,

    Σ_W(θ) = Σ_k Ad(P_k⁻¹) diag(q_k θ) Ad(P_k⁻¹)ᵀ = Σ_c θ_c Q_Wc,

``P_k`` the composition of the window's increments after step k (a heading error at step k
moves every later position: the chain's own propagation, as the estimator sees it). To first
order ``r_W = U_W ẽ``, ``U_W = [Ad(P_k⁻¹) L_k]_k`` applied to the whitened step residuals
``ẽ`` (``L_k = diag σ_k``), so at the least-squares solution ``Cov r_W = Σ_W − M_W`` with
``M_W = U_W H U_Wᵀ`` (H the hat matrix; estimated with the same Hutchinson probes as the
rows' traces, :func:`slamio.noise.fit_self.hat_traces_projected`). The variance-component
sums of a window (generalised least-squares VCE, Koch / Teunissen's LS-VCE, with
``A_c = Σ_W⁻¹ Q_Wc Σ_W⁻¹``):

    shown_c      = θ_c r_Wᵀ A_c r_W
    redundancy_c = θ_c (tr(Σ_W⁻¹ Q_Wc) − tr(A_c M_W))
    pairs_cd     = θ_c θ_d tr(Σ_W⁻¹ Q_Wc Σ_W⁻¹ Q_Wd)
    pair_hat_cd  = θ_c θ_d tr(Σ_W⁻¹ Q_Wc Σ_W⁻¹ M_W Σ_W⁻¹ Q_Wd)

(:func:`window_sums`). For a window of one step they are exactly the per-row sums of
:func:`slamio.noise.fit_self.scoring_step`'s inputs; over longer windows the rates are the
white noise that, chained over the window, is as large as the odometry's error over the
window. All pure numpy / scipy.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

__all__ = ["pose2_adjoint", "compose_pose2", "window_bounds", "window_maps", "window_residuals", "window_sums"]


def pose2_adjoint(pose: np.ndarray) -> np.ndarray:
    """(3, 3) the adjoint of a planar pose ``(x, y, θ)`` in GTSAM's tangent order (vx, vy, ω):
    ``Ad(T) ξ`` is ``T exp(ξ) T⁻¹``'s tangent."""
    x, y, th = (float(v) for v in pose)
    c, s = np.cos(th), np.sin(th)
    return np.array([[c, -s, y], [s, c, -x], [0.0, 0.0, 1.0]])


def compose_pose2(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a · b`` of planar poses ``(x, y, θ)``."""
    c, s = np.cos(a[2]), np.sin(a[2])
    return np.array([a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], a[2] + b[2]])


def inverse_pose2(a: np.ndarray) -> np.ndarray:
    c, s = np.cos(a[2]), np.sin(a[2])
    return np.array([-c * a[0] - s * a[1], s * a[0] - c * a[1], -a[2]])


def window_bounds(stamps_s: np.ndarray, window_s: float) -> list[tuple[int, int]]:
    """Consecutive windows of odometry steps ``[a, b)`` (step k joins pose k to k + 1): each
    the shortest run of steps spanning at least ``window_s`` seconds; the last one, shorter,
    joins the one before it unless it spans half a window."""
    t = np.asarray(stamps_s, dtype=float)
    n = len(t) - 1
    bounds, a = [], 0
    while a < n:
        b = int(np.searchsorted(t, t[a] + window_s - 1e-9, side="left"))
        b = min(max(b, a + 1), n)
        bounds.append((a, b))
        a = b
    if len(bounds) > 1 and t[bounds[-1][1]] - t[bounds[-1][0]] < 0.5 * window_s:
        bounds[-2:] = [(bounds[-2][0], bounds[-1][1])]
    return bounds


def window_maps(increments: np.ndarray, q: np.ndarray, variances: np.ndarray, bounds: list[tuple[int, int]],
                rows_of_step) -> tuple[sp.csr_matrix, np.ndarray, np.ndarray]:
    """``(U, Q, Σ)`` of the windows: ``U`` (3·W, m) maps the whitened rows of A to the
    windows' residuals (``rows_of_step(k)`` the first of step k's three rows, ``m`` =
    ``rows_of_step(None)``); ``Q`` (W, C, 3, 3) each component's share of a window's
    covariance; ``Σ`` (W, 3, 3) its covariance. ``q`` (K, 3, C) the steps' coefficients,
    ``variances`` (K, 3) the steps' factor variances."""
    W, C = len(bounds), q.shape[2]
    Q = np.zeros((W, C, 3, 3))
    S = np.zeros((W, 3, 3))
    rows, cols, vals = [], [], []
    for w, (a, b) in enumerate(bounds):
        after = np.array([0.0, 0.0, 0.0])  # P_k: the increments after step k, composed
        for k in range(b - 1, a - 1, -1):
            ad = pose2_adjoint(inverse_pose2(after))
            Q[w] += np.einsum("ij,jc,kj->cik", ad, q[k], ad)
            S[w] += (ad * variances[k]) @ ad.T
            block = ad * np.sqrt(variances[k])  # Ad · L_k
            r0 = rows_of_step(k)
            for i in range(3):
                for j in range(3):
                    rows.append(3 * w + i)
                    cols.append(r0 + j)
                    vals.append(block[i, j])
            after = compose_pose2(np.asarray(increments[k], dtype=float), after)
    U = sp.csr_matrix((vals, (rows, cols)), shape=(3 * W, rows_of_step(None)))
    return U, Q, S


def window_residuals(poses: np.ndarray, increments: np.ndarray, bounds: list[tuple[int, int]]) -> np.ndarray:
    """(W, 3) ``Log(Z_W⁻¹ · X_a⁻¹ X_b)`` of every window (``poses`` (K+1, 3) the solution,
    ``increments`` (K, 3) the odometry); the log map of SE(2) in GTSAM's order."""
    out = np.zeros((len(bounds), 3))
    for w, (a, b) in enumerate(bounds):
        z = np.zeros(3)
        for k in range(a, b):
            z = compose_pose2(z, np.asarray(increments[k], dtype=float))
        moved = compose_pose2(inverse_pose2(poses[a]), poses[b])
        d = compose_pose2(inverse_pose2(z), moved)
        out[w] = _log_pose2(np.array([d[0], d[1], np.arctan2(np.sin(d[2]), np.cos(d[2]))]))
    return out


def _log_pose2(d: np.ndarray) -> np.ndarray:
    th = d[2]
    half = 0.5 * th
    # half·cot(half), by its series where 1 − cos θ loses its digits
    a = 1.0 - th * th / 12.0 if abs(th) < 1e-4 else half * np.sin(th) / (1.0 - np.cos(th))
    return np.array([a * d[0] + half * d[1], -half * d[0] + a * d[1], th])


def window_sums(theta: np.ndarray, residuals: np.ndarray, Q: np.ndarray, S: np.ndarray,
                M: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(shown, redundancy, pair_sums, pair_hat)`` of the windows (module docstring) for the
    C components of ``theta``: ``residuals`` (W, 3), ``Q`` (W, C, 3, 3), ``S`` (W, 3, 3) the
    windows' covariances, ``M`` (W, 3, 3) = ``U_W H U_Wᵀ``; the pair arrays flattened (C·C,)
    as :func:`slamio.noise.fit_self.scoring_step` takes them."""
    theta = np.asarray(theta, dtype=float)
    Si = np.linalg.inv(S)
    B = np.einsum("wij,wcjk->wcik", Si, Q) * theta[None, :, None, None]  # θ_c Σ⁻¹ Q_c
    A = np.einsum("wcij,wjk->wcik", B, Si)  # θ_c Σ⁻¹ Q_c Σ⁻¹
    shown = np.einsum("wi,wcij,wj->c", residuals, A, residuals)
    redundancy = np.einsum("wcii->c", B) - np.einsum("wcij,wji->c", A, M)
    pairs = np.einsum("wcij,wdji->cd", B, B)
    BM = np.einsum("wcij,wjk->wcik", A, M)  # θ_c Σ⁻¹ Q_c Σ⁻¹ M
    pair_hat = np.einsum("wcij,wdji->cd", BM, B)
    pair_hat = 0.5 * (pair_hat + pair_hat.T)
    return shown, redundancy, pairs.reshape(-1), pair_hat.reshape(-1)
