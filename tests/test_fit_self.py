"""slamio.noise.fit_self: the hat-matrix traces against the exact diagonal, and variance-
component estimation against a linear model whose variances are known."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from slamio.noise.fit_self import (
    component_shares, hat_traces, pair_weights, parabola_minimum, ranges_from_readings, relative_std, scaled_increments,
    scoring_step,
    vce_from_sums, vce_step,
)


def exact_hat_diagonal(A) -> np.ndarray:
    dense = A.toarray()
    return np.einsum("ij,ji->i", dense, np.linalg.solve(dense.T @ dense, dense.T))


def random_design(m=600, n=40, seed=1):
    rng = np.random.default_rng(seed)
    A = sp.random(m, n, density=0.08, random_state=seed, format="csr") + sp.eye(m, n, format="csr")
    return sp.csr_matrix(A), rng


def test_hat_traces_match_the_exact_hat_diagonal():
    A, rng = random_design()
    weights = rng.uniform(0.0, 1.0, size=(A.shape[0], 3))
    exact = weights.T @ exact_hat_diagonal(A)
    estimate = hat_traces(A, weights, probes=2000)
    assert estimate == pytest.approx(exact, rel=0.04)
    # the hat matrix is a projection on the n columns: its trace is n
    assert hat_traces(A, np.ones((A.shape[0], 1)), probes=2000)[0] == pytest.approx(A.shape[1], rel=0.03)


def test_shares_of_a_row_sum_to_one():
    var, w = component_shares(np.array([2.0, 3.0]), np.array([[1.0, 0.0], [1.0, 1.0], [0.0, 0.0]]))
    assert var.tolist() == [2.0, 5.0, 0.0]
    assert w.sum(axis=1).tolist() == pytest.approx([1.0, 1.0, 0.0])


def _linear_vce(step_kind: str, true_theta, q, seed=3, iterations=40):
    """Least squares on y = A x + e with Var(e_j) = q_j·θ, θ re-estimated by VCE."""
    m = len(q)
    A, rng = random_design(m=m, n=30, seed=seed)
    x_true = rng.normal(size=A.shape[1])
    y = A @ x_true + rng.normal(size=m) * np.sqrt(q @ true_theta)
    theta = np.ones(len(true_theta))
    for _ in range(iterations):
        var, w = component_shares(theta, q)
        s = 1.0 / np.sqrt(var)
        Aw = sp.diags(s) @ A
        x = sp.linalg.lsqr(Aw, s * y, atol=1e-12, btol=1e-12)[0]
        e2 = (s * (y - A @ x)) ** 2
        if step_kind == "forstner":
            step = vce_step(theta, e2, w, hat_traces(Aw, w, probes=400))
        else:
            pairs = pair_weights(w)
            hat = hat_traces(Aw, np.hstack([w, pairs]), probes=400)
            C = len(theta)
            step = scoring_step(theta, w.T @ e2, w.sum(axis=0) - hat[:C], pairs.sum(axis=0), hat[C:])
        theta = step.theta
    return theta, step


@pytest.mark.parametrize("kind", ["forstner", "scoring"])
def test_vce_recovers_the_variances_of_two_groups(kind):
    m = 4000
    q = np.zeros((m, 2))
    q[: m // 2, 0] = 1.0
    q[m // 2:, 1] = 1.0
    theta, step = _linear_vce(kind, np.array([0.01, 0.25]), q)
    assert np.sqrt(theta) == pytest.approx([0.1, 0.5], rel=0.06)
    assert step.ratio == pytest.approx([1.0, 1.0], abs=0.02)


def test_scoring_separates_a_constant_and_a_growing_variance():
    """σ² = θ₀ + θ₁ r² (a range σ that grows with range), both terms recovered."""
    rng = np.random.default_rng(5)
    m = 6000
    r = rng.uniform(0.5, 5.0, size=m)
    q = np.stack([np.ones(m), r**2], axis=1)
    theta, _ = _linear_vce("scoring", np.array([0.02**2, 0.03**2]), q, seed=5)
    assert np.sqrt(theta) == pytest.approx([0.02, 0.03], rel=0.15)


def test_a_component_without_redundancy_is_not_updated():
    step = vce_from_sums(np.array([1.0, 2.0]), np.array([10.0, 0.5]), np.array([5.0, 1.0]))
    assert step.determined.tolist() == [True, False]
    assert step.theta[1] == 2.0 and step.theta[0] == pytest.approx(2.0)
    assert np.isnan(step.ratio[1])


def test_relative_std_flags_components_the_data_cannot_tell_apart():
    m = 1000
    w_apart = np.zeros((m, 2))
    w_apart[: m // 2, 0] = w_apart[m // 2:, 1] = 1.0
    assert np.all(relative_std(np.ones(2), w_apart) < 0.1)
    w_same = np.full((m, 2), 0.5)  # every row explained half by each: only their sum is seen
    assert np.all(relative_std(np.ones(2), w_same) >= 1.0)


def test_the_odometry_lag_is_found_from_the_readings_alone():
    """A robot driving and turning among landmarks whose odometry runs 0.24 s ahead of its
    motion (the motion at t is what the odometry said at t − 0.24): the lag is found from the
    readings' bearings, with no truth and no noise model."""
    from slamio.noise.dead_reckoning import DeadReckoning
    from slamio.noise.fit_self import lag_from_readings

    rng = np.random.default_rng(2)
    dt, lag = 0.1, 0.24
    t = np.arange(0.0, 120.0, dt)
    v = 0.2 + 0.1 * np.sin(t / 7.0)
    w = 0.6 * np.sin(t / 3.0) + 0.3 * np.sign(np.sin(t / 11.0))

    def integrate(times):
        pose = np.zeros((len(times), 3))
        for k in range(1, len(times)):
            h = times[k] - times[k - 1]
            vk, wk = np.interp(times[k - 1], t, v), np.interp(times[k - 1], t, w)
            x, y, th = pose[k - 1]
            pose[k] = (x + vk * h * np.cos(th + wk * h / 2), y + vk * h * np.sin(th + wk * h / 2), th + wk * h)
        return pose

    fine = np.arange(0.0, 120.0, 0.01)
    truth = integrate(fine)  # the motion, commanded at t and happening at t + lag
    odometry_poses = truth[::10]  # the odometry at its stamps t_k: where the robot will be at t_k + lag
    increments = []
    for a, b in zip(odometry_poses, odometry_poses[1:]):
        c, s = np.cos(a[2]), np.sin(a[2])
        d = b[:2] - a[:2]
        increments.append((c * d[0] + s * d[1], -s * d[0] + c * d[1], b[2] - a[2]))
    chain = DeadReckoning(t, np.array(increments))
    landmarks = rng.uniform(-6.0, 6.0, size=(25, 2))
    readings = []
    for k in range(0, len(fine), 20):  # a picture every 0.2 s of the motion's own time
        x, y, th = truth[k]
        for j, (lx, ly) in enumerate(landmarks):
            r = np.hypot(lx - x, ly - y)
            b = np.arctan2(ly - y, lx - x) - th
            if r < 4.0 and abs(np.angle(np.exp(1j * b))) < 0.6:
                readings.append((fine[k] + lag, j, r, float(np.angle(np.exp(1j * (b + rng.normal(0, 0.005)))))))
    found = lag_from_readings(chain, readings)
    assert found.pairs > 100
    assert found.lag_s == pytest.approx(lag, abs=0.03)
    assert found.cost[0] > 2 * found.cost.min()


