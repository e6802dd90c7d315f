"""All comparison figures of a set of runs as one JSON-ready dictionary: :func:`compute_metrics`.

Also the keys of that dictionary (:data:`TOP_LEVEL_KEYS`, :data:`METRIC_KEYS`), the SE(2)
transform each run is measured with (:func:`estimator_alignment`; the report draws with the
same one), the NEES of the online poses that have truth (:func:`nees_over_truth`) and the
estimator entries of a dictionary (:func:`estimator_names`).

The shape of :func:`compute_metrics`'s dictionary (a 3-D log's run has the same shape,
:func:`fgslam.runner3d.compute_metrics_3d`)::

    {"reference": "ground_truth" | "smoothed",  # where the reference *trajectory* is from
     "log": log_path, "poses": n,
     "rpe_delta_frames": int,            # Δ of the RPE: the reference's frames per ~1 m
     "reference_poses_with_truth": int,  # poses scored against ground truth (n when all
                                         # have it; 0 against the smoothed solution)
     "landmark_reference": "ground_truth" | "smoothed" | None,  # where the reference
                                         # landmarks come from (None: there are none)
     "reference_landmarks": int,         # how many reference landmarks
     "dimension": 2,                     # of the log (a 3-D log's run: 3, same schema,
                                         # fgslam.runner3d.compute_metrics_3d)
     "<estimator name>": {
         "ate_rmse_m": float,            # final trajectory vs reference
         "ate_online_rmse_m": float|None,# online trajectory; None for batch
         "ate_aligned_rmse_m": float,    # final, after the SE(2) fit over poses with truth
         "ate_online_aligned_rmse_m": float|None,  # online, the same
         "final_pose_error_m": float,    # position error of the last pose with truth
         "rpe_trans_rmse_m": float|None, # RPE over rpe_delta_frames, final trajectory
                                         # (pairs whose both ends have truth with a
                                         # heading; None when the truth has none)
         "rpe_heading_rmse_rad": float|None,
         "nees_mean": float|None,        # mean NEES of the online poses with truth
                                         # (3-DoF; 3 if consistent; position-only, 2-DoF,
                                         # where the truth has no heading); None without
                                         # covariances, against a smoothed reference,
                                         # or when aligned
         "nees_inside_95": float|None,   # share of them whose NEES is inside the 95 %
                                         # band of its dof: χ²(3) [0.216, 9.35],
                                         # χ²(2) [0.0506, 7.38]
         "nees_inside_95_se": float|None,# its binomial standard error (errors.in_band_se)
         "nees_count": int|None,         # how many online poses have a NEES (those with
                                         # truth, a positive-definite covariance and,
                                         # when sampled, a step of the sample)
         "nees_dof": int|None,           # their degrees of freedom: 3, or 2 when the
                                         # truth has no heading (None: none, or mixed)
         "nis_mean": float|None,         # mean NIS of the observations of landmarks
                                         # already mapped, against the prediction before
                                         # their step (2-DoF range-bearing; 2 if
                                         # consistent; range-only readings 1-DoF, 1);
                                         # needs no reference
         "nis_inside_95": float|None,    # share of them inside their χ²(dof) band: χ²(2)
                                         # [0.0506, 7.38], χ²(1) [0.000982, 5.02]
         "nis_inside_95_se": float|None, # its standard error, the step the sampled unit
                                         # (errors.in_band_se_by_step)
         "nis_count": int|None,          # how many observations have a NIS (when
                                         # sampled: at the sample's NIS steps)
         "nis_dof": float|None,          # their mean degrees of freedom: what nis_mean
                                         # is when consistent (2; 1 for range-only)
         "consistency": dict|None,       # the steps NEES and NIS were taken at: mode
                                         # ("sampled" or "all"), seed, steps (of the log),
                                         # nees_steps, nis_steps (how many were drawn);
                                         # None when not taken (--no-consistency)
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
         "time_cpu_s": float|None,       # CPU time (time.thread_time) of the steps and
                                         # finish(); None for batch
         "time_consistency_cpu_s": float|None, # CPU time of the NEES/NIS work between the
                                         # steps and of the landmark covariances after the
                                         # run (untimed above); None when not taken
         "steps": int,                   # poses this estimator estimated
         "failure": str|None},           # why its estimate cannot be scored (NaN poses)
     "<estimator that failed mid-run>": {"failed": {"step": int|None, "time_s": float|None,
                                          "reason": str, "phase": "step"|"finish"|"batch"}},
                                         # and nothing else (fgslam.failure.with_failures)
     ...}

A run whose batch solve ran also has ``"noise_verdict"`` (per noise group: ``chi2``, ``dof``,
``chi2_per_dof``, ``band95``, ``fits``, ``sigma_factor``; :mod:`fgslam.verdict`) and
``"noise_source"`` (where the log's noise came from).
"""

from __future__ import annotations

import math
from typing import Mapping

import numpy as np

