"""The per-run report: six figures and one self-contained HTML page.

This is the only module of the project that imports matplotlib. It uses matplotlib's
object-oriented API with the Agg canvas (``Figure`` + ``FigureCanvasAgg``) instead of
``pyplot``: no window can ever open, no global backend is switched under a user who imported
fgslam into a notebook, and figures are not kept in pyplot's registry (nothing to close —
they are freed when the function returns).

:func:`write_report` writes into a directory:

* ``trajectories.png`` — each estimator's final trajectory and landmarks over the reference,
  with 95 % covariance ellipses: an overview zoomed to the estimators and a detail around
  the pose where their error is largest;
* ``position_error.png`` and ``heading_error.png`` — errors against time (final solid,
  online dashed);
* ``nees.png`` — NEES of the online pose with its χ² band (ground truth only);
* ``nis.png`` — NIS of every observation with its χ² band;
* ``step_time.png`` — time per step, log scale;
* ``report.html`` — one file that opens offline: inline CSS, the PNGs embedded as ``data:``
  URIs, a table of the figures, the metrics table (the same strings as
  :func:`fgslam.compare.format_table`) and what every column means. Its only links point
  inside the page; it has no scripts or external resources.

Dead reckoning (any name in ``baselines``) is a baseline, not a competitor: by default
(``baseline="fade"``) it is drawn faint and every axis is scaled to the other estimators, so
its drift (tens of metres on a large map) cannot hide their centimetres; ``"drop"`` leaves it
out of the figures, ``"show"`` draws it like the others. The table always has it.

The page carries the run's provenance near its top (:func:`provenance`): fgslam's version, the command
line, the date (UTC), the log's path and SHA-256, and the estimators.

What is drawn is what was measured: each estimate is moved by the same SE(2) alignment
:func:`fgslam.compare.compute_metrics` used (the identity when it shares its first pose
with the reference). Where the reference has no pose (gaps in the ground truth), the
reference line and every error curve break: those poses are not scored, so nothing is drawn
for them; the page says which reference was used and how many poses it covers.
"""

from __future__ import annotations

import base64
import html
import json
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

from fgslam.provenance import file_sha256, provenance  # noqa: F401  (re-exported)
from fgslam.compare import (
    COLUMN_MEANINGS,
    NIS_DOF,
    ComparisonError,
    EstimatorRun,
    Reference,
    apply_se2,
    estimator_alignment,
    heading_errors_rad,
    nees,
    nees_band,
    nis_summary,
    position_errors_m,
    reference_description,
    table_rows,
)

__all__ = [
    "write_report",
    "provenance",
    "file_sha256",
    "BASELINE_ESTIMATORS",
    "BASELINE_MODES",
    "trajectory_view",
    "trajectory_figure",
    "detail_pose",
    "plot_trajectories",
    "plot_position_errors",
    "plot_heading_errors",
    "plot_nees",
    "plot_nis",
    "plot_step_times",
    "ellipse_xy",
    "truth_gaps_s",
    "write_monte_carlo_figures",
    "plot_live_map",
    "plot_top_view_3d",
    "write_report_3d",
]

TRAJECTORIES_PNG = "trajectories.png"
POSITION_ERROR_PNG = "position_error.png"
REPORT_HTML = "report.html"
NEES_PNG = "nees.png"
NIS_PNG = "nis.png"
HEADING_ERROR_PNG = "heading_error.png"
STEP_TIME_PNG = "step_time.png"
TOP_VIEW_3D_PNG = "top_view.png"  # 3-D logs (write_report_3d)


@dataclass(frozen=True)
class _Figure:
    """One figure of the report: its anchor, title, PNG name, one-line description, the
    written file (None when there was nothing to draw) and what to say then."""

    anchor: str
    title: str
    file: str
    what: str
    path: Path | None
    missing: str

_FIGSIZE_IN = (9.0, 6.0)
_DPI = 100
_COLOURS = ["#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf"]
_MARKERS = ["o", "^", "s", "D", "v", "P", "X", "h"]
# Errors below this are "identical to the reference" (numerical noise), metres.
_ZERO_ERROR_M = 1e-6
# Switch the error axis to log scale when the estimators' typical errors differ this much.
_LOG_SPREAD = 30.0

#: Estimators drawn as a baseline (faint, or left out) rather than as a competitor.
BASELINE_ESTIMATORS = frozenset({"dead_reckoning"})
#: What the figures do with a baseline: draw it faint and zoom to the others, leave it out,
#: or draw it like any estimator.
BASELINE_MODES = ("fade", "drop", "show")
_FAINT_ALPHA = 0.3
_TRAJECTORY_FIGSIZE_IN = (15.0, 6.8)
# Overview: the estimators' bounding box widened by this share of its larger side (at least _VIEW_MIN_MARGIN_M).
_VIEW_MARGIN = 0.04
_VIEW_MIN_MARGIN_M = 0.3
# Detail window: half-width = this × the largest error at its centre, at least _DETAIL_MIN_SHARE × the
# overview's larger side and _DETAIL_MIN_HALF_M.
_DETAIL_SPAN = 2.0
_DETAIL_MIN_SHARE = 0.02
_DETAIL_MIN_HALF_M = 0.02


def _new_figure() -> Figure:
    fig = Figure(figsize=_FIGSIZE_IN, dpi=_DPI, layout="constrained")
    FigureCanvasAgg(fig)  # attaches the Agg canvas: off-screen rendering only
    return fig


def _style(i: int) -> tuple[str, str]:
    return _COLOURS[i % len(_COLOURS)], _MARKERS[i % len(_MARKERS)]


def _legend_and_save(fig: Figure, ax, path, with_legend: bool = True, **legend) -> Path:
    """Legend outside the axes on the right, then the PNG (no software tag, optimised)."""
    if with_legend:
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False, **legend)
    out = Path(path)
    fig.savefig(out, dpi=_DPI, metadata={"Software": None}, pil_kwargs={"optimize": True})
    return out


def _aligned_final(run: EstimatorRun, reference: Reference) -> tuple[np.ndarray, bool, float, np.ndarray]:
    aligned, rot, trans = estimator_alignment(run, reference)
    final = np.asarray(run.final, dtype=float).reshape(-1, 3)
    return (apply_se2(final, rot, trans) if len(final) else final), aligned, rot, trans


#: Poses per estimator that get a covariance ellipse on the trajectory plot.
_ELLIPSES_PER_RUN = 12


def ellipse_xy(centre_xy, covariance_xy, probability: float = 0.95, points: int = 64) -> np.ndarray:
    """``(points, 2)`` outline of the ellipse that holds ``probability`` of a 2-D Gaussian.

    The boundary is ``{x : (x − c)ᵀ Σ⁻¹ (x − c) = χ²⁻¹(probability; 2)}`` (5.99 for 95 %):
    the unit circle scaled by ``√(χ² λᵢ)`` along the eigenvectors of Σ.
    """
    from scipy.stats import chi2

    values, vectors = np.linalg.eigh(0.5 * (np.asarray(covariance_xy, dtype=float) + np.asarray(covariance_xy).T))
    radii = np.sqrt(chi2.ppf(probability, 2) * np.clip(values, 0.0, None))
    angle = np.linspace(0.0, 2.0 * np.pi, points)
    circle = np.stack([np.cos(angle), np.sin(angle)])
    return (vectors @ (radii[:, None] * circle)).T + np.asarray(centre_xy, dtype=float)[:2]


