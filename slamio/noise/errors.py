"""The one error class of :mod:`slamio.noise`.

:class:`NoiseModelError` is every noise problem a user can cause: a model that cannot be
used, logs that cannot support a fit (no truth, too little motion, a log that already
carries a fitted model), trials that cannot give a covariance, a model that cannot be
applied. :class:`NoiseModelFileError` is the same error when a *file* is to blame (a
noise-model JSON, a trials CSV, a calibration JSON): it is also an
:class:`slamio.errors.InputFileError`, so ``fgslam`` exits with status 2.
"""

from __future__ import annotations

from slamio.errors import FgslamError, InputFileError

__all__ = ["NoiseModelError", "NoiseModelFileError"]


class NoiseModelError(FgslamError):
    """A noise model, fit, trial calibration or application that cannot be made or used
    (names the field: ``field`` holds its keys, e.g. ``("odometry", "lag_s")``, when one
    field is to blame)."""

    def __init__(self, message: str, field: tuple = ()):
        super().__init__(message)
        self.field = field


class NoiseModelFileError(NoiseModelError, InputFileError):
    """A noise file that cannot be used (a noise model, a trials CSV, a trial calibration):
    ``file:line: ...`` naming the field where the format has them (exit status 2)."""
