"""Drive every estimator over the same log, time each step, and pick the reference.

This is the one place that knows about all estimators. Estimators stay pure; the runner
measures (``time.perf_counter`` around each step) and collects, for each estimator, the
*online* trajectory (each pose as estimated at its own step — what the robot would have
acted on) and the *final* one (every pose as estimated after the last step).

Timings are honest (:data:`TIMING`): BLAS and OpenMP are pinned to one thread around each
estimator run (threadpoolctl). A multithreaded BLAS on small matrices spends more time
handing work between threads than computing — on a 200-landmark grid the EKF took 23.2 s
instead of 3.6 s and the table reversed which estimator is faster (on a busy 2-core machine:
197 s instead of 5 s) — and it would time the machine's core count, not the algorithm.

It also picks the reference (:func:`choose_reference`): ground truth wherever the log has
it — all poses, or only some (real datasets have gaps in their motion capture; poses
without truth are then not scored) — else the smoothed batch solution, with the log's
surveyed landmarks as the map reference when it has them.
"""

from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass, field
from typing import Callable, Iterator, Sequence

import gtsam
import numpy as np
import scipy.linalg  # noqa: F401  (scipy's own BLAS is loaded now, so the thread limit below covers it)
from threadpoolctl import threadpool_limits

from fgslam.compare import NIS_DOF, EstimatorRun, Reference, relabel_landmarks, score_associations
from fgslam.consistency_sample import ConsistencySample, every_step, sample_of_steps
from fgslam.failure import EstimatorFailed, EstimatorFailure, StepWatch, check_finite, reason_of
from fgslam.memory import PeakMemory
from fgslam.registry import DEFAULTS, REGISTRY, isam2_names, names_for, parse_names
from fgslam.registry import expected_outlier_kernel  # noqa: F401  (scripts import it from here)
from fgslam.smoother import Isam2Smoother, batch_solve
from fgslam.verdict import verdict_or_none
from slamio.errors import FgslamError
from slamio.estimator import Estimator
from slamio.log import Header, RunLog, Step
from slamio.log.columns import ColumnLog, StepColumns, step_stamps

#: name → factory(header): the planar estimators of :mod:`fgslam.registry` (what ``--estimators``
#: accepts on a planar log).
ESTIMATORS: dict[str, Callable[[Header], Estimator]] = {name: REGISTRY[name].factory for name in names_for(2)}
ISAM2_NAMES = isam2_names(2)
DEFAULT_ESTIMATORS = DEFAULTS[2]


#: Threads BLAS/OpenMP may use while an estimator runs (see the module docstring).
BLAS_THREADS = 1

#: What the times in metrics.json and the table are (``fgslam run`` writes it out).
TIMING = {
    "what": "wall time of estimator.step per step (the total adds finish()), BLAS pinned to 1 thread",
    "clock": "time.perf_counter",
    "blas_threads": BLAS_THREADS,
    "outside_the_timed_region": "NIS before a step, the covariance for NEES after it (at every step or at "
                                "the sampled ones: consistency.mode), association bookkeeping",
    # printed under the table when NIS/NEES ran at every step and an iSAM2 did (measured on MRCLAM
    # and Victoria Park, docs/performance.md: the EKF's steps slow by a few per cent)
    "consistency_note": "the NIS/NEES work between the steps is not timed but slows iSAM2's own steps "
                        "(30-50 % on real logs); --no-consistency times the estimators alone",
    # … and when they ran at the sampled steps (fgslam.consistency_sample; no slow-down measured,
    # docs/performance.md)
    "sampled_note": "NIS/NEES at the sampled steps run between the steps, untimed (their CPU time: "
                    "time_consistency_cpu_s in metrics.json); --no-consistency times the estimators alone",
}


@contextlib.contextmanager
def pinned_threads(threads: int | None = BLAS_THREADS) -> Iterator[None]:
    """BLAS and OpenMP limited to ``threads`` inside (None: left as they are)."""
    if threads is None:
        yield
        return
    with threadpool_limits(limits=threads):
        yield


#: Progress callback: (steps done, steps in all, what is running).
Progress = Callable[[int, int, str], None]


