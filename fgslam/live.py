"""``fgslam live``: drive the Create on the iSAM2 pose, see landmarks, smooth and record.

One process, three threads, one log:

* **The control loop** (the caller's thread) is the recorder's
  (:func:`slamio.create.record.record`): it reads the Create's sensor stream, runs the safety
  monitor and its watchdog, sends wheel commands and writes odometry records. The live loop
  rides on it through :class:`LiveLoop` (its ``hooks``) and steers it with a
  :class:`WaypointFollower` that closes the loop on the smoothed pose.
* **The camera worker** grabs a frame when asked and runs the landmark front-end
  (:class:`slamio.camera.detect.FrontEnd`) on it.
* **The smoother worker** feeds each pose (odometry + observations) to
  :class:`fgslam.smoother.Isam2Smoother` and publishes the pose and its covariance.

How one pose is made:

1. The control loop writes odometry record k (everything the wheels did since record k−1)
   and, in the same breath, asks the camera worker for a frame: the frame belongs to pose k.
   If the worker is still busy with an earlier frame the request is refused (``skipped``).
2. While that frame is being processed no further odometry record is written — the wheel
   readings keep arriving and accumulate into record k+1 (odometry is *batched*), so a slow
   frame delays a pose but never the serial link. The observations are written to the log
   right after record k as soon as they come back; a frame that takes longer than
   ``frame_timeout_s`` is given up (``dropped``).
3. Pose k goes to the smoother worker's queue. The smoother never holds up the control
   loop: the follower steers on the newest smoothed pose composed with the odometry since
   (:class:`PoseTracker`), whatever pose that is. Each smoother step's wall time is written
   to the log as a ``live_step`` record.

Safety is the recorder's: a bump, a wheel drop, a lost serial link, the watchdog or Ctrl-C
stops the wheels first and the log (flushed after every record) is kept. Any exception in a
worker is raised in the control loop, whose link exit stops the wheels before the log is
closed. The log is an ordinary run log: ``fgslam run LOG`` replays it with every estimator.
"""

from __future__ import annotations

import dataclasses
import math
import queue
import threading
import time
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from slamio.create.record import SAME_TIME_S, WheelRamp
from slamio.create.odometry import WHEEL_BASE_M
from slamio.create.sim import STEP_S
from slamio.errors import FgslamError
from slamio.geometry import arc_increment, between_pose, compose_pose, wrap_angle
from slamio.log import LiveStep, LogWriter, Observation, Odometry, Step, TruthLandmark, TruthPose

__all__ = [
    "LiveSettings",
    "waypoint_wheel_speeds",
    "WaypointFollower",
    "PoseTracker",
    "Lockstep",
    "CameraWorker",
    "SmootherWorker",
    "LiveLoop",
    "LiveResult",
    "read_waypoints",
    "polygon_waypoints",
    "LatestFrame",
    "run_live",
    "simulated_camera",
    "start_pose_facing",
    "pose_error_m",
]


@dataclass(frozen=True)
class LiveSettings:
    """Speeds and timings of the live loop (robot time unless marked wall)."""

    speed_m_s: float = 0.2  # cruising speed on a leg
    turn_rate_rad_s: float = 0.8  # turning in place
    accel_m_s2: float = 0.4  # wheel speed changes at most this fast
    min_speed_m_s: float = 0.02
    position_tolerance_m: float = 0.03  # a waypoint is reached within this
    heading_tolerance_rad: float = 0.04  # turn in place until the heading error is below this
    drive_heading_limit_rad: float = 0.35  # while driving: stop and turn again beyond this error
    heading_gain_per_s: float = 2.0  # ω = gain · heading error while driving
    settle_s: float = 0.3  # standing still between a leg and a turn (the encoders count the commanded way)
    record_period_s: float = 0.1  # one pose per period at most
    frame_timeout_s: float = 0.5  # give up a frame after this long (robot time)
    wheel_base_m: float = WHEEL_BASE_M
    command_timeout_s: float = 0.5  # (wall) the recorder's watchdog: no drive command for this long → stop
    data_timeout_s: float = 0.5  # (wall) no valid sensor reading for this long → stop


