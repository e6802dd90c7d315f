"""``fgslam live``: the follower's maths, the pose tracker, and hardware-in-the-loop runs —
the simulated Create on a real pseudo-terminal, frames rendered from its true pose, the
camera front-end and iSAM2 in the loop.

Nothing here depends on how fast this machine is. The hardware-in-the-loop runs are
lockstep (``run_live(..., lockstep=Lockstep(sim))``): every frame and iSAM2 step gets a fixed
budget of robot time and the simulated Create's clock stands still while one overruns it,
so a busy machine stretches a run in wall time but not in robot time; the host-side watchdogs (wall clock) are generous
(:data:`CALM`); faults are injected on events (robot time, a reconnect attempt), never after
a sleep; and the stop is waited for, not slept for.
"""

from __future__ import annotations

import json
import math
import threading
import time

import builders

import numpy as np
import pytest

from fgslam.cli import main
from fgslam.live import (
    LiveSettings,
    Lockstep,
    PoseTracker,
    polygon_waypoints,
    pose_error_m,
    read_waypoints,
    run_live,
    simulated_camera,
    start_pose_facing,
    waypoint_wheel_speeds,
)
from slamio.create.link import CreateLink
from slamio.create.sim import SimulatedCreate
from slamio.errors import FgslamError
from slamio.geometry import arc_increment, compose_pose
from slamio.log import LiveStep, Odometry, read_log
from slamio.sim import ARENA_PATH_WIDTH_M, ARENA_SIDE_M

CENTRE = (0.5 * ARENA_SIDE_M, 0.5 * ARENA_SIDE_M)
TIME_SCALE = 3.0  # at most 3 × real time; slower whenever this machine is (the clock is held)
# The wall-clock watchdogs are about a hung host, which these tests do not simulate; the
# robot streams nothing while its clock is held, so they must outlast the slowest frame.
CALM = LiveSettings(command_timeout_s=30.0, data_timeout_s=30.0)


def wait_for(predicate, timeout_s=30.0):
    return builders.wait_for(predicate, timeout_s)


def wheels_stopped(sim):
    return wait_for(lambda: sim.commanded_mm_s == (0.0, 0.0))


class ManualClock:
    """A simulated robot clock moved by hand, with SimulatedCreate's hold/release API."""

    def __init__(self):
        self.now_s, self.holds, self._next = 0.0, {}, 0

    def clock(self):
        return self.now_s

    def hold(self, at_s=None):
        self._next += 1
        self.holds[self._next] = at_s
        return self._next

    def release(self, token):
        del self.holds[token]


def test_lockstep_frame_holds_the_clock_until_the_loop_takes_its_result():
    """In lockstep a frame's observations are used at exactly their robot time: the hold on
    the clock lasts until the control loop has taken the result, not only until the worker
    finished (then the clock ran on a step or more on a busy machine before the loop looked)."""
    from fgslam.live import CameraWorker

    clock = ManualClock()
    done = threading.Event()

    def process(frame):
        done.set()
        return [frame]

    camera = CameraWorker(process, lockstep=Lockstep(clock, frame_s=0.4))
    try:
        assert camera.request(7, lambda: "frame")
        assert done.wait(30.0) and wait_for(lambda: not camera._results.empty())
        (due_at,) = clock.holds.values()
        assert due_at == pytest.approx(0.4)
        assert camera.result() is None and clock.holds  # not due yet: held
        assert not camera.request(8, lambda: "next")  # busy until the loop took the result
        clock.now_s = 0.4
        assert camera.result() == (7, ["frame"])
        assert not clock.holds  # released when taken
        assert camera.request(8, lambda: "next")  # and free at once: no race with the worker
    finally:
        camera.close()


