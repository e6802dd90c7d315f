"""The ranging radios' model: its fit against truth (slamio/noise/range.py), its correction of a
reading (slamio.noise.apply.correct_range), and the 1-degree-of-freedom NIS of a range in
both estimators (ekf.models.range_nis), against closed forms and simulated runs."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.stats import chi2

from ekf import EkfSlam
from ekf.models import range_nis
from fgslam.compare import nis_summary
from fgslam.runner import run_estimator
from fgslam.smoother import Isam2Smoother
from slamio.log import Observation, RunLog, TruthLandmark, group_steps
from slamio.noise.apply import correct_range
from slamio.noise.errors import NoiseModelError
from slamio.noise.fit_truth import fit_noise_model
from slamio.noise.model import ObservationModel
from test_range_only import BEACONS, range_only_run


def radio_log(scale: float, bias_m: float, sigma_m: float, seed: int = 5) -> RunLog:
    """The simulated ranging run of tests/test_range_only.py with readings
    ``scale·distance + bias_m + N(0, sigma_m²)`` and the beacons as truth landmarks."""
    header, records = range_only_run(seed=seed, laps=3.0, sigma_range_m=1e-9)
    rng = np.random.default_rng(seed + 100)
    out = [TruthLandmark(lid, *xy) for lid, xy in BEACONS.items()]
    for r in records:
        if isinstance(r, Observation):
            r = Observation(r.stamp_s, r.landmark_id, scale * r.range_m + bias_m + rng.normal(0, sigma_m), None,
                            sigma_m, None)
        out.append(r)
    return RunLog("radio.jsonl", header, tuple(out))


def test_range_fit_recovers_scale_bias_and_white_noise():
    model = fit_noise_model([radio_log(1.07, 0.2, 0.05)])
    o = model.observation
    assert o.range_scale == pytest.approx(1.07, abs=0.005)
    assert o.range_bias_m == pytest.approx(0.2, abs=0.03)
    assert math.hypot(o.range_sigma_m, o.range_sigma_per_m * 7.0) == pytest.approx(0.05, rel=0.1)
    assert o.outlier_rate < 0.005 and o.correlated_share == 0.0  # white, Gaussian readings
    report = model.fit_report["observation"]
    assert set(report["per_landmark"]) == {str(i) for i in BEACONS}
    # a constant offset cannot describe a scale: its median is the scale's share of the mean range
    assert report["constant_offset_fit"]["median_offset_m"] > 0.3


def test_correct_range_inverts_the_model():
    model = ObservationModel(range_scale=1.07, range_bias_m=0.03, range_sigma_m=0.5, range_sigma_per_m=0.01)
    r, sigma = correct_range(model, 1.07 * 40.0 + 0.03)
    assert r == pytest.approx(40.0, rel=1e-12)
    assert sigma == pytest.approx(math.hypot(0.5, 0.01 * 40.0) / 1.07, rel=1e-12)
    with pytest.raises(NoiseModelError, match="non-positive"):
        correct_range(model, 0.01)


def test_range_nis_closed_form():
    """Robot at the origin, landmark on the x axis: the range's Jacobian is [−1, 0, 0 | 1, 0],
    so S = P_xx(robot) + P_xx(landmark) − 2 P_x,lx + σ²."""
    P = np.diag([0.04, 0.09, 0.01, 0.25, 0.16])
    P[0, 3] = P[3, 0] = 0.02
    S = 0.04 + 0.25 - 2 * 0.02 + 0.3**2
    assert range_nis((0.0, 0.0, 0.7), (10.0, 0.0), P, 10.5, 0.3) == pytest.approx(0.25 / S, rel=1e-12)


def test_nis_summary_tests_each_value_against_its_own_band():
    low1, high1 = chi2.ppf(0.025, 1), chi2.ppf(0.975, 1)
    low2, high2 = chi2.ppf(0.025, 2), chi2.ppf(0.975, 2)
    values = [0.5 * (low1 + high1), high1 + 0.1, 0.5 * (low2 + high2), low2 / 2]
    mean, inside, count = nis_summary(values, [1, 1, 2, 2])
    assert (inside, count) == (0.5, 4) and mean == pytest.approx(np.mean(values))
    # between χ²(1)'s upper limit 5.02 and χ²(2)'s 7.38: inside as a range-bearing value only
    assert nis_summary([6.0], [1])[1] == 0.0 and nis_summary([6.0])[1] == 1.0


@pytest.mark.parametrize("estimator", [EkfSlam, Isam2Smoother])
def test_range_nis_of_a_consistent_model_is_chi2_1(estimator):
    """Readings simulated exactly as the log states: the ranges' NIS has mean ≈ 1 and about
    95 % inside the χ²(1) band, in the EKF and in iSAM2's online prediction."""
    header, records = range_only_run(seed=4, laps=3.0, sigma_range_m=0.3)
    run, _ = run_estimator(estimator(header), group_steps(header, records))
    assert run.nis_dofs is not None and set(run.nis_dofs.tolist()) == {1}
    mean, inside, count = nis_summary(run.nis, run.nis_dofs)
    assert count > 600
    assert 0.85 < mean < 1.2 and inside > 0.92


def test_calibrate_cli_fits_a_range_only_log_and_import_applies_it(tmp_path, capsys):
    """``fgslam calibrate`` on a range-only log says what the radio does; the file it writes
    is the model ``fgslam import plazaN --noise`` reads."""
    from fgslam.cli import main
    from slamio.log import write_log
    from slamio.noise.model import load_noise_model

    log = radio_log(1.07, 0.2, 0.05)
    path = tmp_path / "radio.jsonl"
    write_log(path, log.header, log.records)
    assert main(["calibrate", str(path), "--out", str(tmp_path / "radio.json")]) == 0
    out = capsys.readouterr().out
    scale = float(out.split("ranges (no bearing): measured = ")[1].split()[0])
    assert scale == pytest.approx(1.07, abs=0.005) and "camera" not in out
    assert load_noise_model(tmp_path / "radio.json").observation.range_scale == pytest.approx(1.07, abs=0.005)


def test_run_noise_corrects_range_only_readings_too():
    """``fgslam run --noise`` (slamio.noise.apply) turns each range by the model, as the
    Plaza importer's ``--noise`` does."""
    from slamio.noise.apply import apply_noise_model
    from slamio.noise.model import NoiseModel

    log = radio_log(1.07, 0.2, 0.05)
    model = NoiseModel(observation=ObservationModel(range_scale=1.07, range_bias_m=0.2, range_sigma_m=0.05))
    corrected, dropped = apply_noise_model(log, model)
    before = [r for r in log.records if isinstance(r, Observation)]
    after = [r for r in corrected.records if isinstance(r, Observation)]
    assert dropped == 0 and len(after) == len(before)
    for a, b in zip(before, after):
        assert b.range_m == pytest.approx((a.range_m - 0.2) / 1.07, rel=1e-12)
        assert b.sigma_range_m == pytest.approx(0.05 / 1.07, rel=1e-12)
