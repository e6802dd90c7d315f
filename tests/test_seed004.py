"""Tests of ``ekf.apriltag_kf`` (``ekf-s004``) against independent references.

* the paper's H for two tags, printed in the paper, reproduced literally;
* the velocity input: Δt cancels, a body velocity is added to the world pose unrotated;
* the observation vector and its covariance on known values;
* four steps (two updates, one of them on the robot/visible-tag sub-state) worked by hand
  from the paper's prediction and update equations;
* a linear setting (constant heading, every tag seen every step) against the closed-form
  weighted least-squares (information-form) solution;
* simulated arena logs run without NaN.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from ekf.apriltag_kf import (
    EkfS004,
    body_velocity,
    measurement_matrix,
    observation_covariance_from_log,
    observation_vector,
    predict_robot,
    tag_pose_in_robot,
)
from builders import assert_arena_run_is_sane, minimal_header, run_estimator as run
from slamio.log import Header, Observation, Odometry, Step, as_matrix3, group_steps
from slamio.sim import simulate


def make_header(start_pose=(0.0, 0.0, 0.0), start_sigma=(1.0, 1.0, 1.0), stamp_s=0.0) -> Header:
    return minimal_header(start_pose=start_pose, start_sigma=start_sigma, stamp_s=stamp_s)


def odo(t, dx, dy, dth, cov=(1e-4, 1e-4, 1e-4)):
    return Odometry(t, dx, dy, dth, as_matrix3(np.diag(cov)))


def tag(t, lid, range_m, bearing_rad, yaw_rad, sigmas=(0.01, 0.01, 0.05)):
    return Observation(t, lid, range_m, bearing_rad, sigmas[0], sigmas[1], tag_yaw_rad=yaw_rad, sigma_tag_yaw_rad=sigmas[2])


def R(a):
    return np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])


# --------------------------------------------------------------------------- models


def test_measurement_matrix_is_the_papers_example():
    expected = np.array(
        [
            [-1, 0, 0, 1, 0, 0, 0, 0, 0],
            [0, -1, 0, 0, 1, 0, 0, 0, 0],
            [0, 0, -1, 0, 0, 1, 0, 0, 0],
            [-1, 0, 0, 0, 0, 0, 1, 0, 0],
            [0, -1, 0, 0, 0, 0, 0, 1, 0],
            [0, 0, -1, 0, 0, 0, 0, 0, 1],
        ]
    )
    np.testing.assert_array_equal(measurement_matrix(2), expected)


def test_velocity_input_is_added_to_the_world_pose_unrotated():
    v = body_velocity((0.1, 0.0, 0.0), 0.5)
    np.testing.assert_allclose(v, [0.2, 0.0, 0.0])
    facing_y = (1.0, 1.0, math.pi / 2)
    # as written: a forward velocity moves the robot along world x whatever its heading
    np.testing.assert_allclose(predict_robot(facing_y, v, 0.5), [1.1, 1.0, math.pi / 2])
    np.testing.assert_allclose(predict_robot(facing_y, v, 0.5, rotate_input=True), [1.0, 1.1, math.pi / 2])
    with pytest.raises(ValueError):
        body_velocity((0.1, 0.0, 0.0), 0.0)


def test_stamps_cancel_and_a_zero_time_step_falls_back_to_the_increment():
    def log(stamps):
        return [
            Step(0, stamps[0], None, (tag(stamps[0], 1, 2.0, 0.2, 3.0),), None),
            Step(1, stamps[1], odo(stamps[1], 0.2, 0.05, 0.1), (tag(stamps[1], 1, 1.8, 0.25, 2.95),), None),
            Step(2, stamps[2], odo(stamps[2], 0.1, 0.0, -0.05), (tag(stamps[2], 1, 1.7, 0.2, 2.9),), None),
        ]

    a = run(EkfS004(make_header()), log([0.0, 0.1, 0.2]))
    b = run(EkfS004(make_header()), log([0.0, 0.7, 0.75]))
    c = run(EkfS004(make_header()), log([0.0, 0.0, 0.3]))
    np.testing.assert_allclose(a.trajectory(), b.trajectory(), atol=1e-12)
    np.testing.assert_allclose(a.trajectory(), c.trajectory(), atol=1e-12)
    assert (a.zero_dt_steps, c.zero_dt_steps) == (0, 1)


def test_observation_vector_known_values():
    p = tag_pose_in_robot(tag(0, 1, 1.0, 0.0, math.pi))  # 1 m ahead, facing the robot
    np.testing.assert_allclose(p, [1.0, 0.0, math.pi], atol=1e-15)
    np.testing.assert_allclose(observation_vector(p, math.pi / 2), [0.0, 1.0, math.pi], atol=1e-15)
    np.testing.assert_allclose(observation_vector(p, math.pi / 2, tag_angle="world"), [0.0, 1.0, 1.5 * math.pi], atol=1e-15)


def test_observation_covariance_known_values():
    o = tag(0, 1, 2.0, 0.0, 0.0, sigmas=(0.1, 0.02, 0.05))
    np.testing.assert_allclose(observation_covariance_from_log(o, 0.0), np.diag([0.01, (2 * 0.02) ** 2, 0.0025]))
    # facing +y the range error lies along world y
    np.testing.assert_allclose(
        observation_covariance_from_log(o, math.pi / 2), np.diag([(2 * 0.02) ** 2, 0.01, 0.0025]), atol=1e-18
    )


# --------------------------------------------------------------------------- steps by hand


def hand_log():
    return [
        Step(0, 0.0, None, (tag(0.0, 3, 2.0, 0.0, 3.0),), None),
        Step(1, 0.5, odo(0.5, 0.4, 0.1, 0.2), (tag(0.5, 3, 1.5, 0.1, 2.9),), None),
        Step(2, 1.0, odo(1.0, 0.3, 0.0, 0.0), (tag(1.0, 5, 1.0, -0.5, -2.5),), None),
        Step(3, 1.5, odo(1.5, 0.1, 0.0, 0.0), (tag(1.5, 5, 0.9, -0.6, -2.4),), None),
    ]


def test_steps_by_hand():
    """Σ₀ = I (start sigma 1), W = 2 I, V = I, worked through the paper's equations."""
    I3 = np.eye(3)
    f = EkfS004(make_header(), process_cov=2 * I3, observation_cov=I3)
    steps = hand_log()

    # step 0: tag 3 at 2 m straight ahead, yaw 3.0 → z = (2, 0, 3.0), appended as robot + z
    f.step(steps[0])
    mu, S = f.state()
    np.testing.assert_allclose(mu, [0, 0, 0, 2, 0, 3.0], atol=1e-15)
    np.testing.assert_allclose(S, np.eye(6))

    # step 1: Δt = 0.5, u = (0.8, 0.2, 0.4), G u = (0.4, 0.1, 0.2); Σ_rr = I + 2 I = 3 I
    robot = np.array([0.4, 0.1, 0.2])
    tag3 = np.array([2.0, 0.0, 3.0])
    z = np.concatenate([R(0.2) @ [1.5 * math.cos(0.1), 1.5 * math.sin(0.1)], [2.9]])
    nu = z - (tag3 - robot)
    # S = 3 + 1 + 1 = 5 I, K = [−3/5 I; 1/5 I], (I − K H) Σ = [[1.2 I, 0.6 I], [0.6 I, 0.8 I]]
    robot, tag3 = robot - 0.6 * nu, tag3 + 0.2 * nu
    Sigma1 = np.block([[1.2 * I3, 0.6 * I3], [0.6 * I3, 0.8 * I3]])
    f.step(steps[1])
    mu, S = f.state()
    np.testing.assert_allclose(mu, np.concatenate([robot, tag3]), atol=1e-12)
    np.testing.assert_allclose(S, Sigma1, atol=1e-12)
    assert f.step_associations() == [3]

    # step 2: G u = (0.3, 0, 0) straight onto the world pose; Σ_rr = 3.2 I. Only the new
    # tag 5 is seen: no update; it is appended at robot + z with V = I, no cross-covariance
    robot = robot + [0.3, 0.0, 0.0]
    tag5 = robot + np.concatenate([R(robot[2]) @ [math.cos(-0.5), math.sin(-0.5)], [-2.5]])
    f.step(steps[2])
    mu, S = f.state()
    np.testing.assert_allclose(mu, np.concatenate([robot, tag3, tag5]), atol=1e-12)

    # step 3: G u = (0.1, 0, 0); Σ_rr = 5.2 I. Tag 5 seen, tag 3 not: the update runs on the
    # (robot, tag 5) sub-state [[5.2 I, 0], [0, I]]: S = 7.2 I, K = [−5.2/7.2 I; 1/7.2 I]
    robot = robot + [0.1, 0.0, 0.0]
    z = np.concatenate([R(robot[2]) @ [0.9 * math.cos(-0.6), 0.9 * math.sin(-0.6)], [-2.4]])
    nu = z - (tag5 - robot)
    robot, tag5 = robot - 5.2 / 7.2 * nu, tag5 + 1 / 7.2 * nu
    Sigma3 = np.zeros((9, 9))
    Sigma3[0:3, 0:3] = (5.2 - 5.2**2 / 7.2) * I3
    Sigma3[0:3, 6:9] = Sigma3[6:9, 0:3] = 5.2 / 7.2 * I3
    Sigma3[6:9, 6:9] = (1 - 1 / 7.2) * I3
    Sigma3[0:3, 3:6] = Sigma3[3:6, 0:3] = 0.6 * I3  # stale: not part of the sub-state
    Sigma3[3:6, 3:6] = 0.8 * I3
    f.step(steps[3])
    mu, S = f.state()
    np.testing.assert_allclose(mu, np.concatenate([robot, tag3, tag5]), atol=1e-12)
    np.testing.assert_allclose(S, Sigma3, atol=1e-12)
    np.testing.assert_allclose(f.current_pose(), robot, atol=1e-12)
    np.testing.assert_allclose(f.current_covariance(), Sigma3[:3, :3], atol=1e-12)
    assert set(f.landmarks()) == {3, 5}

    # a full-state update would have moved the unseen tag 3 through its correlation
    g = run(EkfS004(make_header(), process_cov=2 * I3, observation_cov=I3, substate_update=False), steps)
    mu_full, S_full = g.state()
    assert np.abs(mu_full[3:6] - tag3).max() > 1e-3
    assert np.abs(S_full[0:3, 3:6] - 0.6 * I3).max() > 1e-3


