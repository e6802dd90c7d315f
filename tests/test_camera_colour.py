"""Kinect colour landmarks: depth encodings, segmentation, seed 000/002's formulas, measurements."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from slamio.camera.colour import (
    DEFAULT_COLOURS,
    ColourOptions,
    ColourRejection,
    candidate_blobs,
    clean_mask,
    colour_mask,
    depth_from_kinect_raw,
    depth_from_mm,
    depth_from_scaled,
    detect_colour_landmarks,
    find_blobs,
    gheight_seed002,
    largest_blob,
    linear_bearing_error_rad,
    measure_blob,
)
from slamio.camera.model import T_robot_camera_from_mount, kinect_v1_default
from slamio.camera.render import CYLINDER_BGR, CylinderSpec, Scene, render

RED = DEFAULT_COLOURS[0]
KINECT = kinect_v1_default(T_robot_camera_from_mount(x_m=0.1, z_m=0.3))


def test_depth_encodings_mark_missing_readings():
    mm = np.array([[0, 1000], [2500, 65535]], dtype=np.uint16)
    d = depth_from_mm(mm)
    assert np.isnan(d[0, 0]) and d[0, 1] == 1.0 and d[1, 0] == 2.5
    tum = depth_from_scaled(np.array([[0, 5000, 10000]], dtype=np.uint16))
    assert np.isnan(tum[0, 0]) and list(tum[0, 1:]) == [1.0, 2.0]
    raw = depth_from_kinect_raw(np.array([2047, 600, 1083, 1100], dtype=np.uint16))
    assert np.isnan(raw[0])  # 2047: no reading
    assert raw[1] == pytest.approx(1.0 / (3.3309495161 - 0.0030711016 * 600), rel=1e-6)
    assert raw[2] > 10.0 and np.isnan(raw[3])  # past the fit's pole: no reading either


def test_seed000_linear_bearing_error_is_documented_size():
    errors = [math.degrees(linear_bearing_error_rad(u, kinect_v1_default())) for u in np.arange(0, 640, 0.5)]
    assert abs(errors[int(319.5 * 2)]) < 0.01  # exact at the centre
    worst = int(np.argmax(np.abs(errors)))
    assert 3.1 < abs(errors[worst]) < 3.3  # 57° over 640 px vs atan(x / 525)
    assert 240 < abs(worst / 2 - 319.5) < 260  # worst about 250 px from the centre, not at the edge
    assert 2.8 < abs(errors[0]) < 2.95


def test_gheight_is_the_law_of_cosines():
    rng = np.random.default_rng(4)
    for _ in range(20):
        d1, d2 = rng.uniform(0.5, 4.0, 2)
        theta_deg = rng.uniform(1.0, 40.0)
        expected = math.sqrt(d1 * d1 + d2 * d2 - 2 * d1 * d2 * math.cos(math.radians(theta_deg)))
        # pd pixels map to pd*vfov/rows degrees: one "row" spanning theta
        assert gheight_seed002(d1, d2, 1.0, vfov_deg=theta_deg, rows=1) == pytest.approx(expected)
    # as written: 47° over 480 rows
    assert gheight_seed002(2.0, 2.0, 0.0) == 0.0


def _red_image():
    image = np.full((120, 160, 3), 180, np.uint8)
    image[30:90, 40:70] = (30, 30, 200)  # the cylinder
    image[8:16, 118:126] = (30, 30, 200)  # a smaller red thing (64 px)
    rng = np.random.default_rng(1)
    speckle = rng.random((120, 160)) < 0.01
    image[speckle] = (30, 30, 200)
    return image


def speckle_free_region():
    """Rows and columns away from both red patches: only speckle there, which the opening removes."""
    return np.s_[95:120, 0:160]


def test_one_blob_per_colour_after_clean_up():
    import cv2

    hsv = cv2.cvtColor(_red_image(), cv2.COLOR_BGR2HSV)
    raw = colour_mask(hsv, RED)
    cleaned = clean_mask(raw)
    blob, small = candidate_blobs(cleaned, RED)
    # a speckle touching the edge may be merged by the closing: within a pixel
    assert np.abs(np.array([blob.left, blob.top, blob.right, blob.bottom]) - (40, 30, 69, 89)).max() <= 1
    assert raw[speckle_free_region()].sum() > 0  # the raw mask had speckle there
    assert clean_mask(raw)[speckle_free_region()].sum() == 0
    assert 56 <= small.area_px <= 66  # the 8×8 patch survives clean-up (the opening rounds its corners)
    assert largest_blob(cleaned, RED).area_px == blob.area_px
    blobs, missing = find_blobs(_red_image())
    assert [b.colour.name for b in blobs] == ["red", "red"] and missing == ["green", "blue"]


def test_min_area_drops_small_blobs():
    image = np.full((60, 60, 3), 180, np.uint8)
    image[20:25, 20:25] = (30, 30, 200)  # 25 px < 40
    blobs, missing = find_blobs(image)
    assert not blobs and "red" in missing


def test_blob_without_depth_is_rejected_by_name():
    frame = render(KINECT, (0.0, 0.0, 0.0), Scene(cylinders=(CylinderSpec(2.0, 0.0, 0.05, 0.4, CYLINDER_BGR["red"]),)),
                   supersample=2)
    depth = frame.depth_m.copy()
    depth[:, :] = np.nan  # a Kinect that saw nothing (0 mm / raw 2047 everywhere)
    measured, rejected, blobs = detect_colour_landmarks(frame.bgr, depth, KINECT)
    assert not measured and len(blobs) == 1
    assert isinstance(rejected[0], ColourRejection) and rejected[0].reason == "missing_depth"


@pytest.mark.parametrize("gain", [0.6, 1.0, 1.25])
def test_segmentation_survives_lighting_changes(gain):
    cyl = CylinderSpec(2.0, 0.3, 0.05, 0.6, CYLINDER_BGR["green"], "green", 1)
    frame = render(KINECT, (0.0, 0.0, 0.0), Scene(cylinders=(cyl,)), supersample=2, gain=gain)
    measured, rejected, _ = detect_colour_landmarks(frame.bgr, frame.depth_m, KINECT)
    assert not rejected and len(measured) == 1
    m = measured[0]
    assert m.colour == "green" and m.landmark_id == 1
    assert m.range_m == pytest.approx(math.hypot(2.0, 0.3), rel=0.01)
    assert m.bearing_rad == pytest.approx(math.atan2(0.3, 2.0), abs=math.radians(0.2))


def test_height_notes_when_the_cylinder_is_cut_by_the_image():
    # 0.8 m tall at 0.7 m: its top is above the view -> no height
    tall = CylinderSpec(0.7, 0.0, 0.05, 0.8, CYLINDER_BGR["blue"], "blue", 2)
    frame = render(KINECT, (0.0, 0.0, 0.0), Scene(cylinders=(tall,)), supersample=2)
    (m,), _, _ = detect_colour_landmarks(frame.bgr, frame.depth_m, KINECT)
    assert m.height_m is None and m.height_note == "height_cut_off"
    # 0.4 m tall at 0.55 m: the foot is below the view -> top above the floor (needs the mount height)
    short = CylinderSpec(0.55, 0.0, 0.05, 0.4, CYLINDER_BGR["red"], "red", 0)
    frame = render(KINECT, (0.0, 0.0, 0.0), Scene(cylinders=(short,)), supersample=2)
    (m,), _, _ = detect_colour_landmarks(frame.bgr, frame.depth_m, KINECT)
    assert m.height_note == "top-above-floor" and m.height_m == pytest.approx(0.4, rel=0.02)


def test_seed_options_run_and_are_worse():
    cyl = CylinderSpec(2.0, 0.7, 0.05, 0.4, CYLINDER_BGR["red"], "red", 0)
    frame = render(KINECT, (0.0, 0.0, 0.0), Scene(cylinders=(cyl,)), supersample=2)
    blobs, _ = find_blobs(frame.bgr)
    exact = measure_blob(blobs[0], frame.depth_m, KINECT)
    seeds = measure_blob(blobs[0], frame.depth_m, KINECT, ColourOptions(bearing_method="linear", height_method="gheight"))
    truth = math.atan2(0.7, 2.0)
    assert abs(exact.bearing_rad - truth) < math.radians(0.1)
    assert abs(seeds.bearing_rad - truth) > math.radians(1.5)  # the linear map is off by ~2.5° here
    assert abs(exact.height_m - 0.4) < 0.01 and seeds.height_note == "gheight" and abs(seeds.height_m - 0.4) > 0.02


def test_blob_cut_by_the_image_side_is_rejected():
    # 1.5 m ahead, 0.95 m to the right: the silhouette runs off the image's right side
    cyl = CylinderSpec(1.6, -0.95, 0.05, 0.4, CYLINDER_BGR["red"], "red", 0)
    frame = render(KINECT, (0.0, 0.0, 0.0), Scene(cylinders=(cyl,)), supersample=2)
    measured, rejected, blobs = detect_colour_landmarks(frame.bgr, frame.depth_m, KINECT)
    assert blobs and blobs[0].right == 639
    assert not measured and rejected[0].reason == "blob_at_image_border"


# --------------------------------------------------------------------------- the checks


FRONT_KINECT = kinect_v1_default(T_robot_camera_from_mount(x_m=0.1, z_m=0.3))
WALL_M = 4.5


def _board(shape: str, width_m: float, height_m: float, distance_m: float, bgr=(30, 30, 200),
           image=None, depth=None):
    """A flat board of this shape standing on the floor, facing the level camera ``distance_m`` ahead
    (depth = distance_m on the board exactly), in front of a grey wall at 4.5 m."""
    import cv2

    cam = FRONT_KINECT
    if image is None:
        image = np.full((480, 640, 3), 150, np.uint8)
        depth = np.full((480, 640), WALL_M, np.float32)
    f, cx, cy, lens_z = cam.fx, cam.cx, cam.cy, 0.3
    left, right = cx - f * width_m / 2 / distance_m, cx + f * width_m / 2 / distance_m
    top, bottom = cy - f * (height_m - lens_z) / distance_m, cy + f * lens_z / distance_m
    mask = np.zeros((480, 640), np.uint8)
    if shape == "rectangle":
        pts = [(left, top), (right, top), (right, bottom), (left, bottom)]
    elif shape == "triangle":
        pts = [(cx, top), (right, bottom), (left, bottom)]
    if shape == "circle":
        cv2.ellipse(mask, (int(round(cx * 16)), int(round(0.5 * (top + bottom) * 16))),
                    (int(round((right - left) / 2 * 16)), int(round((bottom - top) / 2 * 16))), 0, 0, 360, 255, -1,
                    cv2.LINE_8, 4)
    else:
        # polygon vertices at pixel boundaries: shift by ½ so the fill covers [left, right)
        cv2.fillPoly(mask, [np.round((np.array(pts) - 0.5) * 16).astype(np.int32)], 255, cv2.LINE_8, 4)
    inside = mask > 0
    image = image.copy()
    depth = depth.copy()
    image[inside] = bgr
    depth[inside] = distance_m
    return image, depth


def _spec(shape, width_m, height_m):
    return replace(RED, shape=shape, width_m=width_m, height_m=height_m)


@pytest.mark.parametrize("shape,width_m,height_m", [("rectangle", 0.30, 0.405), ("triangle", 0.28, 0.243),
                                                     ("circle", 0.24, 0.24), ("cylinder", 0.10, 0.40)])
def test_seed002_shapes_are_measured(shape, width_m, height_m):
    distance = 1.8
    image, depth = _board("rectangle" if shape == "cylinder" else shape, width_m, height_m, distance)
    options = ColourOptions(colours=(_spec(shape, width_m, height_m),))
    measured, rejected, _ = detect_colour_landmarks(image, depth, FRONT_KINECT, options)
    assert not rejected and len(measured) == 1
    m = measured[0]
    face_to_point = 0.5 * width_m if shape == "cylinder" else 0.0  # a flat "cylinder": its face plus a radius
    assert m.range_m == pytest.approx(distance + 0.1 + face_to_point, abs=0.005)
    assert abs(m.bearing_rad) < math.radians(0.1)
    assert m.height_m == pytest.approx(height_m, rel=0.03)
    assert m.width_m == pytest.approx(width_m, rel=0.1 if shape != "cylinder" else 0.35)


def test_each_check_rejects_by_name():
    cases = {
        # a triangle where a rectangle is expected, and the other way round
        "shape_mismatch": (_board("triangle", 0.3, 0.4, 2.0), _spec("rectangle", 0.3, 0.4)),
        # right shape, twice the width
        "size_mismatch": (_board("rectangle", 0.6, 0.4, 2.0), _spec("rectangle", 0.3, 0.4)),
        # right shape and width, 50 % taller
        "height_mismatch": (_board("rectangle", 0.3, 0.6, 2.0), _spec("rectangle", 0.3, 0.4)),
    }
    image, depth = _board("rectangle", 0.3, 0.4, 2.0)
    # the board's depth running from 2.0 m to 2.8 m across its 0.3 m: a surface turned away from the
    # camera, not an upright landmark facing it (and no depth jump to split it along)
    columns = np.broadcast_to(np.arange(640, dtype=np.float32), depth.shape)
    ramp = np.where(depth < WALL_M, 2.0 + 0.8 * (columns - 280.0) / 80.0, depth)
    cases["depth_inconsistent"] = ((image, ramp.astype(np.float32)), _spec("rectangle", 0.3, 0.4))
    for reason, ((image, depth), spec) in cases.items():
        measured, rejected, blobs = detect_colour_landmarks(image, depth, FRONT_KINECT, ColourOptions(colours=(spec,)))
        assert not measured, reason
        assert [r.reason for r in rejected] == [reason], (reason, rejected)
        assert rejected[0].blob is blobs[0] and rejected[0].detail


def test_a_landmark_in_front_of_its_colour_is_split_off_by_depth():
    # a red wall section (1 m wide, 1.2 m tall at 3 m) right behind a red rectangle at 2 m
    wall_image, wall_depth = _board("rectangle", 1.0, 1.2, 3.0)
    image, depth = _board("rectangle", 0.3, 0.4, 2.0, image=wall_image, depth=wall_depth)
    spec = _spec("rectangle", 0.3, 0.4)
    blobs, _ = find_blobs(image, ColourOptions(colours=(spec,)))
    assert len(blobs) == 1  # one colour blob ...
    measured, rejected, _ = detect_colour_landmarks(image, depth, FRONT_KINECT, ColourOptions(colours=(spec,)))
    assert not rejected and len(measured) == 1  # ... but the landmark is found in it
    assert measured[0].range_m == pytest.approx(2.1, abs=0.01)
    assert measured[0].height_m == pytest.approx(0.4, rel=0.03)


@pytest.mark.parametrize("shift", [(2, 0), (-2, 0), (0, 2), (0, -2), (2, 2)])
def test_height_survives_depth_misregistration(shift):
    """Depth shifted 2 px against colour, a cylinder at 2 m in front of a wall at 4.5 m."""
    from slamio.camera.composite import composite, landmark_layer

    cyl = CylinderSpec(2.0, 0.0, 0.05, 0.4, CYLINDER_BGR["red"], "red", 0)
    layer = landmark_layer(KINECT, (0.0, 0.0, 0.0), Scene(cylinders=(cyl,)), supersample=3)
    background = np.full((480, 640, 3), 150, np.uint8)
    image, depth = composite(background, np.full((480, 640), WALL_M, np.float32), layer, depth_shift_px=shift)
    measured, rejected, _ = detect_colour_landmarks(image, depth, KINECT)
    assert not rejected and len(measured) == 1
    m = measured[0]
    assert m.height_m == pytest.approx(0.4, rel=0.03)
    assert m.range_m == pytest.approx(2.0, rel=0.02)


@pytest.mark.parametrize("shift", [(0, 0), (2, 0)])
def test_height_ignores_a_thin_corner_of_its_colour_touching_the_top(shift):
    """A red picture frame's corner on the wall (7 m) touches the top of a red cylinder at 4 m: two
    rows a few pixels wide join the blob within the misregistration margin; they are not the landmark."""
    from slamio.camera.composite import composite, landmark_layer

    cyl = CylinderSpec(4.0, 0.0, 0.05, 0.4, CYLINDER_BGR["red"], "red", 0)
    layer = landmark_layer(KINECT, (0.0, 0.0, 0.0), Scene(cylinders=(cyl,)), supersample=3)
    rows = np.nonzero((layer.alpha > 0.5).any(axis=1))[0]
    cols = np.nonzero((layer.alpha > 0.5).any(axis=0))[0]
    background = np.full((480, 640, 3), 150, np.uint8)
    u = int(cols.mean())
    background[rows[0] - 3 : rows[0] + 1, u - 2 : u + 2] = (30, 30, 190)  # 4 px wide, red, at the wall's depth
    image, depth = composite(background, np.full((480, 640), 7.0, np.float32), layer, depth_shift_px=shift)
    measured, rejected, _ = detect_colour_landmarks(image, depth, KINECT)
    assert not rejected and len(measured) == 1
    assert measured[0].height_m == pytest.approx(0.4, rel=0.03)
