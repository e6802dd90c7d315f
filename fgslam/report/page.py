"""The report page of ``fgslam run`` and the figures beside it.

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

The page carries the run's provenance near its top (:func:`provenance`): fgslam's version, the command
line, the date (UTC), the log's path and SHA-256, and the estimators.
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

from fgslam.atomic import write_text_whole
from fgslam.compare import COLUMN_MEANINGS, EstimatorRun, Reference, reference_description, table_rows
from fgslam.provenance import provenance
from fgslam.report.style import BASELINE_ESTIMATORS, BASELINE_MODES
from fgslam.report.time_plots import plot_heading_errors, plot_nees, plot_nis, plot_position_errors, plot_step_times
from fgslam.report.trajectories import plot_trajectories


TRAJECTORIES_PNG = "trajectories.png"
POSITION_ERROR_PNG = "position_error.png"
REPORT_HTML = "report.html"
NEES_PNG = "nees.png"
NIS_PNG = "nis.png"
HEADING_ERROR_PNG = "heading_error.png"
STEP_TIME_PNG = "step_time.png"


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
table.metrics tr.failed td { text-align: left; color: #a00000; }
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
        if len(row) < len(headers):  # a failed estimator: its name and what stopped it
            parts.append(f'<tr class="failed"><td>{e(row[0])}</td><td colspan="{len(headers) - 1}">'
                         f"{e(' '.join(row[1:]))}</td></tr>")
            continue
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


def _figures(out: Path, runs: list[EstimatorRun], reference: Reference, stamps_s: np.ndarray, *,
             truth_landmarks: dict | None, title: str, baseline: str, baselines) -> list[_Figure]:
    """Draw every figure of the report into ``out`` (see :func:`write_report`)."""
    styles = {"baseline": baseline, "baselines": baselines}
    return [
        _Figure("fig-trajectories", "Trajectories and maps", TRAJECTORIES_PNG,
                "every estimator's final trajectory and landmarks over the reference, with 95 % "
                "covariance ellipses (online poses, final landmarks): the whole map, zoomed to the "
                "estimators, and a detail where their error is largest",
                plot_trajectories(out / TRAJECTORIES_PNG, runs, reference, truth_landmarks=truth_landmarks,
                                  title=title, **styles), ""),
        _Figure("fig-position-error", "Position error over time", POSITION_ERROR_PNG,
                ("distance in metres to the smoothed reference (no ground truth: agreement, not accuracy) "
                 if reference.kind == "smoothed" else "position error in metres ")
                + "against time: final estimate solid, online dashed",
                plot_position_errors(out / POSITION_ERROR_PNG, runs, reference, stamps_s, **styles), ""),
        _Figure("fig-heading-error", "Heading error over time", HEADING_ERROR_PNG,
                ("heading difference in degrees from the smoothed reference " if reference.kind == "smoothed"
                 else "heading error in degrees ") + "against time: final estimate solid, online dashed",
                plot_heading_errors(out / HEADING_ERROR_PNG, runs, reference, stamps_s, **styles),
                "No heading error: the reference has no heading (a truth that measures position only, like GPS)."),
        _Figure("fig-nees", "Consistency: NEES", NEES_PNG,
                "NEES of the online pose against time with the 95 % chi-square(3) band "
                "(chi-square(2), position only, where the truth has no heading)",
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


def _page_html(title: str, metrics: dict, prov: dict, figures: list[_Figure], baseline_note: str) -> str:
    """``report.html``'s text: the metrics table, provenance and every figure embedded."""
    e = html.escape
    reference_text = reference_description(metrics)
    shown, _, _ = table_rows(metrics)
    columns = "\n".join(f"<dt>{e(k)}</dt><dd>{e(COLUMN_MEANINGS[k])}</dd>" for k in shown if k in COLUMN_MEANINGS)
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
{_verdict_html(metrics)}

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
<p class="note">{e(baseline_note)}Each figure is embedded in this page and also
written as a PNG next to it.</p>

{sections}

<h2 id="metrics-json">metrics.json</h2>
<pre>{e(metrics_json)}</pre>
</body>
</html>
"""
    return page


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
    figures = _figures(out, runs, reference, stamps_s, truth_landmarks=truth_landmarks, title=title,
                       baseline=baseline, baselines=baselines)
    page = _page_html(title, metrics, prov, figures, _baseline_note(runs, baseline, baselines))
    return write_text_whole(out / REPORT_HTML, page)


def _verdict_html(metrics: dict) -> str:
    """The noise verdict of ``metrics["noise_verdict"]`` (:mod:`fgslam.verdict`) as a short
    list; empty when the run has none (a 3-D run, or no batch solve)."""
    verdict = metrics.get("noise_verdict")
    if not isinstance(verdict, dict) or not verdict:
        return ""
    from fgslam.verdict import FITS

    e = html.escape
    items = []
    for group, v in verdict.items():
        ratio, factor = v.get("chi2_per_dof"), v.get("sigma_factor")
        if not isinstance(ratio, (int, float)) or not isinstance(factor, (int, float)) or factor <= 0:
            continue
        low, high = v.get("band95", [float("nan")] * 2)
        what = ("the stated noise fits" if v.get("fits") else
                f"the stated {group} sigma is ~{factor:.1f}x too small" if factor > 1 else
                f"the stated {group} sigma is ~{1 / factor:.1f}x too large")
        items.append(f"<li><strong>{e(group)}</strong>: chi2/dof {ratio:.2f} over {v.get('dof', 0):.0f} dof "
                     f"(95 % band {low:.2f}-{high:.2f}): {e(what)}</li>")
    source = metrics.get("noise_source")
    return (f"<h2>Noise verdict</h2>\n<p>Does the noise the log states fit its measurements? Per group, chi2/dof "
            f"of the batch solution: 1 when it fits; between {FITS[0]} and {FITS[1]} (sigma within a factor "
            f"1.4) is called a fit." + (f" The log's noise: {e(str(source))}." if source else "") + "</p>\n<ul>\n"
            + "\n".join(items) + "\n</ul>\n"
            + ("" if all(v.get("fits") for v in verdict.values()) else
               "<p class=\"note\">To fix it: <code>fgslam run LOG --noise self</code> (learn the noise from this "
               "log), or <code>fgslam calibrate LOG... --without-truth --out noise.json</code>.</p>\n"))
