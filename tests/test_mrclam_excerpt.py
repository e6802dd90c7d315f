"""Real robots: the noise model fitted on two MRCLAM Creates, scored on a third, against Vicon.

tests/data/mrclam_excerpt holds the first 100 s of robots 1-3 of MRCLAM Dataset 6 (real
commands, real camera readings, Vicon truth; see its README). The full benchmark over all
five robots is scripts/bench_mrclam.py; this is its shape on a slice a test can afford.
"""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from ekf import EkfSlam
from fgslam.cli import main
from fgslam.runner import ESTIMATORS, expected_outlier_kernel, run_estimator
from slamio.datasets.mrclam import import_mrclam
from slamio.log import RunLog, read_log
from slamio.noise.fit_truth import fit_noise_model

from scripts import bench_association_mrclam, bench_mrclam

EXCERPT = os.path.join(os.path.dirname(__file__), "data", "mrclam_excerpt")


def _log(robot, model=None) -> RunLog:
    header, records = import_mrclam(EXCERPT, robot, model=model)
    return RunLog(f"excerpt robot {robot}", header, tuple(records))


@pytest.fixture(scope="module")
def model():
    return fit_noise_model([_log(2), _log(3)])  # fitted on robots 2 and 3 only


def _ate_vs_vicon(log: RunLog, trajectory) -> float:
    steps = log.steps()
    rows = [(i, s.truth.x_m, s.truth.y_m) for i, s in enumerate(steps) if s.truth is not None]
    idx = np.array([r[0] for r in rows])
    truth = np.array([[r[1], r[2]] for r in rows])
    est = np.asarray(trajectory)[idx, :2]
    return float(np.sqrt(np.mean(np.sum((est - truth) ** 2, axis=1))))


def test_the_fit_finds_the_physics_of_the_real_robots(model):
    o, z = model.odometry, model.observation
    assert 0.1 <= o.lag_s <= 0.35  # commands lead the motion (~0.2-0.3 s, docs/datasets-mrclam-rosbag.md)
    assert 0.85 <= o.forward_scale <= 1.0 and 0.85 <= o.turn_scale <= 1.0
    assert z.range_is_depth  # the camera's "range" is depth along the optical axis
    assert 1.0 < z.range_scale < 1.08
    assert 0.002 < z.bearing_sigma_rad < 0.02
    assert 0.0 < z.outlier_rate < 0.1


def test_fitted_noise_on_other_robots_beats_the_guessed_noise_on_robot_1(model):
    raw, fitted = _log(1), _log(1, model)
    for name in ("ekf", "isam2"):
        ate = {}
        for label, log in (("raw", raw), ("fitted", fitted)):
            run, _ = run_estimator(ESTIMATORS[name](log.header), log.steps(), covariances=False)
            ate[label] = _ate_vs_vicon(log, run.final)
        assert ate["fitted"] < ate["raw"], (name, ate)
        assert ate["fitted"] < 0.2, (name, ate)


def test_dead_reckoning_with_the_fitted_odometry_is_closer_to_vicon(model):
    from ekf import DeadReckoning

    errors = {}
    for label, log in (("raw", _log(1)), ("fitted", _log(1, model))):
        run, _ = run_estimator(DeadReckoning(log.header), log.steps(), covariances=False)
        errors[label] = _ate_vs_vicon(log, run.final)
    assert errors["fitted"] < errors["raw"]


def test_the_fitted_log_picks_a_robust_isam2_and_a_gated_ekf(model):
    fitted = _log(1, model)
    assert fitted.header.noise["observation"]["outlier_rate"] > 0
    assert expected_outlier_kernel(fitted.header) == "dcs"
    assert expected_outlier_kernel(_log(1).header) is None  # no fitted model: least squares
    assert ESTIMATORS["isam2"](fitted.header).name == "isam2"  # the table keeps the name
    ekf = EkfSlam(fitted.header)
    for step in fitted.steps():
        ekf.step(step)
    assert ekf.gated_known_id <= 0.05 * sum(len(s.observations) for s in fitted.steps())


