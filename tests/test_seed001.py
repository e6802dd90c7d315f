"""Tests of ``ekf.signature_ekf`` (seed 001's GoPiGo EKF-SLAM, as written) against independent references.

* a one- and a two-step case computed by hand in this file, in plain numpy, from the paper's
  own equations (eqs. 19, 20, 23–26 and Algorithm 3 lines 2–6) — never calling the module's
  functions — equals the filter's mean and covariance;
* every Jacobian against central finite differences;
* nearest-neighbour association: scenes where it is right, and two where it provably is
  wrong (landmarks closer than the gate merge; a heading error moves an observation onto
  the neighbouring landmark);
* simulated logs: no NaN, consistent keys, ``landmark_id`` never read; with every flaw
  switched off the filter is the textbook EKF-SLAM.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from ekf.signature_ekf import (
    DEFAULT_GATE_M,
    EkfS001,
    expected_observation,
    move_forward,
    move_forward_jacobian,
    nearest_landmark,
    observation_jacobian,
    observation_noise,
    paper_moves,
    predict_forward_rotate,
    rotate_in_place,
    rotate_in_place_jacobian,
)
from slamio.geometry import arc_increment, wrap_angle
from builders import minimal_header as make_header
from jacobians import numeric_jacobian
from slamio.log import Observation, Odometry, Step, group_steps
from slamio.sim import simulate

# --------------------------------------------------------------------------- helpers


def obs(range_m, bearing_rad, sigma_r=0.05, sigma_b=0.02, height=None, sigma_h=None, landmark_id=None):
    return Observation(
        stamp_s=0.0,
        landmark_id=landmark_id,
        range_m=range_m,
        bearing_rad=bearing_rad,
        sigma_range_m=sigma_r,
        sigma_bearing_rad=sigma_b,
        height_m=height,
        sigma_height_m=sigma_h,
    )


def odom(distance_m, angle_rad, covariance, keep_reading=True):
    dx, dy, dth = arc_increment(distance_m, angle_rad)
    return Odometry(
        stamp_s=0.0,
        dx_m=dx,
        dy_m=dy,
        dtheta_rad=dth,
        covariance=tuple(tuple(float(v) for v in row) for row in np.asarray(covariance)),
        distance_m=distance_m if keep_reading else None,
        angle_rad=angle_rad if keep_reading else None,
    )


def step(index, odometry=None, observations=()):
    return Step(index, float(index), odometry, tuple(observations), None)




# --------------------------------------------------------------------------- the hand computation


def hand_expected(mu, with_s):
    """Expected (range, bearing[, signature]) of the hand scene's landmark."""
    dx, dy = mu[3] - mu[0], mu[4] - mu[1]
    z = [math.hypot(dx, dy), wrap_angle(math.atan2(dy, dx) - mu[2])]
    return np.array(z + [mu[5]] if with_s else z)


def hand_jacobian(mu, with_s):
    """Jacobian of :func:`hand_expected` over the 6-state."""
    dx, dy = mu[3] - mu[0], mu[4] - mu[1]
    q = dx * dx + dy * dy
    rq = math.sqrt(q)
    rows = [
        [-dx / rq, -dy / rq, 0, dx / rq, dy / rq, 0],
        [dy / q, -dx / q, -1, -dy / q, dx / q, 0],
    ]
    if with_s:
        rows.append([0, 0, 0, 0, 0, 1])
    return np.array(rows, dtype=float)


def hand_correct(mu, P, z, with_s, Q):
    """The paper's correction, lines 4–6 of its algorithm."""
    Ht = hand_jacobian(mu, with_s)
    K = P @ Ht.T @ np.linalg.inv(Ht @ P @ Ht.T + Q)
    nu = z - hand_expected(mu, with_s)
    nu[1] = wrap_angle(nu[1])
    mu = mu + K @ nu
    mu[2] = wrap_angle(mu[2])
    return mu, (np.eye(6) - K @ Ht) @ P


