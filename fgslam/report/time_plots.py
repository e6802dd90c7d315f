"""The report's figures against time: position and heading error, NEES, NIS, time per step.

Errors are drawn for the final estimate (solid) and the online one (dashed); where the
reference has no pose the curves break and a grey band (:func:`truth_gaps_s`) marks the gap.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from fgslam.compare import (
    NIS_DOF,
    ComparisonError,
    EstimatorRun,
    Reference,
    apply_se2,
    heading_errors_rad,
    nees,
    nees_band,
    nees_dofs,
    nis_summary,
    position_errors_m,
)
from fgslam.report.style import (
    _FAINT_ALPHA,
    BASELINE_ESTIMATORS,
    _aligned_final,
    _faint,
    _is_the_reference,
    _legend_and_save,
    _new_figure,
    _plotted,
    _style,
)


# Errors below this are "identical to the reference" (numerical noise), metres.
_ZERO_ERROR_M = 1e-6
# Switch the error axis to log scale when the estimators' typical errors differ this much.
_LOG_SPREAD = 30.0


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


def _position_error_series(runs: list[EstimatorRun], reference: Reference, ref: np.ndarray, t: np.ndarray,
                           baseline: str, baselines) -> list[tuple]:
    """The curves of :func:`plot_position_errors`: per estimator its final (and online, when
    it differs) position errors, as ``(label, colour, style, times, errors, faint)``."""
    series = []  # (label, colour, style, times, errors, faint)
    for i, run, faint in _plotted(runs, baselines, baseline):
        colour, _ = _style(i)
        final, aligned, rot, trans = _aligned_final(run, reference)
        m = len(final)
        err = position_errors_m(final, ref[:m])  # NaN where the reference has no pose
        finite_err = err[np.isfinite(err)]
        zero = bool(len(finite_err)) and float(finite_err.max()) < _ZERO_ERROR_M
        if zero and _is_the_reference(run.name, reference):
            label = "batch (the reference itself)"
        elif zero:
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
    return series


def plot_position_errors(
    path: str | os.PathLike[str],
    runs: list[EstimatorRun],
    reference: Reference,
    stamps_s,
    *,
    title: str | None = None,
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
    :func:`plot_trajectories` for ``"drop"`` and ``"show"``. Against a smoothed reference (no
    ground truth) the axis and title say "distance to the smoothed reference": agreement with
    our own smoother, not error.
    """
    smoothed = reference.kind == "smoothed"
    if title is None:
        title = ("Distance to the smoothed reference (no ground truth: agreement, not accuracy)" if smoothed
                 else "Position error against the reference")
    ref = np.asarray(reference.trajectory, dtype=float).reshape(-1, 3)
    stamps = np.asarray(stamps_s, dtype=float).reshape(-1)
    if len(stamps) < len(ref):
        raise ComparisonError(f"plot_position_errors: {len(stamps)} stamps for {len(ref)} reference poses")
    t = stamps - stamps[0] if len(stamps) else stamps

    series = _position_error_series(runs, reference, ref, t, baseline, baselines)

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
    ax.set_ylabel("distance to the smoothed reference [m]" if smoothed else "position error [m]")
    ax.set_title(f"{title}\n(solid: final estimate, dashed: online estimate at its own step)", fontsize=11)
    ax.grid(True, which="both", lw=0.5, alpha=0.5)
    return _legend_and_save(fig, ax, path, with_legend=bool(series))


def plot_heading_errors(path, runs: list[EstimatorRun], reference: Reference, stamps_s, *, baseline: str = "fade",
                        baselines=BASELINE_ESTIMATORS) -> Path | None:
    """Heading error (degrees, wrapped) against time since the start; save a PNG (None when
    no reference pose has a heading: a truth that measures position only, like GPS).

    The same alignment, line styles and baseline handling as :func:`plot_position_errors`:
    final solid, online dashed (when it differs from the final estimate); a faded baseline
    is faint and the axis is scaled to the other estimators.
    """
    if not reference.has_heading.any():
        return None
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
        if _is_the_reference(run.name, reference) and rms < 1e-6:
            label = "batch (the reference itself)"
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
    if reference.kind == "smoothed":  # no ground truth: a difference from our own smoother, not an error
        ax.set_ylabel("heading − smoothed reference [deg], wrapped")
        ax.set_title("Heading against the smoothed reference (agreement, not accuracy)\n"
                     "(solid: final estimate, dashed: online estimate)", fontsize=11)
    else:
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
    return _save_log_scatter(fig, ax, path, "time since start [s]",
                             "NIS of the observation (range, bearing: 2 DoF; range only: 1)",
                             "Consistency: NIS of each observation against the prediction before its step", 4)


def plot_nees(path, runs: list[EstimatorRun], reference: Reference, stamps_s, *, baseline: str = "fade",
              baselines=BASELINE_ESTIMATORS) -> Path | None:
    """NEES of each estimator's online pose against time, with the 95 % χ²(3) band; a PNG.

    Only estimators that stated a covariance, and only against ground truth (returns None
    otherwise: NEES against a smoothed solution that shares the measurements means little).
    Poses without truth have no NEES: gaps in the curves. Where the truth has no heading the
    NEES is over the position (:func:`~fgslam.compare.nees`), drawn with the χ²(2) band.
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
        sampled = (run.consistency or {}).get("mode") == "sampled"  # a point per sampled step, not a curve
        ax.plot(t[:k], values, ".-" if sampled else "-", ms=3.0, color=_style(i)[0], lw=0.4 if sampled else 0.8,
                alpha=_FAINT_ALPHA if faint else 1.0, zorder=1 if faint else 2,
                label=(f"{run.name} (baseline: faint)" if faint else run.name) + (" (sampled steps)" if sampled else ""))
        drawn = True
    if not drawn:
        return None
    dofs = sorted(set(nees_dofs(ref[reference.has_pose]).tolist()))
    for dof, style in zip(dofs, ("--", "-.")):
        low, high = nees_band(dof)
        ax.axhline(low, color="k", ls=style, lw=0.8,
                   label=f"95 % band [{low:.2f}, {high:.2f}]" + ("" if dofs == [3] else f", {dof} DoF"))
        ax.axhline(high, color="k", ls=style, lw=0.8)
    ax.set_yscale("log")
    _shade_truth_gaps(ax, t, reference)
    ax.set_xlabel("time since start [s]")
    n, with_truth = len(ref), reference.poses_with_truth
    what = {(3,): "3 DoF", (2,): "position, 2 DoF: the truth has no heading"}.get(tuple(dofs), "3 DoF; 2 without true heading")
    ax.set_ylabel(f"NEES of the online pose ({what})" + ("" if with_truth == n else f"; {with_truth} of {n} poses have truth"))
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
    return _save_log_scatter(fig, ax, path, "step", "time per step [ms]", "Cost: wall-clock time of every step", 6)


def _save_log_scatter(fig, ax, path, xlabel: str, ylabel: str, title: str, markerscale: float) -> Path:
    """Finish a scatter of many small dots on a log y axis (labels, title, grid, a legend whose
    dots are ``markerscale`` times larger) and save it."""
    ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=11)
    ax.grid(True, which="both", lw=0.5, alpha=0.5)
    return _legend_and_save(fig, ax, path, markerscale=markerscale)