def test_scaled_increments_inverts_a_known_distortion():
    """Increments distorted from known true ones by forward scale 0.95, turn scale 0.93 and
    −0.04 rad/m (a reverse stretch included) come back exactly."""
    rng = np.random.default_rng(3)
    true = np.column_stack([rng.uniform(-0.02, 0.05, 50), rng.normal(0, 0.001, 50), rng.normal(0, 0.03, 50)])
    d_true = np.hypot(true[:, 0], true[:, 1]) * np.sign(true[:, 0])
    read = np.column_stack([true[:, :2] / 0.95, (true[:, 2] - (-0.04) * d_true) / 0.93])
    np.testing.assert_allclose(scaled_increments(read, 0.95, 0.93, -0.04), true, atol=1e-12)
    np.testing.assert_allclose(scaled_increments(read, 1.0, 1.0, 0.0), read)


def test_parabola_minimum_of_a_known_parabola():
    f = lambda x: 3.0 * (x - 0.937) ** 2 + 5.0  # noqa: E731
    x = np.array([0.8, 0.9, 1.05])
    assert parabola_minimum(x, f(x)) == pytest.approx(0.937, abs=1e-12)
    assert parabola_minimum(x, -f(x)) is None
    assert parabola_minimum(x, 2.0 * x) is None
    assert parabola_minimum(np.array([0.8, 0.8, 1.0]), np.array([1.0, 1.0, 2.0])) is None


def test_ranges_from_readings_agree_with_applying_the_model():
    """The range model's inverse and σ factor are those of slamio.noise.apply (scale 1)."""
    from slamio.noise.apply import correct_observation
    from slamio.noise.model import ObservationModel

    rng = np.random.default_rng(4)
    measured, bearing = rng.uniform(0.5, 4.0, 30), rng.uniform(-0.6, 0.6, 30)
    for depth, bias in ((False, 0.0), (True, 0.045), (False, -0.03)):
        model = ObservationModel(range_is_depth=depth, range_bias_m=bias, range_sigma_m=0.1, bearing_sigma_rad=1e-6)
        ranges, factor = ranges_from_readings(measured, bearing, depth, bias)
        for m, b, r, f in zip(measured, bearing, ranges, factor):
            r_ref, _, sigma_ref, _ = correct_observation(model, m, b, 0.0)
            assert r == pytest.approx(r_ref, rel=1e-12)
            assert 0.1 * f == pytest.approx(sigma_ref, rel=1e-6)
