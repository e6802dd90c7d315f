"""Robust kernels in fgslam.smoother against real GTSAM: each landmark factor's error is the
kernel of its whitened norm (checked with numpy), odometry stays Gaussian, and robust iSAM2
keeps simulated runs with 10 % outliers within 1.2× of the clean run's error.
"""

from __future__ import annotations

import math

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import L, X

from fgslam.compare import ate_rmse_m
from fgslam.smoother import DEFAULT_ROBUST_K, Isam2Smoother, batch_solve
from slamio.errors import FgslamError
from slamio.geometry import compose_pose, wrap_angle
from slamio.log import Observation, Odometry, Step, as_matrix3, group_steps
from builders import run_smoother as run
from loop_logs import make_header, make_loop_log, pose_difference

def numpy_kernel_loss(kernel: str, k: float, r: float) -> float:
    """Huber / Cauchy / Tukey loss of a whitened residual norm r (Huber 1964; Cauchy and
    Tukey's biweight as GTSAM scales them)."""
    if kernel == "huber":
        return 0.5 * r * r if r <= k else k * r - 0.5 * k * k
    if kernel == "tukey":
        return k * k / 6.0 * (1.0 - (1.0 - (r / k) ** 2) ** 3) if r <= k else k * k / 6.0
    if kernel == "dcs":  # Agarwal et al. 2013: weight min(1, (2Φ/(Φ + r²))²), Φ = k²; ρ' = r·weight
        phi = k * k
        return 0.5 * r * r if r * r <= phi else 1.5 * phi - 2.0 * phi * phi / (phi + r * r)
    return 0.5 * k * k * math.log1p((r / k) ** 2)


@pytest.mark.parametrize("kernel", ["huber", "cauchy", "tukey", "dcs"])
@pytest.mark.parametrize("k", [None, 0.8, 3.0])
def test_robust_landmark_factor_error_is_the_kernel_of_the_whitened_norm(kernel, k):
    pose, landmark = (1.0, -2.0, 0.7), (3.0, 1.5)
    sb, sr = 0.03, 0.2
    true_range = math.hypot(landmark[0] - pose[0], landmark[1] - pose[1])
    true_bearing = wrap_angle(math.atan2(landmark[1] - pose[1], landmark[0] - pose[0]) - pose[2])
    values = gtsam.Values()
    values.insert(X(0), gtsam.Pose2(*pose))
    values.insert(L(9), gtsam.Point2(*landmark))
    width = DEFAULT_ROBUST_K[kernel] if k is None else k
    for db, dr in [(0.0, 0.0), (0.01, 0.05), (0.02, -0.3), (0.5, 1.0), (-1.2, 2.5)]:
        smoother = Isam2Smoother(make_header(start_pose=pose), robust=kernel, robust_k=k)
        obs = Observation(0.0, 9, true_range + dr, wrap_angle(true_bearing + db), sr, sb)
        # seen twice: in robust mode a landmark enters once two observations agree
        smoother.step(Step(0, 0.0, None, (obs, obs), None))
        graph = smoother.graph()
        assert graph.size() == 3
        r = math.hypot(db / sb, dr / sr)
        assert graph.at(1).error(values) == pytest.approx(numpy_kernel_loss(kernel, width, r), rel=1e-9, abs=1e-15)
        assert graph.at(0).error(values) == pytest.approx(0.0, abs=1e-15)  # the prior is untouched


def test_robust_kernel_leaves_odometry_gaussian_and_names_the_estimator():
    Q = np.diag([4e-4, 1e-4, 2.5e-4])
    n = np.array([0.2, -0.1, 0.3])  # many σ: a robust kernel would cap this
    start = (0.5, 0.2, -1.0)
    header = make_header(start_pose=start)
    assert Isam2Smoother(header, robust="huber").name == "isam2-huber"
    values = gtsam.Values()
    values.insert(X(0), gtsam.Pose2(*start))
    values.insert(X(1), gtsam.Pose2(*compose_pose(start, (0.3, 0.0, 0.0))))
    odometry = Odometry(0.1, *(np.array([0.3, 0.0, 0.0]) + n), covariance=as_matrix3(Q))
    errors = {}
    for robust in (None, "cauchy"):
        smoother = Isam2Smoother(header, robust=robust)
        smoother.step(Step(0, 0.0, None, (), None))
        smoother.step(Step(1, 0.1, odometry, (), None))
        errors[smoother.name] = smoother.graph().at(1).error(values)
    assert errors["isam2-cauchy"] == errors["isam2"] > 100  # far outside any kernel, not capped


@pytest.mark.parametrize(
    "kwargs", [{"robust": "welsch"}, {"robust": "huber", "robust_k": 0.0}, {"robust": "cauchy", "robust_k": float("nan")},
               {"robust_k": 2.0}]
)
def test_bad_robust_arguments_raise(kwargs):
    with pytest.raises(FgslamError, match="robust"):
        Isam2Smoother(make_header(), **kwargs)


