"""Camera model: the ROS camera_info YAML, distortion round trips, the mount and its frames."""

from __future__ import annotations

import math

import numpy as np
import pytest

from slamio.camera.model import (
    CameraConfigError,
    CameraModel,
    T_robot_camera_from_mount,
    camera_from_dict,
    floor_range_bearing,
    invert_transform,
    kinect_v1_default,
    load_camera,
    save_camera,
    transform_points,
)

ROS_YAML = """\
image_width: 640
image_height: 480
camera_name: webcam
camera_matrix:
  rows: 3
  cols: 3
  data: [600.5, 0, 322.1, 0, 601.2, 241.7, 0, 0, 1]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [0.11, -0.21, 0.001, -0.002, 0.05]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]
projection_matrix:
  rows: 3
  cols: 4
  data: [600.5, 0, 322.1, 0, 0, 601.2, 241.7, 0, 0, 0, 1, 0]
robot_mount: {x_m: 0.1, y_m: -0.02, z_m: 0.3, pitch_rad: 0.1}
"""


def test_reads_a_ros_camera_info_file(tmp_path):
    path = tmp_path / "cam.yaml"
    path.write_text(ROS_YAML)
    cam = load_camera(path)
    assert (cam.width_px, cam.height_px, cam.name) == (640, 480, "webcam")
    assert (cam.fx, cam.fy, cam.cx, cam.cy) == (600.5, 601.2, 322.1, 241.7)
    assert cam.distortion_model == "plumb_bob" and cam.dist_coeffs[0] == 0.11
    assert np.allclose(cam.T_robot_camera, T_robot_camera_from_mount(x_m=0.1, y_m=-0.02, z_m=0.3, pitch_rad=0.1))


def test_save_then_load_gives_the_same_model(tmp_path):
    cam = CameraModel(320, 240, np.array([[300.0, 0.1, 160.0], [0, 301.0, 120.0], [0, 0, 1]]),
                      np.array([0.01, 0.02, 0.0, 0.0, 0.0, 0.001, 0.0, 0.0]), "rational_polynomial",
                      T_robot_camera_from_mount(0.05, 0.0, 0.25, yaw_rad=0.2), "x")
    save_camera(tmp_path / "c.yaml", cam, comment="written by a test")
    again = load_camera(tmp_path / "c.yaml")
    assert (tmp_path / "c.yaml").read_text().startswith("# written by a test")
    for name in ("K", "dist_coeffs", "T_robot_camera"):
        assert np.allclose(getattr(again, name), getattr(cam, name))
    assert again.distortion_model == "rational_polynomial"


@pytest.mark.parametrize(
    "change, message",
    [
        ({"image_width": 0}, "image_width"),
        ({"camera_matrix": {"rows": 3, "cols": 3, "data": [1, 2, 3]}}, "rows=3, cols=3 but has 3"),
        ({"camera_matrix": {"rows": 3, "cols": 3, "data": [0, 0, 1, 0, 5, 1, 0, 0, 1]}}, "fx, fy > 0"),
        ({"distortion_model": "fisheye_magic"}, "not supported"),
        ({"distortion_coefficients": {"rows": 1, "cols": 3, "data": [0, 0, 0]}}, "takes 4 or 5"),
        ({"robot_mount": {"z_mm": 300}}, "unknown key(s) z_mm"),
        ({"T_robot_camera": {"rows": 4, "cols": 4, "data": [2] * 16}}, "rigid transform"),
    ],
)
def test_bad_camera_files_say_what_to_fix(change, message):
    d = {"image_width": 640, "image_height": 480,
         "camera_matrix": {"rows": 3, "cols": 3, "data": [525, 0, 319.5, 0, 525, 239.5, 0, 0, 1]}}
    d.update(change)
    with pytest.raises(CameraConfigError, match=message.replace("(", r"\(").replace(")", r"\)")):
        camera_from_dict(d, "cam.yaml")


def test_missing_or_broken_file_is_a_user_error(tmp_path):
    with pytest.raises(CameraConfigError, match="cannot read the camera file"):
        load_camera(tmp_path / "nope.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("image_width: [640\n")
    with pytest.raises(CameraConfigError, match="not valid YAML"):
        load_camera(bad)


@pytest.mark.parametrize("model, coeffs", [
    ("plumb_bob", [0.12, -0.25, 0.001, -0.002, 0.08]),
    ("rational_polynomial", [0.1, -0.05, 0.001, 0.001, 0.0, 0.02, 0.0, 0.0]),
    ("equidistant", [0.05, -0.01, 0.002, -0.001]),
])
def test_project_and_normalize_are_inverse(model, coeffs):
    cam = CameraModel(640, 480, kinect_v1_default().K, np.array(coeffs), model)
    rng = np.random.default_rng(3)
    p = np.column_stack([rng.uniform(-0.5, 0.5, 50), rng.uniform(-0.4, 0.4, 50), rng.uniform(1.0, 3.0, 50)])
    uv = cam.project(p)
    rays = cam.rays_camera(uv)
    assert np.allclose(rays * p[:, 2:3], p, atol=1e-7)


def test_mount_frames_follow_the_conventions():
    T = T_robot_camera_from_mount(x_m=0.1, z_m=0.3)
    # the optical axis (camera z) looks along robot x; camera x (image right) is robot -y
    assert np.allclose(T[:3, 2], [1, 0, 0]) and np.allclose(T[:3, 0], [0, -1, 0]) and np.allclose(T[:3, 1], [0, 0, -1])
    assert np.allclose(transform_points(invert_transform(T), transform_points(T, [[0.2, -0.1, 2.0]])), [[0.2, -0.1, 2.0]])
    down = T_robot_camera_from_mount(pitch_rad=0.2)
    assert down[2, 2] < 0  # positive pitch looks down
    # a point 2 m ahead and 1 m to the left: bearing +26.6° (counter-clockwise from x)
    r, b = floor_range_bearing(np.array([2.0, 1.0, 0.7]))
    assert math.isclose(r, math.sqrt(5)) and math.isclose(b, math.atan2(1, 2))


def test_kinect_default_matches_the_design_facts():
    cam = kinect_v1_default()
    assert (cam.fx, cam.fy, cam.cx, cam.cy, cam.width_px, cam.height_px) == (525, 525, 319.5, 239.5, 640, 480)
    assert math.degrees(cam.horizontal_fov_rad) == pytest.approx(62.7, abs=0.1)


def test_size_mismatch_names_a_size_given_height_first():
    """TagSLAM's test_22 cameras.yaml says [800, 848] for its 848-wide T265 images."""
    from slamio.camera.camera_files import load_camera_file

    camera = load_camera_file("data/cameras/fisheye_kalibr.yaml")
    assert (camera.width_px, camera.height_px) == (848, 800)
    assert camera.size_mismatch(848, 800) is None
    fits_other_camera = camera.size_mismatch(640, 480)
    assert "640×480" in fits_other_camera and "848×800" in fits_other_camera and "height first" not in fits_other_camera
    swapped = camera.size_mismatch(800, 848)
    assert "800×848" in swapped and "height first" in swapped
