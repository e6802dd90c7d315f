"""The trajectory figure: every estimator's final trajectory and map over the reference.

Two panels, an overview zoomed to the estimators (:func:`trajectory_view`) and a detail around
the pose where their error is largest (:func:`detail_pose`), with 95 % covariance ellipses
(:func:`ellipse_xy`); :func:`plot_trajectories` saves it as ``trajectories.png``.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

from fgslam.atomic import save_figure
from fgslam.compare import EstimatorRun, Reference, apply_se2, position_errors_m
from fgslam.report.style import (
    _DPI,
    _FAINT_ALPHA,
    BASELINE_ESTIMATORS,
    _aligned_final,
    _faint,
    _is_baseline,
    _is_the_reference,
    _landmark_array,
    _plotted,
    _style,
)


_TRAJECTORY_FIGSIZE_IN = (15.0, 6.8)
# Overview: the estimators' bounding box widened by this share of its larger side (at least _VIEW_MIN_MARGIN_M).
_VIEW_MARGIN = 0.04
_VIEW_MIN_MARGIN_M = 0.3
# Detail window: half-width = this × the largest error at its centre, at least _DETAIL_MIN_SHARE × the
# overview's larger side and _DETAIL_MIN_HALF_M.
_DETAIL_SPAN = 2.0
_DETAIL_MIN_SHARE = 0.02
_DETAIL_MIN_HALF_M = 0.02


#: Poses per estimator that get a covariance ellipse on the trajectory plot.
_ELLIPSES_PER_RUN = 12


def ellipse_xy(centre_xy, covariance_xy, probability: float = 0.95, points: int = 64) -> np.ndarray:
    """``(points, 2)`` outline of the ellipse that holds ``probability`` of a 2-D Gaussian.

    The boundary is ``{x : (x − c)ᵀ Σ⁻¹ (x − c) = χ²⁻¹(probability; 2)}`` (5.99 for 95 %):
    the unit circle scaled by ``√(χ² λᵢ)`` along the eigenvectors of Σ.
    """
    from slamio.chi2 import chi2_ppf

    values, vectors = np.linalg.eigh(0.5 * (np.asarray(covariance_xy, dtype=float) + np.asarray(covariance_xy).T))
    radii = np.sqrt(chi2_ppf(probability, 2) * np.clip(values, 0.0, None))
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


def _draw_run(panel, run: EstimatorRun, reference: Reference, style, faint: bool, *, legend: bool,
              picks_at: int | None) -> np.ndarray:
    """Draw one estimator on one panel of :func:`trajectory_figure`: its final trajectory,
    landmarks and 95 % ellipses (faint: the trajectory alone). ``picks_at`` None: pose
    ellipses spread over the run (the overview); else the one at that pose (the detail).
    Returns its final trajectory as drawn (aligned when it had to be)."""
    colour, marker = style
    final, aligned, rot, trans = _aligned_final(run, reference)
    suffix = " (aligned SE(2))" if aligned else ""
    label = f"{run.name}{suffix}"
    if faint:
        if len(final):
            panel.plot(final[:, 0], final[:, 1], color=colour, lw=0.8, alpha=_FAINT_ALPHA,
                       label=_faint(label) + "; no landmarks or ellipses" if legend else None, zorder=0.5)
        return final
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
        picks = _ellipse_steps(np.asarray(run.online_covariances)[: len(online)], picks_at)
        _draw_ellipses(panel, online[picks, :2], np.asarray(run.online_covariances)[picks], rot, colour,
                       f"{run.name} 95 % pose ellipse (online)" if legend else None)
    if run.landmark_covariances:
        ids = [k for k in sorted(run.landmarks) if k in run.landmark_covariances]
        centres = apply_se2(np.array([run.landmarks[k] for k in ids], dtype=float).reshape(-1, 2), rot, trans)
        _draw_ellipses(panel, centres, [run.landmark_covariances[k] for k in ids], rot, colour, None)
    return final


def _ellipse_steps(covariances: np.ndarray, picks_at: int | None) -> np.ndarray:
    """The steps to draw pose ellipses at, among those with a covariance (every step, or the
    consistency sample's): :data:`_ELLIPSES_PER_RUN` spread over the run, or for the detail
    (``picks_at``) the step nearest to it (each ellipse is drawn around its own pose)."""
    have = np.flatnonzero(np.isfinite(covariances).all(axis=(1, 2)))
    if not len(have):
        return have
    if picks_at is None:
        return have[np.unique(np.linspace(0, len(have) - 1, min(_ELLIPSES_PER_RUN, len(have))).round().astype(int))]
    if picks_at >= len(covariances):
        return np.zeros(0, dtype=int)
    return have[[int(np.argmin(np.abs(have - picks_at)))]]


def _draw_detail(ax, detail, plotted, finals: dict, centre: np.ndarray, k_detail: int, span: float,
                 baselines, reference: Reference) -> None:
    """The detail panel of :func:`trajectory_figure`: pose ``k_detail`` (reference at
    ``centre``) and each estimate joined to it, zoomed to their errors; its window marked on
    the overview ``ax`` (``span``: the overview's larger side). Against a smoothed
    ``reference`` the distances are called that, not errors, and the batch is the reference."""
    smoothed = reference.kind == "smoothed"
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
    # the window fits the estimators' errors, not a baseline's (drawn there with baseline="show")
    sizing = [e for _, e, base in errors if not base] or [e for _, e, _ in errors]
    half = max(_DETAIL_SPAN * max(sizing, default=0.0), _DETAIL_MIN_SHARE * span, _DETAIL_MIN_HALF_M)
    detail.set_xlim(centre[0] - half, centre[0] + half)
    detail.set_ylim(centre[1] - half, centre[1] + half)
    detail.set_aspect("equal", adjustable="box")
    if smoothed:
        detail.set_title(f"Detail around pose {k_detail}, farthest from the smoothed reference", fontsize=10)
    else:
        detail.set_title(f"Detail around pose {k_detail}, where the estimators' error is largest", fontsize=10)
    detail.text(0.02, 0.02, "{} at pose {}:\n{}".format(
                    "distance to the smoothed reference" if smoothed else "position error", k_detail,
                    "\n".join(f"{name}: {'the reference' if _is_the_reference(name, reference) else f'{e:.3f} m'}"
                              for name, e, _ in errors)),
                transform=detail.transAxes, fontsize=8, va="bottom", ha="left", zorder=6,
                bbox={"boxstyle": "round", "fc": "white", "ec": "0.7", "alpha": 0.9})
    ax.add_patch(Rectangle((centre[0] - half, centre[1] - half), 2 * half, 2 * half, fill=False, ec="black",
                           lw=1.0, ls=":", zorder=6, label="detail window (right)"))
    detail.plot([], [], marker="o", color="0.55", mec="black", ls="none",
                label=f"pose {k_detail}: reference (grey) and each estimate, joined")


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
            finals[run.name] = _draw_run(panel, run, reference, _style(i), faint, legend=legend,
                                         picks_at=None if panel is ax else k_detail)

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
        _draw_detail(ax, detail, plotted, finals, ref[k_detail, :2], k_detail,
                     max(xmax - xmin, ymax - ymin), baselines, reference)
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


def plot_trajectories(path: str | os.PathLike[str], runs: list[EstimatorRun], reference: Reference,
                      **options) -> Path:
    """Draw every estimator's final trajectory and map over the reference; save a PNG.
    ``options`` are :func:`trajectory_figure`'s: ``truth_landmarks``, ``title``,
    ``baseline`` and ``baselines``.

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
    fig = trajectory_figure(runs, reference, **options)
    return save_figure(fig, path, dpi=_DPI, metadata={"Software": None}, pil_kwargs={"optimize": True})
