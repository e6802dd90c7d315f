"""A navigator at the wheel of the live loop (``fgslam live --navigate NAME``).

The navigators (:mod:`fgslam.navigate`) are policies: a :class:`~fgslam.navigate.Situation`
in, a speed and turn rate out. This module gives them what the live loop has:

* :class:`ScanSlot` — the newest obstacle scan and the pose estimate it was taken from. The
  camera worker fills it from each frame's registered depth
  (:func:`slamio.camera.depth_scan.depth_scan`) while it looks for landmarks in the same frame;
* :class:`Sightings` — every landmark observation written to the log, counted per landmark
  (the live loop tells it), and the newest map the smoother published;
* :class:`NavigatingController` — the recorder's controller (as
  :class:`~fgslam.live.steering.WaypointFollower` is for ``--path``): each pass of the control
  loop it asks the navigator for a command on the pose the loop steers by
  (:class:`~fgslam.live.steering.PoseTracker`) and turns it into wheel speeds under the same
  acceleration limit. It never ends the run: the duration, or the landmark count, does.
  A bump reaches it through :meth:`~NavigatingController.bumper_changed` (the recorder's, with
  ``RecorderSettings.bump_ends_run`` False): the wheels are already stopped, and the navigator
  is told on its next step (``Situation.bumped``, ``bump_side``) so it can back off.

All three are shared between threads (control loop, camera worker, smoother worker), so each
keeps its state behind a lock and hands out copies.
"""

from __future__ import annotations

import threading
import time
from typing import Callable, Mapping

from slamio.create.controllers import WheelRamp
from slamio.scan import Scan
from slamio.sim_models import wheel_speeds_m_s

__all__ = ["ScanSlot", "Sightings", "NavigatingController", "navigating_camera"]


class ScanSlot:
    """The newest scan and the pose estimate of the frame it came from (thread-safe)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._newest: tuple[Scan, tuple[float, float, float]] | None = None
        self.scans = 0

    def offer(self, scan: Scan, pose: tuple[float, float, float]) -> None:
        with self._lock:
            self._newest = (scan, tuple(float(v) for v in pose))
            self.scans += 1

    def newest(self) -> tuple[Scan | None, tuple[float, float, float] | None]:
        with self._lock:
            return self._newest if self._newest is not None else (None, None)


class Sightings:
    """How often the front-end saw each landmark, and the smoother's newest map (thread-safe)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._counts: dict[int, int] = {}
        self._map: dict[int, tuple[float, float]] = {}

    def seen(self, observations) -> None:
        with self._lock:
            for observation in observations:
                landmark = getattr(observation, "landmark_id", None)
                if landmark is not None:
                    self._counts[landmark] = self._counts.get(landmark, 0) + 1

    def mapped(self, landmarks: Mapping[int, tuple[float, float]]) -> None:
        with self._lock:
            self._map = {int(k): (float(v[0]), float(v[1])) for k, v in landmarks.items()}

    def snapshot(self) -> tuple[dict[int, tuple[float, float]], dict[int, int]]:
        with self._lock:
            return dict(self._map), dict(self._counts)

    @property
    def landmarks_seen(self) -> int:
        with self._lock:
            return len(self._counts)

    def until(self, landmarks: int | None) -> Callable[[float], bool | str] | None:
        """The live loop's end test for ``--until-landmarks``: true (a reason) once that many
        different landmarks have been seen; None when no count is asked for."""
        if landmarks is None:
            return None

        def enough(now_s: float) -> bool | str:
            seen = self.landmarks_seen
            return f"saw {seen} landmarks (--until-landmarks {landmarks})" if seen >= landmarks else False

        return enough


class NavigatingController:
    """The recorder's controller when a navigator drives: :meth:`command` gives (left, right)
    in mm/s each pass; ``state`` is the navigator's last state, for the status line;
    ``step_seconds`` the wall time of the navigator's steps (its cost per control step)."""

    def __init__(self, navigator, estimate: Callable[[], tuple[float, float, float]], scans: ScanSlot,
                 sightings: Sightings, *, accel_m_s2: float, on_advance: Callable[[float, float], None] | None = None):
        self.navigator = navigator
        self.estimate = estimate
        self.scans = scans
        self.sightings = sightings
        self.on_advance = on_advance
        self.state = "starting"
        self.step_seconds: list[float] = []
        self._ramp = WheelRamp(accel_m_s2)
        self._pressed_side: str | None = None  # the side pressed now, None when released
        self._pressed_since_step: str | None = None  # a press the navigator has not been told of

    def bumper_changed(self, state, now_s: float) -> None:
        """The recorder's call on a press or a release (a :class:`slamio.create.bumper.BumperState`)."""
        side = {"both": "front"}.get(state.side, state.side) if state.pressed else None
        self._pressed_side = side
        if side is not None:
            self._pressed_since_step = side

    def advance(self, distance_m: float, angle_rad: float) -> None:
        if self.on_advance is not None:
            self.on_advance(distance_m, angle_rad)

    def situation(self, now_s: float):
        from fgslam.navigate import Situation

        scan, scan_pose = self.scans.newest()
        landmarks, counts = self.sightings.snapshot()
        side = self._pressed_side or self._pressed_since_step
        self._pressed_since_step = None
        return Situation(now_s=now_s, pose=self.estimate(), scan=scan, scan_pose=scan_pose, bumped=side is not None,
                         bump_side=side, landmarks=landmarks, sightings=counts)

    def command(self, now_s: float, unread: tuple[float, float] = (0.0, 0.0)) -> tuple[float, float]:
        situation = self.situation(now_s)
        started = time.perf_counter()
        command = self.navigator.step(situation)
        self.step_seconds.append(time.perf_counter() - started)
        self.state = command.state
        left, right = wheel_speeds_m_s(command.speed_m_s, command.turn_rate_rad_s)
        # slowing down is never delayed; a bump's stop is the safety monitor's, not ours
        return self._ramp((1000.0 * left, 1000.0 * right), now_s)


def navigating_camera(front_end, grab_for, estimate: Callable[[], tuple[float, float, float]], scans: ScanSlot,
                      scan_camera):
    """The camera worker's parts when a navigator drives: ``(grab_for, process)``.

    ``grab_for`` notes the pose estimate each frame is asked for at (the control loop's
    :class:`~fgslam.live.steering.PoseTracker`, ``estimate``); ``process`` runs the landmark
    front-end on the frame and, when the frame has a registered depth image, offers its obstacle scan
    (from ``scan_camera``'s intrinsics and mount) with that pose to ``scans``. The frames are
    the landmarks' frames: one grab, both uses.
    """
    from slamio.camera.depth_scan import depth_scan

    asked_at: dict[int, tuple[float, float, float]] = {}
    lock = threading.Lock()

    def grab_for_navigating(index: int, odometry, true_pose=None):
        with lock:
            asked_at[index] = estimate()
            for old in [k for k in asked_at if k < index - 100]:  # frames refused or given up
                del asked_at[old]
        return grab_for(index, odometry, true_pose=true_pose)

    def process(frame):
        observations = front_end.process(frame).observations
        with lock:
            pose = asked_at.pop(frame.index, None)
        if pose is not None and getattr(frame, "depth_m", None) is not None:
            scans.offer(depth_scan(frame.depth_m, scan_camera), pose)
        return observations

    return grab_for_navigating, process
