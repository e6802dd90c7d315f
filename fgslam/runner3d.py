"""Drive the 3-D estimators (seed 003: stereo camera + IMU) over one 3-D run log and score them.

The 3-D counterpart of :mod:`fgslam.runner` and :mod:`fgslam.compare` for logs with SE(3)
poses (docs/log-format.md, "3-D logs"). The log is read once (:func:`prepare_log3d`): its
typed steps become the inputs of the step protocol of :mod:`ekf.drive3d`
(:func:`ekf.drive3d.step_inputs`), its header the stereo rig, its records the noise. ``fgslam
run``, ``check`` and ``bench`` all go through it. Each estimator's ``step`` is timed with BLAS
pinned to one thread, and the consistency work (the pose covariance for NEES) runs outside
the timed region.

The world frame is the IMU at pose 0 and every estimator starts there, so trajectories are
compared without alignment. The reference is the log's truth wherever it has some
(``truth_pose3``; the map against ``truth_landmark3``): with gaps in the truth only the
poses that have it are scored (ATE, final error, NEES), and the table's reference line says
how many ("ground truth, N of M poses"). Without any pose truth it is the batch solution
of the factor graph (LM started from iSAM2's estimate), as in 2-D.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ekf.drive3d import StepInput, step_inputs
from ekf.vio import pose_nees
from fgslam.compare import TOP_LEVEL_KEYS, nees_band
from fgslam.compare.metrics import OPTIONAL_TOP_LEVEL_KEYS
from fgslam.failure import EstimatorFailed, EstimatorFailure, StepWatch, check_finite, failed_cell, reason_of
from fgslam.memory import PeakMemory, release_free_memory
from fgslam.noise3d import noise_of  # noqa: F401  (re-exported: read with the log)
from fgslam.registry import DEFAULTS, REGISTRY, build, names_for, parse_names
from fgslam.runner import pinned_threads
from slamio.datasets.seed003 import StereoImuNoise
from slamio.errors import FgslamError
from slamio.log import RunLog, StereoCalibration, TruthLandmark3, pose3_from_matrix, pose3_matrix, stereo_calibration
from slamio.log.columns import step_stamps
from slamio.log.columns3d import step_truths

#: name → factory(rig, noise): the 3-D estimators of :mod:`fgslam.registry` (what ``fgslam run
#: --estimators`` accepts on a 3-D log).
ESTIMATORS_3D: dict[str, Callable[[StereoCalibration, StereoImuNoise], object]] = {
    name: REGISTRY[name].factory for name in names_for(3)
}
DEFAULT_ESTIMATORS_3D = DEFAULTS[3]
POSE_DOF = 6
STEREO_DOF = 4


def make_estimator_3d(name: str, rig: StereoCalibration, noise: StereoImuNoise):
    """A fresh estimator ``name`` of :data:`ESTIMATORS_3D` for the stereo ``rig`` (the log
    header's calibration), named ``name``."""
    return build(name, 3, rig, noise)


def parse_estimator_names_3d(text: str | None) -> list[str]:
    """``"ekf-vio,isam2-3d"`` → names; unknown names and a missing isam2-3d are one-line errors."""
    return parse_names(text, 3)


@dataclass(frozen=True)
class Run3d:
    """One estimator's result on a 3-D log (poses are world_T_imu, (T, 4, 4))."""

    name: str
    online: np.ndarray | None  # each pose as estimated at its own step (None for batch)
    final: np.ndarray  # every pose as estimated after the last step
    landmarks: dict[int, np.ndarray]
    step_times_s: np.ndarray | None
    total_time_s: float
    covariances: np.ndarray | None = None  # (T, 6, 6) of the online pose, (ρ, φ), when taken
    nis: np.ndarray | None = None  # per accepted stereo observation (χ²₄ when consistent)
    peak_memory_bytes: int | None = None  # how far the resident memory rose during the run


@dataclass(frozen=True)
class Reference3d:
    kind: str  # "ground_truth" or "batch"
    trajectory: np.ndarray  # (T, 4, 4); NaN where a pose has no truth
    landmarks: dict[int, np.ndarray]
    has_pose: np.ndarray | None = None  # (T,) True where ``trajectory`` holds a pose; None: every pose

    @property
    def mask(self) -> np.ndarray:
        """(T,) booleans: the poses that are scored."""
        if self.has_pose is None:
            return np.ones(len(self.trajectory), dtype=bool)
        return np.asarray(self.has_pose, dtype=bool)

    @property
    def poses_with_truth(self) -> int:
        return int(np.count_nonzero(self.mask)) if self.kind == "ground_truth" else 0


def truth_reference_3d(log: RunLog, steps=None) -> Reference3d | None:
    """The log's ground truth as a :class:`Reference3d` (NaN poses and ``has_pose`` False in
    its gaps), with every ``truth_landmark3`` as the map; None when no pose has truth
    (``steps``: the log's steps when the caller has grouped them already)."""
    truths = step_truths(log.steps() if steps is None else steps)
    trajectory = np.full((len(truths), 4, 4), np.nan)
    has_pose = np.array([truth is not None for truth in truths], dtype=bool)
    if not has_pose.any():
        return None
    for t, truth in enumerate(truths):
        if truth is not None:
            trajectory[t] = truth.matrix()
    landmarks = {r.landmark_id: np.array([r.x_m, r.y_m, r.z_m]) for r in truth_landmarks3(log)}
    return Reference3d("ground_truth", trajectory, landmarks, has_pose)


def truth_landmarks3(log) -> list[TruthLandmark3]:
    """The ``truth_landmark3`` records of a 3-D log, in file order (a log read whole: from its
    records; read into columns, :class:`slamio.log.columns3d.ColumnLog3d`: kept apart)."""
    records = getattr(log, "records", None)
    if records is None:
        return list(log.truth_landmark_records)
    return [r for r in records if isinstance(r, TruthLandmark3)]


@dataclass(frozen=True)
class Comparison3d:
    runs: list[Run3d]
    reference: Reference3d
    stamps_s: np.ndarray
    smoother: object  # the StereoIsam2 the batch solve started from (None: isam2-3d failed)
    batch_error: float | None  # None: no batch solve (isam2-3d or the batch solve failed)
    isam2_error: float | None
    #: noise group ("imu", "stereo") → :class:`fgslam.verdict.GroupVerdict` at the batch optimum
    verdict: dict = field(default_factory=dict)
    #: the estimators that stopped mid-run (not in ``runs``), in the order they ran
    failures: list[EstimatorFailure] = field(default_factory=list)

    def smoother_short_of_optimum(self) -> None:
        """No note on a 3-D log (a planar :class:`fgslam.runner.Comparison` gives one when
        iSAM2's final estimate is not the batch optimum; metrics.json has both graph errors)."""
        return None


def run_estimator_3d(estimator, inputs: list[StepInput], *, covariances: bool = True, progress=None,
                     stamps_s=None) -> Run3d:
    """Feed every step's input (:func:`ekf.drive3d.step_inputs`); time each ``step`` (BLAS
    pinned to one thread) and measure the run's peak memory (:class:`fgslam.memory.PeakMemory`,
    the consistency work included).

    An exception from the estimator, or a pose or stated covariance that is not a number
    after a step (:func:`fgslam.failure.check_finite`), is raised as
    :class:`fgslam.failure.EstimatorFailed` naming the estimator, the step and the reason
    (with its time stamp from ``stamps_s``, the steps' times, when given)."""
    n = len(inputs)
    times = np.empty(n)
    covs = np.full((n, POSE_DOF, POSE_DOF), np.nan) if covariances else None
    watch = StepWatch(estimator.name, stamps_s)
    with watch.failures():
        with pinned_threads(), PeakMemory() as memory:
            _feed_3d(estimator, inputs, times, covs, progress, watch)
            watch.finishing()
            online = np.asarray(estimator.trajectory(), dtype=float)
            finish_s = 0.0
            final = online
            if hasattr(estimator, "finish"):
                start = time.perf_counter()
                estimator.finish()
                final = np.asarray(estimator.smoothed_trajectory(), dtype=float)
                finish_s = time.perf_counter() - start
        landmarks = dict(estimator.landmarks())
        nis = estimator.nis() if hasattr(estimator, "nis") else None
    return Run3d(estimator.name, online, final, landmarks, times, float(times.sum() + finish_s), covs, nis,
                 memory.peak_bytes)


def _feed_3d(estimator, inputs: list[StepInput], times: np.ndarray, covs: np.ndarray | None, progress,
             watch: StepWatch) -> None:
    """Every input into ``estimator``: ``times[t]`` each step's wall time, ``covs[t]`` (when
    not None) the stated pose covariance after it, taken outside the timed region."""
    n = len(inputs)
    every = max(1, n // 200)
    for t, args in enumerate(inputs):
        watch.step = t
        start = time.perf_counter()
        estimator.step(*args)
        times[t] = time.perf_counter() - start
        check_finite(estimator.current_pose())  # a diverged estimator fails here, not in the figures
        if covs is not None:  # outside the timed region
            try:
                covs[t] = estimator.current_covariance()
            except RuntimeError:  # gtsam.IndeterminateSystemException: no marginal this step
                pass
            else:
                check_finite(estimator.current_pose(), covs[t])
        if progress is not None and (t % every == 0 or t == n - 1):
            progress(t + 1, n, estimator.name)


@dataclass(frozen=True)
class Log3d:
    """A 3-D log made ready for the estimators, once: its steps, the stereo rig of its
    header, the one noise level its records state, and every step's input."""

    steps: list
    rig: StereoCalibration
    noise: StereoImuNoise
    inputs: list[StepInput]
    #: the header's start.pose3: where the IMU's first pose is in the log's world frame (the
    #: estimators start at the identity; their results are moved by it, :func:`in_world`)
    world_T_start: np.ndarray = field(default_factory=lambda: np.eye(4))

    @property
    def stamps_s(self) -> np.ndarray:
        return step_stamps(self.steps)

    def estimator(self, name: str):
        """A fresh estimator ``name`` for this log."""
        return make_estimator_3d(name, self.rig, self.noise)


def prepare_log3d(log: RunLog, steps=None) -> Log3d:
    """The :class:`Log3d` of a 3-D ``log`` (``steps``: its steps when already grouped).

    Errors (one line, naming the file): a planar log; records with more than one noise level
    (:func:`noise_of`).
    """
    if not log.header.is_3d:
        raise FgslamError(f"{log.path}: a planar log; the 3-D estimators need a 3-D log (start.pose3, stereo observations)")
    steps = log.steps() if steps is None else steps
    return Log3d(steps, stereo_calibration(log.header), noise_of(log, steps), list(step_inputs(steps)),
                 pose3_matrix(log.header.start_pose3))


def in_world(run: Run3d, world_T_start: np.ndarray) -> Run3d:
    """``run`` (estimated with the IMU's first pose at the identity) in the log's world frame,
    where the first pose is ``world_T_start``: every pose and landmark moved by it. The pose
    covariances are of the right perturbation, which a move on the left leaves as they are."""
    if np.allclose(world_T_start, np.eye(4), atol=1e-12):
        return run
    T = np.asarray(world_T_start, dtype=float)

    def moved(poses):
        return None if poses is None else np.einsum("ij,tjk->tik", T, poses)

    landmarks = {j: T[:3, :3] @ np.asarray(p, dtype=float) + T[:3, 3] for j, p in run.landmarks.items()}
    final = moved(run.final)
    online = final if run.online is run.final else moved(run.online)
    return dataclasses.replace(run, online=online, final=final, landmarks=landmarks)


def run_log3d(log: RunLog, names: list[str], *, consistency: bool = True, progress=None) -> Comparison3d:
    """Every named estimator on ``log``, then the batch solve from isam2-3d's graph.

    An estimator that fails mid-run (:class:`fgslam.failure.EstimatorFailed`) is kept in
    :attr:`Comparison3d.failures` and the others go on. When isam2-3d or the batch solve
    fails there is no batch solution: a log with pose truth is still compared against its
    truth; without truth nothing can be scored, and that is one :class:`FgslamError`."""
    ready = prepare_log3d(log)
    runs, failures, smoother = [], [], None
    for name in names:
        estimator = ready.estimator(name)
        try:
            run = run_estimator_3d(estimator, ready.inputs, covariances=consistency, progress=progress,
                                   stamps_s=ready.stamps_s)
        except EstimatorFailed as failed:
            failures.append(failed.failure)
            continue
        smoother = estimator if name == "isam2-3d" else smoother
        runs.append(in_world(run, ready.world_T_start))
    truth = truth_reference_3d(log, ready.steps)
    if smoother is not None:
        try:
            return _with_batch(ready, runs, failures, smoother, truth, progress)
        except EstimatorFailed as failed:  # the batch solve's
            failures.append(failed.failure)
    if truth is None:
        raise FgslamError(f"{log.path}: {failures[-1].sentence()}; the log has no pose truth, so the reference is "
                          "the batch solve from isam2-3d's graph: nothing can be scored")
    return Comparison3d(runs, truth, ready.stamps_s, smoother, None, None, failures=failures)


def _with_batch(ready: Log3d, runs: list, failures: list, smoother, truth: Reference3d | None,
                progress) -> Comparison3d:
    """The comparison with the batch solve from ``smoother``'s graph (an exception in it is
    raised as :class:`fgslam.failure.EstimatorFailed` named ``batch``)."""
    from fgslam.smoother3d import batch_solve
    from fgslam.verdict import verdict_or_none

    try:
        with pinned_threads(), PeakMemory() as memory:
            if progress is not None:
                progress(0, 1, "batch")
            batch = batch_solve(smoother)
            if progress is not None:
                progress(1, 1, "batch")
    except Exception as error:  # e.g. gtsam's IndeterminateSystemException
        raise EstimatorFailed(EstimatorFailure("batch", None, None, reason_of(error), "batch")) from error
    runs.append(in_world(Run3d("batch", None, batch.trajectory(), batch.landmarks(), None, batch.seconds,
                               peak_memory_bytes=memory.peak_bytes), ready.world_T_start))
    release_free_memory()  # what the batch solve's eliminations freed, before the verdict's
    reference = truth or Reference3d("batch", runs[-1].final, runs[-1].landmarks)
    return Comparison3d(runs, reference, ready.stamps_s, smoother, float(batch.error), smoother.error(),
                        verdict_or_none(smoother.graph, batch.values), failures)


# --------------------------------------------------------------------------- metrics


def position_rmse_m(estimate: np.ndarray, reference: np.ndarray, dims: int = 3, has_pose=None) -> float:
    """RMSE of the positions' first ``dims`` coordinates (3: in 3-D; 2: the top view), over
    the poses ``has_pose`` marks (default: all)."""
    d = estimate[:, :dims, 3] - reference[:, :dims, 3]
    if has_pose is not None:
        d = d[np.asarray(has_pose, dtype=bool)]
    return float(np.sqrt(np.mean(np.sum(d**2, axis=1))))


def final_position_error_m(estimate: np.ndarray, reference: Reference3d) -> float:
    """Distance between the estimate and the reference at the last pose the reference has."""
    last = int(np.flatnonzero(reference.mask)[-1])
    return float(np.linalg.norm(estimate[last, :3, 3] - reference.trajectory[last, :3, 3]))


def map_errors_m(landmarks: dict, reference: dict) -> np.ndarray:
    common = sorted(j for j in landmarks if j in reference)
    return np.array([np.linalg.norm(np.asarray(landmarks[j]) - np.asarray(reference[j])) for j in common])


def nees_values(run: Run3d, reference: Reference3d) -> np.ndarray | None:
    """Pose NEES of the online estimate at every step against the truth (NaN where it
    cannot be computed or the pose has no truth); None without truth or covariances."""
    if run.covariances is None or run.online is None or reference.kind != "ground_truth":
        return None
    return pose_nees_series(run.online, run.covariances, reference.trajectory)


def pose_nees_series(online: np.ndarray, covariances: np.ndarray, reference_trajectory: np.ndarray) -> np.ndarray:
    """(T,) pose NEES (χ²₆ when consistent) of each online pose against the reference pose
    of the same step; NaN where the covariance or the reference pose is missing or singular."""
    out = np.full(len(online), np.nan)
    for t, (T_hat, cov, T_true) in enumerate(zip(online, covariances, reference_trajectory)):
        if not (np.all(np.isfinite(cov)) and np.all(np.isfinite(T_true))):
            continue
        try:
            with np.errstate(all="ignore"):
                value = pose_nees(T_hat, cov, T_true)
        except (np.linalg.LinAlgError, ValueError, FloatingPointError):
            continue
        out[t] = value if math.isfinite(value) else np.nan
    return out


def _finite_or_none(value) -> float | None:
    return float(value) if value is not None and math.isfinite(float(value)) else None


#: The per-estimator keys of a 3-D run's metrics.json beyond those it shares with a planar one
#: (:data:`fgslam.compare.METRIC_KEYS`): the top-view ATE, the median map error, the mean step time.
METRIC_KEYS_3D = (
    "ate_rmse_m", "ate_2d_rmse_m", "ate_online_rmse_m", "final_pose_error_m", "landmarks_estimated",
    "map_median_m", "map_rmse_m", "time_step_mean_s", "time_step_p50_s", "time_step_p99_s", "time_step_max_s",
    "time_total_s", "peak_memory_mb", "steps", "nees_mean", "nees_inside_95", "nees_dof", "nis_mean", "nis_inside_95",
)
#: Top-level keys only a 3-D run's metrics.json has (with :data:`fgslam.compare.TOP_LEVEL_KEYS`).
TOP_LEVEL_KEYS_3D = ("dimension", "nees_band_95", "nis_band_95", "isam2_graph_error", "batch_graph_error")
#: A 3-D metrics.json from before the one schema (entries under "estimators"): old key → (new key, scale).
OLD_KEYS_3D = {
    "ate_3d_m": ("ate_rmse_m", 1.0), "ate_2d_m": ("ate_2d_rmse_m", 1.0), "ate_3d_online_m": ("ate_online_rmse_m", 1.0),
    "final_position_error_m": ("final_pose_error_m", 1.0), "landmarks": ("landmarks_estimated", None),
    "step_ms_mean": ("time_step_mean_s", 1e-3), "step_ms_median": ("time_step_p50_s", 1e-3),
    "total_s": ("time_total_s", 1.0), "nees_in_band": ("nees_inside_95", 1.0), "nis_in_band": ("nis_inside_95", 1.0),
}


def compute_metrics_3d(result: Comparison3d, *, log_path: str) -> dict:
    """metrics.json content for a 3-D log, in the planar run's schema
    (:func:`fgslam.compare.compute_metrics`): what the reference is at the top level, then one
    entry per estimator, keyed by its name, with the planar key names for the same figures
    (:data:`METRIC_KEYS_3D`), plus ``"dimension": 3`` and the 3-D bands and graph errors. The
    reference is ``"ground_truth"`` or ``"smoothed"`` (the batch solution) as in 2-D; a 3-D run
    has no RPE (no ``rpe_delta_frames``)."""
    reference = result.reference
    kind = "ground_truth" if reference.kind == "ground_truth" else "smoothed"  # a planar run's names
    metrics: dict = {
        "reference": kind,
        "log": log_path,
        "poses": int(len(result.stamps_s)),
        "reference_poses_with_truth": reference.poses_with_truth,
        "landmark_reference": kind if reference.landmarks else None,
        "reference_landmarks": len(reference.landmarks),
        "dimension": 3,
        "nees_band_95": list(nees_band(POSE_DOF)),
        "nis_band_95": list(nees_band(STEREO_DOF)),
        "isam2_graph_error": result.isam2_error,
        "batch_graph_error": result.batch_error,
    }
    for run in result.runs:
        if run.name in metrics:
            raise FgslamError(f"estimator name {run.name!r} clashes with another key of the metrics; rename it")
        m = {**_pose_metrics_3d(run, reference), **_time_metrics_3d(run), **_consistency_metrics_3d(run, reference)}
        metrics[run.name] = {k: _finite_or_none(v) if isinstance(v, float) else v for k, v in m.items()}
    return metrics


def _pose_metrics_3d(run: Run3d, reference: Reference3d) -> dict:
    """ATE (3-D and top view), final error and map figures of one run."""
    errors = map_errors_m(run.landmarks, reference.landmarks)
    scored = reference.mask
    return {
        "ate_rmse_m": position_rmse_m(run.final, reference.trajectory, 3, scored),
        "ate_2d_rmse_m": position_rmse_m(run.final, reference.trajectory, 2, scored),
        "ate_online_rmse_m": None if run.online is None else position_rmse_m(run.online, reference.trajectory, 3,
                                                                             scored),
        "final_pose_error_m": final_position_error_m(run.final, reference),
        "landmarks_estimated": len(run.landmarks),
        "map_median_m": float(np.median(errors)) if len(errors) else None,
        "map_rmse_m": float(np.sqrt(np.mean(errors**2))) if len(errors) else None,
    }


def _time_metrics_3d(run: Run3d) -> dict:
    """Step times (mean, median, 99th percentile, slowest; None for batch) and the total, seconds;
    the peak memory the run added, MB (10⁶ bytes)."""
    times = None if run.step_times_s is None or not len(run.step_times_s) else np.asarray(run.step_times_s, float)
    p50, p99 = (None, None) if times is None else (float(v) for v in np.percentile(times, [50.0, 99.0]))
    return {
        "time_step_mean_s": None if times is None else float(np.mean(times)),
        "time_step_p50_s": p50,
        "time_step_p99_s": p99,
        "time_step_max_s": None if times is None else float(np.max(times)),
        "time_total_s": run.total_time_s,
        "peak_memory_mb": None if run.peak_memory_bytes is None else round(run.peak_memory_bytes / 1e6, 3),
        "steps": int(len(run.final)),
    }


def _consistency_metrics_3d(run: Run3d, reference: Reference3d) -> dict:
    """Pose NEES on SE(3) (χ²₆) against the truth and stereo NIS (χ²₄), where measured."""
    out: dict = {}
    nees = nees_values(run, reference)
    if nees is not None and np.any(np.isfinite(nees)):
        low6, high6 = nees_band(POSE_DOF)
        v = nees[np.isfinite(nees)]
        out.update(nees_mean=float(np.mean(v)), nees_inside_95=float(np.mean((v >= low6) & (v <= high6))),
                   nees_dof=POSE_DOF)
    if run.nis is not None and len(run.nis):
        low4, high4 = nees_band(STEREO_DOF)
        out.update(nis_mean=float(np.mean(run.nis)), nis_inside_95=float(np.mean((run.nis >= low4) & (run.nis <= high4))))
    return out


def estimator_entries_3d(metrics: dict) -> dict[str, dict]:
    """name → figures of a 3-D metrics dictionary; one from before the one schema (entries
    under ``"estimators"``, :data:`OLD_KEYS_3D`) is read with the new key names."""
    if isinstance(metrics.get("estimators"), dict):  # an old 3-D metrics.json
        return {name: _upgrade_entry_3d(m) for name, m in metrics["estimators"].items()}
    skip = {*TOP_LEVEL_KEYS, *OPTIONAL_TOP_LEVEL_KEYS, *TOP_LEVEL_KEYS_3D}
    return {k: v for k, v in metrics.items() if k not in skip and isinstance(v, dict)}


def _upgrade_entry_3d(m: dict) -> dict:
    out = {}
    for key, value in m.items():
        new, scale = OLD_KEYS_3D.get(key, (key, None))
        out[new] = value * scale if scale is not None and value is not None else value
    return out


COLUMNS_3D = (
    ("ATE 3-D m", "ate_rmse_m", 1.0, 3),
    ("ATE 2-D m", "ate_2d_rmse_m", 1.0, 3),
    ("online 3-D m", "ate_online_rmse_m", 1.0, 3),
    ("final m", "final_pose_error_m", 1.0, 2),
    ("map med m", "map_median_m", 1.0, 3),
    ("landmarks", "landmarks_estimated", None, 0),
    ("NEES", "nees_mean", 1.0, 1),
    ("in band", "nees_inside_95", 100.0, 0),
    ("NIS", "nis_mean", 1.0, 2),
    ("ms/step", "time_step_mean_s", 1e3, 2),
    ("total s", "time_total_s", 1.0, 2),
    ("peak MB", "peak_memory_mb", 1.0, 0),
)


def table_rows_3d(metrics: dict) -> tuple[list[str], list[list[str]]]:
    header = ["estimator"] + [c[0] for c in COLUMNS_3D]
    rows = []
    batch_is_reference = metrics.get("reference") == "smoothed"
    errors = {"ate_rmse_m", "ate_2d_rmse_m", "final_pose_error_m", "map_median_m"}
    for name, m in estimator_entries_3d(metrics).items():
        if failed_cell(name, m) is not None:  # stopped mid-run: its name and why, no figures
            rows.append([name, failed_cell(name, m)])
            continue
        reference_row = name == "batch" and batch_is_reference  # the reference itself: nothing to score
        cells = ["batch (reference)" if reference_row else name]
        for _, key, scale, digits in COLUMNS_3D:
            v = m.get(key)
            if reference_row and key in errors:
                cells.append("ref")
            elif v is None:
                cells.append("–")
            elif scale is None:
                cells.append(str(v))
            else:
                cells.append(f"{v * scale:.{digits}f}" + ("%" if scale == 100.0 else ""))
        rows.append(cells)
    return header, rows


def reference_line_3d(metrics: dict) -> str:
    with_truth = metrics.get("reference_poses_with_truth", metrics["poses"])
    if metrics["reference"] == "ground_truth" and with_truth < metrics["poses"]:
        missing = metrics["poses"] - with_truth
        what = (f"ground truth, {with_truth} of {metrics['poses']} poses (gaps in the truth: {missing} "
                f"{'pose' if missing == 1 else 'poses'} without truth not scored)")
        if metrics["reference_landmarks"]:
            what += f" and {metrics['reference_landmarks']} landmarks"
    elif metrics["reference"] == "ground_truth":
        what = f"ground truth at all {metrics['poses']} poses"
        if metrics["reference_landmarks"]:
            what += f" and {metrics['reference_landmarks']} landmarks"
    else:
        what = (f"the batch solution (LM from iSAM2; no ground truth), graph error {metrics['batch_graph_error']:.1f} "
                f"against iSAM2's {metrics['isam2_graph_error']:.1f}")
    band = metrics["nees_band_95"]
    return (f"reference: {what}; positions compared without alignment (every estimator starts at the IMU's "
            f"first pose); NEES on SE(3), 95 % band {band[0]:.2f}..{band[1]:.2f} (χ²₆)")


def format_table_3d(metrics: dict) -> str:
    header, rows = table_rows_3d(metrics)
    full = [header, *(r for r in rows if len(r) == len(header))]  # a failed estimator's row: name, sentence
    widths = [max(len(r[i]) for r in full) for i in range(len(header))]
    widths[0] = max(len(r[0]) for r in [header, *rows])
    lines = [reference_line_3d(metrics), ""]
    for r in [header, *rows]:
        if len(r) < len(header):
            lines.append(f"{r[0].ljust(widths[0])}  {r[1]}")
            continue
        lines.append("  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(r, widths))))
    if metrics.get("reference") == "smoothed":
        lines.append("no ground truth: every error above is the distance to the smoothed solution (batch, the "
                     "reference) - agreement with it, not accuracy")
    return "\n".join(lines)


# --------------------------------------------------------------------------- TUM


def format_tum3(stamps_s, poses) -> str:
    """SE(3) trajectory in TUM format: ``t x y z qx qy qz qw`` per pose (``repr`` floats)."""
    stamps = np.asarray(stamps_s, dtype=float).reshape(-1)
    poses = np.asarray(poses, dtype=float)
    if poses.shape != (len(stamps), 4, 4):
        raise FgslamError(f"format_tum3: {len(stamps)} stamps but poses of shape {poses.shape}")
    lines = []
    for t, T in zip(stamps, poses):
        values = (float(t), *pose3_from_matrix(_nearest_rigid(T)))
        lines.append(" ".join(repr(v) for v in values))
    return "".join(line + "\n" for line in lines)


def _nearest_rigid(T: np.ndarray) -> np.ndarray:
    """``T`` with its rotation block projected onto SO(3) (the as-written ekf-s003's pose is not rigid)."""
    if not np.all(np.isfinite(T)):
        raise FgslamError("a trajectory holds a non-finite pose; cannot write it in TUM format")
    U, _, Vt = np.linalg.svd(T[:3, :3])
    R = U @ np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))]) @ Vt
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = R, T[:3, 3]
    return out


def write_tum3(path, stamps_s, poses) -> None:
    """Write :func:`format_tum3` to ``path``, whole or not at all (:mod:`fgslam.atomic`)."""
    from fgslam.atomic import write_text_whole

    write_text_whole(path, format_tum3(stamps_s, poses))
