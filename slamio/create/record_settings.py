"""What a recording is set to and what it gives back: the :class:`RecorderSettings`, the
run-log header of a recording (:func:`make_header`), the :class:`RecordResult` and its
status file (:func:`status_of`). :func:`slamio.create.record.record` uses them all.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any, Sequence

from slamio.create.link import ShutdownReport
from slamio.create.odometry import WHEEL_BASE_M, OdometryNoise
from slamio.create.safety import StopReason
from slamio.errors import FgslamError
from slamio.log import Header

__all__ = ["RECORDER_VERSION", "SAME_TIME_S", "RecorderSettings", "RecordResult", "make_header", "status_of"]

RECORDER_VERSION = 1

#: Robot times closer than this are the same instant: a stamp difference of one 15 ms stream
#: period can come out as 0.01499999… in floating point, and a comparison against the period
#: must not depend on where the run's clock started.
SAME_TIME_S = 1e-9


@dataclass(frozen=True)
class RecorderSettings:
    """Speeds, periods and limits of a recording. Times marked (robot) use the recorder's
    clock (the simulator's when simulated); (wall) ones the computer's.

    How a run may end besides its controller finishing:

    * ``duration_s`` (robot): the drive is as long as this, counted from the robot's first
      answer (starting the robot is not part of it) — when it has passed, the run ends
      normally (kind ``completed``, exit status 0), the stop confirmed as at any end. For a
      controller that never finishes by itself (a navigator exploring);
    * ``max_duration_s`` (robot): a safety cap, counted from the recorder's start (the log's
      stamps) — a run still going then is stopped early (kind ``time-limit``, a fault, exit
      status 2);
    * ``bump_ends_run`` (default True: every recording and ``fgslam live --path``): a bump
      ends the run. False (a robot that navigates by itself): a bump stops the wheels at once
      and is logged as an ``event`` record and counted (:attr:`RecordResult.bumps`); the
      controller is told (its optional ``bumper_changed(state, now_s)``), and while a bumper is
      pressed only commands that do not drive forward are obeyed — reversing, turning in place
      (:mod:`slamio.create.bumper`) — a forward one is replaced by a stop. Wheel drops and a
      cliff (the robot leaving Safe mode) end the run either way.
    """

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
    max_duration_s: float | None = None  # (robot) stop after this long, a fault (time-limit)
    bump_debounce: int = 2  # readings in a row that must show a bump or wheel drop
    duration_s: float | None = None  # (robot) end normally (completed) after this long
    bump_ends_run: bool = True  # False: a bump stops the wheels, is logged, and the run goes on

    def __post_init__(self):
        if self.mode not in ("safe", "full"):
            raise FgslamError(f"mode must be safe or full, got {self.mode!r}")
        for name in ("speed_m_s", "turn_rate_rad_s", "accel_m_s2", "record_period_s", "poll_period_s",
                     "command_timeout_s", "data_timeout_s"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise FgslamError(f"{name} must be a positive number, got {value!r}")
        for name in ("duration_s", "max_duration_s"):
            value = getattr(self, name)
            if value is not None and not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise FgslamError(f"{name} must be a positive number of seconds or None, got {value!r}")
        if not isinstance(self.bump_ends_run, bool):
            raise FgslamError(f"bump_ends_run must be True or False, got {self.bump_ends_run!r}")
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
    bumps: int = 0  # bumper presses the run went on after (RecorderSettings.bump_ends_run False)
    started_s: float | None = None  # robot time the drive began (the robot answered); None: it never did

    @property
    def completed(self) -> bool:
        return not self.reason.is_fault


def status_of(result: RecordResult) -> dict[str, Any]:
    """The recording's result (the stop reason first) as the JSON object of its status file
    (``fgslam record`` writes it next to the log)."""
    return {
        "reason": {"kind": result.reason.kind, "message": result.reason.message},
        "log": result.out_path,
        "records": result.records,
        "duration_s": result.duration_s,
        "distance_m": result.distance_m,
        "angle_rad": result.angle_rad,
        "final_pose": list(result.final_pose),
        "bumps": result.bumps,
        "link": result.link_stats,
        "shutdown": None if result.shutdown is None else {**asdict(result.shutdown),
                                                           "summary": result.shutdown.summary},
        **({"signal": result.signum} if result.signum is not None else {}),
    }


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
