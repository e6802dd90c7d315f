"""The per-run report: two figures and one self-contained HTML page.

This is the only module of the project that imports matplotlib. It uses matplotlib's
object-oriented API with the Agg canvas (``Figure`` + ``FigureCanvasAgg``) instead of
``pyplot``: no window can ever open, no global backend is switched under a user who imported
fgslam into a notebook, and figures are not kept in pyplot's registry (nothing to close —
they are freed when the function returns).

:func:`write_report` writes into a directory:

* ``trajectories.png`` — each estimator's final trajectory and landmarks over the reference;
* ``position_error.png`` — position error against time (final solid, online dashed);
* ``report.html`` — one file that opens offline: inline CSS, the two PNGs embedded as
  ``data:`` URIs, the metrics table (the same strings as :func:`fgslam.compare.format_table`)
  and what every column means. It contains no links, scripts or external resources.

What is drawn is what was measured: each estimate is moved by the same SE(2) alignment
:func:`fgslam.compare.compute_metrics` used (the identity when it shares its first pose
with the reference).
"""

from __future__ import annotations

import base64
import html
import json
import os
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from fgslam.compare import (
    COLUMN_MEANINGS,
    REFERENCE_DESCRIPTIONS,
    ComparisonError,
    EstimatorRun,
    Reference,
    apply_se2,
    estimator_alignment,
    nees,
    nees_band,
    position_errors_m,
    table_rows,
)

__all__ = ["write_report", "plot_trajectories", "plot_position_errors", "plot_nees", "plot_step_times"]

TRAJECTORIES_PNG = "trajectories.png"
POSITION_ERROR_PNG = "position_error.png"
REPORT_HTML = "report.html"
NEES_PNG = "nees.png"
STEP_TIME_PNG = "step_time.png"

_FIGSIZE_IN = (9.0, 6.0)
_DPI = 100
_COLOURS = ["#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd", "#8c564b", "#e377c2", "#17becf"]
_MARKERS = ["o", "^", "s", "D", "v", "P", "X", "h"]
# Errors below this are "identical to the reference" (numerical noise), metres.
_ZERO_ERROR_M = 1e-6
# Switch the error axis to log scale when the estimators' typical errors differ this much.
_LOG_SPREAD = 30.0


def _new_figure() -> Figure:
    fig = Figure(figsize=_FIGSIZE_IN, dpi=_DPI, layout="constrained")
    FigureCanvasAgg(fig)  # attaches the Agg canvas: off-screen rendering only
    return fig


def _style(i: int) -> tuple[str, str]:
    return _COLOURS[i % len(_COLOURS)], _MARKERS[i % len(_MARKERS)]


def _aligned_final(run: EstimatorRun, reference: Reference) -> tuple[np.ndarray, bool, float, np.ndarray]:
    aligned, rot, trans = estimator_alignment(run, reference)
    final = np.asarray(run.final, dtype=float).reshape(-1, 3)
    return (apply_se2(final, rot, trans) if len(final) else final), aligned, rot, trans


def _landmark_array(landmarks: dict | None) -> np.ndarray:
    if not landmarks:
        return np.zeros((0, 2))
    return np.array([landmarks[k] for k in sorted(landmarks)], dtype=float).reshape(-1, 2)


