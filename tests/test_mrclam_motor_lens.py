"""scripts/mrclam_motor_lens_tried.py: the motor-lag model against its closed form, and the
whole script on the shipped MRCLAM excerpt (three real robots)."""

from __future__ import annotations

import math
import os

import numpy as np
import pytest

from builders import run_main_with_json
from scripts import mrclam_motor_lens_tried

HERE = os.path.dirname(__file__)
EXCERPT = os.path.join(HERE, "data", "mrclam_excerpt")


@pytest.fixture(scope="module")
def script():
    return mrclam_motor_lens_tried


def test_a_pure_delay_shifts_the_command_by_whole_grid_steps(script):
    omega = np.r_[np.zeros(10), np.ones(30)]
    out = script.executed_turn_rate(omega, 4 * script.GRID_S, 0.0)
    np.testing.assert_array_equal(out, np.r_[np.zeros(14), np.ones(26)])


def test_the_first_order_lag_follows_the_step_response_of_its_closed_form(script):
    """After the delay, a unit step reaches 1 − (1 − dt/τ)^n in n grid steps (the discrete
    first-order lag), within 1 % of the continuous 1 − exp(−t/τ)."""
    tau, delay, dt = 0.2, 0.1, script.GRID_S
    omega = np.ones(400)
    out = script.executed_turn_rate(omega, delay, tau)
    lag_steps = int(round(delay / dt))
    n = np.arange(1, 400 - lag_steps + 1)
    np.testing.assert_allclose(out[lag_steps:], 1.0 - (1.0 - dt / tau) ** n, rtol=1e-12)
    t = n * dt
    np.testing.assert_allclose(out[lag_steps:], 1.0 - np.exp(-t / tau), atol=0.01)
    np.testing.assert_array_equal(out[:lag_steps], 0.0)


def test_a_short_turn_pulse_is_executed_only_in_part(script):
    """The physical point of the lag: a 0.3 s pulse loses a share τ/T·(1 − e^(−T/τ)) of its
    turn before the pulse ends; all of it arrives once the lag has settled."""
    tau, pulse_s, dt = 0.2, 0.3, script.GRID_S
    steps = int(round(pulse_s / dt))
    omega = np.r_[np.ones(steps), np.zeros(400)]
    out = script.executed_turn_rate(omega, 0.0, tau)
    during = out[:steps].sum() * dt / pulse_s
    a, n = dt / tau, steps  # the discrete sum of 1 − (1 − a)^k, k = 1 … n
    assert during == pytest.approx((n - (1 - a) * (1 - (1 - a) ** n) / a) / n, rel=1e-9)
    assert during == pytest.approx(1.0 - tau / pulse_s * (1.0 - math.exp(-pulse_s / tau)), abs=0.015)
    assert out.sum() * dt == pytest.approx(pulse_s, rel=1e-4)  # 2 s later: (1 − a)^400 ≈ 4e-5 still to come


def test_the_script_runs_on_the_excerpt_and_writes_its_figures(script, tmp_path, capsys):
    out = tmp_path / "motor_lens.json"
    printed, result = run_main_with_json(script.main, [EXCERPT], out, capsys)
    assert "## motor" in printed and "## lens" in printed
    assert sorted(result["motor"]["robots"]) == sorted(result["lens"]) == ["1", "2", "3"]
    best, pure = result["motor"]["best"], result["motor"]["pure"]
    assert best["rms_rad"] <= pure["rms_rad"]  # the grid holds the pure delay
    assert 0.8 < best["scale"] < 1.1  # the robots turn about as commanded
    for cell in result["lens"].values():
        assert 0.001 < cell["linear_rad"] < 0.05  # a real camera's bearing spread (rad)


def test_a_folder_without_robots_is_one_clear_error(script, tmp_path, capsys):
    with pytest.raises(SystemExit):
        script.main([str(tmp_path)])
    assert "no RobotN_Odometry.dat here" in capsys.readouterr().err
