"""A 3-D run log held as columns of numbers: what ``fgslam run`` holds of a stereo + IMU log
instead of its records (issue 43, part 5).

The 3-D counterpart of :mod:`slamio.log.columns`. :func:`~slamio.log.read_log` keeps every
record as an object: a ``stereo_observation`` costs ~500 B as a frozen dataclass, a drive of
40 features a step ~30 MB a thousand steps. :func:`read_columns3d` streams the file once
(:class:`~slamio.log.LogStream`: every line validated as :func:`~slamio.log.read_log` does,
with the same ``file:line`` errors), groups the records into steps as they come
(:func:`~slamio.log.records.iter_steps`) and keeps each step's numbers in typed arrays:
~64 B an observation and ~130 B a pose. The covariances a drive states are few (one for the
IMU and one pixel noise, :func:`fgslam.noise3d.noise_of` refuses more), so each distinct one
is kept once and the records point at it.

:class:`ColumnLog3d` answers what a run asks of a :class:`~slamio.log.RunLog` (``header``,
``steps()``, ``truth_landmarks()``, ``has_motion()``, ``truncated``, ``rejected``); it has no
``records``. Its steps (:class:`StepColumns3d`) are a sequence that builds each
:class:`~slamio.log.Step` when it is read, equal field by field (and in ``repr``) to the one
:func:`~slamio.log.group_steps` makes: the floats are stored as IEEE doubles, an absent
``sigma_px`` as NaN (a valid one is finite) and an absent pixel covariance as -1. Without
building the steps they also give every step's stamp, truth and the noise levels.

Only what a run uses is kept: ``live_step`` records are dropped, ``truth_landmark3`` records
kept as they are (one per landmark).
"""

from __future__ import annotations

import math
import os
from array import array
from dataclasses import dataclass
from typing import Callable, Sequence

from slamio.log.columns import ColumnLogMethods, StepSequence, records_kept
from slamio.log.read import LogStream
from slamio.log.records import Header, Record, Rejected, Step, iter_steps
from slamio.log.records3d import StereoObservation, TruthLandmark3, TruthPose3, VelocityOdometry

__all__ = ["ColumnLog3d", "StepColumns3d", "columns3d_of", "read_columns3d", "step_truths"]

#: A truth_pose3's fields, stored 8 per step (a NaN stamp: no truth at that step).
TRUTH3_FIELDS = ("stamp_s", "x_m", "y_m", "z_m", "qx", "qy", "qz", "qw")
PIXEL_FIELDS = ("u_left_px", "v_left_px", "u_right_px", "v_right_px")
_NONE = -1
_new = object.__new__


def _record(cls: type, values: dict):
    """A frozen record dataclass of ``values``, built as the reader's fast path builds it."""
    record = _new(cls)
    record.__dict__.update(values)
    return record


class _Distinct:
    """Each distinct nested tuple of floats once (told apart bit for bit: 0.0 is not -0.0),
    and the index of each."""

    def __init__(self) -> None:
        self.values: list[tuple] = []
        self._index: dict[bytes, int] = {}

    def index(self, matrix: tuple) -> int:
        key = array("d", [v for row in matrix for v in row]).tobytes()
        i = self._index.get(key)
        if i is None:
            i = self._index[key] = len(self.values)
            self.values.append(matrix)
        return i


