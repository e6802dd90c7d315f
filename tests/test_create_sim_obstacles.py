"""The simulated Create among obstacles (slamio.create.sim ``obstacles=``): the disc stops at a
box and slides along it, and the bumpers press as the OI reports them, read through the pty."""

from __future__ import annotations

import math

import builders
import numpy as np
import pytest

from slamio.create import protocol as p
from slamio.create.odometry import OdometryNoise, quantisation_floor
from slamio.create.sim import ROBOT_RADIUS_M
from slamio.create.sim_model import contact_bump_bits
from slamio.obstacles import Obstacles, box_segments

NOISELESS = OdometryNoise(np.zeros((3, 3)), np.zeros((3, 3)), quantisation_floor("create2"))
# a 0.6 m × 0.6 m box centred at (3, 1): its west face at x = 2.7
BOX = Obstacles(box_segments((3.0, 1.0), (0.6, 0.6)), segment_heights_m=np.full(4, 0.5))


def bumps(sim, port):
    sim.handle_bytes(p.query_list([7]))
    return p.decode_bumps_and_drops(p.decode_query_response([7], port.read(p.query_response_size([7])))[7])


def test_driving_into_a_box_stops_at_its_face_and_presses_both_bumpers(manual):
    sim, port = manual(arena_m=None, odometry_noise=NOISELESS, obstacles=BOX, start_pose=(1.5, 1.0, 0.0))  # 1.2 m west of the face, heading at it
    sim.handle_bytes(p.start() + p.safe() + p.drive_direct(left_mm_s=300, right_mm_s=300))
    builders.sim_steps(sim, 2.0)
    b = bumps(sim, port)
    assert not (b.bump_left or b.bump_right)  # 0.6 m travelled (after the ramp), 1.03 m to go
    builders.sim_steps(sim, 4.0)
    x, y, theta = sim.true_pose
    assert x == pytest.approx(2.7 - ROBOT_RADIUS_M, abs=1e-6)  # the disc touches the face
    assert y == pytest.approx(1.0, abs=1e-9) and theta == pytest.approx(0.0, abs=1e-9)
    b = bumps(sim, port)
    assert b.bump_left and b.bump_right
    assert sim.encoder_distance_m > sim.true_path_length_m + 0.5  # the wheels slip against it


def test_an_oblique_push_slides_along_the_face_and_presses_the_side_bumper(manual):
    # heading θ = 30°: the face (normal −x) is 30° to the robot's right
    sim, port = manual(arena_m=None, odometry_noise=NOISELESS, obstacles=BOX, start_pose=(2.2, 0.6, math.radians(30.0)))
    sim.handle_bytes(p.start() + p.safe() + p.drive_direct(left_mm_s=200, right_mm_s=200))
    builders.sim_steps(sim, 3.0)
    x, y, _ = sim.true_pose
    assert x == pytest.approx(2.7 - ROBOT_RADIUS_M, abs=1e-6)
    # the wheels roll 0.2 m/s × 2.9 s (after the 0.2 s ramp) = 0.58 m; y gains sin 30° of it,
    # before the contact (at y = 0.79, x = 2.53) and while sliding along the face after it
    assert y == pytest.approx(0.6 + 0.5 * 0.58, abs=2e-3)
    b = bumps(sim, port)
    assert b.bump_right and not b.bump_left


def test_bump_directions_by_hand():
    # relative bearing of the contact: ahead ±20° both, left, right, behind the axle none
    cases = {0.0: 0x03, 19.0: 0x03, -19.0: 0x03, 45.0: 0x02, 90.0: 0x02, -45.0: 0x01, -90.0: 0x01,
             120.0: 0x00, -150.0: 0x00, 180.0: 0x00}
    for bearing_deg, bits in cases.items():
        theta = 0.7
        assert contact_bump_bits(theta, [theta + math.radians(bearing_deg)]) == bits, bearing_deg
    assert contact_bump_bits(0.0, [math.radians(45), math.radians(-45)]) == 0x03
    assert contact_bump_bits(0.0, []) == 0


def test_backing_into_a_pillar_stops_but_presses_nothing(manual):
    pillar = Obstacles(circles_m=[(1.0, 1.0, 0.2)])
    sim, port = manual(arena_m=None, odometry_noise=NOISELESS, obstacles=pillar, start_pose=(1.6, 1.0, 0.0))  # the pillar behind
    sim.handle_bytes(p.start() + p.safe() + p.drive_direct(left_mm_s=-200, right_mm_s=-200))
    builders.sim_steps(sim, 3.0)
    assert sim.true_pose[0] == pytest.approx(1.0 + 0.2 + ROBOT_RADIUS_M, abs=1e-6)
    b = bumps(sim, port)
    assert not (b.bump_left or b.bump_right)
