"""The guardian: a small process that stops the robot when the main process vanishes.

The Create has no command timeout: a program that dies without sending the stop — killed
with SIGKILL, by the kernel's OOM killer, by a segfault in native code (GTSAM, OpenCV) —
leaves the robot executing its last drive command for ever. No handler in the dying
process can help, so :class:`CreateLink` starts this guardian next to it when it opens a
port:

* the guardian holds a **duplicate of the serial port's descriptor** (the same open port:
  no second open, the baud rate and line settings are shared) and the read end of a
  **pipe** whose only write end is in the main process;
* it **never writes while the main process lives**: it only waits on the pipe, so no byte
  of its own can land between the bytes of the main process's commands;
* the main process ending for *any* reason closes the pipe (the kernel closes every
  descriptor of a dead process). Then the guardian writes the stop sequence at once
  (:func:`slamio.create.stopping.stop_bytes`), reads the robot back, says on stderr what it
  did, and exits;
* a normal end tells it so first (one byte, ``D``, then the pipe closes): it exits without
  writing — the main process has already stopped the robot and confirmed it;
* it runs in its own session and ignores SIGHUP, SIGINT, SIGQUIT and SIGTERM, so the
  signals that end the main process (a dropped SSH session, Ctrl-C to the process group)
  do not end the guardian before it has done its work. It exits by itself in both cases.

What no guardian can catch: the computer itself losing power or crashing (the guardian
dies with it), and the USB cable pulled or the adapter failing (no path to the robot is
left). Then the robot keeps driving until its bumper, a cliff or a wheel drop stops it in
Safe mode — or someone presses its power button. Test new paths with the robot on blocks,
and keep a hand near it.

Started as ``python -m slamio.create.guardian --serial-fd N --control-fd M``.
"""

from __future__ import annotations

import argparse
import errno
import os
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

from slamio.create.stopping import StopCheck, confirm_stop, stop_bytes

__all__ = ["Guardian", "start_guardian"]

RELEASE = b"D"
READY = b"R"


class Guardian:
    """The main process's handle on a running guardian (see the module docstring)."""

    def __init__(self, process: subprocess.Popen, control_fd: int):
        self.process = process
        self._control_fd: int | None = control_fd

    @property
    def pid(self) -> int:
        return self.process.pid

    def release(self, timeout_s: float = 5.0) -> None:
        """A normal end: the guardian exits without writing to the robot."""
        fd, self._control_fd = self._control_fd, None
        if fd is None:
            return
        try:
            os.write(fd, RELEASE)
        except OSError:
            pass
        os.close(fd)
        try:
            self.process.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:  # pragma: no cover - a guardian that hangs
            self.process.kill()
            self.process.wait()


def _package_root() -> str:
    return str(Path(__file__).resolve().parents[2])


def start_guardian(serial_fd: int, *, ready_timeout_s: float = 30.0) -> Guardian:
    """Start a guardian on ``serial_fd`` and wait until it watches; raises OSError if it
    does not start."""
    read_end, write_end = os.pipe()  # both non-inheritable: only pass_fds reaches the child
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (_package_root(), env.get("PYTHONPATH")) if p)
    try:
        process = subprocess.Popen(
            [sys.executable, "-m", "slamio.create.guardian", "--serial-fd", str(serial_fd),
             "--control-fd", str(read_end)],
            pass_fds=(serial_fd, read_end), stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
            start_new_session=True, env=env,
        )
    except BaseException:
        os.close(write_end)
        raise
    finally:
        os.close(read_end)
    guardian = Guardian(process, write_end)
    ready = select.select([process.stdout], [], [], ready_timeout_s)[0] and process.stdout.read(1) == READY
    process.stdout.close()
    if not ready:
        guardian.release(timeout_s=1.0)
        raise OSError(errno.ECHILD, f"the guardian process did not start within {ready_timeout_s} s")
    return guardian


# --------------------------------------------------------------------------- the guardian side


def _write_all(fd: int, data: bytes, timeout_s: float = 2.0) -> None:
    deadline = time.monotonic() + timeout_s
    while data:
        try:
            data = data[os.write(fd, data):]
        except BlockingIOError:
            if time.monotonic() > deadline:
                raise TimeoutError("the serial port took no bytes for 2 s") from None
            select.select([], [fd], [], 0.05)


def _read_exactly(fd: int, size: int, timeout_s: float) -> bytes:
    out = bytearray()
    deadline = time.monotonic() + timeout_s
    while len(out) < size:
        left = max(0.0, deadline - time.monotonic())  # past the deadline: still take what is buffered
        if not select.select([fd], [], [], left)[0]:
            break
        try:
            chunk = os.read(fd, size - len(out))
        except BlockingIOError:
            continue
        if not chunk:
            break
        out += chunk
    return bytes(out)


def _drain(fd: int, quiet_s: float = 0.05, limit_s: float = 0.5) -> None:
    deadline = time.monotonic() + limit_s
    while time.monotonic() < deadline and select.select([fd], [], [], quiet_s)[0]:
        try:
            if not os.read(fd, 4096):
                return
        except BlockingIOError:
            continue


def stop_robot(serial_fd: int) -> StopCheck:
    """Write the stop sequence on ``serial_fd`` and read the robot back."""
    _write_all(serial_fd, stop_bytes())
    return confirm_stop(lambda data: _write_all(serial_fd, data),
                        lambda size, timeout: _read_exactly(serial_fd, size, timeout),
                        lambda: _drain(serial_fd))


def _wait_for_parent(control_fd: int) -> bool:
    """Block until the main process ends; True if it released us (a normal end)."""
    while True:
        try:
            data = os.read(control_fd, 64)
        except InterruptedError:  # pragma: no cover - PEP 475 retries
            continue
        if not data:
            return False
        if RELEASE in data:
            return True


def _say(message: str) -> None:
    try:
        print(f"fgslam guardian: {message}", file=sys.stderr, flush=True)
    except OSError:  # the terminal is gone (a dropped SSH session): nobody to tell
        pass


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m slamio.create.guardian", description=__doc__.split("\n")[0])
    parser.add_argument("--serial-fd", type=int, required=True)
    parser.add_argument("--control-fd", type=int, required=True)
    args = parser.parse_args(argv)
    for signum in (signal.SIGHUP, signal.SIGINT, signal.SIGQUIT, signal.SIGTERM):
        signal.signal(signum, signal.SIG_IGN)
    try:
        sys.stdout.buffer.write(READY)
        sys.stdout.flush()
        sys.stdout.close()
    except OSError:
        pass
    if _wait_for_parent(args.control_fd):
        return 0
    try:
        check = stop_robot(args.serial_fd)
    except (OSError, TimeoutError) as exc:
        _say(f"the main process ended without stopping the robot, and the stop could not be sent ({exc}): "
             "THE ROBOT MAY STILL BE DRIVING — pick it up or press its power button")
        return 1
    if check.confirmed:
        _say(f"the main process ended without stopping the robot; robot stopped (confirmed): {check.detail}")
        return 0
    _say(f"the main process ended without stopping the robot; stop sent, NOT confirmed ({check.detail}) — "
         "check the robot")
    return 1


if __name__ == "__main__":
    sys.exit(main())
