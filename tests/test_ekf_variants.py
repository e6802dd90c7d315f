"""The textbook EKF's consistent variants (``ekf-fej``: first-estimates Jacobians;
``ekf-inv``: the right-invariant error) against the textbook filter where it is consistent."""

from __future__ import annotations

from pathlib import Path

import pytest

from fgslam.compare import ate_rmse_m
from fgslam.runner import ESTIMATORS, run_estimator, truth_trajectory
from slamio.log import read_log


@pytest.mark.parametrize("variant", ["ekf-fej", "ekf-inv"])
def test_on_the_bundled_arena_log_it_is_as_accurate_as_the_textbook_filter(variant):
    """data/arena_octagon.jsonl (simulated, exact noise): the textbook filter is consistent
    there, and the variant is as accurate."""
    log = read_log(Path(__file__).resolve().parents[1] / "data" / "arena_octagon.jsonl")
    steps = log.steps()
    truth, has = truth_trajectory(steps)
    ate = {}
    for name in ("ekf", variant):
        run, _ = run_estimator(ESTIMATORS[name](log.header), steps, covariances=False)
        ate[name] = ate_rmse_m(run.final, truth, has_pose=has, align=False)
    assert ate[variant] == pytest.approx(ate["ekf"], rel=0.05)
