"""An estimator that stops mid-run: what is kept about it, and the one line that says so.

``fgslam run`` runs several estimators on the same log. When one of them raises part-way
(GTSAM's ``IndeterminateSystemException``, a singular innovation covariance in numpy, a pose
or covariance that is no longer a number), the others' results are still worth having. The
runners (:mod:`fgslam.runner`, :mod:`fgslam.runner3d`) turn the exception into an
:class:`EstimatorFailed` carrying an :class:`EstimatorFailure` — the estimator's name, the
step (0-based pose index of the log) and its time stamp, and a one-line reason — and
``fgslam run`` shows it as a row of the table, in the report, in ``metrics.json``
(``{"failed": {"step": N, "time_s": t, "reason": "..."}}``, no figures) and in its exit
status, :data:`FAILED_EXIT_STATUS`.

A caller that runs a single estimator (``fgslam check``, ``fgslam bench``) lets the
:class:`EstimatorFailed` propagate: it is an :class:`~slamio.errors.FgslamError`, so the
command line prints its one line instead of a traceback.

The log's line numbers are not kept by the reader, so a failure names its step and time
stamp, which locate it in the log as well (``grep`` the stamp).
"""

from __future__ import annotations

import contextlib
import re
from dataclasses import dataclass
from typing import Iterator, Sequence

import numpy as np

from slamio.errors import FgslamError

__all__ = ["EstimatorFailure", "EstimatorFailed", "NonFiniteEstimate", "StepWatch", "FAILED_EXIT_STATUS",
           "check_finite", "failed_cell", "reason_of", "with_failures"]

#: ``fgslam run``'s exit status when an estimator failed and the other estimators' results
#: were written (0: all ran; 1: a mistake in the command; 2: an input file cannot be used).
FAILED_EXIT_STATUS = 4

#: A reason longer than this is cut (one line of the table).
MAX_REASON = 160

#: What GTSAM's exceptions say (they reach Python as a plain RuntimeError) → its class name
#: and what usually causes it on fgslam's logs.
_GTSAM_ERRORS = (
    ("Indeterminant linear system", "IndeterminateSystemException",
     "an under-determined system: check the odometry, on a 3-D log the gyro sign"),
    ("Indeterminate linear system", "IndeterminateSystemException",
     "an under-determined system: check the odometry, on a 3-D log the gyro sign"),
)


@dataclass(frozen=True)
class EstimatorFailure:
    """Where and why one estimator stopped.

    ``phase`` is ``"step"`` (``step`` is the step it was consuming), ``"finish"`` (after the
    last step: ``finish()`` or reading the final estimate; ``step`` is the last step) or
    ``"batch"`` (the batch solve; no step).
    """

    name: str
    step: int | None
    time_s: float | None
    reason: str
    phase: str = "step"

    def as_dict(self) -> dict:
        """The ``"failed"`` entry of ``metrics.json``."""
        return {"step": self.step, "time_s": self.time_s, "reason": self.reason, "phase": self.phase}

    @classmethod
    def from_dict(cls, name: str, entry: dict) -> "EstimatorFailure":
        return cls(name, entry.get("step"), entry.get("time_s"), str(entry.get("reason")), entry.get("phase", "step"))

    def where(self) -> str:
        """``failed at step 529 (t = 52.90 s)``, ``failed in finish() after step 544 (t = ...)``
        (the last step) or ``failed`` (the batch solve)."""
        stamp = "" if self.time_s is None else f" (t = {self.time_s:.2f} s)"
        if self.phase == "batch":  # the name says it: "batch failed: ..."
            return "failed"
        if self.phase == "finish":
            return f"failed in finish() after step {self.step}{stamp}"
        return f"failed at step {self.step}{stamp}"

    def cell(self) -> str:
        """What the table's row says: ``failed at step 529 (t = 52.90 s): <reason>``."""
        return f"{self.where()}: {self.reason}"

    def sentence(self) -> str:
        """The estimator named: ``isam2-3d failed at step 529 (t = 52.90 s): <reason>``."""
        return f"{self.name} {self.cell()}"


class EstimatorFailed(FgslamError):
    """An estimator raised while it ran; :attr:`failure` says where and why."""

    def __init__(self, failure: EstimatorFailure):
        super().__init__(failure.sentence())
        self.failure = failure

    def __reduce__(self):  # pickled whole: fgslam bench runs estimators in worker processes
        return (EstimatorFailed, (self.failure,))


class NonFiniteEstimate(ArithmeticError):
    """An estimator's pose or covariance is no longer a number (:func:`check_finite`)."""


