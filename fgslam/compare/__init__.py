"""Comparison maths: how far each estimator's answer is from a reference, and what it cost.

Everything here is pure numpy (no gtsam, no matplotlib) and works on plain arrays:

* a *trajectory* is an ``(n, 3)`` array of poses ``(x_m, y_m, theta_rad)`` in the world
  frame, one row per pose of the run log (row ``i`` is pose ``X(i)``);
* a *map* is a ``dict`` landmark id → ``(x_m, y_m)`` in the world frame.

The runner (``fgslam.runner``) produces one :class:`EstimatorRun` per estimator and one
:class:`Reference` (the log's ground truth wherever it has some, otherwise the batch-smoothed
solution); :func:`compute_metrics` turns them into a JSON-ready dictionary, and
:func:`format_table` into a terminal table. ``fgslam.report`` draws the same figures.

The package's modules, in the order a comparison uses them:

* :mod:`fgslam.compare.runs` — what is compared (:class:`EstimatorRun`, :class:`Reference`)
  and :class:`ComparisonError`;
* :mod:`fgslam.compare.alignment` — the SE(2) alignment and the policy of when to apply it;
* :mod:`fgslam.compare.errors` — the error metrics (ATE, RPE, final error, NEES, NIS, map);
* :mod:`fgslam.compare.association` — data association scored against the true ids;
* :mod:`fgslam.compare.metrics` — all of them for a set of runs: :func:`compute_metrics`;
* :mod:`fgslam.compare.table` — the metrics as a table (:func:`format_table`);
* :mod:`fgslam.compare.tum` — trajectories as TUM files.

Every public name is importable from ``fgslam.compare`` itself.

Partial ground truth
--------------------
Real datasets have truth for only some poses (motion capture loses the robot). A reference
trajectory then has NaN rows where there is no truth, and :attr:`Reference.has_pose` says
which rows hold a pose. Every pose figure is computed over the poses with truth only: ATE
(final and online) is the RMS over them, the final error is that of the last pose with
truth, an RPE pair counts when both its ends have truth (with a heading), NEES is taken at
the poses with truth, and an SE(2) alignment is fitted to them. A truth that measures
position only (GPS: a NaN heading) scores positions; its NEES is over (x, y), 2 degrees of
freedom (:func:`nees_dofs`), and it gives no RPE pair. The map error does not need pose truth:
it is against the log's surveyed landmarks whenever the log has them, even when the
trajectory reference is the smoothed solution (landmark-only truth). The pure functions
take an optional ``has_pose`` mask; without it, the rows with a finite position count.

Which trajectories are aligned, and why only those, is the policy in
:mod:`fgslam.compare.alignment`.
"""

from fgslam.compare.alignment import (
    FIRST_POSE_TOL_M,
    FIRST_POSE_TOL_RAD,
    align_se2,
    apply_se2,
    reference_rows,
    resolve_alignment,
    shares_first_pose,
)
from fgslam.compare.association import AssociationScore, relabel_landmarks, score_associations
from fgslam.compare.errors import (
    NIS_DOF,
    ate_rmse_m,
    final_pose_error_m,
    heading_errors_rad,
    last_pose_with_truth,
    map_errors_m,
    map_rmse_m,
    chi2_summary,
    nees,
    nees_band,
    nees_dofs,
    nis_summary,
    position_errors_m,
    relative_pose_errors,
    rpe_delta_frames,
    rpe_pairs,
)
from fgslam.compare.metrics import (
    METRIC_KEYS,
    TOP_LEVEL_KEYS,
    compute_metrics,
    estimator_alignment,
    estimator_names,
    nees_over_truth,
)
from fgslam.compare.runs import REFERENCE_DESCRIPTIONS, ComparisonError, EstimatorRun, Reference, describe_reference
from fgslam.compare.table import COLUMN_MEANINGS, format_table, reference_description, reference_line, table_rows
from fgslam.compare.tum import format_tum, read_tum, write_tum

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
    "nees_dofs",
    "nis_summary",
    "chi2_summary",
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
