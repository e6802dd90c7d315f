"""An estimator that fails mid-run is reported as failed — with its step, time and reason — in
the table, the report, ``metrics.json`` and the exit status of ``fgslam run``; the other
estimators' results are kept, identical to a run without it. Real estimators and real GTSAM
throughout: the failures come from real input (a 3-D log whose gyro sign is wrong) or from
small subclasses of real estimators registered for the test."""

from __future__ import annotations

import dataclasses
import json
import math
import pickle

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import X

from ekf import EkfSlam
from fgslam import registry, runner
from fgslam.cli import main
from fgslam.failure import FAILED_EXIT_STATUS, EstimatorFailed, EstimatorFailure, check_finite, reason_of
from fgslam.runner3d import prepare_log3d, run_estimator_3d
from fgslam.smoother import Isam2Smoother
from slamio.datasets.seed003_log import drive_to_log
from slamio.log import RunLog, TruthPose, TruthPose3, VelocityOdometry, read_log, write_log
from slamio.sim3d import DriveScenario, simulate_drive

OCTAGON = "data/arena_octagon.jsonl"
FAIL_STEP = 100  # the step the test estimators fail at


# --------------------------------------------------------------------------- 3-D: the gyro sign


def gyro_flipped(seed: int, scenario: DriveScenario = DriveScenario(), axes: str = "z"):
    """``(header, records)`` of a simulated 3-D drive whose turn rates have the wrong sign about ``axes``."""
    header, records = drive_to_log(simulate_drive(seed, scenario), source={"generator": "test"})

    def flipped(record):
        if not isinstance(record, VelocityOdometry):
            return record
        w = [-v if "xyz"[i] in axes else v for i, v in enumerate(record.w_radps)]
        return dataclasses.replace(record, w_radps=tuple(w))

    return header, [flipped(r) for r in records]


@pytest.fixture(scope="module")
def flipped_log(tmp_path_factory):
    """Seed 5's city loop with the gyro's z sign flipped: isam2-3d stops at step 529 with GTSAM's
    IndeterminateSystemException (the same drive with the right sign runs through)."""
    path = tmp_path_factory.mktemp("gyro") / "gyro_flipped.jsonl"
    write_log(path, *gyro_flipped(5))
    return path


def test_a_wrong_gyro_sign_stops_isam2_3d_and_the_run_reports_it(flipped_log, tmp_path, capsys):
    out = tmp_path / "out"
    status = main(["run", str(flipped_log), "--out", str(out), "--estimators", "ekf-vio,isam2-3d"])
    printed = capsys.readouterr()
    assert status == FAILED_EXIT_STATUS == 4

    metrics = json.loads((out / "metrics.json").read_text())
    failed = metrics["isam2-3d"]["failed"]
    assert set(metrics["isam2-3d"]) == {"failed"}  # no figures made up for it
    assert failed["step"] == 529 and failed["time_s"] == pytest.approx(52.9) and failed["phase"] == "step"
    assert failed["reason"].startswith("gtsam IndeterminateSystemException near variable ")
    assert "gyro sign" in failed["reason"] and "\n" not in failed["reason"]
    assert "batch" not in metrics  # no graph to solve: the truth is the reference
    assert metrics["reference"] == "ground_truth"
    assert metrics["ekf-vio"]["ate_rmse_m"] > 0 and math.isfinite(metrics["ekf-vio"]["ate_rmse_m"])

    row = next(line for line in printed.out.splitlines() if line.startswith("isam2-3d"))
    assert "failed at step 529 (t = 52.90 s): gtsam IndeterminateSystemException near variable" in row
    assert "Traceback" not in printed.err
    assert ("fgslam: isam2-3d failed at step 529 (t = 52.90 s): gtsam IndeterminateSystemException"
            in printed.err) and "exit status 4" in printed.err
    report = (out / "report.html").read_text()
    assert '<tr class="failed"><td>isam2-3d</td><td colspan="12">failed at step 529 (t = 52.90 s): gtsam' in report
    assert (out / "ekf-vio.tum").exists() and not (out / "isam2-3d.tum").exists()


def test_without_truth_a_failed_isam2_3d_leaves_no_reference_and_says_so_in_one_line(flipped_log, tmp_path, capsys):
    log = read_log(flipped_log)
    no_truth = tmp_path / "no_truth.jsonl"
    write_log(no_truth, log.header, [r for r in log.records if not isinstance(r, TruthPose3)])
    status = main(["run", str(no_truth), "--out", str(tmp_path / "out"), "--estimators", "isam2-3d"])
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert status == 1
    assert err.startswith(f"fgslam: error: {no_truth}: isam2-3d failed at step 529 (t = 52.90 s): gtsam "
                          "IndeterminateSystemException")
    assert "no pose truth" in err and "nothing can be scored" in err


