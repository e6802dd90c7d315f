"""A planar run log held as columns of numbers: for a run whose memory grows with its
estimates, not with the log (issue 43).

:func:`~slamio.log.read_log` keeps every record as an object, ~700 B each (an 80 MB log:
~360 000 records, ~290 MB). :func:`read_columns` streams the file once
(:class:`~slamio.log.LogStream`: every line validated as :func:`~slamio.log.read_log` does,
with the same ``file:line`` errors), groups the records into steps as they come
(:func:`~slamio.log.records.iter_steps`, so a ``sensor.pose_on_robot`` is applied as
:func:`~slamio.log.group_steps` applies it) and keeps each step's numbers in typed arrays:
~90 B per observation and ~170 B per pose.

:class:`ColumnLog` answers what a run asks of a :class:`~slamio.log.RunLog` (``header``,
``steps()``, ``truth_landmarks()``, ``has_motion()``, ``truncated``, ``rejected``); it has no
``records``. Its steps (:class:`StepColumns`) are a sequence that builds each
:class:`~slamio.log.Step` when it is read and forgets it after, equal field by field to the
one :func:`~slamio.log.group_steps` makes: the floats are stored as IEEE doubles, an absent
optional value as NaN (no field of a valid record is NaN) or as -1 for an id (ids are ≥ 0).
So an estimator fed from it computes exactly what it computes from the records.

Only what a run uses is kept: ``live_step`` records (the live loop's timings) are dropped,
``truth_landmark`` and ``event`` records kept as they are (one per landmark, and few).
"""

from __future__ import annotations

import math
import os
from array import array
from dataclasses import dataclass
from typing import Callable, Iterator, Sequence, overload

import numpy as np

from slamio.log.read import LogStream
from slamio.log.records import (
    Event, Header, Observation, Odometry, Record, Rejected, Step, TruthLandmark, TruthPose, iter_steps,
    summarise_rejections,
)

__all__ = ["ColumnLog", "StepColumns", "columns_of", "read_columns", "step_stamps"]

#: An observation's float fields (NaN: None) and its id fields (-1: None), stored one column each.
OBSERVATION_FLOATS = ("stamp_s", "range_m", "bearing_rad", "sigma_range_m", "sigma_bearing_rad", "height_m",
                      "sigma_height_m", "tag_yaw_rad", "sigma_tag_yaw_rad")
OBSERVATION_IDS = ("landmark_id", "truth_landmark_id")
#: An odometry record's scalar fields besides its stamp (the step's); its covariance is 9 more.
ODOMETRY_FLOATS = ("dx_m", "dy_m", "dtheta_rad", "distance_m", "angle_rad")
TRUTH_FLOATS = ("stamp_s", "x_m", "y_m", "theta_rad")

_NONE_ID = -1
_new = object.__new__


def _stored(value: float | None) -> float:
    return math.nan if value is None else value


def _read(value: float) -> float | None:
    return None if value != value else value  # NaN: absent


def _record(cls: type, values: dict):
    """A frozen record dataclass of ``values``, built as the reader's fast path builds it."""
    record = _new(cls)
    record.__dict__.update(values)
    return record


class StepSequence(Sequence[Step]):
    """The steps of a log read into columns, built one at a time as they are asked for: what
    :class:`StepColumns` and :class:`~slamio.log.columns3d.StepColumns3d` share (each holds
    its steps' stamps in ``_stamps`` and builds step ``i`` in ``_step(i)``)."""

    _stamps: array

    def _step(self, i: int) -> Step:
        raise NotImplementedError

    def __len__(self) -> int:
        return len(self._stamps)

    @overload
    def __getitem__(self, i: int) -> Step: ...

    @overload
    def __getitem__(self, i: slice) -> list[Step]: ...

    def __getitem__(self, i):
        if isinstance(i, slice):
            return [self._step(k) for k in range(*i.indices(len(self)))]
        n = len(self)
        if not -n <= i < n:
            raise IndexError(f"step {i} of {n}")
        return self._step(i % n)

    def __iter__(self) -> Iterator[Step]:
        return map(self._step, range(len(self)))

    def stamps_s(self) -> np.ndarray:
        """Every step's stamp (s), shape (n,)."""
        return np.array(self._stamps, dtype=float)


