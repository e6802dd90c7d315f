"""Every signal that ends a program runs the robot's stop sequence.

A robot program dies most often not by Ctrl-C but by **SIGHUP** — the SSH session to the
robot drops — or by a supervisor's SIGTERM. Python's defaults stop the program on those
without running any ``finally``, and the Create, which has no command timeout, keeps
driving. While a recording or a live run drives the robot, :class:`TerminationSignals`
turns each of

    SIGHUP (terminal or SSH session closed), SIGINT (Ctrl-C), SIGQUIT (Ctrl-\\),
    SIGTERM (kill, a supervisor)

into :class:`Interrupted` (a ``KeyboardInterrupt`` that knows its signal), raised once in
the main thread: the recorder's ``finally`` then pauses the stream, stops the wheels and
puts the OI in Passive mode. The handlers are installed whatever the process inherited —
a job started with ``&`` from a script inherits SIGINT ignored, a ``nohup`` one SIGHUP —
and the previous dispositions are given back after.

Inside :meth:`TerminationSignals.held` a signal is only remembered: the stop sequence runs
there, so a second Ctrl-C (or the SIGHUP that follows a SIGTERM when a terminal closes)
cannot cut it short; a record write and its count run there too, so they cannot be split.
SIGKILL, the OOM killer and a crash of native code cannot be caught at all: the link's
guardian process (:mod:`slamio.create.guardian`) stops the robot then.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from typing import Iterator

__all__ = ["TERMINATING_SIGNALS", "Interrupted", "TerminationSignals", "signal_name", "describe_signal"]

#: The signals that end a program by default and can be caught.
TERMINATING_SIGNALS = (signal.SIGHUP, signal.SIGINT, signal.SIGQUIT, signal.SIGTERM)

_WHAT = {
    signal.SIGHUP: "the terminal or SSH session closed",
    signal.SIGINT: "Ctrl-C",
    signal.SIGQUIT: "Ctrl-\\",
    signal.SIGTERM: "kill or a supervisor asked the program to end",
}


def signal_name(signum: int) -> str:
    """``SIGHUP`` for 1, and so on."""
    try:
        return signal.Signals(signum).name
    except ValueError:
        return f"signal {signum}"


def describe_signal(signum: int) -> str:
    """``SIGHUP (the terminal or SSH session closed)``."""
    what = _WHAT.get(signum)
    return f"{signal_name(signum)} ({what})" if what else signal_name(signum)


class Interrupted(KeyboardInterrupt):
    """A terminating signal arrived; :attr:`signum` says which."""

    def __init__(self, signum: int):
        super().__init__(describe_signal(signum))
        self.signum = signum

    @property
    def exit_code(self) -> int:
        """The shell's convention for a program ended by a signal: 128 + its number."""
        return 128 + int(self.signum)


class TerminationSignals:
    """Catch :data:`TERMINATING_SIGNALS` while the block runs (see the module docstring).

    :attr:`received` lists every signal that came, in order; :attr:`first` the first one.
    Only the main thread can install handlers: elsewhere the block runs unguarded (the
    caller of a recorder in a thread guards the main thread itself).
    """

    def __init__(self, signals: tuple[int, ...] = TERMINATING_SIGNALS):
        self.signals = tuple(signals)
        self.received: list[int] = []
        self._held = 0
        self._raised = False
        self._previous: dict[int, object] = {}

    @property
    def first(self) -> int | None:
        return self.received[0] if self.received else None

    def _handle(self, signum, frame) -> None:  # noqa: ARG002
        self.received.append(signum)
        if self._held == 0 and not self._raised:
            self._raised = True
            raise Interrupted(signum)

    def install(self) -> "TerminationSignals":
        if threading.current_thread() is threading.main_thread() and not self._previous:
            for signum in self.signals:
                self._previous[signum] = signal.signal(signum, self._handle)
        return self

    def restore(self) -> None:
        previous, self._previous = self._previous, {}
        for signum, handler in previous.items():
            signal.signal(signum, signal.SIG_DFL if handler is None else handler)

    @contextlib.contextmanager
    def held(self, *, raise_after: bool = True) -> Iterator[None]:
        """Remember signals instead of raising them while the block runs; with
        ``raise_after``, raise :class:`Interrupted` for the first one after the block (if
        none was raised before)."""
        self._held += 1
        try:
            yield
        finally:
            self._held -= 1
        if raise_after and self._held == 0 and self.received and not self._raised:
            self._raised = True
            raise Interrupted(self.received[0])

    def __enter__(self) -> "TerminationSignals":
        return self.install()

    def __exit__(self, *exc: object) -> None:
        self.restore()


@contextlib.contextmanager
def guarded(signals: TerminationSignals | None) -> Iterator[TerminationSignals]:
    """``signals`` (already installed by the caller: it outlives this block), or a new
    :class:`TerminationSignals` installed for the block."""
    if signals is not None:
        yield signals
        return
    with TerminationSignals() as own:
        yield own
