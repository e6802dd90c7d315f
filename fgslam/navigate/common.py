"""What every navigator sees and says: the interface between the live loop (or the harness)
and a steering policy, and the few pieces the policies share.

Each step the caller hands a navigator a :class:`Situation` — the robot's pose estimate, the
newest range scan and the pose it was taken from (scans are slow and old: the Kinect gives
one every ~0.4 s), the bumper, and the landmarks the SLAM has mapped with how often each was
seen — and gets back a :class:`Command`: a forward speed, a turn rate and a short state label
for the status line. Commands are kept inside what the iRobot Create can do
(:func:`limited_command`: at most 0.25 m/s cruising, 1 rad/s turning, and the 0.5 m/s wheel
limit via :func:`slamio.sim_models.wheel_speeds_m_s`).

:class:`BackOff` is the one bump reaction of the robust navigators: reverse ~0.15 m, then
turn away from the side that was hit. :class:`SpotWatch` notices a robot that has stayed on
one spot too long (dithering between two ways that each close when looked at, or goals
given up one after another), so the owner can back off and try elsewhere.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Mapping, Protocol


from slamio.geometry import wrap_angle
from slamio.scan import Scan
from slamio.sim_models import WHEEL_BASE_M, wheel_speeds_m_s

__all__ = ["Situation", "Command", "Navigator", "limited_command", "BackOff", "SpotWatch", "ROBOT_RADIUS_M",
           "ROBOT_LENGTH_M", "CRUISE_SPEED_M_S", "MAX_TURN_RATE_RAD_S", "heading_error_rad", "turn_towards"]

ROBOT_RADIUS_M = 0.17  # the Create is a disc 0.34 m across
ROBOT_LENGTH_M = 2 * ROBOT_RADIUS_M
CRUISE_SPEED_M_S = 0.25  # half the wheels' 0.5 m/s: time to stop within a scan's latency
MAX_TURN_RATE_RAD_S = 1.0


@dataclass(frozen=True)
class Situation:
    """What the robot knows at one step (module docstring)."""

    now_s: float
    pose: tuple[float, float, float]
    scan: Scan | None
    scan_pose: tuple[float, float, float] | None
    bumped: bool = False
    bump_side: str | None = None
    landmarks: Mapping[int, tuple[float, float]] = field(default_factory=dict)
    sightings: Mapping[int, int] = field(default_factory=dict)


@dataclass(frozen=True)
class Command:
    """A unicycle command and a short label of what the navigator is doing."""

    speed_m_s: float
    turn_rate_rad_s: float
    state: str


class Navigator(Protocol):
    name: str

    def step(self, situation: Situation) -> Command: ...


def limited_command(speed_m_s: float, turn_rate_rad_s: float, state: str) -> Command:
    """``Command`` clipped to the cruising limits, then to the Create's wheel limit (both
    wheels scaled together so the arc is kept)."""
    speed = min(max(float(speed_m_s), -CRUISE_SPEED_M_S), CRUISE_SPEED_M_S)
    turn = min(max(float(turn_rate_rad_s), -MAX_TURN_RATE_RAD_S), MAX_TURN_RATE_RAD_S)
    left, right = wheel_speeds_m_s(speed, turn)
    return Command(0.5 * (left + right), (right - left) / WHEEL_BASE_M, state)


def heading_error_rad(pose, target_heading_rad: float) -> float:
    """How far the robot must turn (counter-clockwise positive) to face ``target_heading_rad``."""
    return float(wrap_angle(target_heading_rad - pose[2]))


def turn_towards(error_rad: float, gain_per_s: float = 2.0) -> float:
    """A proportional turn rate toward a heading error, within the turning limit."""
    return min(max(gain_per_s * float(error_rad), -MAX_TURN_RATE_RAD_S), MAX_TURN_RATE_RAD_S)


class BackOff:
    """The bump reaction: reverse ``distance_m`` at ``speed_m_s``, then turn ``turn_rad``
    away from the side that was hit (a front hit turns toward ``prefer_left``'s side).

    ``start`` arms it; while :attr:`active` the owner returns :meth:`step`'s command.
    """

    def __init__(self, distance_m: float = 0.15, speed_m_s: float = 0.1, turn_rad: float = math.radians(60)):
        self.distance_m, self.speed_m_s, self.turn_rad = distance_m, speed_m_s, turn_rad
        self._start_xy: tuple[float, float] | None = None
        self._target_heading: float | None = None
        self._deadline_s = 0.0
        self.active = False
        self._distance_now_m = distance_m

    def start(self, situation: Situation, prefer_left: bool = True, distance_m: float | None = None) -> None:
        """Arm it; ``distance_m`` overrides the reverse for this once (leaving a spot the robot
        dithered on takes more than the bump's 0.15 m)."""
        self._distance_now_m = self.distance_m if distance_m is None else distance_m
        side = situation.bump_side
        left = side == "right" or (side != "left" and prefer_left)
        x, y, theta = situation.pose
        self._start_xy = (x, y)
        self._target_heading = wrap_angle(theta + (self.turn_rad if left else -self.turn_rad))
        # a stuck reverse (something behind) must not hold the robot for ever
        self._deadline_s = situation.now_s + 2.0 * self._distance_now_m / self.speed_m_s + 4.0
        self.active = True

    def step(self, situation: Situation) -> Command:
        x, y, _ = situation.pose
        if situation.now_s > self._deadline_s:
            self.active = False
        elif self._start_xy is not None:
            if math.hypot(x - self._start_xy[0], y - self._start_xy[1]) < self._distance_now_m:
                return limited_command(-self.speed_m_s, 0.0, "back-off")
            self._start_xy = None
        if self.active:
            error = heading_error_rad(situation.pose, self._target_heading)
            if abs(error) > math.radians(5):
                return limited_command(0.0, math.copysign(MAX_TURN_RATE_RAD_S, error), "turn-away")
            self.active = False
        return limited_command(0.0, 0.0, "back-off")


class SpotWatch:
    """True from :meth:`update` when the robot's centre has stayed within ``radius_m`` of one
    spot for ``limit_s`` (the spot is reset then, and whenever the centre leaves it)."""

    def __init__(self, limit_s: float = 7.0, radius_m: float = 0.15):
        self.limit_s, self.radius_m = limit_s, radius_m
        self._anchor: tuple[float, float, float] | None = None  # x, y, since

    @property
    def anchor(self) -> tuple[float, float, float] | None:
        """(x, y, since when) of the spot the robot is on (``None`` right after it fired)."""
        return self._anchor

    def update(self, situation: Situation) -> bool:
        x, y = situation.pose[:2]
        if self._anchor is None or math.hypot(x - self._anchor[0], y - self._anchor[1]) > self.radius_m:
            self._anchor = (x, y, situation.now_s)
            return False
        if situation.now_s - self._anchor[2] > self.limit_s:
            self._anchor = None
            return True
        return False
