"""The hooks the recorder's control loop calls (:class:`LiveLoop`): a pose per odometry record,
a frame asked for it, its observations written, the pose handed to the smoother; and the
newest frame of a live camera (:class:`LatestFrame`)."""

from __future__ import annotations

import dataclasses
import threading
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from fgslam.live.steering import LiveSettings, PoseTracker
from fgslam.live.workers import CameraWorker, ControlHold, Lockstep, SmootherWorker
from slamio.create.record_settings import SAME_TIME_S
from slamio.errors import FgslamError
from slamio.log import LiveStep, LogWriter, Observation, Odometry, Step, TruthLandmark, TruthPose


@dataclass
class LiveResult:
    """What a live run did (the recorder's result plus the live loop's counts)."""

    record: object  # slamio.create.record_settings.RecordResult
    final_pose: tuple[float, float, float]  # iSAM2's estimate of the last pose, after finish()
    poses: int
    frames_requested: int
    frames_used: int
    frames_skipped: int  # the camera was still busy when a pose was made
    frames_dropped: int  # a frame took longer than frame_timeout_s
    observations: int
    latencies_s: np.ndarray  # wall time of every smoother step
    frame_seconds: np.ndarray  # wall time of every frame (grab + detection)
    landmarks: dict[int, tuple[float, float]] = field(default_factory=dict)
    navigator_step_s: np.ndarray = field(default_factory=lambda: np.zeros(0))  # CPU of each navigator step

    @property
    def completed(self) -> bool:
        return self.record.completed  # type: ignore[attr-defined]


