"""The simulator: determinism, exactness without noise, honest noise, scenario geometry.

The references here are independent of ``slamio.sim``: poses are composed with
``slamio.geometry``, ranges/bearings/visibility are recomputed with ``math`` one landmark
at a time, and the stated noise is checked against the actual errors with χ² bounds.
"""

from __future__ import annotations

import math
import re
from collections import defaultdict

import numpy as np
import pytest
from scipy import stats

from slamio.errors import FgslamError
from slamio.geometry import arc_increment, arc_increment_jacobian, between_pose, compose_pose, wrap_angle
from builders import assert_log_round_trips
from sim_records import SMALL, in_view, of_type, sim, truth_map
from slamio.log import Observation, Odometry, TruthLandmark, TruthPose, group_steps
from slamio.sim import (
    MAX_WHEEL_SPEED_M_S,
    SCENARIOS,
    WHEEL_BASE_M,
    odometry_covariance,
    simulate,
    wheel_speeds_m_s,
)

ARENA_M = 3.048


def sight_windows(records, gap_s: float) -> dict[int, int]:
    """Landmark id → number of separate time windows it was seen in (gaps longer than gap_s)."""
    stamps = defaultdict(list)
    for obs in of_type(records, Observation):
        stamps[obs.landmark_id].append(obs.stamp_s)
    return {i: 1 + int(np.sum(np.diff(s) > gap_s)) for i, s in stamps.items()}


# --------------------------------------------------------------------------- arguments, determinism


def test_scenarios_are_the_documented_five():
    assert SCENARIOS == ("arena-square", "arena-octagon", "cylinders", "grid", "clutter")


@pytest.mark.parametrize(
    "args, kwargs, fragment",
    [
        (("warehouse", 1), {}, "arena-square, arena-octagon, cylinders, grid"),
        (("grid", 1), {"landmarks": 0}, "landmarks"),
        (("grid", 1), {"landmarks": -5}, "landmarks"),
        (("arena-square", 1), {"laps": 0}, "laps"),
        (("arena-square", 1), {"noise_scale": -0.5}, "noise_scale"),
        (("arena-square", 1), {"noise_scale": float("nan")}, "noise_scale"),
        (("arena-square", -1), {}, "seed"),
        (("arena-square", 1), {"outliers": -0.1}, "outliers"),
        (("arena-square", 1), {"outliers": 1.0}, "outliers"),
        (("arena-square", 1), {"outliers": float("nan")}, "outliers"),
        (("arena-square", 1), {"outliers": True}, "outliers"),
        (("arena-square", 1), {"outliers": "0.1"}, "outliers"),
    ],
)
def test_bad_arguments_raise_fgslam_error(args, kwargs, fragment):
    with pytest.raises(FgslamError, match=fragment):
        simulate(*args, **kwargs)


def test_same_seed_same_records_and_different_seed_different():
    a = simulate("arena-octagon", 7)
    b = simulate("arena-octagon", 7)
    assert a == b
    c = simulate("arena-octagon", 8)
    assert c[1] != a[1]
    assert of_type(c[1], Odometry)[0] != of_type(a[1], Odometry)[0]


def test_header_describes_the_run():
    header, _ = simulate("arena-square", 3, laps=1, noise_scale=0.5, command="fgslam sim arena-square --seed 3")
    assert header.stamp_s == 0.0
    assert header.start_sigma == (1e-3, 1e-3, 1e-3)
    assert header.robot["name"] == "simulated iRobot Create"
    assert header.robot["drive"] == "differential"
    assert header.robot["wheel_base_m"] == 0.235
    assert header.sensor["kind"] == "range-bearing"
    assert header.sensor["landmark_kind"] == "apriltag"
    assert header.sensor["fov_rad"] == pytest.approx(1.2)
    assert (header.sensor["min_range_m"], header.sensor["max_range_m"]) == (0.15, 3.5)
    assert header.noise["odometry"]["k_wheel"] > 0
    assert {"sigma_range_m", "sigma_bearing_rad", "sigma_tag_yaw_rad"} <= set(header.noise["observation"])
    src = header.source
    assert (src["scenario"], src["seed"], src["laps"], src["noise_scale"]) == ("arena-square", 3, 1, 0.5)
    assert src["command"] == "fgslam sim arena-square --seed 3"
    assert simulate("cylinders", 0)[0].sensor["landmark_kind"] == "coloured-cylinder"
    assert simulate("grid", 0, landmarks=4, laps=1)[0].sensor["landmark_kind"] == "point"


