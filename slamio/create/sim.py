"""A simulated iRobot Create that speaks the Open Interface bytes on a pseudo-terminal.

The driver cannot tell it from a robot on a USB cable: it opens :attr:`SimulatedCreate.port`
with pyserial and exchanges the same bytes. Use it for tests, for trying the recorder
without a robot (``fgslam record --port sim``), and for ground truth::

    with SimulatedCreate("create2", seed=1, time_scale=10) as sim:
        with CreateLink(sim.port, "create2") as link:
            ...
        sim.true_pose, sim.true_path_length_m

What is simulated
=================

* **Open Interface.** Modes Off → (128 Start) Passive → (131 Safe / 132 Full); 173 Stop
  (Create 2) back to Off. Drive (137) and Drive Direct (145) are obeyed in Safe and Full
  only, as on the robot; Start and Stop also stop the wheels. Sensors (142), Query List
  (149), Stream (148) with a frame every 15 ms, Pause/Resume (150); Baud (129) is
  accepted and ignored. Every packet of :data:`slamio.create.protocol.PACKETS` can be
  asked for; the modelled ones are 7, 19, 20, 35, 39–44, the others read 0.
* **Robot.** A differential drive (wheel base 235 mm, a disc of radius 0.17 m). Each
  15 ms step the wheel speeds move toward the commanded ones at most ``accel_m_s2``·dt,
  and the centre moves along the arc of the mean wheel speeds. In Safe mode a wheel drop
  (:meth:`lift`) switches to Passive and stops the wheels, like the real OI.
* **Arena.** Walls of a ``arena_m = (width, height)`` rectangle with a corner at the
  origin (default seed 004's 10 ft square; None: no walls). The disc cannot cross a wall
  (it slides along it, the wheels slip and the encoders keep counting); a wall touching
  the front half presses the bumper (packet 7: within 20° of straight ahead both bumpers,
  else the left or right one). ``obstacles`` (:class:`slamio.obstacles.Obstacles`: walls,
  boxes, cylinders, e.g. :func:`slamio.clutter.clutter_world`'s) block and bump the same way.
* **Encoders.** What the wheels report errs like the odometry noise model a recording
  states (:class:`slamio.create.odometry.OdometryNoise`, ``odometry_noise``; default the
  nominal model of :func:`wheel_odometry_noise`): each step the measured distance and turn
  get errors drawn with covariance ``|Δs|·F + |Δθ|·R`` over (distance, heading) — variance
  in proportion to the motion, a random walk, so the error of a drive does not depend on
  the 15 ms step — and the wheels' counts are made from them (seeded
  ``numpy.random.Generator``). Wheels cannot err sideways, so the model's sideways terms
  are not simulated (:func:`wheel_odometry_noise` drops them). A log recorded from the
  simulator with that model in its header is then consistent (NEES). Create 2: packets 43/44
  count ``π·72/508.8`` mm per count, uint16 wrapping, in the *commanded* direction of the
  wheel (the last non-zero command; not quadrature). Both models: packets 19/20 report the
  distance (mm) and angle (degrees) since they were last read, truncated toward zero with
  the remainder thrown away — the Create 1's 1° problem.
* **Faults** on the robot → host bytes, from their own random stream: each byte is
  dropped with probability ``drop_fraction`` and, if not, damaged (XOR with a random
  non-zero mask) with probability ``corrupt_fraction``. :meth:`unplug` pulls the cable:
  the pseudo-terminal closes (the host's port fails), the robot goes on with its last
  command; :meth:`replug` gives a fresh pseudo-terminal behind the same :attr:`port` path
  (a symbolic link, like ``/dev/serial/by-id/...``). :meth:`freeze` hangs the robot's
  firmware: no byte is read or sent, the wheels keep their last command (a stop then goes
  unconfirmed).

Time runs in 15 ms steps of simulated time (:meth:`clock`), paced at ``time_scale`` ×
real time by a background thread (``time_scale`` 10 runs a 30 s drive in 3 s). A host that
falls behind (a busy machine) does not see the robot run away: before each step the
simulator waits until the host has read everything sent so far (the pty's input queue is
empty), for at most ``wait_for_host_s`` of real time, so simulated time stretches instead;
a host in this process that sets ``unread.host_bytes_read`` is also waited for while frames are
still in the kernel's flip buffer (:class:`slamio.create.pty_port.Unread`).
The ground truth — :attr:`true_pose`, :attr:`true_path_length_m`, :attr:`true_turn_rad` —
and the raw frames sent before any damage (:attr:`sent_frames`) can be read at any time.

**Holding the clock (lockstep).** Host-side work that the robot does not wait for on a real
run — rendering and processing a camera frame, a smoother step — takes robot time that
depends on how fast the machine is. ``token = sim.hold(at_s)`` … ``sim.release(token)`` (or
``with sim.held(at_s):``) stops the simulated clock when it reaches ``at_s`` (now if None)
until the work is done: a piece of work given a budget of robot time then always ends
within it, however slow the machine (:class:`fgslam.live.Lockstep` gives a frame's result to
the live loop exactly at the end of its budget). Holds may come from any thread. While the
clock stands no step is taken and no frame is streamed, but commands are still obeyed at
once (a stop goes out whatever holds the clock). A slow or busy machine then only stretches
the run in wall time. ``max_hold_s`` (wall) bounds one wait, so a hold that is never
released cannot freeze the robot for ever.
"""

