"""Colour landmarks on real RGB-D frames: no landmark in real clutter; composited cylinders found and measured.

The frames in tests/data/rgbd-real (Open3D's test sequence and a TUM RGB-D frame) contain
red, green and blue things but no landmark of ours. Rendered cylinders composited into them
at known poses (colour and depth, slamio.camera.composite) must be found (≥ 95 %), with
range error ≤ 2 %, bearing ≤ 0.5° and height ≤ 3 %, also when the depth image is
misregistered against the colour image by 2 px. docs/camera.md has the table over every
real frame (scripts/bench_colour_real.py).
"""

from __future__ import annotations

import math
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from slamio.camera.colour import DEFAULT_COLOURS
from slamio.camera.composite import composite, composite_trial, landmark_layer, shift_depth
from slamio.camera.detect import FrontEnd, FrontEndConfig
from slamio.camera.model import T_robot_camera_from_mount, kinect_v1_default
from slamio.camera.render import CYLINDER_BGR, CylinderSpec, Scene
from slamio.camera.sources import Frame, read_depth_png, read_image

DATA = Path(__file__).parent / "data" / "rgbd-real"
KINECT = kinect_v1_default(T_robot_camera_from_mount(x_m=0.1, z_m=0.3))
SHIFTS_PX = ((0, 0), (2, 0), (0, 2), (-2, -2))


def real_frames() -> list[tuple[str, np.ndarray, np.ndarray]]:
    """[(name, BGR, depth in metres)] of the shipped real frames."""
    out = []
    for name, scale in (("open3d_00000", 1000.0), ("open3d_00004", 1000.0), ("tum", 5000.0)):
        bgr, error = read_image(DATA / f"{name}_color.jpg")
        depth, depth_error = read_depth_png(DATA / f"{name}_depth.png", scale)
        assert error is None and depth_error is None
        out.append((name, bgr, depth))
    return out


@pytest.fixture(scope="module")
def frames():
    return real_frames()


@pytest.fixture(scope="module")
def front():
    return FrontEnd(KINECT, FrontEndConfig(kind="colour"))


def test_real_clutter_gives_no_landmark_and_every_rejection_is_named(frames, front):
    reasons = Counter()
    candidates = 0
    for index, (name, bgr, depth) in enumerate(frames):
        result = front.process(Frame(0.0, index, name, bgr, depth))
        assert result.observations == [], name
        reasons.update(r.reason for r in result.rejections)
        candidates += len(result.blobs)
    print(f"\n{candidates} candidate blobs on {len(frames)} real frames: {dict(reasons)}")
    assert candidates >= 20  # the frames really are full of red, green and blue things
    assert sum(reasons.values()) == candidates  # every candidate rejected, and counted by reason


def cylinders() -> list[CylinderSpec]:
    out = []
    for colour in DEFAULT_COLOURS:
        for distance_m in (1.0, 2.5, 4.0):
            for bearing_deg in (-15.0, 10.0):
                b = math.radians(bearing_deg)
                out.append(CylinderSpec(distance_m * math.cos(b), distance_m * math.sin(b), 0.5 * colour.width_m,
                                        colour.height_m, CYLINDER_BGR[colour.name], colour.name, colour.landmark_id))
    return out


@pytest.fixture(scope="module")
def trial(frames, front):
    scores = composite_trial(front, frames, cylinders(), SHIFTS_PX, supersample=2, noise_sigma=2.0, seed=0)
    print()
    for shift, s in scores.items():
        print(f"depth shift {shift}: found {s.found}/{s.placed}, wrong {s.wrong_landmarks}, "
              f"range {s.worst(s.range_pct):.2f} %, bearing {s.worst(s.bearing_deg):.3f} deg, "
              f"height {s.worst(s.height_pct):.2f} % (n={len(s.height_pct)})")
    return scores


@pytest.mark.parametrize("shift", SHIFTS_PX)
def test_composited_cylinders_are_found_and_measured(trial, shift):
    s = trial[shift]
    assert s.placed == 3 * len(cylinders())
    assert s.found_fraction >= 0.95
    assert s.wrong_landmarks == 0
    assert s.worst(s.range_pct) <= 2.0
    assert s.worst(s.bearing_deg) <= 0.5
    assert len(s.height_pct) >= 0.8 * s.found  # tall cylinders close by are cut off at the top
    assert s.worst(s.height_pct) <= 3.0


def test_composite_layer_matches_the_render():
    cyl = CylinderSpec(2.0, 0.2, 0.05, 0.4, CYLINDER_BGR["red"], "red", 0)
    layer = landmark_layer(KINECT, (0.0, 0.0, 0.0), Scene(cylinders=(cyl,)), supersample=2, depth_model="ideal")
    covered = layer.alpha > 0.99
    # 0.1 m wide at 1.96 m; rows from the near rim 0.1 m above the lens to the foot 0.3 m below it, 1.86 m away
    rows, cols = np.nonzero(covered)
    assert abs((cols.max() - cols.min() + 1) - 27) <= 2 and abs((rows.max() - rows.min() + 1) - 113) <= 2
    assert np.all(np.isfinite(layer.depth_m[covered]))
    assert np.nanmin(layer.depth_m) == pytest.approx(math.hypot(2.0, 0.2) - 0.05 - 0.1, abs=0.03)
    background = np.full((480, 640, 3), 90, np.uint8)
    bgr, depth = composite(background, np.full((480, 640), 5.0, np.float32), layer)
    assert np.all(bgr[~(layer.alpha > 0)] == 90) and np.all(depth[~np.isfinite(layer.depth_m)] == 5.0)


def test_shift_depth_moves_pixels_and_marks_the_gap_missing():
    depth = np.arange(12, dtype=np.float32).reshape(3, 4)
    out = shift_depth(depth, 1, -1)
    assert np.isnan(out[:, 0]).all() and np.isnan(out[2]).all()
    assert out[0, 1] == depth[1, 0] and out[1, 3] == depth[2, 2]
