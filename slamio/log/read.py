"""Reading a run log: every line validated, the first bad one reported as ``file:line``
with how to fix it, everything good before it kept (:class:`LogFormatError`'s ``partial``).

The file is streamed (:class:`LogStream`, :func:`iter_log`): each record line goes
through the fast path (:mod:`slamio.log.fast`, msgspec into typed structs) and, only when
that does not accept it, through the slow path (:mod:`slamio.log.parse`, ``json.loads`` and
one check per field with its own message), so a bad line is reported exactly as before.

Two lines that contradict each other (a stamp earlier than the previous one, two different
truths of one landmark) are reported at the earlier of the two, naming both: either may be
the wrong one, so only the lines before it are known good.
"""

from __future__ import annotations

import collections
import gc
import itertools
import json
import math
import os
import sys
from typing import Any, Iterator

from slamio.errors import InputFileError, _os_error, _too_large, open_regular
from slamio.log.fast import FastDecoder
from slamio.log.fields import SENSOR_LIMIT_SIGMAS, _BadLine, _NotJson, _reject_constant, _show
from slamio.log.parse import (  # noqa: F401  (the slow path, also imported from here)
    _sensor_limit, check_records, parse_header, parse_record, sensor_range_limits,
)
from slamio.log.records import (
    _PLANAR_TYPES, _TYPES_3D, Event, Header, Observation, Odometry, Record, Rejected, RunLog, TruthLandmark,
)
import slamio.log.records3d as log3d

#: The largest run log :func:`read_log` reads (it keeps every record): 1 GiB, about five
#: million records — more than a day of a robot's odometry at 50 Hz. Split a longer
#: recording. :func:`iter_log` (``fgslam validate``) streams a log of any size.
MAX_LOG_BYTES = 2**30
#: The longest line read (bytes): a record is a few hundred bytes and a header a few
#: kilobytes; a longer line is no run log's, and is refused before it is held in memory.
MAX_LINE_BYTES = 2**24


class LogFormatError(InputFileError):
    """A run log that cannot be read past some line.

    ``line`` is the first line that may be wrong: the bad line, or the earlier of two lines
    that contradict each other (the message names both). ``partial`` is the :class:`RunLog`
    of everything before it (``None`` when that is the header), so a caller can still use the
    good part.
    """

    def __init__(self, path: str, line: int, message: str, partial: "RunLog | None" = None):
        super().__init__(f"{path}:{line}: {message}")
        self.path = path
        self.line = line
        self.partial = partial

def _outside_sensor(obs: Observation, low: float | None, high: float | None) -> tuple[str, str] | None:
    """(reason, message) when the sensor cannot have measured ``obs.range_m``, else None."""
    slack = SENSOR_LIMIT_SIGMAS * obs.sigma_range_m
    if low is not None and obs.range_m < low - min(slack, 0.5 * low):
        return (
            "with range_m below the sensor's min_range_m",
            f"range_m {obs.range_m!r} is below the header's sensor.min_range_m {low!r} by more than "
            f"{SENSOR_LIMIT_SIGMAS:g} σ ({obs.sigma_range_m!r} m) or half the minimum: the sensor cannot have "
            "measured it; the observation is left out (fix the front-end, or the header's limit if it is wrong)",
        )
    if high is not None and obs.range_m > high + slack:
        return (
            "with range_m above the sensor's max_range_m",
            f"range_m {obs.range_m!r} is above the header's sensor.max_range_m {high!r} by more than "
            f"{SENSOR_LIMIT_SIGMAS:g} σ ({obs.sigma_range_m!r} m): the sensor cannot have measured it; "
            "the observation is left out (fix the front-end, or the header's limit if it is wrong)",
        )
    return None


def _decode(raw: bytes, number: int) -> str:
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        message = (
            f"not UTF-8 text: byte 0x{raw[exc.start]:02x} at column {exc.start + 1} ({exc.reason}); "
            "a run log is UTF-8 — was the file damaged, or is this not a run log?"
        )
        try:  # complete JSON apart from the bad byte: an error, never a cut-off line
            json.loads(raw.decode("utf-8", errors="replace"))
        except (ValueError, RecursionError):
            raise _NotJson(message) from None
        raise _BadLine(message) from None
    if number == 1 and text.startswith("\ufeff"):
        raise _BadLine("the file starts with a byte-order mark (BOM); save it as UTF-8 without BOM")
    return text


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict:
    """A JSON object as a dict, refusing a key given twice (plain ``json`` keeps the last one
    without a word, so a record could silently say something other than what was written)."""
    d = dict(pairs)
    if len(d) != len(pairs):
        seen: set[str] = set()
        twice = next(k for k, _ in pairs if k in seen or seen.add(k))
        raise _BadLine(f"field {twice!r} is given twice in one object; keep the one that is right and delete the other")
    return d