def test_substate_update_equals_full_update_when_every_tag_is_seen():
    steps = hand_log()[:2]
    a = run(EkfS004(make_header()), steps)
    b = run(EkfS004(make_header(), substate_update=False), steps)
    for x, y in zip(a.state(), b.state()):
        np.testing.assert_allclose(x, y, atol=1e-14)


# --------------------------------------------------------------------------- linear setting vs least squares


def test_linear_setting_equals_least_squares():
    """Heading constant (dθ = 0, tag yaws consistent), all three tags seen every step: the
    filter is a linear KF over positions and must equal the batch solution of the same
    problem — priors on the start and on each tag's first fix, odometry and tag factors."""
    rng = np.random.default_rng(5)
    heading = 0.3
    start = np.array([0.5, -0.2])
    sigma0 = np.array([0.05, 0.04, 0.01])
    w = np.array([0.01, 0.02, 0.001]) ** 2  # odometry covariance diagonal (dx, dy, dθ)
    Vxy = np.diag([0.03, 0.05]) ** 2
    V = np.diag([0.03**2, 0.05**2, 0.01])
    tags = {0: (2.0, 1.0, math.pi), 1: (1.0, 2.5, -math.pi / 2), 2: (-0.5, 0.5, 0.0)}
    position = start.copy()
    steps, data = [], []
    for k in range(10):
        if k == 0:
            record, inc = None, None
        else:
            inc = rng.normal(scale=0.1, size=2)
            record = odo(0.1 * k, inc[0], inc[1], 0.0, cov=w)
            position = position + inc + rng.normal(scale=0.01, size=2)
        observations, zs = [], {}
        for lid, (tx, ty, tyaw) in tags.items():
            rel = np.array([tx, ty]) - position + rng.normal(scale=0.03, size=2)
            p = R(heading).T @ rel
            yaw = tyaw - heading  # exact
            observations.append(tag(0.1 * k, lid, math.hypot(*p), math.atan2(p[1], p[0]), yaw))
            zs[lid] = R(heading) @ p
        steps.append(Step(k, 0.1 * k, record, tuple(observations), None))
        data.append((inc, zs))

    f = run(EkfS004(make_header((*start, heading), sigma0), observation_cov=V), steps)
    mu, S = f.state()

    # least squares over r_0..r_9 and the three tags (x, y)
    K = len(data) - 1
    n = 2 * (K + 1) + 6
    Lam, eta = np.zeros((n, n)), np.zeros(n)

    def add(rows, z, cov):
        A = np.zeros((2, n))
        for col, sign in rows:
            A[:, col : col + 2] += sign * np.eye(2)
        info = np.linalg.inv(cov)
        Lam[:] += A.T @ info @ A
        eta[:] += A.T @ info @ z

    tcol = {lid: 2 * (K + 1) + 2 * lid for lid in tags}
    add([(0, 1.0)], start, np.diag(sigma0[:2] ** 2))
    for lid in tags:
        add([(tcol[lid], 1.0)], start + data[0][1][lid], Vxy)
    for k in range(1, K + 1):
        inc, zs = data[k]
        add([(2 * k, 1.0), (2 * (k - 1), -1.0)], inc, np.diag(w[:2]))
        for lid, z in zs.items():
            add([(tcol[lid], 1.0), (2 * k, -1.0)], z, Vxy)
    cov = np.linalg.inv(Lam)
    mean = cov @ eta
    keep_ls = [2 * K, 2 * K + 1] + [tcol[lid] + i for lid in tags for i in (0, 1)]
    keep_kf = [0, 1, 3, 4, 6, 7, 9, 10]
    np.testing.assert_allclose(mu[keep_kf], mean[keep_ls], atol=1e-10)
    np.testing.assert_allclose(S[np.ix_(keep_kf, keep_kf)], cov[np.ix_(keep_ls, keep_ls)], rtol=1e-8, atol=1e-15)
    assert mu[2] == pytest.approx(heading, abs=1e-12)


# --------------------------------------------------------------------------- bookkeeping and sim


def test_associations_ignore_unknown_ids_tags_without_yaw_and_repeats():
    f = EkfS004(make_header())
    no_yaw = Observation(0.0, 4, 1.0, 0.0, 0.01, 0.01)
    f.step(Step(0, 0.0, None, (tag(0, None, 1, 0, 3), no_yaw, tag(0, 2, 1, 0, 3), tag(0, 2, 1.1, 0, 3)), None))
    assert f.step_associations() == [None, None, 2, None]
    assert set(f.landmarks()) == {2}
    with pytest.raises(ValueError):
        EkfS004(make_header(), tag_angle="absolute")
    with pytest.raises(ValueError):
        EkfS004(make_header(), process_cov=np.eye(2))


@pytest.mark.parametrize("scenario", ["arena-octagon", "arena-square"])
@pytest.mark.parametrize("kwargs", [{}, {"rotate_input": True, "substate_update": False}])
def test_runs_on_simulated_arena_logs(scenario, kwargs):
    header, records = simulate(scenario, 1)
    steps = group_steps(header, records)
    f = run(EkfS004(header, **kwargs), steps)
    assert_arena_run_is_sane(f, steps)
