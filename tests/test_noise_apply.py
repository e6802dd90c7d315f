"""slamio.noise.apply: a fitted noise model applied to a log that is already written."""

from __future__ import annotations

import math
import os

import numpy as np
import pytest

from slamio.datasets.mrclam import import_mrclam
from slamio.log import Observation, Odometry, RunLog, read_log
from slamio.noise.apply import apply_noise_model, correct_observation
from slamio.noise.errors import NoiseModelError
from slamio.noise.fit_truth import fit_noise_model
from slamio.noise.model import NoiseModel, ObservationModel, OdometryModel

DATA = os.path.join(os.path.dirname(__file__), "..", "data", "arena_octagon.jsonl")
EXCERPT = os.path.join(os.path.dirname(__file__), "data", "mrclam_excerpt")


@pytest.fixture(scope="module")
def log():
    return read_log(DATA)


def _odometry(log):
    return [r for r in log.records if isinstance(r, Odometry)]


def test_the_identity_odometry_model_keeps_every_increment(log):
    applied, dropped = apply_noise_model(log, NoiseModel())
    assert dropped == 0
    for before, after in zip(_odometry(log), _odometry(applied)):
        assert (after.dx_m, after.dy_m, after.dtheta_rad) == pytest.approx((before.dx_m, before.dy_m, before.dtheta_rad), abs=1e-12)


def test_scales_and_turn_per_metre_are_applied_to_each_increment(log):
    model = NoiseModel(odometry=OdometryModel(forward_scale=0.9, turn_scale=0.8, turn_per_m_rad=-0.05))
    applied, _ = apply_noise_model(log, model)
    for before, after in zip(_odometry(log), _odometry(applied)):
        distance = 0.9 * math.hypot(before.dx_m, before.dy_m)
        assert after.dx_m == pytest.approx(0.9 * before.dx_m, abs=1e-12)
        assert after.dy_m == pytest.approx(0.9 * before.dy_m, abs=1e-12)
        sign = 1.0 if before.dx_m >= 0 else -1.0
        assert after.dtheta_rad == pytest.approx(0.8 * before.dtheta_rad - 0.05 * distance * sign, abs=1e-12)
        assert np.all(np.linalg.eigvalsh(np.array(after.covariance)) > 0)


def test_a_lag_reads_the_chain_earlier(log):
    """With a lag of one step's duration the increment of step k is (about) step k-1's."""
    odo = _odometry(log)
    dt = odo[1].stamp_s - odo[0].stamp_s  # the simulator's steps are evenly spaced
    applied, _ = apply_noise_model(log, NoiseModel(odometry=OdometryModel(lag_s=dt)))
    new = _odometry(applied)
    for k in range(5, len(odo) - 1, 37):
        assert new[k].dtheta_rad == pytest.approx(odo[k - 1].dtheta_rad, abs=1e-9)


def test_readings_are_corrected_like_the_importer_does(log):
    model = NoiseModel(observation=ObservationModel(range_is_depth=True, range_scale=1.03, range_bias_m=0.02,
                                                    bearing_scale=0.99, bearing_sigma_rad=0.01))
    applied, _ = apply_noise_model(log, model)
    before = [r for r in log.records if isinstance(r, Observation)]
    after = [r for r in applied.records if isinstance(r, Observation)]
    assert len(before) == len(after)
    for b, a in list(zip(before, after))[::50]:
        r, brg, _, _ = correct_observation(model.observation, b.range_m, b.bearing_rad, 0.0)
        assert (a.range_m, a.bearing_rad) == pytest.approx((r, brg), abs=1e-12)
        assert a.landmark_id == b.landmark_id


def test_a_log_that_already_carries_a_model_is_refused():
    header, records = import_mrclam(EXCERPT, 2)
    raw = RunLog("r2", header, tuple(records))
    model = fit_noise_model([raw, RunLog("r3", *[(h, tuple(r)) for h, r in [import_mrclam(EXCERPT, 3)]][0])])
    applied, _ = apply_noise_model(raw, model)
    assert applied.header.noise["fitted_on"] == ["r2", "r3"]
    with pytest.raises(NoiseModelError, match="already carries a fitted noise model"):
        apply_noise_model(applied, model)
