"""Noise learned without truth (fgslam.self_calibration) and the verdict of a run
(fgslam.verdict), on simulated logs whose noise is known exactly."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from fgslam.runner import compare_log
from fgslam.self_calibration import fit_without_truth
from slamio.log import Observation, Odometry, RunLog, read_log
from slamio.noise.apply import apply_noise_model

DATA = Path(__file__).resolve().parent.parent / "data"


@pytest.fixture(scope="module")
def arena():
    return read_log(DATA / "arena_square.jsonl")


def with_odometry_covariance_scaled(log: RunLog, factor: float) -> RunLog:
    records = tuple(
        dataclasses.replace(r, covariance=tuple(tuple(factor * v for v in row) for row in r.covariance))
        if isinstance(r, Odometry) else r for r in log.records)
    return dataclasses.replace(log, records=records)


def test_the_verdict_of_a_log_whose_noise_is_exact_is_one(arena):
    """The simulator draws exactly the noise the log states: every group's χ²/dof ≈ 1."""
    verdict = compare_log(arena, ["isam2"]).verdict
    assert set(verdict) == {"odometry", "range", "bearing"}
    for v in verdict.values():
        assert v.fits and v.ratio == pytest.approx(1.0, abs=0.15), v.sentence()
        assert "fits" in v.sentence()
    # the redundancy is the rows minus what the solution absorbed: below the rows, above 0
    assert 0 < verdict["odometry"].redundancy < verdict["odometry"].rows


def test_the_verdict_says_how_far_a_misstated_odometry_noise_is_off(arena):
    """Odometry σ stated 3× too small (variances / 9): the run says the odometry σ is too small.
    The factor it gives is one step of the estimation, not its end: the solution bends to the
    over-trusted odometry, which hides part of its error (here ~2× of the true 3×; the fit of
    ``--noise self`` iterates to the end)."""
    verdict = compare_log(with_odometry_covariance_scaled(arena, 1.0 / 9.0), ["isam2"]).verdict
    odometry = verdict["odometry"]
    assert not odometry.fits and 1.6 < odometry.sigma_factor <= 3.3
    assert "too small" in odometry.sentence()


def test_gross_outliers_are_counted_apart_and_the_sigma_of_the_rest_still_fits():
    """10 % of the readings replaced by gross outliers (the simulator's ``outliers``): the
    verdict leaves them out of χ² (beyond 5σ), counts them, and the σ of the rest still fit."""
    from slamio.sim import simulate

    header, records = simulate("arena-square", 9, outliers=0.1)
    log = RunLog("outliers.jsonl", header, tuple(records))
    verdict = compare_log(log, ["isam2"]).verdict
    for group in ("range", "bearing"):
        v = verdict[group]
        assert v.fits and v.ratio == pytest.approx(1.0, abs=0.2), v.sentence()
        assert 0.05 < v.outliers / v.measurements < 0.12, v.sentence()
        assert "beyond 5 sigma, counted apart" in v.sentence()
    assert verdict["odometry"].outliers == 0
    assert verdict["range"].as_dict()["outliers"] == verdict["range"].outliers


def test_noise_learned_without_truth_fits_the_log(arena):
    """Fitted on the log alone (the stated noise is never read), the model's bearing σ is the
    simulator's 0.01 rad, and the log with the model applied passes its own verdict."""
    fit = fit_without_truth([arena])
    assert fit.converged
    assert fit.model.observation.bearing_sigma_rad == pytest.approx(0.01, rel=0.1)
    assert fit.outlier_rate < 0.01
    assert "observation.range_scale" in fit.report["not_determined_without_truth"]
    applied, dropped = apply_noise_model(arena, fit.model)
    assert dropped == 0
    for v in compare_log(applied, ["isam2"]).verdict.values():
        assert v.fits, v.sentence()


def _unsimulated_copy(tmp_path) -> Path:
    """The bundled log as if recorded (`run --noise` refuses a simulated log)."""
    lines = (DATA / "arena_square.jsonl").read_text().splitlines()
    header = json.loads(lines[0])
    header["source"] = {"generator": "a test, standing in for a recording"}
    out = tmp_path / "recorded.jsonl"
    out.write_text("\n".join([json.dumps(header)] + lines[1:]) + "\n")
    return out


