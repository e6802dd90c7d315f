"""Every way `fgslam record` and `fgslam live` can end leaves the robot stopped, and says so
only when the robot confirms it.

The robot is the simulated Create in *this* process, on a pseudo-terminal; the verb runs in
a child process on that port, exactly as on a robot's USB cable — so the robot outlives the
program and what became of it can be read off the robot itself. Each test waits for events
(the robot driving, the child ending), never for a time: the timeouts only bound a hang.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import builders
import pytest

from slamio.create.protocol import OiMode
from slamio.create.sim import SimulatedCreate
from slamio.log import read_log

ROOT = Path(__file__).resolve().parents[1]

# Starts a program with the dispositions given in argv[1] ("SIGINT,SIGTERM" ignored, or "-")
# and execs the rest: an exec keeps an ignored signal ignored, as a job started with `&` or
# by `nohup` inherits it.
_WITH_IGNORED = (
    "import os, signal, sys; "
    "[signal.signal(getattr(signal, n), signal.SIG_IGN) for n in sys.argv[1].split(',') if n != '-']; "
    "os.execv(sys.argv[2], sys.argv[2:])"
)


def _verb(verb: str, port: str, out: Path, *extra: str, ignored: str = "-") -> subprocess.Popen:
    """``fgslam VERB`` on ``port`` in a child process (a generous watchdog: a busy machine
    must not stop the robot before the test does)."""
    common = ["--port", port, "--model", "create2", "--out", str(out), "--watchdog", "5"]
    if verb == "record":
        args = ["record", *common, "--path", "square", "--laps", "5"]
    else:
        args = ["live", *common, "--path", "octagon", "--laps", "5"]
    cmd = [sys.executable, "-c", _WITH_IGNORED, ignored, sys.executable, "-m", "fgslam.cli", *args, *extra]
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    return subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            stdin=subprocess.DEVNULL)


def _robot() -> SimulatedCreate:
    return SimulatedCreate("create2", seed=0, time_scale=1.0, arena_m=None)


def _wait_driving(sim: SimulatedCreate, proc: subprocess.Popen) -> None:
    def driving():
        assert proc.poll() is None, proc.communicate()
        return sim.commanded_mm_s != (0.0, 0.0) and sim.mode == OiMode.SAFE

    assert builders.wait_for(driving, 120.0)


def _signal_while_driving(sim: SimulatedCreate, verb: str, out: Path, signum: int, *, ignored: str = "-",
                          before_signal=None) -> tuple[subprocess.Popen, str]:
    """``fgslam VERB`` on the robot, waited for until it drives, then (after ``before_signal()``,
    if given) sent ``signum`` — sent even when the wait fails; the ended process and its stderr."""
    proc = _verb(verb, sim.port, out, ignored=ignored)
    try:
        _wait_driving(sim, proc)
    finally:
        if before_signal is not None:
            before_signal()
        proc.send_signal(signum)
        _, stderr = proc.communicate(timeout=120)
    return proc, stderr


def _stopped(sim: SimulatedCreate) -> bool:
    return sim.commanded_mm_s == (0.0, 0.0) and sim.mode == OiMode.PASSIVE


def _status(out: Path) -> dict:
    return json.loads(out.with_name(out.name + ".status.json").read_text())


SIGNALS = [signal.SIGHUP, signal.SIGINT, signal.SIGQUIT, signal.SIGTERM]


@pytest.mark.parametrize("verb", ["record", "live"])
@pytest.mark.parametrize("signum", SIGNALS, ids=lambda s: signal.Signals(s).name)
def test_every_terminating_signal_stops_the_robot_and_says_which(tmp_path, verb, signum):
    out = tmp_path / "run.jsonl"
    with _robot() as sim:
        proc, stderr = _signal_while_driving(sim, verb, out, signum)
        assert _stopped(sim)
    name = signal.Signals(signum).name
    assert proc.returncode == 128 + signum, stderr
    assert f"interrupted by {name}" in stderr and "robot stopped (confirmed)" in stderr
    assert "Traceback" not in stderr
    last = [line for line in stderr.splitlines() if f"interrupted by {name}" in line]
    assert len(last) == 1
    if verb == "record":
        status = _status(out)
        assert status["reason"]["kind"] == "interrupted" and status["signal"] == signum
        assert status["shutdown"]["confirmed"]
        assert len(read_log(out).records) == status["records"]
    else:
        assert len(read_log(out).records) > 0


@pytest.mark.parametrize("ignored", ["SIGINT", "SIGTERM", "SIGHUP,SIGINT,SIGQUIT,SIGTERM"])
def test_signals_inherited_as_ignored_still_stop_the_robot(tmp_path, ignored):
    """A job started with `&` from a script inherits SIGINT ignored, a `nohup` one SIGHUP."""
    out = tmp_path / "run.jsonl"
    signum = getattr(signal, ignored.split(",")[-1])
    with _robot() as sim:
        proc, stderr = _signal_while_driving(sim, "record", out, signum, ignored=ignored)
        assert _stopped(sim)
    assert proc.returncode == 128 + signum, stderr


@pytest.mark.parametrize("verb", ["record", "live"])
def test_sigkill_the_guardian_stops_the_robot(tmp_path, verb):
    """Nothing in a SIGKILLed process runs: the guardian process sends the stop."""
    out = tmp_path / "run.jsonl"
    with _robot() as sim:
        proc = _verb(verb, sim.port, out)
        try:
            _wait_driving(sim, proc)
            assert builders.wait_for(lambda: out.is_file() and out.read_bytes().count(b"\n") >= 5, 120.0)
        finally:
            proc.send_signal(signal.SIGKILL)
        assert builders.wait_for(lambda: _stopped(sim), 30.0)
        _, stderr = proc.communicate(timeout=60)  # the guardian holds stderr until it is done
    assert proc.returncode == -signal.SIGKILL
    assert "fgslam guardian:" in stderr and "robot stopped (confirmed)" in stderr
    assert len(read_log(out).records) >= 4  # every complete record before the kill


def test_the_guardian_writes_nothing_while_the_program_lives(tmp_path):
    """A whole recording: the robot sees the recorder's commands only — one stop at the end,
    no second stop sequence from the guardian after the program ended normally."""
    out = tmp_path / "run.jsonl"
    with _robot() as sim:
        proc = _verb("record", sim.port, out, "--laps", "1", "--side", "0.2")
        stdout, stderr = proc.communicate(timeout=300)
        assert proc.returncode == 0, stderr
        assert _stopped(sim)
        starts = [c for _, c in sim.commands if c == bytes([128])]
    assert len(starts) == 2  # the recorder's Start, and its one stop (back to passive)
    assert "robot stopped (confirmed)" in stdout and "guardian" not in stderr


@pytest.mark.parametrize("verb", ["record", "live"])
def test_a_robot_that_stops_answering_is_not_reported_stopped(tmp_path, verb):
    out = tmp_path / "run.jsonl"
    with _robot() as sim:
        # the robot's firmware hangs: it takes the stop without a word
        proc, stderr = _signal_while_driving(sim, verb, out, signal.SIGTERM, before_signal=sim.freeze)
    assert proc.returncode == 3, stderr
    assert "NOT confirmed" in stderr and "CHECK THE ROBOT" in stderr
    assert "robot stopped (confirmed)" not in stderr
    if verb == "record":
        assert not _status(out)["shutdown"]["confirmed"]


def test_overwrite_to_a_robot_that_never_answers_keeps_the_old_log(tmp_path):
    out = tmp_path / "run.jsonl"
    out.write_bytes(b"an earlier recording\n")
    status = tmp_path / "run.jsonl.status.json"
    status.write_text('{"reason": "the earlier one"}\n')
    with _robot() as sim:
        sim.freeze()
        proc = _verb("record", sim.port, out, "--overwrite")
        _, stderr = proc.communicate(timeout=120)
        assert proc.returncode == 3, stderr
        assert "was not written" in stderr and "NOT confirmed" in stderr
        assert out.read_bytes() == b"an earlier recording\n"
        assert status.read_text() == '{"reason": "the earlier one"}\n'
        assert sorted(p.name for p in tmp_path.iterdir()) == ["run.jsonl", "run.jsonl.status.json"]
        sim.freeze(False)  # the robot is switched on: a retry works at once
        proc = _verb("record", sim.port, tmp_path / "new.jsonl", "--laps", "1", "--side", "0.2")
        _, stderr = proc.communicate(timeout=300)
    assert proc.returncode == 0, stderr


def test_sigkill_while_waiting_for_the_robot_leaves_no_log_and_blocks_no_retry(tmp_path):
    out = tmp_path / "run.jsonl"
    with _robot() as sim:
        sim.freeze()
        proc = _verb("record", sim.port, out)
        assert builders.wait_for(lambda: any(p.name.startswith(".run.jsonl.recording-") for p in tmp_path.iterdir()),
                                 120.0)
        proc.send_signal(signal.SIGKILL)
        proc.communicate(timeout=60)
        assert not out.exists()
        sim.freeze(False)
        proc = _verb("record", sim.port, out, "--laps", "1", "--side", "0.2")
        _, stderr = proc.communicate(timeout=300)
    assert proc.returncode == 0, stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.jsonl", "run.jsonl.status.json"]


def test_a_second_recorder_on_the_same_log_is_refused_naming_the_first(tmp_path):
    out = tmp_path / "run.jsonl"
    with _robot() as sim:
        first = _verb("record", sim.port, out)
        try:
            _wait_driving(sim, first)
            second = _verb("record", sim.port, out, "--overwrite")
            _, stderr = second.communicate(timeout=120)
        finally:
            first.send_signal(signal.SIGINT)
            first.communicate(timeout=120)
    assert second.returncode == 1
    assert f"process {first.pid}" in stderr and "Traceback" not in stderr
