"""slamio.obstacles and slamio.scan against hand-worked geometry."""

import math

import numpy as np
import pytest

from slamio.obstacles import (Obstacles, box_segments, clearance_m, disc_contacts, push_disc_out, ray_cast_m,
                              room_segments)
from slamio.scan import Scan, scan_from_ranges


def test_rays_in_a_room_reach_its_walls():
    room = Obstacles(room_segments(4.0, 2.0))
    angles = [0.0, math.pi / 2, math.pi, -math.pi / 2, math.atan2(1.0, 3.0)]
    ranges = ray_cast_m(room, (1.0, 1.0), angles)
    np.testing.assert_allclose(ranges, [3.0, 1.0, 1.0, 1.0, math.hypot(3.0, 1.0)], atol=1e-12)


def test_ray_hits_the_near_side_of_a_cylinder_and_misses_past_it():
    world = Obstacles(circles_m=[[3.0, 0.0, 0.5]])
    np.testing.assert_allclose(ray_cast_m(world, (0.0, 0.0), [0.0]), [2.5])
    # tangent ray: sin(a) = 0.5 / 3
    tangent = math.asin(0.5 / 3.0)
    assert np.isfinite(ray_cast_m(world, (0.0, 0.0), [tangent - 1e-6])[0])
    assert np.isinf(ray_cast_m(world, (0.0, 0.0), [tangent + 1e-6])[0])
    assert np.isinf(ray_cast_m(world, (0.0, 0.0), [math.pi])[0])


def test_max_range_and_low_obstacles():
    world = Obstacles(circles_m=[[2.0, 0.0, 0.2], [4.0, 0.0, 0.2]], circle_heights_m=[0.1, 1.0])
    assert ray_cast_m(world, (0, 0), [0.0])[0] == pytest.approx(1.8)
    assert ray_cast_m(world, (0, 0), [0.0], min_height_m=0.3)[0] == pytest.approx(3.8)
    assert np.isinf(ray_cast_m(world, (0, 0), [0.0], max_range_m=1.0)[0])


def test_a_turned_box_is_hit_at_its_corner():
    box = Obstacles(box_segments((2.0, 0.0), (1.0, 1.0), math.pi / 4))
    # the corner nearest the origin is at 2 - sqrt(0.5)
    assert ray_cast_m(box, (0, 0), [0.0])[0] == pytest.approx(2.0 - math.sqrt(0.5))


def test_disc_against_a_wall_slides_and_presses_the_bumper():
    wall = Obstacles([[0.0, -5.0, 0.0, 5.0]])
    x, y = push_disc_out(wall, (0.1, 0.3), 0.17)
    assert (x, y) == pytest.approx((0.17, 0.3))
    contacts = disc_contacts(wall, (x, y), 0.17)
    assert contacts == pytest.approx([math.pi])
    assert len(disc_contacts(wall, (0.5, 0.0), 0.17)) == 0
    assert clearance_m(wall, (0.5, 0.0)) == pytest.approx(0.5)


def test_disc_pushed_out_of_a_cylinder_and_a_corner():
    cylinder = Obstacles(circles_m=[[0.0, 0.0, 0.3]])
    x, y = push_disc_out(cylinder, (0.1, 0.0), 0.2)
    assert (x, y) == pytest.approx((0.5, 0.0))
    room = Obstacles(room_segments(2.0, 2.0))
    x, y = push_disc_out(room, (0.05, 1.95), 0.17)
    assert (x, y) == pytest.approx((0.17, 1.83))
    assert sorted(disc_contacts(room, (x, y), 0.17)) == pytest.approx([math.pi / 2, math.pi])


def test_obstacles_add_and_check_heights():
    both = Obstacles(room_segments(1, 1)) + Obstacles(circles_m=[[0.5, 0.5, 0.1]], circle_heights_m=[0.4])
    assert both.segments_m.shape == (4, 4) and both.circle_heights_m.tolist() == [0.4]
    with pytest.raises(ValueError, match="heights"):
        Obstacles(circles_m=[[0, 0, 1]], circle_heights_m=[1, 2])


def test_scan_marks_free_and_unknown():
    scan = scan_from_ranges([-0.1, 0.0, 0.1, 0.2], [0.0, 5.0, 1.0, float("nan")], max_range_m=4.0, min_range_m=0.5)
    assert np.isnan(scan.ranges_m[0]) and np.isinf(scan.ranges_m[1]) and np.isnan(scan.ranges_m[3])
    assert scan.free_distance_m().tolist() == [0.0, 4.0, 1.0, 0.0]
    assert scan.nearest_m() == 1.0 and scan.known.tolist() == [False, True, True, False]
    assert scan.field_of_view_rad == pytest.approx(0.3)
    with pytest.raises(ValueError, match="increase"):
        Scan([0.1, 0.0], [1.0, 1.0], 4.0)


def test_line_of_sight_and_a_ray_cast_scan():
    from slamio.obstacles import line_of_sight
    from slamio.scan import ray_cast_scan

    world = Obstacles(room_segments(4.0, 4.0)) + Obstacles(circles_m=[[2.0, 2.0, 0.3]])
    assert not line_of_sight(world, (1.0, 2.0), (3.0, 2.0))
    assert line_of_sight(world, (1.0, 1.0), (3.0, 1.0))
    assert line_of_sight(world, (1.0, 1.0), (4.0, 1.0))  # a tag on the wall itself is seen
    scan = ray_cast_scan(world, (1.0, 2.0, 0.0), math.radians(57), 5, max_range_m=2.5)
    assert scan.angles_rad[[0, 2, 4]] == pytest.approx([-math.radians(28.5), 0.0, math.radians(28.5)])
    assert scan.ranges_m[2] == pytest.approx(0.7)
    assert np.isinf(scan.ranges_m[0])  # the wall 3.0 / cos(28.5°) away is beyond 2.5 m