@dataclass(frozen=True)
class Comparison:
    """Everything ``fgslam run`` reports: one run per estimator (and the batch solve)."""

    runs: list[EstimatorRun]
    reference: Reference
    stamps_s: np.ndarray
    smoother: Isam2Smoother | None = None  # the iSAM2 run the batch solve started from (its graph)
    #: χ²/2 of that iSAM2's final estimate and of the batch optimum started from it.
    batch_errors: tuple[float, float] | None = None
    #: noise group → :class:`fgslam.verdict.GroupVerdict` at the batch optimum (empty: none)
    verdict: dict = field(default_factory=dict)
    #: the estimators that stopped mid-run (not in ``runs``), in the order they ran
    failures: list[EstimatorFailure] = field(default_factory=list)

    def smoother_short_of_optimum(self) -> str | None:
        """A note when iSAM2's final estimate is not the batch optimum (its χ²/2 more than
        :data:`OPTIMUM_TOLERANCE` above, and by more than :data:`OPTIMUM_FLOOR`): the log's
        odometry and observations disagree strongly somewhere, and the two answers are
        different minima."""
        if self.batch_errors is None or self.smoother is None:
            return None
        isam2, batch = self.batch_errors
        if not isam2 > max(batch * (1.0 + OPTIMUM_TOLERANCE), batch + OPTIMUM_FLOOR):
            return None
        failures = self.smoother.update_failures
        return (
            f"{self.smoother.name}'s final estimate is not the batch optimum: the batch solve lowered χ²/2 from "
            f"{isam2:.6g} to {batch:.6g}. The odometry and the observations disagree strongly somewhere "
            f"(a corrupted odometry record, a misread landmark?)"
            + (f"; iSAM2 recovered from {failures} failed update{'s' if failures != 1 else ''}" if failures else "")
            + ". Look at the trajectories in the report."
        )


#: iSAM2's final χ²/2 may exceed the batch optimum's by this share before ``fgslam run`` says so
#: (it is within 0.012 % on every log measured, docs/performance.md).
OPTIMUM_TOLERANCE = 1e-3
#: … and by this much in χ²/2 at least: a log with nothing to disagree about (odometry alone,
#: χ²/2 about 1e-22) differs from its optimum only by rounding, which no share can judge; a
#: χ²/2 lower by 10⁻³ is nothing against the one unit per residual a consistent run has.
OPTIMUM_FLOOR = 1e-3


def parse_estimator_names(text: str, *, need_isam2: bool = True) -> list[str]:
    """``"ekf,isam2"`` → ``["ekf", "isam2"]``, rejecting unknown or missing names, and (with
    ``need_isam2``, for ``fgslam run``'s batch solve) a list without an iSAM2 estimator
    (:func:`fgslam.registry.parse_names` for a planar log)."""
    return parse_names(text, 2, need_isam2=need_isam2)


