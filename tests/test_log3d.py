"""Run-log format v2, the 3-D logs: exact round trip (hypothesis), one-line errors, drives ↔ logs."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ekf.drive3d import step_inputs, steps_of
from slamio.datasets.seed003_log import drive_to_log
from slamio.log import Header, LogFormatError, format_line, read_log, write_log
from slamio.log import SIGMA_PIXEL_PX, StereoObservation, TruthLandmark3, TruthPose3, VelocityOdometry
from slamio.log import pose3_from_matrix, pose3_matrix, stereo_sensor
from slamio.se3 import exp_se3
from slamio.sim3d import DriveScenario, simulate_drive

K = np.array([[707.09, 0.0, 601.9], [0.0, 707.09, 183.1], [0.0, 0.0, 1.0]])
CAM_T_IMU = np.array([[0.0, -1.0, 0.0, 0.1], [0.0, 0.0, -1.0, 0.2], [1.0, 0.0, 0.0, -0.3], [0.0, 0.0, 0.0, 1.0]])
HEADER = Header(
    stamp_s=0.0,
    start_pose=(0.0, 0.0, 0.0),
    start_sigma=(1e-6, 1e-6, 1e-6),
    robot={"name": "car"},
    sensor=stereo_sensor(K, 0.537, CAM_T_IMU),
    noise={"odometry": {}, "observation": {}},
    version=2,
    start_pose3=(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0),
    start_sigma3=(1e-6,) * 6,
)
COV6 = tuple(tuple(0.0025 if i == j and i < 3 else 2.5e-5 if i == j else 0.0 for j in range(6)) for i in range(6))
VEL = VelocityOdometry(0.1, 0.1, (8.0, 0.0, 0.1), (0.0, 0.01, 0.2), COV6)
OBS = StereoObservation(0.1, 7, 650.5, 180.25, 630.0, 180.5, 1.0)
TRUTH = TruthPose3(0.1, 0.8, 0.0, 0.01, 0.0, 0.0, math.sin(0.01), math.cos(0.01))
POINT = TruthLandmark3(7, 20.0, 5.0, 1.5)


def header_dict():
    return json.loads(format_line(HEADER))


def write(path, *lines):
    path.write_text("\n".join(x if isinstance(x, str) else json.dumps(x) for x in lines) + "\n", encoding="utf-8")
    return path


def expect_error(path, line, *words):
    with pytest.raises(LogFormatError) as err:
        read_log(path)
    message = str(err.value)
    assert message.startswith(f"{path}:{line}: ") and "\n" not in message, message
    for word in words:
        assert word in message, message
    return err.value


# ------------------------------------------------------------------ round trip

small = st.floats(min_value=-1e3, max_value=1e3, allow_nan=False)
pixel = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False)


@st.composite
def unit_quaternions(draw):
    q = np.array([draw(st.floats(min_value=-1.0, max_value=1.0)) for _ in range(4)])
    if np.linalg.norm(q) < 1e-3:
        q = np.array([0.0, 0.0, 0.0, 1.0])
    return tuple(float(v) for v in q / np.linalg.norm(q))


@st.composite
def covariances6(draw):
    L = np.array([[draw(st.floats(min_value=-1.0, max_value=1.0)) for _ in range(6)] for _ in range(6)])
    m = L @ L.T + draw(st.floats(min_value=1e-6, max_value=1.0)) * np.eye(6)
    return tuple(tuple(float(v) for v in row) for row in (m + m.T) / 2.0)


@st.composite
def covariances4(draw):
    L = np.array([[draw(st.floats(min_value=-3.0, max_value=3.0)) for _ in range(4)] for _ in range(4)])
    m = L @ L.T + draw(st.floats(min_value=1e-6, max_value=1.0)) * np.eye(4)
    return tuple(tuple(float(v) for v in row) for row in (m + m.T) / 2.0)


@st.composite
def records_3d(draw):
    stamp = draw(st.floats(min_value=0.0, max_value=1e3))
    kind = draw(st.sampled_from(["vel", "obs", "truth", "point"]))
    if kind == "vel":
        return VelocityOdometry(stamp, draw(st.floats(min_value=1e-3, max_value=1e3)),
                                (draw(small), draw(small), draw(small)), (draw(small), draw(small), draw(small)),
                                draw(covariances6()))
    if kind == "obs":
        where = (stamp, draw(st.integers(0, 2**31 - 1)), draw(pixel), draw(pixel), draw(pixel), draw(pixel))
        if draw(st.booleans()):
            return StereoObservation(*where, covariance_px2=draw(covariances4()))
        return StereoObservation(*where, draw(st.floats(min_value=SIGMA_PIXEL_PX[0], max_value=SIGMA_PIXEL_PX[1])))
    if kind == "truth":
        return TruthPose3(stamp, draw(small), draw(small), draw(small), *draw(unit_quaternions()))
    return TruthLandmark3(draw(st.integers(0, 2**31 - 1)), draw(small), draw(small), draw(small))


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(record=records_3d(), pose=st.tuples(small, small, small), q=unit_quaternions())
def test_every_3d_record_and_header_round_trip_exactly(tmp_path, record, pose, q):
    header = Header(**{**HEADER.__dict__, "start_pose3": (*pose, *q)})
    if isinstance(record, VelocityOdometry):  # dt_s spans the time since pose 0
        record = VelocityOdometry(**{**record.__dict__, "stamp_s": header.stamp_s + record.dt_s})
    path = tmp_path / "r.jsonl"
    write_log(path, header, [record])
    log = read_log(path)
    assert log.records == (record,)
    assert log.header.start_pose3 == header.start_pose3 and log.header.version == 2 and log.header.is_3d
    x, y, yaw = log.header.start_pose
    R = pose3_matrix(header.start_pose3)[:3, :3]
    assert (x, y) == pose[:2] and yaw == pytest.approx(math.atan2(R[1, 0], R[0, 0]))


def test_pose3_matrix_and_back_agree_with_the_exponential():
    for xi in ([1.0, 2.0, 3.0, 0.1, -0.2, 0.3], [0.0, 0.0, 0.0, math.pi - 1e-3, 0.0, 0.0], [0.0] * 6):
        T = exp_se3(np.array(xi))
        assert np.allclose(pose3_matrix(pose3_from_matrix(T)), T, atol=1e-12)
        assert pose3_from_matrix(T)[6] >= 0.0


def test_a_planar_log_is_still_written_as_version_1(tmp_path):
    from slamio.sim import simulate

    header, records = simulate("arena-square", 1)
    write_log(tmp_path / "p.jsonl", header, records[:5])
    first = json.loads((tmp_path / "p.jsonl").read_text().splitlines()[0])
    assert first["version"] == 1 and "pose3" not in first["start"]


def test_steps_group_the_3d_records():
    from slamio.log import group_steps

    second = VelocityOdometry(0.2, 0.1, VEL.v_mps, VEL.w_radps, COV6)
    steps = group_steps(HEADER, [POINT, OBS, VEL, OBS, TRUTH, second])
    assert [len(s.observations) for s in steps] == [1, 1, 0]
    assert steps[1].odometry == VEL and steps[1].truth == TRUTH and steps[2].odometry == second


# ------------------------------------------------------------------ bad input: one line naming line and field


@pytest.mark.parametrize(
    "mutate, words",
    [
        (lambda d: {**d, "dt_s": 0.0}, ["'dt_s' must be > 0"]),
        (lambda d: {**d, "dt_s": 0.2}, ["'dt_s' is 0.2", "difference of their stamps"]),
        (lambda d: {**d, "v_mps": [1.0, 2.0]}, ["'v_mps' must be a list of 3 numbers"]),
        (lambda d: {**d, "w_radps": [0.0, 0.0, 1e5]}, ["'w_radps'", "rad/s"]),
        (lambda d: {**d, "covariance": [[0.0] * 6] * 6}, ["'covariance' must be positive definite"]),
        (lambda d: {**d, "covariance": [[1.0] * 5] * 6}, ["'covariance'", "list of 6 numbers"]),
        (lambda d: {k: v for k, v in d.items() if k != "covariance"}, ["missing field 'covariance'"]),
    ],
)
def test_bad_velocity_records(tmp_path, mutate, words):
    record = json.loads(format_line(VEL))
    expect_error(write(tmp_path / "v.jsonl", header_dict(), mutate(record)), 2, *words)


@pytest.mark.parametrize(
    "mutate, words",
    [
        (lambda d: {**d, "track_id": -1}, ["'track_id'", "outside 0..2^31-1"]),
        (lambda d: {**d, "track_id": 2**31}, ["'track_id'", "outside 0..2^31-1"]),
        (lambda d: {**d, "track_id": 1.5}, ["'track_id' must be an integer"]),
        (lambda d: {**d, "u_left_px": "650"}, ["'u_left_px' must be a number"]),
        (lambda d: {**d, "v_right_px": 1e7}, ["'v_right_px'", "px"]),
        (lambda d: {**d, "sigma_px": 0.0}, ["'sigma_px' must be > 0"]),
        (lambda d: {**d, "sigma_px": 1e5}, ["'sigma_px'", "outside"]),
        (lambda d: {**d, "u_l_px": 1.0}, ["unknown field(s) u_l_px"]),
        (lambda d: {k: v for k, v in d.items() if k != "sigma_px"}, ["missing field 'sigma_px'", "'covariance_px2'"]),
        (lambda d: {**d, "covariance_px2": COV4}, ["both 'sigma_px' and 'covariance_px2'", "keep one"]),
        (lambda d: {**_no_sigma(d), "covariance_px2": [[1.0] * 4] * 4}, ["'covariance_px2' must be positive definite"]),
        (lambda d: {**_no_sigma(d), "covariance_px2": [[1.0, 0.5, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]},
         ["'covariance_px2' must be symmetric"]),
        (lambda d: {**_no_sigma(d), "covariance_px2": [[2e8, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]},
         ["'covariance_px2' holds 200000000.0", "px²"]),
        (lambda d: {**_no_sigma(d), "covariance_px2": [[1.0] * 4] * 3}, ["'covariance_px2' must be a 4×4"]),
    ],
)
def test_bad_stereo_observations(tmp_path, mutate, words):
    record = json.loads(format_line(OBS))
    expect_error(write(tmp_path / "o.jsonl", header_dict(), mutate(record)), 2, *words)


COV4 = [[0.04, 0.0, 0.01, 0.0], [0.0, 0.25, 0.0, 0.24], [0.01, 0.0, 0.04, 0.0], [0.0, 0.24, 0.0, 0.25]]


def _no_sigma(d: dict) -> dict:
    return {k: v for k, v in d.items() if k != "sigma_px"}


def test_a_stereo_observation_with_a_pixel_covariance_reads_back_and_validates(tmp_path, capsys):
    from fgslam.cli import main

    record = {**_no_sigma(json.loads(format_line(OBS))), "covariance_px2": COV4}
    path = write(tmp_path / "c.jsonl", header_dict(), record)
    (obs,) = read_log(path).records
    assert obs.sigma_px is None and obs.covariance_px2 == tuple(tuple(row) for row in COV4)
    np.testing.assert_array_equal(obs.pixel_covariance(), COV4)
    np.testing.assert_array_equal(OBS.pixel_covariance(), np.eye(4))  # sigma_px 1.0: σ² I
    assert main(["validate", str(path)]) == 0
    assert "1 observation" in capsys.readouterr().out


def test_bad_truth_and_header(tmp_path):
    truth = {**json.loads(format_line(TRUTH)), "qw": 2.0}
    expect_error(write(tmp_path / "t.jsonl", header_dict(), truth), 2, "quaternion", "norm")
    h = header_dict()
    expect_error(write(tmp_path / "h1.jsonl", {**h, "version": 1}), 1, "pose3", "needs \"version\": 2")
    expect_error(write(tmp_path / "h2.jsonl", {**h, "start": {**h["start"], "sigma3": [0.1] * 5}}), 1,
                 "start.sigma3", "6 numbers")
    expect_error(write(tmp_path / "h3.jsonl", {**h, "start": {**h["start"], "pose": [0, 0, 0]}}), 1,
                 "unknown field(s) pose")
    sensor = {k: v for k, v in h["sensor"].items() if k != "baseline_m"}
    expect_error(write(tmp_path / "h4.jsonl", {**h, "sensor": sensor}), 1, "lacks 'baseline_m'")
    bent = [[1.0, 0.1, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
    expect_error(write(tmp_path / "h5.jsonl", {**h, "sensor": {**h["sensor"], "cam_T_imu": bent}}), 1,
                 "cam_T_imu", "rigid")
    expect_error(write(tmp_path / "h6.jsonl", {**h, "sensor": {**h["sensor"], "kind": "range-bearing"}}), 1,
                 "\"stereo\"")


def test_planar_and_3d_records_do_not_mix(tmp_path):
    from tests.test_log import HEADER as PLANAR_HEADER

    planar = json.loads(format_line(PLANAR_HEADER))
    expect_error(write(tmp_path / "a.jsonl", planar, json.loads(format_line(OBS))), 2,
                 "stereo_observation record in a planar log", "start.pose3")
    odometry = {"type": "odometry", "stamp_s": 0.1, "dx_m": 0.1, "dy_m": 0.0, "dtheta_rad": 0.0,
                "covariance": [[1e-4, 0, 0], [0, 1e-4, 0], [0, 0, 1e-4]]}
    expect_error(write(tmp_path / "b.jsonl", header_dict(), odometry), 2, "odometry record in a 3-D log")
    live = {"type": "live_step", "stamp_s": 0.1, "pose_index": 0, "latency_s": 0.001}
    assert len(read_log(write(tmp_path / "c.jsonl", header_dict(), live)).records) == 1


TEMPLATES = [header_dict(), json.loads(format_line(VEL)), json.loads(format_line(OBS)),
             json.loads(format_line(TRUTH)), json.loads(format_line(POINT))]
json_values = st.recursive(
    st.one_of(st.none(), st.booleans(), st.text(max_size=4), st.integers(-(10**30), 10**30),
              st.floats(allow_nan=False, allow_infinity=False), st.sampled_from([0.0, 1e-300, 1e300, -1, 2**31, 2**56])),
    lambda inner: st.one_of(st.lists(inner, max_size=7), st.dictionaries(st.text(max_size=4), inner, max_size=3)),
    max_leaves=10,
)


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_random_field_values_never_raise_anything_but_log_format_error(tmp_path, data):
    """A valid 3-D header or record with one field (or one nested field) replaced by random JSON."""
    index = data.draw(st.sampled_from(range(len(TEMPLATES))))
    d = json.loads(json.dumps(TEMPLATES[index]))
    target = d
    key = data.draw(st.sampled_from(sorted(d) + ["extra"]))
    if isinstance(d.get(key), (dict, list)) and d[key] and data.draw(st.booleans()):  # one level down
        target = d[key]
        key = data.draw(st.sampled_from(sorted(target) if isinstance(target, dict) else range(len(target))))
    target[key] = data.draw(json_values)
    lines = [d] if index == 0 else [header_dict(), d]
    path = write(tmp_path / "f.jsonl", *lines)
    try:
        read_log(path)
    except LogFormatError as err:
        assert str(err).startswith(f"{path}:{err.line}: ") and "\n" not in str(err)


# ------------------------------------------------------------------ drives ↔ logs


def assert_same_inputs(log, drive):
    """The estimators' inputs from the log's typed steps equal those from the drive's arrays
    (every twist but the drive's last, which acts after its last stamp)."""
    from_log, from_drive = list(step_inputs(log.steps())), list(steps_of(drive))
    assert len(from_log) == len(from_drive) == drive.n_steps
    for a, b in zip(from_log, from_drive):
        assert a.dt_s == b[0] and np.array_equal(a.ids, b[2]) and np.array_equal(a.pixels, b[3])
        assert (a.twist is None and b[1] is None) or np.array_equal(a.twist, b[1])


def test_a_simulated_drive_survives_the_log_exactly(tmp_path):
    from fgslam.runner3d import prepare_log3d, truth_reference_3d

    drive = simulate_drive(3, DriveScenario(straight_m=30.0, side_m=20.0))
    header, records = drive_to_log(drive, source={"generator": "test"})
    write_log(tmp_path / "d.jsonl", header, records)
    log = read_log(tmp_path / "d.jsonl")
    assert_same_inputs(log, drive)
    ready = prepare_log3d(log)
    assert np.array_equal(ready.stamps_s, drive.stamps_s)
    assert np.allclose(ready.rig.K, drive.K) and ready.rig.baseline_m == drive.baseline_m
    assert np.array_equal(ready.rig.cam_T_imu, drive.cam_T_imu)
    truth = truth_reference_3d(log)
    assert np.allclose(truth.trajectory, drive.truth_world_T_imu, atol=1e-12)
    ids = drive.ids(np.arange(drive.n_landmarks))
    assert np.array_equal(np.array([truth.landmarks[j] for j in ids]), drive.truth_landmarks_m)


def test_a_planar_log_is_not_a_drive(tmp_path):
    from fgslam.runner3d import prepare_log3d
    from slamio.errors import FgslamError
    from slamio.sim import simulate

    header, records = simulate("arena-square", 1)
    write_log(tmp_path / "p.jsonl", header, records[:3])
    with pytest.raises(FgslamError, match="planar log"):
        prepare_log3d(read_log(tmp_path / "p.jsonl"))


# ------------------------------------------------------------------ the verbs that write 3-D logs


def test_fgslam_sim_stereo_loop_writes_a_valid_3d_log_with_truth(tmp_path, capsys):
    from fgslam.cli import main

    out = tmp_path / "s.jsonl"
    assert main(["sim", "stereo-loop", "--seed", "2", "--out", str(out)]) == 0
    log = read_log(out)
    assert log.header.is_3d and log.header.source["seed"] == 2
    truth = np.array([s.truth.matrix() for s in log.steps()])
    assert np.allclose(truth, simulate_drive(2).truth_world_T_imu, atol=1e-12)
    assert main(["validate", str(out)]) == 0
    assert "valid fgslam 3-D stereo + IMU run log v2" in capsys.readouterr().out
    assert main(["sim", "stereo-loop", "--seed", "2", "--out", str(out)]) == 1  # kept without --overwrite
    assert main(["sim", "stereo-loop", "--hide-ids", "--out", str(tmp_path / "h.jsonl")]) == 1
    assert "--hide-ids: not available for stereo-loop" in capsys.readouterr().err


def test_fgslam_import_seed003_reads_the_npz_layout(tmp_path, capsys):
    from fgslam.cli import main
    from slamio.datasets.seed003 import save_drive

    drive = simulate_drive(4, DriveScenario(straight_m=30.0, side_m=20.0))
    npz = tmp_path / "drive.npz"
    save_drive(npz, drive)
    out = tmp_path / "d.jsonl"
    assert main(["import", "seed003", str(npz), str(out), "--pixel-sigma", "0.5"]) == 0
    log = read_log(out)
    assert {o.sigma_px for s in log.steps() for o in s.observations} == {0.5}
    assert_same_inputs(log, drive)
    assert main(["import", "seed003", str(tmp_path / "none.npz"), str(tmp_path / "x.jsonl")]) == 2  # an input file: status 2
    assert "none.npz: no such file" in capsys.readouterr().err
    assert main(["import", "seed003", str(npz), str(tmp_path / "y.jsonl"), "--speed-sigma", "-1"]) == 1
    assert "--speed-sigma -1.0 must be a standard deviation > 0" in capsys.readouterr().err
    assert not (tmp_path / "y.jsonl").exists()