def test_calibrate_without_truth_and_run_noise_self(tmp_path, capsys):
    from fgslam.cli import main
    from slamio.noise.model import load_noise_model

    log = _unsimulated_copy(tmp_path)
    model_path = tmp_path / "noise.json"
    assert main(["calibrate", str(log), "--without-truth", "--out", str(model_path)]) == 0
    out = capsys.readouterr().out
    assert "learned without truth" in out and "not learnable without truth" in out and "odometry lag 0.0" in out
    model = load_noise_model(model_path)
    assert model.observation.bearing_sigma_rad == pytest.approx(0.01, rel=0.1)
    assert model.fit_report["method"].startswith("without truth")

    assert main(["run", str(log), "--noise", "self", "--estimators", "ekf,isam2", "--out", str(tmp_path / "r")]) == 0
    out = capsys.readouterr().out
    assert "applied the noise model learned from this log (without truth)" in out
    assert "noise verdict" in out and "odometry: chi2/dof" in out
    assert "the log's noise: learned from this log without truth (--noise self)" in out
    metrics = json.loads((tmp_path / "r" / "metrics.json").read_text())
    assert set(metrics["noise_verdict"]) == {"odometry", "range", "bearing"}
    assert all(v["fits"] for v in metrics["noise_verdict"].values())
    assert "ekf" in metrics and "noise_verdict" not in metrics.get("ekf", {})
    page = (tmp_path / "r" / "report.html").read_text()
    assert "<h2>Noise verdict</h2>" in page and "the stated noise fits" in page


def test_calibrate_without_truth_refuses_a_trials_csv(capsys):
    from fgslam.cli import main

    assert main(["calibrate", str(DATA / "calibration_trials_s001.csv"), "--without-truth"]) in (1, 2)
    assert "--without-truth takes run logs" in capsys.readouterr().err