def hand_two_steps(q_power):
    """Seed 001's EKF for a small scene, written out from the paper's equations.

    ``q_power`` is 1 for eq. 20 as written (Q = diag(σ)) and 2 for variances. Returns the
    (mean, covariance) after step 0, step 1 and step 2. Nothing from ekf.signature_ekf is used.

    Scene: start pose (1, 2, 0.3). Step 0 sees a landmark with height (a signature) → the
    state grows to (x, y, θ, m_x, m_y, s) (eq. 19). Step 1 moves forward 0.5 m (eqs. 23,
    25) and sees it again with its height (3-row update, lines 4–6). Step 2 rotates in
    place by −0.2 rad (eqs. 24, 26) and sees it without a height (2-row update). R is the
    first reading's covariance, used unchanged at step 2 (the paper's constant R).
    """
    start = np.array([1.0, 2.0, 0.3])
    Sigma = np.diag([0.01**2, 0.02**2, 0.03**2])
    R = np.array([[4e-4, 1e-5, 0.0], [1e-5, 2e-4, 3e-5], [0.0, 3e-5, 9e-4]])
    out = []

    # step 0: new landmark from r = 2.0, φ = 0.4, height 0.6; σ = (0.05, 0.02, 0.03)
    r, phi, s = 2.0, 0.4, 0.6
    Q = np.diag(np.array([0.05, 0.02, 0.03]) ** q_power)
    x, y, th = start
    a = th + phi
    m = np.array([x + r * math.cos(a), y + r * math.sin(a), s])
    # l = (x + r cos(θ+φ), y + r sin(θ+φ), s): Jacobians w.r.t. the pose and (r, φ, s)
    Gp = np.array([[1, 0, -r * math.sin(a)], [0, 1, r * math.cos(a)], [0, 0, 0]])
    Gz = np.array([[math.cos(a), -r * math.sin(a), 0], [math.sin(a), r * math.cos(a), 0], [0, 0, 1]])
    mu = np.concatenate([start, m])
    P = np.zeros((6, 6))
    P[:3, :3] = Sigma
    P[3:, :3] = Gp @ Sigma
    P[:3, 3:] = (Gp @ Sigma).T
    P[3:, 3:] = Gp @ Sigma @ Gp.T + Gz @ Q @ Gz.T
    out.append((mu.copy(), P.copy()))

    # step 1: forward d = 0.5 (eq. 23) → line 2; G of eq. 25 → line 3
    d = 0.5
    th = mu[2]
    mu = mu + np.array([d * math.cos(th), d * math.sin(th), 0, 0, 0, 0])
    G = np.eye(6)
    G[0, 2] = -d * math.sin(th)
    G[1, 2] = d * math.cos(th)
    Fx = np.zeros((3, 6))
    Fx[:, :3] = np.eye(3)
    P = G @ P @ G.T + Fx.T @ R @ Fx
    z1 = np.array([1.62, 0.47, 0.63])
    Q1 = np.diag(np.array([0.04, 0.015, 0.03]) ** q_power)
    mu, P = hand_correct(mu, P, z1, True, Q1)
    out.append((mu.copy(), P.copy()))

    # step 2: rotate θ' = −0.2 (eq. 24) → line 2; G = I (eq. 26) → line 3, same R
    mu = mu + np.array([0, 0, -0.2, 0, 0, 0])
    mu[2] = wrap_angle(mu[2])
    P = P + Fx.T @ R @ Fx
    z2 = np.array([1.60, 0.66])
    Q2 = np.diag(np.array([0.04, 0.015]) ** q_power)
    mu, P = hand_correct(mu, P, z2, False, Q2)
    out.append((mu.copy(), P.copy()))
    return out, R


