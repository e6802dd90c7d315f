"""The per-run report: six figures and one self-contained HTML page.

This is the only package of the project that imports matplotlib. It uses matplotlib's
object-oriented API with the Agg canvas (``Figure`` + ``FigureCanvasAgg``) instead of
``pyplot``: no window can ever open, no global backend is switched under a user who imported
fgslam into a notebook, and figures are not kept in pyplot's registry (nothing to close —
they are freed when the function returns).

Its modules:

* :mod:`fgslam.report.page` — :func:`write_report`: every figure below and ``report.html``;
* :mod:`fgslam.report.trajectories` — the trajectories and maps over the reference;
* :mod:`fgslam.report.time_plots` — position and heading error, NEES, NIS and step time
  against time;
* :mod:`fgslam.report.style` — what every figure shares (canvas, colours, saving, baselines);
* :mod:`fgslam.report.report3d` — the top view and page of a 3-D log;
* :mod:`fgslam.report.live_map` — the map of ``fgslam live``;
* :mod:`fgslam.report.monte_carlo` — the figures of ``fgslam bench``.

Every public name is importable from ``fgslam.report`` itself, and so are the file names the
report writes (``TRAJECTORIES_PNG``, ..., ``REPORT_HTML``).

Dead reckoning (any name in ``baselines``) is a baseline, not a competitor: by default
(``baseline="fade"``) it is drawn faint and every axis is scaled to the other estimators, so
its drift (tens of metres on a large map) cannot hide their centimetres; ``"drop"`` leaves it
out of the figures, ``"show"`` draws it like the others. The table always has it.

What is drawn is what was measured: each estimate is moved by the same SE(2) alignment
:func:`fgslam.compare.compute_metrics` used (the identity when it shares its first pose
with the reference). Where the reference has no pose (gaps in the ground truth), the
reference line and every error curve break: those poses are not scored, so nothing is drawn
for them; the page says which reference was used and how many poses it covers.
"""

from fgslam.provenance import file_sha256, provenance
from fgslam.report.live_map import plot_live_map
from fgslam.report.monte_carlo import write_monte_carlo_figures
from fgslam.report.page import (
    HEADING_ERROR_PNG,
    NEES_PNG,
    NIS_PNG,
    POSITION_ERROR_PNG,
    REPORT_HTML,
    STEP_TIME_PNG,
    TRAJECTORIES_PNG,
    write_report,
)
from fgslam.report.report3d import TOP_VIEW_3D_PNG, plot_top_view_3d, write_report_3d
from fgslam.report.style import BASELINE_ESTIMATORS, BASELINE_MODES
from fgslam.report.time_plots import (
    plot_heading_errors,
    plot_nees,
    plot_nis,
    plot_position_errors,
    plot_step_times,
    truth_gaps_s,
)
from fgslam.report.trajectories import detail_pose, ellipse_xy, plot_trajectories, trajectory_figure, trajectory_view

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
    "TRAJECTORIES_PNG",
    "POSITION_ERROR_PNG",
    "HEADING_ERROR_PNG",
    "NEES_PNG",
    "NIS_PNG",
    "STEP_TIME_PNG",
    "REPORT_HTML",
    "TOP_VIEW_3D_PNG",
]
