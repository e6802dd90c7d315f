"""Noise learned from a 3-D run itself (fgslam.self_calibration3d), on a simulated drive whose
IMU noise is known, with the σ the log states set wrong on purpose."""

from __future__ import annotations

import json

import numpy as np
import pytest

from fgslam.runner3d import prepare_log3d, run_log3d
from fgslam.self_calibration3d import fit_without_truth_3d, with_noise
from slamio.datasets.seed003 import StereoImuNoise
from slamio.datasets.seed003_log import drive_to_log
from slamio.log import RunLog
from slamio.sim3d import DriveScenario, simulate_drive


@pytest.fixture(scope="module")
def misstated():
    """The simulator's drive (σ_v 0.05 m/s, σ_ω 0.005 rad/s, 1 px) with its records stating
    σ_v 10× too small and σ_ω 4× too large."""
    drive = simulate_drive(2, DriveScenario(straight_m=30.0, side_m=20.0))
    header, records = drive_to_log(drive, StereoImuNoise(sigma_px=3.0, sigma_v_mps=0.005, sigma_w_radps=0.02))
    return RunLog("misstated", header, tuple(records))


def test_the_imu_noise_is_learned_from_the_drive_alone(misstated):
    fit = fit_without_truth_3d(prepare_log3d(misstated))
    assert fit.converged
    truth = StereoImuNoise()
    assert fit.noise.sigma_v_mps == pytest.approx(truth.sigma_v_mps, rel=0.15)
    assert fit.noise.sigma_w_radps == pytest.approx(truth.sigma_w_radps, rel=0.15)
    # the stereo factor reads (u_L, u_R, mean v) with a Huber kernel: its σ is below the 1 px drawn
    assert 0.5 < fit.noise.sigma_px < 1.0
    before = run_log3d(misstated, ["isam2-3d"]).verdict
    after = run_log3d(with_noise(misstated, fit.noise), ["isam2-3d"]).verdict
    assert not before["imu"].fits
    for v in after.values():
        assert v.ratio == pytest.approx(1.0, abs=0.1), v.sentence()


def test_run_noise_self_on_a_3d_log(tmp_path, capsys, misstated):
    from fgslam.cli import main
    from slamio.log import write_log

    path = tmp_path / "misstated.jsonl"
    write_log(path, misstated.header, misstated.records)
    assert main(["run", str(path), "--noise", "self", "--estimators", "isam2-3d", "--out", str(tmp_path / "r")]) == 0
    out = capsys.readouterr().out
    assert "learned without truth" in out and "the log said 3 px, 0.005 m/s, 0.02 rad/s" in out
    metrics = json.loads((tmp_path / "r" / "metrics.json").read_text())
    assert all(v["fits"] for v in metrics["noise_verdict"].values())
    assert np.isfinite(metrics["isam2-3d"]["ate_rmse_m"])


def test_a_stated_pixel_covariance_keeps_its_shape_and_its_size_is_learned(tmp_path):
    """The log states the right correlations (σ_u 0.3, σ_v 1 px, ρ 0.95) at 3× the σ: the fit
    scales the 4×4 back (below the drawn size, as the one σ above, for the Huber kernel) and
    ``with_noise`` writes it on every stereo observation."""
    from fgslam.runner3d import noise_of
    from slamio.log import read_log, write_log
    from slamio.stereo import rectified_pixel_covariance

    true_cov = rectified_pixel_covariance(0.3, 1.0, 0.95)
    as_tuples = lambda m: tuple(tuple(float(v) for v in row) for row in m)  # noqa: E731
    drive = simulate_drive(5, DriveScenario(straight_m=25.0, side_m=15.0), StereoImuNoise(pixel_covariance=as_tuples(true_cov)))
    header, records = drive_to_log(drive, StereoImuNoise(pixel_covariance=as_tuples(9.0 * true_cov)))
    log = RunLog("scaled", header, tuple(records))
    fit = fit_without_truth_3d(prepare_log3d(log))
    fitted = fit.noise.pixel_cov()
    scale = fitted[0, 0] / true_cov[0, 0]
    assert np.allclose(fitted, scale * true_cov, rtol=1e-12)  # the shape kept
    assert 0.3 < scale < 1.0
    assert fit.noise.sigma_px == pytest.approx(np.sqrt(np.trace(fitted) / 4.0))
    write_log(tmp_path / "fitted.jsonl", *(lambda l: (l.header, l.records))(with_noise(log, fit.noise)))
    np.testing.assert_array_equal(noise_of(read_log(tmp_path / "fitted.jsonl")).pixel_cov(), fitted)