@pytest.mark.parametrize("q_diagonal, q_power", [("sigma", 1), ("variance", 2)])
def test_one_and_two_steps_equal_the_hand_computation(q_diagonal, q_power):
    expected, R = hand_two_steps(q_power)
    f = EkfS001(make_header((1.0, 2.0, 0.3), (0.01, 0.02, 0.03)), q_diagonal=q_diagonal)
    steps = [
        step(0, None, [obs(2.0, 0.4, 0.05, 0.02, height=0.6, sigma_h=0.03)]),
        step(1, odom(0.5, 0.0, R), [obs(1.62, 0.47, 0.04, 0.015, height=0.63, sigma_h=0.03)]),
        # a different covariance in the second reading: the constant R must ignore it
        step(2, odom(0.0, -0.2, 7.0 * R), [obs(1.60, 0.66, 0.04, 0.015)]),
    ]
    associations = []
    for k, s in enumerate(steps):
        f.step(s)
        associations.append(f.step_associations())
        mu, P = expected[k]
        np.testing.assert_allclose(f.state_mean(), mu, rtol=0, atol=1e-12)
        np.testing.assert_allclose(f.state_covariance(), P, rtol=1e-9, atol=1e-15)
        np.testing.assert_allclose(f.current_covariance(), P[:3, :3], rtol=1e-9, atol=1e-15)
    assert associations == [[-1], [-1], [-1]]
    assert f.landmarks() == {-1: (pytest.approx(expected[2][0][3]), pytest.approx(expected[2][0][4]))}
    assert f.landmark_heights() == {-1: pytest.approx(expected[2][0][5])}
    assert f.trajectory().shape == (3, 3)
    np.testing.assert_allclose(f.trajectory()[-1], expected[2][0][:3], atol=1e-12)


def test_the_as_written_q_is_not_the_variance_q():
    """Eq. 20 as written differs measurably from the correct Q in the same scene."""
    (_, (mu_sigma, P_sigma), _), _ = hand_two_steps(1)
    (_, (mu_var, P_var), _), _ = hand_two_steps(2)
    assert np.linalg.norm(mu_sigma[:2] - mu_var[:2]) > 1e-3
    # σ < 1 in SI units, so σ > σ²: the as-written filter trusts the measurement less
    assert np.trace(P_sigma[:2, :2]) > np.trace(P_var[:2, :2])


def test_an_arc_reading_is_forward_then_rotate():
    """A reading with both d and θ' is eq. 23 then eq. 24 in one prediction, G = eq. 25."""
    R = np.diag([1e-4, 1e-4, 1e-4])
    f = EkfS001(make_header((0.5, -1.0, 2.0), (0.01, 0.01, 0.01)), motion_covariance=R)
    f.step(step(0))
    f.step(step(1, odom(0.3, 0.25, np.eye(3))))
    x, y, th = 0.5, -1.0, 2.0
    expected = np.array([x + 0.3 * math.cos(th), y + 0.3 * math.sin(th), th + 0.25])
    np.testing.assert_allclose(f.current_pose(), expected, atol=1e-14)
    G = np.array([[1, 0, -0.3 * math.sin(th)], [0, 1, 0.3 * math.cos(th)], [0, 0, 1]])
    np.testing.assert_allclose(f.current_covariance(), G @ np.diag([1e-4] * 3) @ G.T + R, atol=1e-15)


def test_forward_then_rotate_misplaces_an_arc_sideways_by_half_d_theta():
    """The flaw of eqs. 23–24 on arcs: the lateral error of one reading is ≈ d·θ'/2."""
    d, a = 0.2, 0.1
    pose, _ = predict_forward_rotate((0.0, 0.0, 0.0), d, a)
    arc = arc_increment(d, a)
    assert pose[0] == pytest.approx(d)
    assert pose[1] == 0.0
    assert arc[1] - pose[1] == pytest.approx(d * a / 2.0, rel=0.01)


# --------------------------------------------------------------------------- small functions


