"""The reader under attack (issue 15): hostile values give one clear line, never a traceback.

Every case is read twice: by :func:`slamio.log.read_log` (a :class:`LogFormatError` naming
``file:line`` and the fix, with the good prefix in ``partial``) and by ``fgslam validate``
(exit 2, ``fgslam: error: FILE:LINE: ...``, no traceback). Bounds are tested just inside
(the log is read, and the estimators run on it without an error) and just outside.
Observations the sensor cannot have made are not errors: they are rejected, counted and
kept from the estimators.
"""

from __future__ import annotations

import dataclasses
import json
import math

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fgslam.cli import main
from slamio.log import COORDINATE_M, INCREMENT_M, INCREMENT_RAD, MAX_ID, RANGE_M, WORLD_ANGLE_RAD
from slamio.log import SIGMA_ANGLE_RAD, SIGMA_LENGTH_M
from slamio.log import Header, LogFormatError, Observation, Odometry, TruthPose, as_matrix3, format_line, read_log

HEADER = Header(
    stamp_s=0.0,
    start_pose=(0.0, 0.0, 0.0),
    start_sigma=(1e-3, 1e-3, 1e-3),
    robot={"name": "test robot"},
    sensor={"kind": "range-bearing", "min_range_m": 0.15, "max_range_m": 3.5},
    noise={"odometry": {}, "observation": {}},
)
COV = as_matrix3([[1e-4, 0, 0], [0, 1e-4, 0], [0, 0, 1e-5]])
GOOD = [
    TruthPose(0.0, 0.0, 0.0, 0.0),
    Observation(0.0, 7, 2.5, 0.1, 0.05, 0.02),
    Odometry(0.1, 0.1, 0.0, 0.01, COV),
]
OBS = json.loads(format_line(Observation(0.2, 7, 2.4, 0.1, 0.05, 0.02, 0.2, 0.01, 0.5, 0.05, 7)))
ODO = json.loads(format_line(Odometry(0.2, 0.1, 0.0, 0.0, COV)))
HDR = json.loads(format_line(HEADER))
BAD_LINE = len(GOOD) + 2  # the line after the header and the good records


def write(path, *lines, final_newline=True):
    text = "\n".join(line if isinstance(line, str) else json.dumps(line) for line in lines)
    path.write_text(text + ("\n" if final_newline else ""), encoding="utf-8")
    return path


def log_with(tmp_path, line, **kwargs):
    """A log: header, three good records, then ``line`` (a dict or raw text) on line 5."""
    return write(tmp_path / "run.jsonl", format_line(HEADER), *map(format_line, GOOD), line, **kwargs)


def expect_error(path, line, *words, partial_records=None):
    """read_log fails at ``line`` with all ``words``; so does `fgslam validate`, in one line."""
    with pytest.raises(LogFormatError) as err:
        read_log(path)
    message = str(err.value)
    assert message.startswith(f"{path}:{line}: "), message
    assert err.value.line == line
    for word in words:
        assert word in message, message
    assert "\n" not in message
    if partial_records is not None:
        assert err.value.partial is not None and len(err.value.partial.records) == partial_records
    return err.value


def validate(path, capsys):
    code = main(["validate", str(path)])
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err
    return code, out, err


def expect_cli_error(path, line, capsys, *words):
    code, out, err = validate(path, capsys)
    assert code == 2  # an input file that cannot be used
    first = err.splitlines()[0]
    assert first.startswith(f"fgslam: error: {path}:{line}: ")
    for word in words:
        assert word in first
    return err


def obs(**changes):
    return {**OBS, **changes}


def diagonal(d):
    return [[d[0], 0.0, 0.0], [0.0, d[1], 0.0], [0.0, 0.0, d[2]]]


def cov(d):
    return {**ODO, "covariance": diagonal(d)}


def up(x):
    return math.nextafter(x, math.inf)


def down(x):
    return math.nextafter(x, -math.inf)


# ------------------------------------------------------------------ tracebacks in the reader


@pytest.mark.parametrize("kind", [[], {}, 7, None, True])
def test_type_that_is_not_a_string(tmp_path, capsys, kind):
    path = log_with(tmp_path, {"type": kind, "stamp_s": 0.2})
    expect_error(path, BAD_LINE, "field 'type' must be a string", "expected one of", partial_records=3)
    expect_cli_error(path, BAD_LINE, capsys, "field 'type' must be a string")