def run_estimator(
    estimator: Estimator, steps: Sequence[Step], progress: Progress | None = None, *, covariances: bool = True,
    blas_threads: int | None = BLAS_THREADS, sample: ConsistencySample | None = None,
) -> tuple[EstimatorRun, Estimator]:
    """Feed ``steps`` to ``estimator`` in order, timing each step and ``finish()``, with BLAS
    and OpenMP pinned to ``blas_threads`` (default 1; None leaves them as they are).

    With ``covariances`` (default) two consistency measurements are taken outside the
    timed region: before each step, the NIS of its observations against the estimator's
    prediction (``predicted_nis``, where the estimator offers it); after it, the covariance
    the estimator states for its online pose (for NEES). A run that only serves as a
    reference or a timing can skip that work. ``sample``
    (:mod:`fgslam.consistency_sample`) takes the NIS and the covariance only at its steps
    (None: at every step); the other steps' covariances are NaN. The CPU time of the steps
    and of that work (``time.thread_time``) is kept apart. The peak memory of the whole run is measured
    too (:class:`fgslam.memory.PeakMemory`; the consistency work is included in it).

    An exception from the estimator (in a step, ``finish()`` or reading its final estimate),
    or a pose or stated covariance that is not a number after a step
    (:func:`fgslam.failure.check_finite`), is raised as :class:`fgslam.failure.EstimatorFailed`
    naming the estimator, the step and the reason.
    """
    sample = every_step(len(steps)) if sample is None else sample
    trace = _Trace(len(steps), covariances and hasattr(estimator, "current_covariance"),
                   covariances and hasattr(estimator, "predicted_nis"), hasattr(estimator, "step_associations"),
                   sample)
    watch = trace.watch = StepWatch(estimator.name, step_stamps(steps))
    with watch.failures():
        with pinned_threads(blas_threads), PeakMemory() as memory:
            _feed_steps(estimator, steps, progress, trace)
            watch.finishing()
            start, start_cpu = time.perf_counter(), time.thread_time()
            estimator.finish()
            final = np.asarray(estimator.trajectory(), dtype=float)
            finish_s = time.perf_counter() - start
            trace.step_cpu_s += time.thread_time() - start_cpu
        landmarks, heights, landmark_covariances, association = _final_map(estimator, trace, covariances)
    with_nis = trace.with_nis
    run = EstimatorRun(
        name=estimator.name,
        online=trace.online,
        final=final,
        landmarks=landmarks,
        step_times_s=trace.step_times_s,
        total_time_s=float(trace.step_times_s.sum() + finish_s),
        association=association,
        landmark_heights=heights or None,
        online_covariances=trace.pose_covariances,
        nis=np.array(trace.nis_values) if with_nis else None,
        nis_steps=np.array(trace.nis_steps, dtype=int) if with_nis else None,
        nis_dofs=np.array(trace.nis_dofs, dtype=int) if with_nis else None,
        peak_memory_bytes=memory.peak_bytes,
        landmark_covariances=landmark_covariances or None,
        unused_observations=unused_observations(estimator),
        consistency=_consistency_description(trace, sample, covariances),
        cpu_time_s=trace.step_cpu_s,
        consistency_cpu_s=(trace.consistency_cpu_s + trace.map_covariance_cpu_s
                           if (trace.pose_covariances is not None or with_nis) else None),
        map_covariance_cpu_s=trace.map_covariance_cpu_s if landmark_covariances else None,
    )
    return run, estimator


def _consistency_description(trace: "_Trace", sample: ConsistencySample, covariances: bool) -> dict | None:
    """What metrics.json says of the steps the NEES and NIS were taken at (None: not taken)."""
    if not covariances or (trace.pose_covariances is None and not trace.with_nis):
        return None
    return sample.description()


class _Trace:
    """What :func:`run_estimator` records step by step: the online poses and step times, and
    outside the timed region the pose covariances, the NIS values and the association keys."""

    def __init__(self, n: int, with_covariance: bool, with_nis: bool, associating: bool,
                 sample: ConsistencySample) -> None:
        self.online = np.empty((n, 3))
        self.step_times_s = np.empty(n)
        self.step_cpu_s = 0.0  # time.thread_time of the steps and finish()
        self.consistency_cpu_s = 0.0  # time.thread_time of the NIS and covariance work between the steps
        self.map_covariance_cpu_s = 0.0  # … and of the landmark covariances after the run
        self.pose_covariances = np.full((n, 3, 3), np.nan) if with_covariance else None  # NaN where not taken
        self.nees_at, self.nis_at = sample.nees, sample.nis  # the steps to take each at
        self.with_nis = with_nis
        self.associating = associating
        self.nis_values: list[float] = []
        self.nis_steps: list[int] = []
        self.nis_dofs: list[int] = []
        self.true_ids: list[int | None] = []
        self.keys: list[int | None] = []
        self.hidden = False  # an observation (not range-only) without a landmark id was fed (seen when associating)
        self.watch: StepWatch | None = None  # the step being fed, for a failure's report