class StepColumns(StepSequence):
    """The steps of a planar log as columns (:meth:`append` while reading), read back as
    :class:`~slamio.log.Step` objects built on demand (indexing, slicing, iterating)."""

    def __init__(self) -> None:
        self._stamps = array("d")
        self._odometry = {name: array("d") for name in ODOMETRY_FLOATS}  # steps 1, 2, ... (step 0 has none)
        self._covariance = array("d")  # 9 per odometry, row by row
        self._truth = {name: array("d") for name in TRUTH_FLOATS}  # NaN stamp: no truth at that step
        self._observation = {name: array("d") for name in OBSERVATION_FLOATS}
        self._ids = {name: array("q") for name in OBSERVATION_IDS}
        self._first = array("q", [0])  # step i's observations are rows first[i]:first[i + 1]

    def append(self, step: Step) -> None:
        """Step ``len(self)`` (its odometry None exactly for step 0)."""
        if step.index != len(self) or (step.odometry is None) != (step.index == 0):
            raise ValueError(f"step {step.index} out of order (expected step {len(self)}, odometry from step 1 on)")
        self._stamps.append(step.stamp_s)
        if step.odometry is not None:
            for name, column in self._odometry.items():
                column.append(_stored(getattr(step.odometry, name)))
            for row in step.odometry.covariance:
                self._covariance.extend(row)
        truth = step.truth
        for name, column in self._truth.items():
            column.append(math.nan if truth is None else _stored(getattr(truth, name)))
        for observation in step.observations:
            for name, column in self._observation.items():
                column.append(_stored(getattr(observation, name)))
            for name, column in self._ids.items():
                value = getattr(observation, name)
                column.append(_NONE_ID if value is None else value)
        self._first.append(len(self._observation["stamp_s"]))

    @property
    def observation_count(self) -> int:
        return len(self._observation["stamp_s"])

    def observations_per_step(self) -> np.ndarray:
        """``(n,)`` how many observations each step holds (without building the steps)."""
        return np.diff(np.asarray(self._first, dtype=np.int64))

    def truth_trajectory(self) -> tuple[np.ndarray, np.ndarray]:
        """``(trajectory (n, 3), has_pose (n,))`` of the steps' truth poses: NaN rows and False
        where a step has none, a NaN heading where the truth has none
        (:func:`fgslam.runner.truth_trajectory` of these steps)."""
        t = self._truth
        has_pose = ~np.isnan(np.array(t["stamp_s"], dtype=float))
        trajectory = np.column_stack([np.array(t[name], dtype=float) for name in ("x_m", "y_m", "theta_rad")])
        trajectory[~has_pose] = np.nan
        return trajectory, has_pose

    def _step(self, i: int) -> Step:
        return Step(i, self._stamps[i], None if i == 0 else self._odometry_of(i - 1),
                    tuple(map(self._observation_of, range(self._first[i], self._first[i + 1]))), self._truth_of(i))

    def _odometry_of(self, k: int) -> Odometry:
        c, o, j = self._covariance, self._odometry, 9 * k
        return _record(Odometry, {
            "stamp_s": self._stamps[k + 1], "dx_m": o["dx_m"][k], "dy_m": o["dy_m"][k],
            "dtheta_rad": o["dtheta_rad"][k],
            "covariance": ((c[j], c[j + 1], c[j + 2]), (c[j + 3], c[j + 4], c[j + 5]), (c[j + 6], c[j + 7], c[j + 8])),
            "distance_m": _read(o["distance_m"][k]), "angle_rad": _read(o["angle_rad"][k]),
        })

    def _truth_of(self, i: int) -> TruthPose | None:
        t = self._truth
        stamp = t["stamp_s"][i]
        if stamp != stamp:
            return None
        return _record(TruthPose, {"stamp_s": stamp, "x_m": t["x_m"][i], "y_m": t["y_m"][i],
                                   "theta_rad": _read(t["theta_rad"][i])})

    def _observation_of(self, j: int) -> Observation:
        values = {name: _read(column[j]) for name, column in self._observation.items()}
        for name, column in self._ids.items():
            value = column[j]
            values[name] = None if value == _NONE_ID else value
        return _record(Observation, values)