@pytest.mark.parametrize("field", ["range_m", "stamp_s", "height_m"])
def test_400_digit_integer(tmp_path, capsys, field):
    line = format_line(Observation(0.2, 7, 2.4, 0.1, 0.05, 0.02, 0.2, 0.01)).replace(
        f'"{field}": {OBS[field]!r}', f'"{field}": ' + "9" * 400
    )
    assert "9" * 400 in line
    path = log_with(tmp_path, line)
    expect_error(path, BAD_LINE, f"field '{field}'", "integer of 400 digits", "too large", partial_records=3)
    expect_cli_error(path, BAD_LINE, capsys, "integer of 400 digits")


def test_400_digit_integer_in_a_covariance_and_the_start_pose(tmp_path):
    line = json.dumps(ODO).replace('"covariance": [[', '"covariance": [[' + "1" * 400 + ", ", 1)
    line = line.replace("[[" + "1" * 400 + ", 0.0001, ", "[[" + "1" * 400 + ", ")
    expect_error(log_with(tmp_path, line), BAD_LINE, "covariance", "integer of 400 digits")
    header = format_line(HEADER).replace('"pose": [0.0, ', '"pose": [' + "1" * 400 + ", ")
    expect_error(write(tmp_path / "h.jsonl", header), 1, "start.pose", "integer of 400 digits")


def test_5000_digit_integer(tmp_path, capsys):
    path = log_with(tmp_path, '{"type": "truth_pose", "stamp_s": ' + "9" * 5000 + ', "x_m": 0, "y_m": 0, "theta_rad": 0}')
    expect_error(path, BAD_LINE, "more than 4300 digits", "corrupted", partial_records=3)
    expect_cli_error(path, BAD_LINE, capsys, "digits")


def test_header_nested_100000_levels(tmp_path, capsys):
    depth = 100_000
    line = format_line(HEADER).replace('"robot": {', '"deep": ' + "[" * depth + "]" * depth + ', "robot": {')
    path = write(tmp_path / "deep.jsonl", line)
    err = expect_error(path, 1, "nested too deeply")
    assert err.partial is None
    expect_cli_error(path, 1, capsys, "nested too deeply")
    # a record line too
    expect_error(log_with(tmp_path, '{"type": ' + "[" * depth + "]" * depth + "}"), BAD_LINE, "nested too deeply")


def test_header_objects_nested_more_than_64_levels_or_holding_infinity(tmp_path):
    def header_with(robot_extra: str):
        return write(tmp_path / "h.jsonl", format_line(HEADER).replace('"robot": {', '"robot": {' + robot_extra + ", "))

    assert read_log(header_with('"ok": ' + "[" * 63 + "]" * 63))
    expect_error(header_with('"deep": ' + "[" * 64 + "]" * 64), 1, "'robot' is nested more than 64 levels")
    expect_error(header_with('"big": 1e400'), 1, "'robot' holds a number too large", "infinity")


# ------------------------------------------------------------------ accepted, then crashing an estimator


@pytest.mark.parametrize("field", ["landmark_id", "truth_landmark_id"])
@pytest.mark.parametrize("value", [-1, MAX_ID + 1, 2**56, 2**63, 10**400])
def test_landmark_ids_outside_0_to_2_to_the_31(tmp_path, capsys, field, value):
    path = log_with(tmp_path, obs(**{field: value}))
    expect_error(path, BAD_LINE, f"field '{field}'", "0 ≤ id < 2^31", "renumber", partial_records=3)
    expect_cli_error(path, BAD_LINE, capsys, "0 ≤ id < 2^31")


def test_truth_landmark_id_bounds(tmp_path):
    line = {"type": "truth_landmark", "landmark_id": MAX_ID + 1, "x_m": 0.0, "y_m": 0.0}
    expect_error(log_with(tmp_path, line), BAD_LINE, "0 ≤ id < 2^31")
    assert read_log(log_with(tmp_path, {**line, "landmark_id": MAX_ID})).records[-1].landmark_id == MAX_ID


