"""``python -m fgslam.cli ...`` is ``fgslam ...``."""

import sys

from fgslam.cli import main

sys.exit(main())