# --------------------------------------------------------------------------- record layout


@pytest.mark.parametrize("scenario, kwargs", SMALL)
def test_record_order_and_stamps(scenario, kwargs):
    header, records = sim(scenario, 2, **kwargs)
    n = header.source["landmarks"]
    assert [r.landmark_id for r in records[:n]] == list(range(n))
    assert all(isinstance(r, TruthLandmark) for r in records[:n])
    assert not any(isinstance(r, TruthLandmark) for r in records[n:])
    first = records[n]
    assert isinstance(first, TruthPose) and first.stamp_s == header.stamp_s == 0.0
    assert (first.x_m, first.y_m, first.theta_rad) == header.start_pose

    steps = group_steps(header, records)
    dt = header.robot["dt_s"]
    assert steps[0].odometry is None
    for k, step in enumerate(steps):
        assert step.stamp_s == pytest.approx(k * dt, abs=1e-9)
        assert step.truth is not None and step.truth.stamp_s == step.stamp_s
        assert all(o.stamp_s == step.stamp_s for o in step.observations)
        if k:
            assert step.odometry.stamp_s == step.stamp_s
            assert step.stamp_s > steps[k - 1].stamp_s
    # after the landmarks: T O* (D T O*)* — odometry, truth pose, then that pose's observations
    letter = {Odometry: "D", TruthPose: "T", Observation: "O"}
    body = "".join(letter[type(r)] for r in records[n:])
    assert re.fullmatch(r"TO*(DTO*)*", body)
    assert body.count("D") == len(steps) - 1


def test_round_trip_through_the_log_file(tmp_path):
    for scenario, kwargs in SMALL:
        header, records = sim(scenario, 5, **kwargs)
        log = assert_log_round_trips(tmp_path / f"{scenario}.jsonl", header, records)
        assert log.has_full_truth()


# --------------------------------------------------------------------------- exact without noise


@pytest.mark.parametrize("scenario, kwargs", SMALL)
def test_noise_free_odometry_composes_to_the_truth(scenario, kwargs):
    header, records = sim(scenario, 4, noise_scale=0.0, **kwargs)
    pose = header.start_pose
    dt = header.robot["dt_s"]
    for step in group_steps(header, records)[1:]:
        odo = step.odometry
        # the increment is the arc of the Create's own reading
        assert (odo.dx_m, odo.dy_m, odo.dtheta_rad) == arc_increment(odo.distance_m, odo.angle_rad)
        # neither wheel is faster than the Create allows
        left = odo.distance_m - 0.5 * WHEEL_BASE_M * odo.angle_rad
        right = odo.distance_m + 0.5 * WHEEL_BASE_M * odo.angle_rad
        assert max(abs(left), abs(right)) <= MAX_WHEEL_SPEED_M_S * dt + 1e-12
        pose = compose_pose(pose, (odo.dx_m, odo.dy_m, odo.dtheta_rad))
        t = step.truth
        assert pose[0] == pytest.approx(t.x_m, abs=1e-9)
        assert pose[1] == pytest.approx(t.y_m, abs=1e-9)
        assert wrap_angle(pose[2] - t.theta_rad) == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize("scenario, kwargs", SMALL)
