"""Tests of ``ekf.linear_kf_kinect`` (``ekf-s000``) against independent references.

* the edge conversions (compass ↔ counter-clockwise, the start-anchored paper frame, the
  paper's robot frame) on known values and round trips;
* the §3.3.2 input vector, its Δθ = 0 special case and the as-written rotation's mirror;
* one and two filter steps worked by hand from the paper's equations 19–23 and §3.3.4–3.3.7
  (the numbers are written out below; nothing calls the module's internals);
* a linear setting (a fixed heading, straight moves, every landmark seen every step)
  against the closed-form weighted least-squares (information-form) solution, and the
  deviation that the gain-row zeroing and the pseudo-measurements cause when a landmark is
  not seen;
* the units of "variances all one" change the covariance, never the mean;
* rigid re-anchoring of the start pose moves every output rigidly;
* simulated arena logs run without NaN.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from ekf.linear_kf_kinect import (
    EkfS000,
    arc_reading,
    ccw_from_compass,
    compass_from_ccw,
    compass_turn_from_ccw,
    h_times,
    input_vector,
    measurement_matrix,
    paper_pose_from_world,
    paper_robot_xy_from_range_bearing,
    paper_to_world_jacobian,
    paper_xy_from_world,
    rotation_matrix,
    world_pose_from_paper,
    world_xy_from_paper,
)
from slamio.geometry import arc_increment, wrap_angle
from builders import assert_arena_run_is_sane, minimal_header, run_estimator as run
from slamio.log import Header, Observation, Odometry, Step, as_matrix3, group_steps
from slamio.sim import simulate

NORTH_UP = (0.0, 0.0, math.pi / 2)  # a start pose whose paper frame is the world frame


def make_header(start_pose=NORTH_UP, start_sigma=(1e-3, 1e-3, 1e-3)) -> Header:
    return minimal_header(start_pose=start_pose, start_sigma=start_sigma)


def odo(t, distance_m, angle_rad):
    """An odometry record carrying the Create's reading (and its arc increment)."""
    dx, dy, dth = arc_increment(distance_m, angle_rad)
    cov = as_matrix3(np.diag([1e-4, 1e-4, 1e-4]))
    return Odometry(t, dx, dy, dth, cov, distance_m=distance_m, angle_rad=angle_rad)


def obs(t, lid, range_m, bearing_rad):
    return Observation(t, lid, range_m, bearing_rad, 0.01, 0.01)


def R_ccw(a):
    """The §3.3.2 matrix, "rotate counterclockwise by θ" (written out for the tests)."""
    return np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])


def R_cw(a):
    """The rotation consistent with a clockwise compass heading."""
    return np.array([[math.cos(a), math.sin(a)], [-math.sin(a), math.cos(a)]])


# --------------------------------------------------------------------------- conventions


def test_compass_known_values():
    # north = +y (ccw π/2) is heading 0; east = +x (ccw 0) is 90°; south 180°; west 270°
    assert compass_from_ccw(math.pi / 2) == pytest.approx(0.0)
    assert compass_from_ccw(0.0) == pytest.approx(math.pi / 2)
    assert compass_from_ccw(-math.pi / 2) == pytest.approx(math.pi)
    assert wrap_angle(ccw_from_compass(3 * math.pi / 2)) == pytest.approx(-math.pi)  # west
    assert ccw_from_compass(0.0) == pytest.approx(math.pi / 2)
    # a left (counter-clockwise) turn is a negative compass change
    assert compass_turn_from_ccw(0.25) == -0.25


def test_compass_round_trip():
    rng = np.random.default_rng(0)
    for theta, north in rng.uniform(-4, 4, size=(50, 2)):
        assert ccw_from_compass(compass_from_ccw(theta, north), north) == pytest.approx(theta, abs=1e-12)
        assert compass_from_ccw(ccw_from_compass(theta, north), north) == pytest.approx(theta, abs=1e-12)


