"""The command line end to end: help texts, outputs of `fgslam run`, bad and cut-off logs."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fgslam.cli import main
from fgslam.compare import read_tum

VERBS = ["sim", "run", "import", "export", "validate", "check", "bench", "detect", "record", "calibrate", "live"]


def test_console_script_help_lists_every_verb():
    exe = shutil.which("fgslam") or str(Path(sys.executable).parent / "fgslam")
    out = subprocess.run([exe, "--help"], capture_output=True, text=True, check=True).stdout
    assert "iSAM2" in out and "EKF" in out
    assert "2-D landmark log" in out and "3-D" in out and "stereo camera + IMU" in out
    for verb in VERBS:
        assert verb in out


@pytest.mark.parametrize("verb", VERBS)
def test_each_verb_explains_itself(verb, capsys):
    with pytest.raises(SystemExit) as exit_:
        main([verb, "--help"])
    assert exit_.value.code == 0
    out = capsys.readouterr().out
    assert f"usage: fgslam {verb}" in out
    assert len(out.splitlines()) >= 5


@pytest.fixture(scope="module")
def short_log(tmp_path_factory):
    """A short simulated arena run (1 lap) — enough to exercise every output."""
    path = tmp_path_factory.mktemp("logs") / "octagon.jsonl"
    assert main(["sim", "arena-octagon", "--seed", "3", "--laps", "1", "--out", str(path)]) == 0
    return path


def test_sim_is_deterministic(short_log, tmp_path):
    again = tmp_path / "again.jsonl"
    assert main(["sim", "arena-octagon", "--seed", "3", "--laps", "1", "--out", str(again)]) == 0
    assert again.read_bytes().replace(str(again).encode(), b"") == short_log.read_bytes().replace(
        str(short_log).encode(), b""
    )


def test_run_writes_metrics_tum_and_report(short_log, tmp_path, capsys):
    out = tmp_path / "results"
    assert main(["run", str(short_log), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    for name in ("ekf", "isam2", "batch", "dead_reckoning"):
        assert name in printed

    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["reference"] == "ground_truth"
    keys = {
        "ate_rmse_m", "ate_online_rmse_m", "final_pose_error_m", "map_rmse_m",
        "time_total_s", "time_step_p50_s", "time_step_p99_s", "steps",
    }
    for name in ("ekf", "isam2", "batch"):
        assert keys <= set(metrics[name]), name
    assert metrics["batch"]["ate_online_rmse_m"] is None

    poses = sum(json.loads(line)["type"] == "odometry" for line in short_log.read_text().splitlines()) + 1
    for name in ("ekf", "isam2", "batch", "dead_reckoning", "reference"):
        stamps, traj = read_tum(out / f"{name}.tum")
        assert traj.shape == (poses, 3)
        assert np.all(np.diff(stamps) > 0)
    for name in ("ekf", "isam2"):
        assert (out / f"{name}_online.tum").exists()
    assert (out / "report.html").stat().st_size > 10_000
    assert (out / "trajectories.png").exists() and (out / "position_error.png").exists()


def test_validate_summarises(short_log, capsys):
    assert main(["validate", str(short_log)]) == 0
    assert "valid fgslam run log v1" in capsys.readouterr().out


def test_corrupted_middle_line_exits_nonzero_with_file_and_line(short_log, tmp_path, capsys):
    lines = short_log.read_text().splitlines(keepends=True)
    middle = len(lines) // 2
    lines[middle - 1] = lines[middle - 1][: len(lines[middle - 1]) // 2] + "\n"  # half a record
    bad = tmp_path / "corrupt.jsonl"
    bad.write_text("".join(lines))
    code = main(["run", str(bad), "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err
    assert code == 2  # an input file that cannot be used
    assert f"fgslam: error: {bad}:{middle}: not valid JSON" in err
    assert f"head -n {middle - 1}" in err
    assert not (tmp_path / "r" / "metrics.json").exists()


def test_log_truncated_mid_line_runs_on_the_part_before_the_cut(short_log, tmp_path, capsys):
    text = short_log.read_text()
    cut = tmp_path / "cut.jsonl"
    cut.write_text(text[: int(len(text) * 0.6)])  # a recording stopped mid-line
    complete_lines = cut.read_text().count("\n")
    out = tmp_path / "r"
    assert main(["run", str(cut), "--out", str(out), "--no-report"]) == 0
    captured = capsys.readouterr()
    assert "last line is cut off" in captured.err
    assert f"{cut}:{complete_lines + 1}:" in captured.err
    assert "cut off" in captured.out  # said again under the table
    metrics = json.loads((out / "metrics.json").read_text())
    assert "cut off" in metrics["log_truncated"]
    assert metrics["isam2"]["ate_rmse_m"] < metrics["dead_reckoning"]["ate_rmse_m"]


@pytest.mark.parametrize(
    "argv, message, status",
    [
        (["run", "missing.jsonl", "--out", "x"], "cannot open", 2),  # an input file: status 2
        (["run", "LOG", "--out", "x", "--estimators", "ekf,ukf"], "unknown estimator(s) ukf", 1),
        (["run", "NOTRUTH", "--out", "x", "--estimators", "ekf"], "keep isam2", 1),
    ],
)
def test_user_errors_are_one_line_not_tracebacks(argv, message, status, short_log, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    no_truth = tmp_path / "no_truth.jsonl"  # the batch solve is the reference: it needs iSAM2
    no_truth.write_text("".join(line for line in open(short_log) if '"truth_pose"' not in line))
    argv = [str(short_log) if a == "LOG" else str(no_truth) if a == "NOTRUTH" else a for a in argv]
    assert main(argv) == status
    err = capsys.readouterr().err
    assert err.startswith("fgslam: error: ") and message in err
    assert "Traceback" not in err


def test_a_log_with_truth_runs_without_isam2(short_log, tmp_path, capsys):
    """With the log's truth as the reference no batch solve is needed: `--estimators ekf`
    runs, scores against the truth and writes everything but the factor graph."""
    out = tmp_path / "ekf_only"
    assert main(["run", str(short_log), "--out", str(out), "--estimators", "ekf", "--no-report"]) == 0
    assert "ground truth" in capsys.readouterr().out
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["reference"] == "ground_truth" and "batch" not in metrics and metrics["ekf"]["ate_rmse_m"] < 0.1
    assert (out / "ekf.tum").exists() and not (out / "graph.g2o").exists()


def test_estimator_names_without_isam2_where_no_batch_solve_follows():
    from fgslam.runner import parse_estimator_names

    assert parse_estimator_names("ekf, ekf", need_isam2=False) == ["ekf"]


def test_estimator_help_names_every_registered_estimator(capsys):
    from fgslam.cli import ESTIMATOR_HELP
    from fgslam.runner import ESTIMATORS

    assert list(ESTIMATOR_HELP) == list(ESTIMATORS)
    with pytest.raises(SystemExit):
        main(["run", "--help"])
    out = capsys.readouterr().out
    from fgslam.registry import REGISTRY

    for name in REGISTRY:  # 2-D and 3-D
        assert name in out


def test_import_victoria_park_writes_a_valid_log(tmp_path, capsys):
    out = tmp_path / "vp.jsonl"
    assert main(["import", "victoria-park", str(out)]) == 0
    assert "6969 poses" in capsys.readouterr().out
    assert main(["validate", str(out)]) == 0
    assert "6968 odometry records" in capsys.readouterr().out


def test_outliers_from_sim_and_robust_isam2_from_run(tmp_path, capsys):
    log = tmp_path / "outliers.jsonl"
    assert main(["sim", "arena-octagon", "--seed", "1", "--laps", "1", "--outliers", "0.1", "--out", str(log)]) == 0
    out = tmp_path / "r"
    assert main(["run", str(log), "--out", str(out), "--no-report", "--estimators", "isam2,isam2-cauchy"]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    # the log says to expect outliers: the default isam2 takes DCS by itself, as robust as Cauchy
    assert metrics["isam2"]["ate_rmse_m"] < 2 * metrics["isam2-cauchy"]["ate_rmse_m"] < 0.05
    assert main(["run", str(log), "--out", str(out), "--no-report", "--estimators", "isam2-huber"]) == 0


def test_victoria_park_with_the_fast_preset_ends_at_the_smoothed_reference(tmp_path, capsys):
    log = tmp_path / "vp.jsonl"
    assert main(["import", "victoria-park", str(log)]) == 0
    out = tmp_path / "r"
    assert main(["run", str(log), "--out", str(out), "--no-report", "--estimators", "ekf,isam2-fast"]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["reference"] == "smoothed"
    assert metrics["isam2-fast"]["ate_rmse_m"] < 0.05  # its final estimate is the batch optimum
    assert metrics["ekf"]["ate_online_rmse_m"] > 1.0


def test_outlier_mode_add_and_robust_tags_from_the_command_line(tmp_path, capsys):
    log = tmp_path / "added.jsonl"
    argv = ["sim", "arena-octagon", "--seed", "1", "--laps", "1", "--outliers", "0.1", "--outlier-mode", "add"]
    assert main(argv + ["--out", str(log)]) == 0
    source = json.loads(log.read_text().splitlines()[0])["source"]
    assert source["outlier_mode"] == "add" and source["outliers"] == 0.1
    out = tmp_path / "r"
    assert main(["run", str(log), "--out", str(out), "--no-report", "--estimators", "isam2-tukey,isam2-tags"]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["isam2-tukey"]["ate_rmse_m"] < metrics["isam2-tags"]["ate_rmse_m"] / 3


def test_isam2_reports_landmark_heights(tmp_path, capsys):
    log = tmp_path / "cyl.jsonl"
    assert main(["sim", "cylinders", "--seed", "1", "--laps", "1", "--out", str(log)]) == 0
    out = tmp_path / "r"
    assert main(["run", str(log), "--out", str(out), "--no-report", "--estimators", "ekf,isam2"]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["isam2"]["map_height_rmse_m"] == pytest.approx(metrics["ekf"]["map_height_rmse_m"], rel=1e-6)
    assert metrics["isam2"]["map_height_rmse_m"] < 0.01


def test_run_without_consistency_has_no_nees_nis_or_covariance(tmp_path, capsys):
    from fgslam.cli import main as cli_main

    out = tmp_path / "plain"
    assert cli_main(["run", "data/arena_square.jsonl", "--out", str(out), "--no-consistency", "--no-report"]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    for name in ("ekf", "isam2"):
        assert metrics[name]["nees_mean"] is None and metrics[name]["nis_mean"] is None
        assert metrics[name]["peak_memory_mb"] is not None
    assert "NIS in %" not in capsys.readouterr().out


def test_export_rosbag_and_import_it_back_byte_for_byte(tmp_path, capsys):
    bag = tmp_path / "square_bag"
    assert main(["export", "rosbag", "data/arena_square.jsonl", str(bag)]) == 0
    assert "/fgslam/odometry" in capsys.readouterr().out
    back = tmp_path / "back.jsonl"
    assert main(["import", "rosbag", str(bag), str(back)]) == 0
    assert back.read_bytes() == open("data/arena_square.jsonl", "rb").read()
    # topics named on the command line are read, not ignored for the stored log
    assert main(["import", "rosbag", str(bag), str(tmp_path / "x.jsonl"), "--odom-topic", "/odom"]) == 2
    assert "/odom: not in the bag" in capsys.readouterr().err and not (tmp_path / "x.jsonl").exists()
    assert main(["import", "rosbag", str(bag), str(tmp_path / "topics.jsonl"), "--odom-topic", "/fgslam/odometry",
                 "--detections-topic", "/fgslam/tag_detections"]) == 0


def test_import_mrclam_fixture_and_run_it(tmp_path, capsys):
    log = tmp_path / "mrclam.jsonl"
    assert main(["import", "mrclam", "tests/fixtures/mrclam", str(log), "--robot", "1"]) == 0
    assert main(["run", str(log), "--out", str(tmp_path / "r"), "--no-report", "--estimators", "ekf,isam2"]) == 0
    assert "ekf" in capsys.readouterr().out
    assert main(["import", "mrclam", str(log)]) == 1  # no SOURCE: says how
    assert "needs SOURCE" in capsys.readouterr().err


def test_measured_tag_noise_from_the_command_line_reaches_the_estimators(tmp_path, capsys):
    log = tmp_path / "measured.jsonl"
    assert main(["sim", "arena-square", "--seed", "2", "--laps", "1", "--tag-noise", "measured", "--out", str(log)]) == 0
    from slamio.log import Observation, read_log

    run_log = read_log(log)
    sigmas = {o.sigma_tag_yaw_rad for o in run_log.records if isinstance(o, Observation)}
    assert len(sigmas) > 100  # one σ per observation, not one for all
    assert run_log.header.source["tag_noise"] == "measured"
    out = tmp_path / "r"
    assert main(["run", str(log), "--out", str(out), "--no-report", "--estimators", "ekf,isam2"]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["ekf"]["ate_rmse_m"] < 0.05 and metrics["isam2"]["ate_rmse_m"] < 0.05


@pytest.mark.parametrize("argv", [
    ["sim", "arena-octagon", "--seed", "abc", "--out", "x.jsonl"],
    ["record", "--port", "sim", "--model", "create2", "--out", "r.jsonl", "--speed", "-0.2"],
    ["nosuchverb"],
    [],
])
def test_a_mistake_in_the_command_line_is_one_error_line_and_status_1(argv, capsys, tmp_path, monkeypatch):
    """argparse's own errors follow the product's error path: one ``fgslam: error:`` line
    pointing at the verb's --help, exit status 1 (argparse would print a usage block, exit 2)."""
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as exit_:
        main(argv)
    assert exit_.value.code == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("fgslam: error: ") and "--help)" in err
    assert not list(tmp_path.iterdir())  # nothing written


def test_negative_values_are_values_not_options():
    """`--centre -1.5,2` and `--range-bias -1e9` are values (argparse before 3.13 read them
    as an unknown option: "expected one argument")."""
    from fgslam.cli import build_parser

    parser = build_parser()
    assert parser.parse_args(["live", "--port", "sim", "--out", "x", "--centre", "-1.5,2"]).centre == (-1.5, 2.0)
    assert parser.parse_args(["import", "plaza1", "o.jsonl", "--range-bias", "-1e9"]).range_bias == -1e9
    assert parser.parse_args(["import", "plaza1", "o.jsonl", "--range-bias", "-.5"]).range_bias == -0.5
