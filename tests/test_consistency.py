"""NIS of each observation and the peak-memory measurement, against independent references.

* ``range_bearing_nis`` against the textbook formula with a finite-difference Jacobian;
* the EKF's ``predicted_nis`` against a brute-force full-state computation (a copy of the
  filter predicted through the public ``step``, the full H by finite differences);
* iSAM2's ``predicted_nis`` against GTSAM's batch ``Marginals`` of the graph with the new
  pose added (independent of the smoother's covariance propagation);
* on the bundled log, both estimators' NIS are χ²(2)-like (mean ≈ 2, ≈ 95 % inside the band);
* ``PeakMemory`` sees a known allocation.
"""

from __future__ import annotations

import copy
import math

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import L, X

from ekf import EkfSlam
from ekf.models import range_bearing, range_bearing_nis
from fgslam.compare import nees_band
from fgslam.memory import PeakMemory
from fgslam.runner import run_estimator
from fgslam.smoother import FAST_SETTINGS, Isam2Smoother, odometry_noise_covariance
from jacobians import numeric_jacobian
from slamio.geometry import wrap_angle
from slamio.log import Step, read_log

BUNDLED = "data/arena_octagon.jsonl"


@pytest.fixture(scope="module")
def log():
    return read_log(BUNDLED)




def _measure(state, landmark_index=3):
    return np.array(range_bearing(state[:3], state[landmark_index : landmark_index + 2]))


def test_range_bearing_nis_matches_the_formula():
    rng = np.random.default_rng(3)
    for _ in range(20):
        pose = np.array([rng.normal(), rng.normal(), rng.uniform(-math.pi, math.pi)])
        landmark = pose[:2] + rng.uniform(0.5, 4.0) * np.array([math.cos(a := rng.uniform(0, 6.28)), math.sin(a)])
        A = rng.normal(size=(5, 5))
        joint = 0.01 * A @ A.T + 1e-4 * np.eye(5)
        R = np.diag([0.02**2, 0.01**2])
        z = _measure(np.r_[pose, landmark]) + rng.normal(0, 0.05, 2)
        H = numeric_jacobian(_measure, np.r_[pose, landmark], angle_rows=(1,))
        nu = z - _measure(np.r_[pose, landmark])
        nu[1] = wrap_angle(nu[1])
        expected = nu @ np.linalg.solve(H @ joint @ H.T + R, nu)
        assert range_bearing_nis(pose, landmark, joint, z[0], z[1], R) == pytest.approx(expected, rel=1e-6)


def test_ekf_predicted_nis_equals_a_full_state_computation(log):
    steps = log.steps()
    ekf = EkfSlam(log.header)
    checked = 0
    for step in steps[:200]:
        if step.odometry is not None and checked < 40:
            nis = ekf.predicted_nis(step)
            # Reference: predict a copy through the public step (no observations), then the
            # full-state innovation covariance with H over the whole state by finite differences.
            twin = copy.deepcopy(ekf)
            twin.step(Step(step.index, step.stamp_s, step.odometry, (), step.truth))
            mean, P = twin.state_mean(), twin.state_covariance()
            for value, obs in zip(nis, step.observations):
                if obs.landmark_id is None or obs.landmark_id not in ekf.landmarks():
                    assert value is None
                    continue
                i = twin.landmark_index(obs.landmark_id)

                def h(state, i=i):
                    return np.array(range_bearing(state[:3], state[i : i + 2]))

                H = numeric_jacobian(h, mean, angle_rows=(1,))
                nu = np.array([obs.range_m, obs.bearing_rad]) - h(mean)
                nu[1] = wrap_angle(nu[1])
                S = H @ P @ H.T + np.diag([obs.sigma_range_m**2, obs.sigma_bearing_rad**2])
                assert value == pytest.approx(float(nu @ np.linalg.solve(S, nu)), rel=1e-5)
                checked += 1
        ekf.step(step)
    assert checked >= 40


