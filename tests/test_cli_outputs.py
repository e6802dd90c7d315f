"""Nothing the user has is overwritten unless asked, outputs are checked before the work, and
a bad --out is one line (issue 15: data loss, tracebacks in the CLI)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from fgslam.cli import main
from fgslam.cli.common import fail, run_verb

SIM = ["sim", "arena-square", "--seed", "1", "--laps", "1"]


def one_line_error(capsys, *needles: str) -> str:
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("fgslam: error: ") and "Traceback" not in err
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    return lines[0]


@pytest.fixture(scope="module")
def log(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("log") / "square.jsonl"
    assert main([*SIM, "--out", str(path)]) == 0
    return path


def no_estimators(monkeypatch):
    """Make any estimator run fail the test: the check must come before the work."""
    import fgslam.runner

    def boom(*args, **kwargs):
        raise AssertionError("the estimators ran before the outputs were checked")

    monkeypatch.setattr(fgslam.runner, "compare_log", boom)


# --------------------------------------------------------------------------- single files


def test_sim_refuses_an_existing_log_and_keeps_it(log, tmp_path, capsys):
    out = tmp_path / "r.jsonl"
    out.write_bytes(log.read_bytes())
    before = out.read_bytes()
    assert main(["sim", "arena-octagon", "--seed", "2", "--laps", "1", "--out", str(out)]) == 1
    one_line_error(capsys, str(out), "exists", "--overwrite", "lines")
    assert out.read_bytes() == before
    assert main(["sim", "arena-octagon", "--seed", "2", "--laps", "1", "--out", str(out), "--overwrite"]) == 0
    assert out.read_bytes() != before and "arena-octagon" in out.read_text().splitlines()[0]
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporary file left
    plain = tmp_path / "plain"
    plain.write_text("")
    assert out.stat().st_mode == plain.stat().st_mode  # the umask's mode, not a temporary file's 0600


def test_a_replaced_recording_takes_its_status_file_with_it(tmp_path, capsys):
    out = tmp_path / "run.jsonl"
    assert main([*SIM, "--out", str(out)]) == 0
    status = tmp_path / "run.jsonl.status.json"  # as fgslam record leaves it: how that recording ended
    status.write_text('{"reason": "interrupted"}\n')
    assert main([*SIM, "--out", str(out), "--overwrite"]) == 0
    assert not status.exists() and f"removed {status}" in capsys.readouterr().out


def test_each_log_has_its_own_status_file(tmp_path, capsys):
    """run.jsonl and run.json once shared run.status.json; an older recording's status file
    under that name goes with its log only when it says it describes that log."""
    from fgslam.cli.common import status_path

    assert status_path(tmp_path / "run.jsonl") != status_path(tmp_path / "run.json")
    assert status_path(tmp_path / "run.jsonl").name == "run.jsonl.status.json"
    assert status_path(tmp_path / "run").name == "run.status.json"
    out = tmp_path / "run.jsonl"
    assert main([*SIM, "--out", str(out)]) == 0
    older = tmp_path / "run.status.json"  # an older fgslam's name for the status of run.jsonl
    older.write_text(json.dumps({"reason": {"kind": "completed"}, "log": str(tmp_path / "run.json")}) + "\n")
    assert main([*SIM, "--out", str(out), "--overwrite"]) == 0
    assert older.exists()  # it describes run.json, not this log: kept
    older.write_text(json.dumps({"reason": {"kind": "completed"}, "log": str(out)}) + "\n")
    capsys.readouterr()
    assert main([*SIM, "--out", str(out), "--overwrite"]) == 0
    assert not older.exists() and f"removed {older}" in capsys.readouterr().out


def test_sim_into_a_folder_or_under_a_file_is_one_line(tmp_path, capsys):
    assert main([*SIM, "--out", str(tmp_path)]) == 1
    one_line_error(capsys, "is a folder", str(tmp_path / "run.jsonl"))
    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    assert main([*SIM, "--out", str(a_file / "run.jsonl")]) == 1
    one_line_error(capsys, f"{a_file} is a file, not a folder")


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="needs /proc (read-only even for root)")
def test_sim_into_a_place_that_cannot_be_written_is_one_line(capsys):
    assert main([*SIM, "--out", "/proc/self/fgslam-test.jsonl"]) == 1
    one_line_error(capsys, "/proc/self/fgslam-test.jsonl", "cannot write in")


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0, reason="root writes in read-only folders")
def test_sim_into_a_read_only_folder_is_one_line(tmp_path, capsys):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        assert main([*SIM, "--out", str(locked / "r.jsonl")]) == 1
        one_line_error(capsys, "cannot write in", str(locked))
    finally:
        locked.chmod(0o700)


def test_import_and_calibrate_refuse_an_existing_output(tmp_path, capsys):
    out = tmp_path / "vp.jsonl"
    out.write_text("mine\n")
    assert main(["import", "victoria-park", str(out)]) == 1  # refused before the conversion
    one_line_error(capsys, f"OUT {out} exists", "--overwrite")
    cal = tmp_path / "cal.json"
    cal.write_text("{}\n")
    assert main(["calibrate", "data/calibration_trials_s001.csv", "--out", str(cal)]) == 1
    one_line_error(capsys, f"--out {cal} exists", "--overwrite")
    assert out.read_text() == "mine\n" and cal.read_text() == "{}\n"
    assert main(["calibrate", "data/calibration_trials_s001.csv", "--out", str(cal), "--overwrite"]) == 0
    assert json.loads(cal.read_text())["format"] == "fgslam-calibration"


def test_record_refuses_an_existing_recording_before_it_opens_the_port(log, tmp_path, capsys):
    out = tmp_path / "r.jsonl"
    out.write_bytes(log.read_bytes())
    before = out.read_bytes()
    port = str(tmp_path / "ttyUSB9")  # would fail to open: the refusal must come first
    assert main(["record", "--port", port, "--model", "create2", "--out", str(out)]) == 1
    one_line_error(capsys, str(out), "exists", "--overwrite")
    assert out.read_bytes() == before
    # Asked to replace it, but the robot does not answer: the port fails before the log is touched.
    assert main(["record", "--port", port, "--model", "create2", "--out", str(out), "--overwrite"]) == 1
    assert "cannot open serial port" in capsys.readouterr().err
    assert out.read_bytes() == before


def test_live_refuses_an_existing_log_before_anything_moves(log, tmp_path, capsys):
    out = tmp_path / "live.jsonl"
    out.write_bytes(log.read_bytes())
    assert main(["live", "--port", str(tmp_path / "ttyUSB9"), "--out", str(out)]) == 1
    one_line_error(capsys, str(out), "exists", "--overwrite")
    assert out.read_bytes() == log.read_bytes()


# --------------------------------------------------------------------------- results folders


def test_run_into_an_existing_file_is_refused_before_the_run(log, tmp_path, capsys, monkeypatch):
    no_estimators(monkeypatch)
    target = tmp_path / "results"
    target.write_text("keep me")
    assert main(["run", str(log), "--out", str(target)]) == 1
    one_line_error(capsys, str(target), "is a file", "folder")
    assert target.read_text() == "keep me"


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="needs /proc (read-only even for root)")
def test_run_into_a_place_that_cannot_be_written_is_refused_before_the_run(log, capsys, monkeypatch):
    no_estimators(monkeypatch)
    assert main(["run", str(log), "--out", "/proc/self/fgslam-results"]) == 1
    one_line_error(capsys, "/proc/self/fgslam-results", "cannot write in")


def test_run_refuses_a_folder_with_other_files_unless_overwrite(log, tmp_path, capsys, monkeypatch):
    folder = tmp_path / "mine"
    folder.mkdir()
    (folder / "notes.txt").write_text("mine")
    (folder / "ekf.tum").write_text("an ekf.tum of my own")
    with monkeypatch.context() as patch:
        no_estimators(patch)
        assert main(["run", str(log), "--out", str(folder), "--no-report"]) == 1
    one_line_error(capsys, str(folder), "notes.txt", "manifest.json", "--overwrite")
    assert sorted(p.name for p in folder.iterdir()) == ["ekf.tum", "notes.txt"]
    assert main(["run", str(log), "--out", str(folder), "--no-report", "--estimators", "isam2", "--overwrite"]) == 0
    names = {p.name for p in folder.iterdir()}
    assert "notes.txt" in names and "isam2.tum" in names and "manifest.json" in names
    assert "ekf.tum" not in names  # one of fgslam's own names, not written by this run: removed
    assert (folder / "notes.txt").read_text() == "mine"
    manifest = json.loads((folder / "manifest.json").read_text())
    assert "notes.txt" not in manifest["files"] and "isam2.tum" in manifest["files"]


def test_a_reused_results_folder_keeps_no_stale_file(log, tmp_path, capsys):
    out = tmp_path / "r"
    assert main(["run", str(log), "--out", str(out), "--no-report"]) == 0
    first = json.loads((out / "manifest.json").read_text())["files"]
    assert "dead_reckoning.tum" in first and "ekf_online.tum" in first
    (out / "notes.txt").write_text("added by the user")
    capsys.readouterr()
    assert main(["run", str(log), "--out", str(out), "--no-report", "--estimators", "isam2"]) == 0
    printed = capsys.readouterr().out
    assert "replacing the earlier results" in printed and "dead_reckoning.tum" in printed
    names = {p.name for p in out.iterdir()}
    assert not names & {"dead_reckoning.tum", "dead_reckoning_online.tum", "ekf.tum", "ekf_online.tum"}
    assert {"isam2.tum", "batch.tum", "reference.tum", "metrics.json", "graph.g2o", "notes.txt"} <= names
    manifest = json.loads((out / "manifest.json").read_text())
    assert set(manifest["files"]) == names - {"notes.txt"}
    assert manifest["written_by"] == "fgslam run" and "--estimators isam2" in manifest["command"]
    metrics = json.loads((out / "metrics.json").read_text())
    assert set(metrics) >= {"isam2", "batch"} and "ekf" not in metrics


def test_the_results_of_another_log_or_verb_are_kept_unless_overwrite(log, tmp_path, capsys, monkeypatch):
    out = tmp_path / "r"
    assert main(["run", str(log), "--out", str(out), "--no-report", "--estimators", "ekf", "--no-consistency"]) == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    other = tmp_path / "copy.jsonl"
    other.write_bytes(log.read_bytes())
    with monkeypatch.context() as patch:
        no_estimators(patch)
        assert main(["run", str(other), "--out", str(out), "--no-report"]) == 1
        one_line_error(capsys, str(out), str(log.resolve()), str(other.resolve()), "--overwrite")
    import fgslam.montecarlo

    with monkeypatch.context() as patch:
        patch.setattr(fgslam.montecarlo, "monte_carlo", lambda *a, **k: pytest.fail("ran before the check"))
        assert main(["bench", "arena-square", "--runs", "2", "--out", str(out)]) == 1
        one_line_error(capsys, str(out), "`fgslam run`", "fgslam bench", "--overwrite")
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before  # nothing touched
    assert main(["run", str(other), "--out", str(out), "--no-report", "--estimators", "ekf", "--no-consistency",
                 "--overwrite"]) == 0
    assert json.loads((out / "manifest.json").read_text())["source"] == str(other.resolve())


def test_an_older_run_output_without_manifest_is_replaced_whole(log, tmp_path, capsys):
    out = tmp_path / "old"
    out.mkdir()
    (out / "metrics.json").write_text(json.dumps({"reference": "ground_truth", "ekf": {}}))
    for name in ("ekf.tum", "dead_reckoning.tum", "report.html", "trajectories.png"):
        (out / name).write_text("from an older run on another log")
    (out / "notes.txt").write_text("mine")
    assert main(["run", str(log), "--out", str(out), "--no-report", "--estimators", "isam2"]) == 0
    names = {p.name for p in out.iterdir()}
    assert not names & {"ekf.tum", "dead_reckoning.tum", "report.html", "trajectories.png"}
    assert "notes.txt" in names and "isam2.tum" in names


def test_bench_refuses_a_folder_with_other_files_before_the_runs(tmp_path, capsys, monkeypatch):
    import fgslam.montecarlo

    monkeypatch.setattr(fgslam.montecarlo, "monte_carlo", lambda *a, **k: pytest.fail("ran before the check"))
    folder = tmp_path / "b"
    folder.mkdir()
    (folder / "notes.txt").write_text("mine")
    assert main(["bench", "arena-square", "--runs", "2", "--out", str(folder)]) == 1
    one_line_error(capsys, str(folder), "--overwrite")


# --------------------------------------------------------------------------- the one error path


def test_an_os_error_from_user_input_is_one_line_with_the_file():
    import io

    def verb(args):
        raise PermissionError(13, "Permission denied", "/srv/results/metrics.json")

    stream = io.StringIO()
    assert fail(PermissionError(13, "Permission denied", "/srv/x"), stream) == 1
    assert stream.getvalue() == ("fgslam: error: /srv/x: Permission denied "
                                 "(choose a place you can write to, or change its permissions)\n")
    assert run_verb(verb, None) == 1


def test_every_verb_goes_through_the_one_error_path(tmp_path, capsys):
    missing = str(tmp_path / "missing.jsonl")
    cases = [
        ["validate", missing],
        ["run", missing, "--out", str(tmp_path / "r")],
        ["check", missing],
        ["export", "rosbag", missing, str(tmp_path / "bag")],
        ["calibrate", missing],
        ["detect", str(tmp_path / "frames"), "--camera", str(tmp_path / "cam.yaml"), "--out", missing],
        ["import", "mrclam", str(tmp_path / "nothing"), str(tmp_path / "x.jsonl")],
    ]
    for argv in cases:
        assert main(argv) == 2, argv  # an input file that cannot be used: status 2
        err = capsys.readouterr().err
        assert err.startswith("fgslam: error: ") and "Traceback" not in err, (argv, err)
    assert not (tmp_path / "r").exists()  # a failed run leaves no empty results folder behind


def test_every_phase_of_a_run_reports_progress(tmp_path, monkeypatch):
    """The estimators, the batch solve, the metrics and the writing of the results each report
    their stage (what a long run's status line shows, rather than seconds of silence)."""
    import fgslam.cli.run as run_module

    stages = []

    class Recorder:
        def __init__(self, *args, **kwargs):
            pass

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return False

        def __call__(self, done, total, label):
            if not stages or stages[-1] != label:
                stages.append(label)

    monkeypatch.setattr(run_module, "Progress", Recorder)
    log = Path(__file__).resolve().parent.parent / "data" / "arena_octagon.jsonl"
    assert main(["run", str(log), "--out", str(tmp_path / "r"), "--estimators", "ekf,isam2"]) == 0
    assert stages == ["ekf", "isam2", "batch", "metrics", "writing the results"]