# --------------------------------------------------------------------------- waypoints


def polygon_waypoints(sides: int, width_m: float, centre_xy: tuple[float, float], laps: int = 1) -> np.ndarray:
    """Seed 004's paths: a square (4) or octagon (8) of ``width_m`` across flats, driven
    ``laps`` times counter-clockwise and closed at the first corner."""
    from slamio.sim import polygon_path

    corners = polygon_path(sides, width_m, centre_xy)
    loop = np.vstack([corners[1:], corners[:1]])
    return np.vstack([loop] * max(1, int(laps)))


def read_waypoints(path: str) -> np.ndarray:
    """``x_m, y_m`` per line (comma or space separated, ``#`` comments); file:line errors."""
    rows = []
    with open(path, encoding="utf-8") as f:
        for number, line in enumerate(f, start=1):
            text = line.split("#", 1)[0].replace(",", " ").split()
            if not text:
                continue
            try:
                x, y = (float(v) for v in text)
            except ValueError:
                raise FgslamError(f"{path}:{number}: expected 'x_m, y_m', got {line.strip()!r}") from None
            if not (math.isfinite(x) and math.isfinite(y)):
                raise FgslamError(f"{path}:{number}: waypoint is not finite")
            rows.append((x, y))
    if not rows:
        raise FgslamError(f"{path}: no waypoints; write one 'x_m, y_m' per line")
    return np.array(rows)


# --------------------------------------------------------------------------- follower


def waypoint_wheel_speeds(pose, target_xy, settings: LiveSettings, turning: bool) -> tuple[str, float, float]:
    """What to do now on the way from ``pose`` to ``target_xy``: ``(mode, v_m_s, ω_rad_s)``.

    ``mode`` is ``"arrived"`` (within ``position_tolerance_m``), ``"turn"`` (turn in place:
    the heading error is above ``heading_tolerance_rad`` while ``turning``, or above
    ``drive_heading_limit_rad`` while driving) or ``"drive"`` (forward, ``ω`` proportional
    to the heading error, ``v`` slowing along the stopping curve ``√(2·a·d)``). Both wheels
    stay forward while driving (a Create 2 encoder counts the commanded direction).
    """
    x, y, th = pose
    dx, dy = target_xy[0] - x, target_xy[1] - y
    distance = math.hypot(dx, dy)
    if distance <= settings.position_tolerance_m:
        return "arrived", 0.0, 0.0
    error = wrap_angle(math.atan2(dy, dx) - th)
    limit = settings.heading_tolerance_rad if turning else settings.drive_heading_limit_rad
    if abs(error) > limit:
        return "turn", 0.0, math.copysign(settings.turn_rate_rad_s, error)
    v = max(settings.min_speed_m_s, min(settings.speed_m_s, math.sqrt(2.0 * settings.accel_m_s2 * distance)))
    omega = settings.heading_gain_per_s * error
    half = 0.5 * settings.wheel_base_m
    omega = max(-v / half, min(v / half, omega))  # keep both wheels forward
    return "drive", v, omega


class WaypointFollower:
    """The live loop's controller (the recorder's controller protocol): turn in place
    towards the next waypoint, settle, drive to it closing the loop on ``estimate()``
    (the smoothed pose), settle, next. :meth:`command` returns (left, right) in mm/s, or
    None after the last waypoint."""

    def __init__(self, waypoints, estimate: Callable[[], tuple[float, float, float]],
                 settings: LiveSettings = LiveSettings(), on_advance: Callable[[float, float], None] | None = None):
        self.waypoints = np.asarray(waypoints, dtype=float).reshape(-1, 2)
        self.estimate = estimate
        self.s = settings
        self.on_advance = on_advance
        self.index = 0
        self._mode = "turn"
        self._settle_until: float | None = None
        self._ramp = WheelRamp(settings.accel_m_s2)

    def advance(self, distance_m: float, angle_rad: float) -> None:
        if self.on_advance is not None:
            self.on_advance(distance_m, angle_rad)

    def _stop(self, now_s: float, then: str) -> tuple[float, float]:
        self._settle_until = now_s + self.s.settle_s
        self._mode = then
        return self._ramp((0.0, 0.0), now_s)

    def command(self, now_s: float, unread: tuple[float, float] = (0.0, 0.0)) -> tuple[float, float] | None:
        if self._settle_until is not None:
            if now_s < self._settle_until - SAME_TIME_S:
                return self._ramp((0.0, 0.0), now_s)
            self._settle_until = None
        if self.index >= len(self.waypoints):
            return None
        mode, v, omega = waypoint_wheel_speeds(self.estimate(), self.waypoints[self.index], self.s,
                                               turning=self._mode == "turn")
        if mode == "arrived":
            self.index += 1
            return self._stop(now_s, "turn")
        if mode != self._mode:  # from driving to turning or back: stand still first
            return self._stop(now_s, mode)
        half = 0.5 * self.s.wheel_base_m
        left, right = v - omega * half, v + omega * half
        return self._ramp((1000.0 * left, 1000.0 * right), now_s)