def test_robust_batch_solve_uses_the_robust_graph():
    """Exact loop log with the first sighting of two landmarks replaced by misdetections.

    Robust iSAM2 seeds each landmark only from two observations that agree, so the two
    misdetections never seed anything; gated against the landmarks' estimates they are
    dropped, and iSAM2 and the batch solve end at the truth. Least squares is dragged
    metres away.
    """
    header, steps, truth, _ = make_loop_log(n_steps=200)
    first = steps[0].observations
    assert len(first) == 2
    wrong = tuple(Observation(o.stamp_s, o.landmark_id, 0.4 * o.range_m + 1.0, o.bearing_rad + 0.6,
                              o.sigma_range_m, o.sigma_bearing_rad) for o in first)
    steps = [Step(0, 0.0, None, wrong, steps[0].truth)] + steps[1:]
    plain = run(header, steps)
    cauchy = run(header, steps, robust="cauchy")
    batch = batch_solve(cauchy)
    assert batch.initial_error == pytest.approx(cauchy.error(), rel=1e-12)
    assert batch.final_error <= batch.initial_error
    assert cauchy.error() < 1e-12  # exact data and no misdetection in the graph: zero error
    assert pose_difference(batch.trajectory, cauchy.trajectory())[0] < 1e-6
    assert pose_difference(cauchy.trajectory(), truth)[0] < 1e-6
    assert pose_difference(plain.trajectory(), truth)[0] > 1.0
    assert cauchy.dropped_observations == 2 and cauchy.unconfirmed_observations == 0
    # the graph batch_solve optimises holds robust landmark factors, Gaussian odometry
    kinds = [type(cauchy.graph().at(i).noiseModel()).__name__ for i in range(cauchy.graph().size())]
    n_obs = sum(len(s.observations) for s in steps) - 2
    assert kinds.count("Robust") == n_obs and len(kinds) == n_obs + len(steps)
    assert "Robust" not in [type(plain.graph().at(i).noiseModel()).__name__ for i in range(plain.graph().size())]


@pytest.fixture(scope="module")
def octagon_with_outliers():
    """Arena-octagon seed 1, clean and with 10 % outliers in both simulator modes.

    ``replaced``: misdetections take the place of observations; ``oracle`` is that log with
    exactly the outliers removed (they are the observations that differ from the clean
    log). ``added``: every observation is kept and misdetections come on top, so the
    outlier-free log is the clean one.
    """
    from slamio.sim import simulate

    header, clean_records = simulate("arena-octagon", 1)
    clean = group_steps(header, clean_records)
    replaced = group_steps(*simulate("arena-octagon", 1, outliers=0.1))
    added = group_steps(*simulate("arena-octagon", 1, outliers=0.1, outlier_mode="add"))
    oracle = [
        Step(b.index, b.stamp_s, b.odometry,
             tuple(o1 for o0, o1 in zip(a.observations, b.observations) if o0 == o1), b.truth)
        for a, b in zip(clean, replaced)
    ]
    truth = np.array([[s.truth.x_m, s.truth.y_m, s.truth.theta_rad] for s in clean])
    ate = lambda steps, **kw: ate_rmse_m(run(header, steps, **kw).trajectory(), truth)  # noqa: E731
    return ate, {"clean": clean, "replaced": replaced, "added": added, "oracle": oracle}


def test_outliers_ruin_least_squares(octagon_with_outliers):
    ate, logs = octagon_with_outliers
    # measured: 0.165 m (replaced) and 0.146 m (added) against 0.0076 m without outliers
    assert ate(logs["replaced"]) > 5 * ate(logs["clean"])
    assert ate(logs["added"]) > 5 * ate(logs["clean"])


@pytest.mark.parametrize("kernel", ["huber", "cauchy", "tukey", "dcs"])
def test_robust_isam2_with_10_percent_outliers_stays_within_1_2x_of_clean(octagon_with_outliers, kernel):
    """The issue's criterion, with the outliers added to the clean log (``--outlier-mode
    add``). Measured on this seed: clean 0.0076 m; Huber 0.0076 (1.00×), Cauchy 0.0078
    (1.03×), Tukey 0.0074 (0.98×), DCS 0.0076 (1.00×). Seeds 1–10: all ≤ 1.16×
    (docs/performance.md)."""
    ate, logs = octagon_with_outliers
    clean = ate(logs["clean"])
    robust = ate(logs["added"], robust=kernel)
    assert robust <= 1.2 * clean, f"{kernel}: ATE {robust:.4f} m vs {clean:.4f} m without outliers"


@pytest.mark.parametrize("kernel", ["huber", "cauchy", "tukey", "dcs"])
def test_robust_isam2_with_replaced_observations_stays_within_1_2x_of_the_oracle(octagon_with_outliers, kernel):
    """When misdetections *replace* observations, the outlier-free ATE is out of reach
    (the oracle that drops exactly the outliers scores 0.0092 m vs 0.0076 m: it has 10 %
    fewer good observations), so the reference is the oracle. Measured: Huber 0.0103 m
    (1.13×), Cauchy 0.0099 m (1.07×), Tukey 0.0092 m (1.00×), DCS 0.0092 m (1.01×)."""
    ate, logs = octagon_with_outliers
    reference = ate(logs["oracle"])
    robust = ate(logs["replaced"], robust=kernel)
    assert robust <= 1.2 * reference, f"{kernel}: ATE {robust:.4f} m vs {reference:.4f} m with the outliers removed"
