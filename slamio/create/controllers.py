"""What drives the robot during a recording: a scripted path (:class:`Move`,
:func:`path_moves`, driven by :class:`PathController`) or the keyboard
(:class:`TeleopController` reading :class:`TerminalKeys`). Both give (left, right) wheel
speeds in mm/s through a :class:`WheelRamp`, which limits how fast they grow.
"""

from __future__ import annotations

import math
import os
import select
import sys
from dataclasses import dataclass
from typing import Protocol, Sequence

from slamio.create.odometry import WHEEL_BASE_M
from slamio.create.record_settings import SAME_TIME_S, RecorderSettings
from slamio.errors import FgslamError

__all__ = [
    "PATHS", "TELEOP_HELP", "KeySource", "Move", "PathController", "TeleopController", "TerminalKeys", "WheelRamp",
    "path_moves", "polygon_moves", "stopping_speed_m_s",
]

PATHS = ("square", "octagon", "teleop")
DEFAULT_SIDE_M = {"square": 1.0, "octagon": 0.5}


# --------------------------------------------------------------------------- paths


@dataclass(frozen=True)
class Move:
    """One step of a scripted path: ``forward`` by ``amount`` metres or ``rotate`` by
    ``amount`` radians (counter-clockwise positive), in place."""

    kind: str
    amount: float

    def __post_init__(self):
        if self.kind not in ("forward", "rotate"):
            raise FgslamError(f"a move is 'forward' (metres) or 'rotate' (radians), got {self.kind!r}")
        if not (isinstance(self.amount, (int, float)) and math.isfinite(self.amount) and self.amount != 0):
            raise FgslamError(f"a {self.kind} move needs a finite, non-zero amount, got {self.amount!r}")


def polygon_moves(sides: int, side_m: float, laps: int = 1) -> list[Move]:
    """A regular polygon driven counter-clockwise: per side, forward then turn left 2π/sides."""
    if sides < 3 or not side_m > 0 or laps < 1:
        raise FgslamError(f"a polygon needs ≥ 3 sides, a side > 0 m and ≥ 1 lap (got {sides}, {side_m}, {laps})")
    moves = []
    for _ in range(laps):
        for _ in range(sides):
            moves += [Move("forward", side_m), Move("rotate", 2.0 * math.pi / sides)]
    return moves


def path_moves(path: str, side_m: float | None = None, laps: int = 1) -> list[Move]:
    """The moves of ``square`` or ``octagon`` (side defaults: 1.0 m and 0.5 m)."""
    if path not in DEFAULT_SIDE_M:
        raise FgslamError(f"unknown scripted path {path!r}; use square or octagon (or teleop)")
    return polygon_moves(4 if path == "square" else 8, side_m or DEFAULT_SIDE_M[path], laps)


# --------------------------------------------------------------------------- controllers


def stopping_speed_m_s(remaining_m: float, accel_m_s2: float, full_m_s: float, slowest_m_s: float) -> float:
    """Speed from which the wheel can still stop within ``remaining_m`` at ``accel_m_s2``:
    ``sqrt(2·a·d)``, capped at full speed and kept above the slowest speed."""
    return max(slowest_m_s, min(full_m_s, math.sqrt(2.0 * accel_m_s2 * abs(remaining_m))))


class WheelRamp:
    """Limits how fast the commanded wheel speeds grow: the robot can follow them exactly,
    so the commands are also a good prediction of the motion (the Create 1 workaround)."""

    def __init__(self, accel_m_s2: float):
        self.accel_mm_s2 = 1000.0 * accel_m_s2
        self.wheels = (0.0, 0.0)
        self._t: float | None = None

    def __call__(self, target: tuple[float, float], now_s: float, limit_slowing: bool = False) -> tuple[float, float]:
        dt = 0.0 if self._t is None else max(0.0, now_s - self._t)
        self._t = now_s
        step = self.accel_mm_s2 * dt
        out = []
        for prev, want in zip(self.wheels, target):
            slowing = abs(want) <= abs(prev) and want * prev >= 0
            if slowing and not limit_slowing:
                out.append(want)
            else:
                out.append(prev + max(-step, min(step, want - prev)))
        self.wheels = (out[0], out[1])
        return self.wheels


class _Controller:
    """What both drivers keep: the recorder's settings, the wheel base, the wheel-speed ramp."""

    def __init__(self, settings: RecorderSettings, wheel_base_m: float):
        self.s = settings
        self.wheel_base_m = wheel_base_m
        self._ramp = WheelRamp(settings.accel_m_s2)


