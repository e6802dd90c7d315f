"""``explore``'s surface inspection, ways over the floor and glances (issue 44), against
hand-worked scans, grids and brute force."""

import math

import numpy as np
import pytest

from fgslam.navigate import Situation, make_navigator
from fgslam.navigate.inspect import hit_incidence_rad, inspected_hits, inspection_targets, nearest_to_group_middle
from fgslam.navigate.paths import coarse_passable, geodesic_from, way_ahead_xy, way_left_m, way_to
from slamio.scan import Scan


def _wall_scan(distance_m, yaw_rad, bins=81, half_fan_rad=math.radians(20.0)):
    """A scan from the origin facing +x of the wall x = distance_m (no wall: free)."""
    angles = np.linspace(-half_fan_rad, half_fan_rad, bins)
    bearing = angles + yaw_rad
    ranges = np.where(np.cos(bearing) > 0, distance_m / np.cos(bearing), np.inf)
    return Scan(angles, ranges, 4.0)


def test_incidence_on_a_flat_wall_is_the_ray_s_angle_to_its_normal():
    # the wall x = 2 has its normal along x: a ray at bearing b meets it at incidence |b|
    scan = _wall_scan(2.0, math.radians(30.0))
    xy, ranges, incidence = hit_incidence_rad(scan, (0.0, 0.0, math.radians(30.0)))
    bearing = np.arctan2(xy[:, 1], xy[:, 0])
    assert xy[:, 0] == pytest.approx(2.0)
    assert ranges == pytest.approx(2.0 / np.cos(bearing))
    assert incidence == pytest.approx(np.abs(bearing), abs=1e-6)


def test_isolated_hits_have_no_incidence_and_inspect_nothing():
    angles = np.radians(np.arange(-20.0, 20.5, 0.5))
    ranges = np.full(len(angles), np.inf)
    ranges[40] = 1.0  # one ray on a thin pole, the rest free
    scan = Scan(angles, ranges, 4.0)
    _, _, incidence = hit_incidence_rad(scan, (0.0, 0.0, 0.0))
    assert len(incidence) == 1 and np.isnan(incidence[0])
    assert len(inspected_hits(scan, (0.0, 0.0, 0.0), 2.5, math.radians(55))) == 0


def test_inspected_hits_are_near_and_faced():
    # robot 1 m from the wall, looking 50° off its normal: bearings 30°-70°, the hits
    # beyond 2.5 m (bearing > 66.4°) and beyond 55° incidence are left out
    scan = _wall_scan(1.0, math.radians(50.0))
    hits = inspected_hits(scan, (0.0, 0.0, math.radians(50.0)), 2.5, math.radians(55.0))
    bearing = np.degrees(np.arctan2(hits[:, 1], hits[:, 0]))
    assert len(hits) > 0 and bearing.max() <= 55.0 + 1e-6 and bearing.min() >= 30.0 - 1e-6
    assert np.all(np.hypot(hits[:, 0], hits[:, 1]) <= 2.5)


def test_nearest_to_group_middle_matches_a_loop():
    rng = np.random.default_rng(3)
    rows, cols = rng.integers(0, 40, 300), rng.integers(0, 40, 300)
    group = rng.integers(0, 12, 300)
    pick = nearest_to_group_middle(rows, cols, group)
    for g, k in zip(np.unique(group), pick):
        member = np.flatnonzero(group == g)
        r, c = rows[member], cols[member]
        d = (r - r.mean()) ** 2 + (c - c.mean()) ** 2
        assert k == member[int(np.argmin(d))]


