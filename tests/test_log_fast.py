"""The reader's fast path (slamio.log.fast) against its slow path (slamio.log.parse): on any
line, what the fast path accepts the slow path accepts, as the same record — the slow path,
the field-by-field checks every message comes from, is the reference. Lines are generated
around every bound, with nulls, bools, huge integers, NaN tokens, keys given twice (also
as escapes), unknown fields, odd number spellings and covariances at the edge of singular.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import slamio.log.fields as F
import slamio.log.records3d as R3
from slamio.log import EVENT_KINDS, EVENT_SIDES, read_log
from slamio.log.fast import PLANAR_KINDS, KINDS_3D, SPEC, FastDecoder
from slamio.log.fields import _BadLine
from slamio.log.parse import parse_record
from slamio.log.read import _decode, _loads

DECODERS = {False: FastDecoder(False), True: FastDecoder(True)}

#: Every bound of the format, to draw values on, just inside and just outside it.
EDGES = [F.STAMP_S, F.MAX_ID, F.MAX_POSE_INDEX, F.COORDINATE_M, F.WORLD_ANGLE_RAD, F.INCREMENT_M, F.INCREMENT_RAD,
         math.pi, *F.SIGMA_LENGTH_M, *F.SIGMA_ANGLE_RAD, *F.RANGE_M, F.MAX_POSITION_VARIANCE_M2,
         F.MAX_HEADING_VARIANCE_RAD2, F.MIN_COVARIANCE_EIGENVALUE, R3.MAX_PIXEL_PX, *R3.SIGMA_PIXEL_PX, R3.MAX_DT_S,
         R3.MAX_SPEED_MPS, R3.MAX_TWIST_VARIANCE, R3.MIN_TWIST_EIGENVALUE, R3.MAX_PIXEL_VARIANCE_PX2,
         R3.MIN_PIXEL_EIGENVALUE_PX2, 1.0, 0.0]


def _near(edge: float):
    return st.sampled_from([edge, -edge, math.nextafter(edge, math.inf), math.nextafter(edge, -math.inf)])


class Raw(str):
    """A number token written as is (``-0``, ``1E5``, ``NaN``, a 400-digit integer)."""


numbers = st.one_of(
    st.floats(allow_nan=False, allow_infinity=False),
    st.floats(-10.0, 10.0),
    st.integers(-3, 3),
    st.integers(0, 2**64),
    st.sampled_from(EDGES).flatmap(_near),
    st.sampled_from([Raw("-0"), Raw("1E2"), Raw("1e-400"), Raw("1e400"), Raw("NaN"), Raw("-Infinity"),
                     Raw("1" * 400), Raw("0.1e1"), Raw("2.0e-1")]),
)
oddities = st.sampled_from([None, True, False, "1.0", [], {}, [1.0, 2.0, 3.0]])


def covariances(n: int):
    """Symmetric matrices from L·Lᵀ (eigenvalues down to ~1e-13) and their 1-ulp asymmetric
    or diagonal-shifted neighbours; rows of numbers."""
    def build(seed: int, scale_exp: float, small_exp: float, skew: bool) -> list:
        rng = np.random.default_rng(seed)
        q, _ = np.linalg.qr(rng.normal(size=(n, n)))
        eig = 10.0 ** rng.uniform(small_exp, max(scale_exp, small_exp), size=n)
        eig[0] = 10.0 ** small_exp
        m = q @ np.diag(eig) @ q.T
        m = (m + m.T) / 2
        rows = [[float(v) for v in row] for row in m]
        if skew:
            rows[0][1] = math.nextafter(rows[1][0], math.inf)
        return rows
    return st.builds(build, st.integers(0, 2**32 - 1), st.floats(-4.0, 6.5), st.floats(-13.0, -2.0), st.booleans())


def field_values(name: str):
    if name == "covariance":
        return st.one_of(covariances(3), covariances(6), st.lists(st.lists(numbers, min_size=3, max_size=3),
                                                                     min_size=3, max_size=3))
    if name == "covariance_px2":  # the stereo pixel covariance, 4×4 (or a wrong size)
        return st.one_of(covariances(4), covariances(4), covariances(3),
                         st.lists(st.lists(numbers, min_size=4, max_size=4), min_size=4, max_size=4), oddities)
    if name in ("v_mps", "w_radps"):
        return st.lists(numbers, min_size=2, max_size=4)
    if name in ("kind", "side"):  # an event's words: right ones mostly, near misses and other types too
        words = EVENT_KINDS if name == "kind" else EVENT_SIDES
        return st.one_of(st.sampled_from(words), st.sampled_from(words), oddities, numbers,
                         st.sampled_from(["Bump", "bump ", "", "wheel_drop", "cliff\u0000", "both:"]))
    return st.one_of(numbers, numbers, oddities)


@st.composite
def record_lines(draw) -> tuple[bool, str]:
    """A log line of one record type (mostly right, often slightly wrong) and its log's dimension."""
    kind = draw(st.sampled_from(sorted(SPEC)))
    is_3d = draw(st.booleans()) if kind == "live_step" else kind in KINDS_3D
    pairs: list[tuple[str, object]] = [("type", kind)]
    for name, _, required in SPEC[kind][1]:
        if required or draw(st.booleans()):
            pairs.append((name, draw(field_values(name))))
    if draw(st.integers(0, 9)) == 0:
        pairs.append((draw(st.sampled_from(["extra", "range_m", "landmark_id", "type", "stamp_s"])),
                      draw(st.one_of(numbers, oddities))))
    order = draw(st.permutations(range(len(pairs))))
    pairs = [pairs[i] for i in order]
    escape = draw(st.booleans())
    return is_3d, "{" + ", ".join(f"{_key(k, escape)}: {_value(v)}" for k, v in pairs) + "}"