def test_noise_free_observations_are_exact_and_complete(scenario, kwargs):
    header, records = sim(scenario, 4, noise_scale=0.0, **kwargs)
    sensor, model = header.sensor, header.noise["observation"]
    landmarks = truth_map(records)
    n_seen = 0
    for step in group_steps(header, records):
        pose = (step.truth.x_m, step.truth.y_m, step.truth.theta_rad)
        expected = {}
        for lm in landmarks.values():
            seen, range_m, bearing_rad = in_view(pose, lm, sensor)
            if seen:
                expected[lm.landmark_id] = (range_m, bearing_rad)
        got = {o.landmark_id: o for o in step.observations}
        assert sorted(got) == sorted(expected), f"step {step.index}: visible set differs"
        for i, obs in got.items():
            lm = landmarks[i]
            range_m, bearing_rad = expected[i]
            assert obs.range_m == pytest.approx(range_m, abs=1e-9)
            assert wrap_angle(obs.bearing_rad - bearing_rad) == pytest.approx(0.0, abs=1e-9)
            # the written sigmas are the nominal ones, at the true range
            sigma_r = model["sigma_range_m"] + model["sigma_range_per_m"] * range_m + model["sigma_range_per_m2"] * range_m**2
            assert obs.sigma_range_m == pytest.approx(sigma_r, rel=1e-12)
            assert obs.sigma_bearing_rad == model["sigma_bearing_rad"]
            if sensor["landmark_kind"] == "coloured-cylinder":
                assert obs.height_m == pytest.approx(lm.height_m, abs=1e-12)
                assert obs.sigma_height_m == model["sigma_height_m"]
            else:
                assert obs.height_m is None
            if sensor["landmark_kind"] == "apriltag":
                assert wrap_angle(obs.tag_yaw_rad - (lm.yaw_rad - pose[2])) == pytest.approx(0.0, abs=1e-9)
                assert obs.sigma_tag_yaw_rad == model["sigma_tag_yaw_rad"]
            else:
                assert obs.tag_yaw_rad is None
        n_seen += len(got)
    assert n_seen > 50


def test_tags_are_seen_only_from_the_front():
    """visible_landmarks on a hand-made tag: front yes, back no, beyond 70° off its normal no."""
    from slamio.sim import World, visible_landmarks
    from slamio.sim_worlds import _TAG_CAMERA

    world = World(np.array([[0.0, 0.0]]), np.array([0.2]), np.array([0.0]))  # faces +x
    cases = []
    for angle_deg, expect in [(0, True), (40, True), (65, True), (75, False), (120, False), (180, False)]:
        a = math.radians(angle_deg)
        # 1 m from the tag, at angle_deg off its normal, looking straight at it
        cases.append(((math.cos(a), math.sin(a), wrap_angle(a + math.pi)), expect))
    poses = np.array([pose for pose, _ in cases])
    seen = visible_landmarks(poses, world, _TAG_CAMERA)
    assert sorted(seen.pose_index.tolist()) == [i for i, (_, expect) in enumerate(cases) if expect]
    assert seen.range_m == pytest.approx(1.0)
    assert seen.bearing_rad == pytest.approx(0.0, abs=1e-12)


# --------------------------------------------------------------------------- the stated noise is honest


def chi2_mean_bounds(dof_each: int, count: int, p: float = 1e-4) -> tuple[float, float]:
    """Two-sided bounds on the mean of ``count`` χ²(dof_each) samples."""
    total = dof_each * count
    return stats.chi2.ppf(p / 2, total) / count, stats.chi2.ppf(1 - p / 2, total) / count


@pytest.mark.parametrize("scenario, kwargs", [("arena-square", {"laps": 4}), ("grid", {"landmarks": 40})])
def test_odometry_covariance_matches_the_actual_errors(scenario, kwargs):
    header, records = sim(scenario, 11, **kwargs)
    steps = group_steps(header, records)
    nees = []
    for prev, step in zip(steps, steps[1:]):
        a, b, odo = prev.truth, step.truth, step.odometry
        true = between_pose((a.x_m, a.y_m, a.theta_rad), (b.x_m, b.y_m, b.theta_rad))
        e = np.array([odo.dx_m - true[0], odo.dy_m - true[1], wrap_angle(odo.dtheta_rad - true[2])])
        nees.append(e @ np.linalg.solve(np.array(odo.covariance), e))
    low, high = chi2_mean_bounds(3, len(nees))
    assert len(nees) > 1000
    assert low < np.mean(nees) < high, f"mean NEES {np.mean(nees):.3f} outside [{low:.3f}, {high:.3f}]"


