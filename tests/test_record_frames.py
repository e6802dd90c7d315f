"""Record-then-detect: frames saved during a (simulated) recording land on the log's clock, so
`fgslam detect` attaches every one of them to a pose (none rejected for timing)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from fgslam.cli import main
from fgslam.record_frames import FrameSaver
from slamio.camera.sources import Frame, tum_frames
from slamio.log import Observation, Odometry, read_log


@pytest.mark.slow
def test_record_then_detect_on_the_simulator_rejects_no_frame_for_timing(tmp_path, capsys):
    out, frames = tmp_path / "run.jsonl", tmp_path / "frames"
    code = main(["record", "--port", "sim", "--model", "create2", "--path", "square", "--side", "0.5",
                 "--out", str(out), "--sim-time-scale", "2", "--sim-seed", "3", "--save-frames", str(frames)])
    printed = capsys.readouterr().out
    assert code == 0 and "saved" in printed
    log = read_log(out)
    odometry_stamps = {round(r.stamp_s, 6) for r in log.records if isinstance(r, Odometry)}
    saved = list(tum_frames(frames))
    assert len(saved) >= 20 and all(f.depth_m is not None for f in saved)
    assert {round(f.stamp_s, 6) for f in saved} <= odometry_stamps  # every frame at a record's stamp
    assert main(["detect", str(frames), "--camera", str(frames / "camera.yaml"), "--out", str(out),
                 "--tag-size", "0.16"]) == 0
    run = read_log(out)
    rejected = run.header.source["detect"][0]["rejected"]
    assert rejected.get("no_pose_at_frame_time", 0) == 0 and rejected.get("before_log_start", 0) == 0
    observations = [r for r in run.records if isinstance(r, Observation)]
    assert len(observations) >= 20  # the arena's tags, seen along the square
    assert json.loads((tmp_path / "run.jsonl.status.json").read_text())["reason"]["kind"] == "completed"


def test_frame_saver_writes_a_tum_folder_and_skips_when_behind(tmp_path):
    image = np.full((48, 64, 3), 120, np.uint8)
    depth = np.full((48, 64), 1.5, np.float32)
    depth[0, 0] = np.nan
    saver = FrameSaver(tmp_path / "f", lambda i, odo: (lambda: Frame(odo.stamp_s, i, "x", image, depth)), 0.1,
                       queue_size=100)
    assert saver.due(0.1) and not saver.due(0.05)
    for k in range(1, 6):
        saver.after_record(Odometry(0.1 * k, 0.0, 0.0, 0.0, ((1e-4, 0, 0), (0, 1e-4, 0), (0, 0, 1e-4))), None)
    saver.close()
    frames = list(tum_frames(tmp_path / "f"))
    assert [round(f.stamp_s, 6) for f in frames] == [0.1, 0.2, 0.3, 0.4, 0.5] and saver.saved == 5
    assert frames[0].depth_m[1, 1] == pytest.approx(1.5) and np.isnan(frames[0].depth_m[0, 0])


def test_save_frames_needs_an_empty_folder_and_a_source(tmp_path):
    folder = tmp_path / "frames"
    folder.mkdir()
    (folder / "old.png").write_bytes(b"x")
    common = ["record", "--port", "sim", "--model", "create2", "--out", str(tmp_path / "a.jsonl")]
    assert main(common + ["--save-frames", str(folder)]) == 1
    assert main(common[:2] + ["/dev/null-port", "--model", "create2", "--out", str(tmp_path / "b.jsonl"),
                              "--save-frames", str(tmp_path / "new")]) == 1