def _key(name: str, escape: bool) -> str:
    return json.dumps(name).replace("_", "\\u005f") if escape else json.dumps(name)


def _value(v: object) -> str:
    if isinstance(v, Raw):
        return str(v)
    if isinstance(v, list):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    return json.dumps(v)


def slow(line: str, is_3d: bool):
    """The slow path's record, or None when it refuses the line (or it is of the other dimension)."""
    try:
        d = _loads(_decode(line.encode(), 2))
        if d.get("type") not in (KINDS_3D if is_3d else PLANAR_KINDS):
            return None
        return parse_record(d)
    except _BadLine:
        return None


def _same(a, b) -> bool:
    """Equal field by field, to the type and the sign of zero (``==`` says 0.0 == -0 == 0)."""
    return type(a) is type(b) and repr(a) == repr(b) and all(
        type(getattr(a, f)) is type(getattr(b, f)) for f in a.__dataclass_fields__)


@settings(max_examples=3000, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(record_lines())
def test_what_the_fast_path_accepts_the_slow_path_accepts_as_the_same_record(case):
    is_3d, line = case
    fast = DECODERS[is_3d].record(line.encode())
    if fast is not None:
        reference = slow(line, is_3d)
        assert reference is not None, line
        assert _same(fast, reference), (line, fast, reference)


@pytest.mark.parametrize("line", [
    '{"type": "observation", "stamp_s": 1, "landmark_id": null, "landmark_id": null, "range_m": 1, "sigma_range_m": 0.1}',
    '{"type": "observation", "stamp_s": 1, "landmark_id": 3, "range_m": 1, "range_m": 2, "sigma_range_m": 0.1}',
    '{"type": "observation", "stamp_s": 1, "landmark_id": 3, "range\\u005fm": 1, "range_m": 1, "sigma_range_m": 0.1}',
    '{"type": "observation", "type": "observation", "stamp_s": 1, "landmark_id": 3, "range_m": 1, "sigma_range_m": 0.1}',
    '{"type": "truth_pose", "stamp_s": 1, "x_m": 1, "y_m": 2, "theta_rad": NaN}',
    '{"type": "truth_pose", "stamp_s": true, "x_m": 1, "y_m": 2}',
    '{"type": "truth_landmark", "landmark_id": 1.0, "x_m": 1, "y_m": 2}',
    '{"type": "odometry", "stamp_s": 1, "dx_m": 0, "dy_m": 0, "dtheta_rad": 0, '
    '"covariance": [[1e-12, 0, 0], [0, 1, 0], [0, 0, 1]]}',
    '{"type": "event", "stamp_s": 1, "kind": "bump", "pose_index": 2, "side": "left", "side": "right"}',
    '{"type": "event", "stamp_s": 1, "kind": "bump", "pose_index": 2.0}',
    '{"type": "event", "stamp_s": 1, "kind": "bump:", "pose_index": 2}',
])
def test_lines_the_fast_path_leaves_to_the_slow_path(line):
    """Keys twice (also one spelled with an escape), NaN, a bool or a float where an integer
    goes, a covariance at the smallest eigenvalue allowed: the slow path decides."""
    assert DECODERS[False].record(line.encode()) is None


@pytest.mark.parametrize("path", ["data/arena_octagon.jsonl", "data/arena_square.jsonl"])
def test_the_fast_path_reads_every_record_of_a_real_log_as_the_slow_path(path):
    """Not a path that refuses everything: each record of the shipped logs goes through it."""
    with open(path, "rb") as f:
        lines = f.read().splitlines()[1:]
    for raw in lines:
        record = DECODERS[False].record(raw)
        assert record is not None and _same(record, slow(raw.decode(), False)), raw
    assert len(read_log(path).records) == len(lines)


@pytest.mark.parametrize("line", [
    '{"type": "observation", "stamp_s": 1, "landmark_id": null, "range_m": 1, "sigma_range_m": 0.1}',
    '{"type": "observation", "stamp_s": 1, "landmark_id": 3, "range_m": 1, "sigma_range_m": 0.1, "height_m": null, '
    '"bearing_rad": 0.5, "sigma_bearing_rad": 0.01, "tag_yaw_rad": null}',
    '{"type": "truth_pose", "stamp_s": 1, "x_m": 1, "y_m": 2, "theta_rad": null}',
])
def test_a_line_with_an_explicit_null_stays_on_the_fast_path(line):
    """An unknown landmark (``landmark_id`` null) or an optional field written as null: read by
    the fast path (after its count of keys fails on the null), as the slow path reads it."""
    record = DECODERS[False].record(line.encode())
    assert record is not None and _same(record, slow(line, False)), line


@pytest.mark.parametrize("noise", [
    '"sigma_px": 0.7',
    '"covariance_px2": [[0.04, 0, 0.01, 0], [0, 0.25, 0, 0.24], [0.01, 0, 0.04, 0], [0, 0.24, 0, 0.25]]',
    '"sigma_px": null, "covariance_px2": [[1, 0, 0, 0], [0, 1, 0, 0.5], [0, 0, 1, 0], [0, 0.5, 0, 1]]',
])
def test_the_fast_path_reads_a_stereo_observations_sigma_or_covariance_as_the_slow_path(noise):
    """Either noise of a stereo observation goes through the fast path (not only the slow one)."""
    line = ('{"type": "stereo_observation", "stamp_s": 1, "track_id": 4, "u_left_px": 100.5, "v_left_px": 80, '
            f'"u_right_px": 90, "v_right_px": 80.25, {noise}}}')
    record = DECODERS[True].record(line.encode())
    assert record is not None and _same(record, slow(line, True)), line


@pytest.mark.parametrize("noise", [
    '"sigma_px": 0.7, "covariance_px2": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]',
    '"covariance_px2": [[1, 0, 0, 0], [0, 1, 0, 1], [0, 0, 1, 0], [0, 1, 0, 1]]',
    '"covariance_px2": [[1, 0, 0, 0], [0, 1, 0, 0.5], [0, 0, 1, 0], [0, 0.4, 0, 1]]',
    '"sigma_px": null',
])
def test_stereo_noise_lines_the_fast_path_leaves_to_the_slow_path_which_refuses_them(noise):
    """Both noises, a singular or asymmetric covariance, no noise at all: refused by both."""
    line = ('{"type": "stereo_observation", "stamp_s": 1, "track_id": 4, "u_left_px": 100.5, "v_left_px": 80, '
            f'"u_right_px": 90, "v_right_px": 80.25, {noise}}}')
    assert DECODERS[True].record(line.encode()) is None and slow(line, True) is None
