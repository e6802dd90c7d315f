"""Run-log format v1: exact round trip (hypothesis), validation messages, truncation."""

from __future__ import annotations

import json
import math

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from builders import assert_log_round_trips
from slamio.errors import FgslamError
from slamio.log import (
    COORDINATE_M,
    INCREMENT_M,
    INCREMENT_RAD,
    WORLD_ANGLE_RAD,
    MAX_ID,
    RANGE_M,
    SIGMA_ANGLE_RAD,
    SIGMA_LENGTH_M,
    EVENT_KINDS,
    EVENT_SIDES,
    Event,
    Header,
    LogFormatError,
    Observation,
    Odometry,
    TruthLandmark,
    TruthPose,
    as_matrix3,
    event_counts,
    format_line,
    group_steps,
    read_log,
    write_log,
)

finite = st.floats(allow_nan=False, allow_infinity=False, width=64)
small = st.floats(min_value=-1e3, max_value=1e3, allow_nan=False)
# Within the reader's bounds (slamio.log, docs/log-format.md "Bounds"), edges included.
sigma_m = st.one_of(st.floats(min_value=SIGMA_LENGTH_M[0], max_value=SIGMA_LENGTH_M[1]), st.sampled_from(SIGMA_LENGTH_M))
sigma_rad = st.one_of(st.floats(min_value=SIGMA_ANGLE_RAD[0], max_value=SIGMA_ANGLE_RAD[1]), st.sampled_from(SIGMA_ANGLE_RAD))
range_m = st.one_of(st.floats(min_value=RANGE_M[0], max_value=RANGE_M[1]), st.sampled_from(RANGE_M))
angle = st.one_of(st.floats(min_value=-math.pi, max_value=math.pi), st.sampled_from([-math.pi, math.pi]))
landmark_id = st.one_of(st.integers(0, 10**9), st.just(MAX_ID))


def within(limit):
    """Floats in ±limit, the edges included."""
    return st.one_of(st.floats(min_value=-limit, max_value=limit), st.sampled_from([-limit, limit]))


increment_m, increment_rad = within(INCREMENT_M), within(INCREMENT_RAD)
coordinate_m, world_angle = within(COORDINATE_M), within(WORLD_ANGLE_RAD)
json_scalar = st.one_of(st.none(), st.booleans(), st.integers(-(2**53), 2**53), finite, st.text(max_size=8))
json_object = st.dictionaries(st.text(max_size=6), json_scalar, max_size=3)


@st.composite
def headers(draw):
    return Header(
        stamp_s=draw(small),
        start_pose=(draw(small), draw(small), draw(small)),
        start_sigma=(draw(sigma_m), draw(sigma_m), draw(sigma_rad)),
        robot={"name": draw(st.text(max_size=10)), **draw(json_object)},
        sensor={"kind": "range-bearing", **draw(json_object)},
        noise={"odometry": draw(json_object), "observation": draw(json_object)},
        source=draw(json_object),
    )


@st.composite
def covariances(draw):
    """A symmetric positive-definite 3×3: L Lᵀ + εI with L drawn small."""
    entries = [draw(st.floats(min_value=-1.0, max_value=1.0)) for _ in range(6)]
    a, b, c, d, e, f = entries
    low = [[a, 0.0, 0.0], [b, c, 0.0], [d, e, f]]
    m = [[sum(low[i][k] * low[j][k] for k in range(3)) + (1e-3 if i == j else 0.0) for j in range(3)] for i in range(3)]
    m = [[m[min(i, j)][max(i, j)] for j in range(3)] for i in range(3)]  # exactly symmetric
    return as_matrix3(m)


def optional_pair(draw, value, sigma):
    if draw(st.booleans()):
        return draw(value), draw(sigma)
    return None, None


def _new_id(draw, ids, used: set[int]) -> int:
    """An id from ``ids`` not in ``used`` (which it joins)."""
    lid = draw(ids.filter(lambda i: i not in used))
    used.add(lid)
    return lid


