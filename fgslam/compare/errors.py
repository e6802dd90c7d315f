"""Error metrics of a trajectory or a map against the reference (pure functions).

Position and heading errors, ATE, RPE, the final pose error, NEES and NIS with their χ²
bands, and the landmark map error. Only poses the reference has are scored (see
:mod:`fgslam.compare`, "Partial ground truth"); when to align is
:mod:`fgslam.compare.alignment`'s policy. (The exception these raise is
:class:`fgslam.compare.ComparisonError`.)
"""

from __future__ import annotations

import math
from typing import Mapping

import numpy as np

from fgslam.compare.alignment import apply_se2, reference_rows, resolve_alignment
from fgslam.compare.runs import ComparisonError, _as_poses, _as_xy
from slamio.geometry import wrap_angle


def position_errors_m(estimate, reference) -> np.ndarray:
    """``(n,)`` Euclidean distance between corresponding positions, metres (no alignment)."""
    e = _as_xy(estimate, "estimate")
    r = _as_xy(reference, "reference")
    if e.shape != r.shape:
        raise ComparisonError(f"estimate has {len(e)} poses but reference has {len(r)}")
    return np.hypot(e[:, 0] - r[:, 0], e[:, 1] - r[:, 1])


def heading_errors_rad(estimate, reference) -> np.ndarray:
    """``(n,)`` heading error ``wrap(θ_est − θ_ref)`` in [-π, π), radians (no alignment).

    Wrapping matters: 3.1 rad and −3.1 rad are 0.083 rad apart, not 6.2.
    """
    e = _as_poses(estimate, "estimate")
    r = _as_poses(reference, "reference")
    if e.shape != r.shape:
        raise ComparisonError(f"estimate has {len(e)} poses but reference has {len(r)}")
    return wrap_angle(e[:, 2] - r[:, 2])


def _rmse(errors: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(errors)))) if len(errors) else math.nan


def ate_rmse_m(estimate, reference, *, align: bool | None = None, has_pose=None) -> float:
    """Absolute trajectory error: RMS of the position errors over the poses with truth, metres.

    Args:
        estimate, reference: ``(n, 3)`` trajectories, row ``i`` ↔ row ``i``. Reference rows
            of NaN (no truth there) are left out.
        align: ``None`` (default) applies the policy in :mod:`fgslam.compare.alignment` (align in SE(2)
            only when the first poses differ); ``True``/``False`` force it.
        has_pose: optional ``(n,)`` mask of the reference poses with truth (default: the
            finite rows).

    Returns NaN when no pose has truth.
    """
    valid = reference_rows(reference, has_pose)
    aligned, rotation_rad, translation_xy = resolve_alignment(estimate, reference, align, has_pose=valid)
    e = apply_se2(estimate, rotation_rad, translation_xy) if aligned else np.asarray(estimate, float)
    return _rmse(position_errors_m(e, reference)[valid])


def rpe_pairs(has_pose, delta_frames: int) -> np.ndarray:
    """``(n − Δ,)`` booleans: pair (i, i + Δ) counts in the RPE when both ends are True in
    ``has_pose`` (:func:`relative_pose_errors` also needs a true heading at both ends)."""
    mask = np.asarray(has_pose, dtype=bool).reshape(-1)
    d = int(delta_frames)
    if len(mask) <= d:
        return np.zeros(0, dtype=bool)
    return mask[:-d] & mask[d:]


