"""``scripts/bench_speed_goals.py``: its table's rows, on the bundled arena log (about 2 s).

The benchmark's figures are CPU times and move with the machine, so these tests check what
does not: which rows each part gives, that each row's goal is the one issue 43 states for
that log, and that "met?" is the comparison of the measured value with the goal.
"""

from __future__ import annotations

import argparse

import pytest

from scripts.bench_speed_goals import ResidentPoll, Row, goal_rows, isam2_over_ekf_goal, longest_step_goal_ms, parse_parts
from scripts.common import DATA
from slamio.log import read_log


@pytest.fixture(scope="module")
def arena():
    return read_log(DATA / "arena_octagon.jsonl")


def test_parts_2_and_4_on_a_planar_log(arena) -> None:
    rows = goal_rows("arena", arena, [2, 4, 5], 1)  # part 5 is for 3-D logs only
    assert [(r.part, r.figure) for r in rows] == [
        (2, "Python's share of isam2's CPU"), (4, "isam2 longest step, CPU"), (4, "isam2 p99 step, CPU")]
    share, longest, p99 = (r.value for r in rows)
    assert 0.0 < share < 100.0
    assert 0.0 < p99 <= longest
    assert [(r.goal, r.unit) for r in rows] == [(10.0, "%"), (33.0, "ms"), (None, "ms")]
    assert rows[2].met() == "—"


def test_goals_by_log_name() -> None:
    assert isam2_over_ekf_goal("victoria-park.jsonl") == 2.1
    assert isam2_over_ekf_goal("plaza1") == 3.7
    assert isam2_over_ekf_goal("MRCLAM_Dataset6 robot 1") == 1.45
    assert isam2_over_ekf_goal("plaza2") is None
    assert longest_step_goal_ms("grid:2000") == 50.0
    assert longest_step_goal_ms("victoria-park") == 33.0


def test_met_is_the_value_against_the_goal() -> None:
    assert Row("a", 1, "f", 1.0, "×", 1.0).met() == "yes"
    assert Row("a", 1, "f", 1.01, "×", 1.0).met() == "**no**"
    assert Row("a", 1, "f", 151.0, "MB", 150.0).cells() == ("a", "1", "f", "151.0 MB", "≤ 150 MB", "**no**")


def test_parts_option() -> None:
    assert parse_parts("4,1,1") == [1, 4]
    with pytest.raises(argparse.ArgumentTypeError):
        parse_parts("6")


def test_the_resident_poll_sees_a_large_allocation() -> None:
    import time

    import numpy as np

    from fgslam.memory import resident_kib

    before_mb = resident_kib() / 1024.0
    with ResidentPoll(every_s=0.005) as poll:
        block = np.ones(80 * 2**20 // 8)  # 80 MiB, every page touched
        time.sleep(0.05)
        del block
    assert poll.peak_mb >= before_mb + 75.0