def test_follower_turns_then_drives_then_arrives():
    s = LiveSettings()
    mode, v, w = waypoint_wheel_speeds((0.0, 0.0, 0.0), (0.0, 1.0), s, turning=True)
    assert mode == "turn" and v == 0 and w == pytest.approx(s.turn_rate_rad_s)
    mode, v, w = waypoint_wheel_speeds((0.0, 0.0, math.pi / 2 - 0.01), (0.0, 1.0), s, turning=True)
    assert mode == "drive" and v == pytest.approx(s.speed_m_s) and w == pytest.approx(s.heading_gain_per_s * 0.01)
    # driving tolerates a larger heading error before it stops to turn again
    mode, _, _ = waypoint_wheel_speeds((0.0, 0.0, math.pi / 2 - 0.2), (0.0, 1.0), s, turning=False)
    assert mode == "drive"
    mode, v, _ = waypoint_wheel_speeds((0.0, 0.99, math.pi / 2), (0.0, 1.0), s, turning=False)
    assert mode == "arrived" and v == 0
    # slowing down along sqrt(2 a d) near the target, never a backward wheel while driving
    mode, v, w = waypoint_wheel_speeds((0.0, 0.96, math.pi / 2 - 0.3), (0.0, 1.0), s, turning=False)
    assert mode == "drive" and v == pytest.approx(math.sqrt(2 * s.accel_m_s2 * 0.04), rel=0.05)
    assert v - abs(w) * 0.5 * s.wheel_base_m >= -1e-12


def test_pose_tracker_composes_smoothed_pose_records_and_motion_since():
    tracker = PoseTracker((1.0, 2.0, 0.5))
    tracker.recorded(1, Odometry(0.1, 0.1, 0.0, 0.1, ((1, 0, 0), (0, 1, 0), (0, 0, 1))))
    tracker.advance(0.05, 0.02)
    expected = compose_pose(compose_pose((1.0, 2.0, 0.5), (0.1, 0.0, 0.1)), arc_increment(0.05, 0.02))
    assert tracker.current() == pytest.approx(expected)
    tracker.smoothed(1, (1.2, 2.0, 0.6))  # the smoother's pose 1 replaces the odometry up to it
    assert tracker.current() == pytest.approx(compose_pose((1.2, 2.0, 0.6), arc_increment(0.05, 0.02)))


def test_waypoints_from_a_file_and_seed_004_paths(tmp_path):
    path = tmp_path / "w.txt"
    path.write_text("# corners\n0.5, 0.5\n1.5 0.5\n\n1.5,1.5 # last\n")
    np.testing.assert_allclose(read_waypoints(str(path)), [[0.5, 0.5], [1.5, 0.5], [1.5, 1.5]])
    path.write_text("0.5, 0.5\n1.5\n")
    with pytest.raises(FgslamError, match=r"w.txt:2: expected 'x_m, y_m'"):
        read_waypoints(str(path))
    octagon = polygon_waypoints(8, ARENA_PATH_WIDTH_M, CENTRE, laps=2)
    assert octagon.shape == (16, 2) and np.allclose(octagon[7], octagon[15])
    start = start_pose_facing(octagon)
    assert start[:2] == tuple(octagon[-1]) and start[2] == pytest.approx(0.0, abs=1e-12)


@pytest.fixture(scope="module")
def octagon_run(tmp_path_factory):
    """The hardware-in-the-loop run of issue 8: the octagon of seed 004's arena."""
    out = tmp_path_factory.mktemp("live") / "live.jsonl"
    result, true_pose, stopped, _ = hil_octagon(out, 1, simulated_camera)
    return out, result, true_pose, stopped


def hil_octagon(out, seed, camera_for, **live_options):
    """One lockstep octagon of the simulated Create with ``camera_for(sim)``'s camera (and
    ``live_options`` for :func:`run_live`): (result, true end pose, wheels stopped, truth landmarks)."""
    waypoints = polygon_waypoints(8, ARENA_PATH_WIDTH_M, CENTRE)
    start = start_pose_facing(waypoints)
    with SimulatedCreate("create2", seed=seed, time_scale=TIME_SCALE, start_pose=start) as sim:
        grab_for, front_end, truth_landmarks = camera_for(sim)
        result = run_live(CreateLink(sim.port, "create2"), str(out), waypoints, start_pose=start, grab_for=grab_for,
                          front_end=front_end, truth=lambda: sim.true_pose, truth_landmarks=truth_landmarks,
                          clock=sim.clock, settings=CALM, lockstep=Lockstep(sim), odometry_noise=sim.odometry_noise,
                          **live_options)
        stopped = wheels_stopped(sim)
        true_pose = sim.true_pose
        assert sim.holds == 0  # every frame and smoother step gave the clock back
    return result, true_pose, stopped, truth_landmarks