def test_paper_frame_anchored_at_start():
    # start at (1, 2) facing +x: "north" is +x, "east" (its right) is −y
    origin, north = (1.0, 2.0), 0.0
    np.testing.assert_allclose(paper_xy_from_world((2.0, 2.0), origin, north), [0.0, 1.0], atol=1e-15)
    np.testing.assert_allclose(paper_xy_from_world((1.0, 1.0), origin, north), [1.0, 0.0], atol=1e-15)
    # a robot facing world +y from there has turned left: compass heading −90°
    np.testing.assert_allclose(paper_pose_from_world((1.0, 2.0, math.pi / 2), origin, north), [0, 0, -math.pi / 2])
    rng = np.random.default_rng(1)
    for _ in range(20):
        pose = rng.uniform(-5, 5, size=3)
        origin, north = rng.uniform(-5, 5, size=2), rng.uniform(-4, 4)
        back = world_pose_from_paper(paper_pose_from_world(pose, origin, north), origin, north)
        np.testing.assert_allclose(back[:2], pose[:2], atol=1e-12)
        assert wrap_angle(back[2] - pose[2]) == pytest.approx(0.0, abs=1e-12)
        xy = rng.uniform(-5, 5, size=2)
        np.testing.assert_allclose(world_xy_from_paper(paper_xy_from_world(xy, origin, north), origin, north), xy)


def test_paper_to_world_jacobian_matches_finite_differences():
    north, origin = 0.7, (0.3, -1.0)
    x0 = np.array([0.4, -0.2, 1.1])
    J = np.zeros((3, 3))
    for j in range(3):
        d = np.zeros(3)
        d[j] = 1e-6
        diff = world_pose_from_paper(x0 + d, origin, north) - world_pose_from_paper(x0 - d, origin, north)
        diff[2] = wrap_angle(diff[2])
        J[:, j] = diff / 2e-6
    np.testing.assert_allclose(paper_to_world_jacobian(north), J, atol=1e-8)