@st.composite
def records_in_time_order(draw, start_stamp_s):
    stamp = start_stamp_s
    out = []
    truth_ids: set[int] = set()  # a landmark's truth is given once (the reader refuses a second)
    poses = 0  # odometry records so far: an event's pose_index
    for _ in range(draw(st.integers(0, 12))):
        stamp += draw(st.floats(min_value=0.0, max_value=1.0))
        kind = draw(st.sampled_from(["odometry", "observation", "truth_pose", "truth_landmark", "event"]))
        if kind == "event":
            out.append(Event(stamp, draw(st.sampled_from(EVENT_KINDS)), poses,
                             draw(st.one_of(st.none(), st.sampled_from(EVENT_SIDES)))))
        elif kind == "odometry":
            poses += 1
            raw = draw(st.booleans())
            out.append(
                Odometry(
                    stamp, draw(increment_m), draw(increment_m), draw(increment_rad), draw(covariances()),
                    draw(increment_m) if raw else None, draw(increment_rad) if raw else None,
                )
            )
        elif kind == "observation":
            height, sigma_height = optional_pair(draw, coordinate_m, sigma_m)
            yaw, sigma_yaw = optional_pair(draw, angle, sigma_rad)
            out.append(
                Observation(
                    stamp, draw(st.one_of(st.none(), landmark_id)), draw(range_m), draw(angle),
                    draw(sigma_m), draw(sigma_rad), height, sigma_height, yaw, sigma_yaw,
                    draw(st.one_of(st.none(), landmark_id)),
                )
            )
        elif kind == "truth_pose":
            out.append(TruthPose(stamp, draw(coordinate_m), draw(coordinate_m), draw(st.none() | world_angle)))
        else:
            out.append(
                TruthLandmark(
                    _new_id(draw, landmark_id, truth_ids), draw(coordinate_m), draw(coordinate_m),
                    draw(st.one_of(st.none(), coordinate_m)), draw(st.one_of(st.none(), world_angle)),
                )
            )
    return out


