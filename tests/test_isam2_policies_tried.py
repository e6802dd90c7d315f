"""scripts/isam2_policies_tried.py: its two iSAM2 variants against independent references
(the full back-substitution, the formula by hand, the batch optimum) on the bundled arena log."""

from __future__ import annotations

import os
from types import SimpleNamespace

import numpy as np
import pytest
from gtsam.symbol_shorthand import L, X

from builders import load_script
from fgslam.smoother import Isam2Smoother
from slamio.log import read_log

LOG = os.path.join(os.path.dirname(__file__), "..", "data", "arena_octagon.jsonl")


@pytest.fixture(scope="module")
def script():
    return load_script("isam2_policies_tried")


@pytest.fixture(scope="module")
def log():
    return read_log(LOG)


@pytest.mark.parametrize("relinearize_skip", [20, 1])  # 1: iSAM2 relinearises often, the copy goes stale often
def test_marginal_reads_equal_the_full_back_substitution(script, log, relinearize_skip):
    """A variable's mean from its Bayes-tree marginal, at its linearisation point, is the
    exact solution of the linear system: what calculateBestEstimate gives, to 1e-9."""
    smoother = script.MarginalReadSmoother(log.header, relinearize_skip=relinearize_skip)
    steps = log.steps()
    checked = 0
    for step in steps[:150]:
        smoother.step(step)
        if smoother._held.steps:  # held steps: iSAM2 has not seen the newest pose yet
            continue
        isam = smoother._isam
        best = isam._isam.calculateBestEstimate()
        last = smoother._keyframes.last
        pose = isam.calculateEstimatePose2(X(last))
        np.testing.assert_allclose(pose.localCoordinates(best.atPose2(X(last))), 0.0, atol=1e-9)
        for lid in smoother._point_landmarks():
            np.testing.assert_allclose(isam.calculateEstimatePoint2(L(lid)), best.atPoint2(L(lid)), atol=1e-9)
        checked += 1
    assert checked >= 5


def test_news_counts_each_landmark_by_the_share_of_its_readings_held(script, log):
    smoother = script.NewsSmoother(log.header)
    smoother._readings_in_isam = {1: 3}
    smoother._held.entries = [SimpleNamespace(landmark_id=1), SimpleNamespace(landmark_id=2), SimpleNamespace(landmark_id=2)]
    assert smoother._held_news() == pytest.approx(1 / (3 + 1) + 2 / (0 + 2))


def test_news_updates_less_often_and_still_ends_at_the_same_optimum(script, log):
    steps = log.steps()
    default, news = Isam2Smoother(log.header), script.NewsSmoother(log.header)
    for smoother in (default, news):
        for step in steps:
            smoother.step(step)
        smoother.finish()
    assert news.updates < default.updates
    assert news.error() == pytest.approx(default.error(), rel=1e-4)
