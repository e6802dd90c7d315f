"""The one exception base class of the project.

Every error a user can cause (a bad log line, an unknown scenario, a bad option) is an
``FgslamError``; the CLI prints its message and exits non-zero instead of a traceback.
"""


class FgslamError(Exception):
    """Base class of every error fgslam raises on purpose."""