class StepColumns3d(StepSequence):
    """The steps of a 3-D log as columns (:meth:`append` while reading), read back as
    :class:`~slamio.log.Step` objects built on demand (indexing, slicing, iterating)."""

    def __init__(self) -> None:
        self._stamps = array("d")
        self._dt = array("d")  # steps 1, 2, ... (step 0 has no odometry)
        self._twist = array("d")  # 6 per odometry: v_mps then w_radps
        self._twist_cov = array("q")  # per odometry: its covariance in self._twist_covariances
        self._twist_covariances = _Distinct()
        self._truth = array("d")  # 8 per step (TRUTH3_FIELDS); a NaN stamp: none
        self._obs_stamps = array("d")
        self._tracks = array("q")
        self._pixels = array("d")  # 4 per observation (PIXEL_FIELDS)
        self._sigma = array("d")  # NaN: the observation states a covariance instead
        self._pixel_cov = array("q")  # -1: none (sigma_px stated)
        self._pixel_covariances = _Distinct()
        self._first = array("q", [0])  # step i's observations are rows first[i]:first[i + 1]

    def append(self, step: Step) -> None:
        """Step ``len(self)`` (its odometry None exactly for step 0)."""
        if step.index != len(self) or (step.odometry is None) != (step.index == 0):
            raise ValueError(f"step {step.index} out of order (expected step {len(self)}, odometry from step 1 on)")
        self._stamps.append(step.stamp_s)
        odometry = step.odometry
        if odometry is not None:
            self._dt.append(odometry.dt_s)
            self._twist.extend(odometry.v_mps)
            self._twist.extend(odometry.w_radps)
            self._twist_cov.append(self._twist_covariances.index(odometry.covariance))
        truth = step.truth
        if truth is None:
            self._truth.extend([math.nan] * len(TRUTH3_FIELDS))
        else:
            self._truth.extend([getattr(truth, name) for name in TRUTH3_FIELDS])
        for o in step.observations:
            self._obs_stamps.append(o.stamp_s)
            self._tracks.append(o.track_id)
            self._pixels.extend((o.u_left_px, o.v_left_px, o.u_right_px, o.v_right_px))
            self._sigma.append(math.nan if o.sigma_px is None else o.sigma_px)
            self._pixel_cov.append(_NONE if o.covariance_px2 is None else self._pixel_covariances.index(o.covariance_px2))
        self._first.append(len(self._tracks))

    @property
    def observation_count(self) -> int:
        return len(self._tracks)

    def truths(self) -> list[TruthPose3 | None]:
        """Every step's ``truth_pose3`` (None where it has none), as the steps hold them."""
        return [self._truth_of(i) for i in range(len(self))]

    def noise_levels(self) -> tuple[set, set]:
        """``({(sigma_px, covariance_px2)}, {velocity covariance})``: the distinct pixel noises of
        the observations and covariances of the velocity records, as sets of the values the
        steps hold (what :func:`fgslam.noise3d.noise_of` collects from them)."""
        pixel_covariances = self._pixel_covariances.values
        pixels = {(None if s != s else s, None if c == _NONE else pixel_covariances[c])
                  for s, c in set(zip(self._sigma, self._pixel_cov))}
        twists = {self._twist_covariances.values[c] for c in set(self._twist_cov)}
        return pixels, twists

    def _step(self, i: int) -> Step:
        return Step(i, self._stamps[i], None if i == 0 else self._odometry_of(i - 1),
                    tuple(map(self._observation_of, range(self._first[i], self._first[i + 1]))), self._truth_of(i))

    def _odometry_of(self, k: int) -> VelocityOdometry:
        w, j = self._twist, 6 * k
        return _record(VelocityOdometry, {
            "stamp_s": self._stamps[k + 1], "dt_s": self._dt[k], "v_mps": (w[j], w[j + 1], w[j + 2]),
            "w_radps": (w[j + 3], w[j + 4], w[j + 5]), "covariance": self._twist_covariances.values[self._twist_cov[k]],
        })

    def _truth_of(self, i: int) -> TruthPose3 | None:
        j = 8 * i
        if self._truth[j] != self._truth[j]:
            return None
        return _record(TruthPose3, dict(zip(TRUTH3_FIELDS, self._truth[j:j + 8])))

    def _observation_of(self, j: int) -> StereoObservation:
        p, k, sigma, c = self._pixels, 4 * j, self._sigma[j], self._pixel_cov[j]
        return _record(StereoObservation, {
            "stamp_s": self._obs_stamps[j], "track_id": self._tracks[j], "u_left_px": p[k], "v_left_px": p[k + 1],
            "u_right_px": p[k + 2], "v_right_px": p[k + 3], "sigma_px": None if sigma != sigma else sigma,
            "covariance_px2": None if c == _NONE else self._pixel_covariances.values[c],
        })


@dataclass(frozen=True)
class ColumnLog3d(ColumnLogMethods):
    """A 3-D log read into columns (:func:`read_columns3d`): what a run needs of a
    :class:`~slamio.log.RunLog`, in memory that grows with its numbers."""

    path: str
    header: Header
    columns: StepColumns3d
    truth_landmark_records: tuple[TruthLandmark3, ...] = ()
    truncated: str | None = None
    rejected: tuple[Rejected, ...] = ()


def columns3d_of(stream: LogStream, visit: Callable[[Record], None] | None = None) -> ColumnLog3d:
    """The 3-D log ``stream`` (its header read, no record yet) read to its end into a
    :class:`ColumnLog3d`; ``visit`` sees every record kept, in file order (e.g. to count them).
    Raises :class:`~slamio.log.LogFormatError` at the first bad line, as the stream does."""
    if not stream.header.is_3d:
        raise ValueError(f"{stream.path} is a planar log; these columns hold a 3-D log's steps")
    rejected: list[Rejected] = []
    landmarks: list[Record] = []
    columns = StepColumns3d()
    for step in iter_steps(stream.header, records_kept(stream, visit, rejected, landmarks, (TruthLandmark3,))):
        columns.append(step)
    return ColumnLog3d(stream.path, stream.header, columns, tuple(landmarks), stream.truncated, tuple(rejected))


def read_columns3d(path: str | os.PathLike[str]) -> ColumnLog3d:
    """A 3-D run log read and validated into columns (:func:`columns3d_of`)."""
    return columns3d_of(LogStream(path))


def step_truths(steps: Sequence[Step]) -> list:
    """Every step's truth (None where it has none): from the columns when ``steps`` are
    :class:`StepColumns3d` (no observation built), else read off each step."""
    if isinstance(steps, StepColumns3d):
        return steps.truths()
    return [step.truth for step in steps]
