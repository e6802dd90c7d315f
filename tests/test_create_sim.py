"""slamio.create.sim: the simulated Create's OI behaviour, kinematics, encoders, walls, faults.

Most tests step the simulator by hand (``start(thread=False)``, ``step()``), so they are exact
and take no wall-clock time; the robot's answers are read from its pseudo-terminal.
"""

from __future__ import annotations

import math
import builders

import numpy as np
import pytest
import serial

from slamio.create import protocol as p
from slamio.create.odometry import CREATE2_MM_PER_COUNT, WHEEL_BASE_M, OdometryNoise, counts_delta, quantisation_floor
from slamio.create.protocol import OiMode
from slamio.create.sim import STEP_S, SimulatedCreate
from slamio.create.sim_model import wheel_speeds_from_drive
from slamio.create.stream_parser import StreamParser

NOISELESS = OdometryNoise(np.zeros((3, 3)), np.zeros((3, 3)), quantisation_floor("create2"))
from slamio.errors import FgslamError


def ask(sim, port, packet_ids):
    sim.handle_bytes(p.query_list(packet_ids))
    data = port.read(p.query_response_size(packet_ids))
    return p.decode_query_response(packet_ids, data)


def test_modes_and_drive_only_in_safe_or_full(manual):
    sim, port = manual()
    assert sim.mode == OiMode.OFF
    sim.handle_bytes(p.safe())  # ignored before Start
    assert sim.mode == OiMode.OFF
    sim.handle_bytes(p.start())
    assert ask(sim, port, [35]) == {35: OiMode.PASSIVE}
    sim.handle_bytes(p.drive_direct(left_mm_s=100, right_mm_s=100))
    assert sim.commanded_mm_s == (0.0, 0.0)  # passive: actuators are refused
    sim.handle_bytes(p.safe() + p.drive_direct(left_mm_s=100, right_mm_s=-200))
    assert sim.mode == OiMode.SAFE and sim.commanded_mm_s == (100.0, -200.0)
    sim.handle_bytes(p.full())
    assert sim.mode == OiMode.FULL
    sim.handle_bytes(p.start())
    assert sim.mode == OiMode.PASSIVE and sim.commanded_mm_s == (0.0, 0.0)
    sim.handle_bytes(p.stop_oi())
    assert sim.mode == OiMode.OFF


def test_drive_command_radii():
    b = 235.0
    assert wheel_speeds_from_drive(200, 32768, b) == (200.0, 200.0)
    assert wheel_speeds_from_drive(100, 1, b) == (-100.0, 100.0)  # in place, counter-clockwise
    assert wheel_speeds_from_drive(100, -1, b) == (100.0, -100.0)
    left, right = wheel_speeds_from_drive(200, 500, b)
    assert (right - left) / b == pytest.approx(200 / 500)  # ω = v / r


def test_kinematics_straight_and_in_place(manual):
    sim, _ = manual(arena_m=None, odometry_noise=NOISELESS, start_pose=(0.0, 0.0, 0.0))
    sim.handle_bytes(p.start() + p.safe() + p.drive_direct(left_mm_s=200, right_mm_s=200))
    builders.sim_steps(sim, 2.0)
    sim.handle_bytes(p.drive_direct(left_mm_s=0, right_mm_s=0))
    builders.sim_steps(sim, 0.5)
    x, y, theta = sim.true_pose
    # 2 s at 0.2 m/s, less the ramps at 1 m/s² (the accelerate and the brake cancel out)
    assert x == pytest.approx(0.4, abs=0.005) and y == 0.0 and theta == 0.0
    assert sim.true_path_length_m == pytest.approx(x)
    turn = math.pi / 2 * WHEEL_BASE_M / 2 / 1.0  # wheel travel for 90°, over 1 s
    sim.handle_bytes(p.drive_direct(left_mm_s=-1000 * turn, right_mm_s=1000 * turn))
    builders.sim_steps(sim, 1.0)
    sim.handle_bytes(p.drive_direct(left_mm_s=0, right_mm_s=0))
    builders.sim_steps(sim, 0.5)
    assert sim.true_pose[2] == pytest.approx(math.pi / 2, abs=0.02)
    assert sim.true_pose[:2] == pytest.approx((x, 0.0), abs=1e-9)


