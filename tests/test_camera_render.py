"""The renderer that gives the front-end frames with known truth: geometry, depth, determinism."""

from __future__ import annotations

import math

import numpy as np
import pytest

from slamio.camera.model import CameraModel, T_robot_camera_from_mount, kinect_v1_default
from slamio.camera.render import (
    CYLINDER_BGR,
    BoardSpec,
    board_inside,
    CylinderSpec,
    Scene,
    TagSpec,
    kinect_quantise_depth,
    project_world_points,
    render,
    subpixel_offsets,
    tag_cells,
    tag_corners_world,
)

CAM = kinect_v1_default(T_robot_camera_from_mount(x_m=0.1, z_m=0.3))


def test_floor_depth_is_exact():
    frame = render(CAM, (0.0, 0.0, 0.0), Scene(), supersample=1)
    # a pixel below the horizon sees the floor: depth = h / (y/f) for a level camera
    v = 400
    assert frame.depth_m[v, 320] == pytest.approx(0.3 / ((v - CAM.cy) / CAM.fy), rel=1e-6)
    assert np.isnan(frame.depth_m[100, 320])  # above the horizon: nothing, no depth
    assert frame.bgr.dtype == np.uint8 and frame.bgr.shape == (480, 640, 3)


def test_cylinder_depth_and_silhouette():
    cyl = CylinderSpec(2.1, 0.0, 0.05, 0.4, CYLINDER_BGR["red"])
    frame = render(CAM, (0.0, 0.0, 0.0), Scene(cylinders=(cyl,)), supersample=1)
    # straight ahead of the camera: the face nearest the camera is 2.0 - 0.05 m away
    assert frame.depth_m[239, 320] == pytest.approx(2.0 - 0.05, abs=1e-3)
    # half-width in pixels of a 5 cm radius at ~2 m
    row = frame.bgr[239, :, 2].astype(int) - frame.bgr[239, :, 0]
    width = int((row > 50).sum())
    assert width == pytest.approx(2 * 525 * 0.05 / 2.0, abs=2)


def test_tag_pattern_comes_from_the_dictionary():
    cells = tag_cells("tag36h11", 0)
    assert cells.shape == (8, 8)
    assert not cells[0].any() and not cells[:, 0].any()  # the black border
    with pytest.raises(ValueError):
        tag_cells("tagStandard41h12", 0)


def test_tag_corners_project_where_rendered():
    tag = TagSpec(3, 1.0, 0.0, 0.3, math.pi, 0.16)
    frame = render(CAM, (0.0, 0.0, 0.0), Scene(tags=(tag,)), supersample=1)
    tl, tr, br, bl = project_world_points(CAM, (0.0, 0.0, 0.0), tag_corners_world(tag))
    assert tl[0] < tr[0] and tl[1] < bl[1]  # upright, not mirrored
    u, v = int(round(tl[0] + 3)), int(round(tl[1] + 3))
    assert frame.bgr[v, u].max() < 50  # just inside the top-left corner: black border
    assert frame.bgr[int(tl[1]) - 5, int(tl[0]) - 5].min() > 200  # the white margin


def test_noise_needs_a_seeded_generator_and_is_deterministic():
    scene = Scene(cylinders=(CylinderSpec(2.0, 0.0, 0.05, 0.4, CYLINDER_BGR["blue"]),))
    with pytest.raises(ValueError):
        render(CAM, (0.0, 0.0, 0.0), scene, noise_sigma=2.0)
    a = render(CAM, (0.0, 0.0, 0.0), scene, noise_sigma=2.0, rng=np.random.default_rng(5), supersample=2)
    b = render(CAM, (0.0, 0.0, 0.0), scene, noise_sigma=2.0, rng=np.random.default_rng(5), supersample=2)
    assert np.array_equal(a.bgr, b.bgr)


def test_over_exposure_saturates():
    frame = render(CAM, (0.0, 0.0, 0.0), Scene(), gain=4.0, supersample=1)
    assert (frame.bgr >= 250).mean() > 0.9