def _loads(text: str) -> dict:
    if not text.strip():
        raise _NotJson("empty line; remove it (every line must be one JSON object)")
    try:
        d = json.loads(text, parse_constant=_reject_constant, object_pairs_hook=_unique_keys)
    except json.JSONDecodeError as exc:
        raise _NotJson(
            f"not valid JSON ({exc.msg} at column {exc.colno}); each line must be one JSON object"
        ) from None
    except RecursionError:
        raise _BadLine(
            "JSON nested too deeply to read (arrays or objects inside each other about a thousand levels "
            "deep); no field of a run log nests like that — is the line corrupted?"
        ) from None
    except ValueError as exc:
        if "digits" not in str(exc):
            raise _BadLine(f"not valid JSON ({exc}); each line must be one JSON object") from None
        raise _BadLine(  # Python's limit on the digits of an integer
            f"an integer with more than {sys.get_int_max_str_digits()} digits, more than Python reads; "
            "no field of a run log needs one — is the line corrupted?"
        ) from None
    if not isinstance(d, dict):
        raise _BadLine("each line must be one JSON object {...}")
    return d


def _check_dimension(kind: Any, header: Header) -> None:
    """Planar records only in a planar log, 3-D records only in a 3-D log."""
    if header.is_3d and kind in _PLANAR_TYPES and kind not in _TYPES_3D:
        raise _BadLine(
            f"a {kind} record in a 3-D log (the header has start.pose3); a 3-D log holds "
            f"{', '.join(_TYPES_3D)}"
        )
    if not header.is_3d and kind in _TYPES_3D and kind not in _PLANAR_TYPES:
        raise _BadLine(
            f"a {kind} record in a planar log; 3-D records need a version-2 header with start.pose3 "
            "and a stereo sensor (docs/log-format.md, \"3-D logs\")"
        )


class _Conflict(_BadLine):
    """Internal: this line contradicts an earlier one, and either may be wrong; the error is
    reported at ``line`` (the earlier one) with the ``records``/``rejected`` counts read
    before it."""

    def __init__(self, message: str, line: int, records: int, rejected: int):
        super().__init__(message)
        self.line, self.records, self.rejected = line, records, rejected


#: Record types that give the truth of one landmark: one record per ``landmark_id``.
_TRUTH_LANDMARK_TYPES = {TruthLandmark: "truth_landmark", log3d.TruthLandmark3: "truth_landmark3"}


def _landmark_conflict(kind: str, earlier: tuple[int, Record, int, int], number: int, record: Record) -> _BadLine:
    """The error for a second ``kind`` record of one landmark id, on line ``number``.

    An exact repeat is reported at the repeat (the first is good); a different truth at the
    first definition, since either line may be the wrong one.
    """
    line, first, n_records, n_rejected = earlier
    lid = record.landmark_id  # type: ignore[union-attr]
    if record == first:
        return _BadLine(
            f"line {number} repeats line {line}'s {kind} of landmark_id {lid} exactly; each landmark's truth "
            f"is given once: delete line {number}"
        )
    shown = [  # the position, and whatever else differs
        f for f in record.__dataclass_fields__
        if f in ("x_m", "y_m", "z_m") or (f != "landmark_id" and getattr(first, f) != getattr(record, f))
    ]

    def values(r: Record) -> str:
        return ", ".join(f"{f} {_show(getattr(r, f))}" for f in shown)

    return _Conflict(
        f"landmark_id {lid} has two {kind} records: line {line} gives {values(first)}, line {number} gives "
        f"{values(record)}; a landmark has one true place, so one of them is wrong (the map error would be "
        "measured against the last one): fix its landmark_id (one record per landmark) or delete it",
        line, n_records, n_rejected,
    )