def plot_trajectories(
    path: str | os.PathLike[str],
    runs: list[EstimatorRun],
    reference: Reference,
    *,
    truth_landmarks: dict | None = None,
    title: str = "Trajectories and maps",
) -> Path:
    """Draw every estimator's final trajectory and map over the reference; save a PNG.

    Equal axis scale in metres. The reference is the thick grey line with black ``×``
    landmarks; each estimator has its own colour and landmark marker (hollow). The start is
    a gold star, every trajectory's end a square in its colour. ``truth_landmarks``
    (e.g. the simulator's true map while the reference is the smoothed solution) are drawn
    as grey ``+`` when given and different from the reference's landmarks.
    """
    fig = _new_figure()
    ax = fig.add_subplot()
    ref = np.asarray(reference.trajectory, dtype=float).reshape(-1, 3)
    ref_name = "ground truth" if reference.kind == "ground_truth" else "smoothed"
    ax.plot(ref[:, 0], ref[:, 1], color="0.55", lw=3.0, alpha=0.7, label=f"reference ({ref_name})", zorder=1)
    ref_lm = _landmark_array(reference.landmarks)
    if len(ref_lm):
        ax.scatter(ref_lm[:, 0], ref_lm[:, 1], marker="x", s=40, c="black", lw=1.2,
                   label="reference landmarks", zorder=3)
    if truth_landmarks and truth_landmarks != reference.landmarks:
        truth_lm = _landmark_array(truth_landmarks)
        ax.scatter(truth_lm[:, 0], truth_lm[:, 1], marker="+", s=60, c="0.4", lw=1.2,
                   label="true landmarks", zorder=3)

    for i, run in enumerate(runs):
        colour, marker = _style(i)
        final, aligned, rot, trans = _aligned_final(run, reference)
        suffix = " (aligned SE(2))" if aligned else ""
        if len(final):
            ax.plot(final[:, 0], final[:, 1], color=colour, lw=1.3, label=f"{run.name}{suffix}", zorder=2)
            ax.plot(final[-1, 0], final[-1, 1], marker="s", ms=7, color=colour, ls="none", zorder=4)
        lm = _landmark_array(run.landmarks)
        if len(lm):
            lm = apply_se2(lm, rot, trans)
            ax.scatter(lm[:, 0], lm[:, 1], marker=marker, s=36, facecolors="none", edgecolors=colour,
                       lw=1.1, label=f"{run.name} landmarks", zorder=3)

    if len(ref):
        ax.plot(ref[0, 0], ref[0, 1], marker="*", ms=16, color="gold", mec="black", ls="none",
                label="start", zorder=5)
        ax.plot(ref[-1, 0], ref[-1, 1], marker="s", ms=8, color="0.55", mec="black", ls="none",
                label="end (square, each colour)", zorder=5)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title)
    ax.grid(True, lw=0.5, alpha=0.5)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
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
) -> Path:
    """Draw position error [m] against time since the start [s]; save a PNG.

    One colour per estimator: the final trajectory solid, the online one dashed (absent for
    a batch solve). The y axis is logarithmic when the estimators' median errors differ by
    more than a factor of 30 (e.g. EKF metres vs smoother millimetres), linear otherwise.
    An estimator whose errors are all below 1 µm is identical to the reference and is
    labelled as such.
    """
    ref = np.asarray(reference.trajectory, dtype=float).reshape(-1, 3)
    stamps = np.asarray(stamps_s, dtype=float).reshape(-1)
    if len(stamps) < len(ref):
        raise ComparisonError(f"plot_position_errors: {len(stamps)} stamps for {len(ref)} reference poses")
    t = stamps - stamps[0] if len(stamps) else stamps

    series = []  # (label, colour, style, times, errors)
    for i, run in enumerate(runs):
        colour, _ = _style(i)
        final, aligned, rot, trans = _aligned_final(run, reference)
        m = len(final)
        err = position_errors_m(final, ref[:m])
        zero = bool(m) and np.nanmax(err) < _ZERO_ERROR_M
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
        series.append((label, colour, "-", t[:m], err))
        if online is not None and len(online) and not same:
            k = len(online)
            err_on = position_errors_m(apply_se2(online, rot, trans), ref[:k])
            series.append((f"{run.name} online", colour, "--", t[:k], err_on))

    fig = _new_figure()
    ax = fig.add_subplot()
    medians = []
    for label, colour, style, times, err in series:
        ax.plot(times, err, color=colour, ls=style, lw=1.2, label=label)
        positive = err[np.isfinite(err) & (err > _ZERO_ERROR_M)]
        if len(positive):
            medians.append(float(np.median(positive)))
    if len(medians) >= 1:
        all_err = np.concatenate([s[4] for s in series]) if series else np.zeros(0)
        finite = all_err[np.isfinite(all_err)]
        spread = max(medians) / min(medians)
        if spread > _LOG_SPREAD:
            ax.set_yscale("log", nonpositive="mask")
            top = float(finite.max()) if len(finite) else 1.0
            positive_all = finite[finite > _ZERO_ERROR_M]
            bottom = max(_ZERO_ERROR_M, top * 1e-6, 0.5 * float(np.percentile(positive_all, 1.0)))
            ax.set_ylim(bottom=bottom, top=top * 2.0)
        else:
            ax.set_ylim(bottom=0.0)
    ax.set_xlabel("time since start [s]")
    ax.set_ylabel("position error [m]")
    ax.set_title(f"{title}\n(solid: final estimate, dashed: online estimate at its own step)", fontsize=11)
    ax.grid(True, which="both", lw=0.5, alpha=0.5)
    if series:
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    out = Path(path)
    fig.savefig(out, dpi=_DPI, metadata={"Software": None}, pil_kwargs={"optimize": True})
    return out


