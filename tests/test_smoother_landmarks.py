"""iSAM2 with richer landmarks: AprilTags as Pose2 landmarks (seed 004) and heights (seed 002).

References: GTSAM's own Pose2 log map for the tag noise propagation (numerical Jacobian),
closed-form information-weighted means for the heights, the simulator's true tag yaws,
and batch Levenberg–Marquardt on the same graph.
"""

from __future__ import annotations

import dataclasses
import math

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import L, T

from fgslam.smoother import batch_solve, tag_noise_covariance, tag_relative_pose
from slamio.geometry import wrap_angle
from slamio.log import Observation, Step, TruthLandmark, group_steps
from builders import run_smoother
from slamio.sim import simulate


@pytest.fixture(scope="module")
def octagon():
    header, records = simulate("arena-octagon", 1)
    truth = {r.landmark_id: r for r in records if isinstance(r, TruthLandmark)}
    return header, group_steps(header, records), truth


def _map_observations(steps, change) -> list[Step]:
    """Steps with every observation passed through ``change(step_index, position, obs)``."""
    return [
        dataclasses.replace(s, observations=tuple(change(s.index, j, o) for j, o in enumerate(s.observations)))
        for s in steps
    ]


@pytest.mark.parametrize("range_m, bearing_rad, yaw_rad", [(1.0, 0.0, math.pi), (2.5, 0.7, -2.0), (0.4, -1.2, 0.3)])
def test_tag_noise_covariance_matches_the_numerical_jacobian_of_gtsams_error(range_m, bearing_rad, yaw_rad):
    obs = Observation(0.0, 1, range_m, bearing_rad, 0.02, 0.01, tag_yaw_rad=yaw_rad, sigma_tag_yaw_rad=0.05)
    measured = tag_relative_pose(obs)

    def error(r, b, y):  # GTSAM's BetweenFactorPose2 error for a relative pose measured as (r, b, y)
        moved = dataclasses.replace(obs, range_m=r, bearing_rad=b, tag_yaw_rad=y)
        return gtsam.Pose2.Logmap(measured.between(tag_relative_pose(moved)))

    h = 1e-6
    J = np.empty((3, 3))
    for i in range(3):
        d = np.zeros(3)
        d[i] = h
        plus = error(range_m + d[0], bearing_rad + d[1], yaw_rad + d[2])
        minus = error(range_m - d[0], bearing_rad - d[1], yaw_rad - d[2])
        J[:, i] = (plus - minus) / (2 * h)
    expected = J @ np.diag([0.02**2, 0.01**2, 0.05**2]) @ J.T
    assert np.allclose(tag_noise_covariance(obs), expected, rtol=1e-6, atol=1e-12)


def test_tags_are_pose2_landmarks_whose_yaw_is_estimated(octagon):
    header, steps, truth = octagon
    smoother = run_smoother(header, steps, tags=True)
    assert smoother.name == "isam2-tags"
    yaws = smoother.landmark_yaws()
    assert yaws and set(yaws) == set(smoother.landmarks())
    values = smoother.estimate()
    assert all(values.exists(T(i)) and not values.exists(L(i)) for i in yaws)
    errors = [wrap_angle(yaw - truth[i].yaw_rad) for i, yaw in yaws.items()]
    assert math.sqrt(np.mean(np.square(errors))) < 0.02  # measured 0.007 rad (σ_yaw per sighting 0.05)
    positions = smoother.landmarks()
    assert max(math.hypot(x - truth[i].x_m, y - truth[i].y_m) for i, (x, y) in positions.items()) < 0.05

    batch = batch_solve(smoother)
    assert abs(smoother.error() - batch.final_error) <= 1e-6 * batch.final_error
    assert batch.landmark_yaws is not None and set(batch.landmark_yaws) == set(yaws)
    assert max(abs(wrap_angle(batch.landmark_yaws[i] - yaws[i])) for i in yaws) < 1e-4


def test_without_tags_the_same_log_has_point_landmarks(octagon):
    header, steps, _ = octagon
    smoother = run_smoother(header, steps[:200])
    assert smoother.name == "isam2" and smoother.landmark_yaws() == {}
    values = smoother.estimate()
    assert all(values.exists(L(i)) for i in smoother.landmarks())


