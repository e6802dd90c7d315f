"""The sensor where it is mounted (slamio.log.mount): readings moved to the robot's centre,
against a numerical Jacobian and against a run whose readings were taken at the centre."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from slamio.log import LogFormatError, Observation, read_log
from slamio.log.mount import moved_to_robot_centre, pose_on_robot, reading_in_robot_frame

DATA = Path(__file__).resolve().parent.parent / "data"
MOUNT = (0.20, -0.05, 0.3)  # 20 cm ahead, 5 cm to the right, looking 0.3 rad left


def sensor_reading(range_m, bearing_rad, mount):
    """The inverse move: a reading from the robot's centre as the sensor at ``mount`` takes it."""
    mx, my, myaw = mount
    px, py = range_m * math.cos(bearing_rad) - mx, range_m * math.sin(bearing_rad) - my
    c, s = math.cos(myaw), math.sin(myaw)
    sx, sy = c * px + s * py, -s * px + c * py
    return math.hypot(sx, sy), math.atan2(sy, sx)


@settings(max_examples=200, deadline=None)
@given(st.floats(0.3, 20.0), st.floats(-3.0, 3.0))
def test_a_moved_reading_is_the_reading_from_the_centre(range_m, bearing_rad):
    r_s, b_s = sensor_reading(range_m, bearing_rad, MOUNT)
    r, b, _ = reading_in_robot_frame(r_s, b_s, MOUNT)
    assert r == pytest.approx(range_m, abs=1e-9)
    assert math.remainder(b - bearing_rad, 2 * math.pi) == pytest.approx(0.0, abs=1e-9)


def test_the_jacobian_matches_finite_differences():
    r_s, b_s, h = 1.7, -0.4, 1e-6
    _, _, J = reading_in_robot_frame(r_s, b_s, MOUNT)
    numeric = np.zeros((2, 2))
    for k, (dr, db) in enumerate(((h, 0.0), (0.0, h))):
        plus = reading_in_robot_frame(r_s + dr, b_s + db, MOUNT)
        minus = reading_in_robot_frame(r_s - dr, b_s - db, MOUNT)
        numeric[:, k] = [(plus[0] - minus[0]) / (2 * h), math.remainder(plus[1] - minus[1], 2 * math.pi) / (2 * h)]
    assert J == pytest.approx(numeric, abs=1e-7)


def test_sigmas_and_tag_yaw_move_with_the_reading_and_a_radio_stays():
    o = Observation(0.0, 3, 2.0, 0.1, 0.05, 0.02, tag_yaw_rad=1.0, sigma_tag_yaw_rad=0.1)
    moved = moved_to_robot_centre(o, MOUNT)
    assert moved.tag_yaw_rad == pytest.approx(1.3)
    assert moved.sigma_range_m == pytest.approx(0.05, rel=0.25) and moved.sigma_bearing_rad == pytest.approx(0.02, rel=0.25)
    radio = Observation(0.0, 3, 2.0, None, 0.05, None)
    assert moved_to_robot_centre(radio, MOUNT) is radio
    centred = moved_to_robot_centre(o, (0.0, 0.0, 0.0))
    assert (centred.range_m, centred.bearing_rad, centred.sigma_range_m) == pytest.approx((2.0, 0.1, 0.05))


@pytest.mark.parametrize("value, message", [
    ([0.1, 0.2], "three numbers"), ([0.1, "a", 0.0], "three numbers"), ([20.0, 0.0, 0.0], "within 10 m"),
    ([0.0, 0.0, 9.0], "within ±2π"),
])
def test_a_bad_pose_on_robot_is_refused_naming_the_field(tmp_path, value, message):
    lines = (DATA / "arena_square.jsonl").read_text().splitlines()
    header = json.loads(lines[0])
    header["sensor"]["pose_on_robot"] = value
    path = tmp_path / "bad.jsonl"
    path.write_text("\n".join([json.dumps(header)] + lines[1:3]) + "\n")
    with pytest.raises(LogFormatError, match="sensor.pose_on_robot") as err:
        read_log(path)
    assert message in str(err.value) and str(err.value).startswith(f"{path}:1:")
    assert pose_on_robot({"pose_on_robot": [0, 0, 0]}) is None


def log_seen_from_mount(tmp_path, state_mount: bool) -> Path:
    """The bundled arena log with every reading re-taken by a sensor at MOUNT (σ kept), the
    header stating the mount or not."""
    lines = (DATA / "arena_square.jsonl").read_text().splitlines()
    header = json.loads(lines[0])
    header["source"] = {"generator": "a test: the arena log seen from an off-centre sensor"}
    if state_mount:
        header["sensor"]["pose_on_robot"] = list(MOUNT)
    out = [json.dumps(header)]
    for line in lines[1:]:
        d = json.loads(line)
        if d.get("type") == "observation" and d.get("bearing_rad") is not None:
            d["range_m"], d["bearing_rad"] = sensor_reading(d["range_m"], d["bearing_rad"], MOUNT)
            if d.get("tag_yaw_rad") is not None:
                d["tag_yaw_rad"] = math.remainder(d["tag_yaw_rad"] - MOUNT[2], 2 * math.pi)
        out.append(json.dumps(d))
    path = tmp_path / ("stated.jsonl" if state_mount else "unstated.jsonl")
    path.write_text("\n".join(out) + "\n")
    return path


def test_a_stated_mount_gives_the_centre_run_back_and_an_unstated_one_does_not(tmp_path):
    from fgslam.runner import compare_log

    def ate(log):
        runs = {r.name: r for r in compare_log(log, ["ekf", "isam2"]).runs}
        truth = np.array([[s.truth.x_m, s.truth.y_m] for s in log.steps()])
        return {n: float(np.sqrt(np.mean(np.sum((runs[n].final[:, :2] - truth) ** 2, axis=1)))) for n in runs}

    centre = ate(read_log(DATA / "arena_square.jsonl"))
    stated = ate(read_log(log_seen_from_mount(tmp_path, True)))
    unstated = ate(read_log(log_seen_from_mount(tmp_path, False)))
    for name in ("ekf", "isam2"):
        assert stated[name] == pytest.approx(centre[name], rel=0.15, abs=2e-3)
        assert unstated[name] > 5 * centre[name]
    steps = read_log(log_seen_from_mount(tmp_path, True)).steps()
    original = read_log(DATA / "arena_square.jsonl").steps()
    a, b = steps[10].observations[0], original[10].observations[0]
    assert (a.range_m, a.bearing_rad) == pytest.approx((b.range_m, b.bearing_rad), abs=1e-9)


def test_the_verdict_of_a_run_whose_mount_is_not_stated_says_the_noise_does_not_fit(tmp_path):
    from fgslam.runner import compare_log
    from fgslam.verdict import verdict_lines

    stated = compare_log(read_log(log_seen_from_mount(tmp_path, True)), ["isam2"]).verdict
    unstated = compare_log(read_log(log_seen_from_mount(tmp_path, False)), ["isam2"]).verdict
    assert all(v.fits for v in stated.values())
    assert not unstated["odometry"].fits and unstated["odometry"].sigma_factor > 2
    assert any("pose_on_robot" in line for line in verdict_lines(unstated, None))