def test_a_singular_innovation_in_ekf_vio_is_its_failure_and_isam2_3d_runs_on(tmp_path, capsys):
    """A small drive with every gyro axis flipped: ekf-vio's innovation covariance turns
    singular (numpy's LinAlgError) at step 66; isam2-3d and the batch solve run through."""
    log = tmp_path / "small.jsonl"
    write_log(log, *gyro_flipped(3, DriveScenario(straight_m=40.0, side_m=25.0), axes="xyz"))
    status = main(["run", str(log), "--out", str(tmp_path / "out"), "--estimators", "ekf-vio,isam2-3d",
                   "--no-report"])
    out = capsys.readouterr().out
    metrics = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert status == 4
    assert metrics["ekf-vio"]["failed"]["step"] == 66
    assert metrics["ekf-vio"]["failed"]["reason"] == "numpy LinAlgError: Singular matrix"
    assert metrics["isam2-3d"]["ate_rmse_m"] is not None and metrics["batch"]["ate_rmse_m"] is not None
    row = next(line for line in out.splitlines() if line.startswith("ekf-vio "))
    assert row.split(None, 1)[1] == "failed at step 66 (t = 6.60 s): numpy LinAlgError: Singular matrix"


def test_fgslam_check_says_the_failure_in_one_line(tmp_path, capsys):
    log = tmp_path / "small.jsonl"
    write_log(log, *gyro_flipped(3, DriveScenario(straight_m=40.0, side_m=25.0), axes="xyz"))
    assert main(["check", str(log), "--estimator", "ekf-vio", "--against", "truth"]) == 1
    err = capsys.readouterr().err.strip()
    assert err == "fgslam: error: ekf-vio failed at step 66 (t = 6.60 s): numpy LinAlgError: Singular matrix"


def test_the_3d_runner_raises_one_failure_naming_the_estimator_step_and_time():
    header, records = gyro_flipped(3, DriveScenario(straight_m=40.0, side_m=25.0), axes="xyz")
    ready = prepare_log3d(RunLog("small", header, tuple(records)))
    with pytest.raises(EstimatorFailed) as caught:
        run_estimator_3d(ready.estimator("ekf-vio"), ready.inputs, stamps_s=ready.stamps_s)
    failure = caught.value.failure
    assert (failure.name, failure.step, failure.phase) == ("ekf-vio", 66, "step")
    assert failure.time_s == pytest.approx(ready.stamps_s[66])
    assert str(caught.value) == "ekf-vio failed at step 66 (t = 6.60 s): numpy LinAlgError: Singular matrix"
    assert isinstance(caught.value.__cause__, np.linalg.LinAlgError)


# --------------------------------------------------------------------------- 2-D: test estimators


class EkfSingularAt(EkfSlam):
    """The textbook EKF whose innovation turns singular at :data:`FAIL_STEP` (what numpy says then)."""

    def step(self, step):
        if step.index == FAIL_STEP:
            np.linalg.solve(np.zeros((2, 2)), np.ones(2))  # raises LinAlgError: Singular matrix
        super().step(step)


class EkfNanCovarianceAt(EkfSlam):
    """The textbook EKF whose state covariance becomes NaN after :data:`FAIL_STEP` (its pose
    stays a number at that step: only the finiteness check of the covariance can catch it)."""

    def step(self, step):
        super().step(step)
        if step.index == FAIL_STEP:
            self._cov[0, 0] = np.nan


class Isam2IndeterminateAt(Isam2Smoother):
    """Plain iSAM2 that meets a real GTSAM IndeterminateSystemException at :data:`FAIL_STEP`:
    an iSAM2 update of a graph with an unconstrained pose."""

    def step(self, step):
        if step.index == FAIL_STEP:
            unconstrained()
        super().step(step)


def unconstrained():
    """An iSAM2 update with two Pose2 linked by one between-factor and no prior: GTSAM raises."""
    graph = gtsam.NonlinearFactorGraph()
    graph.add(gtsam.BetweenFactorPose2(X(1), X(2), gtsam.Pose2(1, 0, 0), gtsam.noiseModel.Unit.Create(3)))
    values = gtsam.Values()
    values.insert(X(1), gtsam.Pose2())
    values.insert(X(2), gtsam.Pose2(1, 0, 0))
    gtsam.ISAM2().update(graph, values)


