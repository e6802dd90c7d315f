"""slamio.create.guardian on a pipe standing in for the serial port: it writes nothing while
its parent lives, nothing after a normal end, and the stop sequence when the parent's end of
its pipe closes for any other reason (the SIGKILL case on a real pty: test_robot_stops.py)."""

from __future__ import annotations

import os
import select

from slamio.create.guardian import start_guardian
from slamio.create.stopping import CONFIRM_IDS, stop_bytes
from slamio.create import protocol as p


def _serial_pair():
    """(the guardian's end, the robot's end) of a pipe that stands in for the serial port."""
    robot, guardian = os.pipe()
    return guardian, robot


def _read_all(fd: int) -> bytes:
    out = b""
    while select.select([fd], [], [], 0)[0]:
        chunk = os.read(fd, 4096)
        if not chunk:
            break
        out += chunk
    return out


def test_a_released_guardian_exits_without_writing():
    port, robot = _serial_pair()
    guardian = start_guardian(port)
    assert _read_all(robot) == b""  # watching, silent
    guardian.release()
    assert guardian.process.returncode == 0
    os.close(port)
    assert os.read(robot, 4096) == b""  # end of file: nothing was ever written
    os.close(robot)


def test_a_vanished_parent_makes_the_guardian_stop_the_robot():
    port, robot = _serial_pair()
    guardian = start_guardian(port)
    os.close(guardian._control_fd)  # what the kernel does for a process that died
    guardian._control_fd = None
    guardian.process.wait(timeout=60)
    os.close(port)
    written = b""
    while chunk := os.read(robot, 4096):
        written += chunk
    os.close(robot)
    assert written.startswith(stop_bytes())
    assert written[len(stop_bytes()):] == p.query_list(CONFIRM_IDS) * 3  # asked; a pipe never answers
    assert guardian.process.returncode == 1  # stop sent, not confirmed