def _draw_ellipses(ax, centres, covariances, rot: float, colour: str, label: str | None) -> None:
    """Draw 95 % ellipses (covariances rotated by the run's alignment ``rot``)."""
    c, s = np.cos(rot), np.sin(rot)
    R = np.array([[c, -s], [s, c]])
    for j, (centre, cov) in enumerate(zip(centres, covariances)):
        outline = ellipse_xy(centre, R @ np.asarray(cov)[:2, :2] @ R.T)
        ax.plot(outline[:, 0], outline[:, 1], color=colour, lw=0.8, alpha=0.8,
                label=label if j == 0 else None, zorder=2)


def _reference_label(reference: Reference) -> str:
    """Legend text of the reference trajectory: where it comes from, and its coverage."""
    if reference.kind != "ground_truth":
        return "reference (smoothed)"
    n, k = len(reference.trajectory), reference.poses_with_truth
    return "reference (ground truth)" if k == n else f"reference (ground truth, {k} of {n} poses; gaps: no truth)"


def truth_gaps_s(times_s, has_pose) -> list[tuple[float, float]]:
    """Time intervals ``(start_s, end_s)`` in which the reference has no pose: each run of
    poses without truth, from the last pose with truth before it (or the run's first pose) to
    the first one after it (or the run's last pose), which is where the curves break."""
    t = np.asarray(times_s, dtype=float).reshape(-1)
    mask = np.asarray(has_pose, dtype=bool).reshape(-1)[: len(t)]
    gaps = []
    i = 0
    while i < len(mask):
        if mask[i]:
            i += 1
            continue
        j = i
        while j + 1 < len(mask) and not mask[j + 1]:
            j += 1
        gaps.append((float(t[max(i - 1, 0)]), float(t[min(j + 1, len(t) - 1)])))
        i = j + 1
    return gaps


def _shade_truth_gaps(ax, times_s, reference: Reference) -> None:
    """Grey bands where the reference has no pose (nothing is scored there)."""
    for j, (start_s, end_s) in enumerate(truth_gaps_s(times_s, reference.has_pose)):
        ax.axvspan(start_s, end_s, color="0.85", alpha=0.6, lw=0, zorder=0,
                   label="no ground truth (not scored)" if j == 0 else None)


def _landmark_array(landmarks: dict | None) -> np.ndarray:
    if not landmarks:
        return np.zeros((0, 2))
    return np.array([landmarks[k] for k in sorted(landmarks)], dtype=float).reshape(-1, 2)


def _is_baseline(run: EstimatorRun, baselines) -> bool:
    return run.name in baselines


def _plotted(runs: list[EstimatorRun], baselines, baseline: str) -> list[tuple[int, EstimatorRun, bool]]:
    """``(colour index, run, is_baseline)`` for every run a figure draws: the colour index is
    the run's place in ``runs`` (the same colour in every figure whatever is dropped), and
    baselines are left out when ``baseline == "drop"``. A baseline is drawn faint when
    ``baseline == "fade"`` and like any estimator when ``"show"``."""
    if baseline not in BASELINE_MODES:
        raise ValueError(f"baseline must be one of {', '.join(BASELINE_MODES)}, not {baseline!r}")
    out = []
    for i, run in enumerate(runs):
        is_base = _is_baseline(run, baselines) and baseline != "show"
        if is_base and baseline == "drop":
            continue
        out.append((i, run, is_base))
    return out


def _faint(label: str) -> str:
    return f"{label} (baseline: faint, clipped)"


def trajectory_view(
    runs: list[EstimatorRun],
    reference: Reference,
    *,
    truth_landmarks: dict | None = None,
    baselines=BASELINE_ESTIMATORS,
    margin: float = _VIEW_MARGIN,
    min_margin_m: float = _VIEW_MIN_MARGIN_M,
) -> tuple[float, float, float, float]:
    """``(xmin, xmax, ymin, ymax)`` of the trajectory figure's overview: the bounding box of
    the reference (trajectory and landmarks), the true landmarks, and the final trajectory
    and landmarks of every estimator that is not a baseline (aligned as measured), widened
    on every side by ``margin`` × the larger side (at least ``min_margin_m``). A baseline
    such as dead reckoning is left out, so its drift cannot shrink the estimators to a
    smudge; what lies outside is clipped. With no such point at all, everything counts."""

    def collect(include_baselines: bool) -> np.ndarray:
        points = [np.asarray(reference.trajectory, dtype=float).reshape(-1, 3)[:, :2],
                  _landmark_array(reference.landmarks)]
        if truth_landmarks:
            points.append(_landmark_array(truth_landmarks))
        for run in runs:
            if _is_baseline(run, baselines) and not include_baselines:
                continue
            final, _, rot, trans = _aligned_final(run, reference)
            points.append(final[:, :2])
            lm = _landmark_array(run.landmarks)
            if len(lm):
                points.append(apply_se2(lm, rot, trans))
        xy = np.concatenate([p.reshape(-1, 2) for p in points]) if points else np.zeros((0, 2))
        return xy[np.all(np.isfinite(xy), axis=1)]

    xy = collect(False)
    if not len(xy):
        xy = collect(True)
    if not len(xy):
        return (-1.0, 1.0, -1.0, 1.0)
    low, high = xy.min(axis=0), xy.max(axis=0)
    pad = max(margin * float(np.max(high - low)), min_margin_m)
    return (float(low[0] - pad), float(high[0] + pad), float(low[1] - pad), float(high[1] + pad))


def detail_pose(runs: list[EstimatorRun], reference: Reference, *, baselines=BASELINE_ESTIMATORS) -> int | None:
    """The pose the trajectory figure's detail panel is centred on: the one where the worst
    final position error of the estimators that are not baselines (all of them when every
    one is) is largest; None when no pose is scored."""
    ref = np.asarray(reference.trajectory, dtype=float).reshape(-1, 3)
    worst = np.full(len(ref), -np.inf)
    competitors = [r for r in runs if not _is_baseline(r, baselines)] or runs
    for run in competitors:
        final, _, _, _ = _aligned_final(run, reference)
        m = min(len(final), len(ref))
        err = position_errors_m(final[:m], ref[:m])
        worst[:m] = np.fmax(worst[:m], np.where(np.isfinite(err), err, -np.inf))
    if not len(worst) or not np.isfinite(worst).any():
        return None
    return int(np.argmax(worst))


