"""The navigators' pure pieces against hand-worked scans, histograms and grids (issue 44)."""

import math

import numpy as np
import pytest

from fgslam.navigate import NAVIGATORS, Situation, make_navigator
from fgslam.navigate.common import CRUISE_SPEED_M_S, limited_command
from fgslam.navigate.explore import frontier_goals, frontier_mask, goal_cost_m, landmark_viewpoint
from fgslam.navigate.explore_s001 import STOP_DISTANCE_M, approach_distance_m, nearest_obstacle
from fgslam.navigate.grid import OccupancyGrid
from fgslam.navigate.common import SpotWatch
from fgslam.navigate.vfh import (blocked_sectors, candidate_directions, choose_direction, free_distances_m,
                                 sector_angles_rad, valleys)
from fgslam.navigate.vfh_s000 import VfhS000, passable_regions, widest_region_middle_rad
from slamio.errors import FgslamError
from slamio.scan import Scan


# --------------------------------------------------------------------------- common


def test_commands_stay_within_the_create_s_limits():
    assert limited_command(1.0, 0.0, "x").speed_m_s == pytest.approx(CRUISE_SPEED_M_S)
    turn = limited_command(0.0, -5.0, "x")
    assert turn.turn_rate_rad_s == pytest.approx(-1.0) and turn.speed_m_s == pytest.approx(0.0)
    # 0.25 m/s and 1 rad/s: wheels 0.25 ± 0.1175 m/s, inside 0.5 m/s: unchanged
    both = limited_command(0.25, 1.0, "x")
    assert (both.speed_m_s, both.turn_rate_rad_s) == pytest.approx((0.25, 1.0))


def test_make_navigator_builds_each_and_names_a_bad_name():
    for name in NAVIGATORS:
        assert make_navigator(name, seed=3).name == name
    with pytest.raises(FgslamError, match="no navigator called 'wander'.*vfh-s000"):
        make_navigator("wander")
    with pytest.raises(FgslamError, match="--navigate vfh"):
        make_navigator("vfh", colour="red")


# --------------------------------------------------------------------------- vfh-s000


def _scan(ranges, half_rad=0.5, max_range_m=4.0):
    return Scan(np.linspace(-half_rad, half_rad, len(ranges)), np.array(ranges, dtype=float), max_range_m)


def test_passable_regions_are_runs_beyond_one_metre_and_unknown_is_not_passable():
    #        0    1  2   3       4    5  6  7  8    9      10
    scan = _scan([0.5, 2, 2, np.inf, 0.8, 2, 2, 2, 2, np.nan, 3])
    assert passable_regions(scan) == [(1, 3), (5, 4), (10, 1)]
    angles = scan.angles_rad
    assert widest_region_middle_rad(scan) == pytest.approx(0.5 * (angles[5] + angles[8]))
    assert widest_region_middle_rad(_scan([0.5, 0.9, 1.0, np.nan])) is None  # 1.0 m is not beyond 1 000 mm


def test_vfh_s000_heads_for_the_middle_of_the_widest_region():
    scan = _scan([0.5, 0.5, 0.5, 0.5, 2, 2, 2, 2, 2, 2, 2])  # rays 4..10: middle at +0.2 rad (left)
    nav = VfhS000()
    command = nav.step(Situation(0.0, (0.0, 0.0, 0.0), scan, (0.0, 0.0, 0.0)))
    assert command.speed_m_s == pytest.approx(CRUISE_SPEED_M_S) and command.turn_rate_rad_s == pytest.approx(0.4)
    # the robot turned 0.2 rad since that scan: it now faces the middle and drives straight
    command = nav.step(Situation(0.4, (0.0, 0.0, 0.2), scan, (0.0, 0.0, 0.0)))
    assert command.turn_rate_rad_s == pytest.approx(0.0, abs=1e-12)
    blocked = nav.step(Situation(0.8, (0.0, 0.0, 0.2), _scan([0.6, 0.7, np.nan]), (0.0, 0.0, 0.2)))
    assert (blocked.speed_m_s, blocked.state) == (0.0, "scan-turn") and blocked.turn_rate_rad_s > 0


# --------------------------------------------------------------------------- explore-s001


def test_nearest_obstacle_is_placed_in_the_map_frame():
    scan = _scan([3.0, 2.0, np.inf, np.nan, 2.5])  # nearest: ray 1 at −0.25 rad
    x, y, r = nearest_obstacle(scan, (1.0, 1.0, 0.5))
    assert (x, y, r) == pytest.approx((1.0 + 2.0 * math.cos(0.25), 1.0 + 2.0 * math.sin(0.25), 2.0))
    assert nearest_obstacle(_scan([np.inf, np.nan]), (0, 0, 0)) is None
    assert STOP_DISTANCE_M == pytest.approx(0.85)  # 2.5 lengths of the 0.34 m Create
    assert approach_distance_m(2.0) == pytest.approx(1.15) and approach_distance_m(0.5) == 0.0