def test_paper_moves_reads_the_creates_reading_or_inverts_the_arc():
    assert paper_moves(odom(0.2, 0.1, np.eye(3))) == (0.2, 0.1)
    for d, a in [(0.2, 0.1), (-0.15, 0.3), (0.02, 1e-7), (0.3, 0.0), (0.0, 0.5), (0.1, -2.5)]:
        got = paper_moves(odom(d, a, np.eye(3), keep_reading=False))
        assert got == pytest.approx((d, a), abs=1e-12)


def test_observation_noise_as_written_and_as_variances():
    np.testing.assert_array_equal(observation_noise((0.03, 0.01, 0.02)), np.diag([0.03, 0.01, 0.02]))
    np.testing.assert_allclose(observation_noise((0.03, 0.01), diagonal="variance"), np.diag([9e-4, 1e-4]))
    with pytest.raises(ValueError):
        observation_noise((0.1, 0.1), diagonal="std")


def test_jacobians_match_finite_differences():
    rng = np.random.default_rng(1)
    for _ in range(50):
        pose = rng.uniform([-5, -5, -math.pi], [5, 5, math.pi])
        if _ % 5 == 0:
            pose[2] = wrap_angle(math.pi - 1e-4)  # headings next to ±π
        d, a = rng.uniform(-0.5, 0.5), rng.uniform(-1, 1)
        J = numeric_jacobian(lambda p: move_forward(p, d), pose, angle_rows=(2,))
        np.testing.assert_allclose(move_forward_jacobian(pose, d), J, atol=1e-8)
        J = numeric_jacobian(lambda p: rotate_in_place(p, a), pose, angle_rows=(2,))
        np.testing.assert_allclose(rotate_in_place_jacobian(), J, atol=1e-8)
        J = numeric_jacobian(lambda p: predict_forward_rotate(p, d, a)[0], pose, angle_rows=(2,))
        np.testing.assert_allclose(predict_forward_rotate(pose, d, a)[1], J, atol=1e-8)

        direction = rng.uniform(-3, 3)
        landmark = pose[:2] + rng.uniform(0.5, 4.0) * np.array([math.cos(direction), math.sin(direction)])
        s = rng.uniform(0.2, 1.0)
        x = np.concatenate([pose, landmark, [s]])
        for with_s in (True, False):
            def h(v, with_s=with_s):
                return expected_observation(v[:3], v[3:5], v[5] if with_s else None)

            J = numeric_jacobian(h, x, angle_rows=(1,))
            np.testing.assert_allclose(observation_jacobian(pose, landmark, with_s), J, atol=1e-7)


# --------------------------------------------------------------------------- nearest neighbour


def test_nearest_landmark_picks_the_nearest_inside_the_gate():
    landmarks = np.array([[3.0, 0.0], [3.0, 1.0], [0.0, 3.0]])
    none = np.zeros(3, bool)
    got = nearest_landmark((3.05, 0.9), None, landmarks, np.zeros(3), none, 0.5)
    assert got == (1, pytest.approx(math.hypot(0.05, 0.1)))
    assert nearest_landmark((1.5, 1.5), None, landmarks, np.zeros(3), none, 0.5)[0] is None  # outside every gate
    assert nearest_landmark((1.0, 1.0), None, np.zeros((0, 2)), np.zeros(0), none[:0], 0.5) == (None, math.inf)


def test_the_signature_separates_landmarks_at_the_same_place():
    """Two landmarks equally far in (x, y): the signature (height) decides."""
    landmarks = np.array([[2.0, 0.1], [2.0, -0.1]])
    heights = np.array([0.4, 0.8])
    k, dist = nearest_landmark((2.0, 0.0), 0.78, landmarks, heights, np.ones(2, bool), 0.5)
    assert k == 1 and dist == pytest.approx(math.hypot(0.1, 0.02))
    k, _ = nearest_landmark((2.0, 0.0), 0.42, landmarks, heights, np.ones(2, bool), 0.5)
    assert k == 0