def trajectory_figure(
    runs: list[EstimatorRun],
    reference: Reference,
    *,
    truth_landmarks: dict | None = None,
    title: str = "Trajectories and maps",
    baseline: str = "fade",
    baselines=BASELINE_ESTIMATORS,
) -> Figure:
    """The figure of :func:`plot_trajectories` (two panels: ``fig.axes[0]`` the overview,
    ``fig.axes[1]`` the detail, when there is one)."""
    plotted = _plotted(runs, baselines, baseline)
    view_baselines = baselines if baseline != "show" else ()
    ref = np.asarray(reference.trajectory, dtype=float).reshape(-1, 3)  # NaN rows: gaps, drawn as breaks
    k_detail = detail_pose([r for _, r, _ in plotted], reference, baselines=baselines)
    fig = Figure(figsize=_TRAJECTORY_FIGSIZE_IN, dpi=_DPI, layout="constrained")
    FigureCanvasAgg(fig)
    if k_detail is not None and np.all(np.isfinite(ref[k_detail, :2])):
        grid = fig.add_gridspec(1, 2, width_ratios=(1.35, 1.0))
        ax, detail = fig.add_subplot(grid[0, 0]), fig.add_subplot(grid[0, 1])
        panels = (ax, detail)
    else:
        ax, detail = fig.add_subplot(), None
        panels = (ax,)

    ref_lm = _landmark_array(reference.landmarks)
    truth_lm = _landmark_array(truth_landmarks) if truth_landmarks and truth_landmarks != reference.landmarks else None
    finals = {}
    for j, panel in enumerate(panels):
        legend = j == 0  # labels once: the legend is built from the overview
        panel.plot(ref[:, 0], ref[:, 1], color="0.55", lw=3.0, alpha=0.7,
                   label=_reference_label(reference) if legend else None, zorder=1)
        if len(ref_lm):
            source = "surveyed" if reference.landmark_reference == "ground_truth" else "smoothed"
            panel.scatter(ref_lm[:, 0], ref_lm[:, 1], marker="x", s=40, c="black", lw=1.2,
                          label=f"reference landmarks ({source})" if legend else None, zorder=3)
        if truth_lm is not None:
            panel.scatter(truth_lm[:, 0], truth_lm[:, 1], marker="+", s=60, c="0.4", lw=1.2,
                          label="true landmarks" if legend else None, zorder=3)
        for i, run, faint in plotted:
            colour, marker = _style(i)
            final, aligned, rot, trans = _aligned_final(run, reference)
            finals[run.name] = final
            suffix = " (aligned SE(2))" if aligned else ""
            label = f"{run.name}{suffix}"
            if faint:
                if len(final):
                    panel.plot(final[:, 0], final[:, 1], color=colour, lw=0.8, alpha=_FAINT_ALPHA,
                               label=_faint(label) + "; no landmarks or ellipses" if legend else None, zorder=0.5)
                continue
            if len(final):
                panel.plot(final[:, 0], final[:, 1], color=colour, lw=1.3, label=label if legend else None, zorder=2)
                panel.plot(final[-1, 0], final[-1, 1], marker="s", ms=7, color=colour, ls="none", zorder=4)
            lm = _landmark_array(run.landmarks)
            if len(lm):
                lm = apply_se2(lm, rot, trans)
                panel.scatter(lm[:, 0], lm[:, 1], marker=marker, s=36, facecolors="none", edgecolors=colour,
                              lw=1.1, label=f"{run.name} landmarks" if legend else None, zorder=3)
            if run.online_covariances is not None and run.online is not None and len(run.online):
                online = apply_se2(np.asarray(run.online, dtype=float).reshape(-1, 3), rot, trans)
                if panel is ax:
                    picks = np.unique(np.linspace(0, len(online) - 1, _ELLIPSES_PER_RUN).round().astype(int))
                else:  # the detail: the pose at its centre
                    picks = np.array([k_detail]) if k_detail < len(online) else np.zeros(0, dtype=int)
                _draw_ellipses(panel, online[picks, :2], np.asarray(run.online_covariances)[picks], rot, colour,
                               f"{run.name} 95 % pose ellipse (online)" if legend else None)
            if run.landmark_covariances:
                ids = [k for k in sorted(run.landmarks) if k in run.landmark_covariances]
                centres = apply_se2(np.array([run.landmarks[k] for k in ids], dtype=float).reshape(-1, 2), rot, trans)
                _draw_ellipses(panel, centres, [run.landmark_covariances[k] for k in ids], rot, colour, None)

    valid = np.flatnonzero(reference.has_pose)
    if len(valid):
        first, last = int(valid[0]), int(valid[-1])
        ax.plot(ref[first, 0], ref[first, 1], marker="*", ms=16, color="gold", mec="black", ls="none",
                label="start" if first == 0 else "first pose with truth", zorder=5)
        ax.plot(ref[last, 0], ref[last, 1], marker="s", ms=8, color="0.55", mec="black", ls="none",
                label="end (square, each colour)" if last == len(ref) - 1 else "last pose with truth (square)",
                zorder=5)
    xmin, xmax, ymin, ymax = trajectory_view([r for _, r, _ in plotted], reference,
                                             truth_landmarks=truth_landmarks, baselines=view_baselines)
    ax.set_xlim(xmin, xmax)
    ax.set_ylim(ymin, ymax)
    ax.set_aspect("equal", adjustable="box")  # the limits stay: the box takes their shape
    dropped = [r.name for r in runs if _is_baseline(r, baselines)] if baseline == "drop" else []
    faded = any(f for _, _, f in plotted)
    ax.set_title("Overview" + (", zoomed to the estimators" if faded else "")
                 + (f" ({', '.join(dropped)} left out)" if dropped else ""), fontsize=10)

    if detail is not None:
        centre = ref[k_detail, :2]
        errors = []
        for i, run, faint in plotted:
            final = finals[run.name]
            if faint or k_detail >= len(final):
                continue
            colour, _ = _style(i)
            e = float(np.hypot(*(final[k_detail, :2] - centre)))
            errors.append((run.name, e, _is_baseline(run, baselines)))
            detail.plot([centre[0], final[k_detail, 0]], [centre[1], final[k_detail, 1]], color=colour, lw=0.8,
                        zorder=4)
            detail.plot(final[k_detail, 0], final[k_detail, 1], marker="o", ms=6, color=colour, mec="black",
                        mew=0.5, ls="none", zorder=5)
        detail.plot(centre[0], centre[1], marker="o", ms=7, color="0.55", mec="black", ls="none", zorder=5)
        span = max(xmax - xmin, ymax - ymin)
        # the window fits the estimators' errors, not a baseline's (drawn there with baseline="show")
        sizing = [e for _, e, base in errors if not base] or [e for _, e, _ in errors]
        half = max(_DETAIL_SPAN * max(sizing, default=0.0), _DETAIL_MIN_SHARE * span, _DETAIL_MIN_HALF_M)
        detail.set_xlim(centre[0] - half, centre[0] + half)
        detail.set_ylim(centre[1] - half, centre[1] + half)
        detail.set_aspect("equal", adjustable="box")
        detail.set_title(f"Detail around pose {k_detail}, where the estimators' error is largest", fontsize=10)
        detail.text(0.02, 0.02, "position error at pose {}:\n{}".format(
                        k_detail, "\n".join(f"{name}: {e:.3f} m" for name, e, _ in errors)),
                    transform=detail.transAxes, fontsize=8, va="bottom", ha="left", zorder=6,
                    bbox={"boxstyle": "round", "fc": "white", "ec": "0.7", "alpha": 0.9})
        ax.add_patch(Rectangle((centre[0] - half, centre[1] - half), 2 * half, 2 * half, fill=False, ec="black",
                               lw=1.0, ls=":", zorder=6, label="detail window (right)"))
        detail.plot([], [], marker="o", color="0.55", mec="black", ls="none",
                    label=f"pose {k_detail}: reference (grey) and each estimate, joined")
    for panel in panels:
        panel.set_xlabel("x [m]")
        panel.set_ylabel("y [m]")
        panel.grid(True, lw=0.5, alpha=0.5)
    fig.suptitle(title)
    handles, labels = ax.get_legend_handles_labels()
    if detail is not None:
        more = detail.get_legend_handles_labels()
        handles, labels = handles + more[0], labels + more[1]
    (panels[-1]).legend(handles, labels, loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8, frameon=False)
    return fig


