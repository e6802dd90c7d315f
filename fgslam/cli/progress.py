"""The one progress display of every verb, built on tqdm.

- On a terminal: a tqdm bar per stage (``ekf``, ``isam2``, ``batch``, ``monte carlo``) with
  the count, elapsed time, rate and ETA, redrawn in place.
- Not on a terminal (piped, redirected to a log file, under CI): a plain line every
  ``interval_s`` seconds (default 5) with the same figures (tqdm's own formatting), and a
  last line for a stage that printed any. A run shorter than the interval prints nothing.

Two ways to feed it:

- ``progress(done, total, label)`` — the callback :func:`fgslam.runner.compare_log` and
  :func:`fgslam.montecarlo.monte_carlo` call (:data:`fgslam.runner.Progress`);
- ``progress.status(count, make_text)`` — a status line with no known end (``fgslam
  live``): ``make_text()`` is called only when a line is shown (at most every
  ``tty_interval_s`` on a terminal), so costly text (a marginal covariance) is made rarely;
  the line gets the elapsed time and the rate.

The clock is injectable (``clock=``) so the non-terminal mode is tested without sleeping.
"""

from __future__ import annotations

import sys
import threading
import time
from typing import TYPE_CHECKING, Callable

if TYPE_CHECKING:
    from tqdm import tqdm

DEFAULT_INTERVAL_S = 5.0  # a plain line this often when not on a terminal
TTY_INTERVAL_S = 0.5  # at most this often on a terminal


def _tqdm() -> type[tqdm]:
    """tqdm's class, imported at the first progress shown: importing tqdm costs ~30 ms of the
    command line's start-up, which a short verb (``fgslam validate``) should not pay."""
    from tqdm import tqdm

    return tqdm


def _is_terminal(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):  # no isatty, or a closed stream
        return False


def _has_size(stream) -> bool:
    """Whether the terminal says how wide and high it is (a bare pseudo-terminal says 0x0)."""
    import os

    try:
        columns, lines = os.get_terminal_size(stream.fileno())
    except (AttributeError, OSError, ValueError):
        return False
    return columns > 0 and lines > 0


class Progress:
    """Progress of long work on ``stream`` (default stderr); see the module docstring."""

    def __init__(self, stream=None, *, tty: bool | None = None, interval_s: float | None = None,
                 tty_interval_s: float = TTY_INTERVAL_S, clock: Callable[[], float] = time.monotonic,
                 unit: str = "steps", status_at_once: bool = True):
        self.stream = sys.stderr if stream is None else stream
        self.tty = _is_terminal(self.stream) if tty is None else tty
        self.interval_s = DEFAULT_INTERVAL_S if interval_s is None else interval_s
        self.tty_interval_s = tty_interval_s
        self.clock = clock
        self.unit = unit
        self.status_at_once = status_at_once  # the first status line at the first call
        self._lock = threading.Lock()
        self._bar: tqdm | None = None  # a counted stage on a terminal
        self._printer: Callable[[str], None] | None = None  # a status line on a terminal
        self._label: str | None = None
        self._total: int | None = None
        self._started = 0.0
        self._lines_in_stage = 0
        self._last_line = clock()  # the first plain line comes one interval after the start
        self._last_call = self._last_line  # a stage starts when the one before it ended
        self._done = 0

    # ------------------------------------------------------------------ counted stages

    def __call__(self, done: int, total: int, label: str) -> None:
        """``done`` of ``total`` steps of the stage ``label`` (a new label starts a stage)."""
        with self._lock:
            now = self.clock()
            if label != self._label or total != self._total:
                self._end_stage(now)
                self._start_stage(label, total, self._last_call)
            self._last_call = now
            self._done = done
            if self.tty:
                bar = self._bar
                if bar is not None:
                    bar.update(max(0, done - bar.n))
                    if done >= total:
                        self._end_stage(now)
                return
            if done >= total:
                self._end_stage(now)
            elif now - self._last_line >= self.interval_s:
                self._line(now)

    def _start_stage(self, label: str, total: int | None, started: float) -> None:
        """A new stage, under way since ``started`` (the first callback comes after its first step)."""
        self._label, self._total, self._started, self._done = label, total, started, 0
        self._lines_in_stage = 0
        if self.tty and total is not None:
            sized = _has_size(self.stream)  # tqdm shows nothing on a terminal of size 0x0 (a bare pty)
            bar = _tqdm()(total=total, desc=label, unit=" " + self.unit, file=self.stream, leave=True,
                       dynamic_ncols=sized, ncols=None if sized else 100, nrows=None if sized else 24,
                       mininterval=self.tty_interval_s, smoothing=0.1)
            bar._time = self.clock  # one clock for all figures (and a fake one in tests)
            bar.start_t, bar.last_print_t = started, self.clock()
            self._bar = bar

    def _end_stage(self, now: float) -> None:
        if self._label is None:
            return
        if self._bar is not None:
            self._bar.close()
            self._bar = None
        elif self._printer is not None:  # a status line: leave it on its own line
            self._write("\n")
            self._printer = None
        elif self._lines_in_stage:  # it said it was under way: say that it ended
            self._line(now)
        self._label = self._total = None

    def _line(self, now: float) -> None:
        text = _tqdm().format_meter(n=self._done, total=self._total, elapsed=now - self._started, ncols=0,
                                 prefix=self._label or "", unit=" " + self.unit)
        self._write(text + "\n")
        self._last_line = now
        self._lines_in_stage += 1

    # ------------------------------------------------------------------ a status line

    def status(self, count: int, make_text: Callable[[], str]) -> None:
        """Show ``make_text()`` with ``count`` (poses so far), elapsed time and rate, if a line
        is due; ``make_text`` is not called otherwise."""
        with self._lock:
            now = self.clock()
            if self._label is None:
                self._start_stage("", None, self._last_call)
                if self.status_at_once:
                    self._last_line = now - max(self.interval_s, self.tty_interval_s)
            self._last_call = now
            due = self.tty_interval_s if self.tty else self.interval_s
            self._done = count
            if now - self._last_line < due:
                return
            self._last_line = now
            meter = _tqdm().format_meter(n=count, total=None, elapsed=now - self._started, ncols=0,
                                      unit=" " + self.unit, bar_format="[{elapsed}, {rate_fmt}]")
            line = f"{make_text()}  {meter}"
            if self.tty:  # redrawn in place, padded over the longer line before it
                if self._printer is None:
                    self._printer = _tqdm().status_printer(self.stream)
                try:
                    self._printer(line)
                except (OSError, ValueError):
                    pass
            else:
                self._write(line + "\n")

    # ------------------------------------------------------------------ the end

    def close(self) -> None:
        """End the current stage (a terminal bar is left on its own line)."""
        with self._lock:
            self._end_stage(self.clock())

    def __enter__(self) -> "Progress":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _write(self, text: str) -> None:
        try:
            self.stream.write(text)
            self.stream.flush()
        except (OSError, ValueError):  # a closed or broken stderr must not stop the work
            pass
