"""The recorder: drive a Create along a path and write its odometry to a run log.

``fgslam record`` calls :func:`record`. It

1. opens the link (a :class:`~slamio.create.link.CreateLink`, whose exit always stops the
   wheels and puts the OI back in Passive mode), sends Start and Safe (or Full);
2. reads the robot — Create 2: a stream of packets 7, 35, 43, 44 every 15 ms, checksummed
   (:class:`~slamio.create.protocol.StreamParser`); Create 1: a Query List of packets 7,
   35, 19, 20 every ``poll_period_s`` (0.1 s: reading it less often is half the 1° angle
   workaround, see :mod:`slamio.create.odometry`);
3. drives a scripted path — a square or an octagon, turning left in place at each corner,
   open loop on the odometry, wheel speeds rising at most at ``accel_m_s2`` and falling along
   the stopping curve ``sqrt(2·a·remaining)`` — or follows the keyboard (teleop);
4. writes one odometry record every ``record_period_s`` (0.1 s) to the log, **flushed to
   the operating system after each record**, so a recorder killed at any moment (even by
   SIGKILL) leaves every record but possibly the one being written; ``read_log`` drops a
   cut-off last line and says so;
5. stops on the first hazard (:mod:`slamio.create.safety`: bump, wheel drop, mode change,
   watchdog, no data, Ctrl-C/SIGINT/SIGTERM, serial error), keeps the log, and returns the
   :class:`~slamio.create.safety.StopReason` in a :class:`RecordResult`. SIGINT stops the
   robot even in a recorder started with ``&`` from a script, which inherits SIGINT ignored
   (:func:`interrupt_guard`).

The scripted paths stop (``settle_s``) between a straight and a turn: a Create 2 encoder
counts in the commanded direction, so a wheel reversed while still rolling would count the
wrong way.
"""

from __future__ import annotations

import json
import math
import os
import select
import sys
import time
from dataclasses import asdict, dataclass, field
from typing import Any, Callable, Protocol, Sequence

from slamio.create import protocol
from slamio.create.link import CreateLink, LinkError, ShutdownReport
from slamio.create.odometry import (
    WHEEL_BASE_M,
    Create1Odometry,
    Create2Odometry,
    OdometryNoise,
    default_noise,
)
from slamio.create.protocol import OiMode, StreamParser
from slamio.create.odometry import CREATE2_MM_PER_COUNT, counts_delta
from slamio.create.safety import (
    SafetyMonitor,
    StopReason,
    implausible_create1_reading,
    implausible_encoder_jump,
    implausible_frame,
)
from slamio.create.signals import Interrupted, TerminationSignals, describe_signal, guarded
from slamio.errors import FgslamError
from slamio.geometry import compose_pose
from slamio.log import Header, LogWriter
from slamio.log.pending import LogWriteError, PendingLogWriter

__all__ = [
    "PATHS",
    "Move",
    "polygon_moves",
    "path_moves",
    "RecorderSettings",
    "RecordResult",
    "PathController",
    "TeleopController",
    "TerminalKeys",
    "make_header",
    "record",
    "RecordHooks",
    "write_status",
    "STREAM_IDS",
    "POLL_IDS",
]

RECORDER_VERSION = 1
PATHS = ("square", "octagon", "teleop")
DEFAULT_SIDE_M = {"square": 1.0, "octagon": 0.5}
STREAM_IDS = (7, 35, 43, 44)  # Create 2: bumps/drops, OI mode, left and right encoder counts
POLL_IDS = (7, 35, 19, 20)  # Create 1: bumps/drops, OI mode, distance, angle

#: Robot times closer than this are the same instant: a stamp difference of one 15 ms stream
#: period can come out as 0.01499999… in floating point, and a comparison against the period
#: must not depend on where the run's clock started.
SAME_TIME_S = 1e-9


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


# --------------------------------------------------------------------------- settings


