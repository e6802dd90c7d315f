"""The serial link to a Create, on pyserial's ``serial_for_url``.

``port`` is anything ``serial.serial_for_url`` opens: a device (``/dev/ttyUSB0``,
``/dev/serial/by-id/usb-FTDI_...``, ``COM3``), a pseudo-terminal such as the simulated
Create's, or a URL such as ``loop://`` (bytes written come back) or ``socket://host:port``.

Use it as a context manager. Leaving the block — normally, on an exception, on Ctrl-C —
always runs :meth:`CreateLink.shutdown`: pause the stream (150 0), stop both wheels (Drive
0 and Drive Direct 0 0) and put the OI back in Passive mode (Start, 128), then **read the
robot back** (:mod:`slamio.create.stopping`): the report says "stopped (confirmed)" only
when the robot answers that it is in Passive mode with every requested velocity 0. If the
port has failed (an unplugged USB adapter), shutdown tries to reconnect
(``reconnect_attempts`` × ``reconnect_delay_s``) and sends the stop again; if that fails too
it says so in its report: **the Create has no command timeout and keeps driving** until it
is stopped some other way (its Safe mode only stops on a cliff or a wheel drop).

A process that dies without running any of this (SIGKILL, the OOM killer, a segfault in
native code) is covered by the **guardian** (:mod:`slamio.create.guardian`), a small
process the link starts when it opens a port that has a file descriptor: it writes the
stop sequence as soon as this process is gone.

Baud rates: Create 1 57600, Create 2 115200 (the defaults for ``model``).
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from typing import Any, Callable

from slamio.create import protocol
from slamio.create.stopping import StopCheck, confirm_stop, stop_bytes
from slamio.errors import FgslamError

__all__ = ["LinkError", "DEFAULT_BAUD", "MODELS", "CreateLink", "ShutdownReport"]

MODELS = ("create1", "create2")
DEFAULT_BAUD = {"create1": 57600, "create2": 115200}


class LinkError(FgslamError):
    """The serial port could not be opened, read or written."""


@dataclass(frozen=True)
class ShutdownReport:
    """What :meth:`CreateLink.shutdown` managed: ``stopped`` is True when the stop and
    passive commands were written (after a reconnect if ``reconnected``), ``confirmed``
    when the robot then read back stopped (:mod:`slamio.create.stopping`)."""

    stopped: bool
    reconnected: bool
    detail: str
    confirmed: bool = False

    @property
    def summary(self) -> str:
        """One line for the user: ``stopped (confirmed)`` or, loudly, what is not known."""
        if self.confirmed:
            return f"robot stopped (confirmed): {self.detail}"
        if self.stopped:
            return f"stop sent, NOT confirmed — CHECK THE ROBOT: {self.detail}"
        return f"robot NOT stopped — {self.detail}"


def _default_opener(url: str, **kwargs: Any):
    import serial  # pyserial; imported here so the pure modules do not need it

    return serial.serial_for_url(url, **kwargs)


def _serial_errors() -> tuple[type[BaseException], ...]:
    """What a failing port raises: pyserial's errors, OS errors, and on POSIX
    ``termios.error`` (not an OSError), which ``flush()``'s tcdrain raises when the device
    vanishes mid-write (a pulled USB cable)."""
    import serial

    errors: tuple[type[BaseException], ...] = (serial.SerialException, OSError, ValueError)
    try:
        import termios
    except ImportError:  # pragma: no cover - Windows
        return errors
    return errors + (termios.error,)


class CreateLink:
    """A serial connection to one Create (see the module docstring).

    ``opener(port, baudrate=..., timeout=..., write_timeout=...)`` returns a pyserial-like
    object (default ``serial.serial_for_url``); tests pass a spy. Writes are serialised by
    a lock, so the watchdog thread may stop the motors while the main loop reads.
    """

    def __init__(self, port: str, model: str = "create2", *, baud: int | None = None,
                 timeout_s: float = 0.05, write_timeout_s: float = 2.0, reconnect_attempts: int = 3,
                 reconnect_delay_s: float = 0.2, stop_oi_on_exit: bool = False,
                 opener: Callable[..., Any] | None = None, guardian: bool = True):
        if model not in MODELS:
            raise LinkError(f"unknown Create model {model!r}; use one of {', '.join(MODELS)}")
        self.port = port
        self.model = model
        self.baud = baud or DEFAULT_BAUD[model]
        self.timeout_s = timeout_s
        self.write_timeout_s = write_timeout_s
        self.reconnect_attempts = reconnect_attempts
        self.reconnect_delay_s = reconnect_delay_s
        self.stop_oi_on_exit = stop_oi_on_exit and model == "create2"
        self._opener = opener or _default_opener
        self._serial: Any = None
        self._lock = threading.RLock()
        self.bytes_read = 0
        self.bytes_written = 0
        self.reconnects = 0
        self.serial_errors: list[str] = []
        self.use_guardian = guardian
        self._guardian = None
        self.guardian_note = "not started"

    # ------------------------------------------------------------------ open / close

    @property
    def is_open(self) -> bool:
        return self._serial is not None

    def open(self) -> "CreateLink":
        with self._lock:
            if self._serial is not None:
                return self
            try:
                self._serial = self._opener(
                    self.port, baudrate=self.baud, timeout=self.timeout_s, write_timeout=self.write_timeout_s
                )
            except _serial_errors() as exc:
                raise LinkError(
                    f"cannot open serial port {self.port!r} at {self.baud} baud: {exc}. Check the cable and the "
                    "port name (ls /dev/serial/by-id/), that you may use it (Linux: sudo usermod -aG dialout "
                    "$USER, then log in again) and that no other program has it open"
                ) from None
            if self.use_guardian:
                self._start_guardian()
        return self

    def _start_guardian(self) -> None:
        """The guardian process on this port's descriptor (:mod:`slamio.create.guardian`);
        a port without a descriptor (``loop://``, a test's spy) has none."""
        from slamio.create.guardian import start_guardian

        try:
            fd = self._serial.fileno()
        except Exception:  # noqa: BLE001 - pyserial URL ports raise their own errors (or none exists)
            self.guardian_note = "none: the port has no file descriptor"
            return
        if not isinstance(fd, int) or fd < 0:
            self.guardian_note = "none: the port has no file descriptor"
            return
        try:
            self._guardian = start_guardian(fd)
        except OSError as exc:
            ser, self._serial = self._serial, None
            ser.close()
            raise LinkError(f"serial port {self.port!r}: the guardian process (which stops the robot if this "
                            f"program dies) could not start: {exc}") from None
        self.guardian_note = f"process {self._guardian.pid}"

    @property
    def guardian_pid(self) -> int | None:
        """The guardian's process id while it watches this link (None: no guardian)."""
        return None if self._guardian is None else self._guardian.pid

    def close(self) -> None:
        """Close the port; the guardian is released first (it exits without writing)."""
        with self._lock:
            ser, self._serial = self._serial, None
            guardian, self._guardian = self._guardian, None
        if guardian is not None:
            guardian.release()
        if ser is not None:
            try:
                ser.close()
            except _serial_errors():
                pass

    def _fail(self, action: str, exc: BaseException) -> LinkError:
        message = f"serial port {self.port!r}: {action} failed: {exc}"
        self.serial_errors.append(message)
        self.close()
        return LinkError(message + " (cable unplugged? robot switched off?)")

    def reconnect(self) -> bool:
        """Close and reopen the port, up to ``reconnect_attempts`` times; True on success."""
        self.close()
        for attempt in range(max(1, self.reconnect_attempts)):
            if attempt:
                time.sleep(self.reconnect_delay_s)
            try:
                self.open()
            except LinkError as exc:
                self.serial_errors.append(str(exc))
                continue
            self.reconnects += 1
            return True
        return False

    # ------------------------------------------------------------------ bytes

    def write(self, data: bytes) -> None:
        """Write all of ``data``; raises :class:`LinkError` (and closes) when the port fails."""
        with self._lock:
            if self._serial is None:
                raise LinkError(f"serial port {self.port!r} is not open")
            try:
                written = self._serial.write(data)
                self._serial.flush()
            except _serial_errors() as exc:
                raise self._fail("write", exc) from None
            self.bytes_written += len(data) if written is None else written

    def read(self, max_bytes: int = 4096) -> bytes:
        """Wait up to ``timeout_s`` for a byte, then return what is waiting (maybe b'')."""
        ser = self._serial
        if ser is None:
            raise LinkError(f"serial port {self.port!r} is not open")
        try:
            data = ser.read(1)
            if data:
                waiting = ser.in_waiting
                if waiting:
                    data += ser.read(min(waiting, max_bytes - 1))
        except _serial_errors() as exc:
            raise self._fail("read", exc) from None
        self.bytes_read += len(data)
        return data

    def read_exactly(self, size: int, timeout_s: float) -> bytes:
        """Read ``size`` bytes or as many as arrive within ``timeout_s`` (wall clock).

        Reads at least once, whatever the clock says: a host that was not scheduled for
        longer than ``timeout_s`` after asking (a busy machine) still takes the answer waiting
        in its buffer instead of calling it lost (a Create 1's distance is lost with it)."""
        out = bytearray()
        deadline = time.monotonic() + timeout_s
        while len(out) < size:
            out += self.read(size - len(out))
            if time.monotonic() >= deadline:
                break
        return bytes(out)

    def discard_input(self) -> None:
        """Throw away whatever the robot has sent and nobody read yet."""
        ser = self._serial
        if ser is None:
            return
        try:
            ser.reset_input_buffer()
        except _serial_errors() as exc:
            raise self._fail("reset_input_buffer", exc) from None

    # ------------------------------------------------------------------ commands

    def drive_direct(self, left_mm_s: float, right_mm_s: float) -> None:
        self.write(protocol.drive_direct(left_mm_s=left_mm_s, right_mm_s=right_mm_s))

    def stop_motors(self) -> None:
        """Drive Direct 0 0."""
        self.drive_direct(0, 0)

    def drain(self, limit_s: float = 0.5) -> None:
        """Read and drop what arrives until the line is quiet for one read timeout
        (``timeout_s``: frames of a stream just paused), for at most ``limit_s``."""
        deadline = time.monotonic() + limit_s
        while time.monotonic() < deadline and self.read():
            pass

    def confirm_stopped(self) -> StopCheck:
        """Ask the robot whether it is stopped (:func:`slamio.create.stopping.confirm_stop`)."""
        try:
            return confirm_stop(self.write, self.read_exactly, self.drain)
        except LinkError as exc:
            return StopCheck(False, f"the read-back failed: {exc}")

    def _stop_sequence(self) -> StopCheck:
        with self._lock:
            self.write(stop_bytes())
            check = self.confirm_stopped()
            if self.stop_oi_on_exit:
                self.write(protocol.stop_oi())
        return check

    def shutdown(self) -> ShutdownReport:
        """Pause the stream, stop the wheels, back to Passive, read the robot back;
        reconnect once if needed.

        Never raises: the report says what happened and whether the robot confirmed it.
        """
        first_error = None
        done = "stream paused, wheels stopped, OI set to passive"
        if self._serial is not None:
            try:
                check = self._stop_sequence()
                return ShutdownReport(True, False, f"{done}; {check.detail}", check.confirmed)
            except LinkError as exc:
                first_error = str(exc)
        else:
            first_error = f"serial port {self.port!r} was closed"
        if self.reconnect():
            try:
                check = self._stop_sequence()
                return ShutdownReport(True, True, f"{first_error}; reconnected, {done}; {check.detail}",
                                      check.confirmed)
            except LinkError as exc:
                first_error += f"; reconnected but: {exc}"
        return ShutdownReport(
            False,
            False,
            f"{first_error}; could not reach the robot to stop it. THE CREATE KEEPS EXECUTING ITS LAST "
            "DRIVE COMMAND: pick it up or press its power button",
        )

    def __enter__(self) -> "CreateLink":
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.last_shutdown = self.shutdown()
        self.close()
