"""The kinematic harness against hand-worked motion, bumps and metrics, and the seed
navigators' behaviour in it (issue 44)."""

import math

import numpy as np
import pytest

from fgslam.navigate import make_navigator
from fgslam.navigate.common import Command
from fgslam.navigate.explore_s001 import STOP_DISTANCE_M
from fgslam.navigate.harness import bump_side, drive
from slamio.obstacles import Obstacles


class _Constant:
    """A navigator that always says the same (to test the harness)."""

    name = "constant"

    def __init__(self, speed_m_s=0.0, turn_rate_rad_s=0.0):
        self.command = Command(speed_m_s, turn_rate_rad_s, "go")
        self.seen = []

    def step(self, situation):
        self.seen.append(situation)
        return self.command


WALL_AT_3 = Obstacles([[3.0, -5.0, 3.0, 5.0]])


def test_straight_and_arc_motion_in_an_empty_world():
    straight = drive(Obstacles(), _Constant(0.2), (0.0, 0.0, 0.0), duration_s=2.0)
    assert straight.path[-1] == pytest.approx([0.4, 0.0, 0.0], abs=1e-9)
    # 0.1 m/s at 0.5 rad/s for π s: half a circle of radius 0.2 m
    arc = drive(Obstacles(), _Constant(0.1, 0.5), (0.0, 0.0, 0.0), duration_s=2 * math.pi, dt_s=math.pi / 100)
    assert arc.path[-1][:2] == pytest.approx([0.0, 0.4], abs=1e-6) and math.cos(arc.path[-1][2]) == pytest.approx(-1.0)
    assert straight.bumps == arc.bumps == 0


def test_odometry_noise_tells_the_navigator_a_drifting_pose():
    nav = _Constant(0.2, 0.1)
    result = drive(Obstacles(), nav, (0.0, 0.0, 0.0), duration_s=10.0, odometry_noise=0.1, seed=4)
    told, truth = np.array(nav.seen[-1].pose), result.path[-2]
    assert 1e-3 < np.hypot(*(told[:2] - truth[:2])) < 0.2 * 2.0  # drifted, by about 10 % of the 2 m driven


def test_driving_into_a_wall_is_one_bump_and_stops_at_the_wall():
    nav = _Constant(0.25)
    result = drive(WALL_AT_3, nav, (2.0, 0.0, 0.0), duration_s=10.0)
    assert result.bumps == 1
    assert result.path[-1][0] == pytest.approx(3.0 - 0.17, abs=2e-3)
    pressed = [s for s in nav.seen if s.bumped]
    assert pressed and all(s.bump_side == "front" for s in pressed)
    # still from where it came within 0.1 m of the wall: after (0.83 − 0.1 … 0.83) / 0.25 s
    assert 10.0 - 0.83 / 0.25 - 0.1 <= result.longest_stuck_s <= 10.0 - 0.73 / 0.25
    assert bump_side([math.radians(40)]) == "left" and bump_side([math.radians(-50)]) == "right"


def test_standing_still_sees_the_camera_fan_and_is_stuck_all_the_time():
    result = drive(Obstacles(), _Constant(), (0.0, 0.0, 0.0), duration_s=5.0)
    fan_m2 = math.radians(57) / 2 * 4.0**2  # 7.96 m²: 0.25 m cells a ray crosses cover a bit more
    assert fan_m2 <= result.area_seen_m2 <= 1.4 * fan_m2
    assert result.longest_stuck_s == pytest.approx(5.0 - 0.05)
    assert result.area_visited_m2 == pytest.approx(4 * 0.0625)  # the disc at a corner of four cells


def test_landmarks_seen_in_view_and_revisited_after_twenty_seconds_away():
    landmarks = {0: (2.0, 0.0), 1: (-2.0, 0.0), 2: (2.0, 0.0 + 2.0 * math.tan(math.radians(40)))}
    # turning at 0.1 rad/s, ±28.5° in view: landmark 0 at 0–5 s and again from 58 s; landmark 2
    # (at 40°) at 2–12 s and again from 65 s; landmark 1 (behind) at 26–36 s only
    result = drive(Obstacles(), _Constant(0.0, 0.1), (0.0, 0.0, 0.0), duration_s=70.0, landmarks=landmarks)
    assert result.landmarks_seen == {0, 1, 2} and result.landmarks_revisited == {0, 2}
    hidden = drive(Obstacles([[1.0, -1.0, 1.0, 1.0]]), _Constant(), (0.0, 0.0, 0.0), duration_s=1.0,
                   landmarks={0: (2.0, 0.0)})
    assert hidden.landmarks_seen == set()


def test_vfh_s000_drives_toward_the_open_side():
    # a wall across the right half ahead 0.8 m away, open to the left
    world = Obstacles([[0.8, -3.0, 0.8, 0.1]])
    result = drive(world, make_navigator("vfh-s000"), (0.0, 0.0, 0.0), duration_s=3.0)
    assert result.path[-1][1] > 0.2 and result.bumps == 0


def test_explore_s001_stops_two_and_a_half_lengths_from_the_nearest_obstacle_and_turns_45():
    nav = make_navigator("explore-s001", seed=1)
    result = drive(WALL_AT_3, nav, (0.0, 0.0, 0.0), duration_s=20.0)
    states = result.states
    turn = states.index("turn-45")
    assert result.path[turn][0] == pytest.approx(3.0 - STOP_DISTANCE_M, abs=0.02)
    after = turn + states[turn:].index("scan-wait")
    assert abs(math.degrees(result.path[after][2])) == pytest.approx(45.0, abs=2.5)
    assert result.bumps == 0


def test_a_clutter_world_drives_from_its_start_with_the_depth_scan_and_its_tags():
    from slamio.clutter import clutter_world

    world = clutter_world(1)
    nav = _Constant()
    result = drive(world, nav, duration_s=1.0)
    scan = nav.seen[0].scan
    # the live loop's scan: 0.5° bins from the robot's centre over ±21° (depth_scan's fan)
    assert np.degrees(scan.angles_rad[[0, -1]]) == pytest.approx([-21.0, 21.0])
    assert result.path[0] == pytest.approx(world.start_pose) and result.landmark_count == len(world.tags)
    assert sum(s.scan is not s2.scan for s, s2 in zip(nav.seen[1:], nav.seen[:-1])) == 2  # at 0.4 s and 0.8 s


def test_a_tag_is_sighted_from_its_front_only():
    # a tag at the origin facing +x; the robot 2 m away looks at it from 0°, 60° and 80° off its normal
    sighted = []
    for off_deg in (0.0, 60.0, 80.0):
        a = math.radians(off_deg)
        pose = (2.0 * math.cos(a), 2.0 * math.sin(a), a + math.pi)
        result = drive(Obstacles(), _Constant(), pose, duration_s=0.1, landmarks={0: (0.0, 0.0)},
                       landmark_yaws={0: 0.0})
        sighted.append(bool(result.landmarks_seen))
    assert sighted == [True, True, False]  # the detector needs the face within 70°