# --------------------------------------------------------------------------- pose tracker


class PoseTracker:
    """The pose to steer on: the newest smoothed pose ⊕ the odometry since (thread-safe).

    The control loop reports the wheels' motion (:meth:`advance`) and each odometry record
    (:meth:`recorded`); the smoother worker reports each smoothed pose (:meth:`smoothed`).
    """

    def __init__(self, start_pose):
        self._lock = threading.Lock()
        self._base_index = 0
        self._base = tuple(float(v) for v in start_pose)
        self._records: dict[int, tuple[float, float, float]] = {}  # pose index → increment
        self._since_record = (0.0, 0.0, 0.0)

    def advance(self, distance_m: float, angle_rad: float) -> None:
        with self._lock:
            self._since_record = compose_pose(self._since_record, arc_increment(distance_m, angle_rad))

    def recorded(self, index: int, odometry: Odometry) -> None:
        with self._lock:
            self._records[index] = (odometry.dx_m, odometry.dy_m, odometry.dtheta_rad)
            self._since_record = (0.0, 0.0, 0.0)

    def smoothed(self, index: int, pose) -> None:
        with self._lock:
            if index >= self._base_index:
                self._base_index, self._base = index, tuple(float(v) for v in pose)
                for k in [k for k in self._records if k <= index]:
                    del self._records[k]

    def current(self) -> tuple[float, float, float]:
        with self._lock:
            pose = self._base
            for k in sorted(self._records):
                if k > self._base_index:
                    pose = compose_pose(pose, self._records[k])
            return compose_pose(pose, self._since_record)


# --------------------------------------------------------------------------- workers


class Lockstep:
    """Simulation only: a live run whose robot-time behaviour does not depend on how fast
    this machine is (``run_live(..., lockstep=Lockstep(sim))``; the tests use it).

    On a real run the robot drives on while a frame is rendered and detected or a smoother
    step runs, so how much robot time that work takes is this machine's speed. In lockstep
    every such piece of work gets a fixed budget of robot time: a frame's observations reach
    the live loop ``frame_s`` after the frame was asked for, a smoothed pose reaches the
    follower ``smoother_s`` after its step was submitted. Work done sooner waits for its
    time; at that time the simulated Create's clock stops
    (:meth:`slamio.create.sim.SimulatedCreate.hold`) until the work is done *and* the
    control loop has taken its result, so the result is used at exactly its robot time
    whatever the machine's speed (released on completion instead, the clock ran on by a
    step or more on a busy machine before the loop saw the result, and the same seed drove
    a different lap). A slow or busy machine then only stretches the run in wall time. ``frame_s`` must be below the settings'
    ``frame_timeout_s`` (no frame is ever late), and the recorder's wall-clock timeouts
    (``data_timeout_s``) must outlast the slowest frame: the robot streams nothing while
    its clock stands.
    """

    def __init__(self, sim, frame_s: float = 0.4, smoother_s: float = 0.05):
        if not (frame_s >= 0 and smoother_s >= 0):
            raise FgslamError(f"lockstep budgets must be ≥ 0 s, got frame {frame_s}, smoother {smoother_s}")
        self.sim = sim  # clock(), hold(at_s) -> token, release(token)
        self.frame_s = float(frame_s)
        self.smoother_s = float(smoother_s)
        self.end_of_pass: list[int] | None = None  # with a ControlHold: holds to end when the pass ends

    def hold_for(self, budget_s: float) -> tuple[float, int]:
        """``(due_at, token)``: the work started now is due at ``due_at`` (robot time); the
        clock stops there until ``release(token)``."""
        due_at = self.sim.clock() + budget_s
        return due_at, self.sim.hold(due_at)

    def release(self, token: int) -> None:
        self.sim.release(token)

    def release_taken(self, token: int) -> None:
        """End the hold of a result the control loop has just taken: when the loop itself is in
        lockstep (:class:`ControlHold`), at the end of its pass, so that the robot does not
        step while the pass still writes its records (the truth pose read for a record would
        be a step late); otherwise now."""
        if self.end_of_pass is None:
            self.release(token)
        else:
            self.end_of_pass.append(token)

    def reached(self, due_at: float | None) -> bool:
        return due_at is None or self.sim.clock() >= due_at - 1e-9


