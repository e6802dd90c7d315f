"""Noise learned from a run itself: variance-component estimation (VCE) on a smoothed solution.

Without ground truth, the only evidence about the noise is how well the measurements agree
with each other once the whole run is smoothed. Each measurement row ``j`` (one component of
an odometry increment, one bearing, one range) has a variance that is a non-negative
combination of a few *variance components* θ_c with known coefficients,

    σ_j² = Σ_c θ_c · q_jc,

e.g. a forward increment's ``q`` is (distance, duration) for the components
(``forward_m2_per_m``, ``forward_m2_per_s``) and a range's is (1, r²) for
(``range_sigma_m²``, ``range_sigma_per_m²``): the terms of :class:`~slamio.noise.model.NoiseModel`.

At the least-squares solution the whitened residuals ``ẽ`` are smaller than the whitened
errors, because the solution absorbs part of each error: ``E[ẽ_j²] = 1 − h_jj`` where
``h_jj`` is the diagonal of the hat matrix ``H = A (AᵀA)⁻¹ Aᵀ`` of the whitened Jacobian
``A`` (``1 − h_jj`` is row j's *redundancy number*; they sum to rows − unknowns). Förstner's
iterative VCE (the Helmert / LS-VCE family) updates every component by the ratio of what its
rows show to what they should show:

    θ_c ← θ_c · Σ_j w_jc ẽ_j² / Σ_j w_jc (1 − h_jj),      w_jc = θ_c q_jc / σ_j²,

``w_jc`` being the share of row j's variance that component c explains. The update is
multiplicative, so components stay positive; at its fixed point every component's rows show
exactly their redundancy. ``Σ_j w_jc h_jj`` is a weighted trace of ``H``, estimated with
Hutchinson's method (Rademacher probes ``z``: ``E[z ⊙ Hz] = diag H``), one sparse
factorisation of ``AᵀA`` and one solve per block of probes.

The same ratio is the verdict of a run (:mod:`fgslam.verdict`): per noise group, the
whitened χ² of the smoothed solution over its redundancy; 1 when the stated noise fits the
data, ``k²`` when the stated σ are ``k``× too small.

All pure (numpy, scipy); the factor graph that supplies ``A`` and ``ẽ`` is built by
:mod:`fgslam.self_calibration`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from slamio.noise.errors import NoiseModelError

__all__ = ["LagFromReadings", "VceStep", "component_shares", "hat_traces", "hat_traces_blocks", "lag_from_readings",
           "parabola_minimum", "ranges_from_readings", "scaled_increments",
           "pair_weights", "relative_std", "scoring_step", "vce_from_sums", "vce_step"]

#: Hutchinson probes for the traces: the weighted traces are sums over thousands of rows, and
#: 96 probes put their relative error at about a per cent on a 2 000-pose run.
PROBES = 96
#: Probes solved at once: each is a vector over every row (140 000 on a long stereo drive);
#: 8 at a time take a quarter of the memory of 32 for the same time (drawn 32 at a time all
#: the same, so the seeded probes, and every figure from them, are unchanged).
PROBE_BLOCK = 8
#: A component whose rows hold less redundancy than this is not updated (the data say
#: nothing about it): it keeps its value and is reported as not determined.
MIN_REDUNDANCY = 3.0
#: At most this factor of change per iteration (the first iterations from a round guess can
#: be far off; the cap keeps the re-solved graph near its last solution).
MAX_STEP_FACTOR = 30.0


def component_shares(theta: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(σ², w)`` of every row: its variance ``q @ θ`` (m,) and the share ``w`` (m, C) of it
    each component explains (rows of ``w`` sum to 1, or 0 where ``q`` is all zero: rows that
    belong to no component, such as a prior)."""
    theta = np.asarray(theta, dtype=float)
    q = np.asarray(q, dtype=float)
    var = q @ theta
    with np.errstate(invalid="ignore", divide="ignore"):
        w = np.where(var[:, None] > 0.0, q * theta[None, :] / var[:, None], 0.0)
    return var, w