def plot_trajectories(
    path: str | os.PathLike[str],
    runs: list[EstimatorRun],
    reference: Reference,
    *,
    truth_landmarks: dict | None = None,
    title: str = "Trajectories and maps",
    baseline: str = "fade",
    baselines=BASELINE_ESTIMATORS,
) -> Path:
    """Draw every estimator's final trajectory and map over the reference; save a PNG.

    Two panels, equal axis scale in metres:

    * the overview, zoomed to the reference and the estimators that are not baselines
      (:func:`trajectory_view`); a baseline (dead reckoning, see ``baselines``) is drawn as a
      faint thin line clipped to that view, without its landmarks or ellipses
      (``baseline="fade"``, the default), left out (``"drop"``) or drawn like the others,
      the view then covering it too (``"show"``);
    * the detail, a window around the pose where the estimators' final position error is
      largest (:func:`detail_pose`), four times that error wide (at least 4 % of the
      overview): the reference pose and each estimate there, joined, with its error in
      metres; differences of centimetres that the overview cannot show.

    Where the run stated covariances, 95 % ellipses (χ²(2) contour of the x–y block) are
    drawn around 12 evenly spaced online poses (the detail: around the pose at its centre)
    and around every landmark (its final marginal). The reference is the thick grey
    line with black ``×`` landmarks; each estimator has its own colour and landmark marker
    (hollow). The start is a gold star, every trajectory's end a square in its colour.
    ``truth_landmarks`` (e.g. the simulator's true map while the reference is the smoothed
    solution) are drawn as grey ``+`` when given and different from the reference's landmarks.
    """
    fig = trajectory_figure(runs, reference, truth_landmarks=truth_landmarks, title=title, baseline=baseline,
                            baselines=baselines)
    out = Path(path)
    fig.savefig(out, dpi=_DPI, metadata={"Software": None}, pil_kwargs={"optimize": True})
    return out


def plot_position_errors(
    path: str | os.PathLike[str],
    runs: list[EstimatorRun],
    reference: Reference,
    stamps_s,
    *,
    title: str = "Position error against the reference",
    baseline: str = "fade",
    baselines=BASELINE_ESTIMATORS,
) -> Path:
    """Draw position error [m] against time since the start [s]; save a PNG.

    One colour per estimator: the final trajectory solid, the online one dashed (absent for
    a batch solve). The y axis is logarithmic when the estimators' median errors differ by
    more than a factor of 30 (e.g. EKF metres vs smoother millimetres), linear otherwise.
    An estimator whose errors are all below 1 µm is identical to the reference and is
    labelled as such. Poses without a reference (gaps in the truth) are NaN: gaps in the
    curves. A baseline (``baselines``) is drawn faint and the axis is scaled to the other
    estimators, so it is clipped where it is off their scale (``baseline="fade"``); see
    :func:`plot_trajectories` for ``"drop"`` and ``"show"``.
    """
    ref = np.asarray(reference.trajectory, dtype=float).reshape(-1, 3)
    stamps = np.asarray(stamps_s, dtype=float).reshape(-1)
    if len(stamps) < len(ref):
        raise ComparisonError(f"plot_position_errors: {len(stamps)} stamps for {len(ref)} reference poses")
    t = stamps - stamps[0] if len(stamps) else stamps

    series = []  # (label, colour, style, times, errors, faint)
    for i, run, faint in _plotted(runs, baselines, baseline):
        colour, _ = _style(i)
        final, aligned, rot, trans = _aligned_final(run, reference)
        m = len(final)
        err = position_errors_m(final, ref[:m])  # NaN where the reference has no pose
        finite_err = err[np.isfinite(err)]
        zero = bool(len(finite_err)) and float(finite_err.max()) < _ZERO_ERROR_M
        if zero:
            label = f"{run.name} final (= reference, error < 1 µm)"
        else:
            label = f"{run.name} final"
        online = None if run.online is None else np.asarray(run.online, dtype=float).reshape(-1, 3)
        same = online is not None and online.shape == final.shape and np.array_equal(
            apply_se2(online, rot, trans) if len(online) else online, final
        )
        if same:  # a filter: online and final estimates are the same poses
            label = label.replace(" final", " final = online")
        series.append((_faint(label) if faint else label, colour, "-", t[:m], err, faint))
        if online is not None and len(online) and not same:
            k = len(online)
            err_on = position_errors_m(apply_se2(online, rot, trans), ref[:k])
            label = f"{run.name} online"
            series.append((_faint(label) if faint else label, colour, "--", t[:k], err_on, faint))

    fig = _new_figure()
    ax = fig.add_subplot()
    scaled = [s for s in series if not s[5]] or series  # the axis follows the estimators, not a baseline
    medians = []
    for label, colour, style, times, err, faint in series:
        ax.plot(times, err, color=colour, ls=style, lw=0.8 if faint else 1.2, alpha=_FAINT_ALPHA if faint else 1.0,
                label=label, zorder=1 if faint else 2)
    for *_, err, _ in scaled:
        positive = err[np.isfinite(err) & (err > _ZERO_ERROR_M)]
        if len(positive):
            medians.append(float(np.median(positive)))
    if len(medians) >= 1:
        all_err = np.concatenate([s[4] for s in scaled]) if scaled else np.zeros(0)
        finite = all_err[np.isfinite(all_err)]
        spread = max(medians) / min(medians)
        if spread > _LOG_SPREAD:
            ax.set_yscale("log", nonpositive="mask")
            top = float(finite.max()) if len(finite) else 1.0
            positive_all = finite[finite > _ZERO_ERROR_M]
            bottom = max(_ZERO_ERROR_M, top * 1e-6, 0.5 * float(np.percentile(positive_all, 1.0)))
            ax.set_ylim(bottom=bottom, top=top * 2.0)
        elif len(scaled) < len(series) and len(finite) and float(finite.max()) > 0.0:
            ax.set_ylim(bottom=0.0, top=1.08 * float(finite.max()))
        else:
            ax.set_ylim(bottom=0.0)
    _shade_truth_gaps(ax, t, reference)
    ax.set_xlabel("time since start [s]")
    ax.set_ylabel("position error [m]")
    ax.set_title(f"{title}\n(solid: final estimate, dashed: online estimate at its own step)", fontsize=11)
    ax.grid(True, which="both", lw=0.5, alpha=0.5)
    return _legend_and_save(fig, ax, path, with_legend=bool(series))


