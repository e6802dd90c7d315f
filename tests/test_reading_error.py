"""Readings with errors correlated in time (ekf.reading_error, slamio.noise.fit_truth).

References:

* the Gauss–Markov step against its closed form and its own composition law;
* the EKF, which decays a landmark's reading errors only when it is seen again, against a
  dense filter written out here that decays every error at every step (the lazy decay is
  exact, so the two agree to round-off, mean, covariance and NIS);
* the correlation fit against series drawn with a known ρ and τ.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from builders import minimal_header
from ekf import EkfSlam
from ekf.models import (
    landmark_init_jacobians,
    motion_jacobians,
    predict_pose,
    range_bearing,
    range_bearing_jacobians,
)
from ekf.reading_error import ReadingErrorModel, gauss_markov_step, reading_error_model
from slamio.geometry import wrap_angle
from slamio.log import Observation, Odometry, Step, as_matrix3
from slamio.noise.fitting import fit_reading_correlation

SHARE, TIME_S = 0.6, 3.0


def test_one_step_is_the_closed_form():
    scale, added = gauss_markov_step(2.0, 4.0, np.array([0.1, 0.02]), np.array([0.2, 0.01]), 0.5)
    phi = math.exp(-0.5)
    np.testing.assert_allclose(scale, [phi * 2.0, phi * 0.5])
    np.testing.assert_allclose(added, [0.5 * 0.04 * (1 - phi**2), 0.5 * 1e-4 * (1 - phi**2)])


def test_two_steps_compose_into_one():
    sigma = np.array([0.05, 0.01])
    var0 = SHARE * sigma**2  # stationary
    s1, a1 = gauss_markov_step(1.3, TIME_S, sigma, sigma, SHARE)
    s2, a2 = gauss_markov_step(0.4, TIME_S, sigma, sigma, SHARE)
    s12, a12 = gauss_markov_step(1.7, TIME_S, sigma, sigma, SHARE)
    np.testing.assert_allclose(s1 * s2, s12)
    np.testing.assert_allclose(s2**2 * (s1**2 * var0 + a1) + a2, s12**2 * var0 + a12)
    np.testing.assert_allclose(s12**2 * var0 + a12, var0)  # the variance stays stationary


def test_the_header_decides():
    header = minimal_header()
    assert reading_error_model(header.noise) is None
    noise = {"observation": {"correlated_share": 0.5, "correlation_time_s": 12.0}}
    assert reading_error_model(noise) == ReadingErrorModel(0.5, 12.0)
    assert reading_error_model({"observation": {"correlated_share": 0.0, "correlation_time_s": 0.0}}) is None
    assert EkfSlam(dataclasses.replace(header, noise=noise)).reading_error == ReadingErrorModel(0.5, 12.0)


# ----------------------------------------------------------------------------- a run with correlated readings


def correlated_run(seed: int, *, steps: int = 90, share: float = SHARE, time_s: float = TIME_S):
    """A robot on a 3 m circle among six landmarks; every reading's error is ``σ·(√ρ·u + √(1−ρ)·n)``
    with u a unit Gauss–Markov process per landmark (correlation time ``time_s``) and σ growing
    with range. Returns (header, steps, true poses)."""
    rng = np.random.default_rng(seed)
    landmarks = {k: (5.0 * math.cos(k * math.pi / 3), 5.0 * math.sin(k * math.pi / 3)) for k in range(6)}
    sigma_odo = np.array([0.02, 0.01, 0.01])
    covariance = as_matrix3(np.diag(sigma_odo**2))
    pose = np.array([3.0, 0.0, math.pi / 2])
    unit = {k: rng.normal(size=2) for k in landmarks}
    seen_at = {k: 0.0 for k in landmarks}
    out, truth, t = [], [pose.copy()], 0.0
    for index in range(steps):
        odometry = None
        if index:
            true_increment = np.array([2 * 3.0 * math.sin(0.05), 0.0, 0.1])
            pose = np.array(predict_pose(pose, true_increment))
            truth.append(pose.copy())
            t += 0.5
            odometry = Odometry(t, *map(float, true_increment + rng.normal(size=3) * sigma_odo), covariance=covariance)
        observations = []
        for k, xy in landmarks.items():
            r, b = range_bearing(pose, xy)
            if r > 6.0:
                continue
            phi = math.exp(-(t - seen_at[k]) / time_s)
            unit[k] = phi * unit[k] + math.sqrt(1 - phi * phi) * rng.normal(size=2)
            seen_at[k] = t
            sigma = np.array([0.02 + 0.01 * r, 0.01])
            error = sigma * (math.sqrt(share) * unit[k] + math.sqrt(1 - share) * rng.normal(size=2))
            observations.append(Observation(t, k, r + error[0], wrap_angle(b + error[1]), *map(float, sigma)))
        out.append(Step(index, t, odometry, tuple(observations), None))
    header = dataclasses.replace(
        minimal_header((3.0, 0.0, math.pi / 2)),
        noise={"odometry": {}, "observation": {"correlated_share": share, "correlation_time_s": time_s}},
    )
    return header, out, np.array(truth)


class EagerFilter:
    """The same EKF written densely: every reading error decays at every step, and the σ
    ratio of :func:`gauss_markov_step` is applied when the landmark is seen."""

    def __init__(self, header):
        self.x = np.array(header.start_pose, float)
        self.P = np.diag(np.square(header.start_sigma))
        self.slot: dict[int, int] = {}
        self.sigma: dict[int, np.ndarray] = {}

    def predict(self, odometry: Odometry, dt_s: float) -> None:
        increment = (odometry.dx_m, odometry.dy_m, odometry.dtheta_rad)
        F, Fi = motion_jacobians(self.x[:3], increment)
        A = np.eye(len(self.x))
        A[:3, :3] = F
        Q = np.zeros_like(self.P)
        Q[:3, :3] = Fi @ np.asarray(odometry.covariance) @ Fi.T
        phi = math.exp(-dt_s / TIME_S)
        for k, i in self.slot.items():
            A[i + 2, i + 2] = A[i + 3, i + 3] = phi
            Q[i + 2 : i + 4, i + 2 : i + 4] = np.diag(SHARE * self.sigma[k] ** 2 * (1 - phi * phi))
        self.x[:3] = predict_pose(self.x[:3], increment)
        self.P = A @ self.P @ A.T + Q
        for i in self.slot.values():
            self.x[i + 2 : i + 4] *= phi

    def _rescale(self, observation: Observation) -> None:
        k = observation.landmark_id
        sigma = np.array([observation.sigma_range_m, observation.sigma_bearing_rad])
        i = self.slot[k]
        A = np.eye(len(self.x))
        A[i + 2, i + 2], A[i + 3, i + 3] = sigma / self.sigma[k]
        self.x, self.P, self.sigma[k] = A @ self.x, A @ self.P @ A.T, sigma

    def innovation(self, observation: Observation):
        i = self.slot[observation.landmark_id]
        H = np.zeros((2, len(self.x)))
        Hp, Hl = range_bearing_jacobians(self.x[:3], self.x[i : i + 2])
        H[:, :3], H[:, i : i + 2], H[:, i + 2 : i + 4] = Hp, Hl, np.eye(2)
        r, b = range_bearing(self.x[:3], self.x[i : i + 2])
        nu = np.array([observation.range_m - r - self.x[i + 2], wrap_angle(observation.bearing_rad - b - self.x[i + 3])])
        R = (1 - SHARE) * np.diag([observation.sigma_range_m**2, observation.sigma_bearing_rad**2])
        return nu, H, H @ self.P @ H.T + R, R

    def nis(self, observation: Observation) -> float:
        saved = (self.x.copy(), self.P.copy(), dict(self.sigma))
        self._rescale(observation)
        nu, _, S, _ = self.innovation(observation)
        self.x, self.P, self.sigma = saved
        return float(nu @ np.linalg.solve(S, nu))

    def observe(self, observation: Observation) -> None:
        k = observation.landmark_id
        sigma = np.array([observation.sigma_range_m, observation.sigma_bearing_rad])
        if k not in self.slot:
            r, b = observation.range_m, observation.bearing_rad
            a = self.x[2] + b
            n = len(self.x)
            Gp, Gz = landmark_init_jacobians(self.x[:3], r, b)
            G = np.zeros((4, n))
            G[:2, :3] = Gp
            Gm = np.vstack([-Gz, np.eye(2)])  # landmark = g(pose, z − e − w); e is the new state
            R = np.diag(sigma**2)
            Pnn = G @ self.P @ G.T + Gm @ (SHARE * R) @ Gm.T
            Pnn[:2, :2] += Gz @ ((1 - SHARE) * R) @ Gz.T
            self.P = np.block([[self.P, (G @ self.P).T], [G @ self.P, Pnn]])
            self.x = np.r_[self.x, self.x[0] + r * math.cos(a), self.x[1] + r * math.sin(a), 0.0, 0.0]
            self.slot[k], self.sigma[k] = n, sigma
            return
        self._rescale(observation)
        nu, H, S, R = self.innovation(observation)
        K = self.P @ H.T @ np.linalg.inv(S)
        self.x = self.x + K @ nu
        self.x[2] = wrap_angle(self.x[2])
        A = np.eye(len(self.x)) - K @ H
        self.P = A @ self.P @ A.T + K @ R @ K.T


def test_the_lazy_decay_is_the_dense_filter():
    header, steps, _ = correlated_run(3)
    ekf = EkfSlam(header, known_id_gate_probability=None)
    reference = EagerFilter(header)
    last_t = steps[0].stamp_s
    compared = 0
    for step in steps:
        predicted = ekf.predicted_nis(step)
        ekf.step(step)
        if step.odometry is not None:
            reference.predict(step.odometry, step.stamp_s - last_t)
        last_t = step.stamp_s
        for observation, nis in zip(step.observations, predicted):
            if observation.landmark_id in reference.slot:
                assert nis == pytest.approx(reference.nis(observation), rel=1e-7)
                compared += 1
        for observation in step.observations:
            reference.observe(observation)
    assert compared > 200
    # the same states in the same order: pose, then per landmark (x, y, range error, bearing error)
    np.testing.assert_allclose(ekf.state_mean(), reference.x, atol=1e-9)
    np.testing.assert_allclose(ekf.state_covariance(), reference.P, atol=1e-11)


def pose_nees(estimator_factory, seeds=range(8)):
    values = []
    for seed in seeds:
        header, steps, truth = correlated_run(seed, share=0.8, time_s=10.0)
        ekf = estimator_factory(header)
        for step, true_pose in zip(steps, truth):
            ekf.step(step)
            e = np.array(ekf.current_pose()) - true_pose
            e[2] = wrap_angle(e[2])
            values.append(e @ np.linalg.solve(ekf.current_covariance(), e))
    return float(np.mean(values))


def test_modelling_the_correlation_keeps_the_filter_consistent():
    """Readings 80 % correlated over 10 s: the filter that models it has a pose NEES near
    χ²(3)'s mean; the one that takes the readings as independent is overconfident."""
    white = pose_nees(lambda h: EkfSlam(dataclasses.replace(h, noise={"odometry": {}, "observation": {}}),
                                        known_id_gate_probability=None))
    modelled = pose_nees(lambda h: EkfSlam(h, known_id_gate_probability=None))
    assert 1.5 < modelled < 4.5
    assert white > 1.5 * modelled