def test_hil_octagon_ends_within_10_cm_of_the_truth(octagon_run):
    out, result, true_pose, stopped = octagon_run
    assert result.completed and result.record.reason.kind == "completed"
    assert stopped
    assert pose_error_m(result.final_pose, true_pose) < 0.1
    assert set(result.landmarks) == set(range(8))
    # Lockstep: no frame is late in robot time and none finds the camera busy, however slow
    # this machine renders. Only the end loses frames: the recorder's final record comes
    # whether or not a frame is out, and its own frame is given up when the log closes.
    assert result.frames_skipped + result.frames_dropped <= 2
    assert result.frames_used >= result.frames_requested - 2 > 100
    assert result.observations > 100


def test_hil_octagon_with_a_small_sliding_window(tmp_path):
    """The live smoother's sliding window (LIVE_WINDOW_POSES, here 20 so that one lap slides it
    several times) in the loop: the lap ends as close to the truth, with every landmark."""
    seen = []
    result, true_pose, stopped, _ = hil_octagon(tmp_path / "window.jsonl", 1, simulated_camera, window_poses=20,
                                                on_step=lambda index, smoother, latency, loop: seen.append(smoother))
    assert stopped and result.completed and pose_error_m(result.final_pose, true_pose) < 0.1
    assert set(result.landmarks) == set(range(8))
    assert seen[-1].window_slides >= 3


def same_records(a, b, rel=1e-9) -> bool:
    """Records equal, floats within ``rel`` (a stamp difference can round differently)."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(same_records(a[k], b[k], rel) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(same_records(x, y, rel) for x, y in zip(a, b))
    if isinstance(a, float) or isinstance(b, float):
        return abs(a - b) <= rel * max(1.0, abs(a))
    return a == b


@pytest.mark.slow
def test_hil_lap_in_lockstep_is_the_same_lap_again(octagon_run, tmp_path):
    """Same seed, same lap: every command reaches the robot at the same step and every record
    is the same, however this machine's threads were scheduled (only the wall-clock latencies
    of the smoother differ)."""
    out, result, _, _ = octagon_run
    again = tmp_path / "again.jsonl"
    result2, _, _, _ = hil_octagon(again, 1, simulated_camera)

    def records(path):
        lines = [json.loads(line) for line in open(path)][1:]  # the header has the date
        return [r for r in lines if r["type"] != "live_step"]

    first, second = records(out), records(again)
    assert len(first) == len(second) > 300
    assert all(same_records(a, b) for a, b in zip(first, second))
    assert result2.final_pose == pytest.approx(result.final_pose, abs=1e-9)


def test_hil_log_replays_with_every_estimator_against_its_truth(octagon_run, tmp_path, capsys):
    out, result, _, _ = octagon_run
    log = read_log(out)
    steps = log.steps()
    assert len(steps) == result.poses and all(s.truth is not None for s in steps)
    latencies = [r for r in log.records if isinstance(r, LiveStep)]
    assert len(latencies) >= result.poses - 3 and all(r.latency_s > 0 for r in latencies)
    # the camera's mount each detection was placed from is stated; the readings are the centre's
    assert len(log.header.sensor["T_robot_camera"]) == 4 and "pose_on_robot" not in log.header.sensor
    assert main(["run", str(out), "--out", str(tmp_path / "r"), "--no-report"]) == 0
    metrics = json.loads((tmp_path / "r" / "metrics.json").read_text())
    assert metrics["reference"] == "ground_truth"
    assert metrics["isam2"]["ate_rmse_m"] < 0.05 and metrics["isam2"]["landmarks_found"] == 8
    capsys.readouterr()


def test_unplugged_cable_stops_early_keeps_the_log_and_exits_3(tmp_path, capsys):
    """The CLI end to end (real-time pacing, no lockstep): only what does not depend on
    this machine's speed is checked — the exit status, the messages, a complete log. The
    cable stays out, so no stop reaches the robot: exit 3, "not confirmed"."""
    out = tmp_path / "unplugged.jsonl"
    code = main(["live", "--port", "sim", "--sim-time-scale", str(TIME_SCALE), "--sim-unplug-after", "4",
                 "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 3, err
    assert "stopped early: serial-error" in err and "THE CREATE KEEPS EXECUTING" in err
    assert "CHECK THE ROBOT" in err and "robot stopped (confirmed)" not in err
    # Readable to the end, every pose complete (odometry, truth). How many poses came before
    # the unplug depends on how fast this machine renders and smooths in real time (on a
    # machine with every core busy, only the first): not asserted.
    log = read_log(out)
    assert log.truncated is None and log.has_full_truth() and len(log.steps()) >= 1


def test_cable_back_in_time_gets_the_wheels_stopped(tmp_path, cable_back_on_retry):
    """A cable pulled and pushed back within the link's retry window: the stop goes out."""
    out = tmp_path / "glitch.jsonl"
    waypoints = polygon_waypoints(8, ARENA_PATH_WIDTH_M, CENTRE)
    start = start_pose_facing(waypoints)
    with SimulatedCreate("create2", seed=2, time_scale=TIME_SCALE, start_pose=start) as sim:
        def pull_while_driving():  # at 4 s of robot time, on the first leg
            while sim.clock() < 4.0:
                time.sleep(0.005)
            sim.unplug()

        opener, attempts = cable_back_on_retry(sim)  # back after the first reconnect attempt
        link = CreateLink(sim.port, "create2", opener=opener)
        threading.Thread(target=pull_while_driving, daemon=True).start()
        result = run_live(link, str(out), waypoints, start_pose=start, clock=sim.clock, settings=CALM,
                          lockstep=Lockstep(sim))
        assert wheels_stopped(sim)
    assert result.record.reason.kind == "serial-error", result.record.reason
    assert attempts and result.record.shutdown.stopped and result.record.shutdown.reconnected
    assert read_log(out).steps()