def _probed(A: sp.spmatrix, probes: int, seed: int, columns_ordered: bool = False):
    """Hutchinson's probes of the hat matrix ``H = A (AᵀA)⁻¹ Aᵀ``: yields ``(z, Hz)`` blocks of
    Rademacher vectors (seeded, :data:`PROBE_BLOCK` columns at a time) after one sparse factorisation
    of ``AᵀA``; :class:`NoiseModelError` when it is singular (a variable no measurement fixes).

    ``columns_ordered``: A's columns already come in a fill-reducing order (as
    :func:`fgslam.linearized.whitened_system` gives them), factorised in that order; else
    SuperLU orders them (minimum degree on AᵀA, which on some graphs fills in 5× as much:
    890 MB against 170 MB on a long stereo drive). H does not depend on the columns' order."""
    A = sp.csr_matrix(A)
    m, _ = A.shape
    try:
        lu = spla.splu((A.T @ A).tocsc(), permc_spec="NATURAL" if columns_ordered else "MMD_AT_PLUS_A",
                       options={"SymmetricMode": True})
    except RuntimeError as exc:  # "Factor is exactly singular"
        raise NoiseModelError(f"the smoothing problem is singular ({exc}): a pose or landmark no "
                              "measurement fixes") from None
    rng = np.random.default_rng(seed)
    done = 0
    while done < probes:  # drawn 32 at a time (the seeded probes stay what they were), solved a few at a time
        drawn = rng.choice((-1.0, 1.0), size=(m, min(32, probes - done)))
        for first in range(0, drawn.shape[1], PROBE_BLOCK):
            z = drawn[:, first:first + PROBE_BLOCK]
            yield z, A @ lu.solve(np.asarray(A.T @ z))
        done += drawn.shape[1]


def hat_traces(A: sp.spmatrix, weights: np.ndarray, probes: int = PROBES, seed: int = 0, *,
               columns_ordered: bool = False) -> np.ndarray:
    """``Σ_j weights[j, c] · h_jj`` for every column c of ``weights`` (m, C), ``h`` the diagonal
    of the hat matrix of the whitened Jacobian ``A`` (m × n, full column rank).

    Hutchinson's estimator with ``probes`` Rademacher vectors (seeded: the same answer every
    run; ``columns_ordered`` as :func:`_probed`). Raises :class:`NoiseModelError` when ``AᵀA``
    is singular (a variable no measurement fixes)."""
    out = np.zeros(weights.shape[1])
    for z, hz in _probed(A, probes, seed, columns_ordered):
        out += weights.T @ np.sum(z * hz, axis=1)
    return out / probes


def hat_traces_blocks(A: sp.spmatrix, blocks: list[sp.spmatrix], probes: int = PROBES, seed: int = 0, *,
                      columns_ordered: bool = False) -> np.ndarray:
    """``tr(S_c H)`` for every (m × m, sparse, block-diagonal) ``S_c`` of ``blocks``: the
    weighted traces of :func:`hat_traces` when a row's variance components are not on the
    diagonal (a 6×6 IMU increment covariance split into its speed and turn-rate parts, seen
    in whitened coordinates). Hutchinson's estimator, seeded; ``columns_ordered`` as :func:`_probed`."""
    out = np.zeros(len(blocks))
    for z, hz in _probed(A, probes, seed, columns_ordered):
        out += [float(np.sum(z * (S @ hz))) for S in blocks]
    return out / probes


@dataclass(frozen=True)
class VceStep:
    """One VCE iteration: the new components and what each one's rows showed."""

    theta: np.ndarray  # (C,) the updated components
    ratio: np.ndarray  # (C,) Σ w ẽ² / redundancy: 1 at the fixed point; NaN where not determined
    redundancy: np.ndarray  # (C,) Σ_j w_jc (1 − h_jj)
    determined: np.ndarray  # (C,) bool: enough redundancy to update


def vce_step(theta: np.ndarray, whitened_sq: np.ndarray, weights: np.ndarray, hat: np.ndarray,
             min_redundancy: float = MIN_REDUNDANCY, max_factor: float = MAX_STEP_FACTOR) -> VceStep:
    """The Förstner update of every component (module docstring) from the squared whitened
    residuals ``whitened_sq`` (m,), the shares ``weights`` (m, C) and ``hat`` = the weighted
    traces of :func:`hat_traces` (summed over several runs' graphs when they share the
    components)."""
    theta = np.asarray(theta, dtype=float)
    shown = np.asarray(weights).T @ np.asarray(whitened_sq, dtype=float)
    return vce_from_sums(theta, shown, np.asarray(weights).sum(axis=0) - np.asarray(hat), min_redundancy, max_factor)


def vce_from_sums(theta: np.ndarray, shown: np.ndarray, redundancy: np.ndarray,
                  min_redundancy: float = MIN_REDUNDANCY, max_factor: float = MAX_STEP_FACTOR) -> VceStep:
    """:func:`vce_step` from its sums (``shown`` = Σ w ẽ², ``redundancy`` = Σ w (1 − h)) per
    component, e.g. pooled over several runs."""
    determined = redundancy >= min_redundancy
    ratio = np.full(len(theta), np.nan)
    ratio[determined] = shown[determined] / redundancy[determined]
    factor = np.where(determined, np.clip(np.nan_to_num(ratio, nan=1.0), 1.0 / max_factor, max_factor), 1.0)
    return VceStep(theta * factor, ratio, redundancy, determined)


