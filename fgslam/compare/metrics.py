"""Comparison maths: how far each estimator's answer is from a reference, and what it cost.

Everything here is pure numpy (no gtsam, no matplotlib) and works on plain arrays:

* a *trajectory* is an ``(n, 3)`` array of poses ``(x_m, y_m, theta_rad)`` in the world
  frame, one row per pose of the run log (row ``i`` is pose ``X(i)``);
* a *map* is a ``dict`` landmark id → ``(x_m, y_m)`` in the world frame.

The runner (``fgslam.runner``) produces one :class:`EstimatorRun` per estimator and one
:class:`Reference` (the log's ground truth wherever it has some, otherwise the batch-smoothed
solution); :func:`compute_metrics` turns them into a JSON-ready dictionary, and
:func:`format_table` into a terminal table. ``fgslam.report`` draws the same figures.

Partial ground truth
--------------------
Real datasets have truth for only some poses (motion capture loses the robot). A reference
trajectory then has NaN rows where there is no truth, and :attr:`Reference.has_pose` says
which rows hold a pose. Every pose figure is computed over the poses with truth only: ATE
(final and online) is the RMS over them, the final error is that of the last pose with
truth, an RPE pair counts when both its ends have truth, NEES is taken at the poses with
truth, and an SE(2) alignment is fitted to them. The map error does not need pose truth:
it is against the log's surveyed landmarks whenever the log has them, even when the
trajectory reference is the smoothed solution (landmark-only truth). The pure functions
take an optional ``has_pose`` mask; without it, the finite rows of the reference count.

Alignment policy (why and when trajectories are aligned)
--------------------------------------------------------
Absolute trajectory error (ATE) is only meaningful when the estimate and the reference are
expressed in the same world frame. Every estimator in this project anchors pose 0 at the
log's known start pose (iSAM2 and batch through a prior factor with σ = 1e-3; the EKF by
starting its state there), and so does the reference. When both trajectories share their
first pose (see :func:`shares_first_pose`) they are therefore already in the same frame and
**no alignment is applied**: aligning would hide real error (for example a heading error at
the start that rotates the whole map). When pose 0 has no truth, the first pose that has
truth is the one compared.

Only when the first poses differ (an estimate in some other frame, e.g. an imported
dataset) is the estimate aligned to the reference by the least-squares *rigid* SE(2)
transform (:func:`align_se2`). The rotation is found in SO(2) directly, so it can never be a
reflection. (A 3-D Umeyama alignment, as done by evo, can return ``diag(1, -1, -1)`` for
planar data — a mirror — and report a mirrored estimate as perfect.)

One transform per estimator is computed from its *final* trajectory and applied to its
final trajectory, its online trajectory and its landmarks: they all live in that estimator's
frame.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping

import numpy as np

from slamio.errors import FgslamError
from slamio.geometry import wrap_angle

__all__ = [
    "ComparisonError",
    "EstimatorRun",
    "Reference",
    "FIRST_POSE_TOL_M",
    "FIRST_POSE_TOL_RAD",
    "align_se2",
    "apply_se2",
    "shares_first_pose",
    "resolve_alignment",
    "estimator_alignment",
    "position_errors_m",
    "heading_errors_rad",
    "ate_rmse_m",
    "final_pose_error_m",
    "relative_pose_errors",
    "rpe_delta_frames",
    "nees",
    "nees_band",
    "nis_summary",
    "NIS_DOF",
    "map_errors_m",
    "map_rmse_m",
    "AssociationScore",
    "score_associations",
    "relabel_landmarks",
    "compute_metrics",
    "METRIC_KEYS",
    "TOP_LEVEL_KEYS",
    "COLUMN_MEANINGS",
    "REFERENCE_DESCRIPTIONS",
    "describe_reference",
    "reference_description",
    "reference_rows",
    "rpe_pairs",
    "last_pose_with_truth",
    "nees_over_truth",
    "estimator_names",
    "reference_line",
    "table_rows",
    "format_table",
    "format_tum",
    "write_tum",
    "read_tum",
]


class ComparisonError(FgslamError, ValueError):
    """Inputs that cannot be compared (wrong shapes, a bad TUM file, clashing names).

    It is an :class:`~slamio.errors.FgslamError` (the CLI prints it without a traceback)
    and a :class:`ValueError` (what numpy-style callers expect for bad arguments).
    """


# --------------------------------------------------------------------------- data types


@dataclass(frozen=True)
class EstimatorRun:
    """What the runner produces for one estimator on one log.

    Attributes:
        name: short identifier used as the metrics key ("ekf", "isam2", "batch", ...).
        online: ``(n, 3)`` poses as estimated *at their own step* (what a robot acting live
            would have used), or ``None`` for a one-shot batch solve.
        final: ``(n, 3)`` every pose as estimated after the last step (smoothers revise
            old poses; for a filter this usually equals ``online``).
        landmarks: landmark id → estimated ``(x_m, y_m)``.
        step_times_s: ``(n,)`` wall-clock seconds spent on each step, or ``None`` for a
            one-shot batch solve.
        total_time_s: wall-clock seconds for the whole run (including any ``finish``).
        association: how well the estimator associated observations itself (see
            :func:`score_associations`), or ``None`` when it used the log's ids throughout.
            When present, ``landmarks`` are already keyed by true id.
        landmark_heights: landmark id → estimated height above the floor (m), for
            estimators with a 3-D map; ``None`` otherwise.
        online_covariances: ``(n, 3, 3)`` covariance of each online pose over world
            (x, y, θ), as the estimator stated it at that step (for NEES), or ``None``.
        nis: ``(m,)`` NIS of every observation the estimator could predict (a landmark it
            already held), against its prediction before the observation's step; ``None``
            when the estimator does not offer it.
        nis_steps: ``(m,)`` the step of each NIS value.
        nis_dofs: ``(m,)`` the degrees of freedom of each NIS value (1 for a range-only
            reading); ``None`` means :data:`NIS_DOF` for all.
        peak_memory_bytes: how far the process's resident memory rose above where it
            started during the run (:class:`fgslam.memory.PeakMemory`), or ``None``.
        landmark_covariances: landmark id → 2×2 covariance of its final (x, y) estimate
            (world frame), or ``None``; drawn as 95 % ellipses in the report.
    """

    name: str
    online: np.ndarray | None
    final: np.ndarray
    landmarks: dict[int, tuple[float, float]]
    step_times_s: np.ndarray | None
    total_time_s: float
    association: "AssociationScore | None" = None
    landmark_heights: dict[int, float] | None = None
    online_covariances: np.ndarray | None = None
    nis: np.ndarray | None = None
    nis_steps: np.ndarray | None = None
    nis_dofs: np.ndarray | None = None
    peak_memory_bytes: int | None = None
    landmark_covariances: dict[int, np.ndarray] | None = None
    #: what became of observations the estimator did not use as a landmark (e.g. ``skipped``:
    #: no id and no association; ``rejected``: ambiguous; ``unconfirmed``: a first sighting
    #: nothing agreed with), from the estimator's own counters; None when it keeps none
    unused_observations: dict[str, int] | None = None


@dataclass(frozen=True)
class Reference:
    """What the estimators are compared against.

    Four kinds occur (:attr:`description` says which in words):

    * **full ground truth** — ``kind="ground_truth"``, every pose has truth;
    * **partial pose truth** — ``kind="ground_truth"`` with some rows of ``trajectory`` NaN
      (motion capture loses the robot: Vicon gaps). Only poses with truth are scored;
    * **landmark-only truth** — ``kind="smoothed"`` (the trajectory is the batch solution:
      the log has no pose truth) but ``landmark_reference="ground_truth"``: the landmarks are
      the log's surveyed ones, so the map error is against the truth;
    * **smoothed** — trajectory and landmarks from the batch Levenberg–Marquardt solution.

    Attributes:
        kind: where the *trajectory* comes from: ``"ground_truth"`` (simulation, motion
            capture) or ``"smoothed"`` (the batch solution, when no pose has truth).
        trajectory: ``(n, 3)`` reference poses, one per pose of the log; rows without truth
            are NaN (the constructor sets them so).
        landmarks: landmark id → reference ``(x_m, y_m)``.
        landmark_heights: landmark id → reference height above the floor (m), or ``None``.
        has_pose: ``(n,)`` booleans, True where ``trajectory`` holds a reference pose. When
            not given, the rows whose three numbers are finite.
        landmark_reference: where ``landmarks`` come from, ``"ground_truth"`` or
            ``"smoothed"``; by default the same as ``kind``, and ``None`` when there are no
            reference landmarks (no map error can be computed).
    """

    kind: str
    trajectory: np.ndarray
    landmarks: dict[int, tuple[float, float]]
    landmark_heights: dict[int, float] | None = None
    has_pose: np.ndarray | None = None
    landmark_reference: str | None = None

    def __post_init__(self):
        trajectory = _as_poses(self.trajectory, "reference.trajectory").copy()
        if self.has_pose is None:
            has_pose = np.all(np.isfinite(trajectory), axis=1)
        else:
            has_pose = np.asarray(self.has_pose, dtype=bool).reshape(-1)
            if has_pose.shape != (len(trajectory),):
                raise ComparisonError(
                    f"reference.has_pose has {has_pose.size} entries for {len(trajectory)} poses"
                )
        trajectory[~has_pose] = np.nan
        landmark_reference = self.landmark_reference
        if landmark_reference is None and self.landmarks:
            landmark_reference = self.kind
        if landmark_reference is not None and landmark_reference not in REFERENCE_KINDS:
            raise ComparisonError(
                f"landmark_reference {landmark_reference!r}; expected one of {REFERENCE_KINDS}"
            )
        object.__setattr__(self, "trajectory", trajectory)
        object.__setattr__(self, "has_pose", has_pose)
        object.__setattr__(self, "landmark_reference", landmark_reference if self.landmarks else None)

    @property
    def poses_with_truth(self) -> int:
        """How many poses have ground truth (0 when the trajectory is the smoothed solution)."""
        return int(np.count_nonzero(self.has_pose)) if self.kind == "ground_truth" else 0

    @property
    def description(self) -> str:
        """What the figures are measured against, in words (see :func:`describe_reference`)."""
        return describe_reference(
            self.kind,
            poses=len(self.trajectory),
            poses_with_truth=self.poses_with_truth,
            landmark_reference=self.landmark_reference,
            landmarks=len(self.landmarks),
        )


REFERENCE_KINDS = ("ground_truth", "smoothed")

# --------------------------------------------------------------------------- SE(2) alignment


def _as_xy(a, what: str) -> np.ndarray:
    """(n, 2) float array of the x, y columns of an (n, 2) or (n, 3) array."""
    arr = np.asarray(a, dtype=float)
    if arr.ndim != 2 or arr.shape[1] not in (2, 3):
        raise ComparisonError(f"{what}: expected an (n, 2) or (n, 3) array, got shape {arr.shape}")
    return arr[:, :2]


def _as_poses(a, what: str) -> np.ndarray:
    """(n, 3) float array of poses (x_m, y_m, theta_rad)."""
    arr = np.asarray(a, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ComparisonError(f"{what}: expected an (n, 3) array of poses, got shape {arr.shape}")
    return arr


def align_se2(estimate_xy, reference_xy) -> tuple[float, np.ndarray]:
    """Least-squares rigid 2-D alignment of ``estimate_xy`` onto ``reference_xy``.

    Finds the rotation ``R(θ)`` (a proper rotation in SO(2), never a reflection) and the
    translation ``t`` minimising ``Σᵢ |R pᵢ + t − qᵢ|²`` for estimate points ``pᵢ`` and
    reference points ``qᵢ``. With centred points ``p'ᵢ = pᵢ − p̄`` and ``q'ᵢ = qᵢ − q̄``
    the closed form is

        θ = atan2(Σ (p'x q'y − p'y q'x),  Σ (p'x q'x + p'y q'y)),    t = q̄ − R(θ) p̄.

    Args:
        estimate_xy: ``(n, 2)`` points (or ``(n, 3)`` poses; headings are ignored).
        reference_xy: same shape, row ``i`` corresponds to row ``i`` of the estimate.

    Returns:
        ``(rotation_rad, translation_xy)`` with ``translation_xy`` a ``(2,)`` array in
        metres; apply it with :func:`apply_se2`. When the rotation is not determined (one
        point, or all estimate points coincide) the rotation is 0.
    """
    p = _as_xy(estimate_xy, "estimate")
    q = _as_xy(reference_xy, "reference")
    if p.shape != q.shape:
        raise ComparisonError(f"align_se2: estimate has {len(p)} points, reference {len(q)}")
    if len(p) == 0:
        raise ComparisonError("align_se2: no points to align")
    p_mean = p.mean(axis=0)
    q_mean = q.mean(axis=0)
    pc = p - p_mean
    qc = q - q_mean
    cross = float(np.sum(pc[:, 0] * qc[:, 1] - pc[:, 1] * qc[:, 0]))
    dot = float(np.sum(pc[:, 0] * qc[:, 0] + pc[:, 1] * qc[:, 1]))
    rotation_rad = math.atan2(cross, dot)  # atan2(0, 0) = 0 for degenerate inputs
    c, s = math.cos(rotation_rad), math.sin(rotation_rad)
    R = np.array([[c, -s], [s, c]])
    translation_xy = q_mean - R @ p_mean
    return rotation_rad, translation_xy


def apply_se2(poses_or_points, rotation_rad: float, translation_xy) -> np.ndarray:
    """Apply ``x ↦ R(rotation_rad) x + translation_xy`` to points or poses.

    Accepts ``(n, 2)`` points, ``(n, 3)`` poses (headings are rotated too and wrapped into
    [-π, π)), or a single ``(2,)`` point / ``(3,)`` pose. Returns a new float array of the
    same shape.
    """
    arr = np.asarray(poses_or_points, dtype=float)
    single = arr.ndim == 1
    a = arr[None, :] if single else arr
    if a.ndim != 2 or a.shape[1] not in (2, 3):
        raise ComparisonError(f"apply_se2: expected points (…, 2) or poses (…, 3), got {arr.shape}")
    t = np.asarray(translation_xy, dtype=float).reshape(2)
    c, s = math.cos(rotation_rad), math.sin(rotation_rad)
    out = a.copy()
    out[:, 0] = c * a[:, 0] - s * a[:, 1] + t[0]
    out[:, 1] = s * a[:, 0] + c * a[:, 1] + t[1]
    if a.shape[1] == 3:
        out[:, 2] = wrap_angle(a[:, 2] + rotation_rad)
    return out[0] if single else out


# Anchored estimators hold pose 0 at the start pose through a prior with σ = 1e-3 (m and
# rad). The other factors can pull the posterior of pose 0 a few σ away, so two anchored
# trajectories can differ at pose 0 by several 1e-3 — far more than 1e-6, which would
# wrongly trigger an alignment. Trajectories in genuinely different frames differ by
# metres or by large angles. 10σ = 1e-2 separates the two cases with margin on both sides.
FIRST_POSE_TOL_M = 1e-2
FIRST_POSE_TOL_RAD = 1e-2


def shares_first_pose(
    estimate,
    reference,
    tol_m: float = FIRST_POSE_TOL_M,
    tol_rad: float = FIRST_POSE_TOL_RAD,
) -> bool:
    """True when the first poses of two trajectories agree to within the tolerances.

    This is the ATE alignment policy: trajectories that share their first pose are in the
    same world frame (both anchored at the log's known start pose) and are compared as they
    are; otherwise the estimate is aligned in SE(2).

    The default tolerances (1 cm, 0.01 rad) are 10× the σ = 1e-3 of the start-pose prior:
    an anchored estimate stays within a few σ of the start, while a trajectory in another
    frame is off by far more. Pass tighter values if your prior is tighter.

    Args:
        estimate, reference: ``(n, 3)`` trajectories (only row 0 is used).
        tol_m: largest distance between the first positions, metres.
        tol_rad: largest wrapped difference between the first headings, radians.
    """
    e = _as_poses(estimate, "estimate")
    r = _as_poses(reference, "reference")
    if len(e) == 0 or len(r) == 0:
        return False
    distance_m = math.hypot(e[0, 0] - r[0, 0], e[0, 1] - r[0, 1])
    heading_rad = abs(float(wrap_angle(e[0, 2] - r[0, 2])))
    return distance_m <= tol_m and heading_rad <= tol_rad


def reference_rows(reference, has_pose=None) -> np.ndarray:
    """``(n,)`` booleans: the rows of ``reference`` that hold a pose to compare against.

    ``has_pose`` when given (as :attr:`Reference.has_pose`), otherwise the rows whose three
    numbers are finite (a NaN row is a pose without truth).
    """
    r = _as_poses(reference, "reference")
    if has_pose is None:
        return np.all(np.isfinite(r), axis=1)
    mask = np.asarray(has_pose, dtype=bool).reshape(-1)
    if mask.shape != (len(r),):
        raise ComparisonError(f"has_pose has {mask.size} entries for {len(r)} reference poses")
    return mask


def resolve_alignment(
    estimate, reference, align: bool | None = None, *, has_pose=None
) -> tuple[bool, float, np.ndarray]:
    """Decide whether to align and with which transform.

    Only poses the reference has (see :func:`reference_rows`) take part: the first-pose test
    looks at the first of them (pose 0 unless the truth starts later), and the SE(2) fit uses
    all of them.

    Args:
        estimate, reference: ``(n, 3)`` trajectories of equal length.
        align: ``True`` always aligns, ``False`` never does, ``None`` applies the automatic
            policy (align unless :func:`shares_first_pose`).
        has_pose: optional ``(n,)`` mask of the reference poses with truth.

    Returns:
        ``(aligned, rotation_rad, translation_xy)``; the identity transform when not aligned
        (also when the reference has no pose at all: there is nothing to align on).
    """
    e = _as_poses(estimate, "estimate")
    r = _as_poses(reference, "reference")
    if e.shape != r.shape:
        raise ComparisonError(f"estimate has {len(e)} poses but reference has {len(r)}")
    valid = reference_rows(r, has_pose)
    if not valid.any():
        return False, 0.0, np.zeros(2)
    if align is None:
        first = int(np.argmax(valid))
        align = not shares_first_pose(e[first:], r[first:])
    if not align:
        return False, 0.0, np.zeros(2)
    rotation_rad, translation_xy = align_se2(e[valid], r[valid])
    return True, rotation_rad, translation_xy


# --------------------------------------------------------------------------- error metrics


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
        align: ``None`` (default) applies the policy in the module docstring (align in SE(2)
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
    """``(n − Δ,)`` booleans: pair (i, i + Δ) counts in the RPE when both ends have truth."""
    mask = np.asarray(has_pose, dtype=bool).reshape(-1)
    d = int(delta_frames)
    if len(mask) <= d:
        return np.zeros(0, dtype=bool)
    return mask[:-d] & mask[d:]


def relative_pose_errors(
    estimate, reference, delta_frames: int, *, has_pose=None
) -> tuple[np.ndarray, np.ndarray]:
    """Relative pose errors over ``delta_frames`` (RPE, Sturm et al. 2012), for every pair
    (i, i + Δ) whose two reference poses have truth (:func:`rpe_pairs`): the error pose
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
    pairs = rpe_pairs(reference_rows(r, has_pose), d)

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
    freedom (mean 3). A covariance that is not positive definite gives NaN.
    """
    e = _as_poses(estimate, "estimate")
    r = _as_poses(reference, "reference")
    P = np.asarray(covariances, dtype=float)
    if e.shape != r.shape or P.shape != (len(e), 3, 3):
        raise ComparisonError(f"nees: {len(e)} poses, {len(r)} reference poses, covariances {P.shape}")
    err = np.column_stack([e[:, 0] - r[:, 0], e[:, 1] - r[:, 1], wrap_angle(e[:, 2] - r[:, 2])])
    out = np.full(len(e), np.nan)
    for k in range(len(e)):
        try:
            L = np.linalg.cholesky(0.5 * (P[k] + P[k].T))
        except np.linalg.LinAlgError:
            continue
        w = np.linalg.solve(L, err[k])
        out[k] = float(w @ w)
    return out


def nees_band(dof: int = 3, runs: int = 1, probability: float = 0.95) -> tuple[float, float]:
    """Two-sided χ² band for the NEES averaged over ``runs`` runs (Bar-Shalom et al.): the
    average of N independent χ²(dof) values times N is χ²(N·dof), so the band is
    [χ²⁻¹(α/2; N·dof), χ²⁻¹(1 − α/2; N·dof)] / N. From scipy.stats, not a table."""
    from scipy.stats import chi2

    alpha = 1.0 - probability
    return (float(chi2.ppf(alpha / 2, dof * runs)) / runs, float(chi2.ppf(1 - alpha / 2, dof * runs)) / runs)


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
    d = np.full(len(v), NIS_DOF) if dofs is None else np.asarray(dofs, dtype=int).reshape(-1)
    finite = np.isfinite(v)
    v, d = v[finite], d[finite]
    if not len(v):
        return None, None, 0
    inside = np.zeros(len(v), dtype=bool)
    for dof in np.unique(d):
        low, high = nees_band(int(dof))
        m = d == dof
        inside[m] = (v[m] >= low) & (v[m] <= high)
    return float(np.mean(v)), float(np.mean(inside)), int(len(v))


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


# --------------------------------------------------------------------------- data association


@dataclass(frozen=True)
class AssociationScore:
    """How an estimator associated observations with landmarks, scored against truth.

    Attributes:
        observations: observations scored (those whose true landmark is known).
        correct: observations used as the right landmark (see :func:`score_associations`).
        rejected: observations the estimator did not use (gated out or left unpaired).
        identity: estimator's landmark key → the true id it stands for.
        duplicate_keys: keys created for a true landmark that was already mapped.
    """

    observations: int
    correct: int
    rejected: int
    identity: dict[int, int]
    duplicate_keys: frozenset[int]

    @property
    def rate(self) -> float:
        return self.correct / self.observations if self.observations else math.nan

    @property
    def landmarks_created(self) -> int:
        return len(self.identity)

    @property
    def wrong(self) -> int:
        """Observations used as the wrong landmark (or as a duplicate of a mapped one)."""
        return self.observations - self.correct - self.rejected


def score_associations(true_ids, keys) -> AssociationScore:
    """Score one run's data association.

    ``true_ids[i]`` is the true landmark of observation ``i`` (None when unknown: not
    scored) and ``keys[i]`` the estimator's landmark key it was used as (None: rejected),
    in the order the observations were made. A key stands for the true landmark most of its
    scored observations saw (ties: the one seen first) — not merely the first one, so a
    landmark whose first sighting was a misdetection that happened to fall near it is still
    the landmark it maps. When several keys stand for the same true landmark, the one with
    the most observations of it (ties: the first created) is that landmark and the others
    are duplicates, every use of which is wrong. An observation is correct when its key
    stands for its true landmark and is not a duplicate; a rejected observation is not correct.
    """
    votes: dict[int, dict[int, int]] = {}  # key → true id → observations (insertion order = first seen)
    for true_id, key in zip(true_ids, keys, strict=True):
        if key is not None and true_id is not None:
            counts = votes.setdefault(key, {})
            counts[true_id] = counts.get(true_id, 0) + 1
    identity = {key: max(counts, key=counts.get) for key, counts in votes.items()}  # max keeps the first of ties
    primary: dict[int, int] = {}  # true id → its key
    for key, true_id in identity.items():  # keys in order of first use
        best = primary.get(true_id)
        if best is None or votes[key][true_id] > votes[best][true_id]:
            primary[true_id] = key
    duplicates = {key for key, true_id in identity.items() if primary[true_id] != key}
    observations = correct = rejected = 0
    for true_id, key in zip(true_ids, keys, strict=True):
        if true_id is None:
            continue
        observations += 1
        if key is None:
            rejected += 1
        elif key not in duplicates and identity.get(key) == true_id:
            correct += 1
    return AssociationScore(observations, correct, rejected, identity, frozenset(duplicates))


def relabel_landmarks(landmarks: Mapping[int, object], score: AssociationScore) -> dict:
    """Re-key an estimator's landmarks by the true id each stands for (duplicates dropped)."""
    return {
        score.identity[k]: v for k, v in landmarks.items() if k in score.identity and k not in score.duplicate_keys
    }


# --------------------------------------------------------------------------- metrics dict

TOP_LEVEL_KEYS = (
    "reference",
    "log",
    "poses",
    "rpe_delta_frames",
    "reference_poses_with_truth",
    "landmark_reference",
    "reference_landmarks",
    "provenance",
)
METRIC_KEYS = (
    "ate_rmse_m",
    "ate_online_rmse_m",
    "ate_aligned_rmse_m",
    "ate_online_aligned_rmse_m",
    "final_pose_error_m",
    "rpe_trans_rmse_m",
    "rpe_heading_rmse_rad",
    "nees_mean",
    "nees_inside_95",
    "nees_count",
    "nis_mean",
    "nis_inside_95",
    "nis_count",
    "map_rmse_m",
    "map_height_rmse_m",
    "landmarks_estimated",
    "landmarks_found",
    "landmarks_missed",
    "association",
    "unused_observations",
    "aligned",
    "time_total_s",
    "time_step_p50_s",
    "time_step_p99_s",
    "time_step_max_s",
    "peak_memory_mb",
    "steps",
)


def _json_float(value) -> float | None:
    """A plain Python float, or None for NaN/inf/None (JSON has no NaN)."""
    if value is None:
        return None
    value = float(value)
    return value if math.isfinite(value) else None


def estimator_alignment(run: EstimatorRun, reference: Reference) -> tuple[bool, float, np.ndarray]:
    """The SE(2) transform :func:`compute_metrics` applies to one run (see module docstring).

    Computed from the run's final trajectory against the same number of reference poses,
    over the poses that have truth; ``fgslam.report`` uses it to draw exactly what was
    measured.
    """
    final = _as_poses(run.final, f"{run.name}.final")
    ref = _as_poses(reference.trajectory, "reference.trajectory")
    if len(final) > len(ref):
        raise ComparisonError(
            f"estimator {run.name!r} has {len(final)} poses but the reference only {len(ref)}; "
            "compare runs of the same log"
        )
    m = len(final)
    return resolve_alignment(final, ref[:m], None, has_pose=reference.has_pose[:m])


def nees_over_truth(online, covariances, reference, has_pose) -> np.ndarray:
    """NEES (:func:`nees`) of the online poses that have truth, in pose order; values of a
    covariance that is not positive definite are NaN (the caller decides what they mean)."""
    e = _as_poses(online, "online")
    k = len(e)
    valid = np.asarray(has_pose, dtype=bool).reshape(-1)[:k]
    r = _as_poses(reference, "reference")[:k]
    P = np.asarray(covariances, dtype=float)[:k]
    return nees(e[valid], P[valid], r[valid])


def aligned_ate_m(estimate, reference, has_pose) -> float | None:
    """ATE after the least-squares SE(2) alignment over the poses with truth, metres.

    The gauge-free figure: a SLAM map's frame is pinned only by the prior on the start
    pose, so a heading error made before the first landmark is seen (on a real robot,
    start-up motion the odometry describes badly) rotates the whole map and dominates the
    anchored ATE. The aligned ATE (the TUM benchmark's ATE, evo's ``-a``) measures the
    shape. None with fewer than two poses with truth.
    """
    e = _as_poses(estimate, "estimate")
    n = min(len(e), len(reference))
    mask = np.asarray(has_pose[:n], bool)
    if mask.sum() < 2:
        return None
    e_xy = e[:n][mask, :2]
    r_xy = np.asarray(reference, float)[:n][mask, :2]
    rotation, translation = align_se2(e_xy, r_xy)
    return _rmse(position_errors_m(apply_se2(e_xy, rotation, translation), r_xy))


def compute_metrics(runs: list[EstimatorRun], reference: Reference, *, log_path: str) -> dict:
    """All comparison figures as a JSON-ready dictionary (plain floats, ints, bools, None).

    Every pose figure (ATE, final error, RPE, NEES) is computed over the poses that have a
    reference (:attr:`Reference.has_pose`): with partial ground truth, poses in the gaps are
    not scored. The map error is against ``reference.landmarks`` (the log's surveyed
    landmarks whenever it has them, :attr:`Reference.landmark_reference`).

    Shape::

        {"reference": "ground_truth" | "smoothed",  # where the reference *trajectory* is from
         "log": log_path, "poses": n,
         "rpe_delta_frames": int,            # Δ of the RPE: the reference's frames per ~1 m
         "reference_poses_with_truth": int,  # poses scored against ground truth (n when all
                                             # have it; 0 against the smoothed solution)
         "landmark_reference": "ground_truth" | "smoothed" | None,  # where the reference
                                             # landmarks come from (None: there are none)
         "reference_landmarks": int,         # how many reference landmarks
         "<estimator name>": {
             "ate_rmse_m": float,            # final trajectory vs reference
             "ate_online_rmse_m": float|None,# online trajectory; None for batch
             "ate_aligned_rmse_m": float,    # final, after the SE(2) fit over poses with truth
             "ate_online_aligned_rmse_m": float|None,  # online, the same
             "final_pose_error_m": float,    # position error of the last pose with truth
             "rpe_trans_rmse_m": float|None, # RPE over rpe_delta_frames, final trajectory
                                             # (pairs whose both ends have truth)
             "rpe_heading_rmse_rad": float|None,
             "nees_mean": float|None,        # mean NEES of the online poses with truth
                                             # (3-DoF; 3 if consistent); None without
                                             # covariances, against a smoothed reference,
                                             # or when aligned
             "nees_inside_95": float|None,   # share of them whose NEES is inside the 95 %
                                             # χ²(3) band [0.216, 9.35]
             "nees_count": int|None,         # how many online poses have a NEES (those with
                                             # truth and a positive-definite covariance)
             "nis_mean": float|None,         # mean NIS of the observations of landmarks
                                             # already mapped, against the prediction before
                                             # their step (2-DoF range-bearing; 2 if
                                             # consistent; range-only readings 1-DoF, 1);
                                             # needs no reference
             "nis_inside_95": float|None,    # share of them inside their χ²(dof) band: χ²(2)
                                             # [0.0506, 7.38], χ²(1) [0.000982, 5.02]
             "nis_count": int|None,          # how many observations have a NIS
             "map_rmse_m": float|None,       # None when no landmark id in common
             "map_height_rmse_m": float|None,# 3-D maps against true heights, else None
             "landmarks_estimated": int,
             "landmarks_found": int,         # reference landmarks it estimated
             "landmarks_missed": int,        # reference landmarks it never put in its map
             "association": dict|None,       # when the log has observations without ids (or the
                                             # estimator created landmarks): observations,
                                             # correct, wrong, rate, rejected, new (=
                                             # landmarks_created), duplicate_landmarks
             "unused_observations": dict|None, # the estimator's own counts of observations it
                                             # did not use (skipped, rejected, unconfirmed, ...)
             "aligned": bool,                # SE(2) alignment applied (first poses differ)
             "time_total_s": float,
             "time_step_p50_s": float|None,  # median step time; None for batch
             "time_step_p99_s": float|None,  # 99th percentile step time; None for batch
             "time_step_max_s": float|None,  # slowest step; None for batch
             "peak_memory_mb": float|None,   # resident memory the run added at its peak, MB
                                             # (10⁶ bytes; fgslam.memory); None if unmeasured
             "steps": int},                  # poses this estimator estimated
         ...}

    An estimator that estimated fewer poses than the reference (an interrupted run) is
    compared over the poses it has: ``steps`` says how many. Any figure that is not finite
    (e.g. a diverged filter, or no pose with truth among the ones it estimated) is ``None``.
    """
    if reference.kind not in REFERENCE_KINDS:
        raise ComparisonError(f"reference kind {reference.kind!r}; expected one of {REFERENCE_KINDS}")
    ref = _as_poses(reference.trajectory, "reference.trajectory")
    valid = reference.has_pose
    delta = rpe_delta_frames(ref, has_pose=valid)
    metrics: dict = {
        "reference": reference.kind,
        "log": str(log_path),
        "poses": int(len(ref)),
        "rpe_delta_frames": delta,
        "reference_poses_with_truth": reference.poses_with_truth,
        "landmark_reference": reference.landmark_reference,
        "reference_landmarks": int(len(reference.landmarks)),
    }
    for run in runs:
        if run.name in TOP_LEVEL_KEYS or run.name in metrics:
            raise ComparisonError(
                f"estimator name {run.name!r} clashes with another key of the metrics; rename it"
            )
        final = _as_poses(run.final, f"{run.name}.final")
        m = len(final)
        aligned, rot, trans = estimator_alignment(run, reference)
        final_a = apply_se2(final, rot, trans) if m else final

        ate_online = None
        if run.online is not None:
            online = _as_poses(run.online, f"{run.name}.online")
            if len(online) > len(ref):
                raise ComparisonError(
                    f"estimator {run.name!r}: online trajectory has {len(online)} poses, "
                    f"reference {len(ref)}"
                )
            if len(online):
                k = len(online)
                online_a = apply_se2(online, rot, trans)
                ate_online = _rmse(position_errors_m(online_a, ref[:k])[valid[:k]])

        p50 = p99 = tmax = None
        if run.step_times_s is not None:
            times = np.asarray(run.step_times_s, dtype=float).reshape(-1)
            if len(times):
                p50, p99 = np.percentile(times, [50.0, 99.0])
                tmax = float(np.max(times))
        found = len(set(run.landmarks) & set(reference.landmarks))

        rpe_trans, rpe_heading = relative_pose_errors(final, ref[:m], delta, has_pose=valid[:m])
        nees_mean = nees_inside = nees_count = None
        if (run.online_covariances is not None and run.online is not None and not aligned
                and reference.kind == "ground_truth"):
            values = nees_over_truth(run.online, run.online_covariances, ref, valid)
            values = values[np.isfinite(values)]
            if len(values):
                low, high = nees_band()
                nees_mean = float(np.mean(values))
                nees_inside = float(np.mean((values >= low) & (values <= high)))
            nees_count = int(len(values))
        nis_mean, nis_inside, nis_count = nis_summary(run.nis, run.nis_dofs)
        metrics[run.name] = {
            "ate_rmse_m": _json_float(_rmse(position_errors_m(final_a, ref[:m])[valid[:m]])),
            "ate_online_rmse_m": _json_float(ate_online),
            "ate_aligned_rmse_m": _json_float(aligned_ate_m(final, ref[:m], valid[:m])),
            "ate_online_aligned_rmse_m": _json_float(
                aligned_ate_m(_as_poses(run.online, "online"), ref, valid) if run.online is not None else None
            ),
            "final_pose_error_m": _json_float(final_pose_error_m(final_a, ref[:m], has_pose=valid[:m])),
            "rpe_trans_rmse_m": _json_float(_rmse(rpe_trans)),
            "rpe_heading_rmse_rad": _json_float(_rmse(rpe_heading)),
            "nees_mean": _json_float(nees_mean),
            "nees_inside_95": _json_float(nees_inside),
            "nees_count": nees_count,
            "nis_mean": _json_float(nis_mean),
            "nis_inside_95": _json_float(nis_inside),
            "nis_count": nis_count,
            "map_rmse_m": _json_float(map_rmse_m(run.landmarks, reference.landmarks, rot, trans)),
            "map_height_rmse_m": _json_float(_height_rmse_m(run.landmark_heights, reference.landmark_heights)),
            "landmarks_estimated": int(len(run.landmarks)),
            "landmarks_found": int(found),
            "landmarks_missed": int(len(reference.landmarks) - found),
            "association": _association_dict(run.association),
            "unused_observations": None if run.unused_observations is None else dict(run.unused_observations),
            "aligned": bool(aligned),
            "time_total_s": _json_float(run.total_time_s),
            "time_step_p50_s": _json_float(p50),
            "time_step_p99_s": _json_float(p99),
            "time_step_max_s": _json_float(tmax),
            "peak_memory_mb": None if run.peak_memory_bytes is None else round(run.peak_memory_bytes / 1e6, 3),
            "steps": int(m),
        }
    return metrics


def _height_rmse_m(estimated: Mapping[int, float] | None, reference: Mapping[int, float] | None) -> float | None:
    """RMS height error over the landmarks both maps give a height for (None if none)."""
    if not estimated or not reference:
        return None
    common = sorted(set(estimated) & set(reference))
    return _rmse(np.array([estimated[i] - reference[i] for i in common], dtype=float)) if common else None


def _association_dict(score: AssociationScore | None) -> dict | None:
    if score is None:
        return None
    return {
        "observations": score.observations,
        "correct": score.correct,
        "wrong": score.wrong,
        "rate": _json_float(score.rate),
        "rejected": score.rejected,
        "new": score.landmarks_created,
        "landmarks_created": score.landmarks_created,
        "duplicate_landmarks": len(score.duplicate_keys),
    }


def estimator_names(metrics: dict) -> list[str]:
    """The estimator entries of a metrics dictionary, in insertion order."""
    return [k for k, v in metrics.items() if k not in TOP_LEVEL_KEYS and isinstance(v, dict)]


# --------------------------------------------------------------------------- table

TABLE_HEADERS = (
    "estimator",
    "ATE final m",
    "ATE online m",
    "final err m",
    "map RMSE m",
    "landmarks",
    "total ms",
    "step p50 ms",
    "step p99 ms",
)

def _association_cell(m: dict) -> str:
    a = m.get("association")
    return "-" if a is None or a.get("rate") is None else f"{100 * a['rate']:.2f}"


def _association_counts_cell(m: dict) -> str:
    a = m.get("association")
    return "-" if a is None else f"{a.get('wrong', 0)}/{a.get('new', a.get('landmarks_created', 0))}/{a['rejected']}"


def _unused_cell(m: dict) -> str:
    u = m.get("unused_observations")
    if u is None:
        return "-"
    return " ".join(f"{v} {k}" for k, v in u.items() if v) or "0"


#: (header, metrics key, cell formatter) of the columns shown only when some run has them.
OPTIONAL_COLUMNS = (
    ("height RMSE m", "map_height_rmse_m", lambda m: _fmt(m.get("map_height_rmse_m"))),
    ("assoc %", "association", _association_cell),
    ("assoc wrong/new/rej", "association", _association_counts_cell),
    ("unused obs", "unused_observations", _unused_cell),
    ("NEES in %", "nees_inside_95", lambda m: _fmt(m.get("nees_inside_95"), 100.0, 1)),
    ("NIS in %", "nis_inside_95", lambda m: _fmt(m.get("nis_inside_95"), 100.0, 1)),
    ("peak MB", "peak_memory_mb", lambda m: _fmt(m.get("peak_memory_mb"), 1.0, 1)),
)

COLUMN_MEANINGS = {
    "ATE final m": "absolute trajectory error, metres: RMS position error of every pose as "
    "estimated after the last step",
    "ATE online m": "RMS position error, metres, of each pose as estimated at its own step "
    "(what the robot knew live); - for a one-shot batch solve",
    "final err m": "position error of the last pose (the last pose with ground truth when the "
    "truth has gaps), metres",
    "map RMSE m": "RMS landmark position error, metres, over the landmark ids both maps contain "
    "(against the log's surveyed landmarks whenever it has them)",
    "landmarks": "number of landmarks the estimator mapped",
    "total ms": "wall-clock time of the whole run, milliseconds",
    "step p50 ms": "median wall-clock time per step, milliseconds; - for a one-shot batch solve",
    "step p99 ms": "99th-percentile wall-clock time per step, milliseconds; - for a one-shot "
    "batch solve",
    "height RMSE m": "RMS error of the landmark heights, metres, for estimators with a 3-D map",
    "assoc %": "share of observations associated with the right landmark, for estimators that "
    "associate observations themselves (rejected ones count as wrong)",
    "assoc wrong/new/rej": "observations associated with the wrong landmark (or a duplicate), "
    "landmarks the estimator created, and observations it rejected (left unused), scored "
    "against the log's truth_landmark_id",
    "unused obs": "observations the estimator did not use, by reason, from its own counters: "
    "skipped (no id and no association), rejected (ambiguous), unconfirmed (a new landmark's "
    "first sighting no later one agreed with), gated (outside the gate of its id), dropped "
    "(withheld after a failed update); 0 when it used every observation",
    "NEES in %": "share of steps whose NEES (online pose error against ground truth, weighted by "
    "the covariance the estimator stated) lies inside the 95 % chi-square(3) band; about 95 for "
    "a consistent estimator, less when it is over-confident (only with ground truth, over the "
    "steps that have it)",
    "NIS in %": "share of observations of already mapped landmarks whose NIS (innovation against "
    "the estimator's prediction, weighted by its predicted covariance) lies inside the 95 % "
    "chi-square(2) band (chi-square(1) for a range-only reading); about 95 when consistent; needs no ground truth",
    "peak MB": "how far the process's resident memory rose during the run, megabytes (10^6 bytes)",
}

REFERENCE_DESCRIPTIONS = {
    "ground_truth": "ground truth recorded in the log",
    "smoothed": "smoothed solution (batch LM over the whole log; no ground truth)",
}


def _fmt(value, scale: float = 1.0, digits: int = 4) -> str:
    return "-" if value is None else f"{value * scale:.{digits}f}"


def describe_reference(
    kind: str, *, poses: int, poses_with_truth: int, landmark_reference: str | None, landmarks: int
) -> str:
    """What the figures are measured against, in words (no trailing full stop).

    * full ground truth: ``"ground truth recorded in the log"``;
    * partial: ``"ground truth recorded in the log, 1981 of 2238 poses (gaps in the truth:
      257 poses without truth are not scored)"``;
    * landmark-only truth: the smoothed trajectory, and the map against the surveyed landmarks;
    * smoothed: ``"smoothed solution (batch LM over the whole log; no ground truth)"``.

    With pose truth but no landmark truth it adds that the map is not scored.
    """
    if kind == "ground_truth":
        text = REFERENCE_DESCRIPTIONS["ground_truth"]
        if poses_with_truth < poses:
            missing = poses - poses_with_truth
            text += (
                f", {poses_with_truth} of {poses} poses (gaps in the truth: "
                f"{missing} {'pose' if missing == 1 else 'poses'} without truth "
                f"{'is' if missing == 1 else 'are'} not scored)"
            )
        if landmark_reference is None:
            text += "; no landmark truth, so no map error"
        return text
    if landmark_reference == "ground_truth":
        return (
            "smoothed solution (batch LM over the whole log) for the trajectory, as no pose has "
            f"ground truth; map error against the {landmarks} surveyed landmarks recorded in the log"
        )
    return REFERENCE_DESCRIPTIONS.get(kind, str(kind))


def reference_description(metrics: dict) -> str:
    """:func:`describe_reference` of a metrics dictionary (older dictionaries without the
    truth counts read as full ground truth or the smoothed solution, as they meant)."""
    kind = metrics.get("reference")
    poses = int(metrics.get("poses") or 0)
    with_truth = metrics.get("reference_poses_with_truth")
    if with_truth is None:
        with_truth = poses if kind == "ground_truth" else 0
    landmark_reference = metrics.get("landmark_reference", kind)
    return describe_reference(
        str(kind), poses=poses, poses_with_truth=int(with_truth), landmark_reference=landmark_reference,
        landmarks=int(metrics.get("reference_landmarks") or 0),
    )


def reference_line(metrics: dict) -> str:
    """One sentence saying what the figures are measured against.

    ``Reference: ground truth recorded in the log - run.jsonl, 660 poses`` with full truth;
    with gaps ``Reference: ground truth recorded in the log, 1981 of 2238 poses (gaps in the
    truth: 257 poses without truth are not scored) - r1.jsonl``.
    """
    what = reference_description(metrics)
    poses = metrics.get("poses")
    with_truth = metrics.get("reference_poses_with_truth")
    if metrics.get("reference") == "ground_truth" and with_truth is not None and with_truth != poses:
        return f"Reference: {what} - {metrics.get('log')}"  # the counts are in the description
    return f"Reference: {what} - {metrics.get('log')}, {poses} poses"


def table_rows(metrics: dict) -> tuple[tuple[str, ...], list[tuple[str, ...]], list[str]]:
    """The table shared by :func:`format_table` and the HTML report.

    Returns ``(headers, rows, notes)``: ``rows`` hold formatted strings (metres to 0.1 mm,
    times in milliseconds, ``-`` for "not applicable"); an ``*`` after an ATE means the
    estimate was aligned in SE(2); ``notes`` explain the marks that occur.
    """
    names = estimator_names(metrics)
    # Columns that only matter for some runs appear only when some estimator has them.
    optional = [
        (header, cell)
        for header, key, cell in OPTIONAL_COLUMNS
        if any(metrics[n].get(key) is not None for n in names)
    ]
    rows = []
    notes = []
    any_aligned = False
    for name in names:
        m = metrics[name]
        star = "*" if m.get("aligned") else ""
        any_aligned |= bool(m.get("aligned"))
        rows.append(
            (
                name,
                _fmt(m.get("ate_rmse_m")) + star,
                _fmt(m.get("ate_online_rmse_m")) + (star if m.get("ate_online_rmse_m") is not None else ""),
                _fmt(m.get("final_pose_error_m")),
                _fmt(m.get("map_rmse_m")),
                str(m.get("landmarks_estimated")),
                _fmt(m.get("time_total_s"), 1e3, 1),
                _fmt(m.get("time_step_p50_s"), 1e3, 3),
                _fmt(m.get("time_step_p99_s"), 1e3, 3),
                *(cell(m) for _, cell in optional),
            )
        )
        if m.get("steps") != metrics.get("poses"):
            notes.append(f"{name} estimated {m.get('steps')} of {metrics.get('poses')} poses")
    if any_aligned:
        notes.insert(0, "* aligned to the reference in SE(2) (first poses differ)")
    return TABLE_HEADERS + tuple(header for header, _ in optional), rows, notes


def format_table(metrics: dict) -> str:
    """A fixed-width terminal table of :func:`compute_metrics` output.

    First line: what the reference is. Then one row per estimator with ATE final, ATE
    online, final pose error, map RMSE (metres), landmark count, and total / median /
    99th-percentile step time (milliseconds). ``-`` means not applicable.
    """
    headers, rows, notes = table_rows(metrics)
    widths = [max(len(h), *(len(r[i]) for r in rows)) if rows else len(h) for i, h in enumerate(headers)]

    def line(cells) -> str:
        first = cells[0].ljust(widths[0])
        rest = [c.rjust(w) for c, w in zip(cells[1:], widths[1:])]
        return "  ".join([first, *rest]).rstrip()

    out = [reference_line(metrics), line(headers), line(["-" * w for w in widths])]
    out += [line(r) for r in rows]
    out += notes
    return "\n".join(out)


# --------------------------------------------------------------------------- TUM export


def format_tum(stamps_s, poses) -> str:
    """Trajectory in TUM format: one line ``t x y 0 qx qy qz qw`` per pose, in order.

    A planar heading θ is the rotation about z: ``qx = qy = 0, qz = sin(θ/2),
    qw = cos(θ/2)``. Numbers are written with ``repr`` (shortest text that reads back as
    the same float), so nothing is lost. The result ends with a newline (empty for no poses).
    """
    t = np.asarray(stamps_s, dtype=float).reshape(-1)
    p = _as_poses(poses, "poses")
    if len(t) != len(p):
        raise ComparisonError(f"format_tum: {len(t)} stamps but {len(p)} poses")
    lines = []
    for stamp, (x, y, theta) in zip(t, p):
        half = 0.5 * float(theta)
        values = (float(stamp), float(x), float(y), 0.0, 0.0, 0.0, math.sin(half), math.cos(half))
        lines.append(" ".join(repr(v) for v in values))
    return "".join(line + "\n" for line in lines)


def write_tum(path: str | os.PathLike[str], stamps_s, poses) -> None:
    """Write :func:`format_tum` output to ``path`` (overwriting it)."""
    Path(path).write_text(format_tum(stamps_s, poses), encoding="utf-8")


def read_tum(path: str | os.PathLike[str]) -> tuple[np.ndarray, np.ndarray]:
    """Read a TUM trajectory file into ``(stamps_s (n,), poses (n, 3))``.

    Blank lines and ``#`` comments are skipped. The heading is the yaw of the quaternion,
    ``atan2(2(qw qz + qx qy), 1 − 2(qy² + qz²))``, so files from other tools (with tiny
    non-zero qx, qy) read too; z is ignored. Raises :class:`ComparisonError` naming
    ``file:line`` for a malformed line.
    """
    stamps, poses = [], []
    with open(path, encoding="utf-8") as f:
        for line_no, raw in enumerate(f, start=1):
            text = raw.strip()
            if not text or text.startswith("#"):
                continue
            fields = text.split()
            if len(fields) != 8:
                raise ComparisonError(
                    f"{path}:{line_no}: expected 8 numbers 't x y z qx qy qz qw', got {len(fields)}"
                )
            try:
                t, x, y, _z, qx, qy, qz, qw = (float(v) for v in fields)
            except ValueError:
                raise ComparisonError(
                    f"{path}:{line_no}: not a number in {text!r}; a TUM line is 8 numbers "
                    "'t x y z qx qy qz qw'"
                ) from None
            yaw = math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
            stamps.append(t)
            poses.append((x, y, yaw))
    return np.asarray(stamps, dtype=float), np.asarray(poses, dtype=float).reshape(-1, 3)
