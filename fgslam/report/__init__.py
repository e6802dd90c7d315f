"""The per-run report (being split into modules; see trajectories.py)."""

from fgslam.report.trajectories import *  # noqa: F401,F403
from fgslam.report.trajectories import __all__  # noqa: F401
from fgslam.report.trajectories import (  # noqa: F401
    HEADING_ERROR_PNG, NEES_PNG, NIS_PNG, POSITION_ERROR_PNG, REPORT_HTML, STEP_TIME_PNG, TOP_VIEW_3D_PNG,
    TRAJECTORIES_PNG,
)