@pytest.fixture
def test_estimators(monkeypatch):
    """The three test estimators registered as ``--estimators`` names of planar logs."""
    entries = (
        registry.EstimatorEntry("ekf-singular", 2, "test: LinAlgError at step 100", EkfSingularAt),
        registry.EstimatorEntry("ekf-nan-cov", 2, "test: NaN covariance after step 100", EkfNanCovarianceAt),
        registry.EstimatorEntry("isam2-indeterminate", 2, "test: gtsam exception at step 100",
                                lambda header: _named(Isam2IndeterminateAt(header), "isam2-indeterminate"), isam2=True),
    )
    monkeypatch.setattr(registry, "_ENTRIES", (*registry._ENTRIES, *entries))
    for e in entries:
        monkeypatch.setitem(registry.REGISTRY, e.name, e)
        monkeypatch.setitem(runner.ESTIMATORS, e.name, lambda header, e=e: _named(e.factory(header), e.name))


def _named(estimator, name):
    estimator.name = name
    return estimator


#: figures that depend on the machine (times, memory), not on the estimate
MACHINE_KEYS = {"time_total_s", "time_step_p50_s", "time_step_p99_s", "time_step_max_s", "peak_memory_mb",
                "time_cpu_s", "time_consistency_cpu_s"}


def figures(metrics: dict, name: str) -> dict:
    return {k: v for k, v in metrics[name].items() if k not in MACHINE_KEYS}


def test_a_failing_estimator_is_a_row_an_entry_and_exit_4_and_the_others_are_unchanged(
        test_estimators, tmp_path, capsys):
    stamp = read_log(OCTAGON).steps()[FAIL_STEP].stamp_s
    assert main(["run", OCTAGON, "--out", str(tmp_path / "clean"), "--estimators", "ekf,isam2,dead_reckoning",
                 "--no-report"]) == 0
    capsys.readouterr()
    status = main(["run", OCTAGON, "--out", str(tmp_path / "out"),
                   "--estimators", "ekf,ekf-singular,isam2,dead_reckoning"])
    printed = capsys.readouterr()
    assert status == FAILED_EXIT_STATUS

    metrics = json.loads((tmp_path / "out" / "metrics.json").read_text())
    clean = json.loads((tmp_path / "clean" / "metrics.json").read_text())
    assert metrics["ekf-singular"] == {"failed": {"step": FAIL_STEP, "time_s": stamp, "phase": "step",
                                                  "reason": "numpy LinAlgError: Singular matrix"}}
    estimators = [k for k, v in metrics.items() if isinstance(v, dict) and k not in ("provenance", "noise_verdict")]
    assert estimators == ["ekf", "ekf-singular", "isam2", "dead_reckoning", "batch"]  # in the order asked for
    for name in ("ekf", "isam2", "dead_reckoning", "batch"):
        assert figures(metrics, name) == figures(clean, name), name  # to the digit
    assert metrics["noise_verdict"] == clean["noise_verdict"]
    assert "ekf-singular" in metrics["provenance"]["estimators"]

    cell = f"failed at step {FAIL_STEP} (t = {stamp:.2f} s): numpy LinAlgError: Singular matrix"
    lines = printed.out.splitlines()
    assert any(line.startswith("ekf-singular") and line.endswith(cell) for line in lines)
    assert [line.split()[0] for line in lines if line.split() and line.split()[0] in estimators] == \
        ["ekf", "ekf-singular", "isam2", "dead_reckoning", "batch"]
    assert printed.err.count("fgslam: ekf-singular failed at step 100") == 1 and "Traceback" not in printed.err
    report = (tmp_path / "out" / "report.html").read_text()
    assert '<tr class="failed"><td>ekf-singular</td><td colspan="' in report and cell in report
    assert not (tmp_path / "out" / "ekf-singular.tum").exists()


def test_a_nan_covariance_is_caught_at_its_step_by_the_finiteness_check(test_estimators, tmp_path, capsys):
    status = main(["run", OCTAGON, "--out", str(tmp_path / "out"), "--estimators", "ekf-nan-cov,isam2",
                   "--no-report"])
    assert status == 4
    failed = json.loads((tmp_path / "out" / "metrics.json").read_text())["ekf-nan-cov"]["failed"]
    assert failed["step"] == FAIL_STEP
    assert failed["reason"] == ("non-finite estimate: its pose covariance is not a number (1 of 9 entries NaN or "
                                "infinite)")
    row = next(line for line in capsys.readouterr().out.splitlines() if line.startswith("ekf-nan-cov "))
    assert row.split(None, 1)[1].startswith("failed at step 100 (t = ")