def plot_nees(path, runs: list[EstimatorRun], reference: Reference, stamps_s) -> Path | None:
    """NEES of each estimator's online pose against time, with the 95 % χ²(3) band; a PNG.

    Only estimators that stated a covariance, and only against ground truth (returns None
    otherwise: NEES against a smoothed solution that shares the measurements means little).
    """
    if reference.kind != "ground_truth":
        return None
    ref = np.asarray(reference.trajectory, dtype=float).reshape(-1, 3)
    t = np.asarray(stamps_s, dtype=float) - float(stamps_s[0])
    fig = _new_figure()
    ax = fig.add_subplot()
    drawn = False
    for i, run in enumerate(runs):
        if run.online is None or run.online_covariances is None:
            continue
        k = len(run.online)
        values = nees(run.online, run.online_covariances, ref[:k])
        ax.plot(t[:k], values, color=_style(i)[0], lw=0.8, label=run.name)
        drawn = True
    if not drawn:
        return None
    low, high = nees_band()
    ax.axhline(low, color="k", ls="--", lw=0.8, label=f"95 % band [{low:.2f}, {high:.2f}]")
    ax.axhline(high, color="k", ls="--", lw=0.8)
    ax.set_yscale("log")
    ax.set_xlabel("time since start [s]")
    ax.set_ylabel("NEES of the online pose (3 DoF)")
    ax.set_title("Consistency: NEES against time (inside the band about 95 % of the time if consistent)",
                 fontsize=11)
    ax.grid(True, which="both", lw=0.5, alpha=0.5)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    out = Path(path)
    fig.savefig(out, dpi=_DPI, metadata={"Software": None}, pil_kwargs={"optimize": True})
    return out


