"""Where a result comes from: versions, command line, date and the log's SHA-256.

Kept apart from :mod:`fgslam.report` so that ``fgslam run --no-report`` can write it to
``metrics.json`` without loading matplotlib.
"""

from __future__ import annotations

import hashlib
import os
import platform
import shlex
import sys
from collections.abc import Sequence
from datetime import datetime, timezone

__all__ = ["file_sha256", "provenance"]


def _package_version(name: str) -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version(name)
    except PackageNotFoundError:
        return "unknown"


def file_sha256(path: str | os.PathLike[str]) -> str:
    """The SHA-256 of a file's bytes, as lowercase hex (what ``sha256sum`` prints)."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def provenance(
    log_path: str | os.PathLike[str] | None,
    estimators,
    *,
    command: str | Sequence[str] | None = None,
    now: datetime | None = None,
) -> dict:
    """Where a report comes from: a JSON-ready dict for the page (and for ``metrics.json``).

    Keys: ``fgslam_version``, ``gtsam_version`` and ``python`` (the versions that ran),
    ``command`` (``command`` as given, a list joined with shell quoting; default
    ``sys.argv``, the command line of this process), ``date_utc`` (``now``, default the
    present, ISO 8601 to the second with ``Z``), ``log`` (the path as given),
    ``log_sha256`` and ``log_bytes`` (of the file's bytes; None when it cannot be read)
    and ``estimators`` (the names, in the order given).
    """
    if command is None:
        command = sys.argv
    if not isinstance(command, str):
        command = shlex.join(str(a) for a in command)
    when = (now or datetime.now(timezone.utc)).astimezone(timezone.utc)
    sha, size = None, None
    if log_path is not None:
        try:
            sha, size = file_sha256(log_path), os.path.getsize(log_path)
        except OSError:
            pass
    return {
        "fgslam_version": _package_version("fgslam"),
        "gtsam_version": _package_version("gtsam"),
        "python": platform.python_version(),
        "command": command,
        "date_utc": when.strftime("%Y-%m-%dT%H:%M:%SZ"),
        "log": None if log_path is None else str(log_path),
        "log_sha256": sha,
        "log_bytes": size,
        "estimators": [str(n) for n in estimators],
    }