def test_paper_robot_frame():
    # x′ to the right, y′ forward; the log's bearing is counter-clockwise from forward
    np.testing.assert_allclose(paper_robot_xy_from_range_bearing(2.0, 0.0), [0.0, 2.0], atol=1e-15)
    np.testing.assert_allclose(paper_robot_xy_from_range_bearing(2.0, math.pi / 2), [-2.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(paper_robot_xy_from_range_bearing(2.0, -math.pi / 2), [2.0, 0.0], atol=1e-15)


def test_rotations_agree_only_facing_north_or_south():
    forward = np.array([0.0, 1.0])
    np.testing.assert_allclose(rotation_matrix(math.pi / 2, "compass") @ forward, [1.0, 0.0], atol=1e-15)  # east
    np.testing.assert_allclose(rotation_matrix(math.pi / 2, "as-written") @ forward, [-1.0, 0.0], atol=1e-15)
    for a in (0.0, math.pi):
        np.testing.assert_allclose(rotation_matrix(a, "compass"), rotation_matrix(a, "as-written"), atol=1e-15)
    with pytest.raises(ValueError):
        rotation_matrix(0.0, "clockwise")


# --------------------------------------------------------------------------- input vector


def test_input_vector_general_case_by_hand():
    # ΔS = 1, Δθ = 0.5 (clockwise), θ = 0: r = 2, Δx′ = 2(1 − cos .5), Δy′ = 2 sin .5
    u = input_vector(1.0, 0.5, 0.0)
    np.testing.assert_allclose(u, [2 * (1 - math.cos(0.5)), 2 * math.sin(0.5), 0.5])
    # θ = 0.3: the paper rotates that vector counterclockwise by θ
    d = np.array([2 * (1 - math.cos(0.5)), 2 * math.sin(0.5)])
    np.testing.assert_allclose(input_vector(1.0, 0.5, 0.3)[:2], R_ccw(0.3) @ d)
    np.testing.assert_allclose(input_vector(1.0, 0.5, 0.3, rotation="compass")[:2], R_cw(0.3) @ d)


def test_input_vector_special_case_is_exact_zero():
    heading = 1.0
    np.testing.assert_allclose(input_vector(0.5, 0.0, heading), [0.5 * math.sin(1.0), 0.5 * math.cos(1.0), 0.0])
    # the smallest non-zero turn takes the general branch: as written, its sideways
    # component has the opposite sign (the two branches of §3.3.2 disagree) ...
    tiny = input_vector(0.5, 1e-12, heading)
    assert tiny[0] == pytest.approx(-0.5 * math.sin(1.0), rel=1e-9)
    # ... and with the compass-consistent rotation the general branch tends to the special case
    np.testing.assert_allclose(input_vector(0.5, 1e-12, heading, rotation="compass")[:2],
                               [0.5 * math.sin(1.0), 0.5 * math.cos(1.0)], rtol=1e-9)
    # a tolerance widens "Δθ = 0" and then drops the turn, as the special case does
    assert input_vector(0.5, 0.01, heading, straight_tolerance_rad=0.02)[2] == 0.0


def test_arc_reading_prefers_the_creates_reading_and_recovers_it_otherwise():
    record = odo(0.1, 0.3, 0.2)
    assert arc_reading(record) == (0.3, 0.2)
    dx, dy, dth = arc_increment(0.3, 0.2)
    bare = Odometry(0.1, dx, dy, dth, record.covariance)
    assert arc_reading(bare) == pytest.approx((0.3, 0.2), rel=1e-12)
    dx, dy, dth = arc_increment(-0.3, 0.0)
    assert arc_reading(Odometry(0.1, dx, dy, dth, record.covariance)) == pytest.approx((-0.3, 0.0))


def test_measurement_matrix_is_the_papers():
    # §3.3.7's example has three landmarks; here two of them, slots 0 and 2
    H = measurement_matrix([0, 2], 9)
    expected = np.array(
        [
            [-1, 0, 0, 1, 0, 0, 0, 0, 0],
            [0, -1, 0, 0, 1, 0, 0, 0, 0],
            [-1, 0, 0, 0, 0, 0, 0, 1, 0],
            [0, -1, 0, 0, 0, 0, 0, 0, 1],
        ]
    )
    np.testing.assert_array_equal(H, expected)


def test_h_times_equals_the_dense_paper_h():
    rng = np.random.default_rng(6)
    slots, n = [2, 0, 3], 3 + 2 * 5
    H = measurement_matrix(slots, n)
    M = rng.normal(size=(n, n))
    np.testing.assert_allclose(h_times(M, slots), H @ M, atol=1e-14)
    np.testing.assert_allclose(h_times(M.T, slots).T, M @ H.T, atol=1e-14)
    np.testing.assert_allclose(h_times(M[:, 0], slots), H @ M[:, 0], atol=1e-14)


# --------------------------------------------------------------------------- one and two steps by hand


def hand_log():
    """Three steps: see landmark 7; arc and see 7 again; go straight, see new 9 but not 7."""
    return [
        Step(0, 0.0, None, (obs(0.0, 7, 2.0, 0.0),), None),
        Step(1, 0.1, odo(0.1, 1.0, -0.5), (obs(0.1, 7, 1.2, 0.3),), None),
        Step(2, 0.2, odo(0.2, 0.5, 0.0), (obs(0.2, 9, 1.0, -0.4),), None),
    ]


@pytest.mark.parametrize("rotation", ["as-written", "compass"])
@pytest.mark.parametrize("landmark_init", ["as-written", "offset-from-robot"])
def test_one_and_two_steps_by_hand(rotation, landmark_init):
    """Eq. 19–23 with every variance one (``variance_units="m-rad"``), worked by hand.

    Start facing north at the origin, so the paper's frame is the world frame and the
    world heading is π/2 − θ.
    """
    R = R_ccw if rotation == "as-written" else R_cw
    f = EkfS000(make_header(), rotation=rotation, landmark_init=landmark_init, variance_units="m-rad")
    steps = hand_log()

    # step 0: landmark 7 dead ahead at 2 m → (0, 2) (robot at the origin, θ = 0); P = I₅
    f.step(steps[0])
    x, P = f.paper_state()
    np.testing.assert_allclose(x, [0, 0, 0, 0, 2], atol=1e-15)
    np.testing.assert_allclose(P, np.eye(5))

    # step 1 predict: ΔS = 1, Create angle −0.5 (a right turn) → Δθ = +0.5, θ = 0
    u = np.array([2 * (1 - math.cos(0.5)), 2 * math.sin(0.5), 0.5])
    x_pred = np.array([u[0], u[1], 0.5, 0.0, 2.0])
    # update: landmark 7 at range 1.2, bearing 0.3 → x′ = −1.2 sin .3, y′ = 1.2 cos .3,
    # rotated with the predicted heading 0.5
    y = R(0.5) @ np.array([-1.2 * math.sin(0.3), 1.2 * math.cos(0.3)])
    innovation = y - (x_pred[3:5] - x_pred[0:2])
    # P⁻ = diag(2, 2, 2, 1, 1); S = H P⁻ Hᵀ + W = (2 + 1 + 1) I = 4 I
    # K = P⁻ Hᵀ / 4 = [[−½, 0], [0, −½], [0, 0], [¼, 0], [0, ¼]]
    K = np.array([[-0.5, 0], [0, -0.5], [0, 0], [0.25, 0], [0, 0.25]])
    x1 = x_pred + K @ innovation
    P1 = np.array(
        [
            [1.0, 0, 0, 0.5, 0],
            [0, 1.0, 0, 0, 0.5],
            [0, 0, 2.0, 0, 0],
            [0.5, 0, 0, 0.75, 0],
            [0, 0.5, 0, 0, 0.75],
        ]
    )
    f.step(steps[1])
    x, P = f.paper_state()
    np.testing.assert_allclose(x, x1, atol=1e-12)
    np.testing.assert_allclose(P, P1, atol=1e-12)
    pose = f.current_pose()
    np.testing.assert_allclose(pose, [x1[0], x1[1], math.pi / 2 - 0.5], atol=1e-12)
    np.testing.assert_allclose(f.landmarks()[7], x1[3:5], atol=1e-12)
    assert f.step_associations() == [7]

    # step 2 predict: ΔS = 0.5 and an angle of exactly zero → the special case
    # u = (ΔS sin θ, ΔS cos θ, 0) with θ = 0.5; P⁻ = P1 + diag(1, 1, 1, 0, 0)
    x_pred = x1 + np.array([0.5 * math.sin(0.5), 0.5 * math.cos(0.5), 0, 0, 0])
    P_pred = P1 + np.diag([1.0, 1, 1, 0, 0])
    # landmark 7 is not re-observed: y = its prediction (zero innovation), but it stays in
    # H and W. S = (2 − ½ − ½ + ¾ + 1) I = 2.75 I; P⁻Hᵀ = [[−1.5, 0], [0, −1.5], [0, 0],
    # [¼, 0], [0, ¼]]; its landmark rows are zeroed: K = [[−1.5/2.75, 0], [0, −1.5/2.75], 0…]
    k = -1.5 / 2.75
    # x is unchanged; P = P⁻ − K H P⁻ with H P⁻ = [[−1.5, 0, 0, ¼, 0], [0, −1.5, 0, 0, ¼]]
    P2 = P_pred.copy()
    P2[0, 0] = P2[1, 1] = 2.0 - k * -1.5
    P2[0, 3] = P2[1, 4] = 0.5 - k * 0.25  # the landmark's rows keep 0.5: P is not symmetric
    # then landmark 9 is appended: range 1, bearing −0.4, rotated with θ = 0.5
    l9 = R(0.5) @ np.array([-1.0 * math.sin(-0.4), 1.0 * math.cos(-0.4)])
    if landmark_init == "offset-from-robot":
        l9 = l9 + x_pred[0:2]
    x2 = np.concatenate([x_pred, l9])
    P2_full = np.zeros((7, 7))
    P2_full[:5, :5] = P2
    P2_full[5:, 5:] = np.eye(2)  # the fixed landmark covariance, no cross-covariance
    f.step(steps[2])
    x, P = f.paper_state()
    np.testing.assert_allclose(x, x2, atol=1e-12)
    np.testing.assert_allclose(P, P2_full, atol=1e-12)
    assert P[0, 3] != P[3, 0]
    assert f.special_cases == 1
    assert set(f.landmarks()) == {7, 9}
    np.testing.assert_allclose(f.landmarks()[9], l9, atol=1e-12)
    np.testing.assert_allclose(f.trajectory()[:, :2], [[0, 0], x1[:2], x2[:2]], atol=1e-12)
    # the pose covariance leaves the filter symmetrised and in world (ccw) terms
    C = f.current_covariance()
    J = np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, -1.0]])  # north-up: only θ flips
    np.testing.assert_allclose(C, J @ P2[:3, :3] @ J.T, atol=1e-12)


