"""The report of a 3-D log (``fgslam run`` on a seed-003 log, :mod:`fgslam.runner3d`): a top view
of every estimator's trajectory and landmarks, and a self-contained ``report.html``."""

from __future__ import annotations

import html
import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from fgslam.atomic import write_text_whole
from fgslam.report.page import _CSS, REPORT_HTML, _data_uri, _provenance_html
from fgslam.report.style import _landmark_array, _legend_and_save, _new_figure, _style

TOP_VIEW_3D_PNG = "top_view.png"  # 3-D logs (write_report_3d)


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
    body = "\n".join(
        "<tr>" + "".join(f"<td>{e(c)}</td>" for c in row) + "</tr>" if len(row) == len(table_header)
        # a failed estimator: its name and what stopped it
        else f'<tr class="failed"><td>{e(row[0])}</td><td colspan="{len(table_header) - 1}">{e(row[1])}</td></tr>'
        for row in table_rows
    )
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
with BLAS on one thread; "peak MB" how far the process's resident memory rose during the run
(megabytes, GTSAM's allocations included); - means not applicable.</p>

<h2 id="top-view">Top view</h2>
<img src="{_data_uri(png)}"
 alt="top view of every estimator's trajectory and landmarks over the reference">

<h2 id="metrics-json">metrics.json</h2>
<pre>{e(json.dumps(metrics, indent=2))}</pre>
</body>
</html>
"""
    return write_text_whole(out / REPORT_HTML, page)