class ControlHold:
    """Lockstep for the control loop itself: the simulated Create takes one 15 ms step, then
    waits for the loop to have read that step's stream frame and sent its command.

    Without it the robot stepped on as soon as the host had *read* a frame, so a wheel
    command reached it in one step or the next depending on thread timing, and the same seed
    drove a slightly different lap. The clock stands from the moment the loop is made (the
    robot has not been started yet); :meth:`passed` ends every pass of the loop — the
    recorder's start-up polls and its control passes, after their command and records went
    out: it ends the holds of the results the pass took (:meth:`Lockstep.release_taken`), lets
    the clock take one more step once the loop has caught up with the last one, then waits
    until the robot has taken whatever step the holds allow
    (:meth:`slamio.create.sim.SimulatedCreate.settle`), so the next pass reads a whole step."""

    def __init__(self, lockstep: Lockstep):
        self.lockstep = lockstep
        self.sim = lockstep.sim
        lockstep.end_of_pass = []
        self._token: int | None = self.sim.hold()  # the clock stands until the first pass
        self.sim.settle()  # it may have been in the middle of a step
        self._at: float | None = None  # the clock time the hold was last moved on from

    def passed(self) -> None:
        self._release_taken()
        now = self.sim.clock()  # the clock stood here through the pass: nothing was released in it
        if self._token is not None and (self._at is None or now > self._at):
            token = self.sim.hold(now + 0.5 * STEP_S)  # stands again right after the next step
            self.sim.release(self._token)
            self._at, self._token = now, token
        self.sim.settle()

    def _release_taken(self) -> None:
        pending = self.lockstep.end_of_pass or []
        self.lockstep.end_of_pass = []
        for token in pending:
            self.sim.release(token)

    def close(self) -> None:
        self._release_taken()
        self.lockstep.end_of_pass = None
        if self._token is not None:
            self.sim.release(self._token)
            self._token = None


def release_untaken(lockstep: Lockstep | None, waiting: tuple | None, results: queue.Queue) -> None:
    """Let the simulated clock go for results nobody will take any more (a worker closing):
    ``waiting`` and every item of ``results`` end with their hold token."""
    items = [waiting] if waiting is not None else []
    while True:
        try:
            items.append(results.get_nowait())
        except queue.Empty:
            break
    for item in items:
        release_hold(lockstep, item[-1])


def release_hold(lockstep: Lockstep | None, token: int | None) -> None:
    """End a hold on the simulated clock (``token`` None: there is none, not lockstep)."""
    if token is not None:
        lockstep.release(token)  # type: ignore[union-attr]