def pair_weights(weights: np.ndarray) -> np.ndarray:
    """(m, C·C) the products ``w_jc · w_jd`` of every pair of components (for the traces of
    the information matrix of :func:`scoring_step`)."""
    w = np.asarray(weights, dtype=float)
    return (w[:, :, None] * w[:, None, :]).reshape(len(w), -1)


def scoring_step(theta: np.ndarray, shown: np.ndarray, redundancy: np.ndarray, pair_sums: np.ndarray,
                 pair_hat: np.ndarray, min_redundancy: float = MIN_REDUNDANCY,
                 max_factor: float = MAX_STEP_FACTOR) -> VceStep:
    """A Fisher-scoring step on log θ with the same fixed point as :func:`vce_from_sums`.

    The log-likelihood's gradient in log θ_c is ``½ (Σ w ẽ² − Σ w (1 − h))`` and its
    information ``F_cd ≈ ½ Σ_j w_jc w_jd (1 − h_jj)`` (``pair_sums`` = Σ w_c w_d, ``pair_hat``
    = Σ w_c w_d h, both (C·C,)). Where two components are nearly interchangeable (a robot
    that always drove at one speed cannot tell per metre from per second), Förstner's
    multiplicative update crawls along the ridge; this step crosses it at once, and the
    pseudo-inverse leaves the direction the data do not see where it was."""
    theta = np.asarray(theta, dtype=float)
    C = len(theta)
    determined = redundancy >= min_redundancy
    ratio = np.full(C, np.nan)
    ratio[determined] = shown[determined] / redundancy[determined]
    gradient = 0.5 * (shown - redundancy)
    info = 0.5 * (np.asarray(pair_sums) - np.asarray(pair_hat)).reshape(C, C)
    delta = np.zeros(C)
    idx = np.flatnonzero(determined)
    if len(idx):
        sub = info[np.ix_(idx, idx)]
        sub = 0.5 * (sub + sub.T)
        delta[idx] = np.linalg.pinv(sub, rcond=1e-6, hermitian=True) @ gradient[idx]
    bound = np.log(max_factor)
    return VceStep(theta * np.exp(np.clip(delta, -bound, bound)), ratio, redundancy, determined)


