"""vfh's stop test along the commanded arc, and its reverse over known floor only (issue 44:
the live benchmark's one vfh bump, a box corner met while turning past it)."""

import numpy as np
import pytest

from fgslam.navigate.grid import OccupancyGrid
from fgslam.navigate.vfh import Vfh, arc_free_m, arc_poses, known_free_behind_m
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


def test_reverse_only_over_floor_known_free_behind():
    grid = OccupancyGrid(half_size_m=2.0, resolution_m=0.1)
    pose = (0.0, 0.0, 0.0)
    # nothing known behind: no reverse at all (the camera never looked there)
    assert known_free_behind_m(grid, pose, 0.17, 0.3) == 0.0
    # the strip the robot came along (x from −1 to 0, 0.2 m either side) known free: the whole 0.3 m
    xs, ys = np.meshgrid(np.arange(-0.95, 0.0, 0.1), np.arange(-0.15, 0.2, 0.1))
    grid.mark_occupied(np.column_stack([xs.ravel(), ys.ravel()]), -1.0)
    assert known_free_behind_m(grid, pose, 0.17, 0.3) == pytest.approx(0.3)
    # a corner remembered 0.5 m behind: the rear rim (0.17 m behind the centre) meets its cell
    # (x −0.5…−0.4) after 0.24 m of reverse; the sample before is 0.22 m
    grid.mark_occupied([[-0.45, 0.05]], 2.0)
    assert known_free_behind_m(grid, pose, 0.17, 0.3) == pytest.approx(0.22)
    nav = Vfh(grid=grid)
    assert nav.escape_reverse_m(pose) == pytest.approx(0.17)  # less 5 cm
    assert nav.escape_reverse_m(pose, 0.15) == pytest.approx(0.15)