# --------------------------------------------------------------------------- vfh


def test_free_distance_is_how_far_the_enlarged_disc_goes_before_a_cell():
    directions = np.radians([0.0, 10.0, 20.0, 180.0])
    # a cell 1 m ahead, disc enlarged to 0.25 m: straight on 1 − 0.25; at 10° its lateral offset is
    # sin 10° = 0.174 m: cos 10° − √(0.25² − 0.174²) = 0.805; at 20° (0.342 m aside) and behind: clear
    free = free_distances_m([[1.0, 0.0]], (0.0, 0.0), directions, 0.25, 1.6)
    np.testing.assert_allclose(free, [0.75, 0.8050, 1.6, 1.6], atol=1e-3)
    # a cell already inside the enlarged disc, ahead-left: blocks the ways toward it, not away
    near = free_distances_m([[0.1, 0.1]], (0.0, 0.0), np.radians([0.0, 45.0, -90.0, 180.0]), 0.25, 1.6)
    np.testing.assert_allclose(near, [0.0, 0.0, 1.6, 1.6])
    assert free_distances_m(np.zeros((0, 2)), (0, 0), directions, 0.25, 1.6).tolist() == [1.6] * 4


def test_spot_watch_fires_after_the_limit_on_one_spot_and_not_while_moving():
    watch = SpotWatch(limit_s=7.0, radius_m=0.15)
    still = [watch.update(Situation(t, (1.0 + 0.01 * (t % 2), 1.0, t), None, None)) for t in np.arange(0.0, 8.0, 0.5)]
    assert still.index(True) == 15 and sum(still) == 1  # 7.5 s > 7 s, then the spot starts again
    moving = SpotWatch(limit_s=7.0, radius_m=0.15)
    assert not any(moving.update(Situation(t, (0.05 * t, 0.0, 0.0), None, None)) for t in np.arange(0.0, 20.0, 0.5))


def test_threshold_hysteresis_keeps_the_previous_state_in_between():
    smoothed = [0.5, 2.0, 4.0, 2.0]
    first = blocked_sectors(smoothed, 1.0, 3.0)
    assert first.tolist() == [False, False, True, False]
    assert blocked_sectors(smoothed, 1.0, 3.0, [True, True, False, False]).tolist() == [False, True, True, False]


def test_valleys_wrap_round_the_circle():
    assert valleys([True, True, False, False, True]) == [(4, 3)]
    assert valleys([False, True, False, True]) == [(1, 1), (3, 1)]
    assert valleys([True] * 4) == [(0, 4)] and valleys([False] * 4) == []


def test_candidates_narrow_middle_wide_borders_and_goal():
    alpha = 2 * math.pi / 72
    angles = sector_angles_rad(72)
    narrow = candidate_directions([(36, 5)], 72, 1.0, s_max=16)
    assert narrow == pytest.approx([angles[38]])
    wide = candidate_directions([(30, 30)], 72, float(angles[45]), s_max=16)
    assert wide == pytest.approx([angles[30] + 8 * alpha, angles[59] - 8 * alpha, angles[45]])
    assert len(candidate_directions([(30, 30)], 72, float(angles[32]), s_max=16)) == 2  # goal too near a border


def test_choice_weighs_goal_heading_and_previous_and_does_not_turn_back():
    assert choose_direction([0.0, 1.0], 1.0, 0.0, None) == pytest.approx(1.0)  # 5·1 > 2·1 + 2·1
    assert choose_direction([0.0, 0.6], 3.0, 0.0, 0.0) == pytest.approx(0.6)
    # the goal is behind and a way behind is open, but so is one ahead: go on
    assert choose_direction([math.pi, 0.3], math.pi, 0.0, None) == pytest.approx(0.3)
    assert choose_direction([math.pi], math.pi, 0.0, None) == pytest.approx(math.pi)
    assert choose_direction([], 0.0, 0.0, None) is None


