"""Redrawing a run's noise from the σ it states (slamio.redraw) and the band of one run's mean
NEES it gives (fgslam.consistency)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from ekf import EkfSlam
from fgslam.consistency import mean_nees, reading_z_scores, run_nees_band, with_stated_noise_scaled
from slamio.errors import FgslamError
from slamio.geometry import between_pose, wrap_angle
from slamio.log import Odometry, RunLog, TruthPose
from slamio.redraw import redraw_noise
from slamio.sim import simulate

LIVE_LOG = Path(__file__).parent / "data" / "live-sim" / "octagon.jsonl"


@pytest.fixture(scope="module")
def octagon():
    header, records = simulate("arena-octagon", 1, laps=1)
    return RunLog("octagon.jsonl", header, tuple(records))


def whitened_odometry_errors(log: RunLog) -> np.ndarray:
    """Odometry errors against the truth, whitened by each record's covariance."""
    odometry, previous = [], None
    for step in log.steps():
        pose = (step.truth.x_m, step.truth.y_m, step.truth.theta_rad)
        if step.odometry is not None:
            o = step.odometry
            error = np.array([o.dx_m, o.dy_m, o.dtheta_rad]) - np.asarray(between_pose(previous, pose))
            error[2] = wrap_angle(error[2])
            odometry.append(np.linalg.solve(np.linalg.cholesky(np.asarray(o.covariance)), error))
        previous = pose
    return np.array(odometry)


def test_redrawn_errors_have_the_stated_sigma(octagon):
    """Whitened by what each record states, the redrawn errors are standard normal."""
    redrawn = redraw_noise(octagon, np.random.default_rng(0))
    odometry, readings = whitened_odometry_errors(redrawn), np.column_stack(reading_z_scores(redrawn))
    assert len(odometry) > 300 and len(readings) > 300
    for z in (odometry, readings):
        assert np.abs(z.mean(axis=0)).max() < 0.15
        assert np.all(np.abs(z.std(axis=0) - 1.0) < 0.1), z.std(axis=0)


def test_redraw_keeps_the_run_and_is_seeded(octagon):
    a = redraw_noise(octagon, np.random.default_rng(3))
    b = redraw_noise(octagon, np.random.default_rng(3))
    assert a.records == b.records
    steps, original = a.steps(), octagon.steps()
    assert len(steps) == len(original)
    for s, o in zip(steps, original):
        assert s.truth == o.truth and s.stamp_s == o.stamp_s
        assert [x.landmark_id for x in s.observations] == [x.landmark_id for x in o.observations]
        assert [x.sigma_range_m for x in s.observations] == [x.sigma_range_m for x in o.observations]
    assert a.records != octagon.records


def test_redraw_refuses_a_log_without_truth_at_every_pose(octagon):
    records = list(octagon.records)
    first_truth = next(i for i, r in enumerate(records) if isinstance(r, TruthPose) and
                       any(isinstance(q, Odometry) for q in records[:i]))
    del records[first_truth]
    with pytest.raises(FgslamError, match=r"octagon.jsonl: 1 of \d+ poses have no truth"):
        redraw_noise(dataclasses.replace(octagon, records=tuple(records)), np.random.default_rng(0))


@pytest.mark.slow
def test_the_band_of_one_run_holds_the_chi_square_mean(octagon):
    """Redrawn from exact models, a consistent EKF's run means centre on χ²(3)'s mean of 3,
    with a spread far wider than the independent-pose band (one run's poses share its map
    error), and the simulated run itself is inside its band."""
    band = run_nees_band(octagon, EkfSlam, draws=30, seed=1)
    assert 2.0 < float(np.median(band.draws)) < 4.0
    assert band.high - band.low > 3 * (band.independent_band[1] - band.independent_band[0])
    assert band.inside


@pytest.mark.slow
def test_the_shipped_live_log_is_inside_its_own_band():
    """tests/data/live-sim/octagon.jsonl (a lap recorded by fgslam live --port sim): its EKF
    mean NEES 1.6 is below the independent-pose band [2.60, 3.42] but inside the band of runs
    redrawn from the noise it states ([1.15, 8.0] with 100 draws). The band has power: the
    same readings stating 0.4 of their σ (an overconfident log) come out well above it (mean
    9.2 against [0.98, 5.81] with 30 draws; at half their σ, 6.05 against [1.04, 5.83])."""
    from slamio.log import read_log

    log = read_log(LIVE_LOG)
    own, poses = mean_nees(log, EkfSlam)
    assert poses == 137 and own == pytest.approx(1.6, abs=0.1)
    band = run_nees_band(log, EkfSlam, draws=30, seed=0)
    assert band.independent_band[0] > own
    assert band.inside
    overconfident = run_nees_band(with_stated_noise_scaled(log, 0.4), EkfSlam, draws=30, seed=0)
    assert overconfident.mean_nees > overconfident.high