def test_calibrate_then_import_then_run_from_the_command_line(tmp_path, capsys):
    logs = []
    for robot in (2, 3):  # options before, between and after the paths
        out = tmp_path / f"r{robot}.jsonl"
        args = ["import", "mrclam", EXCERPT, "--robot", str(robot), str(out), "--noise", "round"] if robot == 2 else \
            ["import", "mrclam", "--noise", "round", "--robot", str(robot), EXCERPT, str(out)]
        assert main(args) == 0
        logs.append(str(out))
    noise = tmp_path / "noise.json"
    assert main(["calibrate", *logs, "--out", str(noise)]) == 0
    printed = capsys.readouterr().out
    assert "range is depth" in printed and "readings of one landmark: " in printed
    assert json.loads(noise.read_text())["fitted_on"] == logs
    assert main(["calibrate", *logs, "--out", str(noise)]) == 1  # never overwrites
    assert "exists" in capsys.readouterr().err
    r1 = tmp_path / "r1.jsonl"
    assert main(["import", "mrclam", EXCERPT, str(r1), "--robot", "1", "--noise", str(noise)]) == 0
    header = read_log(r1).header
    assert header.noise["fitted_on"] == logs
    # the fitted time correlation of the readings reaches the EKF through the header
    share = json.loads(noise.read_text())["observation"]["correlated_share"]
    assert header.noise["observation"]["correlated_share"] == share
    assert main(["calibrate", str(r1)]) == 1  # a fitted log is not raw data to fit on
    assert "--noise" in capsys.readouterr().err
    assert main(["run", str(r1), "--out", str(tmp_path / "res"), "--no-report", "--estimators", "ekf,isam2"]) == 0
    printed = capsys.readouterr().out
    assert "ground truth recorded in the log" in printed and "of 256 poses" in printed
    metrics = json.loads((tmp_path / "res" / "metrics.json").read_text())
    assert metrics["reference"] == "ground_truth"
    assert metrics["isam2"]["ate_aligned_rmse_m"] <= metrics["isam2"]["ate_rmse_m"] + 1e-12
    # the same model applied at run time to a log imported without it
    assert main(["run", logs[0], "--noise", str(noise), "--out", str(tmp_path / "res2"), "--no-report",
                 "--estimators", "ekf,isam2"]) == 0
    assert "applied the noise model" in capsys.readouterr().out
    metrics = json.loads((tmp_path / "res2" / "metrics.json").read_text())
    assert metrics["noise_model"] == str(noise) and len(metrics["provenance"]["log_sha256"]) == 64
    assert main(["run", str(r1), "--noise", str(noise), "--out", str(tmp_path / "res3")]) == 1  # twice: refused
    assert "already carries a fitted noise model" in capsys.readouterr().err


def test_import_mrclam_applies_the_shipped_model_unless_told_round(tmp_path, capsys):
    """Without --noise the importer applies the model fitted on MRCLAM Dataset 6 and says so
    (in the header's source and on the terminal); --noise round gives the round numbers,
    which calibrate accepts."""
    from slamio.datasets.mrclam import SHIPPED_NOISE_MODEL
    from slamio.noise.model import load_noise_model

    shipped, rounded = tmp_path / "shipped.jsonl", tmp_path / "round.jsonl"
    assert main(["import", "mrclam", EXCERPT, str(shipped), "--robot", "2"]) == 0
    assert "the model shipped with fgslam, fitted on UTIAS MRCLAM Dataset 6" in capsys.readouterr().out
    header = read_log(shipped).header
    assert "MRCLAM Dataset 6" in header.source["noise_model"]
    model = load_noise_model(SHIPPED_NOISE_MODEL)
    assert header.noise["fitted_on"] == list(model.fitted_on) and model.odometry.lag_s > 0
    assert main(["import", "mrclam", EXCERPT, str(rounded), "--robot", "2", "--noise", "round"]) == 0
    assert "not fitted" in read_log(rounded).header.noise["observation"]["model"]


def test_a_missing_noise_file_is_one_clear_line(tmp_path, capsys):
    assert main(["import", "mrclam", EXCERPT, str(tmp_path / "x.jsonl"), "--noise", str(tmp_path / "nope.json")]) == 2
    err = capsys.readouterr().err
    assert "nope.json: no such noise-model file" in err and "Traceback" not in err
    assert not (tmp_path / "x.jsonl").exists()


