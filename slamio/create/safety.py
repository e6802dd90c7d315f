"""When to stop the Create, and remembering why.

The Open Interface itself protects little: in Safe mode the robot stops on a cliff, a wheel
drop or the charger, but **not on a bump**, and it has **no command timeout** — a Create
keeps executing its last drive command for ever if the host dies or the cable is pulled.
So the host watches:

* **bump** or **wheel drop** (packet 7), seen in ``debounce`` consecutive readings (one
  bad frame that slipped through the checksum must not stop a run, a real bumper stays
  pressed). With ``bump_ends_run=False`` (a robot that navigates by itself) a bump stops
  the wheels at once but does not end the run: it is counted, kept as an event, and the
  driver may back away (:mod:`slamio.create.bumper`); a wheel drop still ends it;
* **mode**: the robot left Safe/Full by itself (packet 35 went to Passive: cliff, wheel
  drop, charger, or the robot was reset);
* **watchdog**: the host loop stopped sending commands for ``command_timeout_s`` (a hang,
  a stuck write, a paused debugger) — a background thread stops the motors by itself;
* **no-data**: no valid sensor reading for ``data_timeout_s`` (cable pulled, robot off,
  wrong baud rate, too much corruption);
* **interrupted**: SIGHUP, SIGINT (Ctrl-C), SIGQUIT or SIGTERM
  (:class:`slamio.create.signals.TerminationSignals`);
* **serial-error**: the port failed (USB adapter unplugged);
* **log-error**: the log could not be written (a full disk): the robot stops rather than
  drive on unrecorded.

:class:`SafetyMonitor` keeps the first reason (:class:`StopReason`) and sends the stop at
once (``stop_motors``, normally Drive Direct 0 0). The recorder returns that reason, prints
it and writes it next to the log. The hazards it sees in the readings — a bump, a wheel
drop, the robot leaving Safe mode for Passive by itself (a cliff) — wait in
:attr:`SafetyMonitor.events` for the recorder to write them to the log as ``event`` records.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass
from typing import Callable, Mapping

from slamio.create.bumper import BumperWatch, bumper_state
from slamio.create.protocol import OiMode, decode_bumps_and_drops

__all__ = [
    "StopReason",
    "STOP_KINDS",
    "hazard_from_bumps",
    "hazard_from_mode",
    "implausible_frame",
    "implausible_encoder_jump",
    "implausible_create1_reading",
    "event_of",
    "SafetyMonitor",
]

#: Every kind of stop; ``completed`` and ``quit`` are the normal ends of a run.
STOP_KINDS = (
    "completed", "quit", "bump", "wheel-drop", "mode", "watchdog", "no-data",
    "interrupted", "serial-error", "time-limit", "log-error",
)


@dataclass(frozen=True)
class StopReason:
    """Why a run ended: a ``kind`` from :data:`STOP_KINDS` and a message for the user."""

    kind: str
    message: str

    def __post_init__(self):
        if self.kind not in STOP_KINDS:
            raise ValueError(f"unknown stop kind {self.kind!r}")

    @property
    def is_fault(self) -> bool:
        """True for every stop that is not the normal end of the run."""
        return self.kind not in ("completed", "quit")

    def __str__(self) -> str:
        return f"{self.kind}: {self.message}"


def hazard_from_bumps(packet7: int) -> StopReason | None:
    """The stop that packet 7's byte asks for, if any (a wheel drop before a bump)."""
    b = decode_bumps_and_drops(packet7)
    if b.any_wheel_drop:
        which = [name for name, on in (("left", b.wheel_drop_left), ("right", b.wheel_drop_right),
                                       ("caster", b.wheel_drop_caster)) if on]
        return StopReason("wheel-drop", f"{' and '.join(which)} wheel dropped (robot lifted or over an edge)")
    if b.any_bump:
        which = "both bumpers" if b.bump_left and b.bump_right else ("left bumper" if b.bump_left else "right bumper")
        return StopReason("bump", f"{which} pressed (ran into something)")
    return None


def hazard_from_mode(mode: int, expected: OiMode) -> StopReason | None:
    """A stop when the OI mode (packet 35) is no longer the one the host set."""
    if mode == expected:
        return None
    try:
        name = OiMode(mode).name.lower()
    except ValueError:
        name = f"unknown mode {mode}"
    return StopReason(
        "mode",
        f"the robot left {expected.name.lower()} mode and is now in {name} "
        "(cliff, wheel drop, charger, low battery or a reset)",
    )