def test_encoders_count_in_the_commanded_direction_and_wrap(manual):
    sim, port = manual(arena_m=None, odometry_noise=NOISELESS)
    sim.handle_bytes(p.start() + p.safe())
    first = ask(sim, port, [43, 44])
    sim.handle_bytes(p.drive_direct(left_mm_s=200, right_mm_s=200))
    builders.sim_steps(sim, 1.0)
    moved = ask(sim, port, [43, 44])
    forward = counts_delta(moved[43], first[43])
    assert forward * CREATE2_MM_PER_COUNT == pytest.approx(0.2 * 1000 * 1.0 - 20, abs=2)  # 20 mm lost ramping up
    # Reverse at once: the wheel still rolls forward while it brakes, but counts backwards.
    sim.handle_bytes(p.drive_direct(left_mm_s=-200, right_mm_s=-200))
    sim.step()
    assert sim.wheel_speeds_m_s[0] > 0
    after = ask(sim, port, [43, 44])
    assert counts_delta(after[43], moved[43]) < 0
    assert 0 <= after[43] <= 65535


def test_create1_angle_packet_truncates_and_forgets_the_remainder(manual):
    sim, port = manual("create1", arena_m=None, odometry_noise=NOISELESS)
    sim.handle_bytes(p.start() + p.safe())
    wheel = math.radians(30.0) * WHEEL_BASE_M / 2 * 1000  # 30°/s in place
    sim.handle_bytes(p.drive_direct(left_mm_s=-wheel, right_mm_s=wheel))
    builders.sim_steps(sim, 0.5)  # get up to speed
    ask(sim, port, [20])
    readings = []
    for _ in range(40):  # read every 15 ms: 0.45° each time
        sim.step()
        readings.append(ask(sim, port, [20])[20])
    assert set(readings) == {0}
    for _ in range(round(1.0 / STEP_S)):
        sim.step()
    assert ask(sim, port, [20])[20] in (29, 30)  # read once a second: about right


def test_walls_press_the_bumpers_and_stop_the_robot(manual):
    sim, port = manual(start_pose=(2.5, 1.5, 0.0), odometry_noise=NOISELESS)  # 0.38 m from the east wall
    sim.handle_bytes(p.start() + p.safe() + p.drive_direct(left_mm_s=300, right_mm_s=300))
    builders.sim_steps(sim, 3.0)
    assert sim.true_pose[0] == pytest.approx(3.048 - 0.17)
    b = p.decode_bumps_and_drops(ask(sim, port, [7])[7])
    assert b.bump_left and b.bump_right
    sim.handle_bytes(p.drive_direct(left_mm_s=-100, right_mm_s=100))  # turn left at the wall
    builders.sim_steps(sim, 1.0)
    b = p.decode_bumps_and_drops(ask(sim, port, [7])[7])
    assert b.bump_right and not b.bump_left  # the wall is now on the right


def test_lifting_in_safe_mode_drops_to_passive(manual):
    sim, port = manual()
    sim.handle_bytes(p.start() + p.safe() + p.drive_direct(left_mm_s=100, right_mm_s=100))
    sim.lift()
    sim.step()
    assert ask(sim, port, [7, 35]) == {7: 0b1100, 35: OiMode.PASSIVE}
    assert sim.commanded_mm_s == (0.0, 0.0)


def test_stream_frames_every_step_and_pause(manual):
    sim, port = manual()
    sim.handle_bytes(p.start() + p.safe() + p.stream([7, 35, 43, 44]))
    builders.sim_steps(sim, 10 * STEP_S)
    parser = StreamParser([7, 35, 43, 44])
    frames = parser.feed(port.read(10 * 13))
    assert len(frames) == 10 and frames[0].values[35] == OiMode.SAFE
    assert {f.raw for f in frames} <= sim.sent_frames
    sim.handle_bytes(p.pause_stream())
    sim.step()
    port.timeout = 0.05
    assert port.read(100) == b""


def test_same_seed_same_encoder_noise():
    def run(seed):
        sim = SimulatedCreate("create2", seed=seed, arena_m=None).start(thread=False)
        sim.handle_bytes(p.start() + p.safe() + p.drive_direct(left_mm_s=150, right_mm_s=250))
        builders.sim_steps(sim, 2.0)
        sim.close()
        return sim._ticks, sim.true_pose

    assert run(3) == run(3)
    assert run(3)[0] != run(4)[0]
    assert run(3)[1] == run(4)[1]  # noise is on the encoders, not on the motion


def test_a_frame_counts_as_unread_until_the_host_has_it(manual):
    """A frame still in the kernel's flip buffer is in no queue the pty reports; with the
    host's count of bytes read, the simulator counts it unread until it is queued or read."""
    sim, port = manual()
    read = {"bytes": 0}
    sim.unread.host_bytes_read = lambda: read["bytes"]
    sim.handle_bytes(p.start() + p.safe() + p.stream([7, 35, 43, 44]))
    sim.step()
    assert sim._unread_by_host() == 13  # in the flip buffer or the queue: unread either way
    read["bytes"] += len(port.read(13))
    assert read["bytes"] == 13 and sim._unread_by_host() == 0
    sim.unread.host_bytes_read = None  # a host in another process: the queue alone
    sim.step()
    port.read(13)
    assert sim._unread_by_host() == 0