def test_units_change_the_covariance_not_the_mean():
    """"Variances all one" in mm²/deg² vs m²/rad²: same mean, position covariance ×10⁻⁶."""
    header, steps = arena("arena-octagon", 150)
    a = run(EkfS000(header, variance_units="mm-deg"), steps)
    b = run(EkfS000(header, variance_units="m-rad"), steps)
    xa, Pa = a.paper_state()
    xb, Pb = b.paper_state()
    np.testing.assert_allclose(xa, xb, atol=1e-9)
    pos = [i for i in range(len(xa)) if i != 2]
    np.testing.assert_allclose(Pa[np.ix_(pos, pos)], 1e-6 * Pb[np.ix_(pos, pos)], rtol=1e-6, atol=1e-15)
    assert Pa[2, 2] == pytest.approx(math.radians(1) ** 2 * Pb[2, 2])


# --------------------------------------------------------------------------- linear setting vs least squares


def linear_log(rng, n_steps=12, hide=None):
    """North-up start; a pure 0.6 rad turn on the spot; then straight moves (angle exactly 0).

    Two landmarks, both seen at step 0 (so their as-written initial value is right: the
    robot is at the origin). ``hide`` = set of step indices where landmark 1 is not seen.
    Returns the steps and, per step, (u, {id: y}) as the paper would form them by hand.
    """
    truth = {0: np.array([1.5, 2.0]), 1: np.array([-1.0, 3.0])}
    position, heading = np.zeros(2), 0.0
    steps, data = [], []
    for k in range(n_steps + 1):
        if k == 0:
            record, u = None, None
        elif k == 1:
            record, u = odo(0.1 * k, 0.0, -0.6), np.array([0.0, 0.0])  # ΔS = 0: r = 0
            heading = 0.6
        else:
            ds = float(rng.uniform(0.05, 0.2))
            record, u = odo(0.1 * k, ds, 0.0), np.array([ds * math.sin(heading), ds * math.cos(heading)])
        if u is not None:
            position = position + u + rng.normal(scale=0.01, size=2)
        observations, ys = [], {}
        for lid, l in truth.items():
            if hide and lid == 1 and k in hide:
                continue
            # relative position in world axes; into the paper's robot frame with the
            # inverse of the as-written rotation, then into range/bearing (x fwd, y left)
            rel = l - position + rng.normal(scale=0.02, size=2)
            p = R_ccw(heading).T @ rel  # (x′ right, y′ forward)
            x_fwd, y_left = p[1], -p[0]
            observations.append(obs(0.1 * k, lid, math.hypot(x_fwd, y_left), math.atan2(y_left, x_fwd)))
            ys[lid] = R_ccw(heading) @ p  # what the filter will put in its measurement vector
        steps.append(Step(k, 0.1 * k, record, tuple(observations), None))
        data.append((u, ys))
    return steps, data


