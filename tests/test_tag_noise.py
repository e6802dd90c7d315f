"""The AprilTag observation model: closed-form limits, the pinhole reference, the viewing angle."""

from __future__ import annotations

import math

import numpy as np
import pytest

from slamio.camera.tag_noise import MEASURED_GAINS, TagNoise, TagNoiseGains, view_angle_rad

UNIT = TagNoiseGains(bearing=1.0, range=1.0, range_view_power=0.0, yaw=1.0)


def test_unit_gains_give_the_pinhole_formulas():
    """Gain 1: the tag's centre moves by σ_px (σ_b = σ_px/fx) and its apparent size fx·s/r by
    σ_px (σ_r = r²·σ_px/(fx·s))."""
    model = TagNoise(525.0, 0.16, 0.3, UNIT)
    for r in (0.5, 1.0, 2.5):
        assert model.sigma_range_m(r, 0.0) == pytest.approx(r**2 * 0.3 / (525.0 * 0.16))
    assert model.sigma_bearing_rad() == pytest.approx(0.3 / 525.0)


def test_yaw_sigma_limits_frontal_and_oblique():
    model = TagNoise(500.0, 0.2, 0.5, UNIT)
    r = 2.0
    eps = 0.5 * r / (500.0 * 0.2)  # 0.01
    # head on: the foreshortening is second order in φ, so σ ≈ √ε
    assert model.sigma_tag_yaw_rad(r, 0.0) == pytest.approx(math.sqrt(eps))
    # well away from frontal: σ ≈ ε / sin φ
    assert model.sigma_tag_yaw_rad(r, math.radians(60)) == pytest.approx(eps / math.sin(math.radians(60)), rel=0.01)
    # monotone: worse with distance, better away from frontal
    views = np.radians([0, 10, 20, 40, 60])
    assert np.all(np.diff(model.sigma_tag_yaw_rad(r, views)) < 0)
    assert np.all(np.diff(model.sigma_tag_yaw_rad(np.array([0.5, 1, 2, 3]), 0.3)) > 0)


def test_range_view_power_and_arrays():
    model = TagNoise(500.0, 0.2, 0.5, TagNoiseGains(1.0, 2.0, 1.0, 1.0))
    r = np.array([1.0, 2.0])
    view = np.radians([0.0, 60.0])
    expected = 2.0 * r**2 * 0.5 / (500.0 * 0.2) / np.cos(view)
    np.testing.assert_allclose(model.sigma_range_m(r, view), expected)
    assert model.sigma_bearing_rad(r).shape == (2,)


def test_view_angle_from_robot_frame_values():
    # a tag straight ahead facing the robot: normal points back at it (yaw π), bearing 0
    assert view_angle_rad(0.0, math.pi) == pytest.approx(0.0)
    # the same tag turned 30° either way
    assert view_angle_rad(0.0, math.pi + 0.5) == pytest.approx(0.5)
    assert view_angle_rad(0.0, math.pi - 0.5) == pytest.approx(0.5)
    # seen 0.4 rad to the left, facing the robot
    assert view_angle_rad(0.4, 0.4 + math.pi) == pytest.approx(0.0, abs=1e-12)


def test_bad_parameters_and_the_measured_gains_are_sane():
    with pytest.raises(ValueError):
        TagNoise(0.0, 0.16)
    assert all(0.1 < g < 10 for g in (MEASURED_GAINS.bearing, MEASURED_GAINS.range, MEASURED_GAINS.yaw))


def test_the_real_corner_sigma_is_what_the_photos_give():
    from pathlib import Path

    from slamio.camera.accuracy import real_corner_sigma_px
    from slamio.camera.tag_noise import REAL_CORNER_SIGMA_PX

    sigma_px, tags = real_corner_sigma_px(Path(__file__).resolve().parent / "data" / "apriltag-photos")
    assert tags >= 50
    assert sigma_px == pytest.approx(REAL_CORNER_SIGMA_PX, abs=0.01)