def test_the_real_robot_benchmark_script_runs_on_the_excerpt(tmp_path, capsys):
    """scripts/bench_mrclam.py end to end (leave-one-out over the excerpt's three robots)."""
    bench = bench_mrclam
    out = tmp_path / "bench.json"
    assert bench.main([EXCERPT, "--estimators", "ekf,isam2", "--json", str(out), "--figure", str(tmp_path / "f.png")]) == 0
    table = capsys.readouterr().out
    assert "| median | isam2 |" in table and (tmp_path / "f.png").stat().st_size > 10_000
    results = json.loads(out.read_text())["results"]
    assert sorted(results) == ["1", "2", "3"]
    for robot in results.values():
        assert robot["isam2"]["ate_final_aligned_m"] <= robot["isam2"]["ate_final_m"] + 1e-9
        assert robot["isam2"]["alone_s"] > 0 and robot["ekf"]["alone_s"] > 0  # the timing-only runs
        # the smoother never loses (to a millimetre: on robot 3's short excerpt they tie at 0.039 m)
        assert robot["isam2"]["ate_final_m"] <= robot["ekf"]["ate_final_m"] + 1e-3
    assert np.median([r["isam2"]["ate_final_m"] for r in results.values()]) < 0.2


def test_the_benchmark_fits_on_one_robot_and_scores_the_others(tmp_path, capsys):
    """``--fit-on 1``: one model, fitted on robot 1 alone, scores robots 2 and 3; a robot the
    folder lacks, a robot that is not a number, or ``--fit-on`` with ``--no-model`` is one
    clear line (argparse's exit 2), not a traceback."""
    bench = bench_mrclam
    out = tmp_path / "bench.json"
    assert bench.main([EXCERPT, "--fit-on", "1", "--estimators", "ekf,isam2", "--json", str(out)]) == 0
    saved = json.loads(out.read_text())
    assert sorted(saved["results"]) == ["2", "3"]
    assert saved["models"]["2"] == saved["models"]["3"]
    assert [name.rsplit("/", 1)[-1] for name in saved["models"]["2"]["fitted_on"]] == ["robot1 (raw)"]
    capsys.readouterr()
    with pytest.raises(SystemExit) as exit_:
        bench.main([EXCERPT, "--fit-on", "9"])
    assert exit_.value.code == 2 and "--fit-on 9: need at least one robot" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_:
        bench.main([EXCERPT, "--fit-on", "1", "--no-model"])
    assert exit_.value.code == 2 and "--no-model scores without one" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_:
        bench.main([EXCERPT, "--robots", "one"])
    assert exit_.value.code == 2 and "'one': give robot numbers separated by commas" in capsys.readouterr().err


@pytest.mark.slow
def test_hidden_barcodes_the_ambiguity_margin_halves_the_wrong_pairings(model):
    """MRCLAM's cylinders stand 0.18 m apart in clusters: without the barcodes, a reading
    that fits two neighbours nearly equally is rejected rather than paired (measured on
    robot 3's first 100 s, noise fitted on robots 1 and 2: ekf 11 -> 5 wrong, isam2 60 -> 28)."""
    from fgslam.cli.import_ import hide_landmark_ids
    from fgslam.smoother import Isam2Smoother

    fitted = fit_noise_model([_log(1), _log(2)])
    header, records = hide_landmark_ids(*import_mrclam(EXCERPT, 3, model=fitted))
    log = RunLog("excerpt robot 3, barcodes withheld", header, tuple(records))
    wrong = {}
    for margin in ("default", None):
        ekf = EkfSlam(header) if margin == "default" else EkfSlam(header, ambiguity_margin=None)
        smoother = Isam2Smoother(header, robust=expected_outlier_kernel(header))
        if margin is None:
            smoother._association.ambiguity_margin = None
        for name, estimator in (("ekf", ekf), ("isam2", smoother)):
            run, _ = run_estimator(estimator, log.steps(), covariances=False)
            wrong[name, margin] = run.association.wrong
    for name in ("ekf", "isam2"):
        assert 2 * wrong[name, "default"] <= wrong[name, None]


@pytest.mark.slow
def test_hidden_barcodes_the_smoother_settles_rejected_readings_at_the_end():
    """The deferred decision: readings still rejected when the run ends are associated once
    more against the settled map; those that pair now are mostly right."""
    from fgslam.cli.import_ import hide_landmark_ids
    from fgslam.compare import score_associations
    from fgslam.smoother import Isam2Smoother

    fitted = fit_noise_model([_log(1), _log(2)])
    header, records = hide_landmark_ids(*import_mrclam(EXCERPT, 3, model=fitted))
    steps = RunLog("excerpt robot 3, barcodes withheld", header, tuple(records)).steps()
    smoother = Isam2Smoother(header, robust=expected_outlier_kernel(header))
    for step in steps:
        smoother.step(step)
    before = smoother.associations()
    smoother.finish()
    after = smoother.associations()
    true_ids = [o.truth_landmark_id for step in steps for o in step.observations]
    settled = [i for i, (a, b) in enumerate(zip(before, after)) if a is None and b is not None]
    assert len(settled) >= 10
    identity = score_associations(true_ids, after).identity
    right = sum(identity.get(after[i]) == true_ids[i] for i in settled)
    assert right >= 0.9 * len(settled)