@dataclass(frozen=True)
class RecorderSettings:
    """Speeds, periods and limits of a recording. Times marked (robot) use the recorder's
    clock (the simulator's when simulated); (wall) ones the computer's."""

    speed_m_s: float = 0.2  # straight segments
    turn_rate_rad_s: float = 0.8  # turns in place (wheels at ±0.094 m/s)
    accel_m_s2: float = 0.4  # wheel speed changes at most this fast (speeding up and slowing down)
    min_speed_m_s: float = 0.02  # the slowest wheel speed before the end of a move
    tolerance_m: float = 0.0005
    tolerance_rad: float = 0.002
    settle_s: float = 0.3  # (robot) standing still between moves and at the end
    record_period_s: float = 0.1  # (robot) one odometry record per period
    poll_period_s: float = 0.1  # (robot) Create 1: one Query List per period
    command_interval_s: float = 0.015  # (robot) send a changed command at most this often
    command_refresh_s: float = 0.1  # (wall) resend the drive command at least this often
    command_timeout_s: float = 0.5  # (wall) watchdog: no command for this long → stop
    data_timeout_s: float = 0.5  # (wall) no valid reading for this long → stop
    startup_timeout_s: float = 3.0  # (wall) wait this long for the robot to answer
    mode: str = "safe"  # safe or full
    max_duration_s: float | None = None  # (robot) stop after this long
    bump_debounce: int = 2  # readings in a row that must show a bump or wheel drop

    def __post_init__(self):
        if self.mode not in ("safe", "full"):
            raise FgslamError(f"mode must be safe or full, got {self.mode!r}")
        for name in ("speed_m_s", "turn_rate_rad_s", "accel_m_s2", "record_period_s", "poll_period_s",
                     "command_timeout_s", "data_timeout_s"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise FgslamError(f"{name} must be a positive number, got {value!r}")
        if self.speed_m_s > 0.5:
            raise FgslamError(f"speed_m_s {self.speed_m_s} is above the Create's 0.5 m/s")


@dataclass(frozen=True)
class RecordResult:
    """What a recording did and why it ended."""

    reason: StopReason
    out_path: str
    records: int
    duration_s: float
    distance_m: float  # Σ|distance| of the written records
    angle_rad: float  # Σ|angle| of the written records
    final_pose: tuple[float, float, float]  # dead reckoning from (0, 0, 0)
    link_stats: dict[str, Any] = field(default_factory=dict)
    shutdown: ShutdownReport | None = None
    log_placed: bool = True  # False: the robot never answered, ``out_path`` is as it was
    signum: int | None = None  # the signal that stopped the recording, if one did

    @property
    def completed(self) -> bool:
        return not self.reason.is_fault

    @property
    def robot_confirmed_stopped(self) -> bool:
        return self.shutdown is not None and self.shutdown.confirmed


def write_status(result: RecordResult, path: str | os.PathLike[str], extra: dict[str, Any] | None = None) -> None:
    """Write the result (the stop reason first) as JSON next to the log, through a temporary
    file and a rename (an interrupted write never leaves half a status)."""
    d = {
        "reason": {"kind": result.reason.kind, "message": result.reason.message},
        "log": result.out_path,
        "records": result.records,
        "duration_s": result.duration_s,
        "distance_m": result.distance_m,
        "angle_rad": result.angle_rad,
        "final_pose": list(result.final_pose),
        "link": result.link_stats,
        "shutdown": None if result.shutdown is None else {**asdict(result.shutdown),
                                                           "summary": result.shutdown.summary},
        **({"signal": result.signum} if result.signum is not None else {}),
        **(extra or {}),
    }
    tmp = f"{os.fspath(path)}.{os.getpid()}.tmp"
    try:
        with open(tmp, "w", encoding="utf-8") as f:
            json.dump(d, f, indent=2)
            f.write("\n")
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


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


class PathController:
    """Open-loop-on-odometry driver of a list of :class:`Move` (forward/rotate in place).

    :meth:`advance` adds each reading's (distance, angle); :meth:`command` returns the
    (left, right) wheel speeds in mm/s, or None when the path is done (after the last
    settle). Wheel speeds rise at most at ``accel_m_s2`` and fall along the stopping curve
    ``sqrt(2·a·remaining)``, down to ``min_speed_m_s`` just before the target.
    """

    def __init__(self, moves: Sequence[Move], settings: RecorderSettings, wheel_base_m: float = WHEEL_BASE_M):
        self.moves = list(moves)
        self.s = settings
        self.wheel_base_m = wheel_base_m
        self.index = 0
        self._progress = 0.0
        self._settle_until: float | None = None
        self._ramp = WheelRamp(settings.accel_m_s2)

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


class TeleopController:
    """Keyboard driving: speed and turn rate change in steps and stay until changed.

    w/up +0.05 m/s, s/down −0.05 m/s, a/left +0.2 rad/s, d/right −0.2 rad/s, space stops,
    q quits (after the settle time). Speeds are limited to the settings' ``speed_m_s`` and
    ``turn_rate_rad_s``.
    """

    def __init__(self, keys: KeySource, settings: RecorderSettings, wheel_base_m: float = WHEEL_BASE_M):
        self.keys = keys
        self.s = settings
        self.wheel_base_m = wheel_base_m
        self.speed_m_s = 0.0
        self.turn_rad_s = 0.0
        self._quit_at: float | None = None
        self._ramp = WheelRamp(settings.accel_m_s2)

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


# --------------------------------------------------------------------------- readers


class _StreamReader:
    """Create 2: stream frames, checksum, plausibility (reserved bits, mode, encoder jumps)."""

    def __init__(self, link: CreateLink, model: str, ids: Sequence[int] = STREAM_IDS):
        self.link, self.model, self.ids = link, model, list(ids)
        self.parser = StreamParser(self.ids)
        self.implausible = 0
        self._last: tuple[float, int, int] | None = None  # (time, left, right) of the last accepted frame

    def _implausible(self, values: dict[int, int], now_s: float) -> str | None:
        why = implausible_frame(values, self.model)
        if why is None and self._last is not None and 43 in values:
            t, left, right = self._last
            for new, old in ((values[43], left), (values[44], right)):
                why = why or implausible_encoder_jump(counts_delta(new, old), now_s - t, CREATE2_MM_PER_COUNT)
        return why

    def setup(self) -> None:
        self.link.write(protocol.stream(self.ids))

    def poll(self, now_s: float, tap: Callable | None) -> list[dict[int, int]]:
        out = []
        for frame in self.parser.feed(self.link.read()):
            if self._implausible(frame.values, now_s):
                self.implausible += 1
                continue
            if 43 in frame.values:
                self._last = (now_s, frame.values[43], frame.values[44])
            if tap is not None:
                tap(frame)
            out.append(frame.values)
        return out

    def stamp(self, now_s: float) -> float:
        return now_s

    def stats(self) -> dict[str, Any]:
        return {"reader": "stream", "packets": self.ids, **self.parser.stats(), "implausible_frames": self.implausible}


class _PollReader:
    """Create 1: a Query List every ``period_s`` (robot time); no checksum in the answer."""

    def __init__(self, link: CreateLink, model: str, period_s: float, ids: Sequence[int] = POLL_IDS):
        self.link, self.model, self.period_s, self.ids = link, model, period_s, list(ids)
        self.size = protocol.query_response_size(self.ids)
        self._next_s: float | None = None
        self._asked_s: float | None = None
        self.answers = 0
        self.lost = 0
        self.implausible = 0

    def setup(self) -> None:
        self.link.discard_input()

    def poll(self, now_s: float, tap: Callable | None) -> list[dict[int, int] | None]:
        """A list with the answer's values, [None] for a lost answer, [] when not due."""
        if self._next_s is not None and now_s < self._next_s:
            time.sleep(0.001)
            return []
        self._next_s = now_s + self.period_s
        elapsed = None if self._asked_s is None else now_s - self._asked_s
        self._asked_s = now_s
        self.link.write(protocol.query_list(self.ids))
        data = self.link.read_exactly(self.size, timeout_s=max(0.05, 2 * self.link.timeout_s))
        if len(data) != self.size:
            self.lost += 1
            self.link.discard_input()
            return [None]
        values = protocol.decode_query_response(self.ids, data)
        why = implausible_frame(values, self.model)
        if why is None and elapsed is not None:
            why = implausible_create1_reading(values[19], values[20], elapsed)
        if why:
            self.implausible += 1
            return [None]
        self.answers += 1
        if tap is not None:
            tap(values)
        return [values]

    def stamp(self, now_s: float) -> float:
        """When the robot took the reading: when it was asked for (it answers at once)."""
        return now_s if self._asked_s is None else self._asked_s

    def stats(self) -> dict[str, Any]:
        return {"reader": "poll", "packets": self.ids, "period_s": self.period_s, "answers": self.answers,
                "lost_answers": self.lost, "implausible_answers": self.implausible}


# --------------------------------------------------------------------------- recording


def make_header(model: str, port: str, baud: int, noise: OdometryNoise, settings: RecorderSettings,
                source: dict[str, Any] | None = None, observation_noise: dict[str, Any] | None = None,
                *, start_pose: Sequence[float] = (0.0, 0.0, 0.0), sensor: dict[str, Any] | None = None,
                calibration: dict[str, Any] | None = None) -> Header:
    """The run-log header of a recording: start pose (0, 0, 0) defines the world frame unless
    the caller knows where the robot starts in its map (the live loop). ``calibration`` (what
    ``fgslam calibrate TRIALS.csv`` wrote) goes to ``noise.calibration``, where seed 001's
    EKF takes its R and Q from."""
    if model == "create2":
        odometry = "encoder counts (packets 43/44) streamed every 15 ms"
    else:
        odometry = (f"distance/angle (packets 19/20) polled every {settings.poll_period_s} s; "
                    "commanded motion clamped into each reading's 1 mm / 1 deg truncation interval")
    return Header(
        stamp_s=0.0,
        start_pose=tuple(float(v) for v in start_pose),  # type: ignore[arg-type]
        start_sigma=(1e-3, 1e-3, 1e-3),
        robot={
            "name": "iRobot Create 2" if model == "create2" else "iRobot Create",
            "model": model,
            "drive": "differential",
            "wheel_base_m": WHEEL_BASE_M,
            "port": port,
            "baud": baud,
            "oi_mode": settings.mode,
            "odometry": odometry,
            "speed_m_s": settings.speed_m_s,
            "turn_rate_rad_s": settings.turn_rate_rad_s,
            "record_period_s": settings.record_period_s,
        },
        sensor=sensor or {"kind": "none", "note": "odometry only: this recording has no landmark sensor"},
        noise={
            "odometry": noise.header_dict(),
            "observation": observation_noise or {"model": "none: no landmark sensor in this recording"},
            **({"calibration": calibration} if calibration else {}),
        },
        source={"generator": "slamio.create.record", "recorder_version": RECORDER_VERSION, **(source or {})},
    )


class RecordHooks(Protocol):
    """What :func:`record` asks of a loop that rides on it (``fgslam live``)."""

    def due(self, now_s: float) -> bool:
        """Called every pass of the control loop: write an odometry record now?"""

    def after_record(self, record, log: LogWriter) -> None:
        """Called after each odometry record is written and flushed, from the control loop's
        thread; may write more records (observations) to ``log``."""

    # optional: ``started(log)``, called once the log is open, before the first record;
    # ``passed()``, called at the end of every pass of the control loop (after its command
    # and any record went out) and after every read while waiting for the robot's first answer


def record(
    link: CreateLink,
    out_path: str | os.PathLike[str],
    controller: PathController | TeleopController,
    *,
    settings: RecorderSettings = RecorderSettings(),
    noise: OdometryNoise | None = None,
    clock: Callable[[], float] = time.monotonic,
    source: dict[str, Any] | None = None,
    observation_noise: dict[str, Any] | None = None,
    frame_tap: Callable[[Any], None] | None = None,
    on_record: Callable[[int], None] | None = None,
    hooks: "RecordHooks | None" = None,
    start_pose: Sequence[float] = (0.0, 0.0, 0.0),
    sensor: dict[str, Any] | None = None,
    calibration: dict[str, Any] | None = None,
    overwrite: bool = False,
    signals: TerminationSignals | None = None,
    on_placed: Callable[[], None] | None = None,
) -> RecordResult:
    """Drive ``controller``'s path on the robot behind ``link`` and log the odometry.

    Returns a :class:`RecordResult` whatever happens on the robot side (hazards, a failed
    port, a terminating signal, a full disk); raises :class:`FgslamError` only when the log
    cannot be started. ``clock`` gives the robot time used for stamps and periods (the
    simulator passes its own). ``frame_tap`` sees every accepted reading (tests);
    ``on_record(n)`` is called after the n-th record is flushed. ``hooks`` lets another loop
    ride on this one (the live loop, :mod:`fgslam.live`): it decides when a record is due and
    writes its own records after each odometry record (see :class:`RecordHooks`).

    The log is written beside ``out_path`` and put in place once the robot has answered
    (:class:`slamio.log.pending.PendingLogWriter`; ``overwrite`` lets it replace an existing
    file, ``on_placed()`` is called then): a robot that never answers leaves ``out_path`` as
    it was. ``signals`` (:class:`slamio.create.signals.TerminationSignals`, installed by the
    caller) turns SIGHUP/SIGINT/SIGQUIT/SIGTERM into a stop; None installs one for the
    recording. The stop sequence runs with signals held, so a second one cannot cut it short.
    """
    model = link.model
    noise = noise or default_noise(model)
    target_mode = OiMode.SAFE if settings.mode == "safe" else OiMode.FULL
    header = make_header(model, link.port, link.baud, noise, settings, source, observation_noise,
                         start_pose=start_pose, sensor=sensor, calibration=calibration)
    odometry = Create2Odometry(noise) if model == "create2" else Create1Odometry(noise)
    reader = _StreamReader(link, model) if model == "create2" else _PollReader(link, model, settings.poll_period_s)
    monitor = SafetyMonitor(
        link.stop_motors,
        command_timeout_s=settings.command_timeout_s,
        data_timeout_s=settings.data_timeout_s,
        debounce=settings.bump_debounce if model == "create2" else 1,
        model=model,
        expected_mode=None,
    )
    t0 = clock()
    records = 0
    distance_m = angle_rad = 0.0
    pose = tuple(float(v) for v in start_pose)  # dead-reckoned, for RecordResult.final_pose
    stamp = 0.0
    reason: StopReason | None = None
    signum: int | None = None

    def now_s() -> float:
        return max(stamp, clock() - t0)

    def write_record(log: PendingLogWriter, sig: TerminationSignals) -> None:
        nonlocal records, distance_m, angle_rad, pose, stamp
        with sig.held():  # a written record is always a counted one
            stamp = now_s()
            rec = odometry.take(stamp)
            log.write(rec)
            log.flush()
            records += 1
        if hooks is not None:
            hooks.after_record(rec, log)
        distance_m += abs(rec.distance_m)
        angle_rad += abs(rec.angle_rad)
        pose = compose_pose(pose, (rec.dx_m, rec.dy_m, rec.dtheta_rad))
        if on_record is not None:
            on_record(records)

    def use(values: dict[int, int] | None) -> None:
        t = reader.stamp(now_s())
        if values is None:  # Create 1: lost answer
            d, a = odometry.lost(t)
        else:
            if values.get(35) == target_mode and monitor.expected_mode is None:
                monitor.expected_mode = target_mode
            monitor.readings(values)
            if model == "create2":
                d, a = odometry.update(values[43], values[44])
            else:
                d, a = odometry.update(values[19], values[20], t)
        controller.advance(d, a)

    started = False
    with guarded(signals) as sig, PendingLogWriter(out_path, header, overwrite=overwrite) as log:
        if hooks is not None and hasattr(hooks, "started"):
            hooks.started(log)
        try:
            try:
                link.open()
                link.write(protocol.start())
                link.write(protocol.safe() if target_mode == OiMode.SAFE else protocol.full())
                reader.setup()
                reason = _first_reading(reader, odometry, target_mode, settings, now_s, frame_tap,
                                        getattr(hooks, "passed", None))
                if reason is None:
                    with sig.held():
                        log.place()  # the robot answers: the new log replaces the old one now
                        if on_placed is not None:
                            on_placed()
                    started = True
                    monitor.expected_mode = target_mode
                    reason = _drive(link, reader, odometry, controller, monitor, settings, now_s,
                                    frame_tap, use, lambda: write_record(log, sig), hooks)
                if reason.is_fault:
                    monitor.trip(reason)  # keeps an earlier reason if there is one
            finally:
                _stop_the_robot(link, monitor, sig)
        except LinkError as exc:
            monitor.trip(StopReason("serial-error", str(exc)))
        except LogWriteError as exc:
            monitor.trip(StopReason("log-error", str(exc)))
        except Interrupted as exc:
            signum = exc.signum
            monitor.trip(StopReason("interrupted", f"{describe_signal(exc.signum)}: stopped by a signal"))
        except KeyboardInterrupt:
            monitor.trip(StopReason("interrupted", "KeyboardInterrupt: stopped"))
        reason = monitor.reason or reason  # the first fault wins, whichever thread saw it
        assert reason is not None
        if signum is None and sig.first is not None:  # a signal held during the stop sequence
            signum = sig.first
            if not reason.is_fault:
                reason = StopReason("interrupted", f"{describe_signal(signum)}: came while the robot was stopping")
        if started:
            with sig.held(raise_after=False):
                try:
                    write_record(log, sig)  # whatever moved since the last record
                except LogWriteError as exc:
                    if not reason.is_fault:
                        reason = StopReason("log-error", str(exc))
    stats = {**reader.stats(), "bytes_read": link.bytes_read, "bytes_written": link.bytes_written,
             "reconnects": link.reconnects, "serial_errors": list(link.serial_errors),
             "guardian": link.guardian_note}
    return RecordResult(
        reason=reason,
        out_path=os.fspath(out_path),
        records=records,
        duration_s=stamp,
        distance_m=distance_m,
        angle_rad=angle_rad,
        final_pose=pose,  # type: ignore[arg-type]
        link_stats=stats,
        shutdown=getattr(link, "last_shutdown", None),
        log_placed=log.placed,
        signum=signum,
    )


def _stop_the_robot(link: CreateLink, monitor: SafetyMonitor, sig: TerminationSignals) -> None:
    """The stop sequence with signals held: a second signal cannot cut it short. A first
    signal that lands before the hold is in place is kept (``sig.received``) and the stop
    runs again from the start."""
    while True:
        try:
            with sig.held(raise_after=False):
                monitor.close()
                link.last_shutdown = link.shutdown()
                link.close()
            return
        except Interrupted:
            continue


def _first_reading(reader, odometry, target_mode, settings, now_s, tap, passed=None) -> StopReason | None:
    """Wait for the robot to answer in the requested mode; initialise the odometry
    (``passed()``, if given, after every read)."""
    deadline = time.monotonic() + settings.startup_timeout_s
    seen_mode = None
    while time.monotonic() < deadline:
        readings = reader.poll(now_s(), tap)
        if passed is not None:
            passed()
        for values in readings:
            if values is None:
                continue
            seen_mode = values.get(35)
            if seen_mode != target_mode:
                continue
            if isinstance(odometry, Create2Odometry):
                odometry.update(values[43], values[44])
            else:
                odometry.start(now_s())
            return None
    if seen_mode is None:
        return StopReason(
            "no-data",
            f"no valid answer from the robot within {settings.startup_timeout_s} s: is it switched on, "
            f"is the cable in, is the model right (Create 1: 57600 baud, Create 2: 115200)?",
        )
    return StopReason("mode", f"the robot answers but stays in OI mode {seen_mode}, not {target_mode.name.lower()}")


def _drive(link, reader, odometry, controller, monitor, settings, now_s, tap, use, write_record,
           hooks=None) -> StopReason:
    """The control loop; returns why it ended."""
    last_command: tuple[float, float] | None = None
    last_sent_wall = -math.inf
    last_sent_s = -math.inf
    next_record = settings.record_period_s
    passed = getattr(hooks, "passed", None)
    with monitor:
        while True:
            if monitor.tripped.is_set():
                return monitor.reason  # type: ignore[return-value]
            for values in reader.poll(now_s(), tap):
                use(values)
            if monitor.tripped.is_set():
                return monitor.reason  # type: ignore[return-value]
            t = now_s()
            unread = odometry.unread(t) if isinstance(odometry, Create1Odometry) else (0.0, 0.0)
            wheels = controller.command(t, unread)
            if wheels is None:
                if isinstance(controller, TeleopController):
                    return StopReason("quit", "quit from the keyboard")
                return StopReason("completed", "path driven to the end")
            wall = time.monotonic()
            changed = wheels != last_command and (t - last_sent_s >= settings.command_interval_s - SAME_TIME_S
                                                  or wheels == (0.0, 0.0))
            if changed:
                link.drive_direct(*wheels)
                monitor.command_sent()
                if isinstance(odometry, Create1Odometry):
                    odometry.command(wheels[0], wheels[1], t)
                last_command, last_sent_wall, last_sent_s = wheels, wall, t
            elif last_command is not None and wall - last_sent_wall >= settings.command_refresh_s:
                # keep-alive: the command in force again (a change waits for command_interval_s, which
                # is robot time, so what the robot is told and when does not depend on this machine's speed)
                link.drive_direct(*last_command)
                monitor.command_sent()
                last_sent_wall = wall
            if hooks is not None:
                if hooks.due(t):
                    write_record()
            elif t >= next_record - SAME_TIME_S:
                write_record()
                next_record = t + settings.record_period_s
            if passed is not None:
                passed()
            if settings.max_duration_s is not None and t >= settings.max_duration_s:
                return StopReason("time-limit", f"stopped after the {settings.max_duration_s} s time limit")