def least_squares(data, sigma2, ids=(0, 1)):
    """Information-form solution of the filter's linear-Gaussian problem.

    Variables: robot positions r_0..r_K and the landmarks. Factors: r_0 = 0 and each
    landmark = its first measurement (the filter's initial values, each with the fixed
    covariance), r_k − r_{k−1} = u_k, landmark − r_k = y (k ≥ 1); every covariance σ² I.
    Returns the mean and covariance of (r_K, landmarks in ``ids`` order).
    """
    K = len(data) - 1
    n = 2 * (K + 1) + 2 * len(ids)
    lm = {lid: 2 * (K + 1) + 2 * j for j, lid in enumerate(ids)}
    Lam, eta = np.zeros((n, n)), np.zeros(n)

    def add(rows, z):
        A = np.zeros((2, n))
        for col, sign in rows:
            A[:, col : col + 2] += sign * np.eye(2)
        Lam[:] += A.T @ A / sigma2
        eta[:] += A.T @ z / sigma2

    add([(0, 1.0)], np.zeros(2))
    for lid in ids:
        add([(lm[lid], 1.0)], data[0][1][lid])
    for k in range(1, K + 1):
        u, ys = data[k]
        add([(2 * k, 1.0), (2 * (k - 1), -1.0)], u)
        for lid, y in ys.items():
            add([(lm[lid], 1.0), (2 * k, -1.0)], y)
    cov = np.linalg.inv(Lam)
    mean = cov @ eta
    keep = list(range(2 * K, 2 * K + 2)) + [i for lid in ids for i in (lm[lid], lm[lid] + 1)]
    return mean[keep], cov[np.ix_(keep, keep)]


@pytest.mark.parametrize("variance_units, sigma2", [("mm-deg", 1e-6), ("m-rad", 1.0)])
def test_linear_setting_equals_least_squares(variance_units, sigma2):
    """Heading fixed after the first step, straight moves, both landmarks seen every step:
    the paper's filter is then an ordinary linear KF and must equal the batch solution."""
    steps, data = linear_log(np.random.default_rng(2))
    f = run(EkfS000(make_header(), variance_units=variance_units), steps)
    x, P = f.paper_state()
    mean, cov = least_squares(data, sigma2)
    keep = [0, 1, 3, 4, 5, 6]
    np.testing.assert_allclose(x[keep], mean, atol=1e-9)
    np.testing.assert_allclose(P[np.ix_(keep, keep)], cov, rtol=1e-8, atol=1e-12 * sigma2)
    assert x[2] == pytest.approx(0.6)  # the heading: dead reckoning
    assert P[2, 2] == pytest.approx(math.radians(1) ** 2 * 13 if variance_units == "mm-deg" else 13.0)
    assert f.special_cases == len(steps) - 2


