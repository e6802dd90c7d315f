"""Peak memory of a piece of work, C++ allocations (GTSAM) included.

``tracemalloc`` sees only Python's and numpy's allocations, not GTSAM's, and slows every
allocation; so the peak is read from the kernel instead. On Linux the process's resident
high-water mark (``VmHWM`` in ``/proc/self/status``) can be reset by writing ``5`` to
``/proc/self/clear_refs``. :class:`PeakMemory` frees what it can first (``gc.collect()``
and glibc's ``malloc_trim(0)``, which hands freed heap back to the kernel so that earlier
work's leftovers are not reused unseen), resets the mark, notes the resident size, and at
the end reports how far above that baseline the process went.

It is a property of the whole process: run one estimator at a time. Elsewhere than Linux
(no ``clear_refs``) the result is None.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import gc

__all__ = ["PeakMemory", "release_free_memory", "resident_kib"]

_STATUS = "/proc/self/status"
_CLEAR_REFS = "/proc/self/clear_refs"


def _status_kib(field: str) -> int | None:
    try:
        with open(_STATUS, encoding="ascii") as f:
            for line in f:
                if line.startswith(field + ":"):
                    return int(line.split()[1])
    except OSError:
        return None
    return None


def resident_kib() -> int | None:
    """The process's resident set size now, KiB (None where /proc is missing)."""
    return _status_kib("VmRSS")


def release_free_memory() -> None:
    """Collect garbage and hand the heap's free memory back to the kernel (glibc's
    ``malloc_trim``): what a finished piece of work freed stops counting as resident."""
    gc.collect()
    name = ctypes.util.find_library("c")
    if name is None:
        return
    try:
        ctypes.CDLL(name).malloc_trim(0)
    except (OSError, AttributeError):  # not glibc
        pass


def _reset_high_water_mark() -> bool:
    try:
        with open(_CLEAR_REFS, "w", encoding="ascii") as f:
            f.write("5")
        return True
    except OSError:
        return False


class PeakMemory:
    """``with PeakMemory() as m: work()`` → ``m.peak_bytes``: the highest resident size
    during ``work`` above the resident size just before it, bytes (None if unmeasurable)."""

    def __init__(self) -> None:
        self.peak_bytes: int | None = None
        self._baseline_kib: int | None = None

    def __enter__(self) -> "PeakMemory":
        release_free_memory()
        if _reset_high_water_mark():
            self._baseline_kib = resident_kib()
        return self

    def __exit__(self, *exc) -> None:
        if self._baseline_kib is None:
            return
        high = _status_kib("VmHWM")
        if high is not None:
            self.peak_bytes = max(0, high - self._baseline_kib) * 1024
