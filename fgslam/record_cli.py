"""Kept for scripts and tests that start the recorder as ``python -m fgslam.record_cli``.

The verbs live in :mod:`fgslam.cli.record` and :mod:`fgslam.cli.calibrate`;
``python -m fgslam.record_cli record ...`` is ``fgslam record ...``.
"""

from __future__ import annotations

import sys

from fgslam.cli import main
from fgslam.cli.calibrate import add_parser as add_calibrate_parser
from fgslam.cli.calibrate import cmd_calibrate
from fgslam.cli.calibrate import noise_model_summary
from fgslam.cli.record import EXIT_INTERRUPTED, EXIT_STOPPED_EARLY
from fgslam.cli.record import add_parser as add_record_parser
from fgslam.cli.record import cmd_record

__all__ = ["add_record_parser", "add_calibrate_parser", "cmd_record", "cmd_calibrate", "main",
           "noise_model_summary", "EXIT_STOPPED_EARLY", "EXIT_INTERRUPTED"]

if __name__ == "__main__":
    sys.exit(main())