class CameraWorker:
    """Grabs and processes one frame at a time in its own thread.

    :meth:`request` hands it a zero-argument ``grab`` (called in the worker: it returns a
    :class:`slamio.camera.sources.Frame`) for pose ``index``; it is refused while a frame
    is in progress. :meth:`result` returns ``(index, observations)`` when one is ready (in
    :class:`Lockstep`: not before the frame's budget of robot time has passed, and the
    simulated clock stands at that time until the control loop has taken the result).
    """

    def __init__(self, process: Callable[[object], Sequence[Observation]], lockstep: Lockstep | None = None):
        self.process = process
        self.lockstep = lockstep
        self._requests: queue.Queue = queue.Queue(maxsize=1)
        self._results: queue.Queue = queue.Queue()
        self._waiting: tuple | None = None  # (index, observations, due_at, hold token): done, not yet due
        self._busy = threading.Event()
        self.error: BaseException | None = None
        self.frame_seconds: list[float] = []
        self._thread = threading.Thread(target=self._run, name="fgslam-camera", daemon=True)
        self._thread.start()

    def request(self, index: int, grab: Callable[[], object]) -> bool:
        if self._busy.is_set():
            return False
        self._busy.set()
        due_at, token = self.lockstep.hold_for(self.lockstep.frame_s) if self.lockstep else (None, None)
        self._requests.put((index, grab, due_at, token))
        return True

    def result(self) -> tuple[int, list[Observation]] | None:
        if self._waiting is None:
            try:
                self._waiting = self._results.get_nowait()
            except queue.Empty:
                return None
        index, observations, due_at, token = self._waiting
        if self.lockstep is not None and not self.lockstep.reached(due_at):
            return None
        self._waiting = None
        if self.lockstep is not None:  # the clock stood at due_at until the control loop had the result
            self.lockstep.release_taken(token)
        if self.lockstep is not None:
            self._busy.clear()  # busy until the loop took the result: the next request never races the worker
        return index, observations

    def _run(self) -> None:
        while True:
            item = self._requests.get()
            if item is None:
                return
            index, grab, due_at, token = item
            start = time.perf_counter()
            try:
                observations = list(self.process(grab()))
            except BaseException as exc:  # raised in the control loop (see LiveLoop.due)
                self.error = exc
                observations = []
            self.frame_seconds.append(time.perf_counter() - start)
            # the hold goes with the result: released when the control loop takes it
            self._results.put((index, observations, due_at, token))
            if self.lockstep is None:
                self._busy.clear()

    def close(self) -> None:
        self._requests.put(None)
        self._thread.join(timeout=5.0)
        release_untaken(self.lockstep, self._waiting, self._results)  # results nobody will take
        self._waiting = None


class SmootherWorker:
    """Feeds steps to the smoother in its own thread; publishes each smoothed pose to the
    :class:`PoseTracker` and records each step's wall time. In :class:`Lockstep` a pose is
    published by :meth:`publish` (the control loop), when its budget of robot time is over."""

    def __init__(self, smoother, tracker: PoseTracker, on_step: Callable[[int, object], None] | None = None,
                 lockstep: Lockstep | None = None):
        self.smoother = smoother
        self.tracker = tracker
        self.on_step = on_step
        self.lockstep = lockstep
        self._steps: queue.Queue = queue.Queue()
        self._latencies: queue.Queue = queue.Queue()
        self._smoothed: queue.Queue = queue.Queue()  # lockstep: (due_at, index, pose, hold token) to publish
        self._due: tuple | None = None
        self.latencies_s: list[float] = []
        self.error: BaseException | None = None
        self.max_queue = 0
        self._thread = threading.Thread(target=self._run, name="fgslam-smoother", daemon=True)
        self._thread.start()

    def submit(self, step: Step) -> None:
        due_at, token = self.lockstep.hold_for(self.lockstep.smoother_s) if self.lockstep else (None, None)
        self._steps.put((step, due_at, token))
        self.max_queue = max(self.max_queue, self._steps.qsize())

    def publish(self) -> None:
        """Lockstep: hand the follower every smoothed pose whose time has come."""
        while True:
            if self._due is None:
                try:
                    self._due = self._smoothed.get_nowait()
                except queue.Empty:
                    return
            due_at, index, pose, token = self._due
            if self.lockstep is not None and not self.lockstep.reached(due_at):
                return
            self._due = None
            self.tracker.smoothed(index, pose)
            if self.lockstep is not None:  # the clock stood at due_at until the follower had the pose
                self.lockstep.release_taken(token)

    def drain_latencies(self) -> list[tuple[int, float]]:
        out = []
        while True:
            try:
                out.append(self._latencies.get_nowait())
            except queue.Empty:
                return out

    def _run(self) -> None:
        while True:
            item = self._steps.get()
            if item is None:
                return
            step, due_at, token = item
            queued = False
            try:
                queued = self._smooth(step, due_at, token)
            finally:
                if not queued:
                    release_hold(self.lockstep, token)

    def _smooth(self, step: Step, due_at: float | None, token) -> bool:
        """Smooth one step; True when its pose was queued for :meth:`publish` with ``token``."""
        if self.error is not None:
            return False
        start = time.perf_counter()
        try:
            self.smoother.step(step)
            pose = self.smoother.current_pose()
        except BaseException as exc:  # raised in the control loop (see LiveLoop.due)
            self.error = exc
            return False
        latency = time.perf_counter() - start
        self.latencies_s.append(latency)
        self._latencies.put((step.index, latency))
        if self.lockstep is None:
            self.tracker.smoothed(step.index, pose)
        else:
            self._smoothed.put((due_at, step.index, pose, token))
        if self.on_step is not None:
            try:
                self.on_step(step.index, self.smoother, latency)
            except BaseException as exc:  # a failing status line stops the run like a failing smoother
                self.error = exc
        return self.lockstep is not None

    def close(self) -> None:
        """Wait for every submitted step to be smoothed, then stop the thread (an error of
        the smoother stays in :attr:`error`); poses nobody will publish let the clock go."""
        self._steps.put(None)
        self._thread.join()
        release_untaken(self.lockstep, self._due, self._smoothed)
        self._due = None


