"""The live loop's two worker threads — the camera worker (a frame in, observations out) and
the smoother worker (a pose in, the smoothed pose out) — and the lockstep that makes a
simulated run deterministic however slow the machine."""

from __future__ import annotations

import queue
import threading
import time
from typing import Callable, Sequence

from fgslam.live.steering import PoseTracker
from slamio.create.sim import STEP_S
from slamio.errors import FgslamError
from slamio.log import Observation, Step


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