def test_nn_associates_correctly_when_the_pose_is_good():
    f = EkfS001(make_header(), motion_covariance=np.diag([1e-6, 1e-6, 1e-6]))
    a, b = (3.0, 0.0), (3.0, 1.0)
    f.step(step(0, None, [obs(*_rb((0, 0, 0), a)), obs(*_rb((0, 0, 0), b))]))
    assert f.step_associations() == [-1, -2]
    pose = (0.4, 0.0, 0.0)  # the odometry is exact
    f.step(step(1, odom(0.4, 0.0, np.eye(3)), [obs(*_rb(pose, b)), obs(*_rb(pose, a))]))
    assert f.step_associations() == [-2, -1]
    assert set(f.landmarks()) == {-1, -2}


def _rb(pose, landmark):
    """(range, bearing) of a landmark seen from a pose, computed here."""
    dx, dy = landmark[0] - pose[0], landmark[1] - pose[1]
    return math.hypot(dx, dy), wrap_angle(math.atan2(dy, dx) - pose[2])


def test_nn_merges_landmarks_closer_than_the_gate():
    """Failure mode 1: two landmarks 0.3 m apart, both seen at once from an exact pose,
    with the default 0.5 m gate — the second is taken for the first, never mapped."""
    f = EkfS001(make_header())
    a, b = (3.0, 0.0), (3.0, 0.3)
    f.step(step(0, None, [obs(*_rb((0, 0, 0), a)), obs(*_rb((0, 0, 0), b))]))
    assert DEFAULT_GATE_M > 0.3
    assert f.step_associations() == [-1, -1]
    assert len(f.landmarks()) == 1


def test_nn_takes_the_neighbour_when_the_heading_is_off():
    """Failure mode 2: two landmarks 0.3 m apart at 3 m, mapped correctly (gate 0.25 m).
    The robot then turns 0.1 rad right but its odometry says it did not turn. Landmark A
    is seen at bearing +0.1 rad; placed from the believed heading 0 it lands at
    3·(cos 0.1, sin 0.1) = (2.985, 0.300): 0.015 m from B, 0.300 m from A. Nearest
    neighbour measures only Euclidean distance — not the heading uncertainty that caused
    the shift — so it picks B, and the update then pulls the pose the wrong way."""
    f = EkfS001(make_header(), gate_m=0.25, motion_covariance=np.diag([1e-6, 1e-6, 1e-6]))
    a, b = (3.0, 0.0), (3.0, 0.3)
    f.step(step(0, None, [obs(*_rb((0, 0, 0), a)), obs(*_rb((0, 0, 0), b))]))
    assert f.step_associations() == [-1, -2]
    true_pose = (0.0, 0.0, -0.1)
    f.step(step(1, odom(0.0, 0.0, np.eye(3)), [obs(*_rb(true_pose, a))]))
    assert f.step_associations() == [-2]  # A's observation is used as B: wrong
    assert abs(f.current_pose()[2]) < 0.01  # and the heading error is not noticed


# --------------------------------------------------------------------------- simulated logs


@pytest.fixture(scope="module")
def logs():
    out = {}
    for name, kw in [("arena-octagon", {}), ("cylinders", {}), ("arena-octagon-hidden", {"hide_ids": True})]:
        header, records = simulate(name.replace("-hidden", ""), 1, **kw)
        out[name] = (header, group_steps(header, records))
    return out


def run(estimator, steps):
    keys = []
    for s in steps:
        estimator.step(s)
        got = estimator.step_associations()
        assert len(got) == len(s.observations)
        keys.extend(got)
    estimator.finish()
    return keys