# --------------------------------------------------------------------------- the loop


@dataclass
class LiveResult:
    """What a live run did (the recorder's result plus the live loop's counts)."""

    record: object  # slamio.create.record.RecordResult
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
                 truth_landmarks: Sequence[TruthLandmark] = (), lockstep: Lockstep | None = None):
        self.tracker = tracker
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


def start_pose_facing(waypoints, start_xy=None) -> tuple[float, float, float]:
    """A start pose on ``start_xy`` (default: the path's last waypoint, where a closed path
    starts) facing the first waypoint."""
    w = np.asarray(waypoints, dtype=float).reshape(-1, 2)
    start = w[-1] if start_xy is None else np.asarray(start_xy, dtype=float)
    return float(start[0]), float(start[1]), math.atan2(w[0, 1] - start[1], w[0, 0] - start[0])


def pose_error_m(a, b) -> float:
    """Distance between the positions of two poses."""
    return math.hypot(*between_pose(a, b)[:2])


# --------------------------------------------------------------------------- assembling a run


#: What the AprilTag front-end reports from :func:`simulated_camera`'s frames (640×480, the
#: Kinect's intrinsics, rendered with pixel noise σ 2 grey levels and no supersampling):
#: σ_bearing constant, σ_range = c·r² (:class:`slamio.camera.detect.NoiseModel`). Measured by
#: ``scripts/measure_live_camera.py`` on frames rendered at poses drawn along the octagon and
#: square paths (RMS errors against the truth, outliers included), not on the runs it is
#: then checked with (docs/camera.md, "The simulated live camera").
#: Two draws of 400 frames (seeds 0 and 1): bearing 0.404 / 0.396 mrad, c 3.98 / 3.85 mm/m².
LIVE_SIM_SIGMA_BEARING_RAD = 4.0e-4
LIVE_SIM_RANGE_SIGMA_PER_M2 = 4.0e-3  # for LIVE_SIM_TAG_SIZE_M; c grows as 1/tag size
LIVE_SIM_TAG_SIZE_M = 0.16
#: The tag yaw's σ of those frames: RMS 0.070 / 0.121 rad over the same draws. IPPE's yaw of
#: a near-frontal tag is heavy-tailed (a flipped solution now and then), so this is a
#: second moment, not a Gaussian's width.
LIVE_SIM_SIGMA_TAG_YAW_RAD = 0.1