def test_inspection_targets_are_the_uninspected_tiles_of_a_wall_facing_the_free_side():
    occupied = np.zeros((20, 30), bool)
    occupied[10, :] = True  # a wall along row 10
    free = np.zeros((20, 30), bool)
    free[11:, :] = True  # the free floor above it (rows grow with y)
    inspected = np.zeros((20, 30), bool)
    inspected[10, :10] = True  # its first tile looked at
    targets = inspection_targets(occupied, inspected, free, tile_cells=10, min_cells=3)
    # the middles of the other two tiles (columns 10-19 and 20-29: 14.5 and 24.5, ties to the first)
    assert [(r, c) for r, c, _ in targets] == [(10, 14), (10, 24)]
    assert [f for _, _, f in targets] == pytest.approx([math.pi / 2] * 2)  # facing +y: the free side


def test_ways_go_round_a_wall_and_stop_where_the_floor_is_not_known():
    passable = np.ones((10, 10), bool)
    passable[0:8, 5] = False  # a wall with a gap at rows 8-9
    distance, previous = geodesic_from(passable, (0, 2), 0.2)
    # to the gap (8, 5) and back up to row 0: each leg 8 rows and 3 columns, 3 diagonal moves and 5 straight
    assert distance[0, 8] == pytest.approx(0.2 * (10 + 6 * math.sqrt(2)))
    way = way_to(previous, distance, (0, 8))
    assert way[0] == (0, 2) and way[-1] == (0, 8) and all(passable[r, c] for r, c in way[1:])
    assert any(r >= 8 for r, c in way if c == 5)  # through the gap
    passable[8:, 5] = False
    distance, previous = geodesic_from(passable, (0, 2), 0.2)
    assert math.isinf(distance[0, 8]) and way_to(previous, distance, (0, 8)) == []


def test_coarse_cells_are_passable_when_one_fine_cell_is_roomy_and_free():
    free = np.ones((4, 6), bool)
    clearance = np.zeros((4, 6))
    clearance[0, 0] = clearance[3, 5] = 0.5
    free[3, 5] = False
    assert coarse_passable(free, clearance, 0.3, 2).tolist() == [[True, False, False], [False, False, False]]


def test_the_way_ahead_is_a_lookahead_along_the_way():
    way = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [2.0, 1.0]])
    # to the nearest of the way's points, (1, 0), then along the rest
    assert way_left_m(way, (0.9, 0.1)) == pytest.approx((math.hypot(0.1, 0.1) + 2.0, 1))
    assert way_ahead_xy(way, (0.9, 0.1), 0.5) == pytest.approx((1.0, 1.0))
    assert way_ahead_xy(way, (0.9, 0.1), 5.0) == pytest.approx((2.0, 1.0))


def test_a_landmark_due_a_visit_and_in_sight_is_glanced_at_from_where_the_robot_stands():
    nav = make_navigator("explore", seed=0)
    nav.grid.log_odds[:] = -1.0  # all floor known free
    landmark = {5: (2.0, 0.0)}
    # seen once at t = 0 from the west (its face looks west)
    nav.visits.update({5: 1}, 0.0, landmark, (0.0, 0.0))
    pose = (0.5, 0.3, math.pi / 2)
    early = nav._glance(Situation(10.0, pose, None, None, landmarks=landmark, sightings={5: 1}))
    assert early is None  # not 20 s unseen yet
    nav.vfh.spot.update(Situation(29.0, pose, None, None))
    goal = nav._glance(Situation(30.0, pose, None, None, landmarks=landmark, sightings={5: 1}))
    assert goal is not None and goal.kind == "glance" and goal.landmark == 5 and goal.xy == pytest.approx(pose[:2])
    # from behind it (east, outside 45° of its face) there is no glance
    behind = (3.5, 0.2, 0.0)
    nav.vfh.spot.update(Situation(29.5, behind, None, None))
    assert nav._glance(Situation(30.0, behind, None, None, landmarks=landmark, sightings={5: 1})) is None
    # an occupied cell between hides it
    nav.grid.mark_occupied([[1.2, 0.15]], 3.0)
    assert nav._glance(Situation(30.0, pose, None, None, landmarks=landmark, sightings={5: 1})) is None