# (field, value just inside, value just outside, words of the message)
LOW_M, HIGH_M = SIGMA_LENGTH_M
LOW_RAD, HIGH_RAD = SIGMA_ANGLE_RAD
OBSERVATION_BOUNDS = [
    ("sigma_range_m", HIGH_M, up(HIGH_M), "outside 1e-06..1000 m"),
    ("sigma_range_m", LOW_M, down(LOW_M), "outside 1e-06..1000 m"),
    ("sigma_range_m", HIGH_M, 1e300, "outside 1e-06..1000 m"),
    ("sigma_range_m", LOW_M, 1e-300, "outside 1e-06..1000 m"),
    ("sigma_height_m", HIGH_M, up(HIGH_M), "outside 1e-06..1000 m"),
    ("sigma_height_m", LOW_M, down(LOW_M), "outside 1e-06..1000 m"),
    ("sigma_bearing_rad", HIGH_RAD, up(HIGH_RAD), "outside 1e-06..6.28319 rad"),
    ("sigma_bearing_rad", LOW_RAD, down(LOW_RAD), "outside 1e-06..6.28319 rad"),
    ("sigma_bearing_rad", HIGH_RAD, 1e300, "degrees written as radians?"),
    ("sigma_tag_yaw_rad", HIGH_RAD, up(HIGH_RAD), "outside 1e-06..6.28319 rad"),
    ("sigma_tag_yaw_rad", LOW_RAD, down(LOW_RAD), "outside 1e-06..6.28319 rad"),
    ("range_m", RANGE_M[0], down(RANGE_M[0]), "outside 1e-06..10000 m"),
    ("range_m", RANGE_M[0], 1e-300, "outside 1e-06..10000 m"),
    ("range_m", RANGE_M[1], up(RANGE_M[1]), "outside 1e-06..10000 m"),
    ("bearing_rad", math.pi, up(math.pi), "degrees written as radians?"),
    ("bearing_rad", -math.pi, down(-math.pi), "degrees written as radians?"),
    ("bearing_rad", 0.6, 35.0, "degrees written as radians?"),
    ("bearing_rad", 0.6, 1e300, "degrees written as radians?"),
    ("tag_yaw_rad", math.pi, up(math.pi), "degrees written as radians?"),
    ("tag_yaw_rad", -math.pi, -90.0, "degrees written as radians?"),
]


@pytest.mark.parametrize("field, inside, outside, words", OBSERVATION_BOUNDS)
def test_observation_bounds(tmp_path, capsys, field, inside, outside, words):
    header = dataclasses.replace(HEADER, sensor={"kind": "range-bearing"})  # no range limits
    lines = [format_line(header), *map(format_line, GOOD)]
    path = write(tmp_path / "in.jsonl", *lines, obs(**{field: inside}))
    assert getattr(read_log(path).records[-1], field) == inside
    path = write(tmp_path / "out.jsonl", *lines, obs(**{field: outside}))
    expect_error(path, BAD_LINE, f"field '{field}'", words, partial_records=3)
    expect_cli_error(path, BAD_LINE, capsys, f"field '{field}'", words)


TRUTH_POSE = json.loads(format_line(TruthPose(0.2, 1.0, 2.0, 0.5)))
TRUTH_LANDMARK = {"type": "truth_landmark", "landmark_id": 3, "x_m": 1.0, "y_m": 2.0, "height_m": 0.1, "yaw_rad": 0.0}
RAW_ODO = {**ODO, "distance_m": 0.1, "angle_rad": 0.0}
#: Magnitude bounds of increments, coordinates and world angles: (record, field, limit).
MAGNITUDE_BOUNDS = [
    (ODO, "dx_m", INCREMENT_M), (ODO, "dy_m", INCREMENT_M), (ODO, "dtheta_rad", INCREMENT_RAD),
    (RAW_ODO, "distance_m", INCREMENT_M), (RAW_ODO, "angle_rad", INCREMENT_RAD),
    (TRUTH_POSE, "x_m", COORDINATE_M), (TRUTH_POSE, "y_m", COORDINATE_M), (TRUTH_POSE, "theta_rad", WORLD_ANGLE_RAD),
    (TRUTH_LANDMARK, "x_m", COORDINATE_M), (TRUTH_LANDMARK, "height_m", COORDINATE_M),
    (TRUTH_LANDMARK, "yaw_rad", WORLD_ANGLE_RAD), (OBS, "height_m", COORDINATE_M),
]