def test_tag_seen_without_its_yaw_adds_bearing_and_range_to_its_centre(octagon):
    header, steps, truth = octagon
    first_seen: set[int] = set()

    def drop_every_other_yaw(k, j, obs):
        if obs.landmark_id not in first_seen:  # the first sighting keeps its yaw: a tag
            first_seen.add(obs.landmark_id)
            return obs
        return obs if (k + j) % 2 else dataclasses.replace(obs, tag_yaw_rad=None, sigma_tag_yaw_rad=None)

    mixed = _map_observations(steps, drop_every_other_yaw)
    smoother = run_smoother(header, mixed, tags=True)
    kinds = {type(smoother.graph().at(i)).__name__ for i in range(smoother.graph().size())}
    assert {"BetweenFactorPose2", "BearingRangeFactorPose2"} <= kinds
    yaws = smoother.landmark_yaws()
    assert max(abs(wrap_angle(y - truth[i].yaw_rad)) for i, y in yaws.items()) < 0.05
    batch = batch_solve(smoother)
    assert abs(smoother.error() - batch.final_error) <= 1e-6 * batch.final_error


def test_a_landmark_first_seen_without_a_yaw_stays_a_point(octagon):
    header, steps, _ = octagon
    first_seen: set[int] = set()
    point_id = steps[0].observations[0].landmark_id if steps[0].observations else None

    def strip_first_sighting_of_one(k, j, obs):
        nonlocal point_id
        if point_id is None:
            point_id = obs.landmark_id
        if obs.landmark_id == point_id and point_id not in first_seen:
            first_seen.add(point_id)
            return dataclasses.replace(obs, tag_yaw_rad=None, sigma_tag_yaw_rad=None)
        return obs

    changed = _map_observations(steps[:300], strip_first_sighting_of_one)
    smoother = run_smoother(header, changed, tags=True)
    assert point_id in smoother.landmarks() and point_id not in smoother.landmark_yaws()
    assert smoother.estimate().exists(L(point_id))


def test_robust_tags_name_andrun_smoother(octagon):
    header, steps, _ = octagon
    smoother = run_smoother(header, steps[:200], tags=True, robust="huber")
    assert smoother.name == "isam2-tags-huber" and smoother.landmark_yaws()


def test_heights_are_the_information_weighted_means_of_the_measured_heights():
    header, records = simulate("cylinders", 2)
    steps = group_steps(header, records)
    information: dict[int, float] = {}
    weighted: dict[int, float] = {}
    for s in steps:
        for o in s.observations:
            if o.landmark_id is not None and o.height_m is not None and o.sigma_height_m:
                w = 1.0 / o.sigma_height_m**2
                information[o.landmark_id] = information.get(o.landmark_id, 0.0) + w
                weighted[o.landmark_id] = weighted.get(o.landmark_id, 0.0) + w * o.height_m
    assert information, "the cylinders scenario observes heights"
    expected = {i: weighted[i] / information[i] for i in information}

    smoother = run_smoother(header, steps)
    heights = smoother.landmark_heights()
    assert set(heights) == set(expected)
    assert all(abs(heights[i] - expected[i]) < 1e-9 for i in expected)
    batch = batch_solve(smoother)
    assert all(abs(batch.landmark_heights[i] - expected[i]) < 1e-9 for i in expected)
    truth = {r.landmark_id: r.height_m for r in records if isinstance(r, TruthLandmark)}
    assert max(abs(heights[i] - truth[i]) for i in heights) < 0.01


def test_a_failed_update_is_recovered_with_tags_and_heights_in_the_graph(octagon):
    """The rebuild after an indeterminate update re-seeds Pose2 tags and scalar heights too."""
    header, steps, truth = octagon
    steps = steps[:120]
    bad_at = 60
    with_height = _map_observations(steps, lambda k, j, o: dataclasses.replace(o, height_m=0.3, sigma_height_m=0.02))
    junk = Observation(steps[bad_at].stamp_s, 99, 1e-300, 0.0, 0.02, 0.01)  # zero range: singular
    broken = [s if s.index != bad_at else dataclasses.replace(s, observations=s.observations + (junk,))
              for s in with_height]
    # one update per step: held steps would update on different steps in the two runs (the
    # junk's new id makes its step urgent) and reach the optimum by different paths
    smoother = run_smoother(header, broken, tags=True, update_every=1)
    assert smoother.update_failures == 1 and smoother.pending_observations == 1
    clean = run_smoother(header, with_height, tags=True, update_every=1)
    assert abs(smoother.error() - clean.error()) <= 1e-9 * clean.error()
    assert smoother.landmark_heights() == pytest.approx(clean.landmark_heights(), abs=1e-12)
    assert smoother.landmark_yaws() == pytest.approx(clean.landmark_yaws(), abs=1e-9)