@pytest.mark.parametrize("name", ["arena-octagon", "cylinders", "arena-octagon-hidden"])
def test_runs_on_simulated_logs_without_nan(logs, name):
    header, steps = logs[name]
    f = EkfS001(header)
    keys = run(f, steps)
    traj = f.trajectory()
    assert traj.shape == (len(steps), 3)
    assert np.isfinite(traj).all()
    assert np.isfinite(f.state_covariance()).all()
    lm = f.landmarks()
    assert sorted(lm) == list(range(-len(lm), 0))  # −1, −2, … in creation order
    assert all(k in lm for k in keys if k is not None)
    # the first use of each key is its creation, in order −1, −2, …
    first = list(dict.fromkeys(k for k in keys if k is not None))
    assert first == [-(i + 1) for i in range(len(lm))]
    assert np.all(np.linalg.eigvalsh(f.current_covariance()) > 0)


def test_landmark_ids_and_truth_ids_are_never_read(logs):
    """The same log with ids, with ids hidden, and with scrambled truth ids: identical runs."""
    header, steps = logs["arena-octagon"]
    _, hidden = logs["arena-octagon-hidden"]
    rng = np.random.default_rng(7)
    scrambled = [
        dataclasses.replace(
            s,
            observations=tuple(
                dataclasses.replace(o, landmark_id=int(rng.integers(100)), truth_landmark_id=int(rng.integers(100)))
                for o in s.observations
            ),
        )
        for s in steps
    ]
    results = []
    for variant in (steps, hidden, scrambled):
        f = EkfS001(header)
        keys = run(f, variant)
        results.append((f.trajectory(), keys))
    for traj, keys in results[1:]:
        np.testing.assert_array_equal(traj, results[0][0])
        assert keys == results[0][1]


def test_heights_are_used_as_signatures_on_the_cylinders(logs):
    header, steps = logs["cylinders"]
    f = EkfS001(header)
    run(f, steps)
    heights = sorted(f.landmark_heights().values())
    assert heights == pytest.approx([0.4, 0.6, 0.8], abs=0.05)
    g = EkfS001(header, use_signature=False)
    run(g, steps)
    assert g.landmark_heights() == {}


def test_prediction_only_is_what_the_paper_ran(logs):
    """``correction=False``: observations ignored, the pose is the chain of eqs. 23–24."""
    header, steps = logs["arena-octagon"]
    f = EkfS001(header, correction=False)
    keys = run(f, steps)
    assert all(k is None for k in keys) and f.landmarks() == {}
    pose = np.array(header.start_pose)
    for s in steps[1:]:
        pose, _ = predict_forward_rotate(pose, *paper_moves(s.odometry))
    np.testing.assert_allclose(f.current_pose(), pose, atol=1e-12)


def test_with_every_flaw_off_it_is_the_textbook_ekf(logs):
    """Q with variances, the arc model, each reading's own covariance: on a log where
    nearest neighbour associates every observation right, the trajectory is the textbook
    EKF-SLAM's (``ekf.EkfSlam`` with the log's ids; Joseph vs (I − KH)Σ̄ only)."""
    from ekf import EkfSlam

    header, steps = logs["arena-octagon"]
    f = EkfS001(header, q_diagonal="variance", motion_model="arc", motion_noise="log")
    run(f, steps)
    reference = EkfSlam(header)
    for s in steps:
        reference.step(s)
    np.testing.assert_allclose(f.trajectory(), reference.trajectory(), atol=1e-6)


def test_bad_keywords_are_refused():
    for kw in ({"q_diagonal": "std"}, {"motion_model": "spline"}, {"motion_noise": "x"}, {"gate_m": 0.0}):
        with pytest.raises(ValueError):
            EkfS001(make_header(), **kw)


def test_a_constant_q_replaces_the_observations_sigmas():
    """``q_sigmas``: one calibrated (σ_r, σ_φ, σ_s) for every observation, placed as written."""
    f = EkfS001(make_header(start_sigma=(1e-9, 1e-9, 1e-9)), q_sigmas=(0.1, 0.05, 0.2))
    f.step(step(0, None, [obs(2.0, 0.0, 0.01, 0.001, height=0.5, sigma_h=0.01)]))
    # seen straight ahead from the origin: x along the range, y along r·bearing
    expected = np.diag([0.1, 2.0**2 * 0.05, 0.2])
    np.testing.assert_allclose(f.state_covariance()[3:, 3:], expected, atol=1e-12)


