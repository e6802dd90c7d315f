"""slamio: the front-end and the data — run logs, the simulator, and (later) robot and camera I/O.

Named ``slamio`` rather than ``io``: a package called ``io`` cannot be imported, because the
standard library's ``io`` is loaded first.
"""

from slamio.errors import FgslamError

__all__ = ["FgslamError"]