def plot_step_times(path, runs: list[EstimatorRun]) -> Path | None:
    """Wall-clock time of each step against the step number, log scale; a PNG (None when no
    estimator has per-step times). An EKF's growth with the map shows as a rising band."""
    fig = _new_figure()
    ax = fig.add_subplot()
    drawn = False
    for i, run in enumerate(runs):
        if run.step_times_s is None or not len(run.step_times_s):
            continue
        times_ms = 1e3 * np.asarray(run.step_times_s, dtype=float)
        ax.plot(np.arange(len(times_ms)), np.maximum(times_ms, 1e-4), ".", ms=1.5, color=_style(i)[0],
                label=f"{run.name} (median {np.median(times_ms):.3f} ms)")
        drawn = True
    if not drawn:
        return None
    ax.set_yscale("log")
    ax.set_xlabel("step")
    ax.set_ylabel("time per step [ms]")
    ax.set_title("Cost: wall-clock time of every step", fontsize=11)
    ax.grid(True, which="both", lw=0.5, alpha=0.5)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False, markerscale=6)
    out = Path(path)
    fig.savefig(out, dpi=_DPI, metadata={"Software": None}, pil_kwargs={"optimize": True})
    return out


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
dl dt { font-weight: 600; font-family: ui-monospace, Menlo, Consolas, monospace; }
dl dd { margin: 0 0 0.5em 1.5em; }
img { max-width: 100%; height: auto; border: 1px solid #eee; }
code, pre { font-family: ui-monospace, Menlo, Consolas, monospace; }
pre { background: #f7f7f7; padding: 0.8em; overflow-x: auto; font-size: 0.85em; }
.note { color: #555; font-size: 0.92em; }
"""


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


def write_report(
    out_dir: str | os.PathLike[str],
    metrics: dict,
    runs: list[EstimatorRun],
    reference: Reference,
    stamps_s: np.ndarray,
    *,
    truth_landmarks: dict | None = None,
    title: str = "fgslam: estimator comparison",
) -> Path:
    """Write ``trajectories.png``, ``position_error.png``, ``nees.png`` (with ground truth),
    ``step_time.png`` and ``report.html`` into ``out_dir``.

    Args:
        out_dir: directory to write into (created if missing; files are overwritten).
        metrics: the output of :func:`fgslam.compare.compute_metrics` for these runs.
        runs, reference: what the metrics were computed from (drawn in the figures).
        stamps_s: ``(n,)`` time stamp of each reference pose, seconds.
        truth_landmarks: optional true landmark map to draw as well (useful when the
            reference is the smoothed solution but a simulator knows the true map).
        title: page and figure title.

    Returns:
        The path of ``report.html``.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    traj_png = plot_trajectories(out / TRAJECTORIES_PNG, runs, reference, truth_landmarks=truth_landmarks,
                                 title=title)
    err_png = plot_position_errors(out / POSITION_ERROR_PNG, runs, reference, stamps_s)
    nees_png = plot_nees(out / NEES_PNG, runs, reference, stamps_s)
    time_png = plot_step_times(out / STEP_TIME_PNG, runs)
    nees_section = (
        f'<img src="{_data_uri(nees_png)}"\n alt="NEES of each estimator\'s online pose against time, '
        f'log scale, with the 95 % chi-square band">'
        if nees_png is not None
        else '<p class="note">No NEES: it needs the ground truth and an estimator that states a covariance.</p>'
    )
    time_section = (
        f'<img src="{_data_uri(time_png)}"\n alt="Wall-clock time of every step in milliseconds, log scale">'
        if time_png is not None
        else '<p class="note">No per-step times.</p>'
    )

    e = html.escape
    kind = metrics.get("reference")
    reference_text = REFERENCE_DESCRIPTIONS.get(kind, str(kind))
    shown, _, _ = table_rows(metrics)
    columns = "\n".join(f"<dt>{e(k)}</dt><dd>{e(v)}</dd>" for k, v in COLUMN_MEANINGS.items() if k in shown)
    metrics_json = json.dumps(metrics, indent=2)
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
<p><strong>Log:</strong> <code>{e(str(metrics.get("log")))}</code> ({e(str(metrics.get("poses")))} poses)</p>
<p><strong>Reference:</strong> {e(reference_text)}. Every figure below is measured against it.</p>

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

<h2>Trajectories and maps</h2>
<img src="{_data_uri(traj_png)}"
 alt="Final trajectories and landmark estimates of each estimator over the reference, x and y in metres">

<h2>Position error over time</h2>
<img src="{_data_uri(err_png)}"
 alt="Position error in metres against time since start in seconds, final solid and online dashed">

<h2>Consistency (NEES)</h2>
{nees_section}

<h2>Time per step</h2>
{time_section}

<h2>metrics.json</h2>
<pre>{e(metrics_json)}</pre>
</body>
</html>
"""
    html_path = out / REPORT_HTML
    html_path.write_text(page, encoding="utf-8")
    return html_path


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
    ax.axhline(3.0, color="0.6", ls=":", lw=0.8)
    ax.set_xlabel("step")
    ax.set_ylabel(f"average NEES over {len(result.runs)} runs")
    ax.set_title(f"{result.scenario}: NEES of the online pose (3 DoF)")
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
