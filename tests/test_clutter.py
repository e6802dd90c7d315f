"""slamio.clutter (the cluttered room), render.WallSpec, and ``fgslam sim clutter``'s occlusion."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.ndimage import label

from slamio.camera.model import T_robot_camera_from_mount, kinect_v1_default
from slamio.camera.render import Scene, TagSpec, WallSpec, render
from slamio.clutter import MIN_GAP_M, ROBOT_RADIUS_M, clutter_world, disc_free_grid
from slamio.log import Observation, TruthLandmark, TruthPose
from slamio.obstacles import clearance_m, line_of_sight


def _bounding_circles(world):
    return ([(b.x_m, b.y_m, b.bounding_radius_m) for b in world.boxes]
            + [(c.x_m, c.y_m, c.radius_m) for c in (*world.pillars, *world.colour_cylinders)])


@pytest.mark.parametrize("seed", range(8))
def test_the_room_is_passable_connected_and_has_its_landmarks(seed):
    world = clutter_world(seed)
    assert world.room_m == (6.0, 6.0)
    assert 5 <= len(world.boxes) + len(world.pillars)
    assert [c.name for c in world.colour_cylinders] == ["red", "green", "blue"]
    circles = _bounding_circles(world)
    for i, (x, y, r) in enumerate(circles):  # every gap ≥ 0.6 m: to the walls and to each other
        assert min(x, y, 6.0 - x, 6.0 - y) - r >= MIN_GAP_M - 1e-9
        for x2, y2, r2 in circles[i + 1:]:
            assert math.hypot(x - x2, y - y2) - r - r2 >= MIN_GAP_M - 1e-9
    assert clearance_m(world.obstacles, world.start_pose[:2]) >= 0.5
    free, cell = disc_free_grid(world)
    assert label(free)[1] == 1  # one region for the disc's centre
    # the grid's free cells are free for the disc: checked against the exact geometry
    rows, cols = np.nonzero(free)
    pick = np.random.default_rng(seed).choice(len(rows), 300, replace=False)
    for i, j in zip(rows[pick], cols[pick]):
        assert clearance_m(world.obstacles, ((j + 0.5) * cell, (i + 0.5) * cell)) > ROBOT_RADIUS_M
    ids = [t.tag_id for t in world.tags]
    assert len(ids) >= 12 and sorted(ids) == list(range(len(ids)))
    for tag in world.tags:  # facing open floor, 5 mm off its face
        assert tag.size_m == 0.16 and tag.height_m == 0.20
        out = (tag.x_m + 0.45 * math.cos(tag.yaw_rad), tag.y_m + 0.45 * math.sin(tag.yaw_rad))
        assert clearance_m(world.obstacles, out) >= ROBOT_RADIUS_M
        assert line_of_sight(world.obstacles, out, (tag.x_m, tag.y_m))
        assert clearance_m(world.obstacles, (tag.x_m, tag.y_m)) == pytest.approx(0.005, abs=1e-9)


def test_same_seed_same_room_and_a_kept_loop_stays_clear():
    a, b = clutter_world(3), clutter_world(3)
    assert a.boxes == b.boxes and a.tags == b.tags and a.start_pose == b.start_pose
    assert a.boxes != clutter_world(4).boxes
    loop = np.array([[1.5, 1.5], [4.5, 1.5], [4.5, 4.5], [1.5, 4.5]])
    world = clutter_world(0, keep_clear_xy=loop)
    assert world.start_pose == pytest.approx((1.5, 1.5, 0.0))
    for t in np.linspace(0.0, 4.0, 401):  # along the loop: at least the robot's radius + 0.25 m of room
        k, f = int(t) % 4, t - int(t)
        xy = loop[k] + f * (loop[(k + 1) % 4] - loop[k])
        assert clearance_m(world.obstacles, xy) >= ROBOT_RADIUS_M + 0.25 - 1e-9


def test_a_wall_is_drawn_in_depth_hides_a_tag_behind_it_and_is_culled_from_behind():
    camera = kinect_v1_default(T_robot_camera_from_mount(0.0, 0.0, 0.3))
    tag = TagSpec(0, 3.0, 0.0, 0.3, math.pi)  # 3 m ahead, facing the robot
    # p0 → p1 southwards: its front (left of (0, −2): +x) faces away from the robot → culled
    wall = WallSpec(2.0, 1.0, 2.0, -1.0, 1.0, cull_back=True)
    seen_through = render(camera, (0.0, 0.0, 0.0), Scene(tags=(tag,), walls=(wall,)), supersample=1)
    assert seen_through.depth_m[240, 320] == pytest.approx(3.0, abs=1e-4)
    facing = WallSpec(2.0, -1.0, 2.0, 1.0, 1.0, cull_back=True)  # front faces −x, the robot
    frame = render(camera, (0.0, 0.0, 0.0), Scene(tags=(tag,), walls=(facing,)), supersample=2)
    assert frame.depth_m[240, 320] == pytest.approx(2.0, abs=1e-4)
    # the wall is 1 m tall: above its top edge (1.0 − 0.3 m over 2 m: row 240 − 525·0.35 = 56) no depth
    assert np.isnan(frame.depth_m[50, 320]) and frame.depth_m[62, 320] == pytest.approx(2.0, abs=1e-4)
    assert frame.bgr[200:280, 300:340].std() > 1.0  # its texture: not one flat colour
    assert abs(int(frame.bgr[240, 320, 0]) - 20) > 60  # no black tag cell shows through


def test_the_clutter_scenario_hides_tags_behind_obstacles():
    import dataclasses

    from slamio.sim import simulate
    from slamio.sim_models import visible_landmarks
    from slamio.sim_worlds import clutter_scenario_world, scenario

    room, world, _ = clutter_scenario_world()
    header, records = simulate("clutter", 1, laps=1)
    assert header.source["scenario"] == "clutter"
    truth = {r.landmark_id: (r.x_m, r.y_m) for r in records if isinstance(r, TruthLandmark)}
    assert len(truth) == len(room.tags) >= 12
    pose, seen = None, 0
    for r in records:
        if isinstance(r, TruthPose):
            pose = (r.x_m, r.y_m)
            assert clearance_m(room.obstacles, pose) > ROBOT_RADIUS_M  # the loop stays in free space
        elif isinstance(r, Observation):
            assert line_of_sight(room.obstacles, pose, truth[r.landmark_id])
            seen += 1
    assert seen > 300
    poses = np.array([(r.x_m, r.y_m, r.theta_rad) for r in records if isinstance(r, TruthPose)])
    sc = scenario("clutter", 1)
    bare = visible_landmarks(poses, dataclasses.replace(world, obstacles=None), sc.sensor)
    assert len(bare.pose_index) > seen * 1.1  # without the obstacles far more would be seen