@pytest.mark.parametrize("record, field, limit", MAGNITUDE_BOUNDS, ids=lambda v: v if isinstance(v, str) else None)
def test_increments_coordinates_and_world_angles_are_bounded(tmp_path, capsys, record, field, limit):
    """Each value at ±its bound is read; the next float beyond it, and 1e300, are one error
    naming the field. A 1e30 m odometry step or a 1e300 m truth once crashed `fgslam run`."""
    for value in (limit, -limit):
        assert getattr(read_log(log_with(tmp_path, {**record, field: value})).records[-1], field) == value
    for value in (up(limit), down(-limit), 1e300):
        path = log_with(tmp_path, {**record, field: value})
        expect_error(path, BAD_LINE, f"field '{field}'", "beyond", "corrupted", partial_records=3)
        expect_cli_error(path, BAD_LINE, capsys, f"field '{field}'")


@pytest.mark.parametrize("pose", [[up(COORDINATE_M), 0.0, 0.0], [0.0, -1e300, 0.0], [0.0, 0.0, up(WORLD_ANGLE_RAD)]])
def test_start_pose_is_bounded(tmp_path, pose):
    path = write(tmp_path / "h.jsonl", {**HDR, "start": {**HDR["start"], "pose": pose}})
    expect_error(path, 1, "start.pose", "beyond")


MAX_VAR, MAX_HEADING_VAR, MIN_EIG = HIGH_M**2, HIGH_RAD**2, LOW_M**2
COVARIANCE_BOUNDS = [
    ((MIN_EIG, MIN_EIG, MIN_EIG), (down(MIN_EIG), 1e-4, 1e-4), "nearly singular"),
    ((1e-4, 1e-4, MIN_EIG), (1e-300, 1e-300, 1e-300), "nearly singular"),
    ((MAX_VAR, MAX_VAR, 1e-4), (up(MAX_VAR), 1e-4, 1e-4), "above 1e+06"),
    ((1e-4, MAX_VAR, 1e-4), (1e-4, 1e300, 1e-4), "above 1e+06"),
    ((1e-4, 1e-4, MAX_HEADING_VAR), (1e-4, 1e-4, up(MAX_HEADING_VAR)), "dtheta a variance"),
]


@pytest.mark.parametrize("inside, outside, words", COVARIANCE_BOUNDS)
def test_covariance_bounds(tmp_path, capsys, inside, outside, words):
    assert read_log(log_with(tmp_path, cov(inside))).records[-1].covariance[2][2] == inside[2]
    path = log_with(tmp_path, cov(outside))
    expect_error(path, BAD_LINE, "'covariance'", words, partial_records=3)
    expect_cli_error(path, BAD_LINE, capsys, "'covariance'", words)


def test_nearly_singular_covariance_off_the_axes(tmp_path):
    """Positive definite, sane diagonal, but certain along dx = dy: the smallest eigenvalue counts."""
    a = 1e-4
    eps = 1e-14
    m = [[a, a - eps, 0.0], [a - eps, a, 0.0], [0.0, 0.0, a]]
    expect_error(log_with(tmp_path, {**ODO, "covariance": m}), BAD_LINE, "nearly singular", "smallest eigenvalue")


@pytest.mark.parametrize(
    "sigma, words",
    [
        ([1e-3, 1e-3, up(HIGH_RAD)], "rad for theta"),
        ([up(HIGH_M), 1e-3, 1e-3], "m for x, y"),
        ([down(LOW_M), 1e-3, 1e-3], "m for x, y"),
        ([1e-3, 1e-3, 1e300], "rad for theta"),
    ],
)
def test_start_sigma_bounds(tmp_path, sigma, words):
    path = write(tmp_path / "h.jsonl", {**HDR, "start": {**HDR["start"], "sigma": sigma}})
    expect_error(path, 1, "start.sigma", words)


@pytest.mark.parametrize("sigma", [[LOW_M, LOW_M, LOW_RAD], [HIGH_M, HIGH_M, HIGH_RAD]])
def test_start_sigma_at_the_bounds_is_read(tmp_path, sigma):
    path = write(tmp_path / "h.jsonl", {**HDR, "start": {**HDR["start"], "sigma": sigma}})
    assert read_log(path).header.start_sigma == tuple(sigma)


# Just inside every bound, the estimators run (EKF, iSAM2 with covariances, the batch solve,
# graph.g2o): the bounds keep them working, not only the reader.
ARENA = "data/arena_octagon.jsonl"


