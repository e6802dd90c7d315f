"""Comparison maths (being split into modules; see metrics.py)."""

from fgslam.compare.metrics import *  # noqa: F401,F403
from fgslam.compare.metrics import __all__  # noqa: F401