def test_vfh_backs_off_and_turns_away_from_a_bump():
    nav = make_navigator("vfh", seed=0)
    xs, ys = np.meshgrid(np.arange(0.45, 1.0, 0.1), np.arange(0.75, 1.3, 0.1))  # the floor it came over, seen free
    nav.grid.mark_occupied(np.column_stack([xs.ravel(), ys.ravel()]), -1.0)
    situation = Situation(2.0, (1.0, 1.0, 0.0), None, None, bumped=True, bump_side="left")
    assert nav.step(situation).speed_m_s < 0
    after = Situation(4.0, (0.84, 1.0, 0.0), None, None)  # backed off 0.16 m: now turn right
    command = nav.step(after)
    assert command.state == "turn-away" and command.turn_rate_rad_s < 0
    # nothing known behind (no footprints, no scan there): no reverse, only the turn away
    blind = make_navigator("vfh", seed=0)
    first = blind.step(Situation(0.0, (1.0, 1.0, 0.0), None, None, bumped=True, bump_side="left"))
    assert first.speed_m_s == 0 and first.state == "turn-away" and first.turn_rate_rad_s < 0


# --------------------------------------------------------------------------- grid and explore


def test_a_scan_frees_the_cells_along_its_rays_marks_the_hit_and_leaves_the_rest_unknown():
    grid = OccupancyGrid(half_size_m=2.0, resolution_m=0.1)
    scan = Scan(np.array([-0.5, 0.0, 0.5]), np.array([np.nan, 1.0, np.nan]), 4.0)
    grid.add_scan(scan, (0.05, 0.05, 0.0))
    values = grid.values_at([[0.35, 0.05], [0.85, 0.05], [1.05, 0.05], [1.45, 0.05], [0.45, 0.35]])
    assert values[0] < 0 and values[1] < 0  # crossed: free
    assert values[2] > 0  # the hit
    assert values[3] == 0 and values[4] == 0  # beyond the hit, and along the unknown rays


def test_a_ray_beside_a_thin_pole_does_not_free_the_pole_s_cell():
    # rays every 0.5°; a 0.1 m pole's cell 1 m ahead is crossed by rays that pass beside the pole
    # (they reach 3 m) while the rays through the pole stop at it: the cell is not freed
    grid = OccupancyGrid(half_size_m=4.0, resolution_m=0.1)
    angles = np.radians(np.arange(-20.0, 20.5, 0.5))
    ranges = np.full(len(angles), 3.0)
    pole = np.abs(angles) <= math.radians(1.0)  # the pole, 1 m ahead, hides ±1°
    ranges[pole] = 1.0
    grid.add_scan(Scan(angles, ranges, 4.0), (0.05, 0.05, 0.0))
    assert grid.values_at([[1.05, 0.05]])[0] > 0  # the pole's cell: a hit, never freed
    assert grid.values_at([[1.05, 0.25]])[0] < 0  # beside it, every ray went past: free
    assert grid.values_at([[0.55, 0.05]])[0] < 0  # before it
    # the fan's edge: a cell half outside the fan stays unknown
    assert grid.values_at([[1.05, 0.05 + math.tan(math.radians(20.0)) * 1.0 + 0.04]])[0] == 0


def test_frontiers_are_free_cells_beside_unknown_ones():
    log_odds = np.zeros((10, 10))
    log_odds[:, :5] = -1.0  # the left half seen free, the right half unknown
    log_odds[0, :5] = 1.0  # a wall along the bottom
    mask = frontier_mask(log_odds)
    assert np.nonzero(mask.any(axis=0))[0].tolist() == [4] and not mask[0].any()
    clearance = np.full((10, 10), 1.0)
    [(row, col, size)] = frontier_goals(log_odds, clearance)
    assert (col, size) == (4, 9) and row in (5, 6)


def test_landmark_viewpoint_is_free_in_range_and_sees_the_landmark():
    grid = OccupancyGrid(half_size_m=3.0, resolution_m=0.1)
    grid.log_odds[:] = -1.0
    grid.mark_occupied([[x, 0.0] for x in np.arange(-3, 3, 0.05)], 3.0)  # a wall along y = 0
    landmark = (0.0, 0.01)
    view = landmark_viewpoint(grid, lambda xy: np.full(len(np.atleast_2d(xy)), 1.0), landmark, (0.0, 2.5))
    assert view is not None and view[1] > 0.5
    assert 0.99 <= math.hypot(view[0] - landmark[0], view[1] - landmark[1]) <= 1.51
    # seen from the north-east: a viewpoint within 40° of that side
    facing = landmark_viewpoint(grid, lambda xy: np.full(len(np.atleast_2d(xy)), 1.0), landmark, (-2.5, 2.5),
                                facing_rad=math.radians(45.0))
    assert facing is not None and abs(math.degrees(math.atan2(facing[1] - landmark[1], facing[0] - landmark[0])) - 45) <= 40
    assert goal_cost_m((0, 0, 0), (2, 0)) == pytest.approx(2.0) and goal_cost_m((0, 0, 0), (0, 2)) == pytest.approx(
        2 + 0.5 * math.pi / 2)