#: How far a velocity record's ``dt_s`` may differ from the time since the previous pose (s).
DT_TOLERANCE_S = 1e-6


def _check_interval(record: Record, pose_stamp: float) -> float:
    """A 3-D log's velocity record spans the time since the previous pose; the latest pose's stamp."""
    if not isinstance(record, log3d.VelocityOdometry):
        return pose_stamp
    gap = record.stamp_s - pose_stamp
    if abs(record.dt_s - gap) > DT_TOLERANCE_S + 1e-15 * abs(record.stamp_s):  # + the stamps' rounding
        raise _BadLine(
            f"field 'dt_s' is {record.dt_s!r} s but the previous pose is {gap!r} s earlier: the velocity is "
            "held from the previous pose to this one, so dt_s must be the difference of their stamps"
        )
    return record.stamp_s

#: How much of a log is read at once (bytes); its lines are split in one call.
CHUNK_BYTES = 2**20


def _raw_lines(path: str, limit: int | None, chunk_bytes: int = CHUNK_BYTES) -> Iterator[tuple[list[bytes], bool]]:
    """The lines of the regular file at ``path`` (:func:`~slamio.errors.open_regular`: never a
    FIFO or a device), read ``chunk_bytes`` at a time: lists of lines without their ``\\n``,
    each list with whether a newline ended its lines (only the file's last line may lack one);
    at most ``limit`` bytes in all and :data:`MAX_LINE_BYTES` in one line (its newline
    included), else one :class:`InputFileError` after the lines before it."""
    fd = open_regular(path, "run log")
    with os.fdopen(fd, "rb", buffering=0) as f:
        size = os.fstat(fd).st_size
        if limit is not None and size > limit:
            raise _too_large(path, "run log", size, limit, InputFileError)
        done, number, head = 0, 0, b""  # bytes and lines yielded; the start of a line not ended yet
        while True:
            try:
                chunk = f.read(chunk_bytes)
            except OSError as exc:
                raise _os_error(path, "run log", exc, InputFileError) from None
            if not chunk:
                break
            lines = (head + chunk).split(b"\n") if head else chunk.split(b"\n")
            head = lines.pop()
            if lines:
                nbytes = sum(map(len, lines)) + len(lines)  # with their newlines
                if (limit is not None and done + nbytes > limit) or max(map(len, lines)) >= MAX_LINE_BYTES:
                    yield from _up_to_refused(path, lines, True, number, done, limit)
                yield lines, True
                done, number = done + nbytes, number + len(lines)
            if len(head) > MAX_LINE_BYTES or (limit is not None and done + len(head) > limit):
                yield from _up_to_refused(path, [head], False, number, done, limit)
        if head:
            yield [head], False


def _up_to_refused(path: str, lines: list[bytes], ended: bool, number: int, done: int,
                   limit: int | None) -> Iterator[tuple[list[bytes], bool]]:
    """The lines before the first of ``lines`` that is too long or crosses ``limit`` (the file
    grew while it was read), then its error; ``number`` lines and ``done`` bytes came before."""
    for i, line in enumerate(lines):
        done += len(line) + ended
        if (limit is not None and done > limit) or len(line) + ended > MAX_LINE_BYTES:
            if i:
                yield lines[:i], ended
            if limit is not None and done > limit:
                raise _too_large(path, "run log", None, limit, InputFileError)
            raise LogFormatError(path, number + i + 1, f"the line is longer than {MAX_LINE_BYTES // 2**20} MiB; no "
                                 "line of a run log is that long (a record is a few hundred bytes): is this a run log?")
    raise AssertionError("no line refused")  # pragma: no cover


def _without_cr(raw: bytes) -> bytes:
    """A line without the ``\\r`` of a ``\\r\\n`` ending."""
    return raw[:-1] if raw.endswith(b"\r") else raw


