"""``fgslam record --port sim`` writes the simulated Create's true pose as ``truth_pose``
records (fgslam/record_truth.py), so a simulated recording can be scored like ``fgslam live
--port sim``'s. The references: the simulator's start pose (0.75, 0.75, 0), its own true
path length and final pose in the status file, and the odometry dead-reckoned beside it
(no wall-clock speed: the square driven open loop overshoots more on a busy machine)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from fgslam.cli import main
from fgslam.record_truth import TruthWriter
from slamio.log import Odometry, TruthLandmark, TruthPose, read_log


def _record_square(tmp_path, *extra):
    out = tmp_path / "square.jsonl"
    code = main(["record", "--port", "sim", "--model", "create2", "--path", "square", "--side", "0.5",
                 "--out", str(out), "--sim-time-scale", "20", "--sim-seed", "3",
                 "--watchdog", "30", *extra])  # a busy machine must not stop the robot
    return code, out


def test_record_on_the_simulator_writes_the_true_pose_at_every_odometry_record(tmp_path, capsys):
    code, out = _record_square(tmp_path)
    printed = capsys.readouterr().out
    assert code == 0 and "truth_pose records" in printed
    log = read_log(out)
    assert "simulated Create's true pose" in log.header.source["truth"]
    assert tuple(log.header.start_pose) == (0.75, 0.75, 0.0)  # the arena frame, where the truth is
    odometry = [r for r in log.records if isinstance(r, Odometry)]
    truth = [r for r in log.records if isinstance(r, TruthPose)]
    assert len(truth) == len(odometry) + 1 and len(odometry) > 20
    assert truth[0].stamp_s == 0.0 and (truth[0].x_m, truth[0].y_m, truth[0].theta_rad) == (0.75, 0.75, 0.0)
    assert [t.stamp_s for t in truth[1:]] == [o.stamp_s for o in odometry]  # each record has its truth
    xy = np.array([(t.x_m, t.y_m) for t in truth])
    status = json.loads((tmp_path / "square.jsonl.status.json").read_text())
    simulator = status["simulator"]
    assert xy[-1] == pytest.approx(simulator["true_pose"][:2], abs=1e-6)  # written after the robot stopped
    # Straights and turns in place: the chords of the 0.1 s samples add up to the true path length.
    chords = float(np.sum(np.hypot(*np.diff(xy, axis=0).T)))
    assert chords == pytest.approx(simulator["true_path_length_m"], abs=0.01)
    assert status["records"] == len(odometry)
    # The odometry dead-reckoned from the same start ends within the encoders' drift of the truth.
    # (Not the square's corners: how far a busy machine lets the open-loop path overshoot varies.)
    assert np.hypot(*(np.array(status["final_pose"][:2]) - xy[-1])) < 0.1
    assert chords > 1.9  # at least the 2 m asked for
    # A log with truth is scored against it.
    assert main(["run", str(out), "--out", str(tmp_path / "results"), "--estimators", "ekf", "--no-report"]) == 0
    metrics = json.loads((tmp_path / "results" / "metrics.json").read_text())
    assert metrics["reference"] == "ground_truth" and metrics["ekf"]["ate_rmse_m"] < 0.1


class _Log:
    def __init__(self):
        self.records = []

    def write(self, record):
        self.records.append(record)

    def flush(self):
        pass


class _Inner:
    def __init__(self):
        self.calls = []

    def due(self, now_s):
        self.calls.append(("due", now_s))
        return now_s > 1.0

    def after_record(self, record, log):
        self.calls.append(("after", record.stamp_s, len(log.records)))


def test_truth_writer_writes_before_handing_on_and_keeps_the_inner_schedule():
    poses = iter([(0.0, 0.0, 0.0), (0.1, 0.0, 0.0), (0.2, 0.05, 0.1)])
    inner, log = _Inner(), _Log()
    writer = TruthWriter(lambda: next(poses), inner, truth_landmarks=[TruthLandmark(7, 1.0, 2.0)])
    writer.started(log)
    assert writer.due(0.5) is False and writer.due(1.5) is True  # the inner hooks decide
    odometry = Odometry(0.1, 0.1, 0.0, 0.0, ((1e-4, 0, 0), (0, 1e-4, 0), (0, 0, 1e-4)))
    writer.after_record(odometry, log)
    assert [type(r) for r in log.records] == [TruthLandmark, TruthPose, TruthPose]
    assert log.records[2] == TruthPose(0.1, 0.1, 0.0, 0.0) and writer.last_pose == (0.1, 0.0, 0.0)
    assert inner.calls[-1] == ("after", 0.1, 3)  # the inner hooks see the truth already written
    alone = TruthWriter(lambda: (0.0, 0.0, 0.0), record_period_s=0.1)
    assert not alone.due(0.05) and alone.due(0.1)  # without inner hooks: the recorder's 0.1 s