class ColumnLogMethods:
    """What :class:`ColumnLog` and :class:`~slamio.log.columns3d.ColumnLog3d` answer as a
    :class:`~slamio.log.RunLog` would, from their ``columns``, ``truth_landmark_records``,
    ``path`` and ``rejected``."""

    def steps(self):
        """The per-pose steps, as :meth:`slamio.log.RunLog.steps` groups them (built as read)."""
        return self.columns

    def has_motion(self) -> bool:
        return len(self.columns) > 1

    def truth_landmarks(self) -> dict:
        """landmark id → its truth landmark record."""
        return {r.landmark_id: r for r in self.truth_landmark_records}

    def rejection_summary(self) -> str | None:
        return summarise_rejections(self.path, self.rejected)


@dataclass(frozen=True)
class ColumnLog(ColumnLogMethods):
    """A planar log read into columns (:func:`read_columns`): what a run needs of a
    :class:`~slamio.log.RunLog`, in memory that grows with its numbers."""

    path: str
    header: Header
    columns: StepColumns
    truth_landmark_records: tuple[TruthLandmark, ...] = ()
    events: tuple[Event, ...] = ()
    truncated: str | None = None
    rejected: tuple[Rejected, ...] = ()


def step_stamps(steps: Sequence[Step]) -> np.ndarray:
    """Every step's stamp (s), shape (n,): from the columns when ``steps`` are
    :class:`StepColumns` or :class:`~slamio.log.columns3d.StepColumns3d` (no step built),
    else read off each step."""
    from slamio.log.columns3d import StepColumns3d

    if isinstance(steps, (StepColumns, StepColumns3d)):
        return steps.stamps_s()
    return np.array([step.stamp_s for step in steps], dtype=float)


def records_kept(stream: LogStream, visit: Callable[[Record], None] | None, rejected: list[Rejected],
                 kept: list[Record], keep: tuple[type, ...]) -> Iterator[Record]:
    """``stream``'s records for the steps: a rejected observation goes to ``rejected``
    instead; each other record is shown to ``visit`` and, when of a type in ``keep`` (what
    the steps do not carry: truth landmarks, events), also put in ``kept``."""
    for item in stream:
        if type(item) is Rejected:
            rejected.append(item)
            continue
        if visit is not None:
            visit(item)
        if type(item) in keep:
            kept.append(item)
        yield item


def columns_of(stream: LogStream, visit: Callable[[Record], None] | None = None) -> ColumnLog:
    """The planar log ``stream`` (its header read, no record yet) read to its end into a
    :class:`ColumnLog`; ``visit`` sees every record kept, in file order (e.g. to count them).
    Raises :class:`~slamio.log.LogFormatError` at the first bad line, as the stream does."""
    if stream.header.is_3d:
        raise ValueError(f"{stream.path} is a 3-D log; columns hold a planar log's steps")
    rejected: list[Rejected] = []
    kept: list[Record] = []
    columns = StepColumns()
    for step in iter_steps(stream.header, records_kept(stream, visit, rejected, kept, (TruthLandmark, Event))):
        columns.append(step)
    return ColumnLog(stream.path, stream.header, columns, tuple(r for r in kept if type(r) is TruthLandmark),
                     tuple(r for r in kept if type(r) is Event), stream.truncated, tuple(rejected))


def read_columns(path: str | os.PathLike[str]) -> ColumnLog:
    """A planar run log read and validated into columns (:func:`columns_of`)."""
    return columns_of(LogStream(path))