def implausible_frame(values: Mapping[int, int], model: str) -> str | None:
    """Why a checksum-valid reading cannot be real, or None.

    Reserved bits of packet 7 set (bits 4–7 on the Create 2, 5–7 on the Create 1) or an
    OI mode above 3 mean the bytes were damaged in a way the 8-bit checksum missed.
    """
    reserved = 0xF0 if model == "create2" else 0xE0
    if 7 in values and values[7] & reserved:
        return f"packet 7 has reserved bits set ({values[7]:#04x})"
    if 35 in values and values[35] > 3:
        return f"packet 35 (OI mode) is {values[35]}, not 0–3"
    return None


def implausible_encoder_jump(delta_counts: int, elapsed_s: float, mm_per_count: float,
                             max_wheel_speed_m_s: float = 0.5) -> str | None:
    """Why an encoder change cannot be real, or None.

    A wheel cannot turn faster than the Create's 0.5 m/s; allowed is 1.5 × that over the
    time since the previous accepted reading (at least one 15 ms frame) plus 5 mm. A
    damaged byte that the checksum missed usually moves a count by far more.
    """
    allowed_counts = (1.5 * max_wheel_speed_m_s * max(elapsed_s, 0.015) + 0.005) * 1000.0 / mm_per_count
    if abs(delta_counts) > allowed_counts:
        return f"encoder jumped {delta_counts} counts in {elapsed_s:.3f} s (at most {allowed_counts:.0f} possible)"
    return None


def implausible_create1_reading(distance_mm: int, angle_deg: int, elapsed_s: float,
                                max_wheel_speed_m_s: float = 0.5, wheel_base_m: float = 0.235) -> str | None:
    """Why a Create 1 distance/angle answer (no checksum) cannot be real, or None.

    Allowed: 1.5 × the fastest possible motion over the time since the previous read, plus
    5 mm or 5°.
    """
    elapsed = max(elapsed_s, 0.015)
    max_mm = 1.5 * max_wheel_speed_m_s * elapsed * 1000.0 + 5.0
    max_deg = math.degrees(1.5 * 2.0 * max_wheel_speed_m_s / wheel_base_m * elapsed) + 5.0
    if abs(distance_mm) > max_mm:
        return f"distance {distance_mm} mm in {elapsed:.3f} s (at most {max_mm:.0f} possible)"
    if abs(angle_deg) > max_deg:
        return f"angle {angle_deg}° in {elapsed:.3f} s (at most {max_deg:.0f} possible)"
    return None


def event_of(hazard: StopReason, values: Mapping[int, int]) -> tuple[str, str | None] | None:
    """The log event ``(kind, side)`` of a hazard seen in the reading ``values``: a bump, a
    wheel drop, or a cliff (the robot left Safe mode for Passive without a wheel drop: the OI
    does so at a drop in the floor, and on the charger); None for the other stops."""
    if hazard.kind == "bump":
        return "bump", bumper_state(values.get(7, 0)).side
    if hazard.kind == "wheel-drop":
        b = decode_bumps_and_drops(values.get(7, 0))
        left, right = b.wheel_drop_left, b.wheel_drop_right
        return "wheel-drop", "both" if left and right else ("left" if left else ("right" if right else None))
    if hazard.kind == "mode" and values.get(35) == OiMode.PASSIVE:
        return "cliff", None
    return None