class LogStream:
    """A run log read and validated as it is iterated (see :func:`read_log` for the rules).

    The header is read when the stream is made (:attr:`header`); iterating yields each
    record, or a :class:`Rejected` for an observation the sensor cannot have made, in file
    order, and then sets :attr:`truncated` when the last line was cut off. The first bad line
    raises :class:`LogFormatError`; with ``keep`` the stream also keeps what it yielded (the
    error's ``partial`` then holds it, else only the header). ``limit`` caps the bytes read.
    """

    def __init__(self, path: str | os.PathLike[str], *, keep: bool = False, limit: int | None = None) -> None:
        self.path = os.fspath(path)
        self.truncated: str | None = None
        self.state = _ReadState(self.path, keep)
        self._lines = _raw_lines(self.path, limit)
        first = next(self._lines, None)
        if first is None:
            raise LogFormatError(self.path, 1, "the file is empty; a run log starts with a header line")
        lines, ended = first
        self._after_header = (lines[1:], ended)
        try:
            self.state.take(1, _loads(_decode(_without_cr(lines[0]), 1)))
        except _BadLine as bad:
            raise self.state.error(1, bad) from None

    @property
    def header(self) -> Header:
        assert self.state.header is not None
        return self.state.header

    def __iter__(self) -> Iterator[Record | Rejected]:
        state, fast = self.state, FastDecoder(self.header.is_3d).record
        add, number = state.add, 1
        after_header, self._after_header = self._after_header, ([], True)
        for lines, ended in itertools.chain((after_header,), self._lines):
            for raw in lines:
                number += 1
                record = fast(raw)
                try:
                    item = add(number, record) if record is not None else self._slow(number, raw, ended)
                except _BadLine as bad:
                    raise state.error(number, bad) from None
                if item is None:
                    return
                yield item

    def close(self) -> None:
        """Stop reading: the file is closed (iterating yields nothing more)."""
        self._after_header = ([], True)
        self._lines.close()

    def _slow(self, number: int, raw: bytes, ended: bool) -> Record | Rejected | None:
        """Line ``number`` (without its newline; ``ended``: it had one) through the slow path; None
        for a cut-off last line (noted in :attr:`truncated`)."""
        try:
            return self.state.take(number, _loads(_decode(_without_cr(raw), number)))
        except _NotJson:
            if ended:
                raise
        self.truncated = (
            f"{self.path}:{number}: the last line is cut off (recording interrupted?); "
            f"using the {number - 1} complete lines before it"
        )
        return None


def iter_log(path: str | os.PathLike[str]) -> LogStream:
    """A run log streamed: :class:`LogStream` (header, then records as they are validated),
    in memory that does not grow with the log — for reading logs of any size."""
    return LogStream(path)


def read_log(path: str | os.PathLike[str]) -> RunLog:
    """Read and validate a run log.

    The path must be a regular file of at most :data:`MAX_LOG_BYTES` (a FIFO, a device such
    as ``/dev/zero`` or a loop of symbolic links is one :class:`InputFileError` line, never
    a wait or a read without end: :mod:`slamio.safe_input`).

    Raises :class:`LogFormatError` at the first bad line, carrying the records before it
    in ``partial``. A last line without a newline that is not valid JSON (a recording cut
    off mid-line) is dropped and reported in :attr:`RunLog.truncated` instead; a complete
    JSON object on that line is checked like any other. Observations the header's sensor
    cannot have made (range outside its limits by more than :data:`SENSOR_LIMIT_SIGMAS` σ,
    or below half its minimum) are left out of the records and listed in
    :attr:`RunLog.rejected`.

    Stamps must not decrease, and each landmark has at most one ``truth_landmark`` (3-D:
    ``truth_landmark3``). When two lines contradict each other (a stamp earlier than the
    previous stamp; two different truths of one landmark id) the error is at the earlier
    line and names both, and ``partial`` holds only what precedes it; an exact repeat of a
    truth is an error at the repeat.
    """
    stream = LogStream(path, keep=True, limit=MAX_LOG_BYTES)
    collecting = gc.isenabled()
    gc.disable()  # the records hold no cycles; tracing the growing list again and again took ~20 % of the read
    try:
        collections.deque(stream, maxlen=0)  # read to the end; the state keeps the records
    finally:
        if collecting:
            gc.enable()
    state = stream.state
    return RunLog(stream.path, stream.header, tuple(state.records), stream.truncated, tuple(state.rejected))


