"""The walking skeleton's promises, measured end to end on seeded runs.

On the bundled arena-octagon log and on `grid --landmarks 200` (seed 1):
iSAM2's final ATE is below the EKF's, its online ATE is no worse than the EKF's online
ATE, its final ATE is within 5 % of the batch solution's, and all are far below dead
reckoning's. README.md quotes these numbers and how they spread over other seeds
(scripts/seed_sweep.py).
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from fgslam.compare import compute_metrics
from fgslam.runner import compare_log
from slamio.log import read_log, write_log
from slamio.sim import simulate

DATA = Path(__file__).resolve().parent.parent / "data"


def metrics_of(path: Path) -> dict:
    log = read_log(path)
    result = compare_log(log)
    return compute_metrics(result.runs, result.reference, log_path=str(path))


def assert_skeleton_promises(m: dict) -> None:
    ekf, isam2, batch, dead = (m[k] for k in ("ekf", "isam2", "batch", "dead_reckoning"))
    assert m["reference"] == "ground_truth"
    assert isam2["ate_rmse_m"] < ekf["ate_rmse_m"]
    assert isam2["ate_online_rmse_m"] <= ekf["ate_online_rmse_m"]
    assert abs(isam2["ate_rmse_m"] - batch["ate_rmse_m"]) <= 0.05 * batch["ate_rmse_m"]
    for name in ("ekf", "isam2", "batch"):
        assert m[name]["ate_rmse_m"] < dead["ate_rmse_m"] / 3, name  # "far below"
        assert m[name]["map_rmse_m"] < dead["map_rmse_m"], name
    assert not any(m[k]["aligned"] for k in ("ekf", "isam2", "batch", "dead_reckoning"))


@pytest.mark.parametrize("name", ["arena_octagon", "arena_square"])
def test_bundled_logs_are_what_their_command_makes(name, tmp_path):
    bundled = DATA / f"{name}.jsonl"
    header = read_log(bundled).header
    command = header.source["command"]
    assert command == f"fgslam sim {name.replace('_', '-')} --seed 1 --out data/{name}.jsonl"
    fresh = tmp_path / "fresh.jsonl"
    write_log(fresh, *simulate(header.source["scenario"], header.source["seed"], command=command))
    assert fresh.read_bytes() == bundled.read_bytes(), "regenerate with `make data`"


def test_arena_octagon_skeleton_promises():
    assert_skeleton_promises(metrics_of(DATA / "arena_octagon.jsonl"))


def test_grid_200_skeleton_promises(tmp_path):
    path = tmp_path / "grid200.jsonl"
    write_log(path, *simulate("grid", 1, landmarks=200))
    m = metrics_of(path)
    assert_skeleton_promises(m)
    (tmp_path / "metrics.json").write_text(json.dumps(m))  # kept for a failing run's post-mortem


# --------------------------------------------------------------------------- issue 3: the papers' variants

PAPER_ESTIMATORS = ["ekf", "ekf-s000", "ekf-s001", "ekf-s004", "isam2"]


def test_all_variants_side_by_side_in_one_report(tmp_path, capsys):
    from html.parser import HTMLParser

    from fgslam.cli import main

    out = tmp_path / "five"
    log = DATA / "arena_octagon.jsonl"
    assert main(["run", str(log), "--out", str(out), "--estimators", ",".join(PAPER_ESTIMATORS)]) == 0
    table = capsys.readouterr().out
    metrics = json.loads((out / "metrics.json").read_text())
    for name in PAPER_ESTIMATORS + ["batch"]:
        assert name in metrics and name in table
        assert (out / f"{name}.tum").exists()

    cells: list[str] = []

    class Cells(HTMLParser):
        def handle_data(self, data):
            cells.append(data.strip())

    Cells().feed((out / "report.html").read_text())
    for name in PAPER_ESTIMATORS:
        assert name in cells  # one table row each, in the one report
    # The papers' flaws cost what docs/estimators.md says (scripts/flaw_costs.py):
    assert metrics["ekf-s000"]["ate_rmse_m"] > 1.0  # wrong-way rotation, relative landmark init
    assert metrics["ekf-s004"]["ate_rmse_m"] > 1.0  # body velocity added unrotated
    assert 2 * metrics["ekf"]["ate_rmse_m"] < metrics["ekf-s001"]["ate_rmse_m"] < 0.1  # sigma for variance
    assert metrics["ekf-s001"]["association"]["rate"] == 1.0  # NN is enough for 8 tags 1 m apart


@pytest.mark.parametrize("scenario, landmarks", [("arena-octagon", 8), ("grid", 200)])
def test_jcbb_associates_hidden_ids_at_least_99_percent_and_nn_no_better(scenario, landmarks, tmp_path):
    path = tmp_path / "hidden.jsonl"
    write_log(path, *simulate(scenario, 1, landmarks=landmarks, hide_ids=True))
    log = read_log(path)
    from fgslam.runner import ESTIMATORS, run_estimator, truth_reference

    reference = truth_reference(log)
    steps = log.steps()
    rates = {}
    for name in ("ekf", "ekf-nn"):
        run, _ = run_estimator(ESTIMATORS[name](log.header), steps)
        m = compute_metrics([run], reference, log_path=str(path))[name]
        rates[name] = m["association"]["rate"]
        assert m["association"]["observations"] == sum(len(s.observations) for s in steps)
        assert m["map_rmse_m"] is not None  # landmarks re-keyed by true id
    assert rates["ekf"] >= 0.99, rates
    assert rates["ekf-nn"] <= rates["ekf"], rates


# --------------------------------------------------------------------------- issue 4: outliers on the grid


def test_dcs_isam2_with_10_percent_outliers_on_grid_200_stays_within_1_2x_of_clean():
    """The outlier goal where it is hardest: the 200-landmark grid, whose weakly observed
    large-scale bend moves when a kernel re-weights *good* observations (Huber, Cauchy and
    Tukey already miss 1.2x on the clean log there; docs/performance.md). DCS keeps good
    observations at weight 1. Measured (seed 1): clean 0.1936 m, DCS with the outliers added
    0.2024 m (1.05x); least squares 2.09 m."""
    import numpy as np

    from fgslam.compare import ate_rmse_m
    from fgslam.runner import run_estimator
    from fgslam.smoother import Isam2Smoother
    from slamio.log import group_steps

    header, records = simulate("grid", 1, landmarks=200)
    clean_steps = group_steps(header, records)
    truth = np.array([[s.truth.x_m, s.truth.y_m, s.truth.theta_rad] for s in clean_steps])
    clean = ate_rmse_m(run_estimator(Isam2Smoother(header), clean_steps)[0].final, truth)
    header_out, records_out = simulate("grid", 1, landmarks=200, outliers=0.1, outlier_mode="add")
    run, smoother = run_estimator(Isam2Smoother(header_out, robust="dcs"), group_steps(header_out, records_out))
    assert ate_rmse_m(run.final, truth) <= 1.2 * clean


# --------------------------------------------------------------------------- issue 5: consistency


def test_nees_of_ekf_and_isam2_on_the_bundled_log():
    """Both state a covariance for every online pose; against the ground truth their NEES
    stays in the 95 % chi-square band at most steps. Measured: ekf mean 1.86, 96.1 % inside;
    isam2 1.83, 95.8 % (a mean below 3: on this log both are somewhat conservative)."""
    m = metrics_of(DATA / "arena_octagon.jsonl")
    for name in ("ekf", "isam2"):
        assert 1.0 < m[name]["nees_mean"] < 5.0, name
        assert m[name]["nees_inside_95"] > 0.9, name
    assert m["batch"]["nees_mean"] is None  # no online poses, no covariances
