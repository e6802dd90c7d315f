"""Regression check of an estimator against a reference: ``fgslam check`` and pytest.

The design card's "regression-test EKF against smoothed ground truth": run one estimator on a
log, compare it with the smoothed solution (batch Levenberg–Marquardt started from iSAM2)
or with the log's ground truth, and pass or fail on two tolerances:

* ``max_ate_m`` — the final trajectory's ATE (metres; SE(2)-aligned only when the first
  poses differ, as everywhere in fgslam);
* ``max_nees_outside`` — the share of steps whose NEES (online pose and the covariance the
  estimator stated for it, 3 DoF) lies outside the 95 % χ² band [0.216, 9.35] (against a
  truth without heading, the position's NEES, 2 DoF, and its band [0.0506, 7.38]); a
  consistent estimator is outside about 5 % of the time. Against the smoothed solution
  only steps *above* the band count (2.5 % expected): the smoothed poses are computed from
  the same measurements, so the estimator's error relative to them is smaller than its
  error relative to the truth, and a NEES below the band says nothing there (measured on
  the bundled octagon log: 29 % of the EKF's steps below the band against the smoothed
  solution, 3.9 % outside it against the truth). Above the band is what matters in a
  regression check: an estimator more confident than its errors.

Against the truth, only the poses that have ground truth are scored (real datasets have
gaps in their motion capture): the ATE is over them and the NEES share is of them. A log
whose truth covers fewer than half of its poses, or fewer than 10 poses, is refused
(:func:`require_enough_truth`): check it ``--against smoothed``.

Against the smoothed solution, a reference no better constrained than odometry (its graph
holds no landmark, or no landmark observed twice, e.g. observations the smoother could
neither read an id from nor associate) is refused with the reason and the fix
(:func:`fgslam.runner.require_usable_reference`) instead of grading the estimator against
dead reckoning. Observations without ids are associated by the smoother itself
(:mod:`fgslam.smoother.association`), so hidden-id logs are checked like logs with ids.

Tolerances come, in this order of precedence, from the call (or the command line), from a
TOML file next to the log (``<log>.check.toml``, or the file given), and from the defaults
(0.5 m, 0.1)::

    # runs/grid200.jsonl.check.toml
    [defaults]
    max_ate_m = 0.5
    max_nees_outside = 0.1

    [ekf-nn]            # per estimator
    max_ate_m = 0.8

A 3-D log (seed 003's stereo camera + IMU) is checked the same way with its own
estimators (:func:`score_3d`): the reference is the log's truth (``--against truth``) or
batch Levenberg–Marquardt on the stereo factor graph of ``isam2-3d`` (:mod:`fgslam.smoother3d`)
started from iSAM2's result, exactly as ``fgslam run`` computes it; the ATE is the RMSE of the
3-D positions without alignment (every estimator starts at the IMU's first pose); the NEES is
the pose NEES on SE(3) (right perturbation) against χ²₆'s band [1.24, 14.45]. A smoothed
solution whose graph holds no landmark seen twice is no better than the IMU alone and is
refused, as in 2-D. Which estimators a log takes comes from :mod:`fgslam.registry`.

In pytest::

    from fgslam.check import assert_estimator_close
    assert_estimator_close("runs/grid200.jsonl", estimator="ekf", against="smoothed")
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fgslam.compare import ate_rmse_m, nees_band, nees_over_truth
from fgslam.registry import CHECK_DEFAULTS, names_for
from fgslam.runner import (
    ESTIMATORS, UnusableReferenceError, require_motion, require_usable_reference, run_estimator, truth_reference,
)
from fgslam.smoother import Isam2Smoother, batch_solve
from fgslam.verdict import verdict_or_none
from slamio.errors import FgslamError, InputFileError, read_text
from slamio.log import read_log
from slamio.safe_input import parse_toml

__all__ = [
    "DEFAULT_ESTIMATOR_3D",
    "score_3d",
    "DEFAULT_TOLERANCES",
    "TOLERANCE_RANGES",
    "MIN_TRUTH_POSES",
    "MIN_TRUTH_SHARE",
    "CheckResult",
    "check_estimator",
    "assert_estimator_close",
    "load_tolerances",
    "tolerance_is_valid",
    "require_enough_truth",
]

#: The estimator ``fgslam check`` checks on a 3-D log when none is named: the consistent joint EKF.
DEFAULT_ESTIMATOR_3D = CHECK_DEFAULTS[3]

#: Tolerances used when neither the call nor a TOML file sets them.
DEFAULT_TOLERANCES = {"max_ate_m": 0.5, "max_nees_outside": 0.1}
AGAINST = ("smoothed", "truth")
#: ``--against truth`` needs ground truth for at least this many poses (all of them when the
#: log is shorter) ...
MIN_TRUTH_POSES = 10
#: ... and for at least this share of the log's poses.
MIN_TRUTH_SHARE = 0.5


@dataclass(frozen=True)
class CheckResult:
    """The outcome of one check; ``verdict`` is the one line ``fgslam check`` prints."""

    passed: bool
    verdict: str
    estimator: str
    against: str
    ate_m: float
    nees_outside: float | None  # share of scored steps outside the 95 % band; None without covariances
    max_ate_m: float
    max_nees_outside: float
    poses_scored: int | None = None  # poses compared (those with truth, against the truth)
    poses: int | None = None  # poses of the log
    #: noise group → :class:`fgslam.verdict.GroupVerdict` of the smoothed reference (planar
    #: logs checked against it); empty otherwise
    noise_verdict: dict = field(default_factory=dict)


def tolerance_file_for(log_path: str | os.PathLike[str]) -> Path:
    """The TOML file a log's tolerances are read from: ``<log>.check.toml``."""
    return Path(f"{log_path}.check.toml")


