"""The example camera files in data/cameras load to the models they stand for: the Kinect v1
ROS camera_info file is slamio.camera.model.kinect_v1_default(), and the Kalibr fisheye is
TagSLAM test_22's T265 camera, whose projection is checked against the equidistant
(Kannala-Brandt) formula worked by hand. The docs point users at both files."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from slamio.camera.camera_files import load_camera_file
from slamio.camera.model import kinect_v1_default, load_camera

ROOT = Path(__file__).resolve().parents[1]
CAMERAS = ROOT / "data" / "cameras"


def test_the_kinect_file_is_the_products_kinect_v1_model():
    expected = kinect_v1_default()
    for camera in (load_camera(CAMERAS / "kinect_v1.yaml"), load_camera_file(CAMERAS / "kinect_v1.yaml")):
        assert (camera.width_px, camera.height_px, camera.distortion_model, camera.name) == \
            (expected.width_px, expected.height_px, expected.distortion_model, expected.name)
        np.testing.assert_array_equal(camera.K, expected.K)
        np.testing.assert_array_equal(camera.dist_coeffs, expected.dist_coeffs)
        np.testing.assert_allclose(camera.T_robot_camera, expected.T_robot_camera, atol=1e-15)
    assert math.degrees(expected.horizontal_fov_rad) == pytest.approx(2 * math.degrees(math.atan(320 / 525)))


def test_the_fisheye_file_is_test_22s_t265_camera_at_its_true_size():
    camera = load_camera_file(CAMERAS / "fisheye_kalibr.yaml")
    test_22 = load_camera_file(ROOT / "tests" / "data" / "rosbag-tagslam-test_22" / "cameras.yaml", "cam0")
    assert camera.distortion_model == "equidistant" == test_22.distortion_model
    np.testing.assert_array_equal(camera.K, test_22.K)
    np.testing.assert_array_equal(camera.dist_coeffs, [0.00132, 0.03049, -0.02875, 0.0034])
    # The T265 fisheye is 848 wide, 800 high (principal point 421, 401 near the centre);
    # test_22's file has them the other way round, [800, 848], which TagSLAM never reads.
    assert (camera.width_px, camera.height_px) == (848, 800) and (test_22.width_px, test_22.height_px) == (800, 848)
    # A point 60 deg off the axis, by hand: theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8),
    # u = fx theta_d cos(phi) + cx, v = fy theta_d sin(phi) + cy.
    k1, k2, k3, k4 = 0.00132, 0.03049, -0.02875, 0.0034
    theta, phi = math.radians(60.0), math.radians(30.0)
    theta_d = theta * (1 + k1 * theta ** 2 + k2 * theta ** 4 + k3 * theta ** 6 + k4 * theta ** 8)
    point = np.array([[math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi), math.cos(theta)]]) * 2.0
    uv = camera.project(point)
    assert uv[0] == pytest.approx([283.943 * theta_d * math.cos(phi) + 421.079,
                                   284.986 * theta_d * math.sin(phi) + 400.527], abs=1e-6)


def test_the_docs_point_at_the_example_files():
    for page in ("README.md", "docs/camera.md", "docs/datasets-mrclam-rosbag.md"):
        text = (ROOT / page).read_text(encoding="utf-8")
        assert "data/cameras/kinect_v1.yaml" in text or "data/cameras/fisheye_kalibr.yaml" in text, page
    assert "data/cameras/fisheye_kalibr.yaml" in (ROOT / "docs/datasets-mrclam-rosbag.md").read_text(encoding="utf-8")
