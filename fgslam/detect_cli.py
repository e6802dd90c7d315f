"""Kept for code that imports ``fgslam.detect_cli``: the verb lives in :mod:`fgslam.cli.detect`."""

from __future__ import annotations

from fgslam.cli.detect import (
    DEFAULT_MAX_POSE_GAP_S,
    DetectError,
    merge_observations,
    static_header,
)
from fgslam.cli.detect import add_parser as add_detect_parser
from fgslam.cli.detect import cmd_detect

__all__ = ["DEFAULT_MAX_POSE_GAP_S", "DetectError", "add_detect_parser", "cmd_detect", "merge_observations",
           "static_header"]