def test_kinect_quantisation_step_grows_with_depth_squared():
    for depth in (1.0, 2.0, 4.0):
        z = np.linspace(depth - 0.1, depth + 0.1, 2000, dtype=np.float64)
        levels = np.unique(kinect_quantise_depth(z))
        assert np.median(np.diff(levels)) == pytest.approx(0.00307 * depth**2, rel=0.1)
    assert np.isnan(kinect_quantise_depth(np.array([np.nan])))[0]


def test_subpixel_pattern_is_n_rooks():
    offsets = subpixel_offsets(16)
    assert len(np.unique(offsets[:, 0])) == 16 and len(np.unique(offsets[:, 1])) == 16
    assert np.all(np.abs(offsets) < 0.5) and np.allclose(offsets.mean(axis=0), 0.0)


def test_distorted_camera_renders_through_its_lens():
    cam = CameraModel(640, 480, CAM.K, np.array([-0.2, 0.05, 0.0, 0.0, 0.0]), "plumb_bob", CAM.T_robot_camera)
    tag = TagSpec(5, 1.2, 0.35, 0.3, math.pi, 0.16)
    frame = render(cam, (0.0, 0.0, 0.0), Scene(tags=(tag,)), supersample=2)
    tl = project_world_points(cam, (0.0, 0.0, 0.0), tag_corners_world(tag))[0]
    u, v = int(round(tl[0] + 2)), int(round(tl[1] + 2))
    assert frame.bgr[v, u].max() < 60


def test_board_shapes_inside_tests():
    # rectangle 0.2 × 0.4, triangle base 0.2 height 0.3 (apex up), circle 0.2 across
    assert board_inside("rectangle", 0.099, 0.399, 0.2, 0.4) and not board_inside("rectangle", 0.101, 0.2, 0.2, 0.4)
    assert board_inside("triangle", 0.0, 0.299, 0.2, 0.3) and not board_inside("triangle", 0.06, 0.15, 0.2, 0.3)
    assert board_inside("triangle", 0.049, 0.15, 0.2, 0.3)  # half width at mid height is 0.05
    assert board_inside("circle", 0.0, 0.199, 0.2, 0.2) and not board_inside("circle", 0.08, 0.02, 0.2, 0.2)
    with pytest.raises(ValueError, match="board shape"):
        BoardSpec("hexagon", 1.0, 0.0, 0.2, 0.2, math.pi, (0, 0, 200))


@pytest.mark.parametrize("shape, width, height", [("rectangle", 0.2, 0.4), ("triangle", 0.24, 0.3), ("circle", 0.24, 0.24)])
def test_board_silhouette_and_depth_where_projected(shape, width, height):
    board = BoardSpec(shape, 2.1, 0.0, width, height, math.pi, CYLINDER_BGR["blue"], bottom_m=0.1)
    frame = render(CAM, (0.0, 0.0, 0.0), Scene(boards=(board,)), supersample=1)
    blue = (frame.bgr[..., 0].astype(int) - frame.bgr[..., 2]) > 60
    rows = np.nonzero(blue.any(axis=1))[0]
    # its top and bottom project to these rows (the board faces the camera 2.0 m ahead of the lens)
    top, bottom = project_world_points(CAM, (0.0, 0.0, 0.0), np.array([[2.1, 0.0, 0.1 + height], [2.1, 0.0, 0.1]]))
    apex_px = 2.0 if shape == "triangle" else 1.0  # a triangle's last rows are narrower than a pixel
    assert rows.min() == pytest.approx(top[1], abs=apex_px) and rows.max() == pytest.approx(bottom[1], abs=1.0)
    middle = int(round(0.5 * (top[1] + bottom[1])))
    assert frame.depth_m[middle, 320] == pytest.approx(2.0, abs=1e-3)  # a flat face: depth = distance
    area = blue.sum() / (525.0 / 2.0) ** 2  # pixels → m² at 2 m
    expected = {"rectangle": width * height, "triangle": 0.5 * width * height, "circle": math.pi * width**2 / 4}[shape]
    assert area == pytest.approx(expected, rel=0.05)
