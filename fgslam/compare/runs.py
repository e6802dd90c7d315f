"""What is compared: one :class:`EstimatorRun` per estimator and one :class:`Reference`.

Also :class:`ComparisonError`, raised by every module of :mod:`fgslam.compare` for inputs
that cannot be compared, the words that say what a reference is (:func:`describe_reference`),
and the shape checks of trajectories and point sets that the other modules share.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fgslam.compare.association import AssociationScore  # the type of EstimatorRun.association
from slamio.errors import FgslamError


class ComparisonError(FgslamError, ValueError):
    """Inputs that cannot be compared (wrong shapes, a bad TUM file, clashing names).

    It is an :class:`~slamio.errors.FgslamError` (the CLI prints it without a traceback)
    and a :class:`ValueError` (what numpy-style callers expect for bad arguments).
    """


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
    #: the steps NEES and NIS were taken at (:meth:`fgslam.consistency_sample.ConsistencySample.description`:
    #: mode "all" or "sampled", seed, how many steps of how many); None when they were not taken
    consistency: dict | None = None
    #: CPU time (``time.thread_time``) of the steps and ``finish()``, and of the consistency work:
    #: the NEES/NIS between the steps and the landmark covariances after the run (None: none was
    #: done), seconds; None for a run that did not measure them
    cpu_time_s: float | None = None
    consistency_cpu_s: float | None = None
    #: of ``consistency_cpu_s``, the landmark covariances after the run (the map's ellipses)
    map_covariance_cpu_s: float | None = None


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
            not given, the rows whose x and y are finite. A reference pose whose heading is
            NaN has a measured position only (GPS truth): :attr:`has_heading` is False there.
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
        if self.has_pose is None:  # a pose whose truth has no heading (GPS) has a NaN heading only
            has_pose = np.all(np.isfinite(trajectory[:, :2]), axis=1)
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
    def has_heading(self) -> np.ndarray:
        """``(n,)`` booleans, True where the reference pose has a heading as well as a position
        (False at poses without truth and where the truth measures position only)."""
        return self.has_pose & np.isfinite(self.trajectory[:, 2])

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

REFERENCE_DESCRIPTIONS = {
    "ground_truth": "ground truth recorded in the log",
    "smoothed": "smoothed solution (batch LM over the whole log; no ground truth)",
}


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
