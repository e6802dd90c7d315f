"""The recorder: drive a Create along a path and write its odometry to a run log.

``fgslam record`` calls :func:`record`. It

1. opens the link (a :class:`~slamio.create.link.CreateLink`, whose exit always stops the
   wheels and puts the OI back in Passive mode), sends Start and Safe (or Full);
2. reads the robot — Create 2: a stream of packets 7, 35, 43, 44 every 15 ms, checksummed
   (:class:`~slamio.create.stream_parser.StreamParser`); Create 1: a Query List of packets 7,
   35, 19, 20 every ``poll_period_s`` (0.1 s: reading it less often is half the 1° angle
   workaround, see :mod:`slamio.create.odometry`);
3. drives a scripted path — a square or an octagon, turning left in place at each corner,
   open loop on the odometry, wheel speeds rising at most at ``accel_m_s2`` and falling along
   the stopping curve ``sqrt(2·a·remaining)`` — or follows the keyboard (teleop);
4. writes one odometry record every ``record_period_s`` (0.1 s) to the log, each line
   **handed to the operating system as it is written** (:class:`slamio.log.pending.PendingLogWriter`,
   which also puts the log in place only once the robot has answered), so a recorder killed
   at any moment (even by SIGKILL) leaves every record but possibly the one being written;
   ``read_log`` drops a cut-off last line and says so;
5. writes every bump, wheel drop and cliff it sees as an ``event`` record, just before the
   next odometry record (so every record a hook wrote for the pose before it comes first);
6. stops on the first hazard (:mod:`slamio.create.safety`: bump, wheel drop, mode change,
   watchdog, no data, a terminating signal, serial error, a full disk), keeps the log, and
   returns the :class:`~slamio.create.safety.StopReason` in a :class:`RecordResult`. SIGHUP,
   SIGINT, SIGQUIT and SIGTERM stop the robot even when the recorder inherited them ignored
   (:class:`slamio.create.signals.TerminationSignals`), and the stop is read back from the
   robot (:mod:`slamio.create.stopping`). With ``RecorderSettings.bump_ends_run`` False a bump
   only stops the wheels and the run goes on, its controller kept from driving forward while
   the bumper is pressed (:mod:`slamio.create.bumper`);
7. ends normally (``completed``) when the controller is done, when ``RecorderSettings.duration_s``
   of robot time has passed, or when the hooks say the run is over (``finished``).

The scripted paths stop (``settle_s``) between a straight and a turn: a Create 2 encoder
counts in the commanded direction, so a wheel reversed while still rolling would count the
wrong way.
"""

from __future__ import annotations

import math
import os
import time
from typing import Any, Callable, Protocol, Sequence

from slamio.create import protocol
from slamio.create.bumper import away_from_bumper
from slamio.create.controllers import PathController, TeleopController
from slamio.create.link import CreateLink, LinkError
from slamio.create.odometry import Create1Odometry, Create2Odometry, OdometryNoise, default_noise
from slamio.create.protocol import OiMode
from slamio.create.readers import PollReader, StreamReader
from slamio.create.record_settings import (
    SAME_TIME_S,
    RecorderSettings,
    RecordResult,
    make_header,
)
from slamio.create.safety import SafetyMonitor, StopReason
from slamio.create.signals import Interrupted, TerminationSignals, describe_signal, guarded
from slamio.geometry import compose_pose
from slamio.log import Event, LogWriter
from slamio.log.pending import LogWriteError, PendingLogWriter

__all__ = ["Controller", "RecordHooks", "record"]


# --------------------------------------------------------------------------- recording


class RecordHooks(Protocol):
    """What :func:`record` asks of a loop that rides on it (``fgslam live``)."""

    def due(self, now_s: float) -> bool:
        """Called every pass of the control loop: write an odometry record now?"""

    def after_record(self, record, log: LogWriter) -> None:
        """Called after each odometry record is written and flushed, from the control loop's
        thread; may write more records (observations) to ``log``."""

    # optional: ``started(log)``, called once the log is open, before the first record;
    # ``passed()``, called at the end of every pass of the control loop (after its command
    # and any record went out) and after every read while waiting for the robot's first answer;
    # ``finished(now_s) -> bool | str``, called every pass after ``due``: true ends the run
    # normally (``completed``; a string is the reason's message), e.g. once enough landmarks are mapped