def relative_pose_errors(
    estimate, reference, delta_frames: int, *, has_pose=None
) -> tuple[np.ndarray, np.ndarray]:
    """Relative pose errors over ``delta_frames`` (RPE, Sturm et al. 2012), for every pair
    (i, i + Δ) whose two reference poses have truth with a heading (:func:`rpe_pairs`; the
    relative motion is taken in the reference's frame, so a truth that measures position
    only gives no pair): the error pose
    E = (Qᵢ⁻¹ Qᵢ₊Δ)⁻¹ (Pᵢ⁻¹ Pᵢ₊Δ) of the estimate P against the reference Q. Returns
    ``(‖translation of E‖ in metres, |rotation of E| in radians)``, one entry per such pair
    in order of i.

    Alignment does not matter: a rigid transform of the whole estimate cancels in Pᵢ⁻¹ Pᵢ₊Δ.
    This is what evo's ``evo_rpe --delta Δ --delta_unit f --all_pairs`` computes (a test
    checks it to 1e-9). ``has_pose`` as in :func:`ate_rmse_m`.
    """
    e = _as_poses(estimate, "estimate")
    r = _as_poses(reference, "reference")
    if e.shape != r.shape:
        raise ComparisonError(f"estimate has {len(e)} poses but reference has {len(r)}")
    if int(delta_frames) < 1:
        raise ComparisonError(f"delta_frames must be >= 1, got {delta_frames!r}")
    d = int(delta_frames)
    if len(e) <= d:
        return np.zeros(0), np.zeros(0)
    pairs = rpe_pairs(reference_rows(r, has_pose) & np.isfinite(r[:, 2]), d)

    def relative(poses):  # Pᵢ⁻¹ Pᵢ₊Δ as (x, y, θ) in frame i
        a, b = poses[:-d], poses[d:]
        c, s = np.cos(a[:, 2]), np.sin(a[:, 2])
        dx, dy = b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]
        return c * dx + s * dy, -s * dx + c * dy, b[:, 2] - a[:, 2]

    ex, ey, eth = relative(e)
    rx, ry, rth = relative(r)
    # E = R⁻¹ P with R = (rx, ry, rth), P = (ex, ey, eth)
    c, s = np.cos(rth), np.sin(rth)
    tx, ty = c * (ex - rx) + s * (ey - ry), -s * (ex - rx) + c * (ey - ry)
    return np.hypot(tx, ty)[pairs], np.abs(wrap_angle(eth - rth))[pairs]


def nees(estimate, covariances, reference) -> np.ndarray:
    """``(n,)`` normalised estimation error squared of each pose: eᵀ P⁻¹ e with
    e = (x − x_ref, y − y_ref, wrap(θ − θ_ref)) and P the pose's stated covariance over world
    (x, y, θ). For a consistent estimator each value is χ²-distributed with 3 degrees of
    freedom (mean 3). Where the reference heading is NaN (a truth that measures position
    only, like GPS) the error is (x, y) against the covariance's position block: 2 degrees
    of freedom (:func:`nees_dofs`). A covariance that is not positive definite gives NaN.
    """
    e = _as_poses(estimate, "estimate")
    r = _as_poses(reference, "reference")
    P = np.asarray(covariances, dtype=float)
    if e.shape != r.shape or P.shape != (len(e), 3, 3):
        raise ComparisonError(f"nees: {len(e)} poses, {len(r)} reference poses, covariances {P.shape}")
    err = np.column_stack([e[:, 0] - r[:, 0], e[:, 1] - r[:, 1], wrap_angle(e[:, 2] - r[:, 2])])
    dofs = nees_dofs(r)
    out = np.full(len(e), np.nan)
    for k in range(len(e)):
        d = dofs[k]
        try:
            L = np.linalg.cholesky(0.5 * (P[k][:d, :d] + P[k][:d, :d].T))
        except np.linalg.LinAlgError:
            continue
        w = np.linalg.solve(L, err[k][:d])
        out[k] = float(w @ w)
    return out


def nees_dofs(reference) -> np.ndarray:
    """``(n,)`` degrees of freedom of each pose's NEES (:func:`nees`): 3 where the reference
    pose has a heading, 2 where its heading is NaN (the truth measures position only)."""
    r = _as_poses(reference, "reference")
    return np.where(np.isfinite(r[:, 2]), 3, 2)


def nees_band(dof: int = 3, runs: int = 1, probability: float = 0.95) -> tuple[float, float]:
    """Two-sided χ² band for the NEES averaged over ``runs`` runs (Bar-Shalom et al.): the
    average of N independent χ²(dof) values times N is χ²(N·dof), so the band is
    [χ²⁻¹(α/2; N·dof), χ²⁻¹(1 − α/2; N·dof)] / N. From scipy (:func:`slamio.chi2.chi2_ppf`), not a table."""
    from slamio.chi2 import chi2_ppf

    alpha = 1.0 - probability
    return (float(chi2_ppf(alpha / 2, dof * runs)) / runs, float(chi2_ppf(1 - alpha / 2, dof * runs)) / runs)


