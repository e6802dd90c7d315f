"""How ``fgslam record`` and ``fgslam live`` end: one line that says why and what became of
the robot, and an exit status a script can act on.

Exit status (both verbs):

====  =====================================================================================
0     the path was driven to its end (or teleop quit) and the robot confirmed its stop
2     stopped early — bump, wheel drop, watchdog, no data, serial error, time limit, a full
      disk, a robot that never answered — and the robot confirmed its stop (or never moved)
3     **the stop was sent but NOT confirmed** (the robot did not read back stopped, or could
      not be reached): check the robot. This wins over every other status.
128+N stopped by signal N (129 SIGHUP, 130 SIGINT, 131 SIGQUIT, 143 SIGTERM), stop confirmed
1     a user error before the robot moved (bad option, port that does not open, ...)
====  =====================================================================================
"""

from __future__ import annotations

import contextlib
import os
import sys
from typing import Iterator

from fgslam.cli.common import hold_outputs
from slamio.create.signals import TerminationSignals, describe_signal

EXIT_STOPPED_EARLY = 2
EXIT_STOP_NOT_CONFIRMED = 3


def say(line: str, stream=None) -> None:
    """Print a line; a terminal that is gone (the SSH session dropped) is not an error."""
    try:
        print(line, file=sys.stderr if stream is None else stream, flush=True)
    except (OSError, ValueError):
        pass


def robot_outcome(result) -> str:
    """What became of the robot, for the last line (a :class:`RecordResult`)."""
    if result.shutdown is None:
        return "robot: no stop was sent"
    return result.shutdown.summary


def exit_status(result) -> int:
    """The exit status of a recording or live run (module docstring)."""
    if result.shutdown is None or not result.shutdown.confirmed:
        return EXIT_STOP_NOT_CONFIRMED
    if result.signum is not None:
        return 128 + int(result.signum)
    if result.reason.is_fault:
        return EXIT_STOPPED_EARLY
    return 0


def report_end(verb: str, result, out) -> int:
    """Print how the run ended (stderr for everything but a normal end) and return the
    exit status."""
    status = exit_status(result)
    outcome = robot_outcome(result)
    reason = result.reason
    if not result.log_placed:
        kept = f"{out} was not written (an existing file is as it was)"
    else:
        kept = f"the log keeps the {result.records} records before it ({out})"
    if result.signum is not None:
        say(f"fgslam {verb}: interrupted by {describe_signal(result.signum)}; {outcome}; {kept}")
    elif reason.is_fault:
        say(f"fgslam {verb}: stopped early: {reason}; {outcome}; {kept}")
    elif status == EXIT_STOP_NOT_CONFIRMED:
        say(f"fgslam {verb}: {reason}; {outcome}")
    else:
        say(f"stopped: {reason}; {outcome}", sys.stdout)
    if status == EXIT_STOP_NOT_CONFIRMED:
        say(f"fgslam {verb}: WARNING: the robot did not confirm its stop. CHECK THE ROBOT: it may still be "
            "driving — pick it up or press its power button")
    return status


@contextlib.contextmanager
def robot_session(*outputs: tuple[str | os.PathLike | None, str]) -> Iterator[TerminationSignals]:
    """What a verb that drives the robot holds from its checks to its last line: the locks on
    its outputs, ``(path, option)`` pairs as :func:`fgslam.cli.common.hold_outputs` takes them
    (one writer per output), and the terminating signals (SIGHUP, SIGINT, SIGQUIT, SIGTERM
    run the stop sequence, whatever the process inherited)."""
    with hold_outputs(*outputs), TerminationSignals() as signals:
        yield signals
