"""Ground truth in a simulated recording: ``fgslam record --port sim`` writes the simulated
Create's true pose beside its odometry.

A log recorded on the simulator has the truth at hand (the simulator moves the robot; the
encoders only count, with noise), and a log with truth can be scored (``fgslam run`` reports
the ATE) without a motion-capture system. :class:`TruthWriter` rides on the recorder as its
hooks (:class:`slamio.create.record.RecordHooks`), the way ``fgslam live --port sim`` writes
its truth (:class:`fgslam.live.loop.LiveLoop`): one ``truth_pose`` at stamp 0 when the log
opens (the true start pose), and one after each odometry record at that record's stamp, read
from the simulator just then. The truth is in the arena's frame, the frame of the log
header's ``start_pose`` (the simulator's start pose), so it compares with the estimates
without an alignment.

Other hooks (the camera :class:`fgslam.record_frames.FrameSaver` of ``--save-frames``) ride
inside it: they decide when a record is due and get every record after its truth is written,
so a simulated frame can be rendered at exactly the pose written as truth (:attr:`last_pose`).
The recorder's robot-stop behaviour is not touched: these hooks only write records.
"""

from __future__ import annotations

from typing import Callable, Sequence

from slamio.create.record_settings import SAME_TIME_S
from slamio.log import TruthLandmark, TruthPose

#: What the log header's ``source.truth`` says about the truth records of a simulated recording.
TRUTH_NOTE = ("truth_pose records: the simulated Create's true pose (x, y, heading in the arena frame of "
              "header.start_pose), one at stamp 0 and one after each odometry record at its stamp")


class TruthWriter:
    """Record hooks that write ``true_pose()`` as ``truth_pose`` records (see the module doc);
    ``inner`` (optional) are the hooks it hands on to; without them a record is due every
    ``record_period_s``, as the recorder's own schedule does. ``truth_landmarks`` are written
    once when the log opens (the simulated camera's tags, when its frames are saved)."""

    def __init__(self, true_pose: Callable[[], Sequence[float]], inner=None, record_period_s: float = 0.1,
                 truth_landmarks: Sequence[TruthLandmark] = ()):
        self.true_pose = true_pose
        self.inner = inner
        self.record_period_s = record_period_s
        self.truth_landmarks = tuple(truth_landmarks)
        self.written = 0  # truth_pose records written
        self.last_pose: tuple[float, float, float] | None = None
        self._last_record_s = 0.0

    def _write(self, log, stamp_s: float) -> None:
        x, y, theta = (float(v) for v in self.true_pose())
        self.last_pose = (x, y, theta)
        log.write(TruthPose(stamp_s, x, y, theta))
        self.written += 1

    def started(self, log) -> None:
        for landmark in self.truth_landmarks:
            log.write(landmark)
        self._write(log, 0.0)
        log.flush()
        if self.inner is not None and hasattr(self.inner, "started"):
            self.inner.started(log)

    def due(self, now_s: float) -> bool:
        if self.inner is not None:
            return self.inner.due(now_s)
        return now_s - self._last_record_s >= self.record_period_s - SAME_TIME_S

    def after_record(self, record, log) -> None:
        self._last_record_s = record.stamp_s
        self._write(log, record.stamp_s)
        log.flush()
        if self.inner is not None:
            self.inner.after_record(record, log)

    def passed(self) -> None:
        passed = getattr(self.inner, "passed", None)
        if passed is not None:
            passed()
