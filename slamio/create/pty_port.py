"""The simulated Create's serial port: a pseudo-terminal behind a fixed path (a symbolic
link, like ``/dev/serial/by-id/...``), so the host opens it with pyserial as it would a
robot on a USB cable, and a fresh one can be plugged in behind the same path.
"""

from __future__ import annotations

import fcntl
import os
import termios
import tty

__all__ = ["close_pty", "open_pty", "unread_bytes"]


def open_pty(port: str) -> tuple[int, int]:
    """A new raw pseudo-terminal, its slave's name linked at ``port``: (master, slave) file
    descriptors, the master non-blocking."""
    master, slave = os.openpty()
    tty.setraw(slave)  # no echo, no line editing: bytes pass unchanged
    os.set_blocking(master, False)
    link = port + ".new"
    if os.path.lexists(link):
        os.unlink(link)
    os.symlink(os.ttyname(slave), link)
    os.replace(link, port)
    return master, slave


def close_pty(master: int | None, slave: int | None, port: str | None) -> None:
    """Close both ends (those open) and remove the link at ``port``: the cable is pulled."""
    for fd in (master, slave):
        if fd is not None:
            try:
                os.close(fd)
            except OSError:
                pass
    if port is not None and os.path.lexists(port):
        os.unlink(port)


def unread_bytes(slave: int) -> int:
    """Bytes sent to the host that it has not read yet (the pty's input queue)."""
    try:
        return int.from_bytes(fcntl.ioctl(slave, termios.FIONREAD, b"\0\0\0\0"), "little")
    except OSError:
        return 0
