"""The simulated Create's serial port: a pseudo-terminal behind a fixed path (a symbolic
link, like ``/dev/serial/by-id/...``), so the host opens it with pyserial as it would a
robot on a USB cable, and a fresh one can be plugged in behind the same path.
"""

from __future__ import annotations

import fcntl
import os
import termios
import tty

__all__ = ["Unread", "close_pty", "open_pty", "unread_bytes"]


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


class Unread:
    """Bytes written to a pty's master that its host has not read yet.

    The slave's input queue (:func:`unread_bytes`) alone misses bytes still in the kernel's
    flip buffer: a write reaches the queue only when a kernel worker moves it, on a busy
    machine up to a second later (measured), and a simulator pacing itself by the queue ran
    ahead of a host that had seen nothing (15 s of robot time in one 0.4 s read). A host in
    the same process that says how many bytes it has read (``host_bytes_read``, e.g.
    ``lambda: link.bytes_read``) lets bytes written since count as unread until they are
    queued or read."""

    def __init__(self) -> None:
        self.host_bytes_read = None  # Callable[[], int] | None
        self._unseen = 0  # written since the host was last seen to have our bytes
        self._host_read_seen = 0

    def wrote(self, count: int) -> None:
        self._unseen += count

    def count(self, slave: int) -> int:
        queued = unread_bytes(slave)
        if self.host_bytes_read is None:
            return queued
        read = self.host_bytes_read()
        if queued or read != self._host_read_seen:  # our bytes have left the flip buffer
            self._unseen, self._host_read_seen = 0, read
        return queued + self._unseen