class Controller(Protocol):
    """What drives the robot (:class:`PathController`, :class:`TeleopController`,
    :class:`fgslam.live.steering.WaypointFollower`, a navigator)."""

    def advance(self, distance_m: float, angle_rad: float) -> None:
        """The robot's motion since the previous reading (every reading)."""

    def command(self, now_s: float, unread: tuple[float, float] = (0.0, 0.0)) -> tuple[float, float] | None:
        """(left, right) wheel speeds in mm/s now, or None when done."""

    # optional: ``bumper_changed(state, now_s)``, called when the (debounced) bumper state
    # changes — a :class:`slamio.create.bumper.BumperState`, pressed or released — with
    # ``RecorderSettings.bump_ends_run`` False, before the next ``command``; the wheels have
    # already been stopped, and forward commands are replaced by a stop while it is pressed


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
    header = make_header(model, link.port, link.baud, noise, settings, source, observation_noise,
                         start_pose=start_pose, sensor=sensor, calibration=calibration)
    run = _Recording(link, controller, settings, noise, clock, start_pose, hooks, on_record)
    with guarded(signals) as sig, PendingLogWriter(out_path, header, overwrite=overwrite) as log:
        if hooks is not None and hasattr(hooks, "started"):
            hooks.started(log)
        reason, signum = _run_guarded(run, log, sig, frame_tap, on_placed)
        reason, signum = _final_reason(run.monitor, reason, signum, sig)
        if run.started:
            with sig.held(raise_after=False):
                try:
                    run.write_record(log, sig)  # whatever moved since the last record
                except LogWriteError as exc:
                    if not reason.is_fault:
                        reason = StopReason("log-error", str(exc))
    return run.result(reason, out_path, log.placed, signum)


class _Recording:
    """One recording's parts (odometry, reader, safety monitor) and running totals, and the
    two things the control loop does: :meth:`use` a reading, :meth:`write_record`."""

    def __init__(self, link: CreateLink, controller, settings: RecorderSettings, noise: OdometryNoise,
                 clock: Callable[[], float], start_pose: Sequence[float], hooks, on_record):
        model = self.model = link.model
        self.link, self.controller, self.settings, self.clock = link, controller, settings, clock
        self.hooks, self.on_record = hooks, on_record
        self.target_mode = OiMode.SAFE if settings.mode == "safe" else OiMode.FULL
        self.odometry = Create2Odometry(noise) if model == "create2" else Create1Odometry(noise)
        self.reader = (StreamReader(link, model) if model == "create2"
                       else PollReader(link, model, settings.poll_period_s))
        self.monitor = SafetyMonitor(
            link.stop_motors,
            command_timeout_s=settings.command_timeout_s,
            data_timeout_s=settings.data_timeout_s,
            debounce=settings.bump_debounce if model == "create2" else 1,
            model=model,
            expected_mode=None,
            bump_ends_run=settings.bump_ends_run,
        )
        self.events: list[tuple[float, str, str | None, int]] = []  # (stamp, kind, side, pose) not yet logged
        self.t0 = clock()
        self.records = 0
        self.distance_m = self.angle_rad = 0.0
        self.pose = tuple(float(v) for v in start_pose)  # dead-reckoned, for RecordResult.final_pose
        self.stamp = 0.0
        self.started = False  # the robot answered and the log is in place
        self.started_s: float | None = None  # robot time the drive began

    def now_s(self) -> float:
        return max(self.stamp, self.clock() - self.t0)

    def write_events(self, log: PendingLogWriter) -> None:
        """The events seen since the last record, each stamped when its reading came (never
        before a line already written), with the pose they belong to."""
        for stamp, kind, side, pose in self.events:
            log.write(Event(max(stamp, log.last_stamp_s), kind, pose, side))
        self.events.clear()

    def write_record(self, log: PendingLogWriter, sig: TerminationSignals) -> None:
        with sig.held():  # a written record is always a counted one
            self.write_events(log)
            self.stamp = self.now_s()
            rec = self.odometry.take(self.stamp)
            log.write(rec)
            log.flush()
            self.records += 1
        if self.hooks is not None:
            self.hooks.after_record(rec, log)
        self.distance_m += abs(rec.distance_m)
        self.angle_rad += abs(rec.angle_rad)
        self.pose = compose_pose(self.pose, (rec.dx_m, rec.dy_m, rec.dtheta_rad))
        if self.on_record is not None:
            self.on_record(self.records)

    def use(self, values: dict[int, int] | None) -> None:
        t = self.reader.stamp(self.now_s())
        if values is None:  # Create 1: lost answer
            d, a = self.odometry.lost(t)
        else:
            if values.get(35) == self.target_mode and self.monitor.expected_mode is None:
                self.monitor.expected_mode = self.target_mode
            bumper = self.monitor.bumper.state
            self.monitor.readings(values)
            self.events += [(t, kind, side, self.records) for kind, side in self.monitor.take_events()]
            told = getattr(self.controller, "bumper_changed", None)
            if self.monitor.bumper.state != bumper and told is not None:
                told(self.monitor.bumper.state, t)
            if self.model == "create2":
                d, a = self.odometry.update(values[43], values[44])
            else:
                d, a = self.odometry.update(values[19], values[20], t)
        self.controller.advance(d, a)

    def result(self, reason: StopReason, out_path, log_placed: bool, signum: int | None) -> RecordResult:
        link = self.link
        stats = {**self.reader.stats(), "bytes_read": link.bytes_read, "bytes_written": link.bytes_written,
                 "reconnects": link.reconnects, "serial_errors": list(link.serial_errors),
                 "guardian": link.guardian_note}
        return RecordResult(
            reason=reason,
            out_path=os.fspath(out_path),
            records=self.records,
            duration_s=self.stamp,
            distance_m=self.distance_m,
            angle_rad=self.angle_rad,
            final_pose=self.pose,  # type: ignore[arg-type]
            link_stats=stats,
            shutdown=getattr(link, "last_shutdown", None),
            log_placed=log_placed,
            signum=signum,
            bumps=self.monitor.bump_stops,
            started_s=self.started_s,
        )