def plot_heading_errors(path, runs: list[EstimatorRun], reference: Reference, stamps_s, *, baseline: str = "fade",
                        baselines=BASELINE_ESTIMATORS) -> Path:
    """Heading error (degrees, wrapped) against time since the start; save a PNG.

    The same alignment, line styles and baseline handling as :func:`plot_position_errors`:
    final solid, online dashed (when it differs from the final estimate); a faded baseline
    is faint and the axis is scaled to the other estimators.
    """
    ref = np.asarray(reference.trajectory, dtype=float).reshape(-1, 3)
    t = np.asarray(stamps_s, dtype=float) - float(stamps_s[0])
    fig = _new_figure()
    ax = fig.add_subplot()
    scaled, faded = [], False
    for i, run, faint in _plotted(runs, baselines, baseline):
        colour, _ = _style(i)
        final, _, rot, trans = _aligned_final(run, reference)
        m = len(final)
        if not m:
            continue
        style = {"lw": 0.8, "alpha": _FAINT_ALPHA, "zorder": 1} if faint else {"lw": 1.2, "zorder": 2}
        err = np.degrees(heading_errors_rad(final, ref[:m]))  # NaN where the reference has no pose
        scored = err[np.isfinite(err)]
        rms = float(np.sqrt(np.mean(scored**2))) if len(scored) else float("nan")
        label = f"{run.name} final (RMS {rms:.2f}°)"
        ax.plot(t[:m], err, color=colour, label=_faint(label) if faint else label, **style)
        faded |= faint
        if not faint:
            scaled.append(scored)
        if run.online is not None and len(run.online):
            online = apply_se2(np.asarray(run.online, dtype=float).reshape(-1, 3), rot, trans)
            if not (online.shape == final.shape and np.allclose(online, final)):
                k = len(online)
                err_on = np.degrees(heading_errors_rad(online, ref[:k]))
                ax.plot(t[:k], err_on, color=colour, ls="--",
                        label=_faint(f"{run.name} online") if faint else f"{run.name} online",
                        **(style if faint else {"lw": 1.0, "zorder": 2}))
                if not faint:
                    scaled.append(err_on[np.isfinite(err_on)])
    values = np.concatenate(scaled) if scaled else np.zeros(0)
    if faded and len(values):
        low, high = min(float(values.min()), 0.0), max(float(values.max()), 0.0)
        pad = 0.08 * max(high - low, 1e-3)
        ax.set_ylim(low - pad, high + pad)
    ax.axhline(0.0, color="0.3", lw=0.6)
    _shade_truth_gaps(ax, t, reference)
    ax.set_xlabel("time since start [s]")
    ax.set_ylabel("heading error [deg]  (estimate − reference, wrapped)")
    ax.set_title("Heading error against the reference\n(solid: final estimate, dashed: online estimate)",
                 fontsize=11)
    ax.grid(True, lw=0.5, alpha=0.5)
    return _legend_and_save(fig, ax, path)


def plot_nis(path, runs: list[EstimatorRun], stamps_s, *, baseline: str = "fade",
             baselines=BASELINE_ESTIMATORS) -> Path | None:
    """NIS of every observation against time, with the 95 % χ² band of its degrees of freedom
    (2 for range and bearing, 1 for a range-only reading); a PNG (None when no estimator
    recorded NIS). Needs no reference: it is the estimator's own surprise."""
    t = np.asarray(stamps_s, dtype=float) - float(stamps_s[0])
    fig = _new_figure()
    ax = fig.add_subplot()
    drawn = False
    dofs: set[int] = set()
    for i, run, faint in _plotted(runs, baselines, baseline):
        if run.nis is None or run.nis_steps is None or not len(run.nis):
            continue
        dofs.update({NIS_DOF} if run.nis_dofs is None else set(np.asarray(run.nis_dofs).tolist()))
        mean, inside, count = nis_summary(run.nis, run.nis_dofs)
        label = f"{run.name}: {count} obs., mean {mean:.2f}, {100 * inside:.1f} % inside"
        ax.plot(t[np.asarray(run.nis_steps, dtype=int)], np.maximum(run.nis, 1e-6), ".", ms=2.0,
                color=_style(i)[0], alpha=_FAINT_ALPHA if faint else 1.0,
                label=f"{label} (baseline: faint)" if faint else label)
        drawn = True
    if not drawn:
        return None
    for dof, style in zip(sorted(dofs), ("--", "-.")):
        low, high = nees_band(dof)
        ax.axhline(low, color="k", ls=style, lw=0.8, label=f"95 % band, {dof} DoF [{low:.3f}, {high:.2f}]")
        ax.axhline(high, color="k", ls=style, lw=0.8)
        ax.axhline(dof, color="0.5", ls=":", lw=0.8, label=f"expected mean {dof}")
    ax.set_yscale("log")
    ax.set_xlabel("time since start [s]")
    ax.set_ylabel("NIS of the observation (range, bearing: 2 DoF; range only: 1)")
    ax.set_title("Consistency: NIS of each observation against the prediction before its step", fontsize=11)
    ax.grid(True, which="both", lw=0.5, alpha=0.5)
    return _legend_and_save(fig, ax, path, markerscale=4)


def plot_nees(path, runs: list[EstimatorRun], reference: Reference, stamps_s, *, baseline: str = "fade",
              baselines=BASELINE_ESTIMATORS) -> Path | None:
    """NEES of each estimator's online pose against time, with the 95 % χ²(3) band; a PNG.

    Only estimators that stated a covariance, and only against ground truth (returns None
    otherwise: NEES against a smoothed solution that shares the measurements means little).
    Poses without truth have no NEES: gaps in the curves.
    """
    if reference.kind != "ground_truth":
        return None
    ref = np.asarray(reference.trajectory, dtype=float).reshape(-1, 3)
    t = np.asarray(stamps_s, dtype=float) - float(stamps_s[0])
    fig = _new_figure()
    ax = fig.add_subplot()
    drawn = False
    for i, run, faint in _plotted(runs, baselines, baseline):
        if run.online is None or run.online_covariances is None:
            continue
        k = len(run.online)
        values = np.full(k, np.nan)
        valid = reference.has_pose[:k]
        values[valid] = nees(np.asarray(run.online)[valid], np.asarray(run.online_covariances)[valid], ref[:k][valid])
        ax.plot(t[:k], values, color=_style(i)[0], lw=0.8, alpha=_FAINT_ALPHA if faint else 1.0,
                label=f"{run.name} (baseline: faint)" if faint else run.name, zorder=1 if faint else 2)
        drawn = True
    if not drawn:
        return None
    low, high = nees_band()
    ax.axhline(low, color="k", ls="--", lw=0.8, label=f"95 % band [{low:.2f}, {high:.2f}]")
    ax.axhline(high, color="k", ls="--", lw=0.8)
    ax.set_yscale("log")
    _shade_truth_gaps(ax, t, reference)
    ax.set_xlabel("time since start [s]")
    n, with_truth = len(ref), reference.poses_with_truth
    ax.set_ylabel("NEES of the online pose (3 DoF)" + ("" if with_truth == n else f"; {with_truth} of {n} poses have truth"))
    ax.set_title("Consistency: NEES against time (inside the band about 95 % of the time if consistent)",
                 fontsize=11)
    ax.grid(True, which="both", lw=0.5, alpha=0.5)
    return _legend_and_save(fig, ax, path)


