"""The sliding window of poses (fgslam/smoother/window.py, ``window_poses``).

References: a linear problem's marginal by hand (the Schur complement); ``gtsam.Marginals``
of the whole graph at its optimum against those of the marginalised one; the same run
without the window (its final estimate is the whole graph's optimum either way).
"""

from __future__ import annotations

from pathlib import Path

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import L, X

from fgslam.runner import run_estimator
from fgslam.smoother import Isam2Smoother
from fgslam.smoother.window import marginalise_poses
from slamio.errors import FgslamError
from slamio.log import group_steps, read_log
from slamio.sim import simulate

ARENA = Path(__file__).resolve().parents[1] / "data" / "arena_octagon.jsonl"


def _arena():
    log = read_log(ARENA)
    return log.header, log.steps()


def test_a_linear_marginal_is_the_schur_complement():
    """Points on a line: x0 ~ N(0, 1), x1 − x0 ~ N(1, 1), x2 − x1 ~ N(1, 4). Marginalising
    x0 and x1 leaves x2 ~ N(2, 1 + 1 + 4) (variances add along a chain)."""
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    graph.add(gtsam.PriorFactorPoint2(L(0), gtsam.Point2(0, 0), gtsam.noiseModel.Isotropic.Sigma(2, 1.0)))
    graph.add(gtsam.BetweenFactorPoint2(L(0), L(1), gtsam.Point2(1, 0), gtsam.noiseModel.Isotropic.Sigma(2, 1.0)))
    graph.add(gtsam.BetweenFactorPoint2(L(1), L(2), gtsam.Point2(1, 0), gtsam.noiseModel.Isotropic.Sigma(2, 2.0)))
    for i in range(3):
        values.insert(L(i), gtsam.Point2(0.3 * i, 0.1))  # anywhere: the problem is linear
    kept = marginalise_poses(graph, values, [L(0), L(1)])
    assert kept.values.keys() == [L(2)]
    optimum = gtsam.GaussNewtonOptimizer(kept.factors, kept.values).optimize()
    assert np.allclose(optimum.atPoint2(L(2)), [2.0, 0.0], atol=1e-9)
    covariance = gtsam.Marginals(kept.factors, optimum).marginalCovariance(L(2))
    assert np.allclose(covariance, 6.0 * np.eye(2), atol=1e-9)


def _pose_landmark_graph():
    """A short drive seeing two landmarks, at its optimum (nonlinear: Pose2 and bearings)."""
    header, records = simulate("arena-octagon", 3)
    smoother = Isam2Smoother(header, update_every=1)
    steps = group_steps(header, records)[:120]
    run_estimator(smoother, steps, covariances=False)
    graph = smoother.graph()
    optimum = gtsam.GaussNewtonOptimizer(graph, smoother.estimate()).optimize()
    return graph, optimum, len(steps), sorted(smoother.landmarks())


