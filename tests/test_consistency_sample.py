"""The seeded sample of steps ``fgslam run`` takes NEES and NIS at (fgslam.consistency_sample).

The sample must be reproducible (the same steps from the same log, every time), take the
values the every-step mode takes at its steps (sampling changes which steps, never a value),
and the every-step mode must give the figures an estimator states step by step (checked
against the EKF driven by hand).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from ekf import EkfSlam
from fgslam.compare import compute_metrics, format_table
from fgslam.consistency_sample import ELLIPSE_STEPS, sample_size, choose_steps, every_step, in_band_se, sample_of_steps
from fgslam.runner import compare_log, run_estimator, truth_reference
from fgslam.smoother import Isam2Smoother
from slamio.log import read_log

BUNDLED = "data/arena_octagon.jsonl"


@pytest.fixture(scope="module")
def log():
    return read_log(BUNDLED)


def test_the_sample_is_deterministic_and_drawn_from_the_candidates():
    has_truth = np.ones(1000, dtype=bool)
    has_truth[100:200] = False  # a gap in the truth: no NEES step there
    has_observations = np.zeros(1000, dtype=bool)
    has_observations[::3] = True
    a = choose_steps(has_truth, has_observations, size=50)
    b = choose_steps(has_truth.copy(), has_observations.copy(), size=50)
    assert np.array_equal(a.nees, b.nees) and np.array_equal(a.nis, b.nis)
    assert a.nees.sum() == 50 and a.nis.sum() == 50
    assert not a.nees[100:200].any() and np.all(a.nis <= has_observations)
    other = choose_steps(has_truth, has_observations, size=50, seed=1)
    assert not np.array_equal(a.nees, other.nees)
    gaps = np.diff(np.flatnonzero(a.nees))
    assert len(set(gaps.tolist())) > 5  # not a stride
    assert a.description() == {"mode": "sampled", "seed": a.seed, "steps": 1000, "nees_steps": 50, "nis_steps": 50}


def test_few_candidates_are_all_taken_and_no_truth_samples_every_step():
    has_observations = np.zeros(30, dtype=bool)
    has_observations[[2, 5, 7]] = True
    sample = choose_steps(np.zeros(30, dtype=bool), has_observations, size=10)
    assert np.array_equal(sample.nis, has_observations)
    # no truth, no NEES: the covariance at ELLIPSE_STEPS steps spread evenly, for the report's ellipses
    assert sample.nees.sum() == ELLIPSE_STEPS and sample.nees[0] and sample.nees[-1]
    assert choose_steps(np.ones(8, dtype=bool), has_observations[:8], size=10).nees.all()


def test_sample_of_a_log_is_the_same_every_time(log):
    steps = log.steps()
    a, b = sample_of_steps(steps, "sampled"), sample_of_steps(steps, "sampled")
    assert np.array_equal(a.nees, b.nees) and np.array_equal(a.nis, b.nis)
    assert sample_size(len(steps)) == 50 and sample_size(6969) == 70  # 1 % of the steps, at least 50
    assert a.nees.sum() == 50
    observed = np.array([len(s.observations) > 0 for s in steps])
    assert np.all(a.nis <= observed) and a.nis.sum() == 50
    assert sample_of_steps(steps, "none") is None
    assert sample_of_steps(steps, "all").nees.all()
    with pytest.raises(ValueError):
        sample_of_steps(steps, "some")


def test_every_step_mode_gives_the_ekfs_own_covariances_and_nis(log):
    """The reference: the EKF driven by hand, its NIS asked before each step and P read after."""
    steps = log.steps()[:300]
    ekf = EkfSlam(log.header)
    covariances, nis = [], []
    for step in steps:
        nis += [v for v in ekf.predicted_nis(step) if v is not None]
        ekf.step(step)
        covariances.append(np.array(ekf.current_covariance()))
    for sample in (None, every_step(len(steps))):
        run, _ = run_estimator(EkfSlam(log.header), steps, sample=sample)
        np.testing.assert_array_equal(run.online_covariances, np.array(covariances))
        np.testing.assert_array_equal(run.nis, np.array(nis))
        assert run.consistency["mode"] == "all" and run.consistency["nees_steps"] == len(steps)


@pytest.mark.parametrize("make", [EkfSlam, Isam2Smoother], ids=["ekf", "isam2"])
def test_sampled_values_are_the_every_step_values_at_the_sampled_steps(log, make):
    steps = log.steps()[:400]
    sample = choose_steps(np.ones(len(steps), dtype=bool),
                          np.array([len(s.observations) > 0 for s in steps]), size=60)
    every, _ = run_estimator(make(log.header), steps)
    sampled, _ = run_estimator(make(log.header), steps, sample=sample)
    np.testing.assert_array_equal(sampled.online, every.online)  # asking less changes no estimate
    np.testing.assert_allclose(sampled.online_covariances[sample.nees], every.online_covariances[sample.nees],
                               rtol=1e-9, atol=1e-15)
    assert np.isnan(sampled.online_covariances[~sample.nees]).all()
    keep = sample.nis[every.nis_steps]
    np.testing.assert_array_equal(sampled.nis_steps, every.nis_steps[keep])
    np.testing.assert_allclose(sampled.nis, every.nis[keep], rtol=1e-9)
    assert sampled.consistency == sample.description()
    assert sampled.consistency_cpu_s is not None and sampled.cpu_time_s > 0
    # the map's covariances after the run are consistency work too, counted within it
    assert sampled.landmark_covariances and 0.0 <= sampled.map_covariance_cpu_s <= sampled.consistency_cpu_s
    alone, _ = run_estimator(make(log.header), steps, covariances=False)
    assert alone.consistency_cpu_s is None and alone.map_covariance_cpu_s is None and not alone.landmark_covariances


def test_metrics_and_table_say_how_many_steps_and_the_standard_error(log):
    steps = log.steps()
    reference = truth_reference(log)
    sample = sample_of_steps(steps, "sampled")
    run, _ = run_estimator(EkfSlam(log.header), steps, sample=sample)
    m = compute_metrics([run], reference, log_path=BUNDLED)
    entry = m[run.name]
    assert entry["nees_count"] == int(np.count_nonzero(sample.nees & reference.has_pose))
    p, n = entry["nees_inside_95"], entry["nees_count"]
    q = (p * n + 2) / (n + 4)  # Agresti and Coull's adjusted share
    assert entry["nees_inside_95_se"] == pytest.approx(math.sqrt(q * (1 - q) / (n + 4)))
    # the NIS's: by step (a step's observations share its pose), from the values drawn afresh
    inside = [(v >= 0.0506356) & (v <= 7.37776) if d == 2 else (v >= 0.000982069) & (v <= 5.02389)
              for v, d in zip(run.nis, run.nis_dofs)]
    by_step: dict = {}
    for s, flag in zip(run.nis_steps, inside):
        by_step.setdefault(int(s), []).append(flag)
    y = np.array([sum(f) for f in by_step.values()], dtype=float)
    size = np.array([len(f) for f in by_step.values()], dtype=float)
    share, k = y.sum() / size.sum(), len(size)
    assert entry["nis_inside_95"] == pytest.approx(share)
    assert entry["nis_inside_95_se"] == pytest.approx(math.sqrt(k / (k - 1) * np.sum((y - share * size) ** 2)) / size.sum())
    assert entry["consistency"]["mode"] == "sampled" and entry["consistency"]["nis_steps"] == int(sample.nis.sum())
    table = format_table(m)
    assert f"NEES at {int(sample.nees.sum())} and NIS at {int(sample.nis.sum())} of {len(steps)} steps" in table
    assert f"{100 * p:.1f}±{100 * entry['nees_inside_95_se']:.1f}" in table


def test_in_band_se():
    assert in_band_se(0.9, 100) == pytest.approx(0.03, rel=0.05)  # the textbook √(p(1-p)/n) away from 0 and 1
    assert in_band_se(1.0, 50) == pytest.approx(math.sqrt((52 / 54) * (2 / 54) / 54))  # not 0 when all are in
    assert in_band_se(0.0, 50) == pytest.approx(in_band_se(1.0, 50))
    assert in_band_se(None, 10) is None and in_band_se(0.5, 0) is None


def test_compare_log_modes_share_one_sample(log):
    sampled = compare_log(log, ["ekf", "isam2"], consistency="sampled")
    every = compare_log(log, ["ekf", "isam2"], consistency=True)
    none = compare_log(log, ["ekf", "isam2"], consistency="none")
    by_name = {r.name: r for r in sampled.runs}
    assert by_name["ekf"].consistency == by_name["isam2"].consistency  # like for like
    assert by_name["ekf"].consistency["mode"] == "sampled"
    assert {r.name: r.consistency["mode"] for r in every.runs if r.online is not None} == {"ekf": "all", "isam2": "all"}
    assert all(r.consistency is None and r.nis is None for r in none.runs)
    for a, b in zip(sampled.runs, every.runs):  # the estimates do not depend on the mode
        np.testing.assert_array_equal(a.final, b.final)