def plot_step_times(path, runs: list[EstimatorRun], *, baseline: str = "fade",
                    baselines=BASELINE_ESTIMATORS) -> Path | None:
    """Wall-clock time of each step against the step number, log scale; a PNG (None when no
    estimator has per-step times). An EKF's growth with the map shows as a rising band."""
    fig = _new_figure()
    ax = fig.add_subplot()
    drawn = False
    for i, run, faint in _plotted(runs, baselines, baseline):
        if run.step_times_s is None or not len(run.step_times_s):
            continue
        times_ms = 1e3 * np.asarray(run.step_times_s, dtype=float)
        label = f"{run.name} (median {np.median(times_ms):.3f} ms)"
        ax.plot(np.arange(len(times_ms)), np.maximum(times_ms, 1e-4), ".", ms=1.5, color=_style(i)[0],
                alpha=_FAINT_ALPHA if faint else 1.0, label=f"{label} (baseline: faint)" if faint else label)
        drawn = True
    if not drawn:
        return None
    ax.set_yscale("log")
    ax.set_xlabel("step")
    ax.set_ylabel("time per step [ms]")
    ax.set_title("Cost: wall-clock time of every step", fontsize=11)
    ax.grid(True, which="both", lw=0.5, alpha=0.5)
    return _legend_and_save(fig, ax, path, markerscale=6)


_CSS = """
body { font-family: system-ui, -apple-system, "Segoe UI", Roboto, sans-serif; margin: 2em auto;
       max-width: 1000px; padding: 0 1em; color: #222; line-height: 1.45; }
h1 { font-size: 1.5em; margin-bottom: 0.2em; }
h2 { font-size: 1.15em; margin-top: 1.8em; border-bottom: 1px solid #ddd; }
table.metrics { border-collapse: collapse; font-variant-numeric: tabular-nums; font-size: 0.92em; }
table.metrics th, table.metrics td { border: 1px solid #ccc; padding: 0.3em 0.6em; }
table.metrics th { background: #f2f2f2; }
table.metrics td { text-align: right; font-family: ui-monospace, Menlo, Consolas, monospace; }
table.metrics td:first-child { text-align: left; font-weight: 600; }
table.figures td { text-align: left; font-family: inherit; }
dl dt { font-weight: 600; font-family: ui-monospace, Menlo, Consolas, monospace; }
dl dd { margin: 0 0 0.5em 1.5em; }
img { max-width: 100%; height: auto; border: 1px solid #eee; }
code, pre { font-family: ui-monospace, Menlo, Consolas, monospace; }
pre { background: #f7f7f7; padding: 0.8em; overflow-x: auto; font-size: 0.85em; }
.note { color: #555; font-size: 0.92em; }
dl.provenance { display: grid; grid-template-columns: max-content 1fr; gap: 0.2em 1em; font-size: 0.92em; }
dl.provenance dt { font-family: inherit; }
dl.provenance dd { margin: 0; overflow-wrap: anywhere; }
code.hash { font-size: 0.9em; }
"""


def _gap_note(metrics: dict) -> str:
    """The end of the page's reference sentence when the ground truth has gaps."""
    poses, with_truth = metrics.get("poses"), metrics.get("reference_poses_with_truth")
    if metrics.get("reference") != "ground_truth" or with_truth is None or with_truth == poses:
        return ""
    return "; poses without truth are not scored: the table leaves them out and the curves break there"


def _data_uri(png_path: Path) -> str:
    return "data:image/png;base64," + base64.b64encode(png_path.read_bytes()).decode("ascii")


def _html_table(metrics: dict) -> str:
    headers, rows, notes = table_rows(metrics)
    e = html.escape
    parts = ['<table class="metrics">', "<thead><tr>"]
    parts += [f"<th>{e(h)}</th>" for h in headers]
    parts.append("</tr></thead><tbody>")
    for row in rows:
        parts.append("<tr>" + "".join(f"<td>{e(c)}</td>" for c in row) + "</tr>")
    parts.append("</tbody></table>")
    parts += [f'<p class="note">{e(n)}</p>' for n in notes]
    return "\n".join(parts)


def _provenance_html(prov: dict) -> str:
    e = html.escape
    sha = prov.get("log_sha256")
    size = prov.get("log_bytes")
    log_text = f"<code>{e(str(prov.get('log')))}</code>"
    if sha:
        log_text += f", {e(str(size))} bytes, SHA-256 <code class=\"hash\">{e(sha)}</code>"
    else:
        log_text += " (not readable when the report was written: no SHA-256)"
    rows = [
        ("fgslam", f"{e(str(prov.get('fgslam_version')))} (gtsam {e(str(prov.get('gtsam_version')))}, "
                   f"Python {e(str(prov.get('python')))})"),
        ("command", f"<code>{e(str(prov.get('command')))}</code>"),
        ("date (UTC)", f"<time datetime=\"{e(str(prov.get('date_utc')))}\">{e(str(prov.get('date_utc')))}</time>"),
        ("log", log_text),
        ("estimators", e(", ".join(prov.get("estimators") or []))),
    ]
    body = "\n".join(f"<dt>{k}</dt><dd>{v}</dd>" for k, v in rows)
    return f'<dl class="provenance" id="provenance">\n{body}\n</dl>'


def _baseline_note(runs: list[EstimatorRun], baseline: str, baselines) -> str:
    names = [r.name for r in runs if r.name in baselines]
    if not names or baseline == "show":
        return ""
    what = ", ".join(names)
    if baseline == "drop":
        return (f"Baseline left out of the figures: {what} (it is still in the table). ")
    return (f"Baseline drawn faint in the figures: {what}. The axes are scaled to the other estimators, so "
            f"it is clipped where it leaves them, and its landmarks and ellipses are not drawn (its numbers "
            f"are in the table). ")