from __future__ import annotations

import contextlib
import errno
import math
import os
import select
import tempfile
import threading
import time
from typing import Iterator, Sequence

import numpy as np

from slamio.create import protocol
from slamio.create.odometry import CREATE2_MM_PER_COUNT, WHEEL_BASE_M, OdometryNoise
from slamio.create.protocol import Opcode, OiMode
from slamio.create.pty_port import Unread, close_pty, open_pty
from slamio.create.sim_model import (
    bump_bits,
    move_disc,
    command_size,
    damage_bytes,
    measured_wheel_travel_m,
    ramp_wheels,
    sign,
    truncate,
    wheel_odometry_noise,
    wheel_speeds_from_drive,
)
from slamio.errors import FgslamError
from slamio.obstacles import Obstacles

__all__ = ["SimulatedCreate", "STEP_S", "ROBOT_RADIUS_M", "ARENA_M", "DEFAULT_START_POSE"]

STEP_S = 0.015  # the OI updates its sensors and streams every 15 ms
ROBOT_RADIUS_M = 0.17  # the Create is a disc 339 mm across
ARENA_M = (3.048, 3.048)  # seed 004's 10 ft × 10 ft arena
DEFAULT_START_POSE = (0.75, 0.75, 0.0)


class SimulatedCreate:
    """A Create on a pseudo-terminal (module docstring); start with :meth:`start` or ``with``."""

    def __init__(self, model: str = "create2", *, seed: int = 0, time_scale: float = 1.0,
                 arena_m: tuple[float, float] | None = ARENA_M, obstacles: Obstacles | None = None,
                 start_pose: Sequence[float] = DEFAULT_START_POSE, odometry_noise: OdometryNoise | None = None,
                 accel_m_s2: float = 1.0, corrupt_fraction: float = 0.0, drop_fraction: float = 0.0,
                 robot_radius_m: float = ROBOT_RADIUS_M, wheel_base_m: float = WHEEL_BASE_M,
                 wait_for_host_s: float = 0.5, max_hold_s: float = 60.0, port_dir: str | None = None):
        if model not in ("create1", "create2"):
            raise FgslamError(f"unknown Create model {model!r}; use create1 or create2")
        if not (time_scale > 0 and math.isfinite(time_scale)):
            raise FgslamError(f"time_scale must be a positive number, got {time_scale!r}")
        for name, p in (("corrupt_fraction", corrupt_fraction), ("drop_fraction", drop_fraction)):
            if not 0.0 <= p < 1.0:
                raise FgslamError(f"{name} must be in [0, 1), got {p!r}")
        self.model = model
        self.time_scale = float(time_scale)
        self.arena_m = arena_m
        self.obstacles = obstacles
        self.odometry_noise = wheel_odometry_noise(model) if odometry_noise is None else odometry_noise
        self.accel_m_s2 = float(accel_m_s2)
        self.corrupt_fraction = float(corrupt_fraction)
        self.drop_fraction = float(drop_fraction)
        self.robot_radius_m = robot_radius_m
        self.wheel_base_m = wheel_base_m
        self.wait_for_host_s = float(wait_for_host_s)
        self.max_hold_s = float(max_hold_s)
        self.unread = Unread()  # what the host has not read (a host in this process sets its host_bytes_read)
        motion_seed, fault_seed = np.random.SeedSequence(int(seed)).spawn(2)
        self._rng = np.random.default_rng(motion_seed)
        self._fault_rng = np.random.default_rng(fault_seed)

        self._lock = threading.RLock()
        self._steps = 0
        self._pose = tuple(float(v) for v in start_pose)
        self._path_m = 0.0
        self._encoder_distance_m = 0.0
        self._encoder_turn_rad = 0.0
        self._turn_rad = 0.0
        self.mode = OiMode.OFF
        self._command_mm_s = [0.0, 0.0]  # left, right
        self._requested = (0, 0)  # (velocity, radius) of the last Drive, for packets 39/40
        self._wheel_m_s = [0.0, 0.0]
        self._direction = [1, 1]  # the encoders' counting direction (last non-zero command)
        self._ticks = [0.0, 0.0]  # encoder counts, not yet wrapped
        self._distance_mm = 0.0  # packet 19 accumulator
        self._angle_deg = 0.0  # packet 20 accumulator
        self._lifted = False
        self._frozen = False
        self._bumps = 0
        self._stream_ids: list[int] | None = None
        self._stream_paused = False
        self._inbox = bytearray()

        self.commands: list[tuple[float, bytes]] = []  # (sim time, command bytes) obeyed or not
        self.sent_frames: set[bytes] = set()
        self.frames_sent = 0
        self.bytes_corrupted = 0
        self.bytes_dropped = 0
        self.bytes_overflowed = 0
        self.unknown_opcodes = 0

        self._port_dir = port_dir
        self._own_dir: tempfile.TemporaryDirectory | None = None
        self.port: str | None = None
        self._master: int | None = None
        self._slave: int | None = None
        self._thread: threading.Thread | None = None
        self._running = threading.Event()
        self._holds: dict[int, float] = {}  # token → robot time from which it stops the clock
        self._hold_tokens = 0
        self._held = threading.Condition(threading.Lock())
        self._hold_changes = 0  # holds made or released so far
        self._standing_after: int | None = None  # standing, having seen this many hold changes
        self.hold_wall_s = 0.0  # wall time the clock was held (how much a slow machine stretched the run)

    # ------------------------------------------------------------------ life cycle

    def start(self, *, thread: bool = True) -> "SimulatedCreate":
        """Open the pseudo-terminal (:attr:`port`) and, with ``thread``, start the clock.
        Once only (``with sim:`` starts it too): two clocks would step the robot twice."""
        if self.port is not None:
            raise RuntimeError("SimulatedCreate.start(): already started (use either start() or with)")
        if self._port_dir is None:
            self._own_dir = tempfile.TemporaryDirectory(prefix="create-sim-")
            self._port_dir = self._own_dir.name
        self.port = os.path.join(self._port_dir, "create")
        self._plug()
        if thread:
            self._running.set()
            self._thread = threading.Thread(target=self._run, name="simulated-create", daemon=True)
            self._thread.start()
        return self

    def close(self) -> None:
        self._running.clear()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        with self._lock:
            self._receive()  # obey what the host sent last (its stop and passive commands)
            self._unplug_fds()
        if self._own_dir is not None:
            self._own_dir.cleanup()
            self._own_dir = None

    def __enter__(self) -> "SimulatedCreate":
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _plug(self) -> None:
        self._master, self._slave = open_pty(self.port)

    def _unplug_fds(self) -> None:
        close_pty(self._master, self._slave, self.port)
        self._master = self._slave = None

    def unplug(self) -> None:
        """Pull the cable: the host's port fails; the robot keeps its last command."""
        with self._lock:
            self._unplug_fds()
            self._inbox.clear()

    def replug(self) -> None:
        """Plug the cable back in: a new pseudo-terminal behind the same :attr:`port`."""
        with self._lock:
            if self._master is None:
                self._plug()

    @property
    def plugged(self) -> bool:
        return self._master is not None

    def freeze(self, frozen: bool = True) -> None:
        """The robot's firmware hangs (or thaws): it reads no byte and sends none, and the
        wheels keep their last command — a robot that takes a stop without a word."""
        with self._lock:
            self._frozen = frozen

    @property
    def frozen(self) -> bool:
        return self._frozen

    def lift(self, lifted: bool = True) -> None:
        """Pick the robot up (both wheel drops) or put it back down."""
        with self._lock:
            self._lifted = lifted

    # ------------------------------------------------------------------ ground truth

    def clock(self) -> float:
        """Simulated time in seconds (15 ms per step)."""
        return self._steps * STEP_S

    @property
    def true_pose(self) -> tuple[float, float, float]:
        with self._lock:
            return self._pose  # type: ignore[return-value]

    @property
    def true_path_length_m(self) -> float:
        """Distance the robot's centre has really travelled."""
        with self._lock:
            return self._path_m

    @property
    def encoder_distance_m(self) -> float:
        """Distance the wheel encoders have counted (their mean, signed, noise included):
        more than the robot moved when the wheels slip, e.g. while pushing against a wall."""
        with self._lock:
            return self._encoder_distance_m

    @property
    def encoder_turn_rad(self) -> float:
        """Heading change the wheel encoders have counted (counter-clockwise positive, not
        wrapped, noise included)."""
        with self._lock:
            return self._encoder_turn_rad

    @property
    def true_turn_rad(self) -> float:
        """Sum of the robot's true heading changes (counter-clockwise positive, not wrapped)."""
        with self._lock:
            return self._turn_rad

    @property
    def wheel_speeds_m_s(self) -> tuple[float, float]:
        """The wheels' actual (left, right) speeds."""
        with self._lock:
            return tuple(self._wheel_m_s)  # type: ignore[return-value]

    @property
    def commanded_mm_s(self) -> tuple[float, float]:
        with self._lock:
            return tuple(self._command_mm_s)  # type: ignore[return-value]

    @property
    def moving(self) -> bool:
        with self._lock:
            return any(abs(v) > 1e-9 for v in self._wheel_m_s) or any(c != 0 for c in self._command_mm_s)

    # ------------------------------------------------------------------ the clock

    def hold(self, at_s: float | None = None) -> int:
        """Stop the simulated clock when it reaches ``at_s`` (robot seconds of :meth:`clock`;
        None: now) until :meth:`release` is called with the returned token. Any thread; the
        clock runs while no hold has reached its time."""
        with self._held:
            self._hold_tokens += 1
            token = self._hold_tokens
            self._holds[token] = -math.inf if at_s is None else float(at_s)
            self._hold_changes += 1
            self._held.notify_all()
            return token

    def release(self, token: int) -> None:
        """End the hold ``token`` (from :meth:`hold`)."""
        with self._held:
            if self._holds.pop(token, None) is None:
                raise RuntimeError(f"SimulatedCreate.release({token!r}): no such hold")
            self._hold_changes += 1
            self._held.notify_all()

    def settle(self, timeout_s: float | None = None) -> bool:
        """Wait until the clock stands at a hold, with every hold made or released so far
        seen and any step they allowed taken (its stream frame sent): what a lockstep host
        calls before it reads, so that it always sees a whole step. False after ``timeout_s``
        (wall; default ``max_hold_s``), or at once when no hold can stop the clock (it runs
        freely) or the simulator is not running."""
        give_up = time.monotonic() + (self.max_hold_s if timeout_s is None else timeout_s)
        with self._held:
            while self._standing_after != self._hold_changes:
                remaining = give_up - time.monotonic()
                if remaining <= 0 or not self._holds or not self._running.is_set():
                    return False
                self._held.wait(timeout=min(remaining, 0.05))
            return True

    @contextlib.contextmanager
    def held(self, at_s: float | None = None) -> Iterator[None]:
        """``with sim.held():`` the clock stands still (from ``at_s``) while the block runs."""
        token = self.hold(at_s)
        try:
            yield
        finally:
            self.release(token)

    @property
    def holds(self) -> int:
        """How many holds are active (reached or not)."""
        with self._held:
            return len(self._holds)

    def _holding(self) -> bool:
        """A hold has reached its time (call with ``_held``)."""
        now = self.clock() + 1e-9
        return any(at <= now for at in self._holds.values())

    def _wait_while_held(self) -> bool:
        """Wait (obeying commands meanwhile) until no hold stops the clock, at most
        ``max_hold_s`` of wall time; True if the clock was held at all."""
        with self._held:
            if not self._holding():
                return False
        start = time.monotonic()
        give_up = start + self.max_hold_s
        while self._running.is_set() and time.monotonic() < give_up:
            with self._lock:
                self._receive()  # a stop sent while the clock stands is obeyed at once
            with self._held:
                if self._holding():
                    self._standing_after = self._hold_changes  # settle() may return
                    self._held.notify_all()
                    self._held.wait(timeout=0.005)
                if not self._holding():
                    self._standing_after = None
                    break
        with self._held:
            self._standing_after = None
        self.hold_wall_s += time.monotonic() - start
        return True

    def _unread_by_host(self) -> int:
        """Bytes sent that the host has not read yet (:class:`slamio.create.pty_port.Unread`)."""
        with self._lock:
            return 0 if self._slave is None else self.unread.count(self._slave)

    def _run(self) -> None:
        wall_step = STEP_S / self.time_scale
        next_wall = time.monotonic()
        while self._running.is_set():
            if self._wait_while_held():  # host-side work in progress: time stands still
                next_wall = time.monotonic()
            # Do not run ahead of a host that has not read the last frame yet (a busy
            # machine): simulated time waits, up to wait_for_host_s of real time.
            give_up = time.monotonic() + self.wait_for_host_s
            while self._unread_by_host() and time.monotonic() < give_up and self._running.is_set():
                time.sleep(0.0002)
                next_wall = time.monotonic()
            if not self._running.is_set():
                break
            self.step()
            next_wall += wall_step
            delay = next_wall - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            elif delay < -0.1:  # fell far behind (a busy machine): do not race to catch up
                next_wall = time.monotonic()

    def step(self) -> None:
        """One 15 ms step: obey the bytes received, move, send a stream frame."""
        with self._lock:
            self._receive()
            self._move(STEP_S)
            self._steps += 1
            if self._stream_ids and not self._stream_paused and self.mode != OiMode.OFF:
                frame = protocol.encode_stream_frame({i: self._packet_value(i) for i in self._stream_ids})
                self.sent_frames.add(frame)
                self.frames_sent += 1
                self._send(frame)

    # ------------------------------------------------------------------ bytes

    def _receive(self) -> None:
        if self._master is None or self._frozen:
            return
        while True:
            try:
                chunk = os.read(self._master, 4096)
            except BlockingIOError:
                break
            except OSError as exc:
                if exc.errno == errno.EIO:  # the host closed its end; it may open it again
                    break
                raise
            if not chunk:
                break
            self._inbox += chunk
        self._obey()

    def handle_bytes(self, data: bytes) -> None:
        """Obey command bytes given directly (tests without a host)."""
        with self._lock:
            self._inbox += data
            self._obey()

    def _send(self, data: bytes) -> None:
        if self._master is None or self._frozen:
            return
        if self.drop_fraction or self.corrupt_fraction:
            data, dropped, corrupted = damage_bytes(data, self._fault_rng, self.drop_fraction, self.corrupt_fraction)
            self.bytes_dropped += dropped
            self.bytes_corrupted += corrupted
        try:
            _, writable, _ = select.select([], [self._master], [], 0.05)
            written = os.write(self._master, data) if writable else 0
            self.unread.wrote(written)
        except BlockingIOError:
            written = 0
        except OSError:
            written = 0
        self.bytes_overflowed += len(data) - written

    def _obey(self) -> None:
        buf = self._inbox
        while buf:
            size = command_size(buf)
            if size is None:
                return
            if size == 0:
                self.unknown_opcodes += 1
                del buf[:1]
                continue
            command = bytes(buf[:size])
            del buf[:size]
            self.commands.append((self.clock(), command))
            self._command(command)

    def _command(self, c: bytes) -> None:
        op, args = c[0], c[1:]
        drivable = self.mode in (OiMode.SAFE, OiMode.FULL)
        if op == Opcode.START:
            self.mode = OiMode.PASSIVE
            self._command_mm_s = [0.0, 0.0]
        elif op == Opcode.SAFE and self.mode != OiMode.OFF:
            self.mode = OiMode.SAFE
        elif op == Opcode.FULL and self.mode != OiMode.OFF:
            self.mode = OiMode.FULL
        elif op == Opcode.STOP and self.model == "create2":
            self.mode = OiMode.OFF
            self._command_mm_s = [0.0, 0.0]
            self._stream_ids = None
        elif op == Opcode.DRIVE_DIRECT and drivable:
            right = int.from_bytes(args[0:2], "big", signed=True)
            left = int.from_bytes(args[2:4], "big", signed=True)
            self._set_command(max(-500, min(500, left)), max(-500, min(500, right)))
        elif op == Opcode.DRIVE and drivable:
            velocity = int.from_bytes(args[0:2], "big", signed=True)
            radius = int.from_bytes(args[2:4], "big", signed=False)
            radius = radius if radius in (32767, 32768) else int.from_bytes(args[2:4], "big", signed=True)
            self._requested = (velocity, radius)
            self._set_command(*wheel_speeds_from_drive(velocity, radius, 1000.0 * self.wheel_base_m))
        elif op == Opcode.SENSORS and self.mode != OiMode.OFF:
            if args[0] in protocol.PACKETS:
                self._send(protocol.encode_packet(args[0], self._packet_value(args[0])))
        elif op == Opcode.QUERY_LIST and self.mode != OiMode.OFF:
            ids = list(args[1:])
            if all(i in protocol.PACKETS for i in ids):
                self._send(b"".join(protocol.encode_packet(i, self._packet_value(i)) for i in ids))
        elif op == Opcode.STREAM and self.mode != OiMode.OFF:
            ids = list(args[1:])
            if all(i in protocol.PACKETS for i in ids):
                self._stream_ids = ids or None
                self._stream_paused = False
        elif op == Opcode.PAUSE_RESUME_STREAM:
            self._stream_paused = args[0] == 0

    def _set_command(self, left_mm_s: float, right_mm_s: float) -> None:
        self._command_mm_s = [float(left_mm_s), float(right_mm_s)]
        for i, v in enumerate(self._command_mm_s):
            if v:
                self._direction[i] = sign(v)

    def _packet_value(self, packet_id: int) -> int:
        if packet_id == 7:
            drops = 0x0C if self._lifted else 0
            return self._bumps | drops
        if packet_id == 19:
            value, self._distance_mm = truncate(self._distance_mm), 0.0
            return value
        if packet_id == 20:
            value, self._angle_deg = truncate(self._angle_deg), 0.0
            return value
        if packet_id == 35:
            return int(self.mode)
        if packet_id == 39:
            return self._requested[0]
        if packet_id == 40:
            radius = self._requested[1]
            return radius - 65536 if radius > 32767 else radius
        if packet_id == 41:
            return int(self._command_mm_s[1])
        if packet_id == 42:
            return int(self._command_mm_s[0])
        if packet_id in (43, 44) and self.model == "create2":
            return int(math.floor(self._ticks[packet_id - 43])) & 0xFFFF
        return 0

    # ------------------------------------------------------------------ physics

    def _move(self, dt: float) -> None:
        if self._lifted and self.mode == OiMode.SAFE:
            self.mode = OiMode.PASSIVE  # the OI's own wheel-drop safety
            self._command_mm_s = [0.0, 0.0]
        if self.mode not in (OiMode.SAFE, OiMode.FULL):
            self._command_mm_s = [0.0, 0.0]
        self._wheel_m_s, travel = ramp_wheels(self._wheel_m_s, self._command_mm_s, self.accel_m_s2, dt)
        measured = measured_wheel_travel_m(travel, self.wheel_base_m, self.odometry_noise, self._rng)
        for i in range(2):
            self._ticks[i] += self._direction[i] * measured[i] * 1000.0 / CREATE2_MM_PER_COUNT
        signed = [sign(travel[i]) * measured[i] for i in range(2)]
        self._distance_mm += 500.0 * (signed[0] + signed[1])
        self._encoder_distance_m += 0.5 * (signed[0] + signed[1])
        self._encoder_turn_rad += (signed[1] - signed[0]) / self.wheel_base_m
        self._angle_deg += math.degrees((signed[1] - signed[0]) / self.wheel_base_m)
        if self._lifted:
            self._bumps = 0
            return
        distance_m = 0.5 * (travel[0] + travel[1])
        angle_rad = (travel[1] - travel[0]) / self.wheel_base_m
        x0, y0, _ = self._pose
        self._pose = move_disc(self._pose, distance_m, angle_rad, self.arena_m, self.obstacles, self.robot_radius_m)
        self._turn_rad += angle_rad
        self._path_m += math.hypot(self._pose[0] - x0, self._pose[1] - y0)
        self._bumps = bump_bits(self._pose, self.arena_m, self.robot_radius_m, self.obstacles)
