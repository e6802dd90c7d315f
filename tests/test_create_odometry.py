"""slamio.create.odometry: encoder wraparound, the Create 1 truncation workaround, records."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from slamio.create.odometry import (
    CREATE2_MM_PER_COUNT,
    WHEEL_BASE_M,
    Create1Odometry,
    Create2Odometry,
    OdometryNoise,
    counts_delta,
    counts_to_m,
    default_noise,
    integrate_records,
    odometry_record,
    quantisation_floor,
    truncation_interval,
    wheel_reading,
    within_reading,
)
from slamio.errors import FgslamError
from slamio.geometry import arc_increment
from slamio.log import Header, read_log, write_log


def test_counts_per_millimetre_from_the_spec():
    assert CREATE2_MM_PER_COUNT == pytest.approx(math.pi * 72.0 / 508.8)
    assert counts_to_m(508.8) == pytest.approx(math.pi * 0.072)  # one wheel turn


@pytest.mark.parametrize("new, old, delta", [(3, 65533, 6), (65533, 3, -6), (100, 90, 10), (0, 0, 0),
                                             (32767, 0, 32767), (0, 1, -1)])
def test_counts_delta_across_the_wrap(new, old, delta):
    assert counts_delta(new, old) == delta


@settings(max_examples=200, derandomize=True)
@given(st.integers(0, 65535), st.integers(-32768, 32767))
def test_counts_delta_inverts_uint16_addition(start, delta):
    assert counts_delta((start + delta) % 65536, start) == delta


def test_wheel_reading_is_the_specs_formula():
    assert wheel_reading(0.1, 0.1) == (0.1, 0.0)
    distance, angle = wheel_reading(-0.05, 0.05)
    assert distance == 0.0 and angle == pytest.approx(0.1 / WHEEL_BASE_M)


def test_create2_straight_turn_and_wrap():
    odo = Create2Odometry()
    assert odo.update(65000, 100) == (0.0, 0.0)  # first reading only sets the reference
    d, a = odo.update((65000 + 1000) % 65536, 1100)  # both wheels +1000 counts, left wraps
    assert d == pytest.approx(1000 * CREATE2_MM_PER_COUNT / 1000) and a == pytest.approx(0.0)
    rec = odo.take(1.0)
    assert (rec.dx_m, rec.dy_m, rec.dtheta_rad) == pytest.approx((d, 0.0, 0.0))
    assert rec.distance_m == pytest.approx(d) and rec.angle_rad == pytest.approx(0.0)
    odo.update((65000 + 1000 - 200) % 65536, 1300)  # turn in place: left −200, right +200
    rec = odo.take(2.0)
    assert rec.distance_m == pytest.approx(0.0, abs=1e-12)
    assert rec.angle_rad == pytest.approx(2 * 200 * CREATE2_MM_PER_COUNT / 1000 / WHEEL_BASE_M)


def test_create2_record_is_the_arc_of_the_summed_readings():
    odo = Create2Odometry()
    odo.update(0, 0)
    for k in range(1, 11):
        odo.update(10 * k, 14 * k)  # a gentle left arc, 10 frames
    rec = odo.take(0.15)
    distance = 0.5 * (100 + 140) * CREATE2_MM_PER_COUNT / 1000
    angle = (140 - 100) * CREATE2_MM_PER_COUNT / 1000 / WHEEL_BASE_M
    assert (rec.dx_m, rec.dy_m, rec.dtheta_rad) == pytest.approx(arc_increment(distance, angle))
    assert np.allclose(rec.covariance, default_noise("create2").covariance(distance, angle, 1))


# --------------------------------------------------------------------------- Create 1


@pytest.mark.parametrize("reading, interval", [(3, (3, 4)), (-3, (-4, -3)), (0, (-1, 1))])
def test_truncation_interval(reading, interval):
    assert truncation_interval(reading) == interval


def test_within_reading_clamps_the_prediction():
    assert within_reading(3.4, 3) == 3.4
    assert within_reading(5.0, 3) == 4.0
    assert within_reading(0.7, 0) == 0.7
    assert within_reading(-2.0, 0) == -1.0


def _create1_firmware(true_deg_per_read):
    """What a Create 1 reports: the angle since the last read, truncated, remainder lost."""
    return [int(a) for a in true_deg_per_read]


def test_create1_slow_turn_reads_zero_but_the_workaround_recovers_it():
    rate_deg_s, period_s, n = 30.0, 0.015, 200  # 30°/s polled every 15 ms: 0.45° per read
    readings = _create1_firmware([rate_deg_s * period_s] * n)
    assert set(readings) == {0}  # the pitfall: the robot reports no turn at all
    odo = Create1Odometry()
    wheel_mm_s = math.radians(rate_deg_s) * 1000 * WHEEL_BASE_M / 2
    odo.start(0.0)
    odo.command(-wheel_mm_s, wheel_mm_s, 0.0)
    for k, r in enumerate(readings, start=1):
        odo.update(0, r, k * period_s)
    rec = odo.take(n * period_s)
    assert rec.angle_rad == pytest.approx(math.radians(rate_deg_s * period_s * n), rel=1e-9)


def test_create1_reading_bounds_a_wrong_prediction_to_one_degree_per_read():
    """The wheels turn 20 % slower than commanded: the estimate may be off by at most 1° per
    read, and reading every 0.1 s keeps it inside each reading's interval."""
    true_deg_per_read = [4.6 * 0.8] * 10  # commanded 46°/s, really 36.8°/s, read every 0.1 s
    readings = _create1_firmware(true_deg_per_read)
    odo = Create1Odometry()
    wheel_mm_s = math.radians(46.0) * 1000 * WHEEL_BASE_M / 2
    odo.start(0.0)
    odo.command(-wheel_mm_s, wheel_mm_s, 0.0)
    estimates = [odo.update(0, r, 0.1 * k)[1] for k, r in enumerate(readings, start=1)]
    for estimate, truth in zip(estimates, true_deg_per_read):
        assert abs(math.degrees(estimate) - truth) < 1.0
    naive_error = sum(true_deg_per_read) - sum(readings)
    ours = abs(math.degrees(sum(estimates)) - sum(true_deg_per_read))
    assert ours < naive_error  # better than trusting the truncated readings