def relative_std(theta: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """(C,) the standard deviation of each component relative to its value, from the
    Fisher information of Gaussian rows (``F_cd = ½ Σ_j w_jc w_jd`` for log θ): large (≥ 0.5)
    when the data cannot tell that component from the others (e.g. per-metre and per-second
    terms of a robot that always drove at one speed); inf where the information is singular."""
    weights = np.asarray(weights, dtype=float)
    info = 0.5 * weights.T @ weights
    out = np.full(len(theta), np.inf)
    used = np.diag(info) > 1e-9
    if not used.any():
        return out
    sub = info[np.ix_(used, used)]
    try:
        cov = np.linalg.inv(sub)
    except np.linalg.LinAlgError:
        return out
    d = np.diag(cov)
    out[used] = np.where(d > 0.0, np.sqrt(np.abs(d)), np.inf)
    if np.linalg.cond(sub) > 1e12:
        out[used] = np.maximum(out[used], 1.0)
    return out


# --------------------------------------------------------------------------- the odometry's lag

#: The lags tried (s): commands lead the motion by a few tenths of a second.
LAG_GRID_S = tuple(float(v) for v in np.round(np.arange(0.0, 0.501, 0.02), 2))
#: Two readings of one landmark at most this far apart are a pair.
PAIR_MAX_DT_S = 1.0


@dataclass(frozen=True)
class LagFromReadings:
    """What consecutive readings of the same landmarks say about the odometry's lag."""

    lag_s: float
    cost: np.ndarray  # (lags,) median squared bearing miss, rad²
    pairs: int


def lag_from_readings(chain, readings: list[tuple[float, int, float, float]],
                      lags_s: tuple[float, ...] = LAG_GRID_S) -> LagFromReadings:
    """The odometry's lag learned from the readings alone.

    For consecutive readings of one landmark ``(stamp, landmark, range, bearing)`` taken
    less than :data:`PAIR_MAX_DT_S` apart, the first reading's point is carried to the second
    reading's time by the odometry's motion between the two stamps shifted by the lag (the
    robot moves ``lag`` after its odometry says so), and the second reading's bearing is
    predicted. The lag whose predictions miss least (the median squared miss, robust to
    misread landmarks) is the one the data show: a turn commanded at t is seen by the camera
    at t + lag. Needs no truth and no noise model; ``chain`` is the odometry as a
    :class:`~slamio.noise.dead_reckoning.DeadReckoning`.

    The same search over a turn scale as well (a bearing is an angle: the true turn shows in
    it) found 0.83–0.88 on the MRCLAM Dataset 6 robots where Vicon says 0.948, and made
    the estimates worse, so the turn scale is not learned here (docs/results-datasets.md).
    The bias is not the odometry's: with Vicon's own increments in place of the odometry
    the same search finds 0.82–0.86 where the truth is 1 by construction (and the same with
    the camera's fitted range model, depth +4.7 cm). Over pairs less than a second apart
    the turn is small and its error (the readings' stamps, the short-term motion) is of its
    size, so the fitted ratio is diluted towards 0 (errors in the regressor).
    """
    rows = sorted(readings, key=lambda r: (r[1], r[0]))
    pairs = [(a, b) for a, b in zip(rows, rows[1:]) if a[1] == b[1] and 0.0 < b[0] - a[0] <= PAIR_MAX_DT_S]
    cost = np.full(len(lags_s), np.inf)
    if len(pairs) < 20:
        return LagFromReadings(0.0, cost, len(pairs))
    t1 = np.array([a[0] for a, _ in pairs])
    t2 = np.array([b[0] for _, b in pairs])
    r1, b1 = np.array([a[2] for a, _ in pairs]), np.array([a[3] for a, _ in pairs])
    b2 = np.array([b[3] for _, b in pairs])
    px, py = r1 * np.cos(b1), r1 * np.sin(b1)  # the point in the first reading's frame
    for i, lag in enumerate(lags_s):
        pa, pb = _poses_at(chain, t1 - lag), _poses_at(chain, t2 - lag)
        ok = np.isfinite(pa[:, 0]) & np.isfinite(pb[:, 0])
        if ok.sum() < 20:
            continue
        c, s = np.cos(pa[ok, 2]), np.sin(pa[ok, 2])
        dxw, dyw = pb[ok, 0] - pa[ok, 0], pb[ok, 1] - pa[ok, 1]
        dx, dy = c * dxw + s * dyw, -s * dxw + c * dyw  # the motion in the first frame
        predicted = np.arctan2(py[ok] - dy, px[ok] - dx) - (pb[ok, 2] - pa[ok, 2])
        miss = np.angle(np.exp(1j * (b2[ok] - predicted)))
        cost[i] = float(np.median(miss**2))
    return LagFromReadings(float(lags_s[int(np.argmin(cost))]), cost, len(pairs))


def _poses_at(chain, t_s: np.ndarray) -> np.ndarray:
    """(n, 3) chain poses at the times (NaN outside the run)."""
    out = np.full((len(t_s), 3), np.nan)
    for k, t in enumerate(t_s):
        pose = chain.pose_at(float(t))
        if pose is not None:
            out[k] = pose
    return out


# --------------------------------------------------------------------------- scales on the whole run

def scaled_increments(increments: np.ndarray, forward_scale: float, turn_scale: float,
                      turn_per_m_rad: float) -> np.ndarray:
    """(n, 3) odometry increments ``(dx, dy, dθ)`` re-read with the odometry's scales, as
    :func:`slamio.noise.apply.apply_noise_model` does: ``(dx, dy)·forward_scale`` and
    ``dθ·turn_scale + turn_per_m_rad·(scaled distance)``, the distance counted negative when
    driving backwards."""
    inc = np.asarray(increments, dtype=float).reshape(-1, 3)
    out = inc.copy()
    out[:, :2] *= forward_scale
    distance = np.hypot(out[:, 0], out[:, 1]) * np.where(out[:, 0] >= 0.0, 1.0, -1.0)
    out[:, 2] = inc[:, 2] * turn_scale + turn_per_m_rad * distance
    return out


def parabola_minimum(x: np.ndarray, y: np.ndarray) -> float | None:
    """The abscissa of the minimum of the parabola through three points ``(x, y)`` (x
    increasing); None when they curve downwards or lie on a line (no minimum between) or
    two of them coincide."""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    if not (x[0] < x[1] < x[2]):
        return None
    d1, d2 = (y[1] - y[0]) / (x[1] - x[0]), (y[2] - y[1]) / (x[2] - x[1])
    curvature = (d2 - d1) / (x[2] - x[0])
    if not curvature > 0.0:
        return None
    return float(0.5 * (x[0] + x[1]) - d1 / (2.0 * curvature))


def ranges_from_readings(measured_m: np.ndarray, bearing_rad: np.ndarray, range_is_depth: bool,
                         range_bias_m: float, range_scale: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """``(range_m, sigma_factor)`` of readings under a camera range model: ``measured =
    range_scale·(r·cos b if range_is_depth else r) + range_bias_m`` inverted, as
    :func:`slamio.noise.apply.correct_observation` does, and the factor its σ is stretched
    by (1/(scale·cos b) for a depth, else 1/scale). Without truth the scale is the gauge and
    stays 1, unless the odometry's scale is known (measured trials)."""
    measured, bearing = np.asarray(measured_m, dtype=float), np.asarray(bearing_rad, dtype=float)
    factor = (1.0 / np.cos(bearing) if range_is_depth else np.ones_like(measured)) / range_scale
    return (measured - range_bias_m) * factor, factor