class PathController(_Controller):
    """Open-loop-on-odometry driver of a list of :class:`Move` (forward/rotate in place).

    :meth:`advance` adds each reading's (distance, angle); :meth:`command` returns the
    (left, right) wheel speeds in mm/s, or None when the path is done (after the last
    settle). Wheel speeds rise at most at ``accel_m_s2`` and fall along the stopping curve
    ``sqrt(2·a·remaining)``, down to ``min_speed_m_s`` just before the target.
    """

    def __init__(self, moves: Sequence[Move], settings: RecorderSettings, wheel_base_m: float = WHEEL_BASE_M):
        super().__init__(settings, wheel_base_m)
        self.moves = list(moves)
        self.index = 0
        self._progress = 0.0
        self._settle_until: float | None = None

    def advance(self, distance_m: float, angle_rad: float) -> None:
        if self.index < len(self.moves):
            self._progress += distance_m if self.moves[self.index].kind == "forward" else angle_rad

    def command(self, now_s: float, unread: tuple[float, float] = (0.0, 0.0)) -> tuple[float, float] | None:
        """Wheel speeds now; ``unread`` is the (distance, angle) the robot has made since its
        last reading, as predicted from the commands (the Create 1, read every 0.1 s)."""
        if self._settle_until is not None:
            if now_s < self._settle_until - SAME_TIME_S:
                return self._ramp((0.0, 0.0), now_s)
            self._settle_until = None
            self.index += 1
            self._progress = 0.0
        if self.index >= len(self.moves):
            return None
        move = self.moves[self.index]
        remaining = move.amount - self._progress - (unread[0] if move.kind == "forward" else unread[1])
        s = self.s
        if move.kind == "forward":
            done = remaining * math.copysign(1.0, move.amount) <= s.tolerance_m
            speed = stopping_speed_m_s(remaining, s.accel_m_s2, s.speed_m_s, s.min_speed_m_s)
            wheels = (math.copysign(speed, remaining),) * 2
        else:
            done = remaining * math.copysign(1.0, move.amount) <= s.tolerance_rad
            half_base = 0.5 * self.wheel_base_m
            speed = stopping_speed_m_s(remaining * half_base, s.accel_m_s2, s.turn_rate_rad_s * half_base,
                                       s.min_speed_m_s)
            wheel = math.copysign(speed, remaining)
            wheels = (-wheel, wheel)
        if done:
            self._settle_until = now_s + s.settle_s
            return self._ramp((0.0, 0.0), now_s)
        return self._ramp((1000.0 * wheels[0], 1000.0 * wheels[1]), now_s)


class KeySource(Protocol):
    def read_key(self) -> str | None:
        """The next key pressed, or None; never blocks."""


class TerminalKeys:
    """Keys from a terminal, unbuffered (raw mode) while the block runs.

    Arrow keys arrive as escape sequences and are returned as ``up``, ``down``, ``left``,
    ``right``; other keys as the character.
    """

    _ARROWS = {"A": "up", "B": "down", "C": "right", "D": "left"}

    def __init__(self, stream=None):
        self.stream = stream or sys.stdin
        self._saved = None

    def __enter__(self) -> "TerminalKeys":
        import termios
        import tty

        if not self.stream.isatty():
            raise FgslamError("teleop reads the keyboard: run it in a terminal (stdin is not a TTY)")
        fd = self.stream.fileno()
        self._saved = termios.tcgetattr(fd)
        tty.setcbreak(fd)
        return self

    def __exit__(self, *exc: object) -> None:
        import termios

        if self._saved is not None:
            termios.tcsetattr(self.stream.fileno(), termios.TCSADRAIN, self._saved)

    def _char(self) -> str | None:
        fd = self.stream.fileno()
        if not select.select([fd], [], [], 0)[0]:
            return None
        return os.read(fd, 1).decode("latin-1")

    def read_key(self) -> str | None:
        c = self._char()
        if c == "\x1b" and self._char() == "[":
            return self._ARROWS.get(self._char() or "", None)
        return c


TELEOP_HELP = "teleop keys: w/↑ faster, s/↓ slower (back), a/← left, d/→ right, space stop, q quit"


class TeleopController(_Controller):
    """Keyboard driving: speed and turn rate change in steps and stay until changed.

    w/up +0.05 m/s, s/down −0.05 m/s, a/left +0.2 rad/s, d/right −0.2 rad/s, space stops,
    q quits (after the settle time). Speeds are limited to the settings' ``speed_m_s`` and
    ``turn_rate_rad_s``.
    """

    def __init__(self, keys: KeySource, settings: RecorderSettings, wheel_base_m: float = WHEEL_BASE_M):
        super().__init__(settings, wheel_base_m)
        self.keys = keys
        self.speed_m_s = 0.0
        self.turn_rad_s = 0.0
        self._quit_at: float | None = None

    def advance(self, distance_m: float, angle_rad: float) -> None:
        pass

    def command(self, now_s: float, unread: tuple[float, float] = (0.0, 0.0)) -> tuple[float, float] | None:
        key = self.keys.read_key()
        while key is not None and self._quit_at is None:
            if key in ("w", "up"):
                self.speed_m_s += 0.05
            elif key in ("s", "down"):
                self.speed_m_s -= 0.05
            elif key in ("a", "left"):
                self.turn_rad_s += 0.2
            elif key in ("d", "right"):
                self.turn_rad_s -= 0.2
            elif key in (" ", "x"):
                self.speed_m_s = self.turn_rad_s = 0.0
            elif key in ("q", "\x03"):
                self.speed_m_s = self.turn_rad_s = 0.0
                self._quit_at = now_s + self.s.settle_s
            key = self.keys.read_key()
        if self._quit_at is not None:
            return None if now_s >= self._quit_at - SAME_TIME_S else self._ramp((0.0, 0.0), now_s, limit_slowing=True)
        self.speed_m_s = max(-self.s.speed_m_s, min(self.s.speed_m_s, round(self.speed_m_s, 6)))
        self.turn_rad_s = max(-self.s.turn_rate_rad_s, min(self.s.turn_rate_rad_s, round(self.turn_rad_s, 6)))
        half = 0.5 * self.turn_rad_s * self.wheel_base_m
        target = (1000.0 * (self.speed_m_s - half), 1000.0 * (self.speed_m_s + half))
        return self._ramp(target, now_s, limit_slowing=True)
