"""A 3-D log held as columns (slamio.log.columns3d): the same steps as the records give, the
same errors (file:line and the field), less memory, and a run on it with the same results."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ekf.drive3d import step_inputs
from fgslam.noise3d import noise_of
from fgslam.runner3d import compute_metrics_3d, run_log3d, truth_landmarks3, truth_reference_3d
from slamio.log import LiveStep, LogStream, read_log, write_log
from slamio.log import StereoObservation, TruthLandmark3, TruthPose3, VelocityOdometry
from slamio.log.columns3d import ColumnLog3d, StepColumns3d, columns3d_of, read_columns3d, step_truths
from builders import retained_bytes, write_small_drive
from test_log_columns import assert_same_steps_and_notes, both_errors
from test_log3d import HEADER, covariances4, covariances6, unit_quaternions


def assert_same_log(path) -> ColumnLog3d:
    """``read_columns3d(path)`` answers as ``read_log(path)`` does, step for step and type for type."""
    log, columns = read_log(path), read_columns3d(path)
    steps, table = log.steps(), columns.steps()
    assert isinstance(table, StepColumns3d)
    assert_same_steps_and_notes(log, columns)
    assert repr(step_truths(table)) == repr(step_truths(steps))
    pixels = {(o.sigma_px, o.covariance_px2) for s in steps for o in s.observations}
    twists = {s.odometry.covariance for s in steps if s.odometry is not None}
    assert table.noise_levels() == (pixels, twists)
    assert truth_landmarks3(columns) == truth_landmarks3(log)
    assert columns.truth_landmarks() == {r.landmark_id: r for r in truth_landmarks3(log)}
    for ours, theirs in zip(step_inputs(table), step_inputs(steps)):
        assert repr(ours) == repr(theirs)
    return columns


small = st.floats(min_value=-1e3, max_value=1e3, allow_nan=False)
pixel = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False)
#: a few covariances shared by the records (as a drive states one or two), zeros of either sign
ZERO_SIGNS = (tuple(tuple(1e-2 if i == j else (-0.0 if (i, j) in ((0, 1), (1, 0)) else 0.0) for j in range(6))
                    for i in range(6)),
              tuple(tuple(1e-2 if i == j else 0.0 for j in range(6)) for i in range(6)))


@st.composite
def drives(draw):
    """Records of a 3-D log in time order: velocity records whose dt_s spans the time since the
    previous pose, observations (a σ or a 4×4 covariance, repeated tracks allowed), truths of
    poses and landmarks, live steps."""
    covariances6s = draw(st.lists(st.one_of(covariances6(), st.sampled_from(ZERO_SIGNS)), min_size=1, max_size=3))
    pixel_covariances = draw(st.lists(covariances4(), min_size=1, max_size=2))
    stamp = pose_stamp = HEADER.stamp_s
    records, landmark_ids = [], draw(st.lists(st.integers(0, 2**31 - 1), max_size=4, unique=True))
    for kind in draw(st.lists(st.sampled_from(["vel", "obs", "obs", "truth", "live", "point"]), max_size=40)):
        stamp += draw(st.sampled_from([0.0, 0.05, 0.1, 0.25]))
        if kind == "vel" and stamp > pose_stamp:
            records.append(VelocityOdometry(stamp, stamp - pose_stamp, (draw(small), draw(small), draw(small)),
                                            (draw(small), draw(small), draw(small)), draw(st.sampled_from(covariances6s))))
            pose_stamp = stamp
        elif kind == "obs":
            where = (stamp, draw(st.integers(0, 5)), draw(pixel), draw(pixel), draw(pixel), draw(pixel))
            if draw(st.booleans()):
                records.append(StereoObservation(*where, covariance_px2=draw(st.sampled_from(pixel_covariances))))
            else:
                records.append(StereoObservation(*where, draw(st.sampled_from([0.5, 1.0, 1e-6]))))
        elif kind == "truth":
            records.append(TruthPose3(stamp, draw(small), draw(small), draw(small), *draw(unit_quaternions())))
        elif kind == "live":
            records.append(LiveStep(stamp, 0, 0.01))
        elif kind == "point" and landmark_ids:
            records.append(TruthLandmark3(landmark_ids.pop(), draw(small), draw(small), draw(small)))
    return records


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(records=drives())
def test_any_valid_3d_log_reads_into_the_same_steps(tmp_path, records):
    path = tmp_path / "drive.jsonl"
    write_log(path, HEADER, records)
    assert_same_log(path)


def test_covariances_that_differ_in_the_sign_of_a_zero_stay_apart(tmp_path):
    """Each distinct covariance is kept once: -0.0 and 0.0 are told apart, as the records hold them."""
    minus, plus = ZERO_SIGNS
    records = [VelocityOdometry(0.1 * k, 0.1, (1.0, 0.0, 0.0), (0.0, 0.0, 0.1), c)
               for k, c in enumerate([minus, plus, minus, plus], start=1)]
    records.insert(2, StereoObservation(0.2, 3, 650.0, 180.0, 640.0, 180.5, 1.0))
    path = tmp_path / "zeros.jsonl"
    write_log(path, HEADER, records)
    columns = assert_same_log(path)
    assert [repr(s.odometry.covariance[0][1]) for s in columns.steps()[1:]] == ["-0.0", "0.0", "-0.0", "0.0"]


@pytest.fixture(scope="module")
def small_log(tmp_path_factory):
    return write_small_drive(tmp_path_factory.mktemp("columns3d") / "small.jsonl")


def test_a_simulated_drive_reads_into_the_same_steps_and_truth(small_log):
    columns = assert_same_log(small_log)
    log = read_log(small_log)
    ours, theirs = truth_reference_3d(columns), truth_reference_3d(log)
    np.testing.assert_array_equal(ours.trajectory, theirs.trajectory)
    assert ours.landmarks.keys() == theirs.landmarks.keys() and len(ours.landmarks) > 10
    assert noise_of(columns) == noise_of(log)


def test_a_cut_off_last_line_as_read_log(small_log, tmp_path):
    text = small_log.read_text()
    path = tmp_path / "cut.jsonl"
    path.write_text(text + text.splitlines()[7][:40])
    columns = assert_same_log(path)
    assert columns.truncated and columns.truncated.startswith(f"{path}:")


@pytest.mark.parametrize("field, value, words", [
    ("u_left_px", "left", "field 'u_left_px'"),
    ("sigma_px", -1.0, "'sigma_px'"),
    ("track_id", 1.5, "field 'track_id' must be an integer"),
])
def test_a_bad_line_is_the_same_error_as_read_log(small_log, tmp_path, field, value, words):
    path, number, expected, got = both_errors(small_log, tmp_path, "stereo_observation",
                                              lambda record: record.__setitem__(field, value), read_columns3d)
    assert str(got) == str(expected) and got.line == expected.line == number
    assert str(got).startswith(f"{path}:{number}: ") and words in str(got)


def test_a_bad_velocity_interval_is_the_same_error_as_read_log(small_log, tmp_path):
    _, number, expected, got = both_errors(small_log, tmp_path, "velocity_odometry",
                                           lambda record: record.__setitem__("dt_s", 2.0 * record["dt_s"]),
                                           read_columns3d)
    assert str(got) == str(expected) and f":{number}: field 'dt_s'" in str(got)


def test_a_planar_log_is_refused(tmp_path):
    from slamio.sim import simulate

    header, records = simulate("grid", 3, landmarks=10, laps=1)
    path = tmp_path / "planar.jsonl"
    write_log(path, header, records)
    with pytest.raises(ValueError, match="planar.jsonl is a planar log"):
        read_columns3d(path)


def test_a_stream_read_into_columns_is_read_once(small_log):
    seen: list = []
    columns3d_of(LogStream(small_log), visit=seen.append)
    assert seen == list(read_log(small_log).records)


def test_columns_hold_a_fraction_of_what_records_hold(small_log):
    """~64 B an observation in columns against ~500 B as a record: the bound is loose."""
    assert retained_bytes(read_columns3d, small_log) < 0.25 * retained_bytes(read_log, small_log)


def test_a_run_on_columns_gives_the_same_results(small_log):
    """Every estimate and figure (timings and memory aside) is the same from the columns as
    from the records."""
    names = ["ekf-vio", "isam2-3d"]
    results = {reader.__name__: run_log3d(reader(small_log), names) for reader in (read_columns3d, read_log)}

    def figures(result) -> dict:
        metrics = compute_metrics_3d(result, log_path=str(small_log))
        return {name: {k: v for k, v in m.items() if not k.startswith(("time_", "peak_memory"))}
                if isinstance(m, dict) else m for name, m in metrics.items()}

    assert figures(results["read_columns3d"]) == figures(results["read_log"])
    for ours, theirs in zip(results["read_columns3d"].runs, results["read_log"].runs):
        for field in ("online", "final", "covariances", "nis"):
            if getattr(theirs, field) is not None:
                np.testing.assert_array_equal(getattr(ours, field), getattr(theirs, field))
        assert ours.landmarks.keys() == theirs.landmarks.keys()
        assert all(np.array_equal(ours.landmarks[j], theirs.landmarks[j]) for j in theirs.landmarks)
    assert not math.isnan(results["read_columns3d"].batch_error)