def _feed_steps(estimator: Estimator, steps: Sequence[Step], progress: Progress | None, trace: _Trace) -> None:
    """Every step into ``estimator``, timing ``step`` and ``current_pose`` alone; after each,
    its pose and stated covariance must be numbers (:func:`fgslam.failure.check_finite`)."""
    every = max(1, len(steps) // 200)
    for i, step in enumerate(steps):
        if trace.watch is not None:
            trace.watch.step = i
        if trace.with_nis and trace.nis_at[i]:  # against the prediction, so before the step; not timed
            cpu = time.thread_time()
            for observation, value in zip(step.observations, estimator.predicted_nis(step)):  # type: ignore[attr-defined]
                if value is not None:
                    trace.nis_values.append(value)
                    trace.nis_steps.append(i)
                    trace.nis_dofs.append(1 if observation.range_only else NIS_DOF)
            trace.consistency_cpu_s += time.thread_time() - cpu
        cpu = time.thread_time()
        start = time.perf_counter()
        estimator.step(step)
        trace.online[i] = estimator.current_pose()
        trace.step_times_s[i] = time.perf_counter() - start
        trace.step_cpu_s += time.thread_time() - cpu
        check_finite(trace.online[i])  # a diverged estimator fails here, not in the figures
        if trace.pose_covariances is not None and trace.nees_at[i]:  # for NEES; outside the timed region
            cpu = time.thread_time()
            trace.pose_covariances[i] = _stated_covariance(estimator, trace.online[i])
            trace.consistency_cpu_s += time.thread_time() - cpu
        if trace.associating:  # bookkeeping for the score, outside the timed region
            trace.keys.extend(estimator.step_associations())  # type: ignore[attr-defined]
            trace.true_ids.extend(_true_id(o) for o in step.observations)
            trace.hidden = trace.hidden or any(o.landmark_id is None and not o.range_only for o in step.observations)
        if progress is not None and (i % every == 0 or i == len(steps) - 1):
            progress(i + 1, len(steps), estimator.name)


def _stated_covariance(estimator: Estimator, pose: np.ndarray):
    """The covariance ``estimator`` states for its online ``pose`` (NaN when iSAM2 cannot form
    the marginal this step); a stated covariance that is not a number fails the run."""
    try:
        covariance = estimator.current_covariance()  # type: ignore[attr-defined]
    except RuntimeError:  # gtsam.IndeterminateSystemException: no marginal this step
        return np.nan
    check_finite(pose, covariance)
    return covariance


def _final_map(estimator: Estimator, trace: _Trace, covariances: bool):
    """``(landmarks, heights, landmark covariances, association score)`` after the run, the
    maps relabelled to the true ids when the estimator associated observations itself."""
    landmarks = dict(estimator.landmarks())
    heights = dict(estimator.landmark_heights()) if hasattr(estimator, "landmark_heights") else None
    cpu = time.thread_time()  # the map's ellipses: consistency work too (iSAM2's builds the whole graph's marginals)
    landmark_covariances = (
        dict(estimator.landmark_covariances())  # type: ignore[attr-defined]
        if covariances and hasattr(estimator, "landmark_covariances") else None
    )
    trace.map_covariance_cpu_s = time.thread_time() - cpu
    keys = trace.keys
    if hasattr(estimator, "associations"):  # ids settled after their step (deferred first sightings)
        keys = estimator.associations()  # type: ignore[attr-defined]
    association = None
    if trace.associating and (trace.hidden or any(k is not None and k < 0 for k in keys)):  # it associated: score it
        association = score_associations(trace.true_ids, keys)
        landmarks = relabel_landmarks(landmarks, association)
        heights = relabel_landmarks(heights, association) if heights else heights
        if landmark_covariances:
            landmark_covariances = relabel_landmarks(landmark_covariances, association)
    return landmarks, heights, landmark_covariances, association


def unused_observations(estimator) -> dict[str, int] | None:
    """The estimator's own counts of observations it did not use, by reason (None when it
    keeps no such counters): always shown, so a run that ignored its observations says so."""
    counters = {  # attribute → reason
        "skipped_unknown_id": "skipped",  # EkfSlam
        "rejected_observations": "rejected",
        "gated_known_id": "gated",
        "dropped_observations": "dropped",  # Isam2Smoother
        "rejected_first_sightings": "unconfirmed",
    }
    out: dict[str, int] = {}
    for attribute, reason in counters.items():
        value = getattr(estimator, attribute, None)
        if isinstance(value, int):
            out[reason] = out.get(reason, 0) + value
    for reason, value in (getattr(estimator, "association_counts", None) or {}).items():
        if reason in ("skipped", "rejected", "unconfirmed"):
            out[reason] = out.get(reason, 0) + int(value)
    return out or None


def _true_id(observation) -> int | None:
    """The landmark an observation really saw: its hidden true id, else its logged id."""
    if observation.truth_landmark_id is not None:
        return observation.truth_landmark_id
    return observation.landmark_id


def truth_trajectory(steps: Sequence[Step]) -> tuple[np.ndarray, np.ndarray]:
    """``(trajectory (n, 3), has_pose (n,))`` of the steps' ground truth: NaN rows and False
    where a step has no ``truth_pose`` (e.g. a Vicon gap), a NaN heading where the truth has
    no heading (GPS)."""
    if isinstance(steps, StepColumns):  # the same arrays, without building every step
        return steps.truth_trajectory()
    trajectory = np.full((len(steps), 3), np.nan)
    has_pose = np.zeros(len(steps), dtype=bool)
    for i, step in enumerate(steps):
        if step.truth is not None:
            heading = step.truth.theta_rad
            trajectory[i] = (step.truth.x_m, step.truth.y_m, np.nan if heading is None else heading)
            has_pose[i] = True
    return trajectory, has_pose


def truth_landmark_map(log: RunLog | ColumnLog) -> tuple[dict[int, tuple[float, float]], dict[int, float] | None]:
    """``(landmarks, heights)`` of the log's ``truth_landmark`` records (both empty/None
    when it has none); heights only for the landmarks that give one."""
    truth_landmarks = log.truth_landmarks()
    landmarks = {i: (t.x_m, t.y_m) for i, t in truth_landmarks.items()}
    heights = {i: t.height_m for i, t in truth_landmarks.items() if t.height_m is not None}
    return landmarks, heights or None


def truth_reference(log: RunLog | ColumnLog) -> Reference | None:
    """The log's ground truth as a :class:`Reference`, or None when no pose has truth.

    Poses without a ``truth_pose`` (gaps in motion capture) are NaN rows with
    ``has_pose`` False: :func:`fgslam.compare.compute_metrics` leaves them out. The landmarks
    are the log's ``truth_landmark`` records (none: no map error).
    """
    steps = log.steps()
    trajectory, has_pose = truth_trajectory(steps)
    if not has_pose.any():
        return None
    landmarks, heights = truth_landmark_map(log)
    return Reference("ground_truth", trajectory, landmarks, heights, has_pose=has_pose)


def choose_reference(log: RunLog | ColumnLog, smoothed_trajectory, smoothed_landmarks, smoothed_heights=None) -> Reference:
    """The reference ``fgslam run`` measures against, the best the log offers:

    1. the log's pose truth wherever it has some (full or partial, :func:`truth_reference`),
       with its surveyed landmarks;
    2. no pose truth but surveyed landmarks (landmark-only truth): the smoothed trajectory,
       and the surveyed landmarks for the map error;
    3. neither: the smoothed solution (trajectory and landmarks).
    """
    truth = truth_reference(log)
    if truth is not None:
        return truth
    landmarks, heights = truth_landmark_map(log)
    if landmarks:
        return Reference("smoothed", smoothed_trajectory, landmarks, heights, landmark_reference="ground_truth")
    return Reference("smoothed", smoothed_trajectory, dict(smoothed_landmarks), smoothed_heights)


class UnusableReferenceError(FgslamError):
    """The smoothed solution is too weak to grade an estimator against (see
    :func:`require_usable_reference`)."""


def reference_landmark_observations(smoother: Isam2Smoother) -> int:
    """How many landmark observation factors the smoother's graph holds (factors on a
    landmark or tag variable, heights excluded)."""
    count = 0
    graph = smoother.graph()
    for i in range(graph.size()):
        factor = graph.at(i)
        if factor is None:
            continue
        if any(chr(gtsam.Symbol(key).chr()) in "lt" for key in factor.keys()):
            count += 1
    return count


def require_motion(log, purpose: str) -> None:
    """Refuse a log with nothing to ``purpose`` (e.g. "estimate or score"): only its start pose,
    no odometry, as a recording stopped before the robot moved leaves it; every figure would be
    a trivial 0."""
    if not log.has_motion():
        raise FgslamError(f"{log.path} has no odometry records, only its start pose: there is nothing to {purpose} "
                          "(fgslam validate says what the log holds)")


def require_usable_reference(smoother: Isam2Smoother, steps: Sequence[Step], log_name: str) -> None:
    """Refuse a smoothed reference that is no better constrained than odometry.

    A landmark constrains the trajectory only from its second observation on, so the
    reference is dead reckoning when its graph holds no landmark, or no more landmark
    observations than landmarks. Raises :class:`UnusableReferenceError` saying why (how
    many observations the log has, how many the smoother used, and what it did with the
    others) and how to fix it.
    """
    observations = sum(len(step.observations) for step in steps)
    used = reference_landmark_observations(smoother)
    landmarks = len(smoother.landmarks())
    if observations == 0 or used > landmarks:
        return
    unused = ", ".join(f"{v} {k}" for k, v in (unused_observations(smoother) or {}).items() if v) or "none counted"
    without_id = sum(1 for step in steps for o in step.observations if o.landmark_id is None)
    what = "maps no landmark" if landmarks == 0 else f"maps {landmarks} landmarks but observes none of them twice"
    raise UnusableReferenceError(
        f"{log_name}: the smoothed reference {what} (the log has {observations} observations, "
        f"{without_id} without a landmark id; the smoother used {used}; not used: {unused}), so it is no "
        f"better constrained than odometry and grading an estimator against it would be meaningless. "
        f"Fix: record landmark ids, or observations the smoother can associate (landmarks seen more than "
        f"once, with sensible sigma_range_m/sigma_bearing_rad), or grade against ground truth (--against truth)"
    )


def compare_log(
    log: RunLog | ColumnLog,
    estimator_names: Sequence[str] = DEFAULT_ESTIMATORS,
    progress: Progress | None = None,
    *,
    consistency: bool | str = True,
) -> Comparison:
    """Run the named estimators and the batch solve on ``log``; choose the reference.

    The reference (:func:`choose_reference`) is the log's ground truth wherever it has some
    (poses without truth are not scored), otherwise the batch Levenberg–Marquardt solution
    started from iSAM2's result (the "smoothed ground truth"), with the log's surveyed
    landmarks for the map error when it has them; a smoothed reference no better than
    odometry is refused (:func:`require_usable_reference`). The batch solve starts from plain
    ``isam2`` when it ran, else from the first robust iSAM2 (whose graph, and so whose
    batch solve, is robust too). ``consistency`` says where NEES, NIS and the covariance
    ellipses are taken (:mod:`fgslam.consistency_sample`): ``"sampled"`` (``fgslam run``'s
    default: one seeded sample of steps, shared by every estimator), ``"all"`` or True (every
    step), ``"none"`` or False (not at all).

    An estimator that fails mid-run (:class:`fgslam.failure.EstimatorFailed`) is kept in
    :attr:`Comparison.failures` and the others go on. Where the failure leaves nothing to
    measure against — every iSAM2 failed, or the batch solve did, on a log without pose
    truth — the comparison stops with one :class:`FgslamError` saying which and why.
    """
    steps = log.steps()
    stamps_s = step_stamps(steps)
    mode = ("all" if consistency else "none") if isinstance(consistency, bool) else consistency
    sample = sample_of_steps(steps, mode)
    runs, failures, smoother, smoother_run = _run_each(log, steps, estimator_names, progress, sample, mode != "none")
    truth = truth_reference(log)
    if smoother is None:  # no batch solve: only the log's own truth can be the reference
        if truth is None:
            raise FgslamError(_without_batch(log, failures))
        return Comparison(runs, truth, stamps_s, failures=failures)
    if not log.truth_landmarks() and truth is None:  # the smoothed solution will be the reference
        require_usable_reference(smoother, steps, _log_name(log))
    try:
        batch = _batch_solve(smoother, progress)
    except Exception as error:  # e.g. gtsam's IndeterminateSystemException
        failure = EstimatorFailure("batch", None, None, reason_of(error), "batch")
        if truth is None:
            raise FgslamError(f"{_log_name(log)}: the batch solve from {smoother.name}'s result failed: "
                              f"{failure.reason}; without pose truth in the log it is the reference, so nothing "
                              "can be scored") from error
        return Comparison(runs, truth, stamps_s, smoother, failures=[*failures, failure])
    batch_run = _batch_run(batch, smoother_run)
    runs.append(batch_run)
    reference = choose_reference(log, batch.trajectory, batch_run.landmarks, batch_run.landmark_heights)
    return Comparison(runs, reference, stamps_s, smoother, (batch.initial_error, batch.final_error),
                      verdict_or_none(smoother.graph(), batch.values), failures)


def _log_name(log) -> str:
    return str(getattr(log, "path", "the log"))


def _run_each(log: RunLog | ColumnLog, steps: Sequence[Step], names: Sequence[str], progress: Progress | None,
              sample: ConsistencySample | None, consistency: bool) -> tuple[list[EstimatorRun], list[EstimatorFailure], Isam2Smoother | None,
                                          EstimatorRun | None]:
    """``(runs, failures, smoother, its run)``: every named estimator on ``steps``, those that
    failed set apart, and the iSAM2 the batch solve starts from (plain ``isam2`` when it ran,
    else the first iSAM2; None when none ran through)."""
    runs: list[EstimatorRun] = []
    failures: list[EstimatorFailure] = []
    smoother: Isam2Smoother | None = None
    smoother_run: EstimatorRun | None = None
    for name in names:
        try:
            run, estimator = run_estimator(ESTIMATORS[name](log.header), steps, progress, covariances=consistency,
                                           sample=sample)
        except EstimatorFailed as failed:
            failures.append(failed.failure)
            continue
        runs.append(run)
        if isinstance(estimator, Isam2Smoother) and (smoother is None or name == "isam2"):
            smoother, smoother_run = estimator, run
    return runs, failures, smoother, smoother_run


def _without_batch(log: RunLog | ColumnLog, failures: Sequence[EstimatorFailure]) -> str:
    """Why a log without pose truth cannot be compared when no iSAM2 ran through."""
    failed = [f for f in failures if f.name in REGISTRY and REGISTRY[f.name].isam2]
    if failed:
        return (f"{failed[0].sentence()}; {_log_name(log)} has no pose truth, so the reference is the batch solve, "
                "which starts from iSAM2's result: nothing can be scored")
    return (f"{_log_name(log)} has no pose truth, so the reference is the batch solve, which starts from iSAM2's "
            f"result: keep isam2 (or one of {', '.join(n for n in ISAM2_NAMES if n != 'isam2')}) in --estimators")


def _batch_solve(smoother: Isam2Smoother, progress: Progress | None):
    """:func:`fgslam.smoother.batch_solve` from ``smoother``'s result, BLAS pinned, with progress."""
    if progress is not None:
        progress(0, 1, "batch")
    with pinned_threads():
        batch = batch_solve(smoother)
    if progress is not None:
        progress(1, 1, "batch")
    return batch


def _batch_run(batch, smoother_run: EstimatorRun | None) -> EstimatorRun:
    """The batch solve as an :class:`EstimatorRun`, its landmarks under the true ids when the
    smoother associated observations itself."""
    landmarks, heights = dict(batch.landmarks), batch.landmark_heights
    if smoother_run is not None and smoother_run.association is not None:  # the smoother's own keys → true ids
        landmarks = relabel_landmarks(landmarks, smoother_run.association)
        heights = relabel_landmarks(heights, smoother_run.association) if heights else heights
    return EstimatorRun(name="batch", online=None, final=batch.trajectory, landmarks=landmarks, step_times_s=None,
                        total_time_s=batch.time_s, landmark_heights=heights)
