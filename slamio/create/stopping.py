"""The stop sequence and its read-back: a stop counts only when the robot confirms it.

Writing the stop bytes proves nothing: a robot that stopped answering mid-run, or never
answered, takes them without a word. So after the stop the host asks the robot (Query
List, opcode 149) for

* packet 35, the OI mode — it must be 1, Passive;
* packets 39, 41, 42, the velocity the robot was last asked for (Drive's velocity, Drive
  Direct's right and left wheel) — each must be 0 mm/s.

Both the Create 1 and the Create 2 Open Interface specs define these packets and answer
Query List in Passive mode. Only an answer that says so is a confirmed stop
(:class:`StopCheck`); no answer, or another answer, is "stop sent, NOT confirmed".

The functions here take the byte I/O as callables, so the link (:mod:`slamio.create.link`)
and the guardian process (:mod:`slamio.create.guardian`, which has only a file
descriptor) share them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Mapping

from slamio.create import protocol
from slamio.create.protocol import OiMode

__all__ = ["CONFIRM_IDS", "StopCheck", "stop_bytes", "check_stopped", "confirm_stop"]

#: OI mode, requested velocity (Drive), requested right and left velocity (Drive Direct).
CONFIRM_IDS = (35, 39, 41, 42)
_VELOCITY_NAMES = {39: "requested velocity", 41: "requested right wheel velocity", 42: "requested left wheel velocity"}


def stop_bytes() -> bytes:
    """Pause the stream, Drive 0 (straight) and Drive Direct 0 0, then Start (back to
    Passive, which also stops the wheels). Both drive commands: packet 39 reports the last
    *Drive* velocity, which Drive Direct leaves as it was (another program may have used
    Drive before us)."""
    return (protocol.pause_stream() + protocol.drive(0, protocol.RADIUS_STRAIGHT)
            + protocol.drive_direct(left_mm_s=0, right_mm_s=0) + protocol.passive())


@dataclass(frozen=True)
class StopCheck:
    """The robot's answer to the read-back: ``confirmed`` only when it says stopped."""

    confirmed: bool
    detail: str


def _plausible(values: Mapping[int, int]) -> bool:
    """An answer whose bytes can be real (not stream bytes still in flight)."""
    return 0 <= values[35] <= 3 and all(abs(values[i]) <= 500 for i in _VELOCITY_NAMES)


def check_stopped(values: Mapping[int, int]) -> StopCheck:
    """Is the robot in Passive mode with every requested velocity 0?"""
    problems = []
    if values[35] != OiMode.PASSIVE:
        try:
            name = OiMode(values[35]).name.lower()
        except ValueError:
            name = f"mode {values[35]}"
        problems.append(f"OI mode is {name}, not passive")
    problems += [f"{name} is {values[i]} mm/s" for i, name in _VELOCITY_NAMES.items() if values[i] != 0]
    if problems:
        return StopCheck(False, "the robot reads back: " + ", ".join(problems))
    return StopCheck(True, "read back from the robot: OI mode passive, requested wheel velocities 0 mm/s")


def confirm_stop(write: Callable[[bytes], None], read_exactly: Callable[[int, float], bytes],
                 drain: Callable[[], None], *, attempts: int = 3, timeout_s: float = 0.25) -> StopCheck:
    """Ask the robot (after the stop bytes went out) and check its answer.

    ``drain()`` throws away what is still arriving (frames of the paused stream);
    ``read_exactly(n, timeout_s)`` returns up to ``n`` bytes. An implausible answer (stream
    bytes mixed in) is asked again, up to ``attempts`` times.
    """
    size = protocol.query_response_size(CONFIRM_IDS)
    last = "no answer"
    for _ in range(max(1, attempts)):
        drain()
        write(protocol.query_list(CONFIRM_IDS))
        data = read_exactly(size, timeout_s)
        if len(data) != size:
            last = f"no answer to the read-back ({len(data)} of {size} bytes within {timeout_s} s)"
            continue
        values = protocol.decode_query_response(CONFIRM_IDS, data)
        if not _plausible(values):
            last = f"an answer that cannot be real ({data.hex(' ')})"
            continue
        return check_stopped(values)
    return StopCheck(False, last)