def arena_prefix(change):
    """The first 300 lines of the octagon log with one record changed by ``change``."""
    lines = [json.loads(line) for line in open(ARENA, encoding="utf-8").read().splitlines()[:300]]
    kind = change[0]
    index = 0 if kind == "header" else next(i for i, d in enumerate(lines) if i > 20 and d["type"] == kind)
    lines[index] = change[1](lines[index])
    return lines


ESTIMATOR_CASES = {
    "landmark_id 2^31-1": ("observation", lambda d: {**d, "landmark_id": MAX_ID}),
    "sigma_range_m 1 km": ("observation", lambda d: {**d, "sigma_range_m": HIGH_M}),
    "sigma_range_m 1 µm": ("observation", lambda d: {**d, "sigma_range_m": LOW_M}),
    "sigma_bearing_rad 2π": ("observation", lambda d: {**d, "sigma_bearing_rad": HIGH_RAD}),
    "sigma_bearing_rad 1 µrad": ("observation", lambda d: {**d, "sigma_bearing_rad": LOW_RAD}),
    "sigma_tag_yaw_rad 1 µrad": ("observation", lambda d: {**d, "sigma_tag_yaw_rad": LOW_RAD}),
    "range_m just above half the sensor minimum": ("observation", lambda d: {**d, "range_m": 0.076}),
    "bearing π": ("observation", lambda d: {**d, "bearing_rad": math.pi}),
    "covariance at the smallest eigenvalue": ("odometry", lambda d: {**d, "covariance": diagonal((MIN_EIG,) * 3)}),
    "covariance at the largest variances": (
        "odometry", lambda d: {**d, "covariance": diagonal((MAX_VAR, MAX_VAR, MAX_HEADING_VAR))}),
    "covariance mixed": ("odometry", lambda d: {**d, "covariance": diagonal((MAX_VAR, MIN_EIG, MAX_HEADING_VAR))}),
    "start.sigma 1 µm": ("header", lambda d: {**d, "start": {**d["start"], "sigma": [LOW_M, LOW_M, LOW_RAD]}}),
}


@pytest.mark.parametrize("case", sorted(ESTIMATOR_CASES))
def test_estimators_run_just_inside_the_bounds(tmp_path, capsys, case):
    path = write(tmp_path / "run.jsonl", *arena_prefix(ESTIMATOR_CASES[case]))
    assert read_log(path).rejected == ()  # used, not left out
    code = main(["run", str(path), "--out", str(tmp_path / "out"), "--no-report"])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert "Traceback" not in out + err


# ------------------------------------------------------------------ line numbers and the good prefix


def test_non_utf8_byte_on_line_1001_keeps_the_1000_good_lines(tmp_path, capsys):
    path = tmp_path / "run.jsonl"
    good = [format_line(HEADER)] + [format_line(TruthPose(0.001 * k, 0.0, 0.0, 0.0)) for k in range(999)]
    path.write_bytes(("\n".join(good) + "\n").encode() + b'{"type": "truth_pose", "x_m": "\xff"}\n' + b"{}\n")
    err = expect_error(path, 1001, "not UTF-8", "byte 0xff at column 32", partial_records=999)
    assert err.partial.header == HEADER
    stderr = expect_cli_error(path, 1001, capsys, "not UTF-8")
    assert "head -n 1000" in stderr


def test_non_utf8_on_the_first_line_has_no_prefix(tmp_path):
    path = tmp_path / "bin.jsonl"
    path.write_bytes(b"\x89PNG\r\n\x1a\n\x00\x00")
    assert expect_error(path, 1, "not UTF-8").partial is None


def test_non_utf8_last_line_without_newline(tmp_path):
    good = "\n".join([format_line(HEADER), *map(format_line, GOOD)]) + "\n"
    path = tmp_path / "cut.jsonl"
    path.write_bytes(good.encode() + '{"type": "truth_pose", "x_m": "é'.encode()[:-1])  # cut inside a character
    log = read_log(path)
    assert log.records == tuple(GOOD) and "cut off" in log.truncated
    path.write_bytes(good.encode() + b'{"type": "truth_pose", "x_m": "\xff"}')  # complete: an error
    expect_error(path, BAD_LINE, "not UTF-8")


