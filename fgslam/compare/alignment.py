"""SE(2) alignment of an estimate onto the reference, and the policy of when to apply it.

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

import numpy as np

from fgslam.compare.runs import ComparisonError, _as_poses, _as_xy
from slamio.geometry import wrap_angle


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
        tol_rad: largest wrapped difference between the first headings, radians (not
            used when the reference's first heading is NaN: a truth without heading).
    """
    e = _as_poses(estimate, "estimate")
    r = _as_poses(reference, "reference")
    if len(e) == 0 or len(r) == 0:
        return False
    distance_m = math.hypot(e[0, 0] - r[0, 0], e[0, 1] - r[0, 1])
    if not math.isfinite(r[0, 2]):  # a truth without heading (GPS): the positions decide
        return distance_m <= tol_m
    heading_rad = abs(float(wrap_angle(e[0, 2] - r[0, 2])))
    return distance_m <= tol_m and heading_rad <= tol_rad


def reference_rows(reference, has_pose=None) -> np.ndarray:
    """``(n,)`` booleans: the rows of ``reference`` that hold a pose to compare against.

    ``has_pose`` when given (as :attr:`Reference.has_pose`), otherwise the rows whose x and y
    are finite (a NaN row is a pose without truth; a NaN heading alone, a truth that measures
    position only, still counts).
    """
    r = _as_poses(reference, "reference")
    if has_pose is None:
        return np.all(np.isfinite(r[:, :2]), axis=1)
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