# --------------------------------------------------------------------------- the trials wired in


def test_trial_calibration_in_the_header_gives_the_filter_its_R_and_Q(tmp_path):
    """Seed 001's procedure end to end: the trials' pooled covariance becomes R and the sensor
    trials' σ become Q's σ_r, σ_φ (σ_s stays each observation's own), read from the header
    where `fgslam record --calibration` and `fgslam run --calibration` put it."""
    from ekf.signature_ekf import EkfS001, trial_calibration
    from slamio.noise.trials import calibrate_from_trials, read_trials

    calibration = calibrate_from_trials(*read_trials("data/calibration_trials_s001.csv"), source="trials")
    header = make_header()
    assert trial_calibration(header) == (None, None)
    header = dataclasses.replace(header, noise={**header.noise, "calibration": calibration.to_dict()})
    R, q = trial_calibration(header)
    np.testing.assert_allclose(R, np.array(calibration.pooled_motion_covariance))
    assert q == (calibration.observation["sigma_range_m"], calibration.observation["sigma_bearing_rad"], None)
    ekf = EkfS001(header)
    np.testing.assert_allclose(ekf.R, R)
    obs = Observation(0.0, None, 1.0, 0.1, 0.5, 0.5, height_m=0.3, sigma_height_m=0.02)
    assert ekf._sigmas(obs, True) == [q[0], q[1], 0.02]
    assert EkfS001(header, q_sigmas=(0.1, 0.2, 0.3)).q_sigmas == (0.1, 0.2, 0.3)  # a keyword still wins


@pytest.mark.slow
def test_fgslam_run_calibration_reaches_ekf_s001(tmp_path, capsys):
    from fgslam.cli import main

    cal = tmp_path / "cal.json"
    assert main(["calibrate", "data/calibration_trials_s001.csv", "--out", str(cal)]) == 0
    ate = {}
    for name, extra in (("plain", []), ("calibrated", ["--calibration", str(cal)])):
        out = tmp_path / name
        assert main(["run", "data/arena_octagon.jsonl", "--out", str(out), "--estimators", "ekf-s001,isam2",
                     "--no-report", "--no-consistency", *extra]) == 0
        metrics = __import__("json").loads((out / "metrics.json").read_text())
        ate[name] = metrics["ekf-s001"]["ate_rmse_m"]
    assert metrics["trial_calibration"] == str(cal)
    assert "R and Q from the trial calibration" in capsys.readouterr().out
    assert ate["plain"] != ate["calibrated"]  # the filter did use the trials


@pytest.mark.slow
@pytest.mark.parametrize("spacing_m, noise_scale, low, high", [
    (1.0, 1.0, 0.99, 1.0),  # spacing twice the gate, world-point errors ~0.1 m: right every time
    (0.5, 1.0, 0.0, 0.7),  # spacing = the 0.5 m gate: unseen landmarks merge into mapped neighbours
    (1.0, 4.0, 0.0, 0.5),  # world-point errors ~0.4 m + pose drift reach the gate: duplicates
])
def test_nearest_neighbour_fails_where_spacing_meets_the_gate_or_errors_reach_it(spacing_m, noise_scale, low, high):
    # the boundary of scripts/seed001_association.py (docs/seeds.md), one seed per cell
    from fgslam.compare import score_associations

    header, records = simulate("grid", 1, landmarks=36, hide_ids=True, grid_spacing_m=spacing_m,
                               noise_scale=noise_scale)
    f, keys, true = EkfS001(header), [], []
    for step in group_steps(header, records):
        f.step(step)
        keys += f.step_associations()
        true += [o.truth_landmark_id for o in step.observations]
    assert low <= score_associations(true, keys).rate <= high