class _ReadState:
    """What the reader knows after each line: the header, the records and rejections so far
    (kept only with ``keep``; counted always), and what the next lines are checked against
    (the last stamp, the latest pose's stamp, the truths of landmarks seen)."""

    def __init__(self, path: str, keep: bool) -> None:
        self.path, self.keep = path, keep
        self.header: Header | None = None
        self.is_3d = False
        self.records: list[Record] = []
        self.rejected: list[Rejected] = []
        self.n_records = self.n_rejected = 0
        self.limits: tuple[float | None, float | None] = (None, None)
        self.last_stamp = -math.inf
        self.pose = 0  # the latest pose of a planar log: odometry records so far (an event's pose_index)
        self.pose_stamp = -math.inf  # stamp of the latest pose (3-D logs: velocity_odometry.dt_s must span from it)
        self.stamp_at = (1, 0, 0)  # last_stamp's (line, records and rejections before it); line 1: the header's
        self.truth_at: dict[int, tuple[int, Record, int, int]] = {}  # landmark id -> (line, record, records, rejections)

    def take(self, number: int, d: dict) -> Record | Rejected | None:
        """Line ``number`` (parsed JSON ``d``): the header (None), or one record checked against the lines before."""
        if self.header is None:
            self.header = parse_header(d)
            self.is_3d = self.header.is_3d
            self.limits = sensor_range_limits(self.header)
            self.last_stamp = self.pose_stamp = self.header.stamp_s
            return None
        if d.get("type") == "header":
            raise _BadLine("a second header; a log holds one run — split the file")
        _check_dimension(d.get("type"), self.header)
        return self.add(number, parse_record(d))

    def add(self, number: int, record: Record) -> Record | Rejected:
        """The valid ``record`` of line ``number``, checked against the lines before it."""
        stamp = getattr(record, "stamp_s", None)
        if stamp is not None:
            if stamp < self.last_stamp:
                raise self._stamp_conflict(number, stamp)
            self.last_stamp, self.stamp_at = stamp, (number, self.n_records, self.n_rejected)
        kind = _TRUTH_LANDMARK_TYPES.get(type(record))
        if kind is not None:
            lid = record.landmark_id
            if lid in self.truth_at:
                raise _landmark_conflict(kind, self.truth_at[lid], number, record)
            self.truth_at[lid] = (number, record, self.n_records, self.n_rejected)
        cls = type(record)
        if self.is_3d:
            self.pose_stamp = _check_interval(record, self.pose_stamp)
        elif cls is Odometry:
            self.pose += 1
        elif cls is Event and record.pose_index != self.pose:
            raise _BadLine(
                f"field 'pose_index' is {record.pose_index} but {self.pose} odometry record"
                f"{' comes' if self.pose == 1 else 's come'} before this line: an event belongs to the latest pose, "
                f"the number of odometry records before it; write {self.pose} (or move the line)"
            )
        elif cls is Observation and self.limits != (None, None):
            outside = _outside_sensor(record, *self.limits)
            if outside is not None:
                reason, message = outside
                rejected = Rejected(number, reason, f"{self.path}:{number}: {message}", record)
                self.n_rejected += 1
                if self.keep:
                    self.rejected.append(rejected)
                return rejected
        self.n_records += 1
        if self.keep:
            self.records.append(record)
        return record

    def _stamp_conflict(self, number: int, stamp: float) -> _BadLine:
        """Stamps must not decrease: the conflict is reported at the earlier line."""
        return _Conflict(
            f"line {number}'s stamp_s {stamp!r} is earlier than "
            + (f"line {self.stamp_at[0]}'s {self.last_stamp!r}" if self.stamp_at[0] > 1
               else f"the header's start.stamp_s {self.last_stamp!r} (line 1)")
            + ": one of them is wrong; records must be written in time order (fix the wrong stamp "
            "or delete its line)",
            *self.stamp_at,
        )

    def error(self, number: int, bad: _BadLine) -> LogFormatError:
        """The :class:`LogFormatError` of a bad line, carrying what precedes the line it is reported at
        (streamed without ``keep``: the header alone)."""
        line, kept, kept_rejected = number, self.n_records, self.n_rejected
        if isinstance(bad, _Conflict):  # reported at the earlier line: only what precedes it is known good
            line, kept, kept_rejected = bad.line, bad.records, bad.rejected
        partial = (
            None if self.header is None or line == 1
            else RunLog(self.path, self.header, tuple(self.records[:kept]), None, tuple(self.rejected[:kept_rejected]))
        )
        return LogFormatError(self.path, line, str(bad), partial)