def test_faults_damage_and_drop_bytes_from_their_own_stream(manual):
    sim, port = manual(corrupt_fraction=0.2, drop_fraction=0.1, seed=5)
    sim.handle_bytes(p.start() + p.safe() + p.stream([7, 35, 43, 44]))
    builders.sim_steps(sim, 100 * STEP_S)
    data = port.read(1300 - sim.bytes_dropped)
    assert sim.bytes_corrupted > 0 and sim.bytes_dropped > 0
    assert len(data) == 1300 - sim.bytes_dropped
    parser = StreamParser([7, 35, 43, 44])
    frames = parser.feed(data)
    assert parser.bad_frames > 0
    assert all(p.frame_checksum_ok(f.raw) for f in frames)


def test_bad_arguments():
    with pytest.raises(FgslamError, match="unknown Create model"):
        SimulatedCreate("roomba")
    with pytest.raises(FgslamError, match="corrupt_fraction"):
        SimulatedCreate(corrupt_fraction=1.5)
    with pytest.raises(FgslamError, match="time_scale"):
        SimulatedCreate(time_scale=0)


def _wait_for(predicate, timeout_s=30.0):
    return builders.wait_for(predicate, timeout_s)


def test_a_hold_stops_the_clock_at_its_time_and_commands_are_still_obeyed():
    sim = SimulatedCreate("create2", time_scale=50.0, arena_m=None)
    token = sim.hold(at_s=0.3)  # before the clock starts: on a busy machine 0.3 s pass in no time at 50×
    with sim:  # starts the clock
        port = serial.serial_for_url(sim.port, baudrate=115200, timeout=0.5)
        try:
            assert _wait_for(lambda: sim.clock() >= 0.3)
            stood = sim.clock()
            assert 0.3 <= stood < 0.3 + STEP_S + 1e-9  # it stops at the first step at or after 0.3 s
            port.write(p.start() + p.safe() + p.drive_direct(left_mm_s=100, right_mm_s=100))
            assert _wait_for(lambda: sim.commanded_mm_s == (100.0, 100.0))  # obeyed while time stands
            assert sim.clock() == stood and sim.true_pose == (0.75, 0.75, 0.0)
            with sim.held():  # a second hold, from now: still standing after the first is released
                sim.release(token)
                assert sim.clock() == stood and sim.holds == 1
            assert _wait_for(lambda: sim.clock() > stood + 0.1) and sim.true_pose[0] > 0.75
            assert sim.holds == 0 and sim.hold_wall_s > 0
            with pytest.raises(RuntimeError, match="no such hold"):
                sim.release(token)
        finally:
            port.close()


@pytest.mark.slow
def test_encoder_errors_follow_the_stated_noise_model_whatever_the_step():
    """The encoders err like the odometry noise model a recording from the simulator states:
    over a drive of length L with turn Δθ the (distance, heading) error has covariance
    L·F + |Δθ|·R, however many 15 ms steps make the drive (measured_wheel_travel_m called
    directly: 400 independent drives of 1 m on a 1 rad arc, cut into 10 or into 200 steps)."""
    from slamio.create.sim_model import measured_wheel_travel_m, wheel_odometry_noise

    noise = wheel_odometry_noise("create2")
    length_m, turn_rad = 1.0, 1.0
    index = np.ix_((0, 2), (0, 2))
    expected = length_m * np.array(noise.forward_per_m)[index] + turn_rad * np.array(noise.rotate_per_rad)[index]
    for n_steps in (10, 200):
        rng = np.random.default_rng(7)
        ds, dth = length_m / n_steps, turn_rad / n_steps
        true = (ds - 0.5 * WHEEL_BASE_M * dth, ds + 0.5 * WHEEL_BASE_M * dth)
        errors = []
        for _ in range(400):
            left = right = 0.0
            for _ in range(n_steps):
                m = measured_wheel_travel_m(true, WHEEL_BASE_M, noise, rng)
                left, right = left + m[0], right + m[1]
            errors.append((0.5 * (left + right) - length_m, (right - left) / WHEEL_BASE_M - turn_rad))
        cov = np.cov(np.array(errors).T)
        # 400 samples: a variance is known to about ±14 % (2σ of a χ²₄₀₀ / 400)
        assert np.diag(cov) == pytest.approx(np.diag(expected), rel=0.16), n_steps
    assert noise.forward_per_m[1][1] == 0.0 and noise.rotate_per_rad[1][1] == 0.0  # wheels do not slide sideways