def test_odometry_covariance_is_the_first_order_propagation():
    """Against geometry.arc_increment_jacobian and an explicit wheel Jacobian."""
    header, _ = sim("arena-octagon", 0)
    noise = header.noise["odometry"]
    from slamio.sim import WheelSlipNoise

    model = WheelSlipNoise(noise["k_wheel"], noise["slip_sigma_x_m"], noise["slip_sigma_y_m"], noise["slip_sigma_theta_rad"])
    b = WHEEL_BASE_M
    for left, right in [(0.02, 0.02), (0.015, 0.025), (-0.01, 0.01), (0.0, 0.03), (0.02, 0.01999999)]:
        distance, angle = (left + right) / 2, (right - left) / b
        J = arc_increment_jacobian(distance, angle) @ np.array([[0.5, 0.5], [-1 / b, 1 / b]])
        wheels = np.diag([(model.k_wheel * left) ** 2, (model.k_wheel * right) ** 2])
        c, s = math.cos(angle), math.sin(angle)
        R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
        slip = np.diag([model.slip_sigma_x_m**2, model.slip_sigma_y_m**2, model.slip_sigma_theta_rad**2])
        expected = J @ wheels @ J.T + R @ slip @ R.T
        np.testing.assert_allclose(odometry_covariance(left, right, model), expected, rtol=1e-9, atol=1e-18)
    batch = odometry_covariance(np.array([0.02, 0.0]), np.array([0.01, 0.03]), model)
    np.testing.assert_allclose(batch[1], odometry_covariance(0.0, 0.03, model))


@pytest.mark.parametrize(
    "scenario, kwargs",
    [("arena-square", {"laps": 4}), ("arena-octagon", {"laps": 4, "tag_noise": "measured"}), ("cylinders", {}),
     ("grid", {"landmarks": 40})],
)
def test_observation_sigmas_match_the_actual_errors(scenario, kwargs):
    header, records = sim(scenario, 12, **kwargs)
    landmarks = truth_map(records)
    columns = defaultdict(list)
    for step in group_steps(header, records):
        pose = (step.truth.x_m, step.truth.y_m, step.truth.theta_rad)
        for obs in step.observations:
            lm = landmarks[obs.landmark_id]
            _, range_m, bearing_rad = in_view(pose, lm, header.sensor)
            columns["range"].append((obs.range_m - range_m) / obs.sigma_range_m)
            columns["bearing"].append(wrap_angle(obs.bearing_rad - bearing_rad) / obs.sigma_bearing_rad)
            if obs.height_m is not None:
                columns["height"].append((obs.height_m - lm.height_m) / obs.sigma_height_m)
            if obs.tag_yaw_rad is not None:
                columns["tag_yaw"].append(wrap_angle(obs.tag_yaw_rad - (lm.yaw_rad - pose[2])) / obs.sigma_tag_yaw_rad)
    for name, values in columns.items():
        z = np.asarray(values)
        low, high = chi2_mean_bounds(1, len(z))
        assert len(z) > 500, name
        assert low < np.mean(z**2) < high, f"{name}: mean z² {np.mean(z**2):.3f} outside [{low:.3f}, {high:.3f}]"
        assert abs(np.mean(z)) < 4 / math.sqrt(len(z)), f"{name}: biased, mean z {np.mean(z):.3f}"


def test_noise_scale_scales_the_errors_not_the_stated_sigmas():
    h1, r1 = sim("arena-octagon", 6)
    h2, r2 = sim("arena-octagon", 6, noise_scale=2.0)
    o1, o2 = of_type(r1, Odometry), of_type(r2, Odometry)
    assert o1[0].covariance == o2[0].covariance
    assert of_type(r1, Observation)[0].sigma_bearing_rad == of_type(r2, Observation)[0].sigma_bearing_rad


# --------------------------------------------------------------------------- robot