# ----------------------------------------------------------------------------- the fit


def draw_series(seed: int, share: float, time_s: float, landmarks: int = 12, seconds: float = 600.0):
    """Readings about every 0.4 s of one landmark at a time, normalised errors (range, bearing)."""
    rng = np.random.default_rng(seed)
    stamps, ids, values = [], [], []
    unit = rng.normal(size=(landmarks, 2))
    last = np.zeros(landmarks)
    t, current = 0.0, 0
    while t < seconds:
        t += rng.exponential(0.4)
        if rng.random() < 0.05:
            current = int(rng.integers(landmarks))
        phi = math.exp(-(t - last[current]) / time_s) if time_s > 0 else 0.0
        unit[current] = phi * unit[current] + math.sqrt(1 - phi * phi) * rng.normal(size=2)
        last[current] = t
        stamps.append(t)
        ids.append(current)
        values.append(math.sqrt(share) * unit[current] + math.sqrt(1 - share) * rng.normal(size=2))
    return np.array(stamps), np.array(ids), np.array(values)


def test_the_fit_recovers_a_known_correlation():
    fit = fit_reading_correlation(*draw_series(1, 0.6, 10.0))
    assert fit.share == pytest.approx(0.6, abs=0.08)
    assert fit.time_s == pytest.approx(10.0, rel=0.3)


def test_white_readings_fit_as_white():
    fit = fit_reading_correlation(*draw_series(2, 0.0, 0.0))
    assert fit.share == 0.0