def test_isam2_predicted_nis_equals_batch_marginals(log):
    steps = log.steps()
    # one update per step: the reference below takes the previous pose as iSAM2 holds it
    # (graph() and estimate() would flush held steps and change what is compared)
    smoother = Isam2Smoother(log.header, relinearize_threshold=1e-6, relinearize_skip=1, update_every=1)
    checked = 0
    for step in steps[:120]:
        if step.index >= 30 and step.index % 9 == 0 and any(
            o.landmark_id is not None and smoother._isam.valueExists(L(o.landmark_id)) for o in step.observations
        ):
            nis = smoother.predicted_nis(step)
            # Reference: the whole graph so far plus the new pose's odometry factor, batch
            # marginals (GTSAM, not the smoother's propagation) at iSAM2's linearisation
            # point, where iSAM2's own marginals are taken; means from the estimate.
            k, odo = step.index, step.odometry
            graph, values = smoother.graph(), smoother.estimate()
            linearised = gtsam.Values(smoother._isam.getLinearizationPoint())
            increment = gtsam.Pose2(odo.dx_m, odo.dy_m, odo.dtheta_rad)
            noise = gtsam.noiseModel.Gaussian.Covariance(odometry_noise_covariance(odo))
            graph.add(gtsam.BetweenFactorPose2(X(k - 1), X(k), increment, noise))
            pose = values.atPose2(X(k - 1)).compose(increment)
            values.insert(X(k), pose)
            linearised.insert(X(k), linearised.atPose2(X(k - 1)).compose(increment))
            marginals = gtsam.Marginals(graph, linearised)
            c, s = math.cos(pose.theta()), math.sin(pose.theta())  # body → world at the estimate
            to_world = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
            for value, obs in zip(nis, step.observations):
                if obs.landmark_id is None or not smoother._isam.valueExists(L(obs.landmark_id)):
                    continue
                keys = gtsam.KeyVector([X(k), L(obs.landmark_id)])
                joint = marginals.jointMarginalCovariance(keys)
                cov = np.zeros((5, 5))
                cov[:3, :3] = to_world @ joint.at(X(k), X(k)) @ to_world.T
                cov[:3, 3:] = to_world @ joint.at(X(k), L(obs.landmark_id))
                cov[3:, :3] = cov[:3, 3:].T
                cov[3:, 3:] = joint.at(L(obs.landmark_id), L(obs.landmark_id))
                expected = range_bearing_nis(
                    (pose.x(), pose.y(), pose.theta()), values.atPoint2(L(obs.landmark_id)), cov,
                    obs.range_m, obs.bearing_rad, np.diag([obs.sigma_range_m**2, obs.sigma_bearing_rad**2]),
                )
                assert value == pytest.approx(expected, rel=1e-6, abs=1e-9)
                checked += 1
        smoother.step(step)
    assert checked >= 10


@pytest.mark.parametrize("name", ["ekf", "isam2", "isam2-fast"])
def test_nis_on_the_bundled_log_is_chi_square_2(log, name):
    """A consistent estimator's NIS averages 2 with about 95 % inside the χ²(2) band."""
    estimator = EkfSlam(log.header) if name == "ekf" else (
        Isam2Smoother(log.header) if name == "isam2" else Isam2Smoother(log.header, **FAST_SETTINGS)
    )
    run, _ = run_estimator(estimator, log.steps())
    values = run.nis[np.isfinite(run.nis)]
    assert len(values) > (600 if name != "isam2-fast" else 100)
    low, high = nees_band(2)
    assert 1.6 < values.mean() < 2.4
    assert 0.92 < np.mean((values >= low) & (values <= high)) < 0.98
    assert len(run.nis_steps) == len(run.nis) and np.all(np.diff(run.nis_steps) >= 0)


def test_peak_memory_sees_a_known_allocation():
    size = 64_000_000
    with PeakMemory() as memory:
        block = np.ones(size // 8)  # touched: resident
        del block
    if memory.peak_bytes is None:
        pytest.skip("no /proc/self/clear_refs on this system")
    assert 0.97 * size <= memory.peak_bytes < size + 16_000_000
    with PeakMemory() as small:
        np.ones(1000)
    assert small.peak_bytes < 8_000_000


def test_runner_reports_peak_memory(log):
    run, _ = run_estimator(EkfSlam(log.header), log.steps()[:50])
    assert run.peak_memory_bytes is not None and run.peak_memory_bytes >= 0