class StepWatch:
    """Where one estimator's run is, so that an exception can say where it failed.

    The runner sets :attr:`step` as it feeds each step and calls :meth:`finishing` before
    ``finish()``; inside :meth:`failures` any exception becomes :class:`EstimatorFailed`::

        watch = StepWatch(estimator.name, stamps_s)
        with watch.failures():
            for i, step in enumerate(steps):
                watch.step = i
                estimator.step(step)
            watch.finishing()
            estimator.finish()
    """

    def __init__(self, name: str, stamps_s: Sequence[float] | None = None):
        self.name = name
        self.stamps_s = stamps_s
        self.step = -1  # none fed yet
        self.phase = "step"

    def finishing(self) -> None:
        self.phase = "finish"

    def failure(self, error: BaseException) -> EstimatorFailure:
        step = self.step if self.step >= 0 else None
        time_s = None
        if step is not None and self.stamps_s is not None and step < len(self.stamps_s):
            time_s = float(self.stamps_s[step])
        return EstimatorFailure(self.name, step, time_s, reason_of(error), self.phase)

    @contextlib.contextmanager
    def failures(self) -> Iterator[None]:
        """Any exception inside (not KeyboardInterrupt) is raised again as :class:`EstimatorFailed`."""
        try:
            yield
        except EstimatorFailed:
            raise
        except Exception as error:
            raise EstimatorFailed(self.failure(error)) from error


def check_finite(pose, covariance=None) -> None:
    """Raise :class:`NonFiniteEstimate` when ``pose`` (or ``covariance``, when given) holds a
    NaN or an infinity: the estimator has diverged, and every later step would be noise."""
    pose = np.asarray(pose, dtype=float)
    if not np.all(np.isfinite(pose)):
        shown = np.array2string(pose.reshape(-1)[:6], precision=3, separator=", ")
        raise NonFiniteEstimate(f"its pose is not a number: {shown}")
    if covariance is not None and not np.all(np.isfinite(covariance)):
        bad = int(np.count_nonzero(~np.isfinite(covariance)))
        raise NonFiniteEstimate(f"its pose covariance is not a number ({bad} of {np.size(covariance)} entries NaN "
                                "or infinite)")


def reason_of(error: BaseException) -> str:
    """One short line saying what ``error`` was: its type and the first sentence of its message.

    GTSAM's exceptions reach Python as a bare ``RuntimeError`` with a paragraph of text; they
    are named by their GTSAM class, with the variable they name as a symbol (``l476``, not
    its 64-bit key) and what usually causes them."""
    text = _first_paragraph(str(error))
    if isinstance(error, NonFiniteEstimate):
        return f"non-finite estimate: {text}"
    for marker, gtsam_name, hint in _GTSAM_ERRORS:
        if isinstance(error, RuntimeError) and marker in text:
            return _cut(f"gtsam {gtsam_name}{_gtsam_message(text)}" + (f" ({hint})" if hint else ""))
    kind = type(error).__name__
    if type(error).__module__.startswith("numpy"):
        kind = f"numpy {kind}"
    return _cut(f"{kind}: {text}" if text else kind)


def _first_paragraph(text: str) -> str:
    """The message's lines up to its first blank line, joined into one."""
    lines = []
    for line in text.strip().splitlines():
        if not line.strip():
            break
        lines.append(line.strip())
    return " ".join(lines)


def _gtsam_message(text: str) -> str:
    """What follows the exception's name: `` near variable l476`` when GTSAM names the
    variable (``... near variable 7782220156096217564 (Symbol: l476).``), else ``: <its sentence>``."""
    found = re.search(r"\(Symbol: (\w+)\)", text) or re.search(r"near variable\s+(\w+)", text)
    return f" near variable {found.group(1)}" if found else f": {text.rstrip('.')}"


def _cut(text: str) -> str:
    return text if len(text) <= MAX_REASON else text[: MAX_REASON - 3] + "..."


def with_failures(metrics: dict, failures: Sequence[EstimatorFailure], order: Sequence[str]) -> dict:
    """``metrics`` (a run's ``metrics.json`` content, the estimator entries last) with a
    ``{"failed": ...}`` entry for each failed estimator, no figures for it, and the estimator
    entries in ``order`` (every estimator's name as asked for, ``batch`` included)."""
    if not failures:
        return metrics
    failed = {f.name: {"failed": f.as_dict()} for f in failures}
    out = {k: v for k, v in metrics.items() if k not in order}
    for name in order:
        if name in failed or name in metrics:
            out[name] = failed.get(name, metrics.get(name))
    return out


def failed_cell(name: str, entry: dict) -> str | None:
    """What a table row says for a metrics entry of a failed estimator (``{"failed": ...}``):
    ``failed at step N (t = ... s): <reason>``; None for an estimator that ran through."""
    failed = entry.get("failed")
    return None if not isinstance(failed, dict) else EstimatorFailure.from_dict(name, failed).cell()
