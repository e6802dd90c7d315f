"""The one progress display (fgslam.cli.progress): tqdm on a terminal, a plain line every few
seconds otherwise — tested with fake streams and a fake clock, never by sleeping."""

from __future__ import annotations

import io
import re

from fgslam.cli.progress import Progress


class FakeClock:
    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def plain(clock=None, **kwargs) -> tuple[Progress, io.StringIO, FakeClock]:
    stream = io.StringIO()  # not a terminal: piped or logged
    clock = clock or FakeClock()
    return Progress(stream, clock=clock, **kwargs), stream, clock


def test_not_on_a_terminal_a_plain_line_every_interval_with_elapsed_rate_and_eta():
    progress, stream, clock = plain(interval_s=5.0)
    for done in range(1, 1001):  # 1000 steps, 0.1 s each: 100 s of work
        clock.now += 0.1
        progress(done, 1000, "ekf")
    lines = stream.getvalue().splitlines()
    assert "\r" not in stream.getvalue() and "\x1b" not in stream.getvalue()  # a log file stays readable
    assert 19 <= len(lines) <= 21  # one every 5 s of 100 s, and the last one
    first = lines[0]
    assert first.startswith("ekf:") and "/1000" in first
    assert re.search(r"\[00:0[45]<01:3[56], 10\.\d+ steps/s\]", first), first  # elapsed < ETA, rate
    assert re.match(r"ekf: 100% 1000/1000 \[01:(39|40)<00:00, 10\.0\d steps/s\]$", lines[-1]), lines[-1]


def test_not_on_a_terminal_short_work_prints_nothing():
    progress, stream, clock = plain(interval_s=5.0)
    for label in ("ekf", "isam2", "batch"):
        for done in range(1, 11):
            clock.now += 0.1
            progress(done, 10, label)
    progress.close()
    assert stream.getvalue() == ""


def test_not_on_a_terminal_the_interval_runs_across_stages():
    progress, stream, clock = plain(interval_s=5.0)
    for label in ("ekf", "isam2"):
        for done in range(1, 41):  # 4 s each: the first line comes during isam2
            clock.now += 0.1
            progress(done, 40, label)
    lines = stream.getvalue().splitlines()
    assert [line.split(":")[0] for line in lines] == ["isam2", "isam2"]  # under way, then done
    assert lines[-1].startswith("isam2: 100%")


def test_on_a_terminal_a_tqdm_bar_with_elapsed_rate_and_eta():
    stream = Terminal()
    progress = Progress(stream)
    assert progress.tty
    for done in range(1, 201):
        progress(done, 200, "isam2")
    progress(0, 1, "batch")
    progress(1, 1, "batch")
    progress.close()
    text = stream.getvalue()
    assert "\r" in text  # redrawn in place
    final = [part for part in text.replace("\n", "\r").split("\r") if part.startswith("isam2")][-1]
    assert re.search(r"isam2: 100%.*200/200 \[\d\d:\d\d<\d\d:\d\d, +[\d.]+ steps/s\]", final), final
    assert "batch" in text and "1/1" in text


def test_status_line_not_on_a_terminal_makes_its_text_only_when_shown():
    progress, stream, clock = plain(interval_s=5.0, unit="poses")
    made = []

    def text():
        made.append(clock.now)
        return f"pose {len(made)}  x 1.000 y 2.000 m"

    for count in range(1, 301):  # 30 s at 10 poses a second
        clock.now += 0.1
        progress.status(count, text)
    progress.close()
    lines = stream.getvalue().splitlines()
    assert len(made) == len(lines) == 6  # at once, then every 5 s
    assert lines[0].startswith("pose 1  x 1.000 y 2.000 m  [00:00")
    assert re.search(r"pose 2 .* \[00:05, 10\.\d+ poses/s\]$", lines[1]), lines[1]


def test_status_line_on_a_terminal_redraws_at_most_twice_a_second():
    stream = Terminal()
    clock = FakeClock()
    progress = Progress(stream, clock=clock, unit="poses")
    made = []
    for count in range(1, 51):  # 5 s at 10 poses a second
        clock.now += 0.1
        progress.status(count, lambda: made.append(1) or f"pose {count:5d}  landmarks  8")
    progress.close()
    assert len(made) == 10  # every 0.5 s of 5 s, the first at once
    shown = stream.getvalue().split("\r")
    assert shown[1].startswith("pose     1  landmarks  8  [00:00")
    assert shown[-1].rstrip() == "pose    46  landmarks  8  [00:04, 10.00 poses/s]"  # then a new line


def test_a_broken_stream_never_stops_the_work():
    class Broken(io.StringIO):
        def write(self, text):
            raise BrokenPipeError(32, "Broken pipe")

    clock = FakeClock()
    progress = Progress(Broken(), clock=clock, interval_s=1.0)
    for done in range(1, 101):
        clock.now += 0.1
        progress(done, 100, "ekf")
    progress.close()


def test_fgslam_run_prints_progress_lines_when_piped(tmp_path, capsys, monkeypatch):
    """The run's own callback, with a line due at every call (interval 0)."""
    import fgslam.cli.progress as progress_module
    from fgslam.cli import main

    monkeypatch.setattr(progress_module, "DEFAULT_INTERVAL_S", 0.0)
    assert main(["run", "data/arena_square.jsonl", "--out", str(tmp_path / "r"), "--no-report",
                 "--no-consistency"]) == 0
    err = capsys.readouterr().err
    for name in ("ekf", "isam2", "dead_reckoning"):
        assert re.search(rf"^{name}: +\d+% \d+/\d+ \[", err, re.M), err
    assert re.search(r"^ekf: 100% ", err, re.M)