class _FailingSmoother:
    """An iSAM2 that breaks at pose 15, to check that a worker's exception stops the robot."""

    def __init__(self, inner):
        self.inner = inner

    def step(self, step):
        if step.index == 15:
            raise RuntimeError("smoother failed on purpose")
        self.inner.step(step)

    def __getattr__(self, name):
        return getattr(self.inner, name)


def test_an_exception_in_the_loop_stops_the_wheels_first(tmp_path):
    from fgslam.smoother import Isam2Smoother
    from slamio.log import Header

    out = tmp_path / "broken.jsonl"
    waypoints = polygon_waypoints(4, ARENA_PATH_WIDTH_M, CENTRE)
    start = start_pose_facing(waypoints)
    header = Header(0.0, start, (1e-3, 1e-3, 1e-3), {"name": "t"}, {"kind": "t"}, {"odometry": {}, "observation": {}})
    with SimulatedCreate("create2", seed=3, time_scale=TIME_SCALE, start_pose=start) as sim:
        with pytest.raises(FgslamError, match="smoother failed on purpose"):
            run_live(CreateLink(sim.port, "create2"), str(out), waypoints, start_pose=start, clock=sim.clock,
                     smoother=_FailingSmoother(Isam2Smoother(header)), settings=CALM, lockstep=Lockstep(sim))
        assert wheels_stopped(sim)
    assert len(read_log(out).steps()) >= 15