from fgslam.compare.alignment import align_se2, apply_se2, resolve_alignment
from fgslam.compare.association import AssociationScore
from fgslam.compare.errors import (
    in_band_se,
    in_band_se_by_step,
    _rmse,
    chi2_summary,
    final_pose_error_m,
    map_rmse_m,
    nees,
    nees_dofs,
    nis_summary,
    position_errors_m,
    relative_pose_errors,
    rpe_delta_frames,
)
from fgslam.compare.runs import REFERENCE_KINDS, ComparisonError, EstimatorRun, Reference, _as_poses


TOP_LEVEL_KEYS = (
    "reference",
    "log",
    "poses",
    "rpe_delta_frames",
    "reference_poses_with_truth",
    "landmark_reference",
    "reference_landmarks",
    "dimension",
    "provenance",
)
#: Top-level keys a run has only sometimes: the noise verdict of a planar run's batch solution
#: (:mod:`fgslam.verdict`), where the log's noise came from, and the log's ``event`` records
#: counted by kind (``{"bump": 3}``: what the robot met; the estimators ignore them).
OPTIONAL_TOP_LEVEL_KEYS = ("noise_verdict", "noise_source", "events")
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
    "nees_inside_95_se",
    "nees_count",
    "nees_dof",
    "nis_mean",
    "nis_inside_95",
    "nis_inside_95_se",
    "nis_count",
    "nis_dof",
    "consistency",
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
    "time_cpu_s",
    "time_consistency_cpu_s",
    "steps",
    "failure",
)


def _json_float(value) -> float | None:
    """A plain Python float, or None for NaN/inf/None (JSON has no NaN)."""
    if value is None:
        return None
    value = float(value)
    return value if math.isfinite(value) else None


def estimator_alignment(run: EstimatorRun, reference: Reference) -> tuple[bool, float, np.ndarray]:
    """The SE(2) transform :func:`compute_metrics` applies to one run (see :mod:`fgslam.compare.alignment`).

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


def nees_over_truth(online, covariances, reference, has_pose) -> tuple[np.ndarray, np.ndarray]:
    """``(values, dofs)``: NEES (:func:`nees`) of the online poses that have truth, in pose
    order, and each one's degrees of freedom (3; 2 where the truth has no heading:
    :func:`nees_dofs`). Values of a covariance that is not positive definite are NaN (the
    caller decides what they mean)."""
    e = _as_poses(online, "online")
    k = len(e)
    valid = np.asarray(has_pose, dtype=bool).reshape(-1)[:k]
    r = _as_poses(reference, "reference")[:k]
    P = np.asarray(covariances, dtype=float)[:k]
    return nees(e[valid], P[valid], r[valid]), nees_dofs(r[valid])


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

    The dictionary's shape is in the module docstring.

    An estimator that estimated fewer poses than the reference (an interrupted run) is
    compared over the poses it has: ``steps`` says how many. Any figure that is not finite
    (e.g. a diverged filter, or no pose with truth among the ones it estimated) is ``None``.
    """
    if reference.kind not in REFERENCE_KINDS:
        raise ComparisonError(f"reference kind {reference.kind!r}; expected one of {REFERENCE_KINDS}")
    ref = _as_poses(reference.trajectory, "reference.trajectory")
    delta = rpe_delta_frames(ref, has_pose=reference.has_pose)
    metrics: dict = {
        "reference": reference.kind,
        "log": str(log_path),
        "poses": int(len(ref)),
        "rpe_delta_frames": delta,
        "reference_poses_with_truth": reference.poses_with_truth,
        "landmark_reference": reference.landmark_reference,
        "reference_landmarks": int(len(reference.landmarks)),
        "dimension": 2,
    }
    for run in runs:
        if run.name in TOP_LEVEL_KEYS or run.name in OPTIONAL_TOP_LEVEL_KEYS or run.name in metrics:
            raise ComparisonError(
                f"estimator name {run.name!r} clashes with another key of the metrics; rename it"
            )
        metrics[run.name] = _run_metrics(run, reference, ref, delta)
    return metrics


def _run_metrics(run: EstimatorRun, reference: Reference, ref: np.ndarray, delta: int) -> dict:
    """One estimator's entry of :func:`compute_metrics` (``ref``: the reference poses)."""
    valid = reference.has_pose
    final = _as_poses(run.final, f"{run.name}.final")
    m = len(final)
    aligned, rot, trans = estimator_alignment(run, reference)
    final_a = apply_se2(final, rot, trans) if m else final
    rpe_trans, rpe_heading = relative_pose_errors(final, ref[:m], delta, has_pose=valid[:m])
    found = len(set(run.landmarks) & set(reference.landmarks))
    return {
        "ate_rmse_m": _json_float(_rmse(position_errors_m(final_a, ref[:m])[valid[:m]])),
        "ate_online_rmse_m": _json_float(_online_ate_m(run, ref, valid, rot, trans)),
        "ate_aligned_rmse_m": _json_float(aligned_ate_m(final, ref[:m], valid[:m])),
        "ate_online_aligned_rmse_m": _json_float(
            aligned_ate_m(_as_poses(run.online, "online"), ref, valid) if run.online is not None else None
        ),
        "final_pose_error_m": _json_float(final_pose_error_m(final_a, ref[:m], has_pose=valid[:m])),
        "rpe_trans_rmse_m": _json_float(_rmse(rpe_trans)),
        "rpe_heading_rmse_rad": _json_float(_rmse(rpe_heading)),
        **_consistency_metrics(run, reference, ref, aligned),
        "map_rmse_m": _json_float(map_rmse_m(run.landmarks, reference.landmarks, rot, trans)),
        "map_height_rmse_m": _json_float(_height_rmse_m(run.landmark_heights, reference.landmark_heights)),
        "landmarks_estimated": int(len(run.landmarks)),
        "landmarks_found": int(found),
        "landmarks_missed": int(len(reference.landmarks) - found),
        "association": _association_dict(run.association),
        "unused_observations": None if run.unused_observations is None else dict(run.unused_observations),
        "aligned": bool(aligned),
        **_time_metrics(run),
        "steps": int(m),
        "failure": _failure(final),
    }