def _run_guarded(run: _Recording, log: PendingLogWriter, sig: TerminationSignals, frame_tap,
                 on_placed) -> tuple[StopReason | None, int | None]:
    """Start the robot and drive; whatever ends it (a hazard, the serial port, the log, a
    signal) trips the monitor, and the robot is stopped in every case. Returns the reason
    the drive gave (None if it did not get to give one) and the stopping signal, if any."""
    link, monitor, target_mode = run.link, run.monitor, run.target_mode
    reason: StopReason | None = None
    signum: int | None = None
    try:
        try:
            link.open()
            link.write(protocol.start())
            link.write(protocol.safe() if target_mode == OiMode.SAFE else protocol.full())
            run.reader.setup()
            reason = _first_reading(run.reader, run.odometry, target_mode, run.settings, run.now_s, frame_tap,
                                    getattr(run.hooks, "passed", None))
            if reason is None:
                with sig.held():
                    log.place()  # the robot answers: the new log replaces the old one now
                    if on_placed is not None:
                        on_placed()
                run.started = True
                monitor.expected_mode = target_mode
                run.started_s = run.now_s()
                reason = _drive(link, run.reader, run.odometry, run.controller, monitor, run.settings, run.now_s,
                                frame_tap, run.use, lambda: run.write_record(log, sig), run.hooks, run.started_s)
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
    return reason, signum


def _final_reason(monitor: SafetyMonitor, reason: StopReason | None, signum: int | None,
                  sig: TerminationSignals) -> tuple[StopReason, int | None]:
    """Why the recording ended: the first fault wins, whichever thread saw it; a signal held
    during the stop sequence counts too."""
    reason = monitor.reason or reason
    assert reason is not None
    if signum is None and sig.first is not None:  # a signal held during the stop sequence
        signum = sig.first
        if not reason.is_fault:
            reason = StopReason("interrupted", f"{describe_signal(signum)}: came while the robot was stopping")
    return reason, signum


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
           hooks=None, start_s: float = 0.0) -> StopReason:
    """The control loop from ``start_s`` (robot time: the robot has answered, the drive and its
    ``duration_s`` begin); returns why it ended."""
    last_command: tuple[float, float] | None = None
    last_sent_wall = -math.inf
    last_sent_s = -math.inf
    next_record = settings.record_period_s
    passed = getattr(hooks, "passed", None)
    bump_stops = 0
    with monitor:
        while True:
            if monitor.tripped.is_set():
                return monitor.reason  # type: ignore[return-value]
            for values in reader.poll(now_s(), tap):
                use(values)
            if monitor.tripped.is_set():
                return monitor.reason  # type: ignore[return-value]
            t = now_s()
            if monitor.bump_stops != bump_stops:  # the monitor stopped the wheels for a bump
                bump_stops = monitor.bump_stops
                last_command, last_sent_s = (0.0, 0.0), t
                if isinstance(odometry, Create1Odometry):
                    odometry.command(0.0, 0.0, t)
            unread = odometry.unread(t) if isinstance(odometry, Create1Odometry) else (0.0, 0.0)
            wheels = controller.command(t, unread)
            if wheels is None:
                if isinstance(controller, TeleopController):
                    return StopReason("quit", "quit from the keyboard")
                return StopReason("completed", "path driven to the end")
            wheels = away_from_bumper(wheels, monitor.bumper.state)  # never into a pressed bumper
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
            end = _run_over(t, t - start_s, settings, hooks)
            if end is not None:
                return end


def _run_over(t: float, driven_s: float, settings: RecorderSettings, hooks) -> StopReason | None:
    """The end of a run that the controller did not end at ``t`` (robot time since the recorder
    began), ``driven_s`` after the robot first answered: the duration asked for, the hooks'
    ``finished`` (both normal ends), or the time limit (a fault)."""
    if settings.duration_s is not None and driven_s >= settings.duration_s - SAME_TIME_S:
        return StopReason("completed", f"ran for the {settings.duration_s:g} s asked for")
    finished = getattr(hooks, "finished", None)
    if finished is not None:
        done = finished(t)
        if done:
            return StopReason("completed", done if isinstance(done, str) else "the run's goal was reached")
    if settings.max_duration_s is not None and t >= settings.max_duration_s:
        return StopReason("time-limit", f"stopped after the {settings.max_duration_s} s time limit")
    return None