def live_sim_tag_noise(tag_size_m: float = LIVE_SIM_TAG_SIZE_M):
    """The :class:`slamio.camera.detect.NoiseModel` of :func:`simulated_camera`'s observations
    for tags of ``tag_size_m`` (a tag's apparent size, and so its range error, scales with it)."""
    from slamio.camera.detect import NoiseModel

    c = LIVE_SIM_RANGE_SIGMA_PER_M2 * LIVE_SIM_TAG_SIZE_M / tag_size_m
    return NoiseModel(0.0, 0.0, c, LIVE_SIM_SIGMA_BEARING_RAD, None, LIVE_SIM_SIGMA_TAG_YAW_RAD)


def arena_tag_scene(tag_size_m: float = 0.16):
    """Seed 004's eight arena tags as a render :class:`slamio.camera.render.Scene`."""
    from slamio.camera.render import Scene, TagSpec
    from slamio.sim import TAG_HEIGHT_M, arena_tags

    world = arena_tags()
    return Scene(tags=tuple(
        TagSpec(i, float(x), float(y), TAG_HEIGHT_M, float(yaw), size_m=tag_size_m)
        for i, ((x, y), yaw) in enumerate(zip(world.landmarks_xy, world.yaws_rad))
    ))


def live_sim_camera(mount_height_m: float = 0.2):
    """The simulated live camera: the Kinect's intrinsics on the robot's centre, looking ahead."""
    from slamio.camera.model import T_robot_camera_from_mount, kinect_v1_default

    return kinect_v1_default(T_robot_camera_from_mount(0.0, 0.0, mount_height_m))


def simulated_camera(sim, *, supersample: int = 1, pixel_noise: float = 2.0, seed: int = 0,
                     tag_size_m: float = 0.16, mount_height_m: float = 0.2):
    """The camera of a hardware-in-the-loop run: seed 004's eight arena tags rendered from
    the simulated Create's true pose at the instant each pose is made. Its observations
    carry the noise those frames have (:func:`live_sim_tag_noise`), so a replay of the log
    is consistent.

    Returns ``(grab_for, front_end, truth_landmarks)``: ``grab_for(index, odometry,
    true_pose=None)`` takes ``true_pose`` (the truth the live loop has just written) or
    snapshots the true pose now (in the control loop) and returns the grabber that renders
    it (run in the camera worker); ``truth_landmarks`` are the tags as log records.
    """
    from slamio.camera.detect import FrontEnd, FrontEndConfig
    from slamio.camera.render import render
    from slamio.camera.sources import Frame

    scene = arena_tag_scene(tag_size_m)
    camera = live_sim_camera(mount_height_m)
    front_end = FrontEnd(camera, FrontEndConfig(tag_size_m=tag_size_m, noise=live_sim_tag_noise(tag_size_m)))
    rng = np.random.default_rng(seed)  # used only in the camera worker

    def grab_for(index: int, odometry: Odometry, true_pose=None):
        pose = sim.true_pose if true_pose is None else true_pose  # now, or the truth the loop just wrote

        def grab():
            frame = render(camera, pose, scene, supersample=supersample, noise_sigma=pixel_noise, rng=rng)
            return Frame(odometry.stamp_s, index, f"sim:{index}", frame.bgr, frame.depth_m)

        return grab

    truth_landmarks = [TruthLandmark(t.tag_id, t.x_m, t.y_m, t.z_m, t.yaw_rad) for t in scene.tags]
    return grab_for, front_end, truth_landmarks