def test_create1_lost_answer_uses_the_prediction_with_a_larger_covariance():
    odo = Create1Odometry()
    odo.start(0.0)
    odo.command(100.0, 100.0, 0.0)
    odo.update(10, 0, 0.1)
    normal = odo.take(0.1)
    d, a = odo.lost(0.2)
    assert d == pytest.approx(0.01) and a == 0.0 and odo.lost_reads == 1
    lost = odo.take(0.2)
    assert lost.covariance[0][0] > normal.covariance[0][0]


def test_create1_unread_prediction():
    odo = Create1Odometry()
    odo.start(0.0)
    odo.command(100.0, 100.0, 0.0)
    assert odo.unread(0.05) == pytest.approx((0.005, 0.0))


# --------------------------------------------------------------------------- covariance


def test_covariance_is_symmetric_definite_and_grows_like_a_random_walk():
    noise = default_noise("create2")
    c0 = np.array(noise.covariance(0.0, 0.0))
    assert np.all(np.linalg.eigvalsh(c0) > 0)  # standing still is still definite
    a = np.array(noise.covariance(0.3, 0.2))
    b = np.array(noise.covariance(0.7, 0.1))
    whole = np.array(noise.covariance(1.0, 0.3))
    assert np.allclose(a + b - c0, whole)  # variances add up with distance and angle
    assert np.allclose(whole, whole.T)


def test_noise_model_validation():
    floor = quantisation_floor("create1")
    with pytest.raises(FgslamError, match="positive semi-definite"):
        OdometryNoise(np.diag([-1.0, 1.0, 1.0]), np.eye(3), floor)
    with pytest.raises(FgslamError, match="floor must be positive definite"):
        OdometryNoise(np.eye(3), np.eye(3), np.zeros((3, 3)))
    with pytest.raises(FgslamError, match="unknown Create model"):
        quantisation_floor("roomba")


def test_records_are_valid_log_records(tmp_path):
    noise = default_noise("create1")
    records = [odometry_record(0.1 * k, 0.02, 0.05, noise.covariance(0.02, 0.05, 3)) for k in range(1, 6)]
    header = Header(0.0, (0.0, 0.0, 0.0), (1e-3,) * 3, {"name": "test"}, {"kind": "none"},
                    {"odometry": noise.header_dict(), "observation": {}})
    path = tmp_path / "odo.jsonl"
    write_log(path, header, records)
    log = read_log(path)
    assert log.records == tuple(records)
    pose, length = integrate_records(log.records)
    assert length == pytest.approx(0.1)
    assert pose[2] == pytest.approx(0.25)