class LiveLoop:
    """The hooks the recorder calls (:class:`slamio.create.record.RecordHooks`).

    ``grab_for(index, odometry, true_pose=None)`` returns the zero-argument frame grabber for
    the pose being made (for the simulator: a render at ``true_pose``, the truth just written
    for it); ``truth`` (simulation only) gives the true pose, written as a ``truth_pose`` record.
    """

    def __init__(self, tracker: PoseTracker, camera: CameraWorker | None, smoother: SmootherWorker,
                 grab_for: Callable[[int, Odometry], Callable[[], object]] | None,
                 settings: LiveSettings = LiveSettings(), truth: Callable[[], tuple[float, float, float]] | None = None,
                 truth_landmarks: Sequence[TruthLandmark] = (), lockstep: Lockstep | None = None,
                 until: Callable[[float], bool | str] | None = None,
                 on_observations: Callable[[Sequence[Observation]], None] | None = None):
        self.tracker = tracker
        self.until = until
        self.on_observations = on_observations
        self.controller = None  # what drives (set by run_live): the status line shows a navigator's state
        self._control = ControlHold(lockstep) if lockstep is not None else None
        self.camera = camera
        self.smoother = smoother
        self.grab_for = grab_for
        self.s = settings
        self.truth = truth
        self.truth_landmarks = tuple(truth_landmarks)
        self._log: LogWriter | None = None
        self._index = 0
        self._last_record_s = 0.0
        self._last_stamp_s = 0.0
        self._pending: tuple[int, Odometry, float] | None = None  # (pose, record, asked at)
        self.frames_requested = self.frames_used = self.frames_skipped = self.frames_dropped = 0
        self.observations = 0

    # -- the recorder's hooks

    def started(self, log: LogWriter) -> None:
        """The log is open: the true start pose (simulation), so every pose has a truth."""
        self._log = log
        for landmark in self.truth_landmarks:
            log.write(landmark)
        if self.truth is not None:
            log.write(TruthPose(0.0, *self.truth()))
        log.flush()

    def passed(self) -> None:
        """A pass of the recorder's loop is over: its command and records went out (lockstep:
        the robot may take its next step)."""
        if self._control is not None:
            self._control.passed()

    def due(self, now_s: float) -> bool:
        for worker in (self.camera, self.smoother):
            if worker is not None and worker.error is not None:
                raise FgslamError(f"live loop: {type(worker.error).__name__}: {worker.error}") from worker.error
        self.smoother.publish()
        if self._pending is not None:
            index, odometry, asked = self._pending
            result = self.camera.result() if self.camera is not None else None
            if result is not None:
                got, observations = result
                if got == index:
                    self._write_observations(observations)
                    self.frames_used += 1
                    self._finish_pose(index, odometry, tuple(observations))
                else:  # a late answer to a frame already given up
                    return False
            elif now_s - asked > self.s.frame_timeout_s:
                self._drop_pending()
            else:
                return False
        return now_s - self._last_record_s >= self.s.record_period_s - SAME_TIME_S

    def finished(self, now_s: float) -> bool | str:
        """The recorder's question after each pass: is the run over? (``until``: e.g. enough
        landmarks seen; a string says why.) Ending is the recorder's, with the robot stopped."""
        return self.until(now_s) if self.until is not None else False

    def after_record(self, record, log: LogWriter) -> None:
        self._log = log
        self._drop_pending()  # the recorder's last record comes whether or not we are ready
        self._index += 1
        index = self._index
        self._last_record_s = self._last_stamp_s = record.stamp_s
        self.tracker.recorded(index, record)
        true_pose = self.truth() if self.truth is not None else None
        if true_pose is not None:
            log.write(TruthPose(record.stamp_s, *true_pose))
        self._write_latencies()
        log.flush()
        if self.camera is not None and self.grab_for is not None:
            self.frames_requested += 1
            # a simulated camera renders at the very pose written as truth: read twice, the
            # two could be a 15 ms step apart, 12 mrad of bearing at the turn rate (30 σ)
            if self.camera.request(index, self.grab_for(index, record, true_pose=true_pose)):
                self._pending = (index, record, record.stamp_s)
                return
            self.frames_skipped += 1
        self._finish_pose(index, record, ())

    # -- helpers

    def _drop_pending(self) -> None:
        """Give up the frame in progress (if any): its pose goes to the smoother without it."""
        if self._pending is not None:
            index, odometry, _ = self._pending
            self.frames_dropped += 1
            self._finish_pose(index, odometry, ())

    def _finish_pose(self, index: int, odometry: Odometry, observations: tuple[Observation, ...]) -> None:
        self._pending = None
        self.smoother.submit(Step(index, odometry.stamp_s, odometry, observations, None))

    def _write_observations(self, observations) -> None:
        assert self._log is not None
        for o in observations:
            self._log.write(o)
        self.observations += len(observations)
        if self.on_observations is not None:  # as they enter the log: what --until-landmarks counts
            self.on_observations(observations)
        self._log.flush()

    def _write_latencies(self) -> None:
        for index, latency in self.smoother.drain_latencies():
            self._log.write(LiveStep(self._last_stamp_s, index, latency))

    def close(self, log_path: str | None = None) -> None:
        """After the recorder returned: give the last pose to the smoother (a frame still in
        progress is dropped: the log is closed) and wait for it."""
        self._drop_pending()
        if self._control is not None:
            self._control.close()
        if self.camera is not None:
            self.camera.close()
        self.smoother.close()

    @property
    def poses(self) -> int:
        return self._index + 1


class LatestFrame:
    """Reads a live frame source in a background thread and keeps only the newest frame, so
    grabbing never waits for the camera; the frame is stamped with the pose it is used for
    (at most one camera period off)."""

    def __init__(self, frames):
        self._latest = None
        self._lock = threading.Lock()
        self.error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, args=(frames,), name="fgslam-frames", daemon=True)
        self._thread.start()

    def _run(self, frames) -> None:
        try:
            for frame in frames:
                with self._lock:
                    self._latest = frame
        except BaseException as exc:  # reported by grab
            self.error = exc

    def grab_for(self, index: int, odometry: Odometry, true_pose=None):
        with self._lock:
            frame = self._latest

        def grab():
            if frame is None:
                if self.error is not None:
                    raise FgslamError(f"camera: {self.error}")
                from slamio.camera.sources import Frame

                return Frame(odometry.stamp_s, index, "none", None, None, error="no frame from the camera yet")
            return dataclasses.replace(frame, stamp_s=odometry.stamp_s, index=index)

        return grab
