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