def _failure(final: np.ndarray) -> str | None:
    """Why an estimate cannot be scored (its first non-finite pose), or None."""
    bad = ~np.all(np.isfinite(final), axis=1) if len(final) else np.zeros(0, dtype=bool)
    if not bad.any():
        return None
    first = int(np.flatnonzero(bad)[0])
    return f"its estimate is not a number from pose {first} on ({int(bad.sum())} of {len(final)} poses)"


def _online_ate_m(run: EstimatorRun, ref: np.ndarray, valid: np.ndarray, rot, trans) -> float | None:
    """ATE of the online trajectory, with the final trajectory's alignment (None for batch)."""
    if run.online is None:
        return None
    online = _as_poses(run.online, f"{run.name}.online")
    if len(online) > len(ref):
        raise ComparisonError(
            f"estimator {run.name!r}: online trajectory has {len(online)} poses, "
            f"reference {len(ref)}"
        )
    if not len(online):
        return None
    k = len(online)
    return _rmse(position_errors_m(apply_se2(online, rot, trans), ref[:k])[valid[:k]])


def _consistency_metrics(run: EstimatorRun, reference: Reference, ref: np.ndarray, aligned: bool) -> dict:
    """NEES of the online poses against ground truth (not when aligned) and NIS, in key order."""
    nees_mean = nees_inside = nees_count = nees_dof = None
    if (run.online_covariances is not None and run.online is not None and not aligned
            and reference.kind == "ground_truth"):
        values, dofs = nees_over_truth(run.online, run.online_covariances, ref, reference.has_pose)
        nees_mean, nees_inside, nees_count = chi2_summary(values, dofs)
        finite_dofs = set(dofs[np.isfinite(values)].tolist())
        nees_dof = finite_dofs.pop() if len(finite_dofs) == 1 else None
    nis_mean, nis_inside, nis_count = nis_summary(run.nis, run.nis_dofs)
    nis_dof = None
    if nis_count:  # the mean a consistent estimator's NIS would have (2, or 1 for range-only readings)
        values = np.asarray(run.nis, dtype=float).reshape(-1)
        dofs = np.full(len(values), 2.0) if run.nis_dofs is None else np.asarray(run.nis_dofs, dtype=float)
        nis_dof = float(np.mean(dofs[np.isfinite(values)]))
    return {
        "nees_mean": _json_float(nees_mean),
        "nees_inside_95": _json_float(nees_inside),
        "nees_inside_95_se": _json_float(in_band_se(nees_inside, nees_count)),
        "nees_count": nees_count,
        "nees_dof": nees_dof,
        "nis_mean": _json_float(nis_mean),
        "nis_inside_95": _json_float(nis_inside),
        "nis_inside_95_se": _json_float(
            None if run.nis_steps is None or not nis_count else in_band_se_by_step(run.nis, run.nis_dofs, run.nis_steps)),
        "nis_count": nis_count,
        "nis_dof": _json_float(nis_dof),
        "consistency": None if run.consistency is None else dict(run.consistency),
    }


def _time_metrics(run: EstimatorRun) -> dict:
    """Total time, median/99th-percentile/slowest step (None for batch) and peak memory."""
    p50 = p99 = tmax = None
    if run.step_times_s is not None:
        times = np.asarray(run.step_times_s, dtype=float).reshape(-1)
        if len(times):
            p50, p99 = np.percentile(times, [50.0, 99.0])
            tmax = float(np.max(times))
    return {
        "time_total_s": _json_float(run.total_time_s),
        "time_step_p50_s": _json_float(p50),
        "time_step_p99_s": _json_float(p99),
        "time_step_max_s": _json_float(tmax),
        "peak_memory_mb": None if run.peak_memory_bytes is None else round(run.peak_memory_bytes / 1e6, 3),
        "time_cpu_s": _json_float(run.cpu_time_s),
        "time_consistency_cpu_s": _json_float(run.consistency_cpu_s),
    }


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
    return [k for k, v in metrics.items()
            if k not in TOP_LEVEL_KEYS and k not in OPTIONAL_TOP_LEVEL_KEYS and isinstance(v, dict)]
