"""Writing a run log: one JSON object per line, floats that read back exactly."""

from __future__ import annotations

import json
import os
from typing import IO, Any, Iterable

from slamio.errors import FgslamError
from slamio.log.records import _TYPE_OF, FORMAT_NAME, UNITS, Header, Record
from slamio.log.records3d import TYPE_OF_3D

_ALWAYS_WRITTEN = {"landmark_id"}  # null means "unknown landmark", not "field absent"


def _drop_none(d: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in d.items() if v is not None or k in _ALWAYS_WRITTEN}


def header_to_dict(header: Header) -> dict[str, Any]:
    return {
        "type": "header",
        "format": FORMAT_NAME,
        "version": header.version,
        "units": dict(UNITS),
        "start": (
            {"stamp_s": header.stamp_s, "pose3": list(header.start_pose3), "sigma3": list(header.start_sigma3)}
            if header.is_3d
            else {"stamp_s": header.stamp_s, "pose": list(header.start_pose), "sigma": list(header.start_sigma)}
        ),
        "robot": header.robot,
        "sensor": header.sensor,
        "noise": header.noise,
        "source": header.source,
    }


def record_to_dict(record: Record) -> dict[str, Any]:
    kind = _TYPE_OF.get(type(record)) or TYPE_OF_3D[type(record)]
    out: dict[str, Any] = {"type": kind}
    for name in record.__dataclass_fields__:
        value = getattr(record, name)
        if name in ("covariance", "covariance_px2") and value is not None:
            value = [list(row) for row in value]
        elif isinstance(value, tuple):
            value = list(value)
        out[name] = value
    return _drop_none(out)


def format_line(obj: Header | Record) -> str:
    """One log line (without the newline). Floats are written so they read back exactly."""
    d = header_to_dict(obj) if isinstance(obj, Header) else record_to_dict(obj)
    try:
        return json.dumps(d, allow_nan=False, separators=(", ", ": "))
    except ValueError as exc:
        raise FgslamError(f"cannot write {d.get('type')} record {d!r}: {exc} (NaN or infinity)") from exc


class LogWriter:
    """Streams a log to a file: header first, then one record per line, flushed as written.

    Use as a context manager so a run that crashes still leaves every line it wrote::

        with LogWriter(path, header) as log:
            log.write(record)
    """

    def __init__(self, path: str | os.PathLike[str], header: Header):
        self.path = os.fspath(path)
        self._file: IO[str] = open(self.path, "w", encoding="utf-8")
        self._file.write(format_line(header) + "\n")

    def write(self, record: Record) -> None:
        self._file.write(format_line(record) + "\n")

    def flush(self) -> None:
        self._file.flush()

    def close(self) -> None:
        if not self._file.closed:
            self._file.close()

    def __enter__(self) -> "LogWriter":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def write_log(path: str | os.PathLike[str], header: Header, records: Iterable[Record]) -> None:
    with LogWriter(path, header) as log:
        for record in records:
            log.write(record)