def test_hil_log_states_the_noise_its_camera_and_encoders_have(octagon_run):
    """A replayed live-simulation log is only a fair test if its header and records state the
    noise that made them. The observations against the log's own truth: range and bearing
    errors divided by the σ each observation states have an RMS near 1 (the simulated
    camera's σ, measured by scripts/measure_live_camera.py on other rendered frames); the
    header names the camera's model and the odometry's σ is the simulated encoders' model."""
    from fgslam.consistency import reading_z_scores
    from fgslam.live import LIVE_SIM_RANGE_SIGMA_PER_M2, LIVE_SIM_SIGMA_BEARING_RAD
    from slamio.create.sim_model import wheel_odometry_noise

    out, _, _, _ = octagon_run
    log = read_log(out)
    assert log.header.noise["odometry"]["forward_per_m"] == [list(r) for r in wheel_odometry_noise("create2").forward_per_m]
    stated = log.header.noise["observation"]
    assert stated["sigma_bearing_rad"] == LIVE_SIM_SIGMA_BEARING_RAD
    assert stated["sigma_range_per_m2"] == LIVE_SIM_RANGE_SIGMA_PER_M2
    z_range, z_bearing = reading_z_scores(log)
    assert len(z_range) > 100
    for name, z in (("range", z_range), ("bearing", z_bearing)):
        z = np.asarray(z)
        inliers = z[np.abs(z) < 5.0]
        rms = math.sqrt(np.mean(np.square(inliers)))
        # Ten lockstep laps (seeds 1–10), readings within 5σ: range 0.89–1.05, bearing
        # 0.88–1.14. Before the σ were measured: range 0.95–1.22, bearing 0.64–0.83 (the
        # bearing σ stated 1.4× too large). The σ describe the readings, not a rare
        # misdetection: on a loaded machine the frames that reach the front-end differ, and
        # under stress-ng the plain bearing RMS once came out at 2.0 (an RMS over ~500
        # readings that a few far readings can make); readings beyond 5σ must stay rare.
        # Measured: 0–2 bearings per lap (4 of 606 readings over seeds 1–5, 2.2–2.7 mrad,
        # mostly driving straight: the front-end's own tail, not the frame's timing).
        assert 0.7 < rms < 1.4, (name, rms)
        assert len(inliers) >= 0.97 * len(z), (name, len(z) - len(inliers))


@pytest.mark.slow
def test_hil_colour_landmarks_with_the_simulated_kinect(tmp_path):
    """fgslam live with Kinect colour landmarks: seed 000's cylinders in the arena, rendered RGB-D
    frames from the simulated Create's true pose, the colour front-end and iSAM2 in the loop."""
    from fgslam.live_colour import simulated_kinect

    out = tmp_path / "colour.jsonl"
    result, true_pose, stopped, truth_landmarks = hil_octagon(out, 2, simulated_kinect)
    assert stopped and result.completed and pose_error_m(result.final_pose, true_pose) < 0.1
    assert set(result.landmarks) == {0, 1, 2} and result.observations > 30
    truth = {t.landmark_id: (t.x_m, t.y_m) for t in truth_landmarks}
    for landmark_id, xy in result.landmarks.items():
        assert math.dist(np.asarray(xy)[:2], truth[landmark_id]) < 0.1
    heights = [o.height_m for o in read_log(out).records if getattr(o, "height_m", None) is not None]
    assert heights  # the cylinders' heights are measured on the way


@pytest.mark.slow
def test_hil_colour_landmarks_without_ids(tmp_path):
    """The same colour run with a landmark file that names no ids: the observations carry
    none, and iSAM2 associates them itself (fgslam/smoother/association.py)."""
    import dataclasses

    from fgslam.live_colour import ARENA_CYLINDER_XY, simulated_kinect
    from slamio.camera.colour import ColourOptions

    options = ColourOptions()
    options = dataclasses.replace(options, colours=tuple(dataclasses.replace(c, landmark_id=None)
                                                         for c in options.colours))
    out = tmp_path / "colour_noid.jsonl"
    result, true_pose, stopped, _ = hil_octagon(out, 2, lambda sim: simulated_kinect(sim, options))
    assert stopped and result.completed and pose_error_m(result.final_pose, true_pose) < 0.1
    from slamio.log import Observation

    observations = [o for o in read_log(out).records if isinstance(o, Observation)]
    assert observations and all(o.landmark_id is None for o in observations)
    assert len(result.landmarks) == 3  # the three cylinders, under the smoother's own keys
    truth = list(ARENA_CYLINDER_XY.values())
    for xy in result.landmarks.values():
        assert min(math.dist(np.asarray(xy)[:2], t) for t in truth) < 0.1
