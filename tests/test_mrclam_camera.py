"""scripts/mrclam_camera_tried.py: its correlation bins against pairs of known correlation,
its picture-error fit against an error put into a simulated log, and the whole script on
the shipped MRCLAM excerpt (three real robots)."""

from __future__ import annotations

import math
import os
from dataclasses import replace

import numpy as np
import pytest

from builders import run_main_with_json
from scripts import mrclam_camera_tried

from slamio.log import Observation, RunLog, read_log

HERE = os.path.dirname(__file__)
EXCERPT = os.path.join(HERE, "data", "mrclam_excerpt")
ARENA = os.path.join(HERE, "..", "data", "arena_octagon.jsonl")


@pytest.fixture(scope="module")
def script():
    return mrclam_camera_tried


def test_the_bins_give_the_correlation_the_pairs_were_drawn_with(script):
    """Pairs drawn with correlation 0.6 (range) and 0.2 (bearing) below Δt = 1 s and 0
    above: each bin's correlation is the one drawn, within its sampling error."""
    rng = np.random.default_rng(3)
    n = 20000
    dt = rng.uniform(0.0, 2.0, n)
    rho = np.where(dt < 1.0, 1.0, 0.0)[:, None] * np.array([0.6, 0.2])
    a = rng.normal(size=(n, 2))
    b = rho * a + np.sqrt(1.0 - rho**2) * rng.normal(size=(n, 2))
    pairs = np.column_stack([dt, np.zeros(n), a * b, a**2, b**2])
    near, far = script.binned(pairs, 0, (0.0, 1.0, 2.0))
    assert near["range"] == pytest.approx(0.6, abs=0.02) and near["bearing"] == pytest.approx(0.2, abs=0.03)
    assert abs(far["range"]) < 0.03 and abs(far["bearing"]) < 0.03
    assert near["pairs"] + far["pairs"] == n


def test_a_robust_cubic_ignores_gross_outliers(script):
    rng = np.random.default_rng(4)
    x = rng.uniform(-0.5, 0.5, 2000)
    truth = np.array([0.3, -0.1, 0.05, 0.01])
    y = np.polyval(truth, x) + rng.normal(0.0, 0.002, x.size)
    y[:100] += rng.choice([-1.0, 1.0], 100) * rng.uniform(0.5, 2.0, 100)  # 5 % misreadings
    coef, keep = script.robust_polyfit(x, y, 3)
    np.testing.assert_allclose(coef, truth, atol=0.005)
    assert not keep[:100].any() and keep[100:].mean() > 0.99


def test_a_picture_error_put_into_a_simulated_log_is_found_and_taken_out(script):
    """The arena log's readings, each moved by a cubic in its bearing: picture_errors against
    the log's truth and a robust fit give the cubic back, and ``corrected`` restores the
    readings' error against the truth to what the simulator drew."""
    log = read_log(ARENA)
    range_coef, bearing_coef = np.array([0.2, 0.05, -0.02, 0.03]), np.array([-0.05, 0.0, 0.01, -0.004])
    moved = tuple(
        replace(r, range_m=r.range_m + float(np.polyval(range_coef, r.bearing_rad)),
                bearing_rad=r.bearing_rad + float(np.polyval(bearing_coef, r.bearing_rad)))
        if isinstance(r, Observation) else r
        for r in log.records
    )
    before = script.picture_errors(log)
    err = script.picture_errors(RunLog("moved", log.header, moved))
    fitted_r, _ = script.robust_polyfit(err[:, 0], err[:, 1], 3)
    fitted_b, _ = script.robust_polyfit(err[:, 0], err[:, 2], 3)
    x = np.linspace(err[:, 0].min(), err[:, 0].max(), 50)  # the cubic over the bearings seen
    assert np.abs(np.polyval(fitted_r, x) - np.polyval(range_coef, x)).max() < 0.01
    assert np.abs(np.polyval(fitted_b, x) - np.polyval(bearing_coef, x)).max() < 0.005
    after = script.picture_errors(script.corrected(RunLog("moved", log.header, moved), fitted_r, fitted_b))
    for j in (1, 2):  # range, bearing: RMS as simulated, within the fit's own small error
        assert math.sqrt(np.mean(after[:, j] ** 2)) == pytest.approx(math.sqrt(np.mean(before[:, j] ** 2)), rel=0.1)


def test_the_script_runs_on_the_excerpt_and_writes_its_figures(script, tmp_path, capsys):
    out = tmp_path / "camera.json"
    printed, result = run_main_with_json(script.main, [EXCERPT], out, capsys)
    assert "by |Δ bearing|" in printed and "median isam2" in printed
    assert sorted(result["oracle"]) == ["1", "2", "3", "median"]
    first = result["pairs"]["by_time"][0]
    assert 0.0 < first["range"] < 1.0 and first["low"] == 0.0
    for k in ("1", "2", "3"):
        row = result["oracle"][k]
        assert row["range_rms_m"][1] < row["range_rms_m"][0]  # a fit to its own errors removes some of them
        assert 0.0 < row["model"]["isam2"]["ate_aligned_m"] < 1.0
        assert all(0.5 < row[v][n]["nis_inside"] <= 1.0 for v in ("model", "oracle") for n in ("ekf", "isam2"))
        product, picture = (result["ekf"][k][name] for name in ("product (decay in time)", "decay in time and picture"))
        assert 0.5 < product["nis_inside"] <= 1.0 and 0.5 < picture["nis_inside"] <= 1.0
        assert picture["ate_m"] != product["ate_m"]  # the picture decay changes the filter


def test_a_folder_without_robots_is_one_clear_error(script, tmp_path, capsys):
    with pytest.raises(SystemExit):
        script.main([str(tmp_path)])
    assert "give an MRCLAM dataset folder" in capsys.readouterr().err