@settings(max_examples=150, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_write_then_read_round_trips_exactly(tmp_path, data):
    header = data.draw(headers())
    records = data.draw(records_in_time_order(header.stamp_s))
    assert_log_round_trips(tmp_path / "run.jsonl", header, records)


# ------------------------------------------------------------------ a small valid log

HEADER = Header(
    stamp_s=0.0,
    start_pose=(1.0, 2.0, 0.5),
    start_sigma=(1e-3, 1e-3, 1e-3),
    robot={"name": "test robot"},
    sensor={"kind": "range-bearing"},
    noise={"odometry": {}, "observation": {}},
)
COV = as_matrix3([[1e-4, 0, 0], [0, 1e-4, 0], [0, 0, 1e-5]])
RECORDS = [
    TruthLandmark(7, 3.0, 4.0),
    TruthPose(0.0, 1.0, 2.0, 0.5),
    Observation(0.0, 7, 2.5, 0.1, 0.05, 0.02),
    Odometry(0.1, 0.1, 0.0, 0.01, COV, 0.1, 0.01),
    TruthPose(0.1, 1.09, 2.05, 0.51),
    Observation(0.1, 7, 2.4, 0.1, 0.05, 0.02),
    Observation(0.1, None, 1.0, -0.3, 0.05, 0.02),
    Odometry(0.2, 0.1, 0.0, 0.0, COV),
    Observation(0.2, 7, 2.3, 0.1, 0.05, 0.02),
]


@pytest.fixture
def log_path(tmp_path):
    path = tmp_path / "run.jsonl"
    write_log(path, HEADER, RECORDS)
    return path


def test_steps_group_records_by_pose():
    steps = group_steps(HEADER, RECORDS)
    assert [s.index for s in steps] == [0, 1, 2]
    assert steps[0].odometry is None and steps[0].stamp_s == 0.0
    assert [len(s.observations) for s in steps] == [1, 2, 1]
    assert steps[1].odometry == RECORDS[3] and steps[1].truth == RECORDS[4]
    assert steps[2].truth is None


def test_event_records_belong_to_no_step_and_are_counted_by_kind(tmp_path):
    """An event between two odometry records is kept in file order, changes no step, and
    its pose_index is the odometry records before it (the reader checks)."""
    events = [Event(0.15, "bump", 1, "left"), Event(0.15, "bump", 1, "both"), Event(0.2, "wheel-drop", 2)]
    records = RECORDS[:7] + events[:2] + RECORDS[7:] + events[2:]
    path = tmp_path / "events.jsonl"
    write_log(path, HEADER, records)
    assert json.loads(path.read_text().splitlines()[8]) == {
        "type": "event", "stamp_s": 0.15, "kind": "bump", "pose_index": 1, "side": "left"}
    log = read_log(path)
    assert log.records == tuple(records)
    assert log.steps() == group_steps(HEADER, RECORDS)
    assert event_counts(log.records) == {"bump": 2, "wheel-drop": 1}


def test_unknown_landmark_is_written_as_null(log_path):
    lines = log_path.read_text().splitlines()
    assert json.loads(lines[7])["landmark_id"] is None


def replace_line(path, number, text):
    lines = path.read_text().splitlines(keepends=True)
    lines[number - 1] = text + "\n"
    path.write_text("".join(lines))


@pytest.mark.parametrize(
    "line, expected",
    [
        ('{"type": "odometry", "stamp_s": 0.1, "dx_m": 0.1', "not valid JSON"),
        ('{"type": "odometry", "stamp_s": 0.1, "dx_m": "fast", "dy_m": 0, "dtheta_rad": 0, '
         '"covariance": [[1,0,0],[0,1,0],[0,0,1]]}', "field 'dx_m' must be a number"),
        ('{"type": "odometry", "stamp_s": 0.1, "dx_m": 0.1, "dy_m": 0, "dtheta_rad": 0, '
         '"covariance": [[1,0,0],[0,0,0],[0,0,1]]}', "positive definite"),
        ('{"type": "odometry", "stamp_s": 0.1, "dx_m": 0.1, "dy_m": 0, "dtheta_rad": 0, '
         '"covariance": [[1,0.5,0],[0,1,0],[0,0,1]]}', "symmetric"),
        ('{"type": "observation", "stamp_s": 0.1, "landmark_id": 7, "range_m": -1, "bearing_rad": 0, '
         '"sigma_range_m": 0.1, "sigma_bearing_rad": 0.1}', "'range_m' must be > 0"),
        ('{"type": "observation", "stamp_s": 0.1, "landmark_id": 7, "range_m": 1, "bearing_rad": 0, '
         '"sigma_range_m": 0.1, "sigma_bearing_rad": 0.1, "height_m": 0.3}', "give both or neither"),
        ('{"type": "observation", "stamp_s": 0.1, "landmark_id": 7, "range_m": 1, "bearing_rad": NaN, '
         '"sigma_range_m": 0.1, "sigma_bearing_rad": 0.1}', "NaN is not a number"),
        ('{"type": "observation", "stamp_s": 0.1, "range_m": 1, "bearing_rad": 0, '
         '"sigma_range_m": 0.1, "sigma_bearing_rad": 0.1}', "missing field 'landmark_id'"),
        ('{"type": "wheel", "stamp_s": 0.1}', "unknown record type \"wheel\""),
        ('{"type": "truth_pose", "stamp_s": 0.1, "x_m": 0, "y_m": 0, "theta_rad": 0, "z_m": 1}', "unknown field(s) z_m"),
        ('{"type": "event", "stamp_s": 0.1, "kind": "bumped", "pose_index": 1}',
         "field 'kind' is \"bumped\"; write one of bump, cliff, wheel-drop"),
        ('{"type": "event", "stamp_s": 0.1, "kind": "bump", "pose_index": 1, "side": "front"}',
         "field 'side' is \"front\"; write one of left, right, both"),
        ('{"type": "event", "stamp_s": 0.1, "kind": "bump", "pose_index": -1}', "field 'pose_index' is -1"),
        ('{"type": "event", "stamp_s": 0.1, "kind": "cliff"}', "missing field 'pose_index'"),
        ('{"type": "event", "stamp_s": 0.1, "pose_index": 1}', "missing field 'kind'"),
        ('{"type": "event", "stamp_s": 0.1, "kind": "bump", "pose_index": 0}',
         "field 'pose_index' is 0 but 1 odometry record comes before this line"),
        ('{"type": "event", "stamp_s": 0.1, "kind": "bump", "pose_index": 1, "bumper": "left"}',
         "unknown field(s) bumper in this event record"),
        ("[1, 2, 3]", "one JSON object"),
        ("", "empty line"),
    ],
)
def test_bad_middle_line_names_file_and_line_and_keeps_the_good_part(log_path, line, expected):
    # (a stamp that goes back in time names two lines: tests/test_log_reader_checks.py)
    replace_line(log_path, 6, line)  # line 6 holds the truth pose of step 1
    with pytest.raises(LogFormatError) as err:
        read_log(log_path)
    message = str(err.value)
    assert message.startswith(f"{log_path}:6: ")
    assert expected in message
    assert err.value.line == 6
    assert err.value.partial.records == tuple(RECORDS[:4])


def test_truncated_last_line_is_reported_not_fatal(log_path):
    text = log_path.read_text()
    log_path.write_text(text[: len(text) - 25])  # cut the last record mid-line
    log = read_log(log_path)
    assert log.records == tuple(RECORDS[:-1])
    assert log.truncated is not None
    assert f"{log_path}:10:" in log.truncated and "cut off" in log.truncated


def test_last_line_without_newline_but_complete_is_fine(log_path):
    log_path.write_text(log_path.read_text().rstrip("\n"))
    log = read_log(log_path)
    assert log.records == tuple(RECORDS) and log.truncated is None


def test_complete_but_invalid_last_line_is_an_error(log_path):
    replace_line(log_path, 10, '{"type": "truth_pose"}')
    with pytest.raises(LogFormatError, match=r":10: missing field 'stamp_s'"):
        read_log(log_path)


@pytest.mark.parametrize(
    "mutate, expected",
    [
        (lambda h: {**h, "format": "something-else"}, "is this an fgslam run log"),
        (lambda h: {**h, "version": 3}, "version 3 is not supported"),
        (lambda h: {**h, "units": {"length": "mm", "angle": "rad", "time": "s"}}, "store SI"),
        (lambda h: {**h, "noise": {"odometry": {}}}, "lacks 'observation'"),
        (lambda h: {**h, "start": {**h["start"], "sigma": [0, 1, 1]}}, "start.sigma must be > 0"),
    ],
)
def test_bad_header_is_line_1(log_path, mutate, expected):
    header = json.loads(log_path.read_text().splitlines()[0])
    replace_line(log_path, 1, json.dumps(mutate(header)))
    with pytest.raises(LogFormatError) as err:
        read_log(log_path)
    assert str(err.value).startswith(f"{log_path}:1: ") and expected in str(err.value)
    assert err.value.partial is None


def test_missing_and_empty_files(tmp_path):
    with pytest.raises(FgslamError, match="cannot open"):
        read_log(tmp_path / "nope.jsonl")
    (tmp_path / "empty.jsonl").write_text("")
    with pytest.raises(LogFormatError, match="empty"):
        read_log(tmp_path / "empty.jsonl")


def test_writer_refuses_nan():
    with pytest.raises(FgslamError, match="NaN"):
        format_line(TruthPose(0.0, math.nan, 0.0, 0.0))
