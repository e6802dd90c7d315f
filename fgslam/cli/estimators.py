"""What ``--estimators`` accepts, for the help texts: views of :mod:`fgslam.registry` (which
imports no estimator code)."""

from __future__ import annotations

from fgslam.registry import help_for

#: name -> one line of help, the estimators of a planar log.
ESTIMATOR_HELP = help_for(2)

#: The estimators of a 3-D log (seed 003: stereo camera + IMU).
ESTIMATOR_HELP_3D = help_for(3)