def run_live(link, out_path: str, waypoints, *, start_pose, grab_for=None, front_end=None,
             settings: LiveSettings = LiveSettings(), smoother=None, truth=None, truth_landmarks=(),
             clock: Callable[[], float] = time.monotonic, sensor: dict | None = None,
             observation_noise: dict | None = None, odometry_noise=None, on_step=None,
             lockstep: Lockstep | None = None) -> LiveResult:
    """Drive ``waypoints`` on the robot behind ``link`` with iSAM2 in the loop; log to
    ``out_path``. ``grab_for``/``front_end`` give the camera (None: odometry only);
    ``smoother`` defaults to :class:`fgslam.smoother.Isam2Smoother` (its defaults: an update
    every 10 poses, the online correction in between).
    ``on_step(index, smoother, latency_s, loop)`` is called in the smoother worker after
    each pose (the CLI's status line and map; ``loop`` is the :class:`LiveLoop` with its
    frame counts). ``odometry_noise`` (an :class:`slamio.create.odometry.OdometryNoise`) is
    the odometry noise the log states; None: the recorder's nominal model.
    ``observation_noise`` is the header's observation-model entry; None: the front-end's
    noise model (every observation record carries its own σ either way).

    ``lockstep`` (simulation only, :class:`Lockstep`) gives every frame and smoother step a
    fixed budget of robot time, so how fast this machine renders, detects and smooths
    changes the run's wall time, never what happens in robot time. On a real robot time
    does not stop: leave it None."""
    from fgslam.smoother import Isam2Smoother
    from slamio.create.record import RecorderSettings, record
    from slamio.log import Header

    start_pose = tuple(float(v) for v in start_pose)
    if lockstep is not None and not lockstep.frame_s < settings.frame_timeout_s:
        raise FgslamError(f"lockstep frame budget {lockstep.frame_s} s must be below frame_timeout_s "
                          f"{settings.frame_timeout_s} s")
    if smoother is None:
        header = Header(stamp_s=0.0, start_pose=start_pose, start_sigma=(1e-3, 1e-3, 1e-3),  # as the recorder's
                        robot={"name": "live"}, sensor={"kind": "live"}, noise={"odometry": {}, "observation": {}})
        smoother = Isam2Smoother(header)
    tracker = PoseTracker(start_pose)
    camera = None
    if grab_for is not None and front_end is not None:
        camera = CameraWorker(lambda frame: front_end.process(frame).observations, lockstep=lockstep)
    def step_hook(index, smoother_, latency):
        on_step(index, smoother_, latency, loop)

    worker = SmootherWorker(smoother, tracker, step_hook if on_step is not None else None, lockstep=lockstep)
    loop = LiveLoop(tracker, camera, worker, grab_for, settings, truth, truth_landmarks, lockstep=lockstep)
    worker.submit(Step(0, 0.0, None, (), None))  # pose 0: the start pose (lockstep: the clock stands already)
    follower = WaypointFollower(waypoints, tracker.current, settings, on_advance=tracker.advance)
    recorder = RecorderSettings(speed_m_s=settings.speed_m_s, turn_rate_rad_s=settings.turn_rate_rad_s,
                                accel_m_s2=settings.accel_m_s2, record_period_s=settings.record_period_s,
                                command_timeout_s=settings.command_timeout_s, data_timeout_s=settings.data_timeout_s)
    sensor = sensor or {"kind": "range-bearing", "landmark_kind": "apriltag" if camera else "none",
                        "source": "fgslam live"}
    if observation_noise is None and camera is not None and getattr(front_end, "noise", None) is not None:
        # the header states the σ the front-end gives each observation (each record carries its own)
        observation_noise = {**front_end.noise.describe(), "source": "the camera front-end's noise model"}
    try:
        result = record(link, out_path, follower, settings=recorder, clock=clock, hooks=loop,
                        start_pose=start_pose, sensor=sensor, observation_noise=observation_noise,
                        noise=odometry_noise,
                        source={"generator": "fgslam.live", "waypoints": np.asarray(waypoints).tolist()})
    finally:
        loop.close()
    if worker.error is not None:  # after the last record: the recorder did not see it
        raise FgslamError(f"live loop: {type(worker.error).__name__}: {worker.error}") from worker.error
    smoother.finish()
    return LiveResult(
        record=result,
        final_pose=tuple(float(v) for v in smoother.current_pose()),  # type: ignore[arg-type]
        poses=loop.poses,
        frames_requested=loop.frames_requested,
        frames_used=loop.frames_used,
        frames_skipped=loop.frames_skipped,
        frames_dropped=loop.frames_dropped,
        observations=loop.observations,
        latencies_s=np.array(worker.latencies_s),
        frame_seconds=np.array(camera.frame_seconds if camera else []),
        landmarks=dict(smoother.landmarks()),
    )
