"""The odometry's variance learned over stretches of its steps chained, without truth
(slamio.noise.odometry_windows, ``fit_without_truth(..., odometry_window_s=S)``)."""

from __future__ import annotations

import json
from pathlib import Path

import gtsam
import numpy as np
import pytest
import scipy.sparse as sp

from fgslam import self_calibration
from fgslam.self_calibration import RunGraph, fit_without_truth
from slamio.log import Odometry, read_log
from slamio.noise.fit_self import hat_traces_projected
from slamio.noise.odometry_windows import pose2_adjoint, window_bounds, window_residuals

DATA = Path(__file__).resolve().parent.parent / "data"


@pytest.fixture(scope="module")
def arena():
    return read_log(DATA / "arena_square.jsonl")


def test_the_adjoint_and_the_windows_residual_are_gtsams():
    pose = np.array([0.3, -1.2, 0.7])
    assert np.allclose(pose2_adjoint(pose), gtsam.Pose2(*pose).AdjointMap())
    rng = np.random.default_rng(1)
    increments = rng.normal(0.0, [0.3, 0.05, 0.4], size=(6, 3))
    poses = [gtsam.Pose2(0.5, 0.2, -0.3)]
    for inc in increments:  # the solution: each step's increment a little off
        poses.append(poses[-1].compose(gtsam.Pose2(*inc)).compose(gtsam.Pose2(*rng.normal(0.0, 0.02, 3))))
    array = np.array([[p.x(), p.y(), p.theta()] for p in poses])
    found = window_residuals(array, increments, [(0, 4), (4, 6)])
    for w, (a, b) in enumerate([(0, 4), (4, 6)]):
        z = gtsam.Pose2()
        for inc in increments[a:b]:
            z = z.compose(gtsam.Pose2(*inc))
        expected = gtsam.Pose2.Logmap(z.between(poses[a].between(poses[b])))
        assert np.allclose(found[w], expected, atol=1e-9)


def test_windows_span_the_seconds_asked_and_a_short_tail_joins_the_last():
    stamps = np.arange(0.0, 10.01, 0.5)  # 20 steps of 0.5 s
    assert window_bounds(stamps, 3.0) == [(0, 6), (6, 12), (12, 20)]  # the 1 s tail joins
    assert window_bounds(stamps, 0.1) == [(k, k + 1) for k in range(20)]


def test_the_hat_matrix_seen_through_the_windows_maps_is_u_h_ut():
    """Hutchinson's estimate of ``U H Uᵀ``'s blocks against the exact dense product."""
    rng = np.random.default_rng(0)
    A = sp.random(120, 30, density=0.15, random_state=2, format="csr") \
        + sp.vstack([sp.eye(30), sp.csr_matrix((90, 30))])
    U = sp.csr_matrix(rng.normal(size=(6, 120)) * (rng.random((6, 120)) < 0.2))
    dense = A.toarray()
    H = dense @ np.linalg.solve(dense.T @ dense, dense.T)
    exact = U.toarray() @ H @ U.toarray().T
    traces, M = hat_traces_projected(A, np.ones((120, 1)), U, probes=20000)
    assert traces[0] == pytest.approx(np.trace(H), rel=0.02)
    for w in range(2):
        block = exact[3 * w:3 * w + 3, 3 * w:3 * w + 3]
        assert np.allclose(M[w], block, atol=0.05 * np.abs(block).max())


def test_windows_of_one_step_are_the_step_by_step_fit(arena):
    """With every window a single step the windowed sums are the per-row ones: one iteration
    gives the same components and redundancies to the digit."""
    theta = self_calibration.START.copy()
    rows, _ = self_calibration._iteration([RunGraph(arena)], theta)
    windows, _ = self_calibration._iteration([RunGraph(arena, 1e-6)], theta)
    assert np.allclose(windows.theta, rows.theta, rtol=1e-6)
    assert np.allclose(windows.redundancy, rows.redundancy, rtol=1e-6)


def test_over_5_s_windows_the_simulators_white_odometry_noise_is_learned(arena):
    """The simulator's odometry noise is white: chained over 5 s stretches it is what it is
    step by step, so the learned heading variance (the part its 16 windows see best) stays
    near the simulator's stated one (sampling: ±35 % on 16 windows), and the readings' σ stay
    the simulator's."""
    fit = fit_without_truth([arena], odometry_window_s=5.0)
    stated = np.array([np.array(r.covariance)[2, 2] for r in arena.records if isinstance(r, Odometry)])
    graph = RunGraph(arena)
    learned = (graph.odometry_q @ fit.theta)[:, 2]
    assert learned.sum() / stated[:len(learned)].sum() == pytest.approx(1.0, abs=0.4)
    assert fit.model.observation.bearing_sigma_rad == pytest.approx(0.01, rel=0.1)
    assert fit.report["odometry_window_s"] == 5.0


def test_calibrate_and_run_take_the_window_without_truth(tmp_path, capsys):
    from fgslam.cli import main
    from slamio.noise.model import load_noise_model

    lines = (DATA / "arena_square.jsonl").read_text().splitlines()
    header = json.loads(lines[0])
    header["source"] = {"generator": "a test, standing in for a recording"}
    log = tmp_path / "recorded.jsonl"
    log.write_text("\n".join([json.dumps(header)] + lines[1:]) + "\n")
    model_path = tmp_path / "noise.json"
    assert main(["calibrate", str(log), "--without-truth", "--odometry-window", "5", "--out", str(model_path)]) == 0
    assert "learned over 5 s stretches" in capsys.readouterr().out
    assert load_noise_model(model_path).fit_report["odometry_window_s"] == 5.0
    assert main(["run", str(log), "--odometry-window", "5", "--out", str(tmp_path / "r")]) in (1, 2)
    assert "with --noise self" in capsys.readouterr().err