def test_marginalising_at_the_optimum_keeps_the_optimum_and_its_covariances():
    """Linearised at the optimum, the marginal is exact to first order: the remaining
    variables' optimum does not move, and their covariances are the whole graph's."""
    graph, optimum, n, landmarks = _pose_landmark_graph()
    drop = [X(i) for i in range(n // 2)]
    kept = marginalise_poses(graph, optimum, drop)
    assert not any(kept.values.exists(k) for k in drop)
    moved = gtsam.GaussNewtonOptimizer(kept.factors, kept.values).optimize()
    for i in range(n // 2, n):
        assert np.allclose(moved.atPose2(X(i)).translation(), optimum.atPose2(X(i)).translation(), atol=1e-6)
    whole, part = gtsam.Marginals(graph, optimum), gtsam.Marginals(kept.factors, kept.values)
    for key in [X(n - 1)] + [L(i) for i in landmarks]:
        assert np.allclose(part.marginalCovariance(key), whole.marginalCovariance(key), rtol=1e-6, atol=1e-12)


@pytest.fixture(scope="module")
def arena_runs():
    header, steps = _arena()
    runs = {}
    for window in (None, 60):
        smoother = Isam2Smoother(header, window_poses=window)
        online = []
        held = 0
        for step in steps:
            smoother.step(step)
            online.append(smoother.current_pose())
            if smoother._window is not None:
                held = max(held, len(smoother._window.poses))
        smoother.finish()
        runs[window] = smoother, np.array(online), held
    return runs


def test_the_window_bounds_what_isam2_holds(arena_runs):
    smoother, _, held = arena_runs[60]
    assert smoother.window_slides >= 3
    assert held <= 2 * 60 + 50  # at most twice the window, plus one update's steps


def test_the_final_estimate_is_the_whole_graphs_optimum_either_way(arena_runs):
    full, windowed = arena_runs[None][0], arena_runs[60][0]
    assert windowed.graph().size() == full.graph().size()  # nothing left out of the whole graph
    assert windowed.error() == pytest.approx(full.error(), rel=1e-5)
    assert np.abs(windowed.trajectory() - full.trajectory()).max() < 1e-3
    for lid, xy in full.landmarks().items():
        assert np.allclose(windowed.landmarks()[lid], xy, atol=1e-3)


def test_the_online_estimate_stays_close_to_the_full_smoothers(arena_runs):
    full, windowed = arena_runs[None][1], arena_runs[60][1]
    gap_m = np.sqrt(np.mean(np.sum((windowed[:, :2] - full[:, :2]) ** 2, axis=1)))
    assert gap_m < 0.01  # on a 3 m arena where the online ATE itself is about 0.01 m


def test_covariances_during_the_run_come_from_the_window(arena_runs):
    header, steps = _arena()
    steps = steps[:400]
    full, windowed = Isam2Smoother(header), Isam2Smoother(header, window_poses=60)
    for step in steps:
        full.step(step)
        windowed.step(step)
    a, b = full.current_covariance(), windowed.current_covariance()
    assert np.allclose(b, a, rtol=0.05, atol=1e-8)  # the marginal is a first-order approximation


def test_observations_without_an_id_are_refused_with_a_window():
    header, records = simulate("arena-octagon", 1, hide_ids=True)
    smoother = Isam2Smoother(header, window_poses=50)
    with pytest.raises(FgslamError, match="window_poses"):
        for step in group_steps(header, records):
            smoother.step(step)


@pytest.mark.parametrize("bad", [0, 1, -5])
def test_a_window_of_fewer_than_two_poses_is_refused(bad):
    header = read_log(ARENA).header
    with pytest.raises(FgslamError, match="window_poses"):
        Isam2Smoother(header, window_poses=bad)


def test_a_slide_that_a_fresh_isam2_refuses_leaves_every_pose_in(monkeypatch, arena_runs):
    """Fault injection: the fresh iSAM2 of the first slide raises (as GTSAM does on an
    indeterminate system). The smoother counts it, keeps every pose from then on, and ends
    where the run without a window ends."""
    real = gtsam.ISAM2
    made = []

    class Refusing:
        def __init__(self, params):
            pass

        def update(self, *args):
            raise RuntimeError("Indeterminant linear system detected while working near variable 7")

    def isam2(params):
        made.append(params)
        return real(params) if len(made) == 1 else Refusing(params)

    monkeypatch.setattr(gtsam, "ISAM2", isam2)
    header, steps = _arena()
    smoother = Isam2Smoother(header, window_poses=60)
    for step in steps:
        smoother.step(step)
    smoother.finish()
    assert smoother.window_slides == 0 and smoother.update_failures == 1
    assert "Indeterminant" in smoother.last_failure
    full = arena_runs[None][0]
    assert smoother.error() == pytest.approx(full.error(), rel=1e-9)
    assert np.abs(smoother.trajectory() - full.trajectory()).max() < 1e-6