def test_crlf_line_endings_and_byte_order_mark(tmp_path):
    path = tmp_path / "crlf.jsonl"
    path.write_bytes(("\r\n".join([format_line(HEADER), *map(format_line, GOOD)]) + "\r\n").encode())
    assert read_log(path).records == tuple(GOOD)
    path.write_bytes(b"\xef\xbb\xbf" + format_line(HEADER).encode() + b"\n")
    expect_error(path, 1, "byte-order mark")


# ------------------------------------------------------------------ used silently before


def limits_log(tmp_path, ranges, sigma=0.05):
    """Header with limits 0.15..3.5 m; one observation per range, then a good odometry."""
    lines = [format_line(HEADER), *map(format_line, GOOD)]
    lines += [json.dumps(obs(range_m=r, sigma_range_m=sigma, stamp_s=0.2)) for r in ranges]
    lines.append(format_line(Odometry(0.3, 0.1, 0.0, 0.0, COV)))
    return write(tmp_path / "limits.jsonl", *lines)


def test_ranges_outside_the_sensor_limits_are_rejected_and_counted(tmp_path, capsys):
    ranges = [2.4] * 1000 + [1e-6] + [2.4] * 1000 + [40.0, 0.0751, 0.07]
    path = limits_log(tmp_path, ranges, sigma=0.05)
    log = read_log(path)
    kept = [r for r in log.records if isinstance(r, Observation)]
    assert len(kept) == 1 + 2001  # GOOD's, the good ones and 0.0751 (within half the minimum)
    assert [(r.line, r.record.range_m) for r in log.rejected] == [(1005, 1e-6), (2006, 40.0), (2008, 0.07)]
    assert all(o.range_m not in (1e-6, 40.0, 0.07) for s in log.steps() for o in s.observations)
    summary = log.rejection_summary()
    assert "3 observations rejected and kept from the estimators" in summary
    assert "2 with range_m below the sensor's min_range_m (lines 1005, ..., 2008)" in summary
    assert "1 with range_m above the sensor's max_range_m (line 2006)" in summary
    code, out, err = validate(path, capsys)
    assert code == 0
    assert f"note: {summary}" in out
    assert f"{path}:1005: range_m 1e-06 is below the header's sensor.min_range_m 0.15" in out


@pytest.mark.parametrize(
    "sigma, inside, outside",
    [
        (0.01, 0.15 - 0.05, down(0.15 - 0.05)),  # 5σ below the minimum
        (0.05, 0.075, down(0.075)),  # half the minimum when 5σ is more
        (0.01, 3.5 + 0.05, up(3.5 + 0.05)),  # 5σ above the maximum
    ],
)
def test_sensor_limit_edges(tmp_path, sigma, inside, outside):
    assert not read_log(limits_log(tmp_path, [inside], sigma)).rejected
    assert [r.record.range_m for r in read_log(limits_log(tmp_path, [outside], sigma)).rejected] == [outside]


def test_rejections_are_kept_in_the_partial_log(tmp_path):
    path = write(tmp_path / "p.jsonl", format_line(HEADER), obs(range_m=1e-3), '{"type": "wheel"}')
    err = expect_error(path, 3, "unknown record type")
    assert err.partial.records == () and len(err.partial.rejected) == 1


@pytest.mark.parametrize(
    "sensor, words",
    [
        ({"kind": "k", "min_range_m": "0.15"}, "'sensor.min_range_m' must be a number"),
        ({"kind": "k", "max_range_m": True}, "'sensor.max_range_m' must be a number"),
        ({"kind": "k", "min_range_m": -1}, "'sensor.min_range_m' must be a number of metres ≥ 0"),
        ({"kind": "k", "min_range_m": 3.0, "max_range_m": 1.0}, "must be below 'sensor.max_range_m'"),
        ({"kind": "k", "max_range_m": 10**400}, "'sensor.max_range_m' must be a number of metres"),  # was OverflowError
    ],
)
def test_bad_sensor_limits_in_the_header(tmp_path, sensor, words):
    expect_error(write(tmp_path / "h.jsonl", {**HDR, "sensor": sensor}), 1, words)


@pytest.mark.parametrize("version", [True, 1.0, "1", None, [1]])
def test_version_must_be_the_integer_1(tmp_path, capsys, version):
    path = write(tmp_path / "v.jsonl", {**HDR, "version": version})
    expect_error(path, 1, "'version' must be the integer 1")
    expect_cli_error(path, 1, capsys, "'version' must be the integer 1")