class SafetyMonitor:
    """Trips once, stops the motors at once, remembers why; watches two timeouts.

    ``stop_motors`` is called (from whichever thread trips) with no arguments; exceptions
    from it are kept in :attr:`stop_errors` instead of raised. Call :meth:`command_sent`
    whenever the host sends a drive command and :meth:`readings` with every sensor
    reading. :meth:`start` runs the watchdog thread (use the monitor as a context manager).
    ``expected_mode`` None skips the mode check (until the host has seen the mode it set).
    Timeouts are in wall-clock seconds (``wall_clock``): they are about the host being
    alive, not about robot time.

    ``bump_ends_run`` False: a bump does not trip the monitor. On each new press (debounced
    like every hazard, :class:`slamio.create.bumper.BumperWatch` in :attr:`bumper`) it calls
    ``stop_motors`` at once, counts the stop in :attr:`bump_stops` and adds the event; the
    caller keeps its commands away from the bumper while :attr:`bumper` shows it pressed
    (:func:`slamio.create.bumper.away_from_bumper`). :attr:`events` collects ``(kind, side)``
    of every hazard seen in the readings (:func:`event_of`); :meth:`take_events` empties it.
    """

    def __init__(self, stop_motors: Callable[[], None], *, command_timeout_s: float = 0.5,
                 data_timeout_s: float = 0.5, debounce: int = 2, model: str = "create2",
                 expected_mode: OiMode | None = OiMode.SAFE, wall_clock: Callable[[], float] = time.monotonic,
                 bump_ends_run: bool = True):
        self._stop_motors = stop_motors
        self.command_timeout_s = command_timeout_s
        self.data_timeout_s = data_timeout_s
        self.debounce = max(1, int(debounce))
        self.model = model
        self.expected_mode = expected_mode
        self._wall = wall_clock
        self._lock = threading.Lock()
        self._reason: StopReason | None = None
        self.tripped = threading.Event()
        self.stop_errors: list[str] = []
        now = wall_clock()
        self._last_command = now
        self._last_data = now
        self._hazard_streak: dict[str, int] = {}
        self._thread: threading.Thread | None = None
        self._quit = threading.Event()
        self.bump_ends_run = bump_ends_run
        self.bumper = BumperWatch(self.debounce)
        self.bump_stops = 0  # stops sent for a bump that did not end the run
        self.events: list[tuple[str, str | None]] = []  # (kind, side) seen in the readings, not yet logged

    @property
    def reason(self) -> StopReason | None:
        return self._reason

    def trip(self, reason: StopReason) -> bool:
        """Stop the motors and keep ``reason`` if it is the first; True if it was."""
        with self._lock:
            first = self._reason is None
            if first:
                self._reason = reason
        if first:
            try:
                self._stop_motors()
            except Exception as exc:  # the reason is kept; the caller tries again at shutdown
                self.stop_errors.append(f"{type(exc).__name__}: {exc}")
            self.tripped.set()
        return first

    def command_sent(self) -> None:
        self._last_command = self._wall()

    def take_events(self) -> list[tuple[str, str | None]]:
        """The events seen since the last call, oldest first (called from the reading thread)."""
        events, self.events = self.events, []
        return events

    def _stop_for_bump(self) -> None:
        """A new press with ``bump_ends_run`` False: the wheels stop now, the run goes on."""
        try:
            self._stop_motors()
        except Exception as exc:  # kept as trip() keeps it; the loop's next command or the shutdown retries
            self.stop_errors.append(f"{type(exc).__name__}: {exc}")
        self.bump_stops += 1
        self.events.append(("bump", self.bumper.state.side))

    def readings(self, values: Mapping[int, int]) -> StopReason | None:
        """Check one sensor reading; trips (and returns the reason) on a hazard."""
        self._last_data = self._wall()
        hazards = []
        if 7 in values:
            hazard = hazard_from_bumps(values[7])
            if hazard is not None and (self.bump_ends_run or hazard.kind != "bump"):
                hazards.append(hazard)
            if not self.bump_ends_run:
                presses = self.bumper.presses
                self.bumper.reading(values[7])
                if self.bumper.presses > presses:
                    self._stop_for_bump()
        if 35 in values and self.expected_mode is not None:
            hazard = hazard_from_mode(values[35], self.expected_mode)
            if hazard is not None:
                hazards.append(hazard)
        seen = {h.kind for h in hazards}
        self._hazard_streak = {k: self._hazard_streak.get(k, 0) + 1 for k in seen}
        for hazard in hazards:
            if self._hazard_streak[hazard.kind] >= self.debounce:
                if self.trip(hazard):
                    event = event_of(hazard, values)
                    if event is not None:
                        self.events.append(event)
                return hazard
        return None

    def check_timeouts(self) -> StopReason | None:
        """Trip on the watchdog or the data timeout; called by the thread, also callable."""
        now = self._wall()
        if now - self._last_command > self.command_timeout_s:
            reason = StopReason(
                "watchdog",
                f"no drive command from the host for {now - self._last_command:.2f} s "
                f"(limit {self.command_timeout_s} s): the control loop hung",
            )
        elif now - self._last_data > self.data_timeout_s:
            reason = StopReason(
                "no-data",
                f"no valid sensor reading for {now - self._last_data:.2f} s (limit {self.data_timeout_s} s): "
                "cable, power, baud rate?",
            )
        else:
            return None
        self.trip(reason)
        return reason

    def _watch(self) -> None:
        period = max(0.005, 0.1 * min(self.command_timeout_s, self.data_timeout_s))
        while not self._quit.wait(period) and not self.tripped.is_set():
            self.check_timeouts()

    def start(self) -> "SafetyMonitor":
        now = self._wall()
        self._last_command = self._last_data = now
        if self._thread is None:
            self._thread = threading.Thread(target=self._watch, name="create-watchdog", daemon=True)
            self._thread.start()
        return self

    def close(self) -> None:
        self._quit.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None

    def __enter__(self) -> "SafetyMonitor":
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()