def write_report(
    out_dir: str | os.PathLike[str],
    metrics: dict,
    runs: list[EstimatorRun],
    reference: Reference,
    stamps_s: np.ndarray,
    *,
    truth_landmarks: dict | None = None,
    title: str = "fgslam: estimator comparison",
    command: str | Sequence[str] | None = None,
    provenance_info: dict | None = None,
    baseline: str = "fade",
    baselines=BASELINE_ESTIMATORS,
) -> Path:
    """Write the figures (see the module docstring; ``nees.png`` only with ground truth,
    ``nis.png`` only when an estimator predicted its observations) and ``report.html``
    into ``out_dir``.

    Args:
        out_dir: directory to write into (created if missing; files are overwritten).
        metrics: the output of :func:`fgslam.compare.compute_metrics` for these runs.
        runs, reference: what the metrics were computed from (drawn in the figures).
        stamps_s: ``(n,)`` time stamp of each reference pose, seconds.
        truth_landmarks: optional true landmark map to draw as well (useful when the
            reference is the smoothed solution but a simulator knows the true map).
        title: page and figure title.
        command: the command line that made the report, for its provenance (a string, or
            a list joined with shell quoting); default ``sys.argv``.
        provenance_info: the provenance to show, as :func:`provenance` returns it; default
            ``metrics["provenance"]`` when the caller put it there (so the page and
            ``metrics.json`` say the same), else ``provenance(metrics["log"], <the runs'
            names>, command=command)``.
        baseline: what the figures do with a baseline estimator such as dead reckoning:
            ``"fade"`` (faint, the axes zoomed to the others), ``"drop"`` (not drawn; still
            in the table) or ``"show"`` (drawn like the others).
        baselines: the names of the baseline estimators (default: ``dead_reckoning``).

    Returns:
        The path of ``report.html``.
    """
    if baseline not in BASELINE_MODES:
        raise ValueError(f"baseline must be one of {', '.join(BASELINE_MODES)}, not {baseline!r}")
    prov = provenance_info if provenance_info is not None else metrics.get("provenance")
    if not isinstance(prov, dict):
        prov = provenance(metrics.get("log"), [r.name for r in runs], command=command)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    styles = {"baseline": baseline, "baselines": baselines}
    figures = [
        _Figure("fig-trajectories", "Trajectories and maps", TRAJECTORIES_PNG,
                "every estimator's final trajectory and landmarks over the reference, with 95 % "
                "covariance ellipses (online poses, final landmarks): the whole map, zoomed to the "
                "estimators, and a detail where their error is largest",
                plot_trajectories(out / TRAJECTORIES_PNG, runs, reference, truth_landmarks=truth_landmarks,
                                  title=title, **styles), ""),
        _Figure("fig-position-error", "Position error over time", POSITION_ERROR_PNG,
                "position error in metres against time: final estimate solid, online dashed",
                plot_position_errors(out / POSITION_ERROR_PNG, runs, reference, stamps_s, **styles), ""),
        _Figure("fig-heading-error", "Heading error over time", HEADING_ERROR_PNG,
                "heading error in degrees against time: final estimate solid, online dashed",
                plot_heading_errors(out / HEADING_ERROR_PNG, runs, reference, stamps_s, **styles), ""),
        _Figure("fig-nees", "Consistency: NEES", NEES_PNG,
                "NEES of the online pose against time with the 95 % chi-square(3) band",
                plot_nees(out / NEES_PNG, runs, reference, stamps_s, **styles),
                "No NEES: it needs the ground truth and an estimator that states a covariance."),
        _Figure("fig-nis", "Consistency: NIS", NIS_PNG,
                "NIS of each observation against time with the 95 % chi-square(2) band",
                plot_nis(out / NIS_PNG, runs, stamps_s, **styles),
                "No NIS: no estimator predicted its observations."),
        _Figure("fig-step-time", "Time per step", STEP_TIME_PNG,
                "wall-clock time of every step in milliseconds, log scale",
                plot_step_times(out / STEP_TIME_PNG, runs, **styles), "No per-step times."),
    ]

    e = html.escape
    reference_text = reference_description(metrics)
    shown, _, _ = table_rows(metrics)
    columns = "\n".join(f"<dt>{e(k)}</dt><dd>{e(v)}</dd>" for k, v in COLUMN_MEANINGS.items() if k in shown)
    metrics_json = json.dumps(metrics, indent=2)
    figure_rows = "\n".join(
        f'<tr><td><a href="#{f.anchor}">{e(f.title)}</a></td><td><code>{e(f.file)}</code></td>'
        f"<td>{e(f.what) if f.path is not None else e(f.missing)}</td></tr>"
        for f in figures
    )
    sections = "\n\n".join(
        f'<h2 id="{f.anchor}">{e(f.title)}</h2>\n'
        + (f'<img src="{_data_uri(f.path)}"\n alt="{e(f.what)}">' if f.path is not None
           else f'<p class="note">{e(f.missing)}</p>')
        for f in figures
    )
    page = f"""<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<meta name="generator" content="fgslam {e(str(prov.get("fgslam_version")))}">
<title>{e(title)}</title>
<style>{_CSS}</style>
</head>
<body>
<h1>{e(title)}</h1>
<p><strong>Log:</strong> <code>{e(str(metrics.get("log")))}</code> ({e(str(metrics.get("poses")))} poses)</p>
<p><strong>Reference:</strong> {e(reference_text)}. Every figure below is measured against it{e(_gap_note(metrics))}.</p>

<h2>Provenance</h2>
{_provenance_html(prov)}

<h2>Metrics</h2>
{_html_table(metrics)}

<h2>What the columns mean</h2>
<dl>
{columns}
</dl>
<p class="note">Alignment: estimators anchored at the log's known start pose share their first
pose with the reference and are compared as they are, without any alignment. An estimate whose
first pose differs (another frame) is aligned to the reference by the least-squares rigid 2-D
transform (rotation and translation, never a reflection); its ATE is marked with *. Times are
wall-clock on the machine that ran the comparison. - means not applicable (a one-shot batch
solve has no online estimate and no per-step time).</p>

<h2>Figures</h2>
<table class="metrics figures">
<thead><tr><th>figure</th><th>file</th><th>what it shows</th></tr></thead>
<tbody>
{figure_rows}
</tbody>
</table>
<p class="note">{e(_baseline_note(runs, baseline, baselines))}Each figure is embedded in this page and also
written as a PNG next to it.</p>

{sections}

<h2 id="metrics-json">metrics.json</h2>
<pre>{e(metrics_json)}</pre>
</body>
</html>
"""
    html_path = out / REPORT_HTML
    html_path.write_text(page, encoding="utf-8")
    return html_path


