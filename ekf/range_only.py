"""Range-only landmarks: where is a beacon, given ranges to it from several robot positions?

A range says the landmark is on a circle around the robot; one range cannot place it, and
ranges from robot positions on a line place it only up to a mirror image across that line.
Both estimators (the EKF and iSAM2) therefore hold a landmark back — *delayed
initialisation* — until its ranges pin it down, with the same rule (:func:`try_initialise`):

1. at least ``min_ranges`` ranges (default 6);
2. the least-squares position (:func:`trilaterate`: a linear solve, then Gauss–Newton) has
   every standard deviation of its covariance ``(JᵀWJ)⁻¹`` below ``max_sigma_m`` (default
   2 m): the robot positions surround the landmark enough;
3. the fit is plausible: χ² of the range residuals below the 99.9 % quantile of χ²(m − 2);
4. the mirror image across the robot positions' best-fit line fits clearly worse: its χ²
   exceeds the solution's by at least ``min_mirror_gap`` (default 25, i.e. 5 σ). On a
   straight drive the two are equally good and the landmark waits for a turn.

Until then its ranges are kept (the latest ``max_buffer`` of them, default 400), each with
the robot position it was measured from. Everything here is plain numpy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = [
    "Trilateration",
    "trilaterate",
    "mirror_across_line",
    "try_initialise",
    "DelayedInitRule",
]


@dataclass(frozen=True)
class Trilateration:
    """A least-squares landmark position from ranges."""

    xy: np.ndarray  # (2,) metres, world frame
    covariance: np.ndarray  # (2, 2) (JᵀWJ)⁻¹ at the solution
    chi2: float  # Σ ((|xy − p_i| − r_i) / σ_i)²


@dataclass(frozen=True)
class DelayedInitRule:
    """The thresholds of :func:`try_initialise` (see the module docstring)."""

    min_ranges: int = 6
    max_sigma_m: float = 2.0
    fit_probability: float = 0.999
    min_mirror_gap: float = 25.0
    max_buffer: int = 400


def _chi2(xy, positions, ranges, sigmas) -> float:
    predicted = np.hypot(positions[:, 0] - xy[0], positions[:, 1] - xy[1])
    return float(np.sum(((predicted - ranges) / sigmas) ** 2))


def trilaterate(positions_xy, ranges_m, sigmas_m, *, iterations: int = 20, guess=None) -> Trilateration | None:
    """Weighted least-squares landmark position from ranges measured at ``positions_xy``.

    Starts from ``guess`` or from the linear solution (each range equation minus their
    mean: ``2 (p_i − p̄)·x = |p_i|² − mean|p|² − (r_i² − mean r²)``), then Gauss–Newton on
    ``Σ ((|x − p_i| − r_i)/σ_i)²``. Returns None when the positions cannot determine a
    point (fewer than 3, or all on one spot or line for the linear start).
    """
    P = np.asarray(positions_xy, dtype=float).reshape(-1, 2)
    r = np.asarray(ranges_m, dtype=float).reshape(-1)
    s = np.asarray(sigmas_m, dtype=float).reshape(-1)
    if len(P) < 3:
        return None
    if guess is None:
        A = 2.0 * (P - P.mean(axis=0))
        sq = np.sum(P**2, axis=1)
        b = (sq - sq.mean()) - (r**2 - np.mean(r**2))
        x, _, rank, _ = np.linalg.lstsq(A, b, rcond=None)
        if rank < 2:
            return None
    else:
        x = np.asarray(guess, dtype=float).reshape(2).copy()
    w = 1.0 / s**2
    for _ in range(iterations):
        d = x - P
        dist = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-9)
        J = d / dist[:, None]
        e = dist - r
        JtW = J.T * w
        try:
            step = np.linalg.solve(JtW @ J, -JtW @ e)
        except np.linalg.LinAlgError:
            return None
        x = x + step
        if float(np.hypot(*step)) < 1e-9:
            break
    d = x - P
    dist = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-9)
    J = d / dist[:, None]
    try:
        cov = np.linalg.inv((J.T * w) @ J)
    except np.linalg.LinAlgError:
        return None
    return Trilateration(x, 0.5 * (cov + cov.T), _chi2(x, P, r, s))


def mirror_across_line(xy, positions_xy) -> np.ndarray:
    """``xy`` reflected across the total-least-squares line through ``positions_xy``."""
    P = np.asarray(positions_xy, dtype=float).reshape(-1, 2)
    centre = P.mean(axis=0)
    _, _, vt = np.linalg.svd(P - centre)
    direction = vt[0]
    v = np.asarray(xy, dtype=float) - centre
    along = direction * float(v @ direction)
    return centre + 2.0 * along - v


def try_initialise(positions_xy, ranges_m, sigmas_m, rule: DelayedInitRule = DelayedInitRule()) -> Trilateration | None:
    """The landmark's position when the ranges pin it down by ``rule``, else None."""
    from slamio.chi2 import chi2_ppf

    P = np.asarray(positions_xy, dtype=float).reshape(-1, 2)
    m = len(P)
    if m < max(3, rule.min_ranges):
        return None
    fit = trilaterate(P, ranges_m, sigmas_m)
    if fit is None:
        return None
    mirror = trilaterate(P, ranges_m, sigmas_m, guess=mirror_across_line(fit.xy, P))
    if mirror is not None and float(np.hypot(*(mirror.xy - fit.xy))) > 1e-3:
        best, other = (fit, mirror) if fit.chi2 <= mirror.chi2 else (mirror, fit)
        if other.chi2 - best.chi2 < rule.min_mirror_gap:
            return None  # two places fit about as well: wait for a turn
        fit = best
    eigenvalues = np.linalg.eigvalsh(fit.covariance)
    if not eigenvalues[0] > 0.0 or math.sqrt(eigenvalues[-1]) > rule.max_sigma_m:
        return None  # a covariance that is not positive definite: the positions do not pin it down
    if fit.chi2 > chi2_ppf(rule.fit_probability, m - 2):
        return None
    return fit