@pytest.mark.slow
def test_the_hidden_barcode_benchmark_scores_both_estimators_against_the_bound(tmp_path, capsys):
    """scripts/bench_association_mrclam.py on the excerpt's robot 3 (noise fitted on robots 1
    and 2): every reading is correct, wrong or unused; "ambiguous" is part of "rejected"; and
    the bound with the Vicon pose and the surveyed map splits the readings into right,
    ambiguous and wrong (its right share at most the nearest-is-the-barcode share)."""
    bench = bench_association_mrclam
    out = tmp_path / "hidden.json"
    assert bench.main([EXCERPT, "--robots", "3", "--json", str(out)]) == 0
    table = capsys.readouterr().out
    assert "| median | isam2 |" in table and "| 3 | " in table.split("surveyed map")[1]
    robot = json.loads(out.read_text())["3"]
    assert robot["oracle_correct"] + robot["oracle_wrong"] + robot["ambiguous_with_truth"] == pytest.approx(1.0)
    assert robot["oracle_correct"] <= robot["nearest_is_barcode"] <= 1.0
    for name in ("ekf", "isam2"):
        row = robot[name]
        assert row["correct"] + row["wrong"] + row["rejected"] == row["observations"]
        assert 0 <= row["ambiguous"] <= row["rejected"]
        assert row["rate"] >= 0.5  # the excerpt is the easy start of the run


@pytest.mark.slow
def test_hidden_barcodes_the_smoother_redecides_its_pairings_against_the_settled_map():
    """At the end the smoother asks every id-less reading once more against the settled map
    and moves or drops the pairings the data no longer support (measured on robot 3's first
    100 s, noise fitted on robots 1 and 2: wrong pairings 31 -> 0, correct 336 -> 337,
    ATE against Vicon 0.053 -> 0.035 m)."""
    from fgslam.cli.import_ import hide_landmark_ids
    from fgslam.smoother import Isam2Smoother

    fitted = fit_noise_model([_log(1), _log(2)])
    header, records = hide_landmark_ids(*import_mrclam(EXCERPT, 3, model=fitted))
    log = RunLog("excerpt robot 3, barcodes withheld", header, tuple(records))
    score, ate, counts = {}, {}, {}
    for redecide in (False, True):
        smoother = Isam2Smoother(header, robust=expected_outlier_kernel(header))
        smoother.redecide = redecide
        run, est = run_estimator(smoother, log.steps(), covariances=False)
        score[redecide], ate[redecide], counts[redecide] = run.association, _ate_vs_vicon(log, run.final), est.association_counts
    assert score[True].wrong <= score[False].wrong // 5
    assert score[True].correct >= 0.97 * score[False].correct
    assert ate[True] < ate[False]
    assert counts[True]["repaired"] + counts[True]["unpaired"] > 0 and counts[False]["repaired"] == 0
    # the counts still add up: every observation is paired, rejected, unconfirmed or waiting
    c = counts[True]
    assert c["paired"] + c["rejected"] + c["unconfirmed"] + c["waiting"] == score[True].observations


def test_the_odometry_window_sets_the_stretch_the_rates_describe(tmp_path, capsys):
    """Real Creates: --odometry-window 5 fits the variance rates over 5 s stretches (the report
    says so, and they differ from the 1 s fit: the turn error is correlated over seconds,
    docs/results-datasets.md); an impossible window is named."""
    logs = []
    for robot in (2, 3):
        out = tmp_path / f"r{robot}.jsonl"
        assert main(["import", "mrclam", EXCERPT, str(out), "--robot", str(robot), "--noise", "round"]) == 0
        logs.append(str(out))
    models = {}
    for window in ("1", "5"):
        out = tmp_path / f"w{window}.json"
        assert main(["calibrate", *logs, "--odometry-window", window, "--out", str(out)]) == 0
        models[window] = json.loads(out.read_text())
    assert models["5"]["fit_report"]["odometry"]["window_s"] == 5.0
    assert models["5"]["odometry"]["noise"] != models["1"]["odometry"]["noise"]
    capsys.readouterr()
    assert main(["calibrate", *logs, "--odometry-window", "-1"]) == 1
    assert "--odometry-window must be a number > 0 and <= 600" in capsys.readouterr().err