def plot_live_map(path, trajectory, landmarks: dict, waypoints=None) -> Path:
    """The live loop's map so far (``fgslam live --map-png``): iSAM2's trajectory, its
    landmarks with their ids, and the waypoints. Written to a temporary file and renamed,
    so a viewer never sees half a picture."""
    fig = Figure(figsize=(6, 6), dpi=80)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    traj = np.asarray(trajectory, dtype=float).reshape(-1, 3)
    if waypoints is not None:
        w = np.asarray(waypoints, dtype=float).reshape(-1, 2)
        ax.plot(w[:, 0], w[:, 1], "o--", color="0.6", lw=0.8, ms=4, label="waypoints")
    if len(traj):
        ax.plot(traj[:, 0], traj[:, 1], color=_COLOURS[1], lw=1.2, label="iSAM2 trajectory")
        ax.plot(traj[-1, 0], traj[-1, 1], marker=(3, 0, np.degrees(traj[-1, 2]) - 90), ms=12, color=_COLOURS[1])
    for lid, (x, y) in sorted(landmarks.items()):
        ax.plot(x, y, "s", color=_COLOURS[0], ms=6)
        ax.annotate(str(lid), (x, y), textcoords="offset points", xytext=(4, 4), fontsize=8)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(f"fgslam live: {len(traj)} poses, {len(landmarks)} landmarks", fontsize=10)
    ax.grid(True, lw=0.5, alpha=0.5)
    ax.legend(loc="upper right", fontsize=8)
    out = Path(path)
    tmp = out.with_name(out.name + ".tmp.png")
    fig.savefig(tmp)
    os.replace(tmp, out)
    return out


def write_monte_carlo_figures(out_dir: str | os.PathLike[str], result) -> list[str]:
    """``nees.png`` (average NEES per step with its χ² band, per estimator) and ``ate.png``
    (box plots of the final and online ATE over the runs) for a
    :class:`fgslam.montecarlo.MonteCarloResult`; returns the file names written."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    names = list(result.average_nees)
    low, high = result.band

    fig = Figure(figsize=(8, 4))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    for name in names:
        ax.plot(result.average_nees[name], lw=1, label=f"{name} ({100 * result.share_inside(name):.0f} % inside)")
    ax.axhline(low, color="k", ls="--", lw=0.8, label=f"95 % band [{low:.2f}, {high:.2f}]")
    ax.axhline(high, color="k", ls="--", lw=0.8)
    ax.axhline(float(result.dof), color="0.6", ls=":", lw=0.8)
    ax.set_xlabel("step")
    ax.set_ylabel(f"average NEES over {len(result.runs)} runs")
    ax.set_title(f"{result.scenario}: NEES of the online pose ({result.dof} DoF)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out / "nees.png", dpi=110)

    fig = Figure(figsize=(8, 4))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    data, labels = [], []
    for name in names:
        for kind, values in (("final", "ate_final_m"), ("online", "ate_online_m")):
            data.append([getattr(r, values)[name] for r in result.runs])
            labels.append(f"{name}\n{kind}")
    ax.boxplot(data)
    ax.set_xticks(range(1, len(labels) + 1), labels)
    ax.set_ylabel("ATE (m)")
    ax.set_title(f"{result.scenario}: ATE over {len(result.runs)} runs")
    fig.tight_layout()
    fig.savefig(out / "ate.png", dpi=110)
    return ["nees.png", "ate.png"]


# --------------------------------------------------------------------------- 3-D logs


def plot_top_view_3d(path, runs, reference, *, zoom_out_of: Sequence[str] = ("ekf-s003",)) -> Path:
    """Top view (x, y) of every estimator's final trajectory and landmarks over the reference.

    ``runs`` are :class:`fgslam.runner3d.Run3d`, ``reference`` a
    :class:`fgslam.runner3d.Reference3d`. The view is framed on the reference and the
    estimators except those in ``zoom_out_of`` (the as-written ekf-s003 stays within a step
    of the origin or leaves the drive entirely; it is drawn, but does not set the frame).
    """
    fig = _new_figure()
    ax = fig.add_subplot()
    ref_pts = _landmark_array({j: p[:2] for j, p in reference.landmarks.items()})
    if len(ref_pts):
        ax.scatter(ref_pts[:, 0], ref_pts[:, 1], s=4, c="0.65", label=f"reference landmarks ({reference.kind})")
    ax.plot(reference.trajectory[:, 0, 3], reference.trajectory[:, 1, 3], color="0.2", lw=3, alpha=0.35,
            label=f"reference ({reference.kind})")
    framed = [reference.trajectory[:, :2, 3]]
    for i, run in enumerate(runs):
        colour, marker = _style(i)
        xy = run.final[:, :2, 3]
        ax.plot(xy[:, 0], xy[:, 1], color=colour, lw=1.2, label=run.name)
        pts = _landmark_array({j: p[:2] for j, p in run.landmarks.items()})
        if len(pts):
            ax.scatter(pts[:, 0], pts[:, 1], s=6, color=colour, marker=marker, alpha=0.5)
        if run.name not in zoom_out_of:
            framed.append(xy)
    xy = np.vstack(framed)
    lo, hi = np.nanmin(xy, axis=0), np.nanmax(xy, axis=0)  # NaN: gaps in the reference's truth
    margin = 0.1 * float(np.max(hi - lo)) + 5.0
    ax.set_xlim(lo[0] - margin, hi[0] + margin)
    ax.set_ylim(lo[1] - margin, hi[1] + margin)
    ax.plot([0.0], [0.0], "k^", ms=8, label="start (IMU at pose 0)")
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title("top view: final trajectories and landmarks")
    return _legend_and_save(fig, ax, path)


def write_report_3d(out_dir, metrics: dict, runs, reference, *, title: str = "fgslam run",
                    table_header: Sequence[str] = (), table_rows: Sequence[Sequence[str]] = (),
                    reference_text: str = "") -> Path:
    """``top_view.png`` and a self-contained ``report.html`` for a 3-D log (fgslam.runner3d)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    png = plot_top_view_3d(out / TOP_VIEW_3D_PNG, runs, reference)
    e = html.escape
    prov = metrics.get("provenance") or {}
    head = "".join(f"<th>{e(h)}</th>" for h in table_header)
    body = "\n".join("<tr>" + "".join(f"<td>{e(c)}</td>" for c in row) + "</tr>" for row in table_rows)
    page = f"""<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>{e(title)}</title>
<style>{_CSS}</style>
</head>
<body>
<h1>{e(title)}</h1>
<p><strong>Log:</strong> <code>{e(str(metrics.get("log")))}</code> ({e(str(metrics.get("poses")))} poses, 3-D)</p>
<p><strong>Reference:</strong> {e(reference_text)}.</p>

<h2>Provenance</h2>
{_provenance_html(prov) if prov else ""}

<h2>Metrics</h2>
<table class="metrics"><thead><tr>{head}</tr></thead><tbody>
{body}
</tbody></table>
<p class="note">ATE 3-D and ATE 2-D (top view, x and y) are RMSEs of the final positions; "final m" is
the last pose's position error; "map med m" the median error of the landmarks an estimator placed;
NEES is the online pose's on SE(3) (right perturbation, χ²₆) and "in band" the share of steps inside
its 95 % band; NIS is per accepted stereo observation (χ²₄); ms/step is the wall time of one step
with BLAS on one thread; - means not applicable.</p>

<h2 id="top-view">Top view</h2>
<img src="{_data_uri(png)}"
 alt="top view of every estimator's trajectory and landmarks over the reference">

<h2 id="metrics-json">metrics.json</h2>
<pre>{e(json.dumps(metrics, indent=2))}</pre>
</body>
</html>
"""
    html_path = out / REPORT_HTML
    html_path.write_text(page, encoding="utf-8")
    return html_path