def test_complete_last_line_with_a_typo_and_no_newline_is_an_error(tmp_path, capsys):
    path = log_with(tmp_path, obs(rnage_m=2.0), final_newline=False)
    expect_error(path, BAD_LINE, "unknown field(s) rnage_m", partial_records=3)
    expect_cli_error(path, BAD_LINE, capsys, "unknown field(s) rnage_m")
    path = log_with(tmp_path, obs(range_m=-2.0), final_newline=False)
    expect_error(path, BAD_LINE, "'range_m' must be > 0")


@pytest.mark.parametrize("cut", [1, 10, 40])
def test_only_invalid_json_at_the_very_end_is_cut_off(tmp_path, capsys, cut):
    text = json.dumps(obs())
    path = log_with(tmp_path, text[:-cut], final_newline=False)
    log = read_log(path)
    assert log.records == tuple(GOOD) and f"{path}:{BAD_LINE}: the last line is cut off" in log.truncated
    assert validate(path, capsys)[0] == 0
    path = log_with(tmp_path, text[:-cut], final_newline=True)  # with a newline it is not cut off
    expect_error(path, BAD_LINE, "not valid JSON")
    path = write(tmp_path / "mid.jsonl", format_line(HEADER), text[:-cut], format_line(GOOD[0]), final_newline=False)
    expect_error(path, 2, "not valid JSON")


# ------------------------------------------------------------------ property: nothing but LogFormatError


def read_or_format_error(path) -> None:
    try:
        read_log(path)
    except LogFormatError as err:
        assert str(err).startswith(f"{path}:{err.line}: ") and "\n" not in str(err)


json_values = st.recursive(
    st.one_of(
        st.none(), st.booleans(), st.text(max_size=6),
        st.integers(), st.integers(-(10**500), 10**500), st.sampled_from([2**56, 2**63, -1, 0, 10**400]),
        st.floats(allow_nan=False, allow_infinity=False),
        st.sampled_from([0.0, -0.0, 1e-300, 1e300, 5e-324, math.pi, 1e6, 1e-6, 35.0]),
    ),
    lambda inner: st.one_of(st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=6), inner, max_size=4)),
    max_leaves=12,
)
TEMPLATES = [HDR, OBS, ODO, json.loads(format_line(GOOD[0])),
             {"type": "truth_landmark", "landmark_id": 1, "x_m": 0.0, "y_m": 0.0, "height_m": 0.1, "yaw_rad": 0.0},
             {"type": "live_step", "stamp_s": 0.3, "pose_index": 3, "latency_s": 0.001}]


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.binary(max_size=300), after_header=st.booleans())
def test_random_bytes_never_raise_anything_but_log_format_error(tmp_path, data, after_header):
    path = tmp_path / "bytes.jsonl"
    path.write_bytes((format_line(HEADER).encode() + b"\n" if after_header else b"") + data)
    read_or_format_error(path)


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(value=json_values, line=st.sampled_from([1, 2]), newline=st.booleans())
def test_random_json_lines_never_raise_anything_but_log_format_error(tmp_path, value, line, newline):
    lines = [format_line(HEADER), json.dumps(value)] if line == 2 else [json.dumps(value)]
    read_or_format_error(write(tmp_path / "value.jsonl", *lines, final_newline=newline))


@settings(max_examples=600, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_random_field_values_never_raise_anything_but_log_format_error(tmp_path, data):
    """A valid header or record with one field (or one nested field) replaced by random JSON."""
    template = data.draw(st.sampled_from(TEMPLATES))
    d = json.loads(json.dumps(template))
    target = d
    key = data.draw(st.sampled_from(sorted(d) + ["extra"]))
    if key in ("start", "sensor", "covariance") and data.draw(st.booleans()):  # one level down
        target = d[key]
        key = data.draw(st.sampled_from(sorted(target) if isinstance(target, dict) else range(len(target))))
    target[key] = data.draw(json_values)
    lines = [json.dumps(d)] if template is HDR else [format_line(HEADER), json.dumps(d)]
    read_or_format_error(write(tmp_path / "field.jsonl", *lines, final_newline=data.draw(st.booleans())))
