"""slamio.camera.depth_scan: the obstacle scan from depth images of the clutter room, rendered
(ideal and Kinect-quantised depth) and checked against ray-cast truth (slamio.obstacles)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from slamio.camera.depth_scan import depth_scan, kinect_scan_camera, ray_cast_depth_scan
from slamio.camera.render import kinect_quantise_depth, render
from slamio.clutter import clutter_world
from slamio.errors import FgslamError
from slamio.obstacles import clearance_m, ray_cast_m

CAMERA = kinect_scan_camera()  # 57°, 0.13 m ahead, 0.30 m up


def _poses(world, count, rng):
    poses = []
    while len(poses) < count:
        x, y = rng.uniform(0.4, 5.6, 2)
        if clearance_m(world.obstacles, (x, y)) > 0.3:
            poses.append((float(x), float(y), float(rng.uniform(-math.pi, math.pi))))
    return poses


@pytest.fixture(scope="module")
def frames():
    """(world, pose, ideal depth) for 8 poses in 4 rooms."""
    out = []
    for seed in range(4):
        world = clutter_world(seed)
        for pose in _poses(world, 2, np.random.default_rng(seed)):
            out.append((world, pose, render(CAMERA, pose, world.scene(), supersample=1).depth_m))
    return out


def _truth(world, pose, scan):
    return ray_cast_m(world.obstacles, pose[:2], scan.angles_rad + pose[2], min_height_m=0.05)


def test_the_fan_is_what_the_camera_sees_from_half_a_metre():
    scan = depth_scan(np.full((480, 640), 2.0, np.float32), CAMERA)
    # robot-centre ray β in the 57° view from 0.5 m: 0.5 sin β / (0.5 cos β − 0.13) ≤ tan 28.5° → β ≤ 21.37°:
    # the last ray (a multiple of 0.5°) is at 21.0°
    assert np.degrees(scan.angles_rad[-1]) == pytest.approx(21.0) and np.degrees(scan.angles_rad[0]) == pytest.approx(-21.0)
    assert np.allclose(np.diff(scan.angles_rad), math.radians(0.5))
    assert scan.max_range_m == 4.0


@pytest.mark.parametrize("depth_model", ["ideal", "kinect"])
def test_ranges_match_the_ray_cast_truth(frames, depth_model):
    errors, free_truth, unknown = [], [], 0
    total = 0
    for world, pose, depth in frames:
        scan = depth_scan(depth if depth_model == "ideal" else kinect_quantise_depth(depth), CAMERA)
        truth = _truth(world, pose, scan)
        in_range = (truth >= 0.8) & (truth <= 4.0)
        total += in_range.sum()
        unknown += np.isnan(scan.ranges_m[in_range]).sum()
        hit = in_range & np.isfinite(scan.ranges_m)
        errors.append(scan.ranges_m[hit] - truth[hit])
        free_truth.append(truth[np.isposinf(scan.ranges_m)])
        assert not np.any(np.isposinf(scan.ranges_m) & (truth < 3.9))  # never free before an obstacle
    e = np.concatenate(errors)
    # measured: ideal median 3.4 mm, p90 19 mm; kinect median 5.2 mm, p90 20 mm (8 frames, 484 rays)
    assert np.median(np.abs(e)) <= 0.02
    assert np.percentile(np.abs(e), 90) <= 0.05
    assert unknown <= 0.05 * total  # a few rays: what the robot's centre sees past an edge the camera does not
    assert np.all(np.concatenate(free_truth) >= 3.9)
    assert np.median(e) < 0.0  # the nearest point of a bin: never farther than the middle of it


def test_a_hole_in_the_depth_makes_its_rays_unknown(frames):
    world, pose, depth = frames[0]
    holed = depth.copy()
    holed[:, 300:340] = np.nan  # 40 columns without depth around the centre
    scan, whole = depth_scan(holed, CAMERA), depth_scan(depth, CAMERA)
    centre = np.abs(scan.angles_rad) <= math.radians(1.0)
    assert np.all(np.isnan(scan.ranges_m[centre])) and np.all(np.isfinite(whole.ranges_m[centre]))
    away = np.abs(scan.angles_rad) >= math.radians(4.0)
    assert np.array_equal(scan.ranges_m[away], whole.ranges_m[away], equal_nan=True)


def test_a_black_box_is_unknown_never_free_or_the_wall_behind_it():
    from slamio.camera.render import Scene, WallSpec

    room = Scene(walls=(WallSpec(3.0, -3.0, 3.0, 3.0, 2.0),))  # a wall 3 m ahead
    box = Scene(walls=(WallSpec(3.0, -3.0, 3.0, 3.0, 2.0), WallSpec(1.5, -0.2, 1.5, 0.2, 0.25)))  # 0.25 m tall, 1.5 m
    wall_only = render(CAMERA, (0.0, 0.0, 0.0), room, supersample=1).depth_m
    with_box = render(CAMERA, (0.0, 0.0, 0.0), box, supersample=1).depth_m
    black = np.where(np.isclose(with_box, wall_only, atol=1e-4), with_box, np.nan)  # the box returns no light
    seen, dark = depth_scan(with_box, CAMERA), depth_scan(black, CAMERA)
    behind = np.abs(np.tan(seen.angles_rad) * 1.5) < 0.18  # rays that meet the box's face
    assert np.allclose(seen.ranges_m[behind], 1.5 / np.cos(seen.angles_rad[behind]), atol=0.01)
    assert np.all(np.isnan(dark.ranges_m[behind]))
    clear = np.abs(np.tan(seen.angles_rad) * 1.5) > 0.3
    assert np.allclose(dark.ranges_m[clear], 3.0 / np.cos(dark.angles_rad[clear]), atol=0.01)


def test_free_only_as_far_as_the_depth_saw():
    from slamio.camera.render import Scene, WallSpec

    far = Scene(walls=(WallSpec(6.0, -6.0, 6.0, 6.0, 2.0),))  # 6 m ahead: beyond max range
    depth = render(CAMERA, (0.0, 0.0, 0.0), far, supersample=1).depth_m
    assert np.all(np.isposinf(depth_scan(depth, CAMERA).ranges_m))
    blind = depth.copy()
    blind[blind > 5.0] = np.nan  # a Kinect that reads nothing past 5 m: the horizon has no depth
    assert np.all(np.isnan(depth_scan(blind, CAMERA).ranges_m))
    empty = render(CAMERA, (0.0, 0.0, 0.0), Scene(), supersample=1).depth_m  # floor only: no depth at the horizon
    assert np.all(np.isnan(depth_scan(empty, CAMERA).ranges_m))


def test_bad_input_names_the_problem():
    with pytest.raises(FgslamError, match="register the depth"):
        depth_scan(np.zeros((240, 320)), CAMERA)
    with pytest.raises(FgslamError, match="floor_clearance_m < robot_height_m"):
        depth_scan(np.zeros((480, 640)), CAMERA, floor_clearance_m=0.5, robot_height_m=0.4)


def test_the_ray_cast_scan_matches_the_depth_scan_of_rendered_frames(frames):
    """The harness's scan (no rendering) against depth_scan on the same ideal frames: same
    fan, same kind per ray (hit / free / unknown) nearly everywhere, ranges within mm."""
    differences, agree, total = [], 0, 0
    for world, pose, depth in frames:
        rendered = depth_scan(depth, CAMERA)
        cast = ray_cast_depth_scan(world.obstacles, pose, CAMERA)
        np.testing.assert_allclose(cast.angles_rad, rendered.angles_rad)
        kind = lambda r: np.where(np.isnan(r), 0, np.where(np.isinf(r), 1, 2))  # noqa: E731
        agree += int((kind(cast.ranges_m) == kind(rendered.ranges_m)).sum())
        total += len(cast.ranges_m)
        both = np.isfinite(cast.ranges_m) & np.isfinite(rendered.ranges_m)
        differences.append(np.abs(cast.ranges_m[both] - rendered.ranges_m[both]))
    d = np.concatenate(differences)
    # measured: kinds agree on 99 % of rays, median |difference| 0.5 mm, max ~1 cm (a bin's edge)
    assert agree >= 0.97 * total
    assert np.median(d) <= 0.003 and np.percentile(d, 95) <= 0.02