def test_the_batch_starts_from_another_isam2_when_one_fails_and_without_any_there_is_no_reference(
        test_estimators, tmp_path, capsys):
    assert main(["run", OCTAGON, "--out", str(tmp_path / "a"), "--estimators", "isam2-indeterminate,isam2",
                 "--no-report"]) == 4
    metrics = json.loads((tmp_path / "a" / "metrics.json").read_text())
    assert metrics["isam2-indeterminate"]["failed"]["reason"].startswith(
        "gtsam IndeterminateSystemException near variable x1")
    assert metrics["batch"]["ate_rmse_m"] is not None
    # the log's truth is the reference: with the only iSAM2 failed, the others are still scored
    assert main(["run", OCTAGON, "--out", str(tmp_path / "b"), "--estimators", "ekf,isam2-indeterminate",
                 "--no-report"]) == 4
    metrics = json.loads((tmp_path / "b" / "metrics.json").read_text())
    assert "batch" not in metrics and metrics["ekf"]["ate_rmse_m"] is not None
    # without truth the batch solve is the reference: nothing can be scored, one line, status 1
    log = read_log(OCTAGON)
    no_truth = tmp_path / "no_truth.jsonl"
    write_log(no_truth, log.header, [r for r in log.records if not isinstance(r, TruthPose)])
    capsys.readouterr()
    assert main(["run", str(no_truth), "--out", str(tmp_path / "c"), "--estimators", "ekf,isam2-indeterminate"]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("fgslam: error: isam2-indeterminate failed at step 100") and "\n" not in err
    assert "no pose truth" in err


def test_a_failed_batch_solve_is_a_row_against_truth_and_one_line_without(monkeypatch, tmp_path, capsys):
    """The batch solve meeting GTSAM's IndeterminateSystemException (a real one, from an iSAM2
    update of an unconstrained graph, in place of the batch solve)."""
    monkeypatch.setattr(runner, "batch_solve", lambda smoother: unconstrained())
    assert main(["run", OCTAGON, "--out", str(tmp_path / "a"), "--estimators", "ekf,isam2", "--no-report"]) == 4
    printed = capsys.readouterr()
    metrics = json.loads((tmp_path / "a" / "metrics.json").read_text())
    assert metrics["batch"] == {"failed": {"step": None, "time_s": None, "phase": "batch", "reason": (
        "gtsam IndeterminateSystemException near variable x1 (an under-determined system: check the odometry, "
        "on a 3-D log the gyro sign)")}}
    assert metrics["isam2"]["ate_rmse_m"] is not None and "noise_verdict" not in metrics
    row = next(line for line in printed.out.splitlines() if line.startswith("batch "))
    assert row.split(None, 1)[1].startswith("failed: gtsam IndeterminateSystemException near variable x1")
    log = read_log(OCTAGON)
    no_truth = tmp_path / "no_truth.jsonl"
    write_log(no_truth, log.header, [r for r in log.records if not isinstance(r, TruthPose)])
    assert main(["run", str(no_truth), "--out", str(tmp_path / "b"), "--estimators", "ekf,isam2"]) == 1
    err = capsys.readouterr().err
    # one error line; a slow machine may also show progress lines (every 5 s when not on a terminal)
    errors = [line for line in err.splitlines() if line.startswith("fgslam:")]
    assert len(errors) == 1 and "Traceback" not in err
    assert errors[0].startswith(f"fgslam: error: {no_truth}: the batch solve from isam2's result failed: gtsam "
                                "IndeterminateSystemException near variable x1")


# --------------------------------------------------------------------------- the pieces


def test_reason_of_names_gtsam_exceptions_by_their_class_and_variable():
    with pytest.raises(RuntimeError) as caught:
        unconstrained()
    assert reason_of(caught.value) == ("gtsam IndeterminateSystemException near variable x1 (an under-determined "
                                       "system: check the odometry, on a 3-D log the gyro sign)")
    assert reason_of(ValueError("first line\nsecond line\n\nmore")) == "ValueError: first line second line"
    assert len(reason_of(RuntimeError("x" * 500))) == 160


def test_a_failure_survives_pickling_as_a_worker_process_sends_it():
    failed = EstimatorFailed(EstimatorFailure("ekf", 12, 1.2, "numpy LinAlgError: Singular matrix"))
    again = pickle.loads(pickle.dumps(failed))
    assert again.failure == failed.failure and str(again) == str(failed)


def test_check_finite_accepts_numbers_and_names_what_is_not():
    check_finite(np.zeros(3), np.eye(3))
    check_finite(np.eye(4), None)
    with pytest.raises(ArithmeticError, match="its pose is not a number"):
        check_finite([0.0, np.nan, 0.0])
    with pytest.raises(ArithmeticError, match=r"covariance is not a number \(2 of 9"):
        check_finite(np.zeros(3), np.diag([np.inf, 1.0, -np.inf]))
