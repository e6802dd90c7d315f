"""Where the live robot goes: the loop's settings, the waypoints, the follower that steers on
the smoothed pose, and the pose tracker that composes the odometry since onto it."""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from typing import Callable

import numpy as np

from slamio.create.controllers import WheelRamp
from slamio.create.odometry import WHEEL_BASE_M
from slamio.create.record_settings import SAME_TIME_S
from slamio.errors import InputFileError, read_text
from slamio.geometry import arc_increment, between_pose, compose_pose, wrap_angle
from slamio.log import Odometry


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


#: Waypoints farther than this from the map's origin are a typo (a Create drives 0.5 m/s).
MAX_WAYPOINT_M = 1.0e4


def read_waypoints(path: str) -> np.ndarray:
    """``x_m, y_m`` per line (comma or space separated, ``#`` comments); file:line errors."""
    rows = []
    content = read_text(path, "waypoint file", "a waypoint file is UTF-8 text with one 'x_m, y_m' per line")
    lines = content.replace("\r\n", "\n").replace("\r", "\n").split("\n")  # as open() splits them
    for number, line in enumerate(lines, start=1):
        text = line.split("#", 1)[0].replace(",", " ").split()
        if not text:
            continue
        try:
            x, y = (float(v) for v in text)
        except ValueError:
            shown = line.strip() if len(line.strip()) <= 80 else line.strip()[:77] + "..."
            raise InputFileError(f"{path}:{number}: expected 'x_m, y_m', got {shown!r}") from None
        if not (abs(x) <= MAX_WAYPOINT_M and abs(y) <= MAX_WAYPOINT_M):  # NaN fails too
            raise InputFileError(f"{path}:{number}: a waypoint must be finite and within {MAX_WAYPOINT_M:g} m of "
                                 f"the origin (metres in the map frame); got {text[0][:20]}, {text[1][:20]}")
        rows.append((x, y))
    if not rows:
        raise InputFileError(f"{path}: no waypoints; write one 'x_m, y_m' per line")
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


def start_pose_facing(waypoints, start_xy=None) -> tuple[float, float, float]:
    """A start pose on ``start_xy`` (default: the path's last waypoint, where a closed path
    starts) facing the first waypoint."""
    w = np.asarray(waypoints, dtype=float).reshape(-1, 2)
    start = w[-1] if start_xy is None else np.asarray(start_xy, dtype=float)
    return float(start[0]), float(start[1]), math.atan2(w[0, 1] - start[1], w[0, 0] - start[0])


def pose_error_m(a, b) -> float:
    """Distance between the positions of two poses."""
    return math.hypot(*between_pose(a, b)[:2])
