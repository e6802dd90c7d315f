"""Honest timings (issue 15): BLAS/OpenMP pinned to one thread around the timed estimator runs,
and metrics.json and the table say what was timed."""

from __future__ import annotations

import json

import numpy as np
import pytest
from threadpoolctl import threadpool_info

from fgslam.runner import BLAS_THREADS, TIMING, run_estimator
from slamio.log import read_log


def blas_threads() -> list[int]:
    return [pool["num_threads"] for pool in threadpool_info() if pool["user_api"] in ("blas", "openmp")]


class Probe:
    """A do-nothing estimator that notes the BLAS threads while it steps and finishes."""

    name = "probe"

    def __init__(self) -> None:
        self.seen: list[list[int]] = []

    def step(self, step) -> None:
        np.linalg.inv(np.eye(3) * 2.0)
        self.seen.append(blas_threads())

    def current_pose(self):
        return (0.0, 0.0, 0.0)

    def finish(self) -> None:
        self.seen.append(blas_threads())

    def trajectory(self):
        return np.zeros((len(self.seen) - 1, 3))

    def landmarks(self):
        return {}


@pytest.fixture(scope="module")
def steps():
    return read_log("data/arena_square.jsonl").steps()[:20]


def test_blas_is_pinned_to_one_thread_while_an_estimator_runs_and_restored_after(steps):
    if not blas_threads():
        pytest.skip("no BLAS/OpenMP library that threadpoolctl can see")
    before = blas_threads()
    probe = Probe()
    run, _ = run_estimator(probe, steps, covariances=False)
    assert len(probe.seen) == len(steps) + 1
    assert all(threads == [BLAS_THREADS] * len(threads) for threads in probe.seen)
    assert blas_threads() == before
    assert run.total_time_s > 0


def test_blas_threads_none_leaves_them_as_they_are(steps):
    if not blas_threads():
        pytest.skip("no BLAS/OpenMP library that threadpoolctl can see")
    before = blas_threads()
    probe = Probe()
    run_estimator(probe, steps, covariances=False, blas_threads=None)
    assert all(threads == before for threads in probe.seen)


def test_fgslam_run_says_what_was_timed(tmp_path, capsys):
    from fgslam.cli import main

    out = tmp_path / "r"
    assert main(["run", "data/arena_square.jsonl", "--out", str(out), "--no-report"]) == 0
    printed = capsys.readouterr().out
    assert "wall time of estimator.step per step" in TIMING["what"] and "BLAS pinned to 1 thread" in TIMING["what"]
    assert f"time: {TIMING['what']}" in printed
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["timing"] == TIMING["what"] and metrics["blas_threads"] == 1
    assert "timing" not in printed.split("time:")[0].split("batch")[-1]  # not a row of the table


def test_fgslam_run_says_when_the_consistency_work_slows_the_smoother(tmp_path, capsys):
    """NIS/NEES at every step is untimed but slows iSAM2's own steps: the table says so; at
    the default sample it says they are untimed; neither when there was none
    (--no-consistency) or no iSAM2 ran."""
    from fgslam.cli import main

    note = TIMING["consistency_note"]
    assert main(["run", "data/arena_square.jsonl", "--out", str(tmp_path / "a"), "--no-report",
                 "--consistency", "all"]) == 0
    assert note in capsys.readouterr().out
    assert main(["run", "data/arena_square.jsonl", "--out", str(tmp_path / "s"), "--no-report"]) == 0
    printed = capsys.readouterr().out
    assert TIMING["sampled_note"] in printed and note not in printed
    assert main(["run", "data/arena_square.jsonl", "--out", str(tmp_path / "b"), "--no-report",
                 "--no-consistency"]) == 0
    printed = capsys.readouterr().out
    assert note not in printed and TIMING["sampled_note"] not in printed
    assert main(["run", "data/arena_square.jsonl", "--out", str(tmp_path / "c"), "--no-report",
                 "--estimators", "ekf,dead_reckoning"]) == 0
    printed = capsys.readouterr().out
    assert note not in printed and TIMING["sampled_note"] not in printed
