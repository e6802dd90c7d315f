"""vfh's stop test along the commanded arc, and the pose jumps that grow its margin (issue 44:
the live benchmark's one vfh bump, a box corner met while turning past it)."""

import math

import numpy as np
import pytest

from fgslam.navigate.grid import OccupancyGrid
from fgslam.navigate.vfh import PoseJumps, Vfh, arc_free_m, arc_poses, pose_jump_m
from slamio.geometry import arc_increment, compose_pose


def _disc_path(pose, speed, turn, distance_m, step_m=0.001):
    """Reference: the centre's positions every millimetre along the arc, by slamio.geometry."""
    s = np.arange(step_m, distance_m + 1e-12, step_m)
    return np.array([compose_pose(pose, arc_increment(d, d * turn / speed))[:2] for d in s])


def test_arc_poses_follow_the_commanded_arc():
    pose = (1.0, 2.0, 0.3)
    poses = arc_poses(pose, 0.2, -0.8, 0.1, step_m=0.02)
    reference = [compose_pose(pose, arc_increment(s, s * -0.8 / 0.2)) for s in (0.02, 0.04, 0.06, 0.08, 0.1)]
    np.testing.assert_allclose(poses, reference, atol=1e-12)
    straight = arc_poses((0.0, 0.0, 0.0), 0.1, 0.0, 0.04, step_m=0.02)
    np.testing.assert_allclose(straight, [[0.02, 0, 0], [0.04, 0, 0]], atol=1e-12)
    assert arc_poses(pose, 0.0, 1.0, 0.2).shape == (0, 3)  # turning in place sweeps nothing


def test_arc_free_is_where_the_enlarged_disc_first_meets_a_cell_it_approaches():
    # straight on, a cell 1 m ahead 0.1 m aside, disc enlarged to 0.25 m: 1 − √(0.25² − 0.1²) = 0.7709
    free = arc_free_m([[1.0, 0.1]], (0.0, 0.0, 0.0), 0.2, 0.0, 0.25, 1.5, step_m=0.01)
    assert free == pytest.approx(0.77, abs=1e-9)  # the last 1 cm sample before it
    # a cell already inside the enlarged disc, beside and behind the axle: going on moves away from it
    assert arc_free_m([[-0.02, -0.2]], (0.0, 0.0, 0.0), 0.2, 0.0, 0.25, 0.3) == pytest.approx(0.3)
    assert arc_free_m(np.zeros((0, 2)), (0.0, 0.0, 0.0), 0.2, 0.5, 0.25, 0.3) == pytest.approx(0.3)


def test_a_box_corner_met_on_a_right_arc_stops_the_new_rule_not_the_old():
    # the robot at the origin heading +x arcs right (0.2 m/s, −0.8 rad/s); a box's corner at
    # (0.31, −0.04) is in the grid (its cell's centre is (0.35, −0.05)). Stopping distance at
    # 0.2 m/s: 0.08 + 0.2²/(2·0.5) + 0.2·0.2 = 0.16 m.
    corner, speed, turn = (0.31, -0.04), 0.2, -0.8
    stopping = 0.08 + speed**2 / (2 * 0.5) + speed * 0.2
    grid = OccupancyGrid(half_size_m=2.0, resolution_m=0.1)
    grid.mark_occupied([corner], 2.0)
    nav = Vfh(grid=grid)
    nav.histogram((0.0, 0.0, 0.0))  # reads the active window
    # the true disc (0.17 m) on that arc touches the corner within the stopping distance ...
    path = _disc_path((0.0, 0.0, 0.0), speed, turn, stopping)
    touch = np.hypot(path[:, 0] - corner[0], path[:, 1] - corner[1]) < 0.17
    assert touch.any() and np.argmax(touch) * 0.001 < stopping
    # ... the old rule (the straight corridor, the disc's front to the cell's centre) lets it drive
    assert nav._gap_ahead_m((0.0, 0.0, 0.0)) >= stopping
    # ... the new one (the disc enlarged as the histogram's, swept along the arc) stops it
    assert nav._arc_free_m((0.0, 0.0, 0.0), speed, turn, stopping) < stopping


def test_a_pose_jump_is_what_the_wheels_could_not_have_driven():
    dt = 0.015
    moved = compose_pose((0.0, 0.0, 0.0), arc_increment(0.25 * dt, 0.5 * dt))
    assert pose_jump_m((0.0, 0.0, 0.0), moved, 0.25, 0.5, dt) == 0.0  # as commanded
    # a smoother's correction of 6 cm sideways: 6 cm less the slack (5 mm + 0.25 m/s · 15 ms)
    jumped = (moved[0], moved[1] + 0.06, moved[2])
    assert pose_jump_m((0.0, 0.0, 0.0), jumped, 0.25, 0.5, dt) == pytest.approx(0.06 - 0.005 - 0.00375, abs=1e-4)
    # a heading correction of 5°: beyond the slack (1° + 1 rad/s · 15 ms) times the 0.5 m lever
    turned = (moved[0], moved[1], moved[2] + math.radians(5))
    assert pose_jump_m((0.0, 0.0, 0.0), turned, 0.25, 0.5, dt) == pytest.approx(
        0.5 * (math.radians(4) - dt), abs=1e-6)


def test_pose_jumps_add_up_for_their_memory_then_are_forgotten_and_are_capped():
    jumps = PoseJumps(memory_s=30.0, cap_m=0.08)
    jumps.update(0.0, (0.0, 0.0, 0.0), 0.0, 0.0)
    jumps.update(0.015, (0.0, 0.03, 0.0), 0.0, 0.0)  # 3 cm while standing: 3 − 0.5 − 0.375 cm
    assert jumps.misregistration_m() == pytest.approx(0.02125)
    jumps.update(0.03, (0.0, 0.11, 0.0), 0.0, 0.0)  # another 8 cm: the sum (9.25 cm) capped at 8 cm
    assert jumps.misregistration_m() == pytest.approx(0.08)
    jumps.update(31.0, (0.0, 0.11, 0.0), 0.0, 0.0)  # both older than 30 s
    assert jumps.misregistration_m() == 0.0