def test_check_against_the_smoothed_solution_gives_the_same_verdict(tmp_path, capsys):
    from fgslam.check import check_estimator
    from fgslam.cli import main

    log = _unsimulated_copy(tmp_path)
    result = check_estimator(log, estimator="ekf", against="smoothed")
    assert set(result.noise_verdict) == {"odometry", "range", "bearing"}
    assert main(["check", str(log), "--estimator", "ekf"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("PASS ekf vs smoothed") and "noise verdict" in out and "range: chi2/dof" in out


def test_the_verdict_names_a_recorders_nominal_noise_as_round_numbers():
    """A Create recording states its nominal odometry noise (source "nominal (uncalibrated)"):
    the run's verdict says the noise is round numbers, not fitted, as for an importer's."""
    from fgslam.cli.run import noise_source
    from slamio.create.odometry import default_noise
    from slamio.create.record_settings import RecorderSettings, make_header

    header = make_header("create1", "sim", 57600, default_noise("create1"), RecorderSettings())
    assert noise_source(header).startswith("round numbers, not fitted")


def with_odometry_distorted(log: RunLog, forward_scale: float, turn_scale: float, turn_per_m_rad: float) -> RunLog:
    """The log's odometry as a robot with these scales would report it: the true motion is
    ``forward_scale`` × the reported distance and ``turn_scale`` × the reported turn plus
    ``turn_per_m_rad`` per true metre."""
    def distorted(r):
        d_true = float(np.hypot(r.dx_m, r.dy_m)) * (1.0 if r.dx_m >= 0 else -1.0)
        return dataclasses.replace(r, dx_m=r.dx_m / forward_scale, dy_m=r.dy_m / forward_scale,
                                   dtheta_rad=(r.dtheta_rad - turn_per_m_rad * d_true) / turn_scale)
    return dataclasses.replace(log, records=tuple(distorted(r) if isinstance(r, Odometry) else r for r in log.records))


def test_the_odometrys_scales_are_learned_from_the_whole_run(arena):
    """A robot whose odometry over-reads its turns (true turn 0.93× the reported, like
    MRCLAM's 0.948), curves −0.04 rad per metre and over-reads distance (0.95): the scales
    learned without truth, from how the run's landmarks agree, are the ones put in."""
    distorted = with_odometry_distorted(arena, 0.95, 0.93, -0.04)
    odometry = fit_without_truth([distorted], scales=True, lags_s=(0.0,)).model.odometry
    assert odometry.turn_scale == pytest.approx(0.93, abs=0.01)
    assert odometry.turn_per_m_rad == pytest.approx(-0.04, abs=0.01)
    assert odometry.forward_scale == pytest.approx(0.95, abs=0.01)


def with_ranges_as_depth(log: RunLog, bias_m: float, scale: float = 1.0) -> RunLog:
    """The log's readings as a camera that sizes the landmark's image reports them: the
    depth along its axis, ``r·cos b``, times ``scale``, reading ``bias_m`` long."""
    return dataclasses.replace(log, records=tuple(
        dataclasses.replace(r, range_m=scale * r.range_m * float(np.cos(r.bearing_rad)) + bias_m)
        if isinstance(r, Observation) else r for r in log.records))


def test_the_cameras_range_model_is_learned_without_truth(arena):
    """Ranges reported as depth plus 4 cm (MRCLAM's camera: depth, +4.7 cm by Vicon) are
    recognised as depth and the bias found; the simulator's own Euclidean ranges stay range.
    The lag is pinned at the simulator's 0 (the lag search finds 0.02 s here, and the bias of
    the plain ranges then comes out −1.4 cm: a lag's error leaks into the bias)."""
    depth = fit_without_truth([with_ranges_as_depth(arena, 0.04)], lags_s=(0.0,)).model.observation
    assert depth.range_is_depth and depth.range_bias_m == pytest.approx(0.04, abs=0.01)
    plain = fit_without_truth([arena], lags_s=(0.0,)).model.observation
    assert not plain.range_is_depth and plain.range_bias_m == pytest.approx(0.0, abs=0.01)


def test_scales_measured_by_trials_are_held_and_the_rest_learned_around_them(arena):
    """The odometry's scales the run alone cannot give, held at what trials measured: the
    model carries them, and the camera's range model — depth, bias and now its scale too,
    which shows once the odometry's is known — is learned as the one put in."""
    distorted = with_ranges_as_depth(with_odometry_distorted(arena, 0.95, 0.93, -0.04), 0.04, scale=1.03)
    pinned = {"forward_scale": 0.95, "turn_scale": 0.93, "turn_per_m_rad": -0.04}
    fit = fit_without_truth([distorted], lags_s=(0.0,), pinned=pinned)
    odometry, observation = fit.model.odometry, fit.model.observation
    assert (odometry.forward_scale, odometry.turn_scale, odometry.turn_per_m_rad) == (0.95, 0.93, -0.04)
    assert observation.range_is_depth and observation.range_bias_m == pytest.approx(0.04, abs=0.015)
    assert observation.range_scale == pytest.approx(1.03, abs=0.01)
    assert fit.report["odometry_scales_pinned"] == pinned
    assert "odometry.forward_scale" not in fit.report["not_determined_without_truth"]


def test_calibrate_without_truth_holds_the_scales_of_a_trials_file(tmp_path, capsys):
    from fgslam.cli import main
    from slamio.noise.model import load_noise_model
    from slamio.noise.trials import calibrate_from_trials, read_trials

    trials = DATA / "calibration_trials_s001.csv"
    expected = calibrate_from_trials(*read_trials(trials)).odometry_scales()
    model_path = tmp_path / "noise.json"
    log = _unsimulated_copy(tmp_path)
    assert main(["calibrate", str(log), "--without-truth", "--scales-from", str(trials), "--out", str(model_path)]) == 0
    out = capsys.readouterr().out
    assert "odometry scales held at the trials'" in out and "held at the trials' values: forward_scale" in out
    odometry = load_noise_model(model_path).odometry
    assert odometry.forward_scale == pytest.approx(expected["forward_scale"], abs=1e-12)
    assert odometry.turn_scale == pytest.approx(expected["turn_scale"], abs=1e-12)
    assert main(["calibrate", str(log), "--scales-from", str(trials)]) in (1, 2)
    assert "use it with --without-truth" in capsys.readouterr().err