def test_wheel_speed_limit_keeps_the_arc():
    left, right = wheel_speeds_m_s(0.5, 1.0)
    assert max(abs(left), abs(right)) == pytest.approx(MAX_WHEEL_SPEED_M_S)
    v, w = (left + right) / 2, (right - left) / WHEEL_BASE_M
    assert w / v == pytest.approx(1.0 / 0.5)
    assert wheel_speeds_m_s(0.2, 0.0) == (0.2, 0.2)
    assert wheel_speeds_m_s(0.0, 1.0) == pytest.approx((-0.1175, 0.1175))


# --------------------------------------------------------------------------- scenario geometry


def test_arena_has_eight_inward_facing_tags_two_per_wall():
    header, records = sim("arena-square", 1)
    tags = of_type(records, TruthLandmark)
    assert len(tags) == 8
    walls = defaultdict(list)
    for t in tags:
        assert t.height_m == pytest.approx(0.2, abs=0.05)
        normal = (math.cos(t.yaw_rad), math.sin(t.yaw_rad))
        if t.y_m == 0.0:
            wall, along, inward = "south", t.x_m, (0.0, 1.0)
        elif t.x_m == pytest.approx(ARENA_M):
            wall, along, inward = "east", t.y_m, (-1.0, 0.0)
        elif t.y_m == pytest.approx(ARENA_M):
            wall, along, inward = "north", t.x_m, (0.0, -1.0)
        else:
            assert t.x_m == 0.0
            wall, along, inward = "west", t.y_m, (1.0, 0.0)
        assert normal == pytest.approx(inward, abs=1e-12)
        walls[wall].append(along)
    assert sorted(walls) == ["east", "north", "south", "west"]
    for positions in walls.values():
        assert sorted(positions) == pytest.approx([ARENA_M / 3, 2 * ARENA_M / 3])


@pytest.mark.parametrize("scenario", ["arena-square", "arena-octagon"])
def test_arena_paths_stay_inside_see_every_tag_and_close_the_loop(scenario):
    header, records = sim(scenario, 1)
    poses = np.array([(t.x_m, t.y_m) for t in of_type(records, TruthPose)])
    assert 500 < len(poses) < 2500  # small bundled logs
    assert poses.min() > 0.4 and poses.max() < ARENA_M - 0.4
    centre = poses.mean(axis=0)
    assert centre == pytest.approx([ARENA_M / 2, ARENA_M / 2], abs=0.1)
    assert np.hypot(*(poses[-1] - poses[0])) < 0.05  # back at the start
    windows = sight_windows(records, gap_s=5.0)
    assert sorted(windows) == list(range(8))
    assert all(w >= 2 for w in windows.values())  # every tag seen on both laps


def test_square_turns_in_place_and_octagon_drives_arcs():
    for scenario, corners in [("arena-square", 4), ("arena-octagon", 8)]:
        header, records = sim(scenario, 1, laps=1, noise_scale=0.0)
        headings = np.array([t.theta_rad for t in of_type(records, TruthPose)])
        # one lap turns at every corner but the last (the run ends on the start corner)
        turn = np.sum(wrap_angle(np.diff(headings)))
        assert turn == pytest.approx(2 * math.pi * (corners - 1) / corners, abs=0.02)
        odometry = of_type(records, Odometry)
        nominal_step_m = header.robot["speed_m_s"] * header.robot["dt_s"]
        shortest = min(o.distance_m for o in odometry)
        if corners == 4:
            assert shortest < 0.05 * nominal_step_m  # turning (nearly) in place
        else:
            assert shortest > 0.3 * nominal_step_m  # never stops: arcs round the corners


def test_cylinders_three_coloured_landmarks_seen_on_every_lap():
    header, records = sim("cylinders", 1)
    cylinders = of_type(records, TruthLandmark)
    assert [c.landmark_id for c in cylinders] == [0, 1, 2]
    assert all(c.height_m is not None and c.height_m > 0 for c in cylinders)
    assert len({c.height_m for c in cylinders}) == 3
    assert header.sensor["landmark_colours"] == ["red", "green", "blue"]
    assert header.sensor["fov_rad"] == pytest.approx(math.radians(57))
    assert (header.sensor["min_range_m"], header.sensor["max_range_m"]) == (0.8, 4.0)
    laps = header.source["laps"]
    windows = sight_windows(records, gap_s=5.0)
    assert sorted(windows) == [0, 1, 2] and all(w >= laps for w in windows.values())
    steps = group_steps(header, records)
    in_sight = np.mean([len(s.observations) > 0 for s in steps])
    assert in_sight > 0.75


