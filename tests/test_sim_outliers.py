"""The simulator's outliers: zero outliers changes nothing, outliers change only range and
bearing of some readings, the requested fraction is what comes out, and misdetections stay
within the sensor's limits (checked against an independent visibility test)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from sim_records import SMALL, in_view, of_type, sim, truth_map
from slamio.errors import FgslamError
from slamio.geometry import wrap_angle
from slamio.log import Observation, group_steps, write_log
from slamio.sim import simulate


def test_zero_outliers_is_byte_identical_to_no_argument(tmp_path):
    for scenario, kwargs in SMALL:
        header, records = sim(scenario, 9, **kwargs)
        header0, records0 = simulate(scenario, 9, outliers=0.0, **kwargs)
        assert header0 == header and "outliers" not in header0.source
        assert tuple(records0) == records
        write_log(tmp_path / "a.jsonl", header, records)
        write_log(tmp_path / "b.jsonl", header0, records0)
        assert (tmp_path / "a.jsonl").read_bytes() == (tmp_path / "b.jsonl").read_bytes()


def test_outliers_change_only_range_and_bearing_of_some_observations():
    header, records = sim("arena-square", 9)
    header_out, records_out = sim("arena-square", 9, outliers=0.2)
    assert header_out.source == {**header.source, "outliers": 0.2}
    assert (header_out.robot, header_out.sensor, header_out.noise) == (header.robot, header.sensor, header.noise)
    assert len(records_out) == len(records)
    changed = 0
    for a, b in zip(records, records_out):
        if isinstance(a, Observation):
            # nothing marks an outlier: same id, same nominal sigmas, same height and tag yaw
            assert (b.stamp_s, b.landmark_id, b.sigma_range_m, b.sigma_bearing_rad, b.tag_yaw_rad) == (
                a.stamp_s, a.landmark_id, a.sigma_range_m, a.sigma_bearing_rad, a.tag_yaw_rad)
            assert b.truth_landmark_id is None
            changed += (a.range_m, a.bearing_rad) != (b.range_m, b.bearing_rad)
        else:
            assert a == b  # trajectory, odometry and truth untouched
    assert changed > 0
    # a larger fraction only adds outliers (documented: one uniform draw per observation)
    _, records_more = sim("arena-square", 9, outliers=0.4)
    for a, b, c in zip(records, records_out, records_more):
        if isinstance(a, Observation) and (a.range_m, a.bearing_rad) != (b.range_m, b.bearing_rad):
            assert (c.range_m, c.bearing_rad) == (b.range_m, b.bearing_rad)


def _outlier_scan(header, records, box_sigmas=6.0):
    """Observations more than ``box_sigmas`` off the exact geometry in range or bearing.

    Returns (flags, miss_probability) per observation: ``miss_probability`` is the chance
    that an outlier drawn uniformly over the sensor's range × field of view lands inside
    the ±box_sigmas box around the truth (and so is not flagged), computed from the box's
    overlap with the sensor limits.
    """
    sensor = header.sensor
    fov, r_min, r_max = sensor["fov_rad"], sensor["min_range_m"], sensor["max_range_m"]
    landmarks = truth_map(records)
    flags, miss = [], []
    for step in group_steps(header, records):
        pose = (step.truth.x_m, step.truth.y_m, step.truth.theta_rad)
        for obs in step.observations:
            _, range_m, bearing_rad = in_view(pose, landmarks[obs.landmark_id], sensor)
            dr, db = box_sigmas * obs.sigma_range_m, box_sigmas * obs.sigma_bearing_rad
            flags.append(abs(obs.range_m - range_m) > dr or abs(wrap_angle(obs.bearing_rad - bearing_rad)) > db)
            overlap_r = max(0.0, min(r_max, range_m + dr) - max(r_min, range_m - dr)) / (r_max - r_min)
            overlap_b = max(0.0, min(fov / 2, bearing_rad + db) - max(-fov / 2, bearing_rad - db)) / fov
            miss.append(overlap_r * overlap_b)
    return np.array(flags), np.array(miss)


@pytest.mark.parametrize(
    "scenario, kwargs, p", [("arena-square", {"laps": 4}, 0.1), ("grid", {"landmarks": 40}, 0.1), ("cylinders", {}, 0.3)]
)
def test_outlier_fraction_is_as_requested_and_within_the_sensor_limits(scenario, kwargs, p):
    header, records = sim(scenario, 13, outliers=p, **kwargs)
    flags, miss = _outlier_scan(header, records)
    n = len(flags)
    assert n > 1000
    # Inliers are never 6σ off (P ≈ 4e-9 each); an outlier is flagged unless it fell in the box.
    expected = p * np.sum(1.0 - miss)
    sd = math.sqrt(np.sum(p * (1.0 - miss) * (1.0 - p * (1.0 - miss))))
    assert abs(flags.sum() - expected) < 4.0 * sd, f"{flags.sum()} outliers flagged, expected {expected:.0f} ± {sd:.0f}"
    observations = of_type(records, Observation)
    outliers = [o for o, f in zip(observations, flags) if f]
    sensor = header.sensor
    r = np.array([o.range_m for o in outliers])
    b = np.array([o.bearing_rad for o in outliers])
    assert np.all((r >= sensor["min_range_m"]) & (r <= sensor["max_range_m"]))
    assert np.all(np.abs(b) <= sensor["fov_rad"] / 2)
    # uniform over the limits (the few that fell near the truth are missing: a small bias)
    span = sensor["max_range_m"] - sensor["min_range_m"]
    assert stats.kstest((r - sensor["min_range_m"]) / span, "uniform").pvalue > 1e-4
    assert stats.kstest(b / sensor["fov_rad"] + 0.5, "uniform").pvalue > 1e-4
    # the stated sigmas stay nominal (σ_r at the true range), as for an inlier
    model = header.noise["observation"]
    assert all(o.sigma_bearing_rad == model["sigma_bearing_rad"] for o in outliers)


def test_add_mode_keeps_every_observation_and_adds_misdetections():
    header, records = sim("arena-square", 9, laps=4)
    header_add, records_add = sim("arena-square", 9, laps=4, outliers=0.1, outlier_mode="add")
    assert header_add.source == {**header.source, "outliers": 0.1, "outlier_mode": "add"}
    observations = of_type(records, Observation)
    added = of_type(records_add, Observation)
    # the clean log is a subsequence: each original observation, then maybe one misdetection
    extras, i = [], 0
    for o in added:
        if i < len(observations) and o == observations[i]:
            i += 1
        else:
            prev = observations[i - 1]  # a misdetection directly follows its observation
            assert (o.stamp_s, o.landmark_id, o.sigma_range_m, o.tag_yaw_rad) == (
                prev.stamp_s, prev.landmark_id, prev.sigma_range_m, prev.tag_yaw_rad)
            extras.append(o)
    assert i == len(observations)
    assert [r for r in records_add if not isinstance(r, Observation)] == [
        r for r in records if not isinstance(r, Observation)]
    # a share p of all observations are misdetections (binomial, p/(1-p) per observation)
    q = 0.1 / 0.9
    n = len(observations)
    assert abs(len(extras) - q * n) < 4 * math.sqrt(n * q * (1 - q))
    flags, _ = _outlier_scan(header_add, records_add)
    assert flags.sum() <= len(extras) and flags.sum() > 0.9 * len(extras)


def test_bad_outlier_mode_raises():
    with pytest.raises(FgslamError, match="outlier_mode"):
        simulate("arena-square", 1, outliers=0.1, outlier_mode="swap")