def test_gain_zeroing_and_pseudo_measurements_deviate_from_least_squares():
    """Landmark 1 unseen on some steps. Without the paper's two measures the filter is the
    optimal KF (= least squares with those measurements left out); with them it is not:
    the zero-innovation pseudo-measurements shrink P and change the gain, and the zeroed
    gain rows stop the unseen landmark from following the robot's correction."""
    hide = {4, 5, 6, 9}
    steps, data = linear_log(np.random.default_rng(3), hide=hide)
    mean, cov = least_squares(data, 1e-6)
    keep = [0, 1, 3, 4, 5, 6]

    optimal = run(EkfS000(make_header(), pseudo_measurements=False, gain_zeroing=False), steps)
    x, P = optimal.paper_state()
    np.testing.assert_allclose(x[keep], mean, atol=1e-9)
    np.testing.assert_allclose(P[np.ix_(keep, keep)], cov, rtol=1e-8, atol=1e-18)

    paper = run(EkfS000(make_header()), steps)
    x, P = paper.paper_state()
    assert np.abs(x[keep] - mean).max() > 1e-4  # the cost: 4 mm here (2 mm from either measure alone)
    assert np.abs(P - P.T).max() > 1e-8  # the zeroing leaves P non-symmetric
    # the pseudo-measurements make the filter over-confident about its pose
    assert P[0, 0] < cov[0, 0]

    # zeroing alone: on the steps landmark 1 is unseen its estimate does not move
    zero_only = EkfS000(make_header(), pseudo_measurements=False)
    before = None
    for k, step in enumerate(steps):
        zero_only.step(step)
        now = zero_only.landmarks().get(1)
        if k in hide:
            assert now == before
        before = now


# --------------------------------------------------------------------------- edges and bookkeeping


def test_rigid_re_anchoring_moves_every_output_rigidly():
    """The paper's frame is anchored at the start pose, so starting somewhere else must
    only move and rotate the outputs."""
    steps, _ = linear_log(np.random.default_rng(4))
    a = run(EkfS000(make_header(NORTH_UP)), steps)
    start = (1.0, -2.0, 0.7)
    b = run(EkfS000(make_header(start)), steps)
    rot = start[2] - math.pi / 2
    Rz = np.array([[math.cos(rot), -math.sin(rot)], [math.sin(rot), math.cos(rot)]])
    ta, tb = a.trajectory(), b.trajectory()
    np.testing.assert_allclose(tb[:, :2], ta[:, :2] @ Rz.T + start[:2], atol=1e-12)
    np.testing.assert_allclose(wrap_angle(tb[:, 2] - ta[:, 2] - rot), 0.0, atol=1e-12)
    for lid, xy in a.landmarks().items():
        np.testing.assert_allclose(b.landmarks()[lid], Rz @ np.array(xy) + start[:2], atol=1e-12)
    A = np.eye(3)
    A[:2, :2] = Rz
    np.testing.assert_allclose(b.current_covariance(), A @ a.current_covariance() @ A.T, atol=1e-18)


def test_associations_ignore_unknown_and_repeated_ids():
    f = EkfS000(make_header())
    f.step(Step(0, 0.0, None, (obs(0, None, 1.0, 0.0), obs(0, 3, 1.0, 0.1), obs(0, 3, 1.1, 0.1)), None))
    assert f.step_associations() == [None, 3, None]
    assert set(f.landmarks()) == {3}
    with pytest.raises(ValueError):
        EkfS000(make_header(), rotation="ccw")


def arena(scenario, n_steps=None):
    header, records = simulate(scenario, 1)
    steps = group_steps(header, records)
    return header, steps[:n_steps] if n_steps else steps


@pytest.mark.parametrize("scenario", ["arena-octagon", "arena-square"])
@pytest.mark.parametrize(
    "kwargs", [{}, {"rotation": "compass", "landmark_init": "offset-from-robot", "noise": "log"}]
)
def test_runs_on_simulated_arena_logs(scenario, kwargs):
    header, steps = arena(scenario)
    f = run(EkfS000(header, **kwargs), steps)
    assert_arena_run_is_sane(f, steps)