def test_grid_has_n_landmarks_returns_to_start_and_revisits():
    header, records = sim("grid", 1)  # default: 200 landmarks, 2 laps
    landmarks = of_type(records, TruthLandmark)
    assert len(landmarks) == 200 == header.source["landmarks"]
    xy = np.array([(lm.x_m, lm.y_m) for lm in landmarks])
    spacing = np.min(np.hypot(*(xy[1:] - xy[:-1]).T))
    assert spacing == pytest.approx(3.0)
    poses = of_type(records, TruthPose)
    assert len(poses) < 8000
    assert math.hypot(poses[-1].x_m - poses[0].x_m, poses[-1].y_m - poses[0].y_m) < 0.2
    windows = sight_windows(records, gap_s=60.0)
    assert len(windows) == 200  # every landmark seen
    assert np.mean([w >= 2 for w in windows.values()]) > 0.9  # revisits


@pytest.mark.parametrize("n", [1, 2, 7, 10])
def test_grid_with_few_landmarks(n):
    header, records = simulate("grid", 0, landmarks=n, laps=1)
    assert len(of_type(records, TruthLandmark)) == n
    assert {o.landmark_id for o in of_type(records, Observation)} == set(range(n))


# --------------------------------------------------------------------------- measured tag noise


def test_measured_tag_noise_sigmas_follow_range_and_viewing_angle():
    header, records = sim("arena-square", 3, tag_noise="measured")
    assert header.source["tag_noise"] == "measured"
    obs = header.noise["observation"]
    fx, size, px = obs["fx_px"], obs["tag_size_m"], obs["corner_sigma_px"]
    landmarks = truth_map(records)
    checked = 0
    for step in group_steps(header, records):
        pose = (step.truth.x_m, step.truth.y_m, step.truth.theta_rad)
        for o in step.observations:
            lm = landmarks[o.landmark_id]
            _, range_m, bearing_rad = in_view(pose, lm, header.sensor)
            # viewing angle from the world geometry: tag normal vs tag→robot direction
            to_robot = math.atan2(pose[1] - lm.y_m, pose[0] - lm.x_m)
            view = abs(wrap_angle(lm.yaw_rad - to_robot))
            eps = px * range_m / (fx * size)
            assert o.sigma_bearing_rad == pytest.approx(obs["g_b"] * px / fx)
            assert o.sigma_range_m == pytest.approx(obs["g_r"] * range_m * eps / max(math.cos(view), 0.1) ** obs["p_r"])
            g_eps = obs["g_y"] * eps
            assert o.sigma_tag_yaw_rad == pytest.approx(g_eps / math.sqrt(math.sin(view) ** 2 + g_eps))
            checked += 1
    assert checked > 500


def test_measured_tag_noise_only_for_tag_scenarios_and_names_checked():
    with pytest.raises(FgslamError, match="AprilTag scenarios"):
        simulate("cylinders", 1, tag_noise="measured")
    with pytest.raises(FgslamError, match="tag_noise must be one of"):
        simulate("arena-square", 1, tag_noise="real")


def test_grid_spacing_sets_the_landmark_spacing_and_is_checked():
    header, records = sim("grid", 2, landmarks=9, grid_spacing_m=0.75)
    xy = np.array([(r.x_m, r.y_m) for r in records if isinstance(r, TruthLandmark)])
    gaps = np.linalg.norm(xy[:, None, :] - xy[None, :, :], axis=2)
    assert np.min(gaps[gaps > 0]) == pytest.approx(0.75)
    assert header.sensor["grid_spacing_m"] == 0.75
    with pytest.raises(FgslamError, match="grid_spacing_m"):
        simulate("grid", 1, grid_spacing_m=0.0)