#: Degrees of freedom of an observation's NIS (range and bearing).
NIS_DOF = 2


def nis_summary(values, dofs=None) -> tuple[float | None, float | None, int | None]:
    """``(mean, share inside the 95 % χ² band, count)`` of per-observation NIS values
    (NaNs dropped); all None when there are none to summarise (``values`` None).

    ``dofs`` gives each value's degrees of freedom (1 for a range-only reading, 2 for range
    and bearing); default :data:`NIS_DOF` for all. Each value is tested against its own
    band; the mean is of the values as they are (1 or 2 when consistent)."""
    if values is None:
        return None, None, None
    v = np.asarray(values, dtype=float).reshape(-1)
    return chi2_summary(v, np.full(len(v), NIS_DOF) if dofs is None else dofs)


def chi2_summary(values, dofs) -> tuple[float | None, float | None, int]:
    """``(mean, share inside the 95 % χ² band, count)`` of χ² values (NIS, NEES) with
    ``dofs`` degrees of freedom each, NaNs dropped; each value is tested against the band of
    its own degrees of freedom. ``(None, None, 0)`` when no value is finite."""
    v, inside = _finite_inside(values, dofs)
    if not len(v):
        return None, None, 0
    return float(np.mean(v)), float(np.mean(inside)), int(len(v))


def _finite_inside(values, dofs) -> tuple[np.ndarray, np.ndarray]:
    """``(finite values, whether each is inside the 95 % band of its degrees of freedom)``."""
    v = np.asarray(values, dtype=float).reshape(-1)
    d = np.asarray(dofs, dtype=int).reshape(-1)
    finite = np.isfinite(v)
    v, d = v[finite], d[finite]
    inside = np.zeros(len(v), dtype=bool)
    for dof in np.unique(d):
        low, high = nees_band(int(dof))
        m = d == dof
        inside[m] = (v[m] >= low) & (v[m] <= high)
    return v, inside


def in_band_se_by_step(values, dofs, steps) -> float | None:
    """Standard error of the in-band share of χ² values taken several to a step (the NIS of
    a step's observations, which share its pose), with the step as the sampled unit: the
    ratio estimator's √(k/(k−1) Σⱼ (yⱼ − p mⱼ)²) / Σⱼ mⱼ over the k steps, yⱼ of whose mⱼ
    values are inside. One value a step gives about the binomial √(p(1 − p)/k). None
    with fewer than two steps."""
    v = np.asarray(values, dtype=float).reshape(-1)
    finite = np.isfinite(v)
    _, inside = _finite_inside(v, np.full(len(v), NIS_DOF) if dofs is None else dofs)
    groups, where = np.unique(np.asarray(steps).reshape(-1)[finite], return_inverse=True)
    k = len(groups)
    if k < 2:
        return None
    m = np.bincount(where, minlength=k).astype(float)
    y = np.bincount(where, weights=inside.astype(float), minlength=k)
    p = y.sum() / m.sum()
    if p in (0.0, 1.0):  # every value in (or out of) the band: no spread to measure, so the binomial's over the steps
        return in_band_se(float(p), k)
    return math.sqrt(k / (k - 1) * float(np.sum((y - p * m) ** 2))) / float(m.sum())


def in_band_se(share: float | None, count: int | None) -> float | None:
    """Standard error of an in-band share ``p`` over ``count`` values (None when there is no
    share): the binomial √(p̃(1 − p̃)/(n + 4)) with Agresti and Coull's p̃ = (np + 2)/(n + 4),
    which is the textbook √(p(1 − p)/n) within a few per cent for shares away from 0 and 1,
    and does not read 0 when every value (or none) is inside: 50 of 50 give ±2.6 points,
    not ±0. It treats the values as independent: for a sample of spread-out steps that is
    about right; over every step, whose neighbours are correlated, it understates the
    uncertainty of the share as a measure of the estimator."""
    if share is None or not count:
        return None
    adjusted = (share * count + 2.0) / (count + 4.0)
    return math.sqrt(adjusted * (1.0 - adjusted) / (count + 4.0))