#: What each tolerance may be, as said in the errors (the file's, the call's and the CLI's).
TOLERANCE_RANGES = {
    "max_ate_m": "a finite number >= 0 (metres)",
    "max_nees_outside": "a finite number in [0, 1] (a share of the steps: 0.1 = 10 %)",
}


def tolerance_is_valid(key: str, value) -> bool:
    """Whether ``value`` is allowed for the tolerance ``key`` (:data:`TOLERANCE_RANGES`)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return False
    return value >= 0 and (key != "max_nees_outside" or value <= 1)


def load_tolerances(path: str | os.PathLike[str] | None, estimator: str) -> dict[str, float]:
    """Tolerances for ``estimator`` from a TOML file (``[defaults]`` then ``[estimator]``);
    the built-in defaults where the file says nothing or does not exist."""
    out = dict(DEFAULT_TOLERANCES)
    if path is None or not os.path.lexists(path):
        return out
    text = read_text(path, "tolerance file",
                     "a tolerance file is UTF-8 TOML text (see `fgslam check --help` for the layout)")
    # file:line errors; no FIFO, device, deep nesting, inf, nan or 5000-digit number
    doc = parse_toml(path, text, fix="see `fgslam check --help` for the layout")
    for table in ("defaults", estimator):
        section = doc.data.get(table, {})
        if not isinstance(section, dict):
            raise InputFileError(f"{doc.where(table)}: [{table}] must be a table of tolerances")
        for key, value in section.items():
            if key not in DEFAULT_TOLERANCES:
                raise InputFileError(
                    f"{doc.where(table, key)}: [{table}] has unknown key {key!r}; expected {', '.join(DEFAULT_TOLERANCES)}"
                )
            if not tolerance_is_valid(key, value):
                raise InputFileError(
                    f"{doc.where(table, key)}: [{table}] {key} must be {TOLERANCE_RANGES[key]}, got {value!r}")
            out[key] = float(value)
    return out


def require_enough_truth(log_path, poses_with_truth: int, poses: int) -> None:
    """Raise a one-line :class:`FgslamError` unless enough poses have ground truth for
    ``--against truth``: at least :data:`MIN_TRUTH_SHARE` of the ``poses`` and at least
    :data:`MIN_TRUTH_POSES` (or all of them, for a shorter log)."""
    needed = min(poses, max(MIN_TRUTH_POSES, math.ceil(MIN_TRUTH_SHARE * poses)))
    if poses_with_truth == 0:
        raise FgslamError(f"{log_path}: no pose has ground truth; use --against smoothed")
    if poses_with_truth < needed:
        raise FgslamError(
            f"{log_path}: only {poses_with_truth} of {poses} poses have ground truth, too few to check against "
            f"(at least {needed} needed: half the poses and at least {MIN_TRUTH_POSES}); use --against smoothed"
        )


def check_estimator(
    log_path: str | os.PathLike[str],
    *,
    estimator: str | None = None,
    against: str = "smoothed",
    max_ate_m: float | None = None,
    max_nees_outside: float | None = None,
    tolerances_file: str | os.PathLike[str] | None = None,
) -> CheckResult:
    """Run ``estimator`` on the log at ``log_path`` and check it against the reference.

    ``estimator`` defaults to ``ekf`` on a planar log and to :data:`DEFAULT_ESTIMATOR_3D`
    on a 3-D log (seed 003's stereo + IMU; :func:`score_3d`)."""
    if against not in AGAINST:
        raise FgslamError(f"--against must be one of {', '.join(AGAINST)}, got {against!r}")
    for key, value in (("max_ate_m", max_ate_m), ("max_nees_outside", max_nees_outside)):
        if value is not None and not tolerance_is_valid(key, value):
            raise FgslamError(f"{key} must be {TOLERANCE_RANGES[key]}, got {value!r}")
    log = read_log(log_path)
    require_motion(log, "check")
    dimension = 3 if log.header.is_3d else 2
    estimator = estimator or CHECK_DEFAULTS[dimension]
    known = names_for(dimension)
    if estimator not in known:
        kind = "a 3-D log" if dimension == 3 else "a planar log"
        raise FgslamError(f"unknown estimator {estimator!r} for {kind}; choose from {', '.join(known)}")
    file = tolerance_file_for(log_path) if tolerances_file is None else Path(tolerances_file)
    if tolerances_file is not None and not os.path.lexists(file):
        raise InputFileError(f"{file}: no such tolerance file")
    tol = load_tolerances(file, estimator)
    if max_ate_m is not None:
        tol["max_ate_m"] = float(max_ate_m)
    if max_nees_outside is not None:
        tol["max_nees_outside"] = float(max_nees_outside)

    if log.header.is_3d:
        score = score_3d(log, log_path, estimator, against)
    else:
        score = _score_planar(log, log_path, estimator, against)
    return _judge(score, log_path, estimator, against, tol)


@dataclass(frozen=True)
class Score:
    """What a check measured: the ATE over the scored poses, the NEES of those poses (None:
    the estimator states no covariance) with each value's degrees of freedom (its 95 % band
    is :func:`fgslam.compare.nees_band` of them), and how many poses were scored."""

    ate_m: float
    nees: np.ndarray | None
    nees_dofs: np.ndarray | None
    poses_scored: int
    poses: int
    noise_verdict: dict = field(default_factory=dict)

    def bands(self) -> tuple[np.ndarray, np.ndarray]:
        """``(low, high)``: each NEES value's 95 % band."""
        edges = {int(d): nees_band(int(d)) for d in np.unique(self.nees_dofs)}
        low = np.array([edges[int(d)][0] for d in self.nees_dofs])
        high = np.array([edges[int(d)][1] for d in self.nees_dofs])
        return low, high


def _score_planar(log, log_path, estimator: str, against: str) -> Score:
    steps = log.steps()
    noise: dict = {}
    if against == "truth":
        reference = truth_reference(log)
        require_enough_truth(log_path, 0 if reference is None else reference.poses_with_truth, len(steps))
        reference_poses, has_pose = reference.trajectory, reference.has_pose
    else:
        smoother = Isam2Smoother(log.header)
        run_estimator(smoother, steps, covariances=False)  # only its graph is needed
        require_usable_reference(smoother, steps, str(log_path))
        batch = batch_solve(smoother)
        reference_poses, noise = batch.trajectory, verdict_or_none(smoother.graph(), batch.values)
        has_pose = np.ones(len(reference_poses), dtype=bool)

    run, _ = run_estimator(ESTIMATORS[estimator](log.header), steps)
    m = len(run.final)
    ate = ate_rmse_m(run.final, reference_poses[:m], has_pose=has_pose[:m])
    values = dofs = None
    if run.online_covariances is not None:
        values, dofs = nees_over_truth(run.online, run.online_covariances, reference_poses, has_pose)
    return Score(ate, values, dofs, int(np.count_nonzero(has_pose[:m])), len(steps), noise)


def score_3d(log, log_path, estimator: str, against: str) -> Score:
    """The :class:`Score` of the 3-D ``estimator`` on the 3-D ``log`` against ``against``."""
    from fgslam.runner3d import (
        POSE_DOF, in_world, pose_nees_series, position_rmse_m, prepare_log3d, run_estimator_3d, truth_reference_3d,
    )
    from fgslam.smoother3d import batch_solve as batch_solve_3d

    ready = prepare_log3d(log)  # read once: the inputs, the rig, the noise and the truth come from it
    n_steps = len(ready.steps)
    run = None
    if against == "truth":
        reference = truth_reference_3d(log, ready.steps)
        require_enough_truth(log_path, 0 if reference is None else reference.poses_with_truth, n_steps)
        reference_poses, has_pose = reference.trajectory, reference.mask
    else:
        graph = ready.estimator("isam2-3d")
        # checking isam2-3d itself: its one run (with covariances) also gives the graph
        graph_run = run_estimator_3d(graph, ready.inputs, covariances=estimator == "isam2-3d", stamps_s=ready.stamps_s)
        require_landmarks_seen_twice(graph, log_path)
        if estimator == "isam2-3d":
            run = graph_run
        reference_poses = batch_solve_3d(graph).trajectory()
        has_pose = np.ones(n_steps, dtype=bool)
    if run is None:
        run = run_estimator_3d(ready.estimator(estimator), ready.inputs, stamps_s=ready.stamps_s)
    if against == "truth":  # the truth is in the log's world frame, where the first pose is start.pose3
        run = in_world(run, ready.world_T_start)
    ate = position_rmse_m(run.final, reference_poses, 3, has_pose)
    values = None
    if run.covariances is not None and np.any(np.isfinite(run.covariances)):
        values = pose_nees_series(run.online, run.covariances, reference_poses)[has_pose]
    dofs = None if values is None else np.full(len(values), POSE_DOF)
    return Score(ate, values, dofs, int(np.count_nonzero(has_pose)), n_steps)


def require_landmarks_seen_twice(graph, log_path) -> None:
    """Refuse a 3-D smoothed solution that no landmark constrains beyond the IMU: every stereo
    factor is then a landmark's only one."""
    if graph.stereo_factors <= len(graph.landmark_ids()):
        raise UnusableReferenceError(
            f"{log_path}: the smoothed solution is the IMU dead reckoning (no landmark is seen twice with a "
            f"usable disparity: {graph.stereo_factors} stereo factors on {len(graph.landmark_ids())} landmarks); "
            "check against the truth (--against truth) or record a log whose tracks last"
        )


def _judge(score: Score, log_path, estimator: str, against: str, tol: dict[str, float]) -> CheckResult:
    """PASS or FAIL on the two tolerances, and the one line that says why."""
    ate = score.ate_m
    outside = None
    if score.nees is not None:
        low, high = score.bands()
        finite = np.isfinite(score.nees)
        if against == "smoothed":  # only overconfidence counts (module docstring)
            outside = float(np.mean(~finite | (score.nees > high)))
        else:
            outside = float(np.mean(~finite | (score.nees < low) | (score.nees > high)))

    ate_ok = math.isfinite(ate) and ate <= tol["max_ate_m"]
    nees_ok = outside is None or outside <= tol["max_nees_outside"]
    passed = ate_ok and nees_ok
    nees_text = (
        "NEES n/a (no covariance)"
        if outside is None
        else f"NEES {'above' if against == 'smoothed' else 'outside'} the 95 % band at {100 * outside:.1f} % of steps "
        f"{'<=' if nees_ok else '>'} {100 * tol['max_nees_outside']:.1f} %"
    )
    scored, poses = score.poses_scored, score.poses
    coverage = "" if scored == poses else f" ({scored} of {poses} poses have truth; only they are scored)"
    verdict = (
        f"{'PASS' if passed else 'FAIL'} {estimator} vs {against} on {Path(log_path).name}: "
        f"ATE {ate:.4f} m {'<=' if ate_ok else '>'} {tol['max_ate_m']:g} m, {nees_text}{coverage}"
    )
    return CheckResult(passed, verdict, estimator, against, ate, outside, tol["max_ate_m"], tol["max_nees_outside"],
                       scored, poses, score.noise_verdict)


def assert_estimator_close(log_path: str | os.PathLike[str], **kwargs) -> CheckResult:
    """:func:`check_estimator`, raising ``AssertionError`` with the verdict when it fails."""
    result = check_estimator(log_path, **kwargs)
    if not result.passed:
        raise AssertionError(result.verdict)
    return result