def rpe_delta_frames(reference, distance_m: float = 1.0, *, has_pose=None) -> int:
    """The frame delta over which the reference travels ``distance_m`` on average (≥ 1).

    The mean step length comes from consecutive poses that both have truth (``has_pose`` as
    in :func:`ate_rmse_m`); 1 when there is no such pair.
    """
    r = _as_poses(reference, "reference")
    if len(r) < 2:
        return 1
    steps = np.hypot(np.diff(r[:, 0]), np.diff(r[:, 1]))[rpe_pairs(reference_rows(r, has_pose), 1)]
    if not len(steps):
        return 1
    mean_step = float(np.mean(steps))
    if not mean_step > 0.0:
        return 1
    return max(1, min(len(r) - 1, int(round(distance_m / mean_step))))


def last_pose_with_truth(has_pose) -> int | None:
    """Index of the last True entry of a mask, or None when there is none."""
    mask = np.asarray(has_pose, dtype=bool).reshape(-1)
    return int(len(mask) - 1 - np.argmax(mask[::-1])) if mask.any() else None


def final_pose_error_m(estimate, reference, *, align: bool | None = False, has_pose=None) -> float:
    """Position error of the last pose that has truth, metres (NaN when none has).

    That is the last pose of the run when its truth exists; with a gap in the truth at the
    end, the last pose before the gap. ``align`` as in :func:`ate_rmse_m`, but defaults to
    ``False``: callers that aligned already (like :func:`compute_metrics`) pass aligned
    poses. ``has_pose`` as in :func:`ate_rmse_m`.
    """
    valid = reference_rows(reference, has_pose)
    aligned, rotation_rad, translation_xy = resolve_alignment(estimate, reference, align, has_pose=valid)
    e = apply_se2(estimate, rotation_rad, translation_xy) if aligned else np.asarray(estimate, float)
    r = np.asarray(reference, float)
    last = last_pose_with_truth(valid)
    if len(e) == 0 or last is None:
        return math.nan
    return float(math.hypot(e[last, 0] - r[last, 0], e[last, 1] - r[last, 1]))


def map_errors_m(
    estimated_landmarks: Mapping[int, tuple[float, float]],
    reference_landmarks: Mapping[int, tuple[float, float]],
    rotation_rad: float = 0.0,
    translation_xy=(0.0, 0.0),
) -> dict[int, float]:
    """Landmark id → position error in metres, for the ids present in both maps.

    The estimated landmarks are first moved by the SE(2) transform (the same one used to
    align that estimator's trajectory; the identity by default). Landmarks only one side
    knows are left out: count them with ``len()`` of each map.
    """
    common = sorted(set(estimated_landmarks) & set(reference_landmarks))
    if not common:
        return {}
    est = np.array([estimated_landmarks[i] for i in common], dtype=float).reshape(-1, 2)
    ref = np.array([reference_landmarks[i] for i in common], dtype=float).reshape(-1, 2)
    est = apply_se2(est, rotation_rad, translation_xy)
    errors = np.hypot(est[:, 0] - ref[:, 0], est[:, 1] - ref[:, 1])
    return {int(i): float(err) for i, err in zip(common, errors)}


def map_rmse_m(
    estimated_landmarks: Mapping[int, tuple[float, float]],
    reference_landmarks: Mapping[int, tuple[float, float]],
    rotation_rad: float = 0.0,
    translation_xy=(0.0, 0.0),
) -> float:
    """RMS landmark position error over the ids both maps contain, metres.

    Returns NaN when the maps have no id in common (:func:`compute_metrics` turns it into
    ``None``). See :func:`map_errors_m` for the per-landmark errors and the transform.
    """
    errors = map_errors_m(estimated_landmarks, reference_landmarks, rotation_rad, translation_xy)
    return _rmse(np.fromiter(errors.values(), dtype=float, count=len(errors)))
